//! Top-down binned SAH construction of the 8-wide BVH, straight into wide nodes.
//!
//! Each node starts with one candidate (its triangles) and repeatedly splits the candidate of
//! largest surface area along the best of `bins` centroid bins per axis (Wald, "On fast
//! Construction of SAH-based Bounding Volume Hierarchies", 2007) until it has eight children or
//! none is worth splitting; that is how Embree builds its wide trees too (Wald et al., "Embree:
//! A Kernel Framework for Efficient CPU Ray Tracing", 2014, §4). Costs count triangle *blocks*
//! of four, the unit the leaf test works in, so leaves fill their blocks. Large ranges are
//! binned and their subtrees built in parallel (rayon).

use glam::Vec3A;
use rayon::prelude::*;

use super::node::{
    leaf_blocks, leaf_ref, node_index, node_ref, Bvh8, Node8, Tri4, EMPTY, LEAF, MAX_BLOCKS,
    MAX_DEPTH, MAX_LEAF_BLOCKS, NODE_UNITS,
};
use super::watertight::Tri;

/// Centroid bins per axis (16 built trees as good as 32 on the shared scenes, faster).
const BINS: usize = 16;

/// Build settings.
#[derive(Clone, Copy, Debug)]
pub struct BuildParams {
    /// Most triangles in one leaf (a multiple of 4, at most `4 · MAX_LEAF_BLOCKS`).
    pub max_leaf: usize,
    /// Cost of visiting a node, in units of one block test.
    pub node_cost: f32,
    /// Ranges at least this large are binned and built in parallel (rayon); `usize::MAX`
    /// builds on the calling thread only.
    pub parallel_min: usize,
}

impl BuildParams {
    /// The settings `cast_rays` uses.
    pub const fn standard() -> Self {
        Self {
            max_leaf: 8,
            node_cost: 1.0,
            parallel_min: 8192,
        }
    }

    /// The same tree, built on the calling thread only.
    pub const fn sequential(self) -> Self {
        Self {
            parallel_min: usize::MAX,
            ..self
        }
    }
}

/// An axis-aligned box; empty when `lo > hi`.
#[derive(Clone, Copy, Debug)]
pub struct Aabb {
    pub lo: Vec3A,
    pub hi: Vec3A,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        lo: Vec3A::INFINITY,
        hi: Vec3A::NEG_INFINITY,
    };

    #[inline(always)]
    pub fn grow(&mut self, b: &Aabb) {
        self.lo = self.lo.min(b.lo);
        self.hi = self.hi.max(b.hi);
    }

    #[inline(always)]
    fn grow_point(&mut self, p: Vec3A) {
        self.lo = self.lo.min(p);
        self.hi = self.hi.max(p);
    }

    #[inline(always)]
    pub fn union(mut self, b: &Aabb) -> Aabb {
        self.grow(b);
        self
    }

    /// The box around node `n`'s occupied children ([`Node8::bounds`]).
    pub fn of_node(n: &Node8) -> Aabb {
        let (lo, hi) = n.bounds();
        Aabb {
            lo: Vec3A::from(lo),
            hi: Vec3A::from(hi),
        }
    }

    /// Write this box as child slot `k`'s of node `n`.
    pub fn set_child(&self, n: &mut Node8, k: usize) {
        for a in 0..3 {
            n.b[a][k] = self.lo[a];
            n.b[3 + a][k] = self.hi[a];
        }
    }

    /// Half the surface area (0 for an empty box).
    #[inline(always)]
    fn half_area(&self) -> f32 {
        let e = (self.hi - self.lo).max(Vec3A::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }
}

/// A triangle's box padded by a few ulps of its coordinates' magnitude, so that the f32 slab
/// tests can never reject a ray that grazes a box exactly at a triangle's vertex or edge: the
/// watertight triangle test then decides alone.
pub fn padded_box(t: &Tri) -> Aabb {
    let lo = t.v[0].min(t.v[1]).min(t.v[2]);
    let hi = t.v[0].max(t.v[1]).max(t.v[2]);
    let mag = lo.abs().max(hi.abs()).max_element() + (hi - lo).max_element();
    let pad = Vec3A::splat(8.0 * f32::EPSILON * mag + f32::MIN_POSITIVE);
    Aabb {
        lo: lo - pad,
        hi: hi + pad,
    }
}

/// Build the tree over `tris` (at most `4 · MAX_BLOCKS` of them; the caller checks).
pub fn build(tris: &[Tri], params: BuildParams) -> Bvh8 {
    assert!(
        params.max_leaf.is_multiple_of(4)
            && (4..=4 * MAX_LEAF_BLOCKS as usize).contains(&params.max_leaf)
    );
    if tris.is_empty() {
        return Bvh8 {
            nodes: vec![Node8::EMPTY],
            blocks: vec![],
            depth: 1,
            inst: None,
        };
    }
    let parallel = params.parallel_min < tris.len();
    let boxes: Vec<Aabb> = if parallel {
        tris.par_iter().map(padded_box).collect()
    } else {
        tris.iter().map(padded_box).collect()
    };
    build_over(Some(tris), &boxes, params)
}

/// The tree over `boxes` (not empty), with leaves of [`Tri4`] blocks that hold only ids: each
/// lane's id is its box's index, its corners NaN. The top tree of a two-level tree is built
/// this way over its instances' boxes (`instances`), which then names them in its own leaves.
pub fn build_boxes(boxes: &[Aabb], params: BuildParams) -> Bvh8 {
    assert!(!boxes.is_empty());
    build_over(None, boxes, params)
}

/// [`build`] over `boxes`, with the triangles `tris` (one per box) in the leaves if given.
fn build_over(tris: Option<&[Tri]>, boxes: &[Aabb], params: BuildParams) -> Bvh8 {
    // Twice the centroid: one add, no multiply, and the same order.
    let centers: Vec<Vec3A> = boxes.iter().map(|b| b.lo + b.hi).collect();
    let mut refs: Vec<u32> = (0..boxes.len() as u32).collect();
    let b = Builder {
        tris,
        boxes,
        centers: &centers,
        p: params,
    };
    // Typical sizes (a node per ~16 triangles, a block per ~3.5), so the vectors rarely grow.
    let n = boxes.len();
    let mut out = Out {
        nodes: Vec::with_capacity(n / 12 + 1),
        blocks: Vec::with_capacity(n / 3 + 1),
        depth: 0,
    };
    let all = b.candidate(&refs, 0, bounds_of(&b, &refs), 1);
    let root = b.node(&mut refs, vec![all], 1, &mut out);
    debug_assert_eq!(root, 0);
    rank_for_any_hit(&mut out.nodes, &out.blocks);
    Bvh8 {
        nodes: out.nodes,
        blocks: out.blocks,
        depth: out.depth,
        inst: None,
    }
}

/// Fix each node's any-hit order (`Node8::any_slot`): its children by the chance that a ray
/// crossing a child's box is stopped inside it, per unit of the work that finding out costs,
/// highest first. This is the order of Ize and Hansen's ray termination SAH ("RTSAH Traversal
/// Order for Occlusion Rays", Eurographics 2011, §3), for an any-hit query: among children it
/// cannot tell apart by the ray, it tries first the one whose success per unit cost is highest.
///
/// - The chance: a line through a convex box meets a flat piece of area `a` inside it with
///   probability `2a / S` (S the box's surface area, by Crofton's formula); over a subtree of
///   triangle area `A`, taken as independent pieces, `1 − exp(−2A / S)`.
/// - The cost: the SAH's expected count of node and block tests in the subtree (a block costs
///   what a node does).
///
/// Measured with one thread on the occlusion rays of `bench rays`, against children nearest
/// first by entry distance with the same boxes around the start last (a Rust harness, rounds
/// interleaved in one process or alternated between two): `khr_toy_car` 1.07-1.20x (6.5 node
/// and 2.5 block tests per ray instead of 7.3 and 2.8); the other nine scenes' medians
/// 0.97-1.05x, single runs 0.89-1.04x (this machine's noise). Each child's order is fixed, so
/// there is no per-ray sort, but it ignores where along the ray the boxes lie.
pub(super) fn rank_for_any_hit(nodes: &mut [Node8], blocks: &[Tri4]) -> (f64, f64) {
    let mut subtree = vec![(0.0f64, 0.0f64); nodes.len()];
    rank_first_nodes(nodes, blocks, nodes.len(), &mut subtree);
    subtree[0]
}

/// [`rank_for_any_hit`] of the first `count` nodes, given in `subtree` each later node's
/// subtree triangle area and expected cost that they have as children (and filling in
/// theirs). Returns nothing; `subtree[0]` is the root's.
pub(super) fn rank_first_nodes(
    nodes: &mut [Node8],
    blocks: &[Tri4],
    count: usize,
    subtree: &mut [(f64, f64)],
) {
    // Each node's subtree: triangle area and expected cost. Children follow their parents in
    // `nodes`, so one pass from the back sees every child before its parent.
    for i in (0..count).rev() {
        let n = &nodes[i];
        let surface: f64 = {
            let (lo, hi) = n.bounds();
            let e: [f64; 3] = std::array::from_fn(|a| (hi[a] - lo[a]).max(0.0) as f64);
            2.0 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0])
        };
        let (mut area, mut cost) = (0.0, 1.0);
        let mut worth = [f64::NEG_INFINITY; 8];
        for k in (0..8).filter(|&k| n.child[k] != EMPTY) {
            let c = n.child[k];
            let (a, c_cost) = if c & LEAF != 0 {
                let range = leaf_blocks(c);
                let cost = range.len() as f64;
                (blocks[range].iter().map(block_area).sum(), cost)
            } else {
                let j = node_index(c);
                debug_assert!(j > i, "a child precedes its parent");
                subtree[j]
            };
            let s = n.child_area(k);
            area += a;
            cost += (s / surface.max(f64::MIN_POSITIVE)).min(1.0) * c_cost;
            let chance = -(-2.0 * a / s.max(f64::MIN_POSITIVE)).exp_m1();
            worth[k] = chance / c_cost;
        }
        subtree[i] = (area, cost);
        let mut slots: [u32; 8] = std::array::from_fn(|k| k as u32);
        // Highest first; ties (and empty slots, last) by slot.
        slots.sort_by(|&x, &y| {
            worth[y as usize]
                .total_cmp(&worth[x as usize])
                .then(x.cmp(&y))
        });
        nodes[i].set_any_order(slots);
    }
}

/// The total area of a block's triangles (unused lanes hold NaN corners and count nothing).
fn block_area(b: &Tri4) -> f64 {
    (0..4)
        .filter(|&lane| b.id[lane] != u32::MAX)
        .map(|lane| {
            let [p, q, r] = b.corners(lane).map(|c| c.map(f64::from));
            let (u, v) = (
                [0, 1, 2].map(|a| q[a] - p[a]),
                [0, 1, 2].map(|a| r[a] - p[a]),
            );
            let n = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
        })
        .sum()
}

fn bounds_of(b: &Builder, refs: &[u32]) -> (Aabb, Aabb) {
    let one = |r: &u32| {
        let mut c = Aabb::EMPTY;
        c.grow_point(b.centers[*r as usize]);
        (b.boxes[*r as usize], c)
    };
    let merge = |(a, c): (Aabb, Aabb), (d, e): (Aabb, Aabb)| (a.union(&d), c.union(&e));
    if refs.len() < b.p.parallel_min {
        return refs.iter().map(one).fold((Aabb::EMPTY, Aabb::EMPTY), merge);
    }
    refs.par_iter()
        .with_min_len(4096)
        .map(one)
        .reduce(|| (Aabb::EMPTY, Aabb::EMPTY), merge)
}

/// The tree under construction: nodes, leaf blocks and their triangle ids.
#[derive(Default)]
pub(super) struct Out {
    pub nodes: Vec<Node8>,
    pub blocks: Vec<Tri4>,
    pub depth: u32,
}

impl Out {
    /// Append a subtree built on its own, shifting its references; returns its root's index.
    pub fn append(&mut self, sub: Out) -> u32 {
        let (node_off, block_off) = (node_ref(self.nodes.len()), self.blocks.len() as u32);
        self.nodes.extend(sub.nodes.into_iter().map(|mut n| {
            for c in &mut n.child {
                if *c == EMPTY {
                    continue;
                }
                *c += if *c & LEAF != 0 { block_off } else { node_off };
            }
            n
        }));
        self.blocks.extend(sub.blocks);
        self.depth = self.depth.max(sub.depth);
        node_off / NODE_UNITS as u32
    }
}

/// A set of triangles (`refs[start..end]`), its boxes, and what to do with it.
#[derive(Clone, Debug)]
struct Candidate {
    start: usize,
    end: usize,
    bounds: Aabb,
    centers: Aabb,
    plan: Plan,
    /// The surface area heuristic prefers a leaf; `plan` still says how to split it if the
    /// node it belongs to has a slot to spare.
    leaf: bool,
}

#[derive(Clone, Copy, Debug)]
enum Plan {
    Leaf,
    /// Split at bin `bin` of `axis`: bins below it go left, with these boxes.
    Bins {
        axis: usize,
        bin: usize,
        left: Aabb,
        right: Aabb,
    },
    /// Split at the median of the centroids along `axis` (all centroids coincide, or the tree
    /// is too deep for more SAH splits).
    Median {
        axis: usize,
    },
}

impl Candidate {
    fn len(&self) -> usize {
        self.end - self.start
    }

    fn stays_leaf(&self) -> bool {
        self.leaf || matches!(self.plan, Plan::Leaf)
    }
}

/// Per-axis bins: count and the triangles' box.
#[derive(Clone)]
struct Bins {
    count: [[u32; 3]; BINS],
    bounds: [[Aabb; 3]; BINS],
}

impl Bins {
    fn new() -> Self {
        Self {
            count: [[0; 3]; BINS],
            bounds: [[Aabb::EMPTY; 3]; BINS],
        }
    }

    fn merge(mut self, o: Bins) -> Bins {
        for i in 0..BINS {
            for a in 0..3 {
                self.count[i][a] += o.count[i][a];
                self.bounds[i][a].grow(&o.bounds[i][a]);
            }
        }
        self
    }
}

/// Blocks of four needed for `n` triangles.
#[inline(always)]
fn blocks(n: usize) -> f32 {
    ((n as u32 + 3) >> 2) as f32
}

struct Builder<'a> {
    /// The triangles, or `None` for leaves of ids only (`build_boxes`).
    tris: Option<&'a [Tri]>,
    boxes: &'a [Aabb],
    centers: &'a [Vec3A],
    p: BuildParams,
}

/// Where a centroid falls among the bins starting at `lo`, on each axis.
#[inline(always)]
fn bins_of(c: Vec3A, lo: Vec3A, scale: Vec3A) -> [usize; 3] {
    // Clamped as floats, so the conversion needs no saturation (and is one instruction).
    let x = ((c - lo) * scale).clamp(Vec3A::ZERO, Vec3A::splat(BINS as f32 - 1.0));
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{__m128, _mm_cvttps_epi32, _mm_storeu_si128};
        let mut i = [0i32; 4];
        // SAFETY: SSE2 is part of x86_64; `i` has room for four lanes.
        unsafe { _mm_storeu_si128(i.as_mut_ptr().cast(), _mm_cvttps_epi32(__m128::from(x))) };
        [i[0] as usize, i[1] as usize, i[2] as usize]
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        [x.x as usize, x.y as usize, x.z as usize]
    }
}

impl Builder<'_> {
    /// Decide what to do with `refs` (already known to lie in `bounds`).
    fn candidate(
        &self,
        refs: &[u32],
        start: usize,
        (bounds, centers): (Aabb, Aabb),
        depth: u32,
    ) -> Candidate {
        let n = refs.len();
        let extent = centers.hi - centers.lo;
        let widest = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let mut leaf = false;
        let plan = if n <= 4 {
            Plan::Leaf
        } else if extent.max_element() <= 0.0 {
            if n <= self.p.max_leaf {
                Plan::Leaf
            } else {
                Plan::Median { axis: widest }
            }
        } else if depth >= MAX_DEPTH - 12 {
            // Median splits at least halve the largest child at every step, so the ~log8(n)
            // levels left fit under MAX_DEPTH (triangles < 4·2^28 = 8^10).
            Plan::Median { axis: widest }
        } else {
            let (plan, prefers_leaf) = self.sah(refs, &bounds, &centers);
            leaf = prefers_leaf;
            plan
        };
        Candidate {
            start,
            end: start + n,
            bounds,
            centers,
            plan,
            leaf,
        }
    }

    /// The best binned split of `refs`, and whether a leaf would cost less.
    fn sah(&self, refs: &[u32], bounds: &Aabb, centers: &Aabb) -> (Plan, bool) {
        let nb = BINS;
        let scale = centers_scale(centers);
        let fill = |chunk: &[u32]| {
            let add = |bins: &mut Bins, r: u32| {
                let at = bins_of(self.centers[r as usize], centers.lo, scale);
                let b = &self.boxes[r as usize];
                for (a, &i) in at.iter().enumerate() {
                    bins.count[i][a] += 1;
                    bins.bounds[i][a].grow(b);
                }
            };
            if chunk.len() < 64 {
                let mut bins = Bins::new();
                chunk.iter().for_each(|&r| add(&mut bins, r));
                return bins;
            }
            // Two sets of bins for alternate triangles: neighbours often share a bin, and one
            // set would chain every update on the store of the one before.
            let (mut even, mut odd) = (Bins::new(), Bins::new());
            for pair in chunk.chunks(2) {
                add(&mut even, pair[0]);
                if let Some(&r) = pair.get(1) {
                    add(&mut odd, r);
                }
            }
            even.merge(odd)
        };
        let bins = if refs.len() >= self.p.parallel_min {
            refs.par_chunks(self.p.parallel_min / 2)
                .map(fill)
                .reduce(Bins::new, Bins::merge)
        } else {
            fill(refs)
        };
        // Sweep each axis: costs of every split position from both sides.
        let mut best = (f32::INFINITY, 0, 0);
        let mut right_area = [0.0f32; BINS];
        let mut right_blocks = [0.0f32; BINS];
        for a in 0..3 {
            if scale[a] == 0.0 {
                continue;
            }
            let (mut acc, mut count) = (Aabb::EMPTY, 0usize);
            for i in (1..nb).rev() {
                acc.grow(&bins.bounds[i][a]);
                count += bins.count[i][a] as usize;
                right_area[i] = acc.half_area();
                right_blocks[i] = blocks(count);
            }
            let (mut acc, mut count) = (Aabb::EMPTY, 0usize);
            for i in 1..nb {
                acc.grow(&bins.bounds[i - 1][a]);
                count += bins.count[i - 1][a] as usize;
                if count == 0 || count == refs.len() {
                    continue;
                }
                let cost = acc.half_area() * blocks(count) + right_area[i] * right_blocks[i];
                if cost < best.0 {
                    best = (cost, a, i);
                }
            }
        }
        let (cost, axis, bin) = best;
        let area = bounds.half_area().max(f32::MIN_POSITIVE);
        let split_cost = self.p.node_cost + cost / area;
        if !split_cost.is_finite() {
            // No two bins differ (a degenerate spread of centroids): split at the median.
            return (Plan::Median { axis: 0 }, false);
        }
        let leaf = refs.len() <= self.p.max_leaf && blocks(refs.len()) <= split_cost;
        let side = |range: std::ops::Range<usize>| {
            range.fold(Aabb::EMPTY, |b, i| b.union(&bins.bounds[i][axis]))
        };
        let plan = Plan::Bins {
            axis,
            bin,
            left: side(0..bin),
            right: side(bin..nb),
        };
        (plan, leaf)
    }

    /// Split `c`, partitioning its part of `refs`, into two candidates.
    fn split(&self, refs: &mut [u32], c: &Candidate, depth: u32) -> (Candidate, Candidate) {
        let part = &mut refs[c.start..c.end];
        let (mid, left, right) = match c.plan {
            Plan::Bins {
                axis,
                bin,
                left,
                right,
            } => {
                // `bins_of(..)[axis] < bin`, without the conversion: the bin is the truncated
                // position, so it is below `bin` exactly when the position is.
                let scale = centers_scale(&c.centers)[axis];
                let (lo, bin) = (c.centers.lo[axis], bin as f32);
                let goes_left = |r: &u32| (self.centers[*r as usize][axis] - lo) * scale < bin;
                let mid = partition(part, goes_left);
                let (l, r) = part.split_at(mid);
                (
                    mid,
                    (left, self.center_bounds(l)),
                    (right, self.center_bounds(r)),
                )
            }
            Plan::Median { axis } => {
                let mid = part.len() / 2;
                part.select_nth_unstable_by(mid, |a, b| {
                    let (ca, cb) = (self.centers[*a as usize], self.centers[*b as usize]);
                    ca[axis].total_cmp(&cb[axis]).then(a.cmp(b))
                });
                let (l, r) = part.split_at(mid);
                (mid, bounds_of(self, l), bounds_of(self, r))
            }
            Plan::Leaf => unreachable!("leaves are never split"),
        };
        let (l, r) = part.split_at(mid);
        (
            self.candidate(l, c.start, left, depth),
            self.candidate(r, c.start + mid, right, depth),
        )
    }

    /// Build the node whose children start as `kids` (within `refs`) at `depth`; returns its
    /// index in `out`.
    fn node(&self, refs: &mut [u32], mut kids: Vec<Candidate>, depth: u32, out: &mut Out) -> u32 {
        let deep = depth >= MAX_DEPTH - 12;
        while kids.len() < 8 {
            // Open the largest candidate (by area; by count once the tree is too deep), even one
            // the surface area heuristic would keep as a leaf: a spare slot costs the node test
            // nothing, and two small leaves are tested only where the ray enters them (Embree
            // fills its nodes the same way). Its own split plan says how.
            let open = kids
                .iter()
                .enumerate()
                .filter(|(_, k)| !matches!(k.plan, Plan::Leaf))
                .max_by(|a, b| {
                    if deep {
                        a.1.len().cmp(&b.1.len())
                    } else {
                        a.1.bounds.half_area().total_cmp(&b.1.bounds.half_area())
                    }
                })
                .map(|(i, _)| i);
            let Some(i) = open else { break };
            let (l, r) = self.split(refs, &kids[i], depth + 1);
            kids[i] = l;
            kids.push(r);
        }
        kids.sort_by_key(|k| k.start);
        let index = out.nodes.len() as u32;
        out.nodes.push(Node8::EMPTY);
        out.depth = out.depth.max(depth);
        let mut node = Node8::EMPTY;
        for (k, kid) in kids.iter().enumerate() {
            for a in 0..3 {
                node.b[a][k] = kid.bounds.lo[a];
                node.b[a + 3][k] = kid.bounds.hi[a];
            }
        }
        // Children's slices of `refs`, in order.
        let mut slices: Vec<&mut [u32]> = Vec::with_capacity(8);
        let mut rest = &mut refs[..];
        let mut at = kids.first().map_or(0, |k| k.start);
        for kid in &kids {
            let (_, tail) = std::mem::take(&mut rest).split_at_mut(kid.start - at);
            let (mine, tail) = tail.split_at_mut(kid.len());
            slices.push(mine);
            rest = tail;
            at = kid.end;
        }
        let total: usize = kids.iter().map(Candidate::len).sum();
        if total >= self.p.parallel_min {
            // Subtrees in parallel, each into its own `Out`, appended in order.
            let subs: Vec<Option<(u32, Out)>> = slices
                .into_par_iter()
                .zip(kids.par_iter())
                .map(|(s, kid)| {
                    if kid.stays_leaf() {
                        return None;
                    }
                    let mut sub = Out::default();
                    let root = self.node(s, vec![rebase(kid)], depth + 1, &mut sub);
                    Some((root, sub))
                })
                .collect();
            for (k, (kid, sub)) in kids.iter().zip(subs).enumerate() {
                node.child[k] = match sub {
                    Some((root, sub)) => node_ref((out.append(sub) + root) as usize),
                    None => self.leaf(&refs[kid.start..kid.end], out),
                };
            }
        } else {
            for (k, (s, kid)) in slices.into_iter().zip(&kids).enumerate() {
                node.child[k] = if kid.stays_leaf() {
                    self.leaf(s, out)
                } else {
                    node_ref(self.node(s, vec![rebase(kid)], depth + 1, out) as usize)
                };
            }
        }
        node.set_order();
        out.nodes[index as usize] = node;
        index
    }

    /// The box of the centroids of `refs`.
    fn center_bounds(&self, refs: &[u32]) -> Aabb {
        let mut c = Aabb::EMPTY;
        for &r in refs {
            c.grow_point(self.centers[r as usize]);
        }
        c
    }

    /// Write the triangles of `refs` as one leaf of blocks of four.
    fn leaf(&self, refs: &[u32], out: &mut Out) -> u32 {
        let first = out.blocks.len() as u32;
        for chunk in refs.chunks(4) {
            let mut block = Tri4::NONE;
            for (lane, &r) in chunk.iter().enumerate() {
                match self.tris {
                    Some(tris) => block.set(lane, &tris[r as usize], r),
                    None => block.id[lane] = r,
                }
            }
            out.blocks.push(block);
        }
        assert!(
            out.blocks.len() as u64 <= MAX_BLOCKS as u64,
            "too many triangles"
        );
        leaf_ref(first, out.blocks.len() as u32 - first)
    }
}

/// The same candidate at the start of its own slice.
fn rebase(c: &Candidate) -> Candidate {
    Candidate {
        start: 0,
        end: c.len(),
        ..c.clone()
    }
}

/// Bins per unit of centroid position along each axis (0 where the centroids do not spread).
fn centers_scale(c: &Aabb) -> Vec3A {
    let e = c.hi - c.lo;
    Vec3A::select(
        e.cmpgt(Vec3A::ZERO),
        Vec3A::splat(BINS as f32 * (1.0 - 1e-6)) / e,
        Vec3A::ZERO,
    )
}

/// Move the refs for which `left` holds to the front; returns how many there are.
fn partition(refs: &mut [u32], left: impl Fn(&u32) -> bool) -> usize {
    let (mut i, mut j) = (0, refs.len());
    loop {
        while i < j && left(&refs[i]) {
            i += 1;
        }
        while i < j && !left(&refs[j - 1]) {
            j -= 1;
        }
        if i >= j {
            return i;
        }
        refs.swap(i, j - 1);
        i += 1;
        j -= 1;
    }
}

#[cfg(test)]
#[path = "build_tests.rs"]
mod tests;
