//! Where a traversal's hits go: the closest hit (with or without a mask of the triangles
//! kept) and any hit. The front-face, k-nearest and crossing sinks live with their queries.

use super::node::Bvh8;
use super::traverse::{Sink, Tri4Hit};

/// No instance: a hit in a flat tree, whose blocks hold world corners.
pub const WORLD: u32 = u32::MAX;

/// A hit in a leaf block: block, lane, the instance it was found through (`WORLD` in a flat
/// tree), triangle, `t` and the barycentrics' numerators and denominator (divided only when
/// reported).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlockHit {
    pub block: u32,
    pub lane: u32,
    pub inst: u32,
    pub triangle: u32,
    pub t: f32,
    pub bu: f32,
    pub bv: f32,
    pub det: f32,
}

impl BlockHit {
    #[inline(always)]
    pub fn of(bvh: &Bvh8, block: usize, lane: usize, h: &Tri4Hit, inst: u32) -> Self {
        Self {
            block: block as u32,
            lane: lane as u32,
            inst,
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
        self.take_in(bvh, block, h, WORLD)
    }

    #[inline(always)]
    fn take_in(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit, inst: u32) -> bool {
        let mut m = h.mask;
        while m != 0 {
            let lane = m.trailing_zeros() as usize;
            m &= m - 1;
            let hit = BlockHit::of(bvh, block, lane, h, inst);
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
        self.take_in(bvh, block, h, WORLD)
    }

    #[inline(always)]
    fn take_in(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit, inst: u32) -> bool {
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
        self.closest.take_in(bvh, block, &kept, inst)
    }
}

/// Any-hit sink: stops at the first hit, visiting children nearest first (`NEAREST`, as closest
/// hits do) or in the builder's any-hit order (`Kernel::push_any`: the children likeliest to
/// stop a ray for their cost first, the boxes around the ray's start last). Neither order wins
/// everywhere (`api::occluded` has the figures; `jobs::any_plan` picks one per call).
///
/// One ray at a time, never as packets, but in turns where the tree is large (`interleave`):
/// one thread, 400K occlusion segments between random points of 2M-triangle tilings of
/// `stanford_bunny` and `intel_sponza_ivy`, 2.0-2.2x.
#[derive(Clone, Copy)]
pub struct AnyHit<const NEAREST: bool> {
    pub t_far: f32,
    /// The block that stopped the traversal, if any.
    pub hit: Option<u32>,
    /// A block to test first: the one that stopped the previous ray (Haines and Greenberg's
    /// shadow cache, "The Light Buffer", 1986). Shadow rays from neighbouring points (in image
    /// order) are mostly blocked by the same occluder, and one block test then replaces a
    /// traversal. Whatever it finds is a hit in range, so the answer does not change.
    pub hint: Option<u32>,
}

impl<const NEAREST: bool> AnyHit<NEAREST> {
    #[inline(always)]
    pub fn new(t_far: f32, hint: Option<u32>) -> Self {
        Self {
            t_far,
            hit: None,
            hint,
        }
    }
}

impl<const NEAREST: bool> Sink for AnyHit<NEAREST> {
    const ORDERED: bool = NEAREST;
    const PREFETCH: bool = true;
    const PACKETS: bool = NEAREST;
    const INTERLEAVE: bool = true;

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
    fn done(&self) -> bool {
        self.hit.is_some()
    }

    #[inline(always)]
    fn hint(&self) -> Option<usize> {
        self.hint.map(|b| b as usize)
    }
}

/// A sink that counts the nodes and blocks its traversal visits, for a probe that compares
/// traversal orders by the work they cost (the same work on every kernel and thread count).
#[derive(Clone, Copy)]
pub struct Counted<S> {
    pub sink: S,
    pub nodes: u32,
    pub blocks: u32,
}

impl<S> Counted<S> {
    pub fn new(sink: S) -> Self {
        Self {
            sink,
            nodes: 0,
            blocks: 0,
        }
    }
}

impl<S: Sink> Sink for Counted<S> {
    const ORDERED: bool = S::ORDERED;
    const PREFETCH: bool = S::PREFETCH;
    const PACKETS: bool = false;
    const INTERLEAVE: bool = false;

    #[inline(always)]
    fn t_far(&self) -> f32 {
        self.sink.t_far()
    }

    #[inline(always)]
    fn take(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit) -> bool {
        self.sink.take(bvh, block, h)
    }

    #[inline(always)]
    fn take_in(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit, inst: u32) -> bool {
        self.sink.take_in(bvh, block, h, inst)
    }

    #[inline(always)]
    fn hint(&self) -> Option<usize> {
        self.sink.hint()
    }

    #[inline(always)]
    fn count(&mut self, nodes: u32, blocks: u32) {
        self.nodes += nodes;
        self.blocks += blocks;
    }
}
