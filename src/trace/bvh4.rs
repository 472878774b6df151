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
    pub fn closest(
        &self,
        o: Vec3A,
        d: Vec3A,
        shear: &RayShear,
        t_min: f32,
        t_max: f32,
    ) -> Option<SlotHit> {
        let inv = |x: f32| {
            1.0 / if x.abs() < 1e-20 {
                1e-20f32.copysign(x)
            } else {
                x
            }
        };
        let (ox, oy, oz) = (Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z));
        let (ix, iy, iz) = (
            Vec4::splat(inv(d.x)),
            Vec4::splat(inv(d.y)),
            Vec4::splat(inv(d.z)),
        );
        let lo_t = Vec4::splat(t_min);
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
                let first = ((entry & !LEAF_FLAG) >> 4) as usize;
                for slot in first..first + (entry & 15) as usize {
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
            let (x0, x1) = ((node.lo[0] - ox) * ix, (node.hi[0] - ox) * ix);
            let (y0, y1) = ((node.lo[1] - oy) * iy, (node.hi[1] - oy) * iy);
            let (z0, z1) = ((node.lo[2] - oz) * iz, (node.hi[2] - oz) * iz);
            let t_in = x0.min(x1).max(y0.min(y1)).max(z0.min(z1)).max(lo_t);
            // Widened by a few ulps (PBRT's 1 + 2γ₃) so rounding never rejects a grazed box.
            let t_out = x0
                .max(x1)
                .min(y0.max(y1))
                .min(z0.max(z1))
                .min(Vec4::splat(t_far))
                * (1.0 + 4.0 * f32::EPSILON);
            let mut mask = t_in.cmple(t_out).bitmask() & node.valid;
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
            stack.extend(order[..k].iter().map(|&(t, child)| (child, t)));
        }
        best
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
