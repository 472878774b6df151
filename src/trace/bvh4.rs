//! A 4-wide BVH for CPU ray casting. obvhs builds the binary tree (PLOC with parallel
//! reinsertion, Meister et al.); we collapse it into nodes of four children with float SoA boxes,
//! so one SSE slab test (glam's `Vec4`) covers four children, and traverse nearest child first,
//! skipping every box that starts beyond the closest hit so far. Leaves hold up to `LEAF_MAX`
//! triangles stored contiguously in leaf order.

use glam::{Vec3A, Vec4};
use obvhs::aabb::Aabb;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::bvh2::Bvh2;
use obvhs::ploc::PlocBuilder;
use obvhs::{Boundable, BvhBuildParams};
use smallvec::SmallVec;

use super::watertight::{self, RayShear, Tri};

/// The most triangles a tree can index (27 bits of a leaf entry).
pub const MAX_TRIANGLES: u32 = 1 << 27;
/// Subtrees with at most this many triangles become one leaf (2 measured fastest on primary
/// rays of a 134K-triangle scene: 1: 0.122 s, 2: 0.117 s, 3: 0.122 s, 4: 0.145 s, 8: 0.165 s).
const LEAF_MAX: u32 = 2;
const LEAF_FLAG: u32 = 1 << 31;
/// Children with no content get a box at +inf, which every slab test rejects.
const EMPTY: u32 = u32::MAX;

#[repr(C, align(32))]
#[derive(Clone, Copy, Debug)]
struct Node4 {
    lo: [Vec4; 3],
    hi: [Vec4; 3],
    /// Inner child: node index. Leaf: `LEAF_FLAG | first_slot << 4 | count`. Empty: `EMPTY`.
    child: [u32; 4],
    /// Bit k set when child k exists.
    valid: u32,
}

#[derive(Debug)]
pub struct Bvh4 {
    nodes: Vec<Node4>,
    /// Triangles in leaf order, and each one's index in the scene.
    pub tris: Vec<Tri>,
    pub ids: Vec<u32>,
}

/// A closest hit: `slot` indexes `Bvh4::tris`.
#[derive(Clone, Copy, Debug)]
pub struct SlotHit {
    pub t: f32,
    pub slot: u32,
    pub bary: [f32; 2],
}

impl Bvh4 {
    pub fn build<B: Boundable>(tris: &[Tri], boxes: &[B], params: BvhBuildParams) -> Self {
        let n = tris.len();
        let mut bvh2 = PlocBuilder::with_capacity(n).build(
            params.ploc_search_distance,
            boxes,
            (0..n as u32).collect(),
            params.sort_precision,
            params.search_depth_threshold,
        );
        ReinsertionOptimizer::default().run(&mut bvh2, params.reinsertion_batch_ratio, None);
        Collapse::new(&bvh2, tris).run()
    }

    /// Closest hit with `t_min <= t < t_max` along `o + t·d`.
    #[inline(always)]
    pub fn closest(
        &self,
        o: Vec3A,
        d: Vec3A,
        shear: &RayShear,
        t_min: f32,
        t_max: f32,
    ) -> Option<SlotHit> {
        let ray = SlabRay::new(o, d, t_min);
        let mut t_far = t_max;
        let mut best: Option<SlotHit> = None;
        // Inline for any realistic depth; spills to the heap rather than overflowing.
        let mut stack: SmallVec<[(u32, f32); 96]> = SmallVec::new();
        stack.push((0, t_min));
        while let Some((entry, near)) = stack.pop() {
            if near > t_far {
                continue;
            }
            if entry & LEAF_FLAG != 0 {
                for slot in leaf_slots(entry) {
                    if let Some((t, bary)) =
                        watertight::intersect(&self.tris[slot], o, shear, t_min, t_far)
                    {
                        t_far = t;
                        best = Some(SlotHit {
                            t,
                            slot: slot as u32,
                            bary,
                        });
                    }
                }
                continue;
            }
            let node = &self.nodes[entry as usize];
            let (t_in, mut mask) = ray.slab(node, t_far);
            // Push hit children farthest first, so the nearest is popped next.
            let t_in = t_in.to_array();
            let mut order = [(0f32, 0u32); 4];
            let mut k = 0;
            while mask != 0 {
                let i = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let mut j = k;
                while j > 0 && order[j - 1].0 < t_in[i] {
                    order[j] = order[j - 1];
                    j -= 1;
                }
                order[j] = (t_in[i], node.child[i]);
                k += 1;
            }
            for &(t, child) in &order[..k] {
                stack.push((child, t));
            }
        }
        best
    }

    /// Closest hits of a packet of coherent rays (ranged traversal, Overbeck, Ramamoorthi and
    /// Mark, "Large Ray Packets for Real-time Whitted Ray Tracing", 2008): each visited node
    /// carries the first and last ray of the packet that hit its box, so an upper node's box is
    /// tested once for the whole packet rather than once per ray, and interval arithmetic over
    /// the packet's origins and inverse directions culls boxes that every ray misses without
    /// testing any ray. Gives exactly the hits of [`Bvh4::closest`] ray by ray (a ray that misses
    /// a box misses every box inside it, since the slab test is monotone in the box's bounds).
    ///
    /// `t_far[i]` is ray i's `t_max` on entry and its closest hit's `t` on return. Returns
    /// `false`, touching nothing, when the rays' directions differ in sign on some axis (no
    /// interval bound then); the caller traces such a packet ray by ray.
    #[inline(always)]
    pub fn closest_packet(
        &self,
        rays: &[PacketRay],
        t_far: &mut [f32],
        best: &mut [Option<SlotHit>],
    ) -> bool {
        let n = rays.len();
        assert!(n > 0 && n <= PACKET && t_far.len() == n && best.len() == n);
        let Some(bounds) = PacketBounds::new(rays) else {
            return false;
        };
        let mut t_packet = t_far.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
        // (entry, first ray, last ray, interval lower bound of the entry distance).
        let mut stack: SmallVec<[(u32, u8, u8, f32); 96]> = SmallVec::new();
        stack.push((0, 0, (n - 1) as u8, bounds.t_min));
        while let Some((entry, first, last, near)) = stack.pop() {
            if near > t_packet {
                continue;
            }
            let (first, last) = (first as usize, last as usize);
            if entry & LEAF_FLAG != 0 {
                let mut hit = false;
                for r in first..=last {
                    let ray = &rays[r];
                    for slot in leaf_slots(entry) {
                        if let Some((t, bary)) = watertight::intersect(
                            &self.tris[slot],
                            ray.slab.org,
                            &ray.shear,
                            ray.slab.t_min,
                            t_far[r],
                        ) {
                            t_far[r] = t;
                            best[r] = Some(SlotHit {
                                t,
                                slot: slot as u32,
                                bary,
                            });
                            hit = true;
                        }
                    }
                }
                if hit {
                    t_packet = t_far.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
                }
                continue;
            }
            let node = &self.nodes[entry as usize];
            let (near4, possible) = bounds.cull(node, t_packet);
            if possible == 0 {
                continue;
            }
            // First ray hitting each child, then last, scanning from both ends of the range.
            let mut lo = [0u8; 4];
            let mut hi = [0u8; 4];
            let mut need = possible;
            for (r, ray) in rays.iter().enumerate().take(last + 1).skip(first) {
                let m = ray.slab.slab(node, t_far[r]).1 & need;
                for_bits(m, |k| lo[k] = r as u8);
                need &= !m;
                if need == 0 {
                    break;
                }
            }
            let found = possible & !need;
            let mut need = found;
            for r in (first..=last).rev() {
                if need == 0 {
                    break;
                }
                let m = rays[r].slab.slab(node, t_far[r]).1 & need;
                for_bits(m, |k| hi[k] = r as u8);
                need &= !m;
            }
            // Push farthest first (by the interval bound), so the nearest is popped next.
            let near4 = near4.to_array();
            let mut order = [(0f32, 0usize); 4];
            let mut k = 0;
            for_bits(found, |i| {
                let mut j = k;
                while j > 0 && order[j - 1].0 < near4[i] {
                    order[j] = order[j - 1];
                    j -= 1;
                }
                order[j] = (near4[i], i);
                k += 1;
            });
            for &(t, i) in &order[..k] {
                stack.push((node.child[i], lo[i], hi[i], t));
            }
        }
        true
    }
}

/// The most rays in one packet of [`Bvh4::closest_packet`].
pub const PACKET: usize = 32;

#[inline(always)]
fn leaf_slots(entry: u32) -> std::ops::Range<usize> {
    let first = ((entry & !LEAF_FLAG) >> 4) as usize;
    first..first + (entry & 15) as usize
}

#[inline(always)]
fn for_bits(mut mask: u32, mut f: impl FnMut(usize)) {
    while mask != 0 {
        f(mask.trailing_zeros() as usize);
        mask &= mask - 1;
    }
}

/// A ray's constants for the 4-wide slab test, splatted once.
#[derive(Clone, Copy, Debug)]
pub struct SlabRay {
    org: Vec3A,
    o: [Vec4; 3],
    inv: [Vec4; 3],
    t_min: f32,
}

impl SlabRay {
    #[inline(always)]
    fn new(o: Vec3A, d: Vec3A, t_min: f32) -> Self {
        // Components this close to zero get a huge but finite inverse of the same sign.
        let tiny = Vec3A::splat(1e-20);
        let d = Vec3A::select(d.abs().cmplt(tiny), tiny.copysign(d), d);
        let inv = Vec3A::ONE / d;
        Self {
            org: o,
            o: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            inv: [Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z)],
            t_min,
        }
    }

    /// Entry distances of the four children and the mask of those the ray hits before `t_far`.
    #[inline(always)]
    fn slab(&self, node: &Node4, t_far: f32) -> (Vec4, u32) {
        let [ox, oy, oz] = self.o;
        let [ix, iy, iz] = self.inv;
        let (x0, x1) = ((node.lo[0] - ox) * ix, (node.hi[0] - ox) * ix);
        let (y0, y1) = ((node.lo[1] - oy) * iy, (node.hi[1] - oy) * iy);
        let (z0, z1) = ((node.lo[2] - oz) * iz, (node.hi[2] - oz) * iz);
        let t_in = x0
            .min(x1)
            .max(y0.min(y1))
            .max(z0.min(z1))
            .max(Vec4::splat(self.t_min));
        // Widened by a few ulps (PBRT's 1 + 2γ₃) so rounding never rejects a grazed box.
        let t_out = x0
            .max(x1)
            .min(y0.max(y1))
            .min(z0.max(z1))
            .min(Vec4::splat(t_far))
            * (1.0 + 4.0 * f32::EPSILON);
        (t_in, t_in.cmple(t_out).bitmask() & node.valid)
    }
}

/// One ray of a packet: its slab constants and its watertight shear.
pub struct PacketRay {
    slab: SlabRay,
    shear: RayShear,
}

impl PacketRay {
    /// `d` should be unit length, as for [`Bvh4::closest`].
    #[inline(always)]
    pub fn new(o: Vec3A, d: Vec3A, t_min: f32) -> Self {
        Self {
            slab: SlabRay::new(o, d, t_min),
            shear: RayShear::new(d),
        }
    }
}

/// Interval bounds of a packet's origins and inverse directions, per axis, for culling a box
/// that no ray of the packet can hit (Wald, Boulos and Shirley, "Ray Tracing Deformable Scenes
/// Using Dynamic Bounding Volume Hierarchies", 2007, §4.2).
struct PacketBounds {
    /// Per axis: whether the directions are positive (the near plane is then the box's low one).
    positive: [bool; 3],
    o_lo: [Vec4; 3],
    o_hi: [Vec4; 3],
    inv_lo: [Vec4; 3],
    inv_hi: [Vec4; 3],
    t_min: f32,
}

impl PacketBounds {
    #[inline(always)]
    fn new(rays: &[PacketRay]) -> Option<Self> {
        let mut b = Self {
            positive: [false; 3],
            o_lo: [Vec4::ZERO; 3],
            o_hi: [Vec4::ZERO; 3],
            inv_lo: [Vec4::ZERO; 3],
            inv_hi: [Vec4::ZERO; 3],
            t_min: rays.iter().fold(f32::INFINITY, |a, r| a.min(r.slab.t_min)),
        };
        for a in 0..3 {
            let (mut olo, mut ohi) = (f32::INFINITY, f32::NEG_INFINITY);
            let (mut ilo, mut ihi) = (f32::INFINITY, f32::NEG_INFINITY);
            for r in rays {
                let (o, i) = (r.slab.org[a], r.slab.inv[a].x);
                (olo, ohi) = (olo.min(o), ohi.max(o));
                (ilo, ihi) = (ilo.min(i), ihi.max(i));
            }
            if ilo < 0.0 && ihi > 0.0 {
                return None;
            }
            b.positive[a] = ilo > 0.0;
            b.o_lo[a] = Vec4::splat(olo);
            b.o_hi[a] = Vec4::splat(ohi);
            b.inv_lo[a] = Vec4::splat(ilo);
            b.inv_hi[a] = Vec4::splat(ihi);
        }
        Some(b)
    }

    /// A lower bound on every ray's entry distance into each child, and the mask of children
    /// some ray of the packet may hit before `t_far` (the largest of the rays' `t_far`).
    #[inline(always)]
    fn cull(&self, node: &Node4, t_far: f32) -> (Vec4, u32) {
        let mut t_in = Vec4::splat(self.t_min);
        let mut t_out = Vec4::splat(t_far);
        for a in 0..3 {
            let (near, far) = if self.positive[a] {
                (node.lo[a], node.hi[a])
            } else {
                (node.hi[a], node.lo[a])
            };
            let (il, ih) = (self.inv_lo[a], self.inv_hi[a]);
            // (plane − o)·inv over o ∈ [o_lo, o_hi], inv ∈ [inv_lo, inv_hi]: the extremes lie
            // at the interval's corners.
            let (n0, n1) = (near - self.o_hi[a], near - self.o_lo[a]);
            let entry = (n0 * il).min(n0 * ih).min(n1 * il).min(n1 * ih);
            let (f0, f1) = (far - self.o_hi[a], far - self.o_lo[a]);
            let exit = (f0 * il).max(f0 * ih).max(f1 * il).max(f1 * ih);
            t_in = t_in.max(entry);
            t_out = t_out.min(exit);
        }
        let t_out = t_out * (1.0 + 4.0 * f32::EPSILON);
        (t_in, t_in.cmple(t_out).bitmask() & node.valid)
    }
}

/// Collapse of a binary tree into 4-wide nodes: each node's children are found by opening the
/// candidate with the largest surface area until there are four, or only leaves remain.
struct Collapse<'a> {
    bvh2: &'a Bvh2,
    tris: &'a [Tri],
    /// Triangles under each binary node.
    counts: Vec<u32>,
    out: Bvh4,
}

impl<'a> Collapse<'a> {
    fn new(bvh2: &'a Bvh2, tris: &'a [Tri]) -> Self {
        // Triangles under every node, by an explicit post-order walk (PLOC stores parents after
        // their children, so no index order is a post-order).
        let mut counts = vec![0u32; bvh2.nodes.len()];
        let mut stack = if bvh2.nodes.is_empty() {
            vec![]
        } else {
            vec![(0usize, false)]
        };
        while let Some((i, children_done)) = stack.pop() {
            let n = &bvh2.nodes[i];
            let (a, b) = (n.first_index as usize, n.first_index as usize + 1);
            if n.is_leaf() {
                counts[i] = n.prim_count;
            } else if children_done {
                counts[i] = counts[a] + counts[b];
            } else {
                stack.extend([(i, true), (a, false), (b, false)]);
            }
        }
        let out = Bvh4 {
            nodes: Vec::new(),
            tris: Vec::with_capacity(tris.len()),
            ids: Vec::with_capacity(tris.len()),
        };
        Self {
            bvh2,
            tris,
            counts,
            out,
        }
    }

    fn is_leaf(&self, i: usize) -> bool {
        self.bvh2.nodes[i].is_leaf() || self.counts[i] <= LEAF_MAX
    }

    fn run(mut self) -> Bvh4 {
        let root = if self.bvh2.nodes.is_empty() {
            None
        } else {
            Some(0usize)
        };
        self.out.nodes.push(empty_node());
        let mut work = vec![];
        if let Some(r) = root {
            let kids = if self.is_leaf(r) {
                vec![r]
            } else {
                self.children(r)
            };
            work.push((0usize, kids));
        }
        while let Some((slot, kids)) = work.pop() {
            let mut node = empty_node();
            for (k, &b) in kids.iter().enumerate() {
                let aabb = self.bvh2.nodes[b].aabb;
                for axis in 0..3 {
                    node.lo[axis][k] = aabb.min[axis];
                    node.hi[axis][k] = aabb.max[axis];
                }
                node.valid |= 1 << k;
                node.child[k] = if self.is_leaf(b) {
                    let first = self.out.tris.len() as u32;
                    self.gather(b);
                    let count = self.out.tris.len() as u32 - first;
                    // PLOC leaves hold one triangle, so leaves hold at most LEAF_MAX; `MAX_TRIANGLES`
                    // (checked before building) keeps `first` within its 27 bits.
                    debug_assert!(count <= LEAF_MAX && first < MAX_TRIANGLES);
                    LEAF_FLAG | first << 4 | count
                } else {
                    let index = self.out.nodes.len();
                    self.out.nodes.push(empty_node());
                    work.push((index, self.children(b)));
                    index as u32
                };
            }
            self.out.nodes[slot] = node;
        }
        self.out
    }

    /// Up to four descendants of inner node `i` that together cover it.
    fn children(&self, i: usize) -> Vec<usize> {
        let n = &self.bvh2.nodes[i];
        let mut kids = vec![n.first_index as usize, n.first_index as usize + 1];
        while kids.len() < 4 {
            let open = kids
                .iter()
                .enumerate()
                .filter(|(_, &k)| !self.is_leaf(k))
                .max_by(|a, b| {
                    area(&self.bvh2.nodes[*a.1].aabb).total_cmp(&area(&self.bvh2.nodes[*b.1].aabb))
                });
            let Some((at, &k)) = open else { break };
            let first = self.bvh2.nodes[k].first_index as usize;
            kids[at] = first;
            kids.push(first + 1);
        }
        kids
    }

    /// Append every triangle under binary node `i` to the leaf-ordered arrays.
    fn gather(&mut self, i: usize) {
        let mut stack = vec![i];
        while let Some(j) = stack.pop() {
            let n = &self.bvh2.nodes[j];
            if n.is_leaf() {
                for k in n.first_index..n.first_index + n.prim_count {
                    let prim = self.bvh2.primitive_indices[k as usize];
                    self.out.tris.push(self.tris[prim as usize]);
                    self.out.ids.push(prim);
                }
            } else {
                stack.push(n.first_index as usize + 1);
                stack.push(n.first_index as usize);
            }
        }
    }
}

fn area(b: &Aabb) -> f32 {
    b.half_area()
}

fn empty_node() -> Node4 {
    Node4 {
        lo: [Vec4::INFINITY; 3],
        hi: [Vec4::INFINITY; 3],
        child: [EMPTY; 4],
        valid: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::tests::icosphere;

    #[test]
    fn every_triangle_lands_in_exactly_one_leaf() {
        let (v, f) = icosphere(3);
        let tris: Vec<Tri> = f
            .iter()
            .map(|t| Tri {
                v: t.map(|k| Vec3A::from(v[k as usize])),
            })
            .collect();
        let boxes: Vec<Aabb> = tris.iter().map(|t| Aabb::from_points(&t.v)).collect();
        let tree = Bvh4::build(&tris, &boxes, BvhBuildParams::medium_build());
        let mut ids = tree.ids.clone();
        ids.sort_unstable();
        assert_eq!(ids, (0..f.len() as u32).collect::<Vec<_>>());
        // Every leaf is within LEAF_MAX and inside the triangle array.
        for n in &tree.nodes {
            for k in 0..4 {
                let c = n.child[k];
                if n.valid & (1 << k) != 0 && c & LEAF_FLAG != 0 {
                    let (first, count) = (((c & !LEAF_FLAG) >> 4) as usize, (c & 15) as usize);
                    assert!(
                        count >= 1
                            && count <= LEAF_MAX as usize
                            && first + count <= tree.tris.len()
                    );
                }
            }
        }
    }
}
