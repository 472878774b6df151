//! The query jobs: what each kind of query does with a chunk of rays (`dispatch::Job`), over
//! the shared ray loop of `rays`. Closest hits (all triangles, or those kept), any hit, the k
//! nearest hits, every hit, and how many hits.

use std::mem::MaybeUninit;

use glam::Vec3;

use super::dispatch::{dispatch, Job};
use super::node::Bvh8;
use super::rays::{Hit, Rays, Scratch, Traced};
use super::refine::Pending;
use super::schedule::{FreshHits, HitSlices};
use super::sinks::{AnyHit, BlockHit, Closest, ClosestKept, Counted, WORLD};
use super::traverse::{
    block_stops, coherent, traverse, Kernel, PacketStack, Sink, Stack, Tri4Hit, WIDEN, WIDTH,
};
use crate::types::SAME_HIT;

/// Mark every entry of a chunk "no hit" (`t` +inf, triangle −1, barycentrics 0), before the
/// hits are written. The result arrays are allocated zeroed (`api::RayHits::zeroed`), which the
/// system does lazily, and each chunk's thread fills its own part here: filled up front, by the
/// calling thread, 786K rays' 12.6 MB took 4-5 ms of page faults and stores that no other core
/// could share (on `intel_sponza_ivy`'s primary rays, 15% of the trace on two cores).
#[inline(always)]
fn no_hits<'o>((t, tri, bary): FreshHits<'o>) -> HitSlices<'o> {
    /// Write `v` into every entry of `s` and give `s` back as written.
    fn fill<T: Copy>(s: &mut [MaybeUninit<T>], v: T) -> &mut [T] {
        for x in s.iter_mut() {
            x.write(v);
        }
        // SAFETY: every entry was just written; `MaybeUninit<T>` has `T`'s layout.
        unsafe { &mut *(s as *mut [MaybeUninit<T>] as *mut [T]) }
    }
    (fill(t, f32::INFINITY), fill(tri, -1), fill(bary, [0.0; 2]))
}

/// A closest-hit sink: what it kept.
/// Closest-hit sink that meets only the triangles whose counter-clockwise front faces the ray
/// (direction `d`, as given): the traversal passes through back faces, as a rasteriser that
/// culls them skips them (views with `cull_backfaces`). A plain sink per ray, so coherent rays
/// travel as packets; before it, culled views took the k-nearest path ray by ray.
#[derive(Clone, Copy)]
pub(crate) struct ClosestFront<'a> {
    pub closest: Closest,
    pub rays: &'a Rays<'a>,
    pub d: Vec3,
}

impl Sink for ClosestFront<'_> {
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
        let mut front = *h;
        let mut m = h.mask;
        while m != 0 {
            let lane = m.trailing_zeros() as usize;
            m &= m - 1;
            let [a, b, c] = self
                .rays
                .corners(&BlockHit::of(bvh, block, lane, h, inst))
                .map(Vec3::from);
            if (b - a).cross(c - a).dot(self.d) >= 0.0 {
                front.mask &= !(1 << lane);
            }
        }
        self.closest.take_in(bvh, block, &front, inst)
    }
}

pub(crate) trait Best: Sink + Copy + Sync {
    fn best(&self) -> Option<BlockHit>;
    /// The sink for ray `i` of `rays`, from the job's prototype.
    #[inline(always)]
    fn for_ray(self, rays: &Rays, i: usize) -> Self {
        let _ = (rays, i);
        self
    }
}

impl Best for Closest {
    #[inline(always)]
    fn best(&self) -> Option<BlockHit> {
        self.best
    }
}

impl Best for ClosestKept<'_> {
    #[inline(always)]
    fn best(&self) -> Option<BlockHit> {
        self.closest.best
    }
}

impl Best for ClosestFront<'_> {
    #[inline(always)]
    fn best(&self) -> Option<BlockHit> {
        self.closest.best
    }

    #[inline(always)]
    fn for_ray(self, rays: &Rays, i: usize) -> Self {
        Self {
            d: Vec3::from(rays.input(i).1),
            ..self
        }
    }
}

/// Closest hits, each ray's sink a copy of the prototype `.1`.
pub(crate) struct ClosestJob<'a, S>(pub &'a Rays<'a>, pub S);

impl<'a> ClosestJob<'a, Closest> {
    pub fn new(rays: &'a Rays<'a>) -> Self {
        ClosestJob(rays, Closest::new(rays.range.1))
    }
}

impl<S: Best> Job for ClosestJob<'_, S> {
    type Out<'o> = FreshHits<'o>;

    #[inline(always)]
    fn chunk<K: Kernel>(&self, k: K, base: usize, fresh: FreshHits<'_>) {
        // Two passes per batch: traversal records each closest hit in f32; the f64 refinement
        // then runs over the batch's hits, free of the traversal's long dependency chains (the
        // processor overlaps one hit's refinement with the next's; inline it took as long as
        // the traversal of a primary ray).
        const BATCH: usize = 256;
        let (t, tri, bary) = no_hits(fresh);
        let mut scratch = Scratch::new();
        let mut found = [0u32; BATCH];
        let mut pending = [Pending::default(); BATCH];
        let mut shifts = [0.0f32; BATCH];
        let mut hit = [None; BATCH];
        for start in (0..t.len()).step_by(BATCH) {
            let end = (start + BATCH).min(t.len());
            let mut hits = 0;
            let rays = self.0;
            rays.trace(
                k,
                base,
                start..end,
                &mut scratch,
                #[inline(always)]
                |j| self.1.for_ray(rays, base + j),
                // Inlined, so compiled with the kernel's instructions: a closure does not
                // inherit its caller's target features, and a call from AVX2 code into this
                // one, for every ray, spilled the traversal's registers around it.
                #[inline(always)]
                |j, sink| {
                    if let Some(h) = sink.best() {
                        tri[j] = h.triangle as i32;
                        found[hits] = j as u32;
                        (pending[hits], shifts[hits]) = rays.pending(base + j, &h);
                        hit[hits] = Some(h);
                        hits += 1;
                    }
                },
            );
            k.refine(&mut pending[..hits], rays.refine_range());
            for i in 0..hits {
                let h = hit[i].expect("a hit was kept");
                let j = found[i] as usize;
                (t[j], bary[j]) = rays.settle(&pending[i], shifts[i], &h);
            }
        }
    }
}

pub(crate) struct AnyJob<'a, const NEAREST: bool, const HINT: bool>(pub &'a Rays<'a>);

impl<const NEAREST: bool, const HINT: bool> Job for AnyJob<'_, NEAREST, HINT> {
    type Out<'o> = &'o mut [bool];

    #[inline(always)]
    fn chunk<K: Kernel>(&self, k: K, base: usize, out: &mut [bool]) {
        let mut scratch = Scratch::new();
        // The block that stopped the last ray done (`AnyHit::hint`); none after a ray that
        // nothing stopped, whose neighbour is likely unblocked too.
        let last = std::cell::Cell::new(None);
        self.0.trace(
            k,
            base,
            0..out.len(),
            &mut scratch,
            #[inline(always)]
            |_| AnyHit::<NEAREST>::new(self.0.range.1, if HINT { last.get() } else { None }),
            #[inline(always)]
            |j, sink| {
                out[j] = sink.hit.is_some();
                if HINT {
                    last.set(sink.hit);
                }
            },
        );
    }
}

/// How an any-hit query traces its rays: which order, and whether each ray first tries the
/// block that stopped the one before (`AnyHit::hint`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct AnyPlan {
    pub nearest: bool,
    pub hint: bool,
}

/// Rays of a probe ([`any_plan`]): this many, in [`PROBE_RUNS`] runs of neighbouring rays
/// spread evenly over the batch.
const PROBE_RAYS: usize = 256;
const PROBE_RUNS: usize = 8;

/// How an any-hit query over `n` rays should go, from a probe of [`PROBE_RAYS`] of them: nearest
/// first when that visits no more nodes and blocks than the builder's any-hit order, and with
/// hints when at least 15% of the rays after a blocked neighbour are stopped by its block. Counts,
/// not times: the same plan on every machine, kernel and thread count, and the answers do not
/// depend on it. Batches of fewer than `4 * PROBE_RAYS` rays take the any-hit order with hints.
pub(crate) fn any_plan(rays: &Rays, n: usize) -> AnyPlan {
    if n < 4 * PROBE_RAYS {
        return AnyPlan {
            nearest: false,
            hint: true,
        };
    }
    let mut p = Probe::default();
    dispatch(&ProbeJob(rays, n), 0, &mut p);
    plan_of(&p)
}

/// The plan a probe's counts call for (see [`any_plan`]).
pub(crate) fn plan_of(p: &Probe) -> AnyPlan {
    AnyPlan {
        nearest: p.work[0] <= p.work[1],
        hint: 20 * p.hinted[0] >= 3 * p.hinted[1] && p.hinted[1] > 0,
    }
}

/// What [`any_plan`]'s probe found: nodes plus blocks visited nearest first and in the any-hit
/// order, and how many rays after a blocked neighbour its block stopped, of how many.
#[derive(Default)]
pub(crate) struct Probe {
    work: [u64; 2],
    hinted: [u64; 2],
}

pub(crate) struct ProbeJob<'a>(pub &'a Rays<'a>, pub usize);

impl Job for ProbeJob<'_> {
    type Out<'o> = &'o mut Probe;

    #[inline(always)]
    fn chunk<K: Kernel>(&self, k: K, _: usize, p: &mut Probe) {
        let (rays, n) = (self.0, self.1);
        let run = PROBE_RAYS / PROBE_RUNS;
        let mut stack = Stack::new();
        for r in 0..PROBE_RUNS {
            let first = r * n / PROBE_RUNS;
            let mut previous = None;
            for j in first..first + run {
                let (ray, _) = rays.traversal_ray(j);
                let t_far = rays.range.1;
                let mut near = Counted::new(AnyHit::<true>::new(t_far, None));
                traverse(k, rays.bvh, &ray, &mut near, &mut stack);
                let mut any = Counted::new(AnyHit::<false>::new(t_far, None));
                traverse(k, rays.bvh, &ray, &mut any, &mut stack);
                p.work[0] += u64::from(near.nodes + near.blocks);
                p.work[1] += u64::from(any.nodes + any.blocks);
                if let Some(b) = previous.filter(|_| rays.bvh.inst.is_none()) {
                    let mut tried = AnyHit::<false>::new(t_far, None);
                    p.hinted[0] +=
                        u64::from(block_stops(k, rays.bvh, b as usize, &ray, &ray, &mut tried));
                    p.hinted[1] += 1;
                }
                previous = any.sink.hit;
            }
        }
    }
}

/// The rays, the hits wanted per ray, and whether back faces are skipped.
pub(crate) struct NearestJob<'a>(pub &'a Rays<'a>, pub usize, pub bool);

impl Job for NearestJob<'_> {
    type Out<'o> = FreshHits<'o>;

    #[inline(always)]
    fn chunk<K: Kernel>(&self, k: K, base: usize, fresh: FreshHits<'_>) {
        let (rays, want) = (self.0, self.1);
        let (t, tri, bary) = no_hits(fresh);
        let n = t.len() / want;
        // Memory for the hits found, not for `want` (which may be far larger).
        let mut found: [Vec<Hit>; WIDTH] =
            std::array::from_fn(|_| Vec::with_capacity(want.min(64) + 1));
        let mut stack = Stack::new();
        let mut packet = PacketStack::new();
        // A packet's rays, set up in place by plain loops (see `Rays::trace`).
        let none = rays.ray(base);
        let mut traced = [none; WIDTH];
        let mut lanes = [none.ray; WIDTH];
        let mut dirs = [none.d; WIDTH];
        let mut j = 0;
        while j < n {
            // Runs of eight coherent rays (a camera's pixels: peeling) as packets; a ray's
            // surfaces do not depend on the order its hits arrive in (`Nearest`).
            let mut done = 1;
            if K::PACKETS && j + WIDTH <= n {
                for i in 0..WIDTH {
                    traced[i] = rays.ray(base + j + i);
                    (lanes[i], dirs[i]) = (traced[i].ray, traced[i].d);
                }
                if coherent(&lanes, &dirs, rays.origin_extent) {
                    let mut sinks = {
                        let (mut f, mut r) = (found.iter_mut(), traced.iter());
                        std::array::from_fn(|i| {
                            let (found, r) = (f.next().expect("a lane"), r.next().expect("a lane"));
                            found.clear();
                            Nearest::new(rays, base + j + i, r, want, self.2, found)
                        })
                    };
                    k.packet(rays.bvh, &lanes, (1 << WIDTH) - 1, &mut sinks, &mut packet);
                    sinks.into_iter().for_each(Nearest::finish);
                    done = WIDTH;
                }
            }
            if done == 1 {
                nearest(k, rays, base + j, want, self.2, &mut found[0], &mut stack);
            }
            for (i, found) in found[..done].iter().enumerate() {
                let at = (j + i) * want;
                for (m, h) in found.iter().enumerate() {
                    t[at + m] = h.t;
                    tri[at + m] = h.triangle as i32;
                    bary[at + m] = h.bary;
                }
            }
            j += done;
        }
    }
}

/// Every distinct hit of each ray of a chunk (the k-nearest sink without a k): how many per
/// ray, appended to the first vector, and the hits, nearest first, to the second.
pub(crate) struct AllJob<'a>(pub &'a Rays<'a>, pub usize);

impl Job for AllJob<'_> {
    type Out<'o> = (&'o mut Vec<u32>, &'o mut Vec<Hit>);

    #[inline(always)]
    fn chunk<K: Kernel>(&self, k: K, base: usize, (counts, hits): Self::Out<'_>) {
        let mut found = Vec::new();
        let mut stack = Stack::new();
        for j in 0..self.1 {
            nearest(
                k,
                self.0,
                base + j,
                usize::MAX,
                false,
                &mut found,
                &mut stack,
            );
            counts.push(found.len() as u32);
            hits.extend_from_slice(&found);
        }
    }
}

/// How many hits [`all_hits`] would give each ray, without keeping them.
pub(crate) struct CountJob<'a>(pub &'a Rays<'a>);

impl Job for CountJob<'_> {
    type Out<'o> = &'o mut [u32];

    #[inline(always)]
    fn chunk<K: Kernel>(&self, k: K, base: usize, out: &mut [u32]) {
        let mut found = Vec::new();
        let mut stack = Stack::new();
        for (j, n) in out.iter_mut().enumerate() {
            nearest(
                k,
                self.0,
                base + j,
                usize::MAX,
                false,
                &mut found,
                &mut stack,
            );
            *n = found.len() as u32;
        }
    }
}

/// Ray `i`'s first `want` distinct hits (every hit for `usize::MAX`), nearest first, into
/// `found` (emptied first): the one traversal of the k-nearest, all-hits and count jobs.
#[inline(always)]
fn nearest<K: Kernel>(
    k: K,
    rays: &Rays,
    i: usize,
    want: usize,
    front_only: bool,
    found: &mut Vec<Hit>,
    stack: &mut Stack,
) {
    let r = rays.ray(i);
    found.clear();
    let mut sink = Nearest::new(rays, i, &r, want, front_only, found);
    traverse(k, rays.bvh, &r.ray, &mut sink, stack);
    sink.finish();
}

/// The k-nearest-hits sink: the first `want` distinct surfaces along the ray, each hit refined
/// as it is found.
///
/// Hits whose `t` agree within [`SAME_HIT`] are one surface met twice (a shared edge, a
/// duplicated face). Which hits count as one is decided on the sorted list, not in the order
/// they arrive: in `(t, triangle)` order, a hit joins the surface of the last hit that started
/// one if it lies within the tolerance of it ([`same_surface`]), else starts the next, and each
/// surface is reported as the hit that started it. So the answer does not depend on the order
/// the traversal visits the tree (a packet's, a single ray's, any kernel's), which a merge of
/// each new hit into the list would (three hits each within the tolerance of the next). The
/// search stops at the `want`-th surface: a hit beyond it cannot come before it, and a later
/// hit in front can only move it nearer (the surfaces are a greedy cover of the hits by
/// intervals, and no cover of more hits needs fewer intervals).
pub(crate) struct Nearest<'a> {
    rays: &'a Rays<'a>,
    /// The ray's index.
    i: usize,
    r: &'a Traced,
    want: usize,
    /// Every hit kept so far, sorted by `(t, triangle)`; [`Nearest::finish`] leaves the
    /// surfaces.
    found: &'a mut Vec<Hit>,
    /// Traversal bound: `t_max` until `want` surfaces are in hand, then the last one's `t`
    /// widened by twice the same-hit tolerance.
    pub(crate) t_far: f32,
    /// Skip triangles whose front (counter-clockwise) faces away from the ray.
    front_only: bool,
}

/// Whether a hit at `t` (at or after `start` on the sorted list) is on the surface that
/// `start` began: within [`SAME_HIT`] of it, relative.
#[inline(always)]
fn same_surface(start: f32, t: f32) -> bool {
    t - start <= SAME_HIT * t
}

impl<'a> Nearest<'a> {
    pub(crate) fn new(
        rays: &'a Rays<'a>,
        i: usize,
        r: &'a Traced,
        want: usize,
        front_only: bool,
        found: &'a mut Vec<Hit>,
    ) -> Self {
        Self {
            rays,
            i,
            r,
            want,
            found,
            t_far: r.t_far,
            front_only,
        }
    }

    pub(crate) fn add(&mut self, h: Hit) {
        let at = self
            .found
            .partition_point(|e| (e.t, e.triangle) < (h.t, h.triangle));
        if self.found.get(at).is_some_and(|e| e.triangle == h.triangle) {
            // The same triangle from another leaf: the same hit.
            return;
        }
        self.found.insert(at, h);
        if self.want == usize::MAX {
            return;
        }
        // The `want`-th surface, if there are that many yet: nothing beyond its tolerance can
        // come before it, now or after more hits.
        let (mut surfaces, mut start) = (0, f32::NAN);
        for (k, e) in self.found.iter().enumerate() {
            if surfaces > 0 && same_surface(start, e.t) {
                continue;
            }
            if surfaces == self.want {
                self.found.truncate(k);
                break;
            }
            (surfaces, start) = (surfaces + 1, e.t);
        }
        if surfaces == self.want {
            let bound = start as f64 * (1.0 + 2.0 * SAME_HIT as f64);
            self.t_far = self.t_far.min(bound as f32 * WIDEN);
        }
    }

    /// Leave only the surfaces in `found`: the first hit of each, at most `want`.
    pub(crate) fn finish(self) {
        let (found, want) = (self.found, self.want);
        let mut kept = 0;
        let mut start = f32::NAN;
        for k in 0..found.len() {
            let e = found[k];
            if kept > 0 && same_surface(start, e.t) {
                continue;
            }
            if kept == want {
                break;
            }
            start = e.t;
            found[kept] = e;
            kept += 1;
        }
        found.truncate(kept);
    }
}

impl Sink for Nearest<'_> {
    #[inline(always)]
    fn t_far(&self) -> f32 {
        self.t_far
    }

    fn take(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit) -> bool {
        self.take_in(bvh, block, h, WORLD)
    }

    fn take_in(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit, inst: u32) -> bool {
        let mut m = h.mask;
        while m != 0 {
            let lane = m.trailing_zeros() as usize;
            m &= m - 1;
            let hit = BlockHit::of(bvh, block, lane, h, inst);
            if self.front_only {
                let [a, b, c] = self.rays.corners(&hit).map(Vec3::from);
                if (b - a).cross(c - a).dot(Vec3::from(self.r.d)) >= 0.0 {
                    continue;
                }
            }
            let hit = self.rays.report(self.i, &hit);
            self.add(hit);
        }
        false
    }
}
