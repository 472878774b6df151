//! The 8-wide BVH that every CPU ray query traverses, and its traversal.
//!
//! Layout (the single-ray layout of Fuetterling et al., "Accelerated Single Ray Tracing for Wide
//! Vector Units", HPG 2017): each node holds its eight children's boxes as six arrays of eight
//! floats, so one AVX2 slab test covers all eight; leaves are runs of `Tri4` blocks, four
//! triangles stored lane by lane, tested together by the watertight test (`watertight`).
//!
//! Traversal is depth first with a short stack. A node whose ray hits several children pushes
//! them sorted by entry distance (an 8-lane sorting network on AVX2) and descends into the
//! nearest; entries popped beyond the closest hit so far are skipped. The same loop serves the
//! three queries through a [`Sink`]: closest hit, any hit, and the k nearest hits. Any-hit rays
//! visit children in an order the builder fixed, the likeliest to stop a ray for its cost first
//! and the boxes around the ray's start last (`Kernel::push_any`), and first try the block that
//! stopped the previous ray (`Any::hint`).

use std::mem::MaybeUninit;
use std::ops::Range;

use glam::Vec3A;

use super::watertight::{RayShear, Tri};

/// Child reference bit marking a leaf: `LEAF | (blocks − 1) << 28 | first block`. An inner
/// child's reference is its node's offset in `Bvh8::nodes` in units of 32 bytes (a shift, not a
/// multiply, on the way to its boxes).
pub const LEAF: u32 = 1 << 31;
/// A leaf spans at most this many `Tri4` blocks (3 bits of its reference).
pub const MAX_LEAF_BLOCKS: u32 = 8;
/// Blocks a tree can index (28 bits of a leaf reference, the last value kept for `EMPTY`).
pub const MAX_BLOCKS: u32 = (1 << 28) - 1;
/// The reference of a child slot with nothing in it (its box is empty: lo = +inf, hi = −inf).
pub const EMPTY: u32 = u32::MAX;
/// Entries of the traversal stack. The builder keeps trees at most `MAX_DEPTH` nodes deep, and
/// each node leaves at most 7 entries behind, plus up to 16 lanes written at once by an AVX2
/// push (the any-hit push stores two groups of 8).
pub const STACK: usize = 512;
pub const MAX_DEPTH: u32 = (STACK as u32 - 16) / 7;

/// 32-byte units in a node.
pub const NODE_UNITS: usize = size_of::<Node8>() / 32;
/// Nodes a tree can hold (their references must stay below `LEAF`); more than `MAX_BLOCKS`, so
/// a tree of at most `MAX_BLOCKS` triangles (at most that many nodes) always fits.
pub const MAX_NODES: usize = (LEAF as usize) / NODE_UNITS;

/// The reference of node `index`.
#[inline(always)]
pub fn node_ref(index: usize) -> u32 {
    debug_assert!(index < MAX_NODES);
    (index * NODE_UNITS) as u32
}

/// The index in `Bvh8::nodes` of the node an inner reference names.
#[inline(always)]
pub fn node_index(r: u32) -> usize {
    r as usize / NODE_UNITS
}

/// The node an inner reference names.
#[inline(always)]
pub(crate) fn node_at(nodes: &[Node8], r: u32) -> &Node8 {
    debug_assert!(
        (r as usize) < nodes.len() * NODE_UNITS && (r as usize).is_multiple_of(NODE_UNITS)
    );
    // SAFETY: inner references name nodes of `nodes` (checked by the builder's tests).
    unsafe { &*((nodes.as_ptr() as *const u8).add(node_offset(r)) as *const Node8) }
}

/// The byte offset in `nodes` of the node an inner reference names.
#[inline(always)]
fn node_offset(r: u32) -> usize {
    (r as usize) << 5
}

/// The first block of the leaf a leaf reference names.
#[inline(always)]
fn leaf_first(r: u32) -> usize {
    (r & ((1 << 28) - 1)) as usize
}

#[inline(always)]
pub fn leaf_ref(first: u32, blocks: u32) -> u32 {
    debug_assert!((1..=MAX_LEAF_BLOCKS).contains(&blocks) && first + blocks <= MAX_BLOCKS);
    LEAF | (blocks - 1) << 28 | first
}

#[inline(always)]
pub fn leaf_blocks(r: u32) -> Range<usize> {
    let first = leaf_first(r);
    first..first + ((r >> 28) & 7) as usize + 1
}

/// Eight children: `b[0..3]` their low x, y, z, `b[3..6]` their high x, y, z; and for each of
/// the eight octants a ray's direction can point into, the children in the order the ray meets
/// their centres: bits `3o..3o+3` of `order[r]` hold the slot of rank `r` for octant `o`
/// (Fuetterling et al. 2017, §4.2). Bits `ANY_SHIFT..ANY_SHIFT+3` of `order[r]` hold the slot of
/// rank `r` in the any-hit order (`build::rank_for_any_hit`), and the next three bits of
/// `order[k]` the rank of slot `k` in it.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug)]
pub struct Node8 {
    pub b: [[f32; 8]; 6],
    pub child: [u32; 8],
    pub order: [u32; 8],
}

/// Where the any-hit order lies in each entry of `Node8::order` (above the octants' 24 bits).
pub const ANY_SHIFT: u32 = 24;

/// The size of one row of `Node8::b`.
pub const ROW_BYTES: usize = std::mem::size_of::<[f32; 8]>();

impl Node8 {
    /// The row of `b` at byte offset `off` (`Ray::near`, `Ray::far`): an offset, not an index,
    /// saves the traversal loop a shift per plane.
    ///
    /// # Safety
    /// `off` is `ROW_BYTES * i` for a row `i < 6`, as `Ray::new` makes them.
    #[inline(always)]
    pub(crate) unsafe fn row(&self, off: usize) -> &[f32; 8] {
        debug_assert!(off.is_multiple_of(ROW_BYTES) && off < std::mem::size_of_val(&self.b));
        // SAFETY: `b` is the first field (repr(C)); the caller keeps `off` within it.
        unsafe { &*((self as *const Node8 as *const u8).add(off) as *const [f32; 8]) }
    }

    pub const EMPTY: Node8 = Node8 {
        b: [
            [f32::INFINITY; 8],
            [f32::INFINITY; 8],
            [f32::INFINITY; 8],
            [f32::NEG_INFINITY; 8],
            [f32::NEG_INFINITY; 8],
            [f32::NEG_INFINITY; 8],
        ],
        child: [EMPTY; 8],
        order: [0; 8],
    };

    /// Fill the octants' part of `order` from the boxes: valid children by the position of their
    /// centres along each octant's diagonal, nearest first; empty slots last. The any-hit order
    /// is left as it was.
    pub fn set_order(&mut self) {
        for o in &mut self.order {
            *o &= !((1 << ANY_SHIFT) - 1);
        }
        // A refit calls this for every node, so it neither allocates nor branches on the
        // keys: each slot's key (compared as `f32::total_cmp` does: its bits made a signed
        // integer of the same order; +inf for an empty slot, which comes last) is widened
        // with the slot below it, which makes keys unique and breaks ties by slot, and the
        // eight are sorted by a fixed network.
        let centre: [[f32; 8]; 3] =
            std::array::from_fn(|a| std::array::from_fn(|k| self.b[a][k] + self.b[a + 3][k]));
        for o in 0..8u32 {
            let sign = [0, 1, 2].map(|a| if o >> a & 1 == 1 { -1.0f32 } else { 1.0 });
            let mut key: [i64; 8] = std::array::from_fn(|k| {
                let x = if self.child[k] == EMPTY {
                    f32::INFINITY
                } else {
                    (0..3).map(|a| centre[a][k] * sign[a]).sum()
                };
                let bits = x.to_bits() as i32;
                let ordered = bits ^ (((bits >> 31) as u32) >> 1) as i32;
                (i64::from(ordered) << 3) | k as i64
            });
            sort8(&mut key);
            for (rank, k) in key.iter().enumerate() {
                self.order[rank] |= ((k & 7) as u32) << (3 * o);
            }
        }
    }

    /// Set the any-hit order: `slots[r]` is the slot of rank `r` (a permutation of 0..8).
    pub fn set_any_order(&mut self, slots: [u32; 8]) {
        for o in &mut self.order {
            *o &= (1 << ANY_SHIFT) - 1;
        }
        for (rank, k) in slots.into_iter().enumerate() {
            debug_assert!(k < 8);
            self.order[rank] |= k << ANY_SHIFT;
            self.order[k as usize] |= (rank as u32) << (ANY_SHIFT + 3);
        }
    }

    /// The rank of slot `slot` in the any-hit order.
    #[inline(always)]
    pub fn any_rank(&self, slot: usize) -> u32 {
        (self.order[slot] >> (ANY_SHIFT + 3)) & 7
    }

    /// The slot of rank `rank` in the any-hit order.
    #[inline(always)]
    pub fn any_slot(&self, rank: usize) -> usize {
        (self.order[rank] >> ANY_SHIFT) as usize & 7
    }

    /// The box around the occupied children's boxes, as (low, high) corners (low above high
    /// when no slot is occupied).
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for k in (0..8).filter(|&k| self.child[k] != EMPTY) {
            for a in 0..3 {
                lo[a] = lo[a].min(self.b[a][k]);
                hi[a] = hi[a].max(self.b[a + 3][k]);
            }
        }
        (lo, hi)
    }

    /// The surface area of child `k`'s box (0 for an empty slot).
    pub fn child_area(&self, k: usize) -> f64 {
        let e: [f64; 3] =
            std::array::from_fn(|a| (self.b[a + 3][k] - self.b[a][k]).max(0.0) as f64);
        2.0 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0])
    }
}

/// The 19 compare-exchanges that sort any eight values (Knuth, TAOCP vol. 3, §5.3.4, the
/// optimal network for n = 8), each a branch-free min and max.
#[rustfmt::skip]
const SORT8: [(usize, usize); 19] = [
    (0, 2), (1, 3), (4, 6), (5, 7),
    (0, 4), (1, 5), (2, 6), (3, 7),
    (0, 1), (2, 3), (4, 5), (6, 7),
    (2, 4), (3, 5),
    (1, 4), (3, 6),
    (1, 2), (3, 4), (5, 6),
];

/// Sort eight keys ascending with the [`SORT8`] network, unrolled so that the keys stay in
/// registers.
#[inline(always)]
fn sort8(x: &mut [i64; 8]) {
    macro_rules! exchange {
        ($($k:expr),*) => {$(
            let (i, j) = SORT8[$k];
            let (a, b) = (x[i], x[j]);
            (x[i], x[j]) = (a.min(b), a.max(b));
        )*};
    }
    exchange!(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18);
}

/// Four triangles lane by lane: `v[corner][axis][lane]`, and each lane's triangle index in the
/// scene (beside the corners, so the closest-hit tie-break reads no other cache line). Unused
/// lanes hold NaN corners, which every comparison of the triangle test rejects, and the id
/// `u32::MAX`.
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug)]
pub struct Tri4 {
    pub v: [[[f32; 4]; 3]; 3],
    pub id: [u32; 4],
}

impl Tri4 {
    pub const NONE: Tri4 = Tri4 {
        v: [[[f32::NAN; 4]; 3]; 3],
        id: [u32::MAX; 4],
    };

    pub fn set(&mut self, lane: usize, t: &Tri, id: u32) {
        for (c, p) in t.v.iter().enumerate() {
            for a in 0..3 {
                self.v[c][a][lane] = p[a];
            }
        }
        self.id[lane] = id;
    }

    /// Lane `lane`'s corners as arrays.
    #[inline(always)]
    pub fn corners(&self, lane: usize) -> [[f32; 3]; 3] {
        let c = |k: usize| [self.v[k][0][lane], self.v[k][1][lane], self.v[k][2][lane]];
        [c(0), c(1), c(2)]
    }

    #[inline(always)]
    pub fn tri(&self, lane: usize) -> Tri {
        Tri {
            v: std::array::from_fn(|c| {
                Vec3A::new(self.v[c][0][lane], self.v[c][1][lane], self.v[c][2][lane])
            }),
        }
    }
}

/// The tree: nodes (the root first) and triangle blocks in leaf order.
#[derive(Debug)]
pub struct Bvh8 {
    pub nodes: Vec<Node8>,
    pub blocks: Vec<Tri4>,
    /// Nodes on the longest root-to-leaf path.
    pub depth: u32,
}

impl Bvh8 {
    /// The diagonal of the root's box (0 for an empty tree).
    pub fn diagonal(&self) -> f32 {
        let (lo, hi) = self.nodes[0].bounds();
        if lo[0] > hi[0] {
            0.0
        } else {
            (Vec3A::from(hi) - Vec3A::from(lo)).length()
        }
    }

    /// See `BvhStats::sah`.
    pub fn sah(&self) -> f64 {
        let (lo, hi) = self.nodes[0].bounds();
        let e: [f64; 3] = std::array::from_fn(|a| hi[a] as f64 - lo[a] as f64);
        // Surface areas: twice the root's half area over each child's full area.
        let ra = 2.0 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0]).max(f64::MIN_POSITIVE);
        let mut cost = 1.0;
        for n in self.nodes.iter() {
            for k in 0..8 {
                let c = n.child[k];
                if c == EMPTY {
                    continue;
                }
                let w = if c & LEAF != 0 {
                    leaf_blocks(c).len() as f64
                } else {
                    1.0
                };
                cost += n.child_area(k) / ra * w;
            }
        }
        cost
    }

    /// Bytes held by the tree (nodes and blocks).
    pub fn bytes(&self) -> usize {
        self.nodes.len() * size_of::<Node8>() + self.blocks.len() * size_of::<Tri4>()
    }
}

/// A ray's constants for traversal (its direction as given, not normalised).
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub o: Vec3A,
    pub inv: Vec3A,
    /// `inv` widened by [`WIDEN`]: exit distances computed with it come out a few ulps long.
    pub inv_far: Vec3A,
    /// Per axis, the byte offset in a `Node8` of the row of `b` holding each box's near plane,
    /// and of its far plane (see [`Node8::row`]).
    pub(crate) near: [usize; 3],
    pub(crate) far: [usize; 3],
    pub shear: RayShear,
    /// The origin in the shear's axis order (kx, ky, kz).
    pub o_k: [f32; 3],
    pub t_min: f32,
    /// 3 × the direction's octant (bit a set when component a is negative): where this ray's
    /// order lies in `Node8::order`.
    pub octant_shift: u32,
}

impl Ray {
    /// The ray from `o` along `d`, traced in units of `d`'s length (no normalisation: every
    /// test is invariant to the direction's scale, and the square root and divisions it would
    /// take sit at the head of every ray's dependency chain).
    #[inline(always)]
    pub fn new(o: Vec3A, d: Vec3A, t_min: f32) -> Self {
        // Components this small (relative to the largest) get a huge but finite inverse of the
        // same sign, so the slab products never meet 0 · inf.
        let tiny = Vec3A::splat(1e-20 * d.abs().max_element());
        let inv = Vec3A::ONE / Vec3A::select(d.abs().cmplt(tiny), tiny.copysign(d), d);
        let row = |a: usize| a + 3 * usize::from(inv[a] < 0.0);
        let near = std::array::from_fn(|a| ROW_BYTES * row(a));
        let shear = RayShear::with_inverse(d, inv);
        Self {
            o,
            inv,
            inv_far: inv * WIDEN,
            near,
            far: std::array::from_fn(|a| ROW_BYTES * ((row(a) + 3) % 6)),
            shear,
            o_k: shear.permute(o),
            t_min,
            octant_shift: 3 * (0..3).map(|a| u32::from(inv[a] < 0.0) << a).sum::<u32>(),
        }
    }
}

/// Boxes whose exit distance rounds to just below the entry distance are still entered: exits
/// are computed with the inverse direction widened by a few ulps (PBRT's 1 + 2γ₃; Embree's
/// robust mode does the same), so the f32 slab test never rejects a box the ray grazes, and
/// the watertight triangle test decides alone.
pub const WIDEN: f32 = 1.0 + 4.0 * f32::EPSILON;

/// Four triangles' test results: lanes hit within `[t_min, t_far)`, their `t` (+inf in the
/// other lanes), and for each lane the barycentric numerators and their common denominator
/// (barycentric (u, v) = (`bu / det`, `bv / det`)).
#[derive(Clone, Copy, Debug)]
pub struct Tri4Hit {
    pub mask: u32,
    pub t: [f32; 4],
    pub bu: [f32; 4],
    pub bv: [f32; 4],
    pub det: [f32; 4],
}

impl Tri4Hit {
    /// No lane hit.
    pub const NONE: Tri4Hit = Tri4Hit {
        mask: 0,
        t: [f32::INFINITY; 4],
        bu: [0.0; 4],
        bv: [0.0; 4],
        det: [1.0; 4],
    };
}

/// The arithmetic of traversal, one implementation per instruction set. Every implementation
/// gives bit-identical results (the portable one is the reference in the tests).
pub trait Kernel: Copy {
    /// Whether [`Kernel::packet`] traces packets.
    const PACKETS: bool = false;
    /// A ray's constants in this kernel's registers.
    type R: Copy;
    /// What a node test leaves for ordering the children it hit.
    type D: Copy;
    fn prepare(self, r: &Ray) -> Self::R;
    /// The entry distance of child `lane` left by `node`.
    fn dist(self, d: &Self::D, lane: u32) -> f32;
    /// The children of `n` whose boxes the ray enters before `t_far`, as a bit mask.
    fn node(self, n: &Node8, r: &Self::R, t_far: f32) -> (u32, Self::D);
    /// Push the children in `mask` (three or more) onto `s` above `sp`, farthest first (by
    /// entry distance); return the nearest, unpushed.
    fn push_sorted(self, n: &Node8, mask: u32, d: Self::D, s: &mut Stack, sp: &mut usize) -> u32;
    /// Push the children in `mask` (three or more; `descend` orders two by a compare, the same
    /// way, and the kernels take any two or more) for an any-hit query and return the first to
    /// visit, unpushed: the node's any-hit order ([`Node8::any_slot`]), with the boxes that hold
    /// the ray's start (entry distance `t_min`) below the rest. A shadow ray leaves a surface,
    /// which those boxes hold and which rarely blocks it. The entries' distances are 0: an any-hit
    /// query never shortens its range, so nothing on its stack is culled.
    fn push_any(
        self,
        n: &Node8,
        mask: u32,
        d: Self::D,
        t_min: f32,
        s: &mut Stack,
        sp: &mut usize,
    ) -> u32;
    /// The watertight test of a block's four triangles.
    fn tri4(self, b: &Tri4, r: &Self::R, ray: &Ray, t_far: f32) -> Tri4Hit;
    /// Refine hits in f64 (`refine`), as `refine::refine_one` does one by one.
    fn refine(self, p: &mut [super::refine::Pending], range: (f32, f32));
    /// Trace eight coherent rays as one packet (lanes not in `active` are ignored), if this
    /// kernel can; false leaves them to be traced one by one.
    #[inline(always)]
    fn packet<L: Lanes>(
        self,
        _bvh: &Bvh8,
        _rays: &[Ray; WIDTH],
        _active: u32,
        _sinks: &mut L,
        _stack: &mut PacketStack,
    ) -> bool {
        false
    }
}

/// The traversal stack: node references with their entry distances (rounded down). Its height
/// lives in the traversal loop, in a register.
pub struct Stack {
    pub node: [MaybeUninit<u32>; STACK],
    pub dist: [MaybeUninit<f32>; STACK],
}

impl Default for Stack {
    fn default() -> Self {
        Self::new()
    }
}

impl Stack {
    #[inline(always)]
    pub fn new() -> Self {
        Self {
            node: [MaybeUninit::uninit(); STACK],
            dist: [MaybeUninit::uninit(); STACK],
        }
    }

    #[inline(always)]
    pub fn push(&mut self, sp: &mut usize, node: u32, dist: f32) {
        debug_assert!(*sp < STACK);
        // SAFETY: the builder bounds the tree's depth so the stack never exceeds STACK.
        unsafe {
            self.node.get_unchecked_mut(*sp).write(node);
            self.dist.get_unchecked_mut(*sp).write(dist);
        }
        *sp += 1;
    }

    /// The next entry whose box starts no farther than `t_far`, if any.
    #[inline(always)]
    pub(crate) fn pop(&self, sp: &mut usize, t_far: f32) -> Option<u32> {
        while *sp > 0 {
            *sp -= 1;
            // SAFETY: entries below `sp` were written by `push` or a kernel's `push_sorted` or
            // `push_any`.
            let (node, dist) = unsafe {
                (
                    self.node.get_unchecked(*sp).assume_init(),
                    self.dist.get_unchecked(*sp).assume_init(),
                )
            };
            if dist <= t_far {
                return Some(node);
            }
        }
        None
    }
}

/// Rays in a packet (`packet`).
pub const WIDTH: usize = 8;

/// What each ray of a packet collects: one [`Sink`] per lane.
pub trait Lanes {
    /// Lane `lane`'s current bound: hits at or beyond it are not wanted.
    fn t_far(&self, lane: usize) -> f32;
    /// Lane `lane`'s hits in a block; true when the lane needs no more (an any-hit query).
    fn take(&mut self, bvh: &Bvh8, lane: usize, block: usize, h: &Tri4Hit) -> bool;
}

impl<S: Sink> Lanes for [S; WIDTH] {
    #[inline(always)]
    fn t_far(&self, lane: usize) -> f32 {
        self[lane].t_far()
    }

    #[inline(always)]
    fn take(&mut self, bvh: &Bvh8, lane: usize, block: usize, h: &Tri4Hit) -> bool {
        self[lane].take(bvh, block, h)
    }
}

/// Whether `rays` (with directions `d`) can travel as one packet: their directions share an
/// octant (so they share each box's near and far planes), their origins lie within
/// `origin_extent` of each other on every axis, and their directions within about 14 degrees
/// (camera rays of neighbouring pixels do; shuffled or random rays do not, and go one by one).
#[inline(always)]
pub fn coherent(rays: &[Ray; WIDTH], d: &[Vec3A; WIDTH], origin_extent: f32) -> bool {
    // Octants first: rays in random order almost never share one, and then nothing else is
    // computed.
    let octant = rays[0].octant_shift;
    if rays.iter().any(|r| r.octant_shift != octant) {
        return false;
    }
    let (mut lo, mut hi) = (rays[0].o, rays[0].o);
    // Directions scaled to a largest component of 1: the spread of each component then
    // measures the angle between them, with no square root.
    let unit = |d: Vec3A| d / d.abs().max_element();
    let (mut dlo, mut dhi) = (unit(d[0]), unit(d[0]));
    for i in 1..WIDTH {
        (lo, hi) = (lo.min(rays[i].o), hi.max(rays[i].o));
        let u = unit(d[i]);
        (dlo, dhi) = (dlo.min(u), dhi.max(u));
    }
    (hi - lo).max_element() <= origin_extent && (dhi - dlo).max_element() <= 0.25
}

/// A packet's stack: node references with the lanes that entered them.
pub struct PacketStack {
    pub node: [MaybeUninit<u32>; STACK],
    pub lanes: [MaybeUninit<u32>; STACK],
}

impl Default for PacketStack {
    fn default() -> Self {
        Self::new()
    }
}

impl PacketStack {
    #[inline(always)]
    pub fn new() -> Self {
        Self {
            node: [MaybeUninit::uninit(); STACK],
            lanes: [MaybeUninit::uninit(); STACK],
        }
    }
}

/// Where hits go. `t_far` bounds the search (hits at or beyond it are not reported).
pub trait Sink {
    /// Whether children are visited strictly nearest first (closest hits), or in the builder's
    /// any-hit order (any hit, see [`Kernel::push_any`]).
    const ORDERED: bool = true;
    /// Whether runs of coherent rays may travel as packets (`Kernel::packet`).
    const PACKETS: bool = true;
    /// Whether rays may be traced in turns where the tree is large (`interleave`; only for
    /// `ORDERED` sinks, whose descent prefetches the children it enters).
    const INTERLEAVE: bool = false;
    fn t_far(&self) -> f32;
    /// Take block `block`'s hits; return true to stop the traversal.
    fn take(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit) -> bool;
    /// A block worth testing before the traversal starts (see [`Any::hint`]).
    #[inline(always)]
    fn hint(&self) -> Option<usize> {
        None
    }
}

/// Visit the tree along `ray`, giving every leaf block's hits to `sink`. `stack` is scratch
/// space, reused from ray to ray.
#[inline(always)]
pub fn traverse<K: Kernel, S: Sink>(k: K, bvh: &Bvh8, ray: &Ray, sink: &mut S, stack: &mut Stack) {
    let r = k.prepare(ray);
    if sink
        .hint()
        .is_some_and(|b| block_stops(k, bvh, b, &r, ray, sink))
    {
        return;
    }
    let (mut cur, mut sp) = (0u32, 0usize);
    while let Some(next) = visit(k, bvh, cur, &r, ray, sink, stack, &mut sp) {
        cur = next;
    }
}

/// One step of a traversal: visit node or leaf `cur` and return the next to visit (a child
/// entered, or the stack's top), or `None` when the traversal has ended (the sink wants no
/// more, or the stack is spent). `traverse` loops over it; `interleave` takes one step per turn.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn visit<K: Kernel, S: Sink>(
    k: K,
    bvh: &Bvh8,
    cur: u32,
    r: &K::R,
    ray: &Ray,
    sink: &mut S,
    stack: &mut Stack,
    sp: &mut usize,
) -> Option<u32> {
    if cur & LEAF == 0 {
        let n = node_at(&bvh.nodes, cur);
        let (mask, d) = k.node(n, r, sink.t_far());
        if mask != 0 {
            return Some(descend::<K, S>(k, bvh, n, mask, d, ray, stack, sp));
        }
    } else {
        for b in leaf_blocks(cur) {
            if block_stops(k, bvh, b, r, ray, sink) {
                return None;
            }
        }
    }
    stack.pop(sp, sink.t_far())
}

/// The child of `n` to visit next, of those in `mask` (not empty) that the ray enters, by the
/// order `S` asks for: the nearest, or the first in the any-hit order. The others are pushed
/// onto `stack` above `sp`, the last to visit first. Closest-hit rays also ask the cache for
/// every child entered (`prefetch_children`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn descend<K: Kernel, S: Sink>(
    k: K,
    bvh: &Bvh8,
    n: &Node8,
    mask: u32,
    d: K::D,
    ray: &Ray,
    stack: &mut Stack,
    sp: &mut usize,
) -> u32 {
    if S::ORDERED {
        prefetch_children(bvh, n, mask);
    }
    let first = mask.trailing_zeros();
    let rest = mask & (mask - 1);
    if rest == 0 {
        return n.child[first as usize];
    }
    if !S::ORDERED {
        if rest & (rest - 1) == 0 {
            // Two children: by a compare, as for closest hits (the vector push cost 3-9% more
            // on the occlusion rays of `bench rays`). A box around the start goes after one
            // that is not; otherwise the lower rank goes first.
            let second = rest.trailing_zeros();
            let (ca, cb) = (n.child[first as usize], n.child[second as usize]);
            let key = |lane: u32| {
                u32::from(k.dist(&d, lane) <= ray.t_min) << 3 | n.any_rank(lane as usize)
            };
            let (next, later) = if key(first) < key(second) {
                (ca, cb)
            } else {
                (cb, ca)
            };
            stack.push(sp, later, 0.0);
            return next;
        }
        return k.push_any(n, mask, d, ray.t_min, stack, sp);
    }
    if rest & (rest - 1) == 0 {
        // Two children: the nearer next, the other pushed. Both references are loaded before
        // the comparison, which then only selects.
        let second = rest.trailing_zeros();
        let (ca, cb) = (n.child[first as usize], n.child[second as usize]);
        let a = sort_key(k.dist(&d, first), first);
        let b = sort_key(k.dist(&d, second), second);
        let (near, far, far_key) = if a < b { (ca, cb, b) } else { (cb, ca, a) };
        stack.push(sp, far, key_dist(far_key));
        near
    } else {
        k.push_sorted(n, mask, d, stack, sp)
    }
}

/// Test block `b` and give its hits to `sink`; true when the sink wants no more.
#[inline(always)]
pub(crate) fn block_stops<K: Kernel, S: Sink>(
    k: K,
    bvh: &Bvh8,
    b: usize,
    r: &K::R,
    ray: &Ray,
    sink: &mut S,
) -> bool {
    debug_assert!(b < bvh.blocks.len());
    // SAFETY: leaf references index `blocks` (checked by the builder's tests), and hints are
    // blocks an earlier ray hit in this tree.
    let block = unsafe { bvh.blocks.get_unchecked(b) };
    let h = k.tri4(block, r, ray, sink.t_far());
    h.mask != 0 && sink.take(bvh, b, &h)
}

/// Ask the cache for what the children in `mask` will read: an inner child's four lines (boxes
/// and references), a leaf's first block. Embree's traversal prefetches its children the same
/// way. It pays where the tree outgrows the core's cache: a closest-hit ray pops most children
/// it pushes, and by then their lines are in (on the 1M-triangle spheres scene, shuffled and
/// incoherent rays ran 1.25–1.3× faster). Any-hit queries stop early and leave most pushed
/// children unread, so they do not prefetch.
#[inline(always)]
fn prefetch_children(bvh: &Bvh8, n: &Node8, mask: u32) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let nodes = bvh.nodes.as_ptr() as usize;
        let blocks = bvh.blocks.as_ptr() as usize;
        let mut m = mask;
        while m != 0 {
            let c = n.child[m.trailing_zeros() as usize];
            m &= m - 1;
            // Both addresses, then a select by mask arithmetic: a branch on inner or leaf
            // would be a coin toss for the predictor at every child.
            let inner = nodes.wrapping_add(node_offset(c));
            let leaf = blocks.wrapping_add(leaf_first(c) * size_of::<Tri4>());
            let is_leaf = ((c >> 31) as usize).wrapping_neg();
            let p = (inner ^ ((inner ^ leaf) & is_leaf)) as *const i8;
            for l in 0..4 {
                // SAFETY: a prefetch is only a hint: it never faults, whatever the address.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64 * l)) };
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (bvh, n, mask);
}

/// A hit in a leaf block: block, lane, triangle, `t` and the barycentrics' numerators and
/// denominator (divided only when reported).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlockHit {
    pub block: u32,
    pub lane: u32,
    pub triangle: u32,
    pub t: f32,
    pub bu: f32,
    pub bv: f32,
    pub det: f32,
}

impl BlockHit {
    #[inline(always)]
    pub fn of(bvh: &Bvh8, block: usize, lane: usize, h: &Tri4Hit) -> Self {
        Self {
            block: block as u32,
            lane: lane as u32,
            triangle: bvh.blocks[block].id[lane],
            t: h.t[lane],
            bu: h.bu[lane],
            bv: h.bv[lane],
            det: h.det[lane],
        }
    }

    /// Barycentric (u, v) in f32, from the watertight test.
    #[inline(always)]
    pub fn bary(&self) -> [f32; 2] {
        [self.bu / self.det, self.bv / self.det]
    }

    /// Whether this hit comes first: nearer, or as near with a smaller triangle index. The
    /// order does not depend on how the tree was traversed, so packets, single rays and any
    /// thread count report the same triangle where two meet the ray at the same `t` (at a
    /// shared edge, or on duplicated faces).
    #[inline(always)]
    pub fn before(&self, other: &BlockHit) -> bool {
        self.t < other.t || (self.t == other.t && self.triangle < other.triangle)
    }
}

/// The smallest float above `t >= 0`: a bound that still lets hits at exactly `t` through a
/// strict `< t_far` test, for the tie-break of [`BlockHit::before`].
#[inline(always)]
pub fn above(t: f32) -> f32 {
    f32::from_bits(if t == 0.0 { 1 } else { t.to_bits() + 1 })
}

/// Closest-hit sink.
#[derive(Clone, Copy)]
pub struct Closest {
    pub t_far: f32,
    pub best: Option<BlockHit>,
}

impl Closest {
    #[inline(always)]
    pub fn new(t_far: f32) -> Self {
        Self { t_far, best: None }
    }
}

impl Sink for Closest {
    /// On trees larger than the core's cache, several closest-hit rays in turns hide the wait
    /// for each one's nodes (`INTERLEAVE_BYTES` has the figures).
    const INTERLEAVE: bool = true;

    #[inline(always)]
    fn t_far(&self) -> f32 {
        self.t_far
    }

    #[inline(always)]
    fn take(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit) -> bool {
        let mut m = h.mask;
        while m != 0 {
            let lane = m.trailing_zeros() as usize;
            m &= m - 1;
            let hit = BlockHit::of(bvh, block, lane, h);
            if self.best.is_none_or(|b| hit.before(&b)) {
                self.best = Some(hit);
                self.t_far = above(hit.t);
            }
        }
        false
    }
}

/// Closest-hit sink that meets only the triangles whose bit is set in `keep` (bit `i % 64` of
/// word `i / 64` for triangle `i`); the traversal passes through the others.
#[derive(Clone, Copy)]
pub struct ClosestKept<'a> {
    pub closest: Closest,
    pub keep: &'a [u64],
}

impl Sink for ClosestKept<'_> {
    const INTERLEAVE: bool = true;

    #[inline(always)]
    fn t_far(&self) -> f32 {
        self.closest.t_far
    }

    #[inline(always)]
    fn take(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit) -> bool {
        let mut kept = *h;
        let mut m = h.mask;
        while m != 0 {
            let lane = m.trailing_zeros() as usize;
            m &= m - 1;
            let id = bvh.blocks[block].id[lane] as usize;
            if self.keep[id / 64] >> (id % 64) & 1 == 0 {
                kept.mask &= !(1 << lane);
            }
        }
        self.closest.take(bvh, block, &kept)
    }
}

/// Any-hit sink: stops at the first hit.
#[derive(Clone, Copy)]
pub struct Any {
    pub t_far: f32,
    /// The block that stopped the traversal, if any.
    pub hit: Option<u32>,
    /// A block to test first: the one that stopped the previous ray (none when nothing did).
    /// Shadow rays from neighbouring points (in image order) are mostly blocked by the same
    /// occluder, and one block test then replaces a traversal (Haines and Greenberg's shadow
    /// cache, "The Light Buffer", 1986). Whatever it finds is a hit in range, so the answer does
    /// not change. After a ray that nothing blocked, the next is likely unblocked too, and the
    /// test is skipped (the cache is emptied): with one thread on the occlusion rays of
    /// `bench rays`, 1.06x on the procedural shapes, whose tests mostly missed; 0.97-1.02x on
    /// the real scenes.
    pub hint: Option<u32>,
}

impl Sink for Any {
    const ORDERED: bool = false;
    /// One by one, so that each ray tries its hint first: on shadow rays in image order that
    /// beat packets on the four scenes measured (e.g. 0.83× → 0.89× Embree's speed on
    /// `khr_toy_car`, 0.94× → 1.05× on the procedural shapes). Not in turns either
    /// (`interleave`): shadow rays in image order find their nodes in the cache, and the turns
    /// only cost (one thread, 786K occlusion rays: 0.77x on `khr_metal_rough_spheres_notex`,
    /// whose tree is 60 MB; 0.78x on `khr_toy_car`).
    const PACKETS: bool = false;

    #[inline(always)]
    fn t_far(&self) -> f32 {
        self.t_far
    }

    #[inline(always)]
    fn take(&mut self, _: &Bvh8, block: usize, _: &Tri4Hit) -> bool {
        self.hit = Some(block as u32);
        true
    }

    #[inline(always)]
    fn hint(&self) -> Option<usize> {
        self.hint.map(|b| b as usize)
    }
}

pub mod portable {
    //! The reference kernel: plain f32 arithmetic (SSE2 or NEON through the compiler), the
    //! scalar watertight test lane by lane.

    use super::*;
    use crate::trace::watertight;

    #[derive(Clone, Copy, Debug, Default)]
    pub struct Portable;

    impl Kernel for Portable {
        type R = Ray;
        type D = [f32; 8];

        #[inline(always)]
        fn prepare(self, r: &Ray) -> Ray {
            *r
        }

        #[inline(always)]
        fn node(self, n: &Node8, r: &Ray, t_far: f32) -> (u32, [f32; 8]) {
            node_ray(n, r, t_far)
        }

        #[inline(always)]
        fn dist(self, d: &[f32; 8], lane: u32) -> f32 {
            d[lane as usize]
        }

        fn push_any(
            self,
            n: &Node8,
            mask: u32,
            d: [f32; 8],
            t_min: f32,
            s: &mut Stack,
            sp: &mut usize,
        ) -> u32 {
            // Each group last rank first, so that it is popped in rank order.
            let last_first = || {
                (0..8)
                    .rev()
                    .map(|r| n.any_slot(r))
                    .filter(|k| mask >> k & 1 == 1)
            };
            for k in last_first().filter(|&k| d[k] <= t_min) {
                s.push(sp, n.child[k], 0.0);
            }
            for k in last_first().filter(|&k| d[k] > t_min) {
                s.push(sp, n.child[k], 0.0);
            }
            *sp -= 1;
            // SAFETY: pushed just above (`mask` has at least two children).
            unsafe { s.node.get_unchecked(*sp).assume_init() }
        }

        fn push_sorted(
            self,
            n: &Node8,
            mask: u32,
            d: [f32; 8],
            s: &mut Stack,
            sp: &mut usize,
        ) -> u32 {
            let mut keys = [0u32; 8];
            let mut count = 0;
            let mut m = mask;
            while m != 0 {
                let i = m.trailing_zeros();
                keys[count] = sort_key(d[i as usize], i);
                count += 1;
                m &= m - 1;
            }
            // Descending, as the AVX2 sorting network leaves them.
            keys[..count].sort_unstable_by(|a, b| b.cmp(a));
            for &key in &keys[..count - 1] {
                s.push(sp, n.child[(key & 7) as usize], key_dist(key));
            }
            n.child[(keys[count - 1] & 7) as usize]
        }

        #[inline(always)]
        fn tri4(self, b: &Tri4, _: &Ray, ray: &Ray, t_far: f32) -> Tri4Hit {
            tri4_scalar(b, ray, t_far)
        }

        #[inline(always)]
        fn refine(self, p: &mut [crate::trace::refine::Pending], range: (f32, f32)) {
            for q in p {
                crate::trace::refine::refine_one(q, range);
            }
        }
    }

    /// The portable node test.
    #[inline(always)]
    pub fn node_ray(n: &Node8, r: &Ray, t_far: f32) -> (u32, [f32; 8]) {
        let mut mask = 0;
        let mut t_in = [0.0; 8];
        #[allow(clippy::needless_range_loop)] // `i` indexes the node's rows as well
        for i in 0..8 {
            let slab = |a: usize| {
                (
                    (n.b[r.near[a] / ROW_BYTES][i] - r.o[a]) * r.inv[a],
                    (n.b[r.far[a] / ROW_BYTES][i] - r.o[a]) * r.inv_far[a],
                )
            };
            let ((x0, x1), (y0, y1), (z0, z1)) = (slab(0), slab(1), slab(2));
            // Pairwise, as the AVX2 kernel reduces (two steps of latency, not three).
            let near = max(max(x0, y0), max(z0, r.t_min));
            let far = min(min(x1, y1), min(z1, t_far));
            t_in[i] = near;
            mask |= u32::from(near <= far) << i;
        }
        (mask, t_in)
    }

    /// `_mm256_max_ps`'s rule (the second operand on ties), so both kernels agree bit for bit.
    #[inline(always)]
    fn max(a: f32, b: f32) -> f32 {
        if a > b {
            a
        } else {
            b
        }
    }

    #[inline(always)]
    fn min(a: f32, b: f32) -> f32 {
        if a < b {
            a
        } else {
            b
        }
    }

    /// The scalar watertight test of each lane; AVX2 falls back to it too.
    #[inline(always)]
    pub fn tri4_scalar(b: &Tri4, ray: &Ray, t_far: f32) -> Tri4Hit {
        let mut h = Tri4Hit::NONE;
        for lane in 0..4 {
            if let Some(hit) =
                watertight::intersect(&b.tri(lane), ray.o, &ray.shear, ray.t_min, t_far)
            {
                h.mask |= 1 << lane;
                h.t[lane] = hit.t;
                [h.bu[lane], h.bv[lane]] = hit.b;
                h.det[lane] = hit.det;
            }
        }
        h
    }
}

/// A child's sort key: its entry distance's bits with the sign cleared (distances are never
/// negative, but may be −0) and the low three bits replaced by its slot. Keys order like the
/// distances, up to those three bits.
#[inline(always)]
pub fn sort_key(dist: f32, slot: u32) -> u32 {
    (dist.to_bits() & 0x7FFF_FFF8) | slot
}

/// The distance kept on the stack for a key: rounded down, so it never culls a box it should
/// enter.
#[inline(always)]
pub fn key_dist(key: u32) -> f32 {
    f32::from_bits(key & 0x7FFF_FFF8)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The octant orders as a stable sort of (key, slot) gives them, the definition
    /// `Node8::set_order` must keep.
    fn sorted_orders(n: &Node8) -> [u32; 8] {
        let mut order = [0u32; 8];
        for o in 0..8u32 {
            let sign = [0, 1, 2].map(|a| if o >> a & 1 == 1 { -1.0f32 } else { 1.0 });
            let mut slots: Vec<(f32, u32)> = (0..8)
                .map(|k| {
                    let key = if n.child[k] == EMPTY {
                        f32::INFINITY
                    } else {
                        (0..3).map(|a| (n.b[a][k] + n.b[a + 3][k]) * sign[a]).sum()
                    };
                    (key, k as u32)
                })
                .collect();
            slots.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            for (rank, &(_, k)) in slots.iter().enumerate() {
                order[rank] |= k << (3 * o);
            }
        }
        order
    }

    #[test]
    fn the_network_sorts_every_input_of_zeros_and_ones() {
        // The 0-1 principle: a network that sorts all 256 such inputs sorts every input.
        for m in 0..256u32 {
            let mut x: [i64; 8] = std::array::from_fn(|k| i64::from(m >> k & 1));
            sort8(&mut x);
            assert!(x.windows(2).all(|w| w[0] <= w[1]), "{m:08b}");
        }
    }

    #[test]
    fn octant_orders_rank_slots_as_a_sort_does() {
        let mut s = 12345u64;
        let mut r = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 33) as u32
        };
        // Ties, signed zeros and empty slots are where ranks and sorts could part.
        let values = [0.0f32, -0.0, 1.0, -1.0, 0.5, 2.0, 1e-30, -3.25];
        for _ in 0..5000 {
            let mut n = Node8::EMPTY;
            for k in 0..8 {
                if r() % 4 != 0 {
                    n.child[k] = k as u32;
                    for a in 0..3 {
                        let (lo, hi) = (values[r() as usize % 8], values[r() as usize % 8]);
                        (n.b[a][k], n.b[a + 3][k]) = (lo.min(hi), lo.max(hi));
                    }
                }
            }
            n.order = [0xAB << ANY_SHIFT; 8];
            let want = sorted_orders(&n);
            n.set_order();
            for (got, want) in n.order.iter().zip(want) {
                assert_eq!(got & ((1 << ANY_SHIFT) - 1), want);
                assert_eq!(got >> ANY_SHIFT, 0xAB, "the any-hit order is kept");
            }
        }
    }
}
