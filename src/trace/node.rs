//! The 8-wide BVH's layout: nodes of eight children's boxes, leaves of four-triangle blocks,
//! and the references between them.
//!
//! Each node holds its eight children's boxes as six arrays of eight floats (the single-ray
//! layout of Fuetterling et al., "Accelerated Single Ray Tracing for Wide Vector Units", HPG
//! 2017), so one AVX2 slab test covers all eight; leaves are runs of [`Tri4`] blocks, four
//! triangles stored lane by lane, tested together by the watertight test (`watertight`).
//! `traverse` walks the tree; `build` and `refit` make it.

use std::ops::Range;

use std::sync::Arc;

use glam::{DAffine3, DMat4, Mat3A, Vec3A};

use super::watertight::Tri;
use crate::scene::pose::transform_point;

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
pub(crate) fn node_offset(r: u32) -> usize {
    (r as usize) << 5
}

/// The first block of the leaf a leaf reference names.
#[inline(always)]
pub(crate) fn leaf_first(r: u32) -> usize {
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
    /// For a two-level tree (`instances`): `nodes` is the top tree over the instances, whose
    /// leaf references name runs of `Instanced::refs`, and `blocks` is empty. `None` for a
    /// flat tree.
    pub inst: Option<Box<Instanced>>,
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

    /// Put a tree's nodes and blocks on huge pages where the kernel grants them
    /// (`limits::collapse_to_huge_pages`, in place): rays visit nodes and blocks all over a
    /// tree of hundreds of megabytes, and with 4 KiB pages most visits also miss the TLB
    /// (262,144 incoherent rays on 100 tiles, interleaved runs: `stanford_bunny`, 375 MB, best
    /// 0.0438 -> 0.0415 s and median 0.0528 -> 0.0433 s; `balloon` best 0.0321 -> 0.0311 s;
    /// the build's time unchanged within noise).
    pub fn move_to_huge_pages(&self) {
        crate::limits::collapse_to_huge_pages(&self.nodes);
        crate::limits::collapse_to_huge_pages(&self.blocks);
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

    /// The tree's surface areas in world units, summed in three parts: the inner nodes' boxes
    /// (the root's included), the leaves' boxes each times its blocks, and each triangle's own
    /// box (`triangles`, given: the refit sums them while it gathers the corners). How the three grow when the corners move says where a refit tree lost its tightness:
    /// leaves that grew more than their triangles hold triangles that moved apart, inner nodes
    /// that grew more than the leaves group leaves that moved apart.
    pub fn area_parts(&self, triangles: f64) -> [f64; 3] {
        let (lo, hi) = self.nodes[0].bounds();
        let e: [f64; 3] = std::array::from_fn(|a| (hi[a] - lo[a]).max(0.0) as f64);
        let mut inner = 2.0 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0]);
        let mut leaves = 0.0;
        for n in self.nodes.iter() {
            for k in 0..8 {
                let c = n.child[k];
                if c == EMPTY {
                    continue;
                } else if c & LEAF != 0 {
                    leaves += n.child_area(k) * leaf_blocks(c).len() as f64;
                } else {
                    inner += n.child_area(k);
                }
            }
        }
        [inner, leaves, triangles]
    }

    /// Bytes held by the tree (nodes and blocks; for a two-level tree, its objects' trees and
    /// instances too).
    pub fn bytes(&self) -> usize {
        let own = self.nodes.len() * size_of::<Node8>() + self.blocks.len() * size_of::<Tri4>();
        own + self.inst.as_ref().map_or(0, |i| {
            i.objects.bytes()
                + i.refs.len() * size_of::<InstRef>()
                + i.instances.len() * size_of::<Instance>()
        })
    }
}

/// What a top tree's leaf names: a subtree of an object's tree (`node`: an inner node's or a
/// leaf's reference in [`Instanced::objects`]) seen through instance `inst`.
#[derive(Clone, Copy, Debug)]
pub struct InstRef {
    pub node: u32,
    pub inst: u32,
}

/// An object placed in the world, as its rays see it: the inverse of its transform (world to
/// object) in f64, and its linear part rounded to f32; the object's world box. (The transform
/// itself, which only reported hits need, is kept apart in `Instanced::to_world`.)
#[derive(Clone, Copy, Debug)]
pub struct Instance {
    pub to_object: DAffine3,
    pub linear: Mat3A,
    pub lo: Vec3A,
    pub hi: Vec3A,
}

/// The instance level of a two-level tree: the objects' trees, and what the top tree's leaves
/// name. A [`Bvh8`] whose `inst` is set holds the top tree in its `nodes` (and no blocks); its
/// leaf references name runs of [`Instanced::refs`].
#[derive(Debug)]
pub struct Instanced {
    pub objects: Arc<Bvh8>,
    pub refs: Vec<InstRef>,
    pub instances: Vec<Instance>,
    /// Each instance's transform, object to world, as the pose gave it.
    pub to_world: Vec<DMat4>,
    /// Triangles in the objects' trees.
    pub triangles: usize,
}

impl Instanced {
    /// The world corners of lane `lane` of block `block` of the objects' tree, seen through
    /// instance `inst`.
    #[inline(always)]
    pub fn world_corners(&self, block: u32, lane: u32, inst: u32) -> [[f32; 3]; 3] {
        let c = self.objects.blocks[block as usize].corners(lane as usize);
        let m = &self.to_world[inst as usize];
        c.map(|p| transform_point(m, p))
    }
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
