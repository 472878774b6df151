//! CPU ray queries: closest hit (`cast_rays`), any hit (`occluded`) and the k nearest hits
//! (`nearest_hits`), on an 8-wide BVH (`bvh8`, built by `build`) cached per scene, with the
//! watertight ray/triangle test of `watertight` and a float64 refinement of each reported hit.
//!
//! Rays are traced with the AVX2 kernel where the CPU has it (`avx2`), else the portable one;
//! both give bit-identical hits. Coherent groups of eight go as packets (`packet`); the others
//! one by one, or, for closest hits on trees larger than [`INTERLEAVE_BYTES`], several in turns
//! (`interleave`). Work is split across the cores with rayon, on the calling thread only
//! (`Threads::One`), or on a pool of a given size.

pub mod avx2;
pub mod build;
pub mod bvh8;
pub mod crossings;
pub mod interleave;
#[cfg(target_arch = "x86_64")]
mod packet;
pub mod points;
pub mod refine;
pub mod refit;
pub mod token;
pub mod watertight;
pub mod winding;

use std::num::NonZeroUsize;
use std::sync::Arc;
use std::time::Instant;

use glam::{Vec3, Vec3A};
use rayon::prelude::*;

use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;
use bvh8::{
    coherent, portable::Portable, traverse, Any, BlockHit, Bvh8, Closest, ClosestKept, Kernel,
    PacketStack, Ray, Sink, Stack, Tri4Hit, WIDTH,
};
use interleave::Flights;
use refine::Pending;
use watertight::Tri;

/// The most triangles a tree can index (one block each at worst).
pub const MAX_TRIANGLES: u32 = bvh8::MAX_BLOCKS;

/// A scene's BVH.
#[derive(Debug)]
pub struct Bvh {
    tree: Bvh8,
    pub build_seconds: f64,
}

/// What a BVH holds and what it cost.
#[derive(Clone, Copy, Debug)]
pub struct BvhStats {
    pub triangles: usize,
    pub nodes: usize,
    pub blocks: usize,
    /// Bytes of nodes and triangle blocks: everything the queries read besides the rays.
    pub bytes: usize,
    pub depth: u32,
    pub build_seconds: f64,
    /// Surface area heuristic cost, Embree's measure: inner nodes' areas plus leaves' areas
    /// times their blocks, relative to the root's area.
    pub sah: f64,
}

impl Bvh {
    pub fn build(scene: &Scene) -> Self {
        Self::build_with(scene, build::BuildParams::standard())
    }

    pub fn build_with(scene: &Scene, params: build::BuildParams) -> Self {
        let start = Instant::now();
        if let Some(pose) = scene.pose() {
            // A posed scene: its base's object trees, moved and refit.
            let base = &pose.base;
            let trees = base.derived(|| {
                let objects = base.objects().len();
                refit::ObjectTrees::of(&base.rig(), base.object_ids(), objects, params)
            });
            return Self {
                tree: trees.posed(scene.vertices(), scene.faces()),
                build_seconds: start.elapsed().as_secs_f64(),
            };
        }
        let v = scene.vertices();
        let tris: Vec<Tri> = scene
            .faces()
            .iter()
            .map(|f| Tri {
                v: f.map(|k| Vec3A::from(Vec3::from(v[k as usize]))),
            })
            .collect();
        let tree = build::build(&tris, params);
        Self {
            tree,
            build_seconds: start.elapsed().as_secs_f64(),
        }
    }

    /// The scene's BVH, built on first use (by every core) and cached for the scene's lifetime.
    pub fn of(scene: &Scene) -> Arc<Bvh> {
        Self::of_with(scene, Threads::All)
    }

    /// [`Bvh::of`], building on `threads` when the BVH is not cached yet.
    pub fn of_with(scene: &Scene, threads: Threads) -> Arc<Bvh> {
        let params = build::BuildParams::standard();
        scene.derived(|| {
            // `Count` threads: the caller runs this inside that pool already.
            match threads {
                Threads::One => Bvh::build_with(scene, params.sequential()),
                _ => Bvh::build_with(scene, params),
            }
        })
    }

    pub fn stats(&self) -> BvhStats {
        let t = &self.tree;
        BvhStats {
            triangles: t
                .blocks
                .iter()
                .flat_map(|b| b.id)
                .filter(|&i| i != u32::MAX)
                .count(),
            nodes: t.nodes.len(),
            blocks: t.blocks.len(),
            bytes: t.bytes(),
            depth: t.depth,
            build_seconds: self.build_seconds,
            sah: t.sah(),
        }
    }
}

/// Which threads run a query.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Threads {
    /// rayon's global pool: every core.
    All,
    /// The calling thread only.
    One,
    /// A pool of this many threads (created once per size and kept).
    Count(NonZeroUsize),
}

impl Threads {
    pub fn from_count(n: Option<usize>) -> Result<Self> {
        match n {
            None => Ok(Self::All),
            Some(0) => input_err!("threads must be at least 1 (or None for all cores), got 0"),
            Some(1) => Ok(Self::One),
            Some(n) => Ok(Self::Count(NonZeroUsize::new(n).expect("n > 1"))),
        }
    }
}

/// The range and threads of a query. Hits count when `t_min <= t < t_max`, in units of each
/// direction's length.
#[derive(Clone, Copy, Debug)]
pub struct Query {
    pub t_min: f32,
    pub t_max: f32,
    pub threads: Threads,
    /// Count the rays as the calling call's progress (`process::counter`): set by a ray query
    /// that is itself the call, not by the algorithms that cast rays on the way to theirs.
    pub report: bool,
}

impl Query {
    pub fn new(t_min: f32, t_max: f32) -> Self {
        Self {
            t_min,
            t_max,
            threads: Threads::All,
            report: false,
        }
    }
}

/// Results of `cast_rays` and `nearest_hits`: `k` entries per ray, nearest first.
#[derive(Debug, Default)]
pub struct RayHits {
    pub k: usize,
    /// Distance in units of the direction's length; +inf where there is no (further) hit.
    pub t: Vec<f32>,
    /// Triangle index (the scene's face index); −1 where there is no hit.
    pub triangle: Vec<i32>,
    /// Barycentric (u, v) of the hit: point = (1−u−v)·v0 + u·v1 + v·v2; (0, 0) without a hit.
    pub barycentric: Vec<[f32; 2]>,
    pub bvh_build_seconds: f64,
    pub trace_seconds: f64,
}

/// Results of `occluded`.
#[derive(Debug, Default)]
pub struct Occlusion {
    pub hit: Vec<bool>,
    pub bvh_build_seconds: f64,
    pub trace_seconds: f64,
}

/// Closest hit of each ray in `[t_min, t_max)` (units of each direction's length), on every
/// core. Directions need not be unit length but must be finite and non-zero.
pub fn cast_rays(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    t_min: f32,
    t_max: f32,
) -> Result<RayHits> {
    cast_rays_with(scene, origins, directions, &Query::new(t_min, t_max))
}

/// [`cast_rays`] with a chosen range and threads.
pub fn cast_rays_with(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    q: &Query,
) -> Result<RayHits> {
    nearest_hits(scene, origins, directions, 1, q)
}

/// The first `k` hits along each ray, nearest first, in `[t_min, t_max)`. Hits whose `t` agree
/// within [`SAME_HIT`] (relative) are one surface met twice (coincident or duplicated
/// triangles) and count once, as the triangle with the smaller `t` (then the smaller index).
pub fn nearest_hits(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    k: usize,
    q: &Query,
) -> Result<RayHits> {
    nearest_hits_facing(scene, origins, directions, k, q, false)
}

/// [`nearest_hits`], optionally counting only the triangles whose counter-clockwise front
/// faces the ray (`front_only`: a back face is passed through, as a culling rasterizer skips
/// it; a back face coincident with a front one then cannot take its place as the surface).
pub fn nearest_hits_facing(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    k: usize,
    q: &Query,
    front_only: bool,
) -> Result<RayHits> {
    if k == 0 {
        return input_err!("max_hits must be at least 1, got 0");
    }
    let n = origins.len();
    // t, triangle and barycentric per hit.
    crate::limits::check(
        || format!("{n} rays x max_hits={k}"),
        crate::limits::product(&[n as u64, k as u64]),
        16,
    )?;
    on_threads(q.threads, || {
        nearest_hits_here(scene, origins, directions, k, q, front_only)
    })?
}

fn nearest_hits_here(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    k: usize,
    q: &Query,
    front_only: bool,
) -> Result<RayHits> {
    let (bvh, built) = prepare(scene, origins, directions, q)?;
    let start = Instant::now();
    let n = origins.len();
    let len = n * k; // checked against the memory limit by `nearest_hits_facing`
    let mut t = vec![f32::INFINITY; len];
    let mut triangle = vec![-1i32; len];
    let mut barycentric = vec![[0.0f32; 2]; len];
    let job = Rays::new(&bvh.tree, origins, directions, q);
    let out: HitSlices = (&mut t, &mut triangle, &mut barycentric);
    if k == 1 && !front_only {
        run(q, out, 1, |base, out| {
            dispatch(&ClosestJob::new(&job), base, out)
        })?;
    } else {
        run(q, out, k, |base, out| {
            dispatch(&NearestJob(&job, k, front_only), base, out)
        })?;
    }
    Ok(RayHits {
        k,
        t,
        triangle,
        barycentric,
        bvh_build_seconds: built,
        trace_seconds: start.elapsed().as_secs_f64(),
    })
}

/// [`cast_rays_with`] meeting only the triangles kept: triangle `i` counts when bit `i % 64`
/// of `keep[i / 64]` is set, and a ray passes through the others (the visibility field's
/// CPU view traces only its marked cells, as its GPU view draws only them).
pub fn cast_rays_kept(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    q: &Query,
    keep: &[u64],
) -> Result<RayHits> {
    let need = scene.triangle_count().div_ceil(64);
    if keep.len() < need {
        return input_err!(
            "{} words of triangle bits for {} triangles, need {need}",
            keep.len(),
            scene.triangle_count()
        );
    }
    let n = origins.len();
    crate::limits::check(|| format!("{n} rays"), n as u128, 16)?;
    on_threads(q.threads, || -> Result<RayHits> {
        let (bvh, built) = prepare(scene, origins, directions, q)?;
        let start = Instant::now();
        let mut t = vec![f32::INFINITY; n];
        let mut triangle = vec![-1i32; n];
        let mut barycentric = vec![[0.0f32; 2]; n];
        let job = Rays::new(&bvh.tree, origins, directions, q);
        let sink = ClosestKept {
            closest: Closest::new(job.range.1),
            keep,
        };
        run(
            q,
            (&mut t[..], &mut triangle[..], &mut barycentric[..]),
            1,
            |base, out| dispatch(&ClosestJob(&job, sink), base, out),
        )?;
        Ok(RayHits {
            k: 1,
            t,
            triangle,
            barycentric,
            bvh_build_seconds: built,
            trace_seconds: start.elapsed().as_secs_f64(),
        })
    })?
}

/// Whether anything lies along each ray within `[t_min, t_max)`: the traversal stops at the
/// first hit it finds, in whatever order.
pub fn occluded(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    q: &Query,
) -> Result<Occlusion> {
    on_threads(q.threads, || occluded_here(scene, origins, directions, q))?
}

fn occluded_here(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    q: &Query,
) -> Result<Occlusion> {
    let (bvh, built) = prepare(scene, origins, directions, q)?;
    let start = Instant::now();
    let mut hit = vec![false; origins.len()];
    let job = Rays::new(&bvh.tree, origins, directions, q);
    run(q, &mut hit[..], 1, |base, out| {
        dispatch(&AnyJob(&job), base, out)
    })?;
    Ok(Occlusion {
        hit,
        bvh_build_seconds: built,
        trace_seconds: start.elapsed().as_secs_f64(),
    })
}

/// Check the rays, count them, and get the scene's BVH with the seconds spent building it now
/// (0 when it was cached).
fn prepare(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    q: &Query,
) -> Result<(Arc<Bvh>, f64)> {
    check_rays(origins, directions, q.t_min, q.t_max, q.threads)?;
    crate::counters::add(crate::counters::Op::RaysCast, origins.len() as u64);
    bvh_for(scene, q.threads)
}

/// The scene's BVH (built on `threads` if not cached yet) and the seconds spent building it now
/// (0 when it was cached).
fn bvh_for(scene: &Scene, threads: Threads) -> Result<(Arc<Bvh>, f64)> {
    if scene.triangle_count() >= MAX_TRIANGLES as usize {
        return input_err!(
            "the ray and point queries handle scenes of fewer than {MAX_TRIANGLES} triangles; \
             this one has {}",
            scene.triangle_count()
        );
    }
    let had = scene.derived_if_built::<Bvh>().is_some();
    let bvh = Bvh::of_with(scene, threads);
    let built = if had { 0.0 } else { bvh.build_seconds };
    Ok((bvh, built))
}

/// Rays per parallel task.
const CHUNK: usize = 1024;

/// Output slices that split into matching chunks of `k` entries per ray.
trait Chunks: Send + Sized {
    fn rays(&self, k: usize) -> usize;
    fn split(self, at: usize) -> (Self, Self);
}

impl<T: Send> Chunks for &mut [T] {
    fn rays(&self, k: usize) -> usize {
        self.len() / k
    }
    fn split(self, at: usize) -> (Self, Self) {
        self.split_at_mut(at)
    }
}

type HitSlices<'o> = (&'o mut [f32], &'o mut [i32], &'o mut [[f32; 2]]);

impl Chunks for HitSlices<'_> {
    fn rays(&self, k: usize) -> usize {
        self.0.len() / k
    }
    fn split(self, at: usize) -> (Self, Self) {
        let (t0, t1) = self.0.split_at_mut(at);
        let (i0, i1) = self.1.split_at_mut(at);
        let (b0, b1) = self.2.split_at_mut(at);
        ((t0, i0, b0), (t1, i1, b1))
    }
}

/// Run `f(first ray, its chunk of out)` over `out` in chunks of [`CHUNK`] rays, on `q.threads`;
/// every chunk first checks for an interruption (`process::check`), and with `q.report` counts
/// its rays as the call's progress once done.
fn run<O: Chunks>(q: &Query, out: O, k: usize, f: impl Fn(usize, O) + Sync) -> Result<()> {
    let progress = q.report.then(crate::process::counter).flatten();
    if let Some(p) = &progress {
        p.add_total(out.rays(k) as u64);
    }
    let mut chunks = Vec::with_capacity(out.rays(k).div_ceil(CHUNK));
    let mut rest = out;
    while rest.rays(k) > CHUNK {
        let (a, b) = rest.split(CHUNK * k);
        chunks.push(a);
        rest = b;
    }
    chunks.push(rest);
    let each = |(c, o): (usize, O)| {
        crate::process::check()?;
        let rays = o.rays(k) as u64;
        f(c * CHUNK, o);
        if let Some(p) = &progress {
            p.advance(rays);
        }
        Ok(())
    };
    if q.threads == Threads::One {
        chunks.into_iter().enumerate().try_for_each(each)
    } else {
        chunks.into_par_iter().enumerate().try_for_each(each)
    }
}

/// Run `f` where `threads` says: on the calling thread, or inside this process's pool of all
/// cores or of `n` threads (so every parallel step of `f` stays on those).
fn on_threads<R: Send>(threads: Threads, f: impl FnOnce() -> R + Send) -> Result<R> {
    match threads {
        Threads::One => Ok(f()),
        Threads::All => crate::process::install(None, f),
        Threads::Count(n) => crate::process::install(Some(n.get()), f),
    }
}

/// A query's work on one chunk of rays, for any kernel.
trait Job: Sync {
    type Out<'o>;
    fn chunk<K: Kernel>(&self, k: K, base: usize, out: Self::Out<'_>);
}

/// Run `job` with the best kernel this CPU has.
#[inline(always)]
fn dispatch<J: Job>(job: &J, base: usize, out: J::Out<'_>) {
    #[cfg(target_arch = "x86_64")]
    if let Some(k) = avx2::Avx2::detect() {
        // SAFETY: the CPU has AVX2 (the token proves it).
        return unsafe { chunk_avx2(job, k, base, out) };
    }
    job.chunk(Portable, base, out)
}

/// [`Job::chunk`] compiled for AVX2 (and the VEX encodings, bit scans and popcount that come
/// with it), so the kernel's intrinsics inline.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2,bmi1,bmi2,lzcnt,popcnt")]
unsafe fn chunk_avx2<J: Job>(job: &J, k: avx2::Avx2, base: usize, out: J::Out<'_>) {
    job.chunk(k, base, out)
}

/// What every query shares: the tree, the rays and the range.
struct Rays<'a> {
    bvh: &'a Bvh8,
    origins: &'a [[f32; 3]],
    directions: &'a [[f32; 3]],
    range: (f32, f32),
    /// How far apart the origins of a packet's rays may lie (`bvh8::coherent`).
    origin_extent: f32,
    /// Whether closest-hit rays that do not travel as packets are traced in turns
    /// (`interleave`): where the tree is larger than [`INTERLEAVE_BYTES`].
    interleave: bool,
}

/// Trees larger than this trace their closest-hit rays in turns (`interleave`), on x86-64 (where
/// the traversal asks the cache for nodes ahead). One thread, 786K incoherent rays, 8 flights
/// against one ray at a time, interleaved rounds: `khr_metal_rough_spheres_notex` (60 MB) 1.58x,
/// `scenes.shapes(detail=5)` (24 MB) 1.2-1.3x, `shapes(detail=4)` (7.6 MB) 1.07-1.12x,
/// `khr_toy_car` (6.5 MB) 0.95-1.01x.
pub const INTERLEAVE_BYTES: usize = 8 << 20;

impl<'a> Rays<'a> {
    fn new(bvh: &'a Bvh8, origins: &'a [[f32; 3]], directions: &'a [[f32; 3]], q: &Query) -> Self {
        Self {
            bvh,
            origins,
            directions,
            range: (q.t_min, q.t_max),
            origin_extent: 0.05 * bvh.diagonal(),
            interleave: cfg!(target_arch = "x86_64") && bvh.bytes() > INTERLEAVE_BYTES,
        }
    }
}

/// Traversal stacks and a group of rays, kept from ray to ray.
struct Scratch<K: Kernel, S> {
    single: Stack,
    packet: PacketStack,
    /// The group of [`WIDTH`] rays being traced, and their directions as given.
    rays: [Ray; WIDTH],
    dirs: [Vec3A; WIDTH],
    /// Rays left to trace in turns (`Rays::trace`), and the flights that trace them.
    lone: Vec<u32>,
    flights: Flights<K, S>,
}

impl<K: Kernel, S> Scratch<K, S> {
    fn new() -> Self {
        let none = Ray::new(Vec3A::ZERO, Vec3A::X, 0.0);
        Self {
            single: Stack::new(),
            packet: PacketStack::new(),
            rays: [none; WIDTH],
            dirs: [Vec3A::X; WIDTH],
            lone: Vec::new(),
            flights: Flights::default(),
        }
    }
}

/// One ray in traversal form.
struct Traced {
    o: Vec3A,
    d: Vec3A,
    ray: Ray,
    t_far: f32,
}

impl Rays<'_> {
    /// Trace rays `base + j` for `j` in `range`, each into a fresh sink `sink(j)`, handed to
    /// `done(j, sink)` (not necessarily in order). Runs of eight coherent rays go as packets
    /// where the kernel and the sink can; the others one by one, or in turns (`interleave`)
    /// where the tree is large and the sink allows it ([`Sink::INTERLEAVE`]).
    ///
    /// Rays are set up in place, in `scratch`, by a plain loop: built with `array::from_fn`
    /// and copied into the packet's arrays, the setup of a group was a call the compiler did
    /// not inline (so compiled without AVX2) plus two copies of 1 KB, and took 40% of the time
    /// of rays that miss the scene (786K rays that miss `khr_glass_vase_flowers`: 72 -> 39 ms;
    /// its incoherent rays, which mostly hit, 3-5% faster against embreex).
    #[inline(always)]
    fn trace<K: Kernel, S: Sink + Copy>(
        &self,
        k: K,
        base: usize,
        range: std::ops::Range<usize>,
        scratch: &mut Scratch<K, S>,
        sink: impl Fn(usize) -> S,
        mut done: impl FnMut(usize, S),
    ) {
        let turns = S::INTERLEAVE && self.interleave;
        scratch.lone.clear();
        let mut j = range.start;
        while j < range.end {
            if K::PACKETS && S::PACKETS && j + WIDTH <= range.end {
                for i in 0..WIDTH {
                    (scratch.rays[i], scratch.dirs[i]) = self.traversal_ray(base + j + i);
                }
                if coherent(&scratch.rays, &scratch.dirs, self.origin_extent) {
                    let mut sinks: [S; WIDTH] = std::array::from_fn(|i| sink(j + i));
                    let all = (1 << WIDTH) - 1;
                    if k.packet(
                        self.bvh,
                        &scratch.rays,
                        all,
                        &mut sinks,
                        &mut scratch.packet,
                    ) {
                        for (i, s) in sinks.into_iter().enumerate() {
                            done(j + i, s);
                        }
                        j += WIDTH;
                        continue;
                    }
                }
                if turns {
                    scratch.lone.extend(j as u32..(j + WIDTH) as u32);
                } else {
                    for i in 0..WIDTH {
                        let mut s = sink(j + i);
                        traverse(k, self.bvh, &scratch.rays[i], &mut s, &mut scratch.single);
                        done(j + i, s);
                    }
                }
                j += WIDTH;
                continue;
            }
            if turns {
                scratch.lone.push(j as u32);
            } else {
                let (ray, _) = self.traversal_ray(base + j);
                let mut s = sink(j);
                traverse(k, self.bvh, &ray, &mut s, &mut scratch.single);
                done(j, s);
            }
            j += 1;
        }
        if !scratch.lone.is_empty() {
            let lone = &scratch.lone;
            interleave::traverse(
                k,
                self.bvh,
                0..lone.len(),
                &mut scratch.flights,
                #[inline(always)]
                |i| {
                    let j = lone[i] as usize;
                    (self.traversal_ray(base + j).0, sink(j))
                },
                #[inline(always)]
                |i, s| done(lone[i] as usize, s),
            );
        }
    }

    /// Ray `i` as given: origin and direction.
    #[inline(always)]
    fn input(&self, i: usize) -> (Vec3A, Vec3A) {
        (
            Vec3A::from(Vec3::from(self.origins[i])),
            Vec3A::from(Vec3::from(self.directions[i])),
        )
    }

    /// Ray `i` set up for traversal, and its direction as given.
    #[inline(always)]
    fn traversal_ray(&self, i: usize) -> (Ray, Vec3A) {
        let (o, d) = self.input(i);
        (Ray::new(o, d, self.range.0), d)
    }

    #[inline(always)]
    fn ray(&self, i: usize) -> Traced {
        let (ray, d) = self.traversal_ray(i);
        Traced {
            o: ray.o,
            d,
            ray,
            t_far: self.range.1,
        }
    }

    /// The hit in the caller's units, refined in f64.
    #[inline(always)]
    fn report(&self, r: &Traced, h: &BlockHit) -> Hit {
        let mut p = Pending {
            v: self.bvh.blocks[h.block as usize].corners(h.lane as usize),
            o: r.o.to_array(),
            d: r.d.to_array(),
            t: h.t,
            bary: h.bary(),
        };
        refine::refine_one(&mut p, self.range);
        Hit {
            t: p.t,
            triangle: h.triangle,
            bary: p.bary,
        }
    }
}

/// A closest-hit sink: what it kept.
trait Best: Sink + Copy + Sync {
    fn best(&self) -> Option<BlockHit>;
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

/// Closest hits, each ray's sink a copy of the prototype `.1`.
struct ClosestJob<'a, S>(&'a Rays<'a>, S);

impl<'a> ClosestJob<'a, Closest> {
    fn new(rays: &'a Rays<'a>) -> Self {
        ClosestJob(rays, Closest::new(rays.range.1))
    }
}

impl<S: Best> Job for ClosestJob<'_, S> {
    type Out<'o> = HitSlices<'o>;

    #[inline(always)]
    fn chunk<K: Kernel>(&self, k: K, base: usize, (t, tri, bary): HitSlices<'_>) {
        // Two passes per batch: traversal records each closest hit in f32; the f64 refinement
        // then runs over the batch's hits, free of the traversal's long dependency chains (the
        // processor overlaps one hit's refinement with the next's; inline it took as long as
        // the traversal of a primary ray).
        const BATCH: usize = 256;
        let mut scratch = Scratch::new();
        let mut found = [0u32; BATCH];
        let mut pending = [Pending::default(); BATCH];
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
                |_| self.1,
                // Inlined, so compiled with the kernel's instructions: a closure does not
                // inherit its caller's target features, and a call from AVX2 code into this
                // one, for every ray, spilled the traversal's registers around it.
                #[inline(always)]
                |j, sink| {
                    if let Some(h) = sink.best() {
                        tri[j] = h.triangle as i32;
                        found[hits] = j as u32;
                        pending[hits] = Pending {
                            v: rays.bvh.blocks[h.block as usize].corners(h.lane as usize),
                            o: rays.origins[base + j],
                            d: rays.directions[base + j],
                            t: h.t,
                            bary: h.bary(),
                        };
                        hits += 1;
                    }
                },
            );
            k.refine(&mut pending[..hits], self.0.range);
            for (&j, p) in found[..hits].iter().zip(&pending[..hits]) {
                t[j as usize] = p.t;
                bary[j as usize] = p.bary;
            }
        }
    }
}

struct AnyJob<'a>(&'a Rays<'a>);

impl Job for AnyJob<'_> {
    type Out<'o> = &'o mut [bool];

    #[inline(always)]
    fn chunk<K: Kernel>(&self, k: K, base: usize, out: &mut [bool]) {
        let mut scratch = Scratch::new();
        // The block that stopped the last ray, tried first on the next; none after a ray that
        // nothing stopped (`Any::hint`).
        let last = std::cell::Cell::new(None);
        let any = |_| Any {
            t_far: self.0.range.1,
            hit: None,
            hint: last.get(),
        };
        self.0.trace(
            k,
            base,
            0..out.len(),
            &mut scratch,
            any,
            #[inline(always)]
            |j, sink| {
                out[j] = sink.hit.is_some();
                last.set(sink.hit);
            },
        );
    }
}

pub use crate::types::SAME_HIT;

/// The rays, the hits wanted per ray, and whether back faces are skipped.
struct NearestJob<'a>(&'a Rays<'a>, usize, bool);

impl Job for NearestJob<'_> {
    type Out<'o> = HitSlices<'o>;

    #[inline(always)]
    fn chunk<K: Kernel>(&self, k: K, base: usize, (t, tri, bary): HitSlices<'_>) {
        let want = self.1;
        // Memory for the hits found, not for `want` (which may be far larger).
        let mut found = Vec::with_capacity(want.min(64) + 1);
        let mut stack = Stack::new();
        for j in 0..t.len() / want {
            let r = self.0.ray(base + j);
            found.clear();
            let mut sink = Nearest {
                rays: self.0,
                r: &r,
                want,
                found: &mut found,
                t_far: r.t_far,
                front_only: self.2,
            };
            traverse(k, self.0.bvh, &r.ray, &mut sink, &mut stack);
            for (m, h) in found.iter().enumerate() {
                t[j * want + m] = h.t;
                tri[j * want + m] = h.triangle as i32;
                bary[j * want + m] = h.bary;
            }
        }
    }
}

/// Every distinct hit of each ray of a chunk (the k-nearest sink without a k): how many per
/// ray, appended to the first vector, and the hits, nearest first, to the second.
struct AllJob<'a>(&'a Rays<'a>, usize);

impl Job for AllJob<'_> {
    type Out<'o> = (&'o mut Vec<u32>, &'o mut Vec<Hit>);

    #[inline(always)]
    fn chunk<K: Kernel>(&self, k: K, base: usize, (counts, hits): Self::Out<'_>) {
        let mut found = Vec::new();
        let mut stack = Stack::new();
        for j in 0..self.1 {
            let r = self.0.ray(base + j);
            found.clear();
            let mut sink = Nearest {
                rays: self.0,
                r: &r,
                want: usize::MAX,
                found: &mut found,
                t_far: r.t_far,
                front_only: false,
            };
            traverse(k, self.0.bvh, &r.ray, &mut sink, &mut stack);
            counts.push(found.len() as u32);
            hits.extend_from_slice(&found);
        }
    }
}

/// How many hits [`all_hits`] would give each ray, without keeping them.
struct CountJob<'a>(&'a Rays<'a>);

impl Job for CountJob<'_> {
    type Out<'o> = &'o mut [u32];

    #[inline(always)]
    fn chunk<K: Kernel>(&self, k: K, base: usize, out: &mut [u32]) {
        let mut found = Vec::new();
        let mut stack = Stack::new();
        for (j, n) in out.iter_mut().enumerate() {
            let r = self.0.ray(base + j);
            found.clear();
            let mut sink = Nearest {
                rays: self.0,
                r: &r,
                want: usize::MAX,
                found: &mut found,
                t_far: r.t_far,
                front_only: false,
            };
            traverse(k, self.0.bvh, &r.ray, &mut sink, &mut stack);
            *n = found.len() as u32;
        }
    }
}

/// Results of [`count_hits`].
#[derive(Debug, Default)]
pub struct HitCounts {
    pub count: Vec<u32>,
    pub bvh_build_seconds: f64,
    pub trace_seconds: f64,
}

/// How many distinct hits each ray has in `[t_min, t_max)`: the length of its [`all_hits`]
/// (coincident hits counting once), found the same way but with no memory for the hits.
pub fn count_hits(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    q: &Query,
) -> Result<HitCounts> {
    on_threads(q.threads, || {
        let (bvh, built) = prepare(scene, origins, directions, q)?;
        let start = Instant::now();
        let mut count = vec![0u32; origins.len()];
        let job = Rays::new(&bvh.tree, origins, directions, q);
        run(q, &mut count[..], 1, |base, out| {
            dispatch(&CountJob(&job), base, out)
        })?;
        Ok(HitCounts {
            count,
            bvh_build_seconds: built,
            trace_seconds: start.elapsed().as_secs_f64(),
        })
    })?
}

/// Every hit of every ray, ragged: ray i's hits are `splits[i]..splits[i + 1]`.
#[derive(Debug, Default)]
pub struct AllHits {
    /// Offsets of each ray's hits (one more than there are rays).
    pub splits: Vec<u64>,
    pub t: Vec<f32>,
    pub triangle: Vec<i32>,
    pub barycentric: Vec<[f32; 2]>,
    pub bvh_build_seconds: f64,
    pub trace_seconds: f64,
}

/// Every hit along each ray in `[t_min, t_max)`, nearest first, with memory for the hits found
/// only. Hits within [`SAME_HIT`] of each other count once, as in [`nearest_hits`].
pub fn all_hits(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    q: &Query,
) -> Result<AllHits> {
    on_threads(q.threads, || {
        let (bvh, built) = prepare(scene, origins, directions, q)?;
        let start = Instant::now();
        let job = Rays::new(&bvh.tree, origins, directions, q);
        let n = origins.len();
        let progress = q.report.then(crate::process::counter).flatten();
        if let Some(p) = &progress {
            p.add_total(n as u64);
        }
        let each = |c: usize| -> Result<(Vec<u32>, Vec<Hit>)> {
            crate::process::check()?;
            let len = CHUNK.min(n - c * CHUNK);
            let (mut counts, mut hits) = (Vec::with_capacity(len), Vec::new());
            dispatch(&AllJob(&job, len), c * CHUNK, (&mut counts, &mut hits));
            if let Some(p) = &progress {
                p.advance(len as u64);
            }
            Ok((counts, hits))
        };
        let chunks = n.div_ceil(CHUNK);
        let parts: Vec<(Vec<u32>, Vec<Hit>)> = if q.threads == Threads::One {
            (0..chunks).map(each).collect::<Result<_>>()?
        } else {
            (0..chunks)
                .into_par_iter()
                .map(each)
                .collect::<Result<_>>()?
        };
        let total: usize = parts.iter().map(|p| p.1.len()).sum();
        let mut out = AllHits {
            splits: Vec::with_capacity(n + 1),
            t: Vec::with_capacity(total),
            triangle: Vec::with_capacity(total),
            barycentric: Vec::with_capacity(total),
            bvh_build_seconds: built,
            trace_seconds: 0.0,
        };
        out.splits.push(0);
        for (counts, hits) in parts {
            for c in counts {
                let last = *out.splits.last().expect("starts at 0");
                out.splits.push(last + c as u64);
            }
            for h in hits {
                out.t.push(h.t);
                out.triangle.push(h.triangle as i32);
                out.barycentric.push(h.bary);
            }
        }
        out.trace_seconds = start.elapsed().as_secs_f64();
        Ok(out)
    })?
}

/// The k-nearest-hits sink: up to `want` distinct hits, refined as they are found, nearest
/// first.
struct Nearest<'a> {
    rays: &'a Rays<'a>,
    r: &'a Traced,
    want: usize,
    found: &'a mut Vec<Hit>,
    /// Traversal bound: `t_max` until `want` hits are in hand, then the last one's `t` widened
    /// by the same-hit tolerance.
    t_far: f32,
    /// Skip triangles whose front (counter-clockwise) faces away from the ray.
    front_only: bool,
}

impl Nearest<'_> {
    fn add(&mut self, h: Hit) {
        let same = |a: f32, b: f32| (a - b).abs() <= SAME_HIT * a.max(b);
        if let Some(e) = self.found.iter_mut().find(|e| same(e.t, h.t)) {
            if (h.t, h.triangle) < (e.t, e.triangle) {
                *e = h;
                self.found.sort_by(|a, b| a.t.total_cmp(&b.t));
            }
            return;
        }
        let at = self.found.partition_point(|e| e.t <= h.t);
        self.found.insert(at, h);
        self.found.truncate(self.want);
        if self.found.len() == self.want {
            let last = self.found[self.want - 1].t as f64;
            let bound = last * (1.0 + 2.0 * SAME_HIT as f64);
            self.t_far = self.t_far.min(bound as f32 * bvh8::WIDEN);
        }
    }
}

impl Sink for Nearest<'_> {
    #[inline(always)]
    fn t_far(&self) -> f32 {
        self.t_far
    }

    fn take(&mut self, _: &Bvh8, block: usize, h: &Tri4Hit) -> bool {
        let mut m = h.mask;
        while m != 0 {
            let lane = m.trailing_zeros() as usize;
            m &= m - 1;
            if self.front_only {
                let [a, b, c] = self.rays.bvh.blocks[block].corners(lane).map(Vec3::from);
                if (b - a).cross(c - a).dot(Vec3::from(self.r.d)) >= 0.0 {
                    continue;
                }
            }
            let hit = self
                .rays
                .report(self.r, &BlockHit::of(self.rays.bvh, block, lane, h));
            self.add(hit);
        }
        false
    }
}

/// A reported hit, in the caller's units.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Hit {
    t: f32,
    triangle: u32,
    bary: [f32; 2],
}

fn check_rays(
    o: &[[f32; 3]],
    d: &[[f32; 3]],
    t_min: f32,
    t_max: f32,
    threads: Threads,
) -> Result<()> {
    if o.len() != d.len() {
        return input_err!(
            "origins has {} rows but directions has {}; they must match",
            o.len(),
            d.len()
        );
    }
    if t_min.is_nan() || t_max.is_nan() || t_min < 0.0 || t_max < t_min {
        return input_err!("need 0 <= t_min <= t_max, got t_min={t_min}, t_max={t_max}");
    }
    // One cheap pass (no square roots, no branches: it vectorises), in parallel unless the
    // caller asked for its own thread only; the first bad row is looked up only when there is
    // one. A direction whose squared length is positive and finite has finite components.
    let bad_origin = |v: &[f32; 3]| !(v[0].is_finite() & v[1].is_finite() & v[2].is_finite());
    let bad_direction = |v: &[f32; 3]| {
        let l2 = Vec3::from(*v).length_squared();
        !((l2 > 0.0) & l2.is_finite())
    };
    fn any(rows: &[[f32; 3]], threads: Threads, bad: impl Fn(&[f32; 3]) -> bool + Sync) -> bool {
        let chunk = |c: &[[f32; 3]]| c.iter().fold(false, |b, v| b | bad(v));
        match threads {
            Threads::One => chunk(rows),
            _ => rows.par_chunks(1 << 14).any(chunk),
        }
    }
    if any(o, threads, bad_origin) {
        let i = o.iter().position(bad_origin).expect("found above");
        return input_err!("origins[{i}] is not finite: {:?}", o[i]);
    }
    if any(d, threads, bad_direction) {
        let i = d.iter().position(bad_direction).expect("found above");
        return input_err!(
            "directions[{i}] must be finite and non-zero, got {:?}",
            d[i]
        );
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// An icosphere subdivided `n` times: a closed mesh with shared edges and vertices.
    pub(crate) fn icosphere(n: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let (v0, f0) = crate::scene::shapes::icosahedron();
        let mut v: Vec<Vec3> = v0.iter().map(|p| p.as_vec3()).collect();
        let mut f: Vec<[u32; 3]> = f0.to_vec();
        for _ in 0..n {
            let mut mid = std::collections::HashMap::new();
            let mut next = Vec::new();
            for tri in &f {
                let m: Vec<u32> = (0..3)
                    .map(|k| {
                        let (a, b) = (tri[k].min(tri[(k + 1) % 3]), tri[k].max(tri[(k + 1) % 3]));
                        *mid.entry((a, b)).or_insert_with(|| {
                            v.push(((v[a as usize] + v[b as usize]) * 0.5).normalize());
                            v.len() as u32 - 1
                        })
                    })
                    .collect();
                next.push([tri[0], m[0], m[2]]);
                next.push([tri[1], m[1], m[0]]);
                next.push([tri[2], m[2], m[1]]);
                next.push([m[0], m[1], m[2]]);
            }
            f = next;
        }
        (v.iter().map(|p| p.to_array()).collect(), f)
    }

    /// A deterministic generator (SplitMix64) for test data.
    pub(crate) struct Rng(pub u64);

    impl Rng {
        pub fn next(&mut self) -> f32 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
        }

        pub fn point(&mut self, lo: f32, hi: f32) -> [f32; 3] {
            [0; 3].map(|_| lo + (hi - lo) * self.next())
        }
    }

    /// A cloud of random triangles of every size, with duplicated and coplanar ones mixed in.
    fn soup(n: usize, seed: u64) -> Scene {
        let mut r = Rng(seed);
        let mut v = Vec::new();
        let mut f = Vec::new();
        for i in 0..n {
            let c = r.point(-1.0, 1.0);
            let s = 0.002 + 0.3 * r.next().powi(3);
            for _ in 0..3 {
                let p = r.point(-s, s);
                v.push([c[0] + p[0], c[1] + p[1], c[2] + p[2]]);
            }
            let b = 3 * i as u32;
            f.push([b, b + 1, b + 2]);
            if i % 17 == 0 {
                // The same triangle again, corners rotated: every hit on it ties.
                f.push([b + 1, b + 2, b]);
            }
        }
        Scene::from_arrays(v, f, None, None).unwrap()
    }

    fn random_rays(n: usize, seed: u64) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
        let mut r = Rng(seed);
        (0..n)
            .map(|_| {
                let o = r.point(-1.5, 1.5);
                let t = r.point(-1.0, 1.0);
                (o, [t[0] - o[0], t[1] - o[1], t[2] - o[2]])
            })
            .unzip()
    }

    /// Camera-like rays: one origin, directions over a small grid (coherent: packets).
    fn camera_rays(size: usize, eye: [f32; 3]) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
        let mut o = Vec::new();
        let mut d = Vec::new();
        for y in 0..size {
            for x in 0..size {
                let u = (x as f32 + 0.5) / size as f32 - 0.5;
                let v = (y as f32 + 0.5) / size as f32 - 0.5;
                o.push(eye);
                d.push([u - 0.3 * eye[0], v - 0.3 * eye[1], -1.0]);
            }
        }
        (o, d)
    }

    /// Every hit of a ray by brute force in f64: (t, triangle), sorted.
    fn brute(s: &Scene, o: [f32; 3], d: [f32; 3], t_max: f64) -> Vec<(f64, u32)> {
        let (o, d) = (o.map(f64::from), d.map(f64::from));
        let mut hits = Vec::new();
        for (i, f) in s.faces().iter().enumerate() {
            let v = f.map(|k| s.vertices()[k as usize].map(f64::from));
            let [det, u, w, t] = refine::moller_trumbore(v, o, d, 1.0);
            if det != 0.0 && u >= 0.0 && w >= 0.0 && u + w <= 1.0 && t >= 0.0 && t < t_max {
                // Ranked as reported: t in float32, then the smaller index.
                hits.push((t as f32 as f64, i as u32));
            }
        }
        hits.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        hits
    }

    #[test]
    fn hits_closest_triangle_with_barycentrics() {
        let v = vec![
            [0., 0., 0.],
            [1., 0., 0.],
            [0., 1., 0.],
            [0., 0., -1.],
            [1., 0., -1.],
            [0., 1., -1.],
        ];
        let s = Scene::from_arrays(v, vec![[3, 4, 5], [0, 1, 2]], None, None).unwrap();
        let h = cast_rays(
            &s,
            &[[0.25, 0.5, 1.0]],
            &[[0.0, 0.0, -2.0]],
            0.0,
            f32::INFINITY,
        )
        .unwrap();
        assert_eq!(h.triangle, vec![1]);
        assert!(
            (h.t[0] - 0.5).abs() < 1e-6,
            "t in units of the direction's length"
        );
        assert!(
            (h.barycentric[0][0] - 0.25).abs() < 1e-6 && (h.barycentric[0][1] - 0.5).abs() < 1e-6
        );
        let miss = cast_rays(
            &s,
            &[[2.0, 2.0, 1.0]],
            &[[0.0, 0.0, -1.0]],
            0.0,
            f32::INFINITY,
        )
        .unwrap();
        assert_eq!((miss.triangle[0], miss.t[0]), (-1, f32::INFINITY));
    }

    #[test]
    fn no_ray_through_shared_vertices_or_edges() {
        let (v, f) = icosphere(3);
        let s = Scene::from_arrays(v.clone(), f.clone(), None, None).unwrap();
        let mut targets: Vec<Vec3> = v.iter().map(|p| Vec3::from(*p)).collect();
        for tri in &f {
            for k in 0..3 {
                let (a, b) = (
                    Vec3::from(v[tri[k] as usize]),
                    Vec3::from(v[tri[(k + 1) % 3] as usize]),
                );
                targets.push((a + b) * 0.5);
            }
        }
        let (mut o, mut d) = (Vec::new(), Vec::new());
        for (i, p) in targets.iter().enumerate() {
            // Deterministic directions spread over the sphere (golden-angle spiral).
            let z = 1.0 - 2.0 * ((i as f32 * 0.618_034) % 1.0);
            let phi = i as f32 * 2.399_963;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let out = Vec3::new(r * phi.cos(), r * phi.sin(), z);
            // Tilt the outward normal by at most ~40° so each ray enters the mesh at its target
            // (a ray that only grazes a convex mesh at a vertex may rightly miss).
            let n = p.normalize();
            let tangent = (out - n * out.dot(n)).normalize_or_zero();
            let origin = *p + (n + tangent * 0.8).normalize() * 3.0;
            o.push(origin.to_array());
            d.push((*p - origin).to_array());
        }
        let h = cast_rays(&s, &o, &d, 0.0, f32::INFINITY).unwrap();
        let misses = h.triangle.iter().filter(|&&t| t < 0).count();
        assert_eq!(
            misses,
            0,
            "{misses} of {} rays passed through the closed mesh",
            o.len()
        );
        assert!(occluded(&s, &o, &d, &Query::new(0.0, f32::INFINITY))
            .unwrap()
            .hit
            .iter()
            .all(|&h| h));
    }

    /// Closest hits are those of a float64 brute force: same triangle, `t` within 1e-6. On an
    /// exact tie (the duplicated triangles) the smaller index wins, whatever the traversal.
    #[test]
    fn closest_hits_match_brute_force() {
        let s = soup(3000, 7);
        let (o, d) = random_rays(4000, 8);
        let h = cast_rays(&s, &o, &d, 0.0, f32::INFINITY).unwrap();
        let mut same = 0;
        for i in 0..o.len() {
            let b = brute(&s, o[i], d[i], f64::INFINITY);
            match b.first() {
                None => assert_eq!(h.triangle[i], -1, "ray {i}: brute force misses"),
                Some(&(t, tri)) => {
                    assert!(
                        ((h.t[i] as f64 - t) / t).abs() < 1e-6,
                        "ray {i}: t {} vs {t}",
                        h.t[i]
                    );
                    // Triangles met at the same depth (duplicated faces, shared edges) rank by
                    // their f32 depth, which the f64 one may order differently by an ulp: any
                    // of them is right. Beyond that, f32 and f64 may disagree on which of two
                    // triangles is first only rarely.
                    let _ = tri;
                    let tied = b.iter().take_while(|&&(u, _)| u <= t * (1.0 + 1e-6));
                    same += usize::from(tied.clone().any(|&(_, k)| k as i32 == h.triangle[i]));
                }
            }
        }
        let hits = h.triangle.iter().filter(|&&t| t >= 0).count();
        assert!(
            same >= hits * 999 / 1000,
            "{same} of {hits} closest triangles agree"
        );
    }

    /// The AVX2 kernel, packets, single rays, the portable kernel, shuffled orders and every
    /// thread setting give bit-identical hits.
    #[test]
    fn kernels_packets_orders_and_threads_agree() {
        let (v, f) = icosphere(4);
        let s = Scene::from_arrays(v, f, None, None).unwrap();
        let (mut o, mut d) = camera_rays(64, [0.3, 0.2, 3.0]);
        let (ro, rd) = random_rays(4096, 3);
        o.extend(ro);
        d.extend(rd);
        let q = Query::new(0.0, f32::INFINITY);
        let reference = cast_rays_with(&s, &o, &d, &q).unwrap();
        assert!(reference.triangle.iter().filter(|&&t| t >= 0).count() > 3000);
        let bits = |h: &RayHits| {
            h.t.iter()
                .map(|x| x.to_bits())
                .zip(h.triangle.iter().copied())
                .zip(h.barycentric.iter().map(|b| b.map(f32::to_bits)))
                .collect::<Vec<_>>()
        };
        for threads in [Threads::One, Threads::Count(NonZeroUsize::new(3).unwrap())] {
            let h = cast_rays_with(&s, &o, &d, &Query { threads, ..q }).unwrap();
            assert_eq!(bits(&h), bits(&reference), "{threads:?}");
        }
        let perm: Vec<usize> = (0..o.len()).map(|i| (i * 7919) % o.len()).collect();
        let (po, pd): (Vec<_>, Vec<_>) = perm.iter().map(|&i| (o[i], d[i])).unzip();
        let shuffled = cast_rays_with(&s, &po, &pd, &q).unwrap();
        for (k, &i) in perm.iter().enumerate() {
            assert_eq!(shuffled.triangle[k], reference.triangle[i]);
            assert_eq!(shuffled.t[k].to_bits(), reference.t[i].to_bits());
        }
        // The portable kernel (no packets) over the same rays.
        let bvh = Bvh::of(&s);
        let rays = Rays::new(&bvh.tree, &o, &d, &q);
        let n = o.len();
        let mut p = (vec![f32::INFINITY; n], vec![-1; n], vec![[0.0; 2]; n]);
        ClosestJob::new(&rays).chunk(Portable, 0, (&mut p.0, &mut p.1, &mut p.2));
        let portable = RayHits {
            k: 1,
            t: p.0,
            triangle: p.1,
            barycentric: p.2,
            ..Default::default()
        };
        assert_eq!(bits(&portable), bits(&reference));
        // Rays traced in turns, as on trees larger than INTERLEAVE_BYTES: both kernels, a count
        // of rays that is not a multiple of the packets' eight, camera rays (packets, on AVX2)
        // and random ones (turns).
        let m = n - 3;
        let mut turns = Rays::new(&bvh.tree, &o[..m], &d[..m], &q);
        turns.interleave = true;
        let mut a = (vec![f32::INFINITY; m], vec![-1; m], vec![[0.0; 2]; m]);
        dispatch(&ClosestJob::new(&turns), 0, (&mut a.0, &mut a.1, &mut a.2));
        let mut p = (vec![f32::INFINITY; m], vec![-1; m], vec![[0.0; 2]; m]);
        ClosestJob::new(&turns).chunk(Portable, 0, (&mut p.0, &mut p.1, &mut p.2));
        for (name, (t, tri, bary)) in [("dispatched", a), ("portable", p)] {
            let h = RayHits {
                k: 1,
                t,
                triangle: tri,
                barycentric: bary,
                ..Default::default()
            };
            assert_eq!(bits(&h), bits(&reference)[..m], "{name}, in turns");
        }
        let mut any = vec![false; n];
        AnyJob(&rays).chunk(Portable, 0, &mut any);
        assert_eq!(any, occluded(&s, &o, &d, &q).unwrap().hit);
    }

    /// Whether `cast_rays` finds a hit in the range, per ray.
    fn hit_by_closest(s: &Scene, o: &[[f32; 3]], d: &[[f32; 3]], q: &Query) -> Vec<bool> {
        let h = cast_rays_with(s, o, d, q).unwrap();
        h.triangle.iter().map(|&t| t >= 0).collect()
    }

    /// `occluded` is true exactly where `cast_rays` finds a hit in the range.
    #[test]
    fn occluded_agrees_with_closest_hits() {
        let s = soup(2000, 11);
        let (o, d) = random_rays(5000, 12);
        for t_max in [0.3, 1.0, f32::INFINITY] {
            let q = Query::new(0.05, t_max);
            let a = occluded(&s, &o, &d, &q).unwrap();
            assert_eq!(a.hit, hit_by_closest(&s, &o, &d, &q), "t_max {t_max}");
        }
    }

    /// Shadow rays in image order, where each ray's predecessor was stopped by a block (the
    /// hint it tries first): every other segment ends short of that occluder, and some rays pass
    /// beside it. The hint must never turn them into hits.
    #[test]
    fn occluded_hints_never_add_hits() {
        // A quad at z = 1 over [0, 1]²; shadow rays rise from a grid over [-0.5, 1.5]².
        let v = [
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ];
        let s = Scene::from_arrays(v.to_vec(), vec![[0, 1, 2], [0, 2, 3]], None, None).unwrap();
        let (mut o, mut d) = (vec![], vec![]);
        for i in 0..64 {
            for j in 0..64 {
                o.push([
                    -0.5 + 2.0 * j as f32 / 63.0,
                    -0.5 + 2.0 * i as f32 / 63.0,
                    0.0,
                ]);
                d.push([0.0, 0.0, if (i + j) % 2 == 0 { 2.0 } else { 0.5 }]);
            }
        }
        let q = Query::new(0.0, 1.0);
        let a = occluded(&s, &o, &d, &q).unwrap();
        let want = hit_by_closest(&s, &o, &d, &q);
        assert_eq!(a.hit, want);
        let blocked = want.iter().filter(|&&h| h).count();
        assert!(
            blocked > 500 && blocked < 4096 / 2,
            "{blocked} rays blocked"
        );
    }

    /// The k nearest hits are the brute force's, nearest first, ties (duplicated triangles)
    /// counted once as the smaller index.
    #[test]
    fn nearest_hits_match_brute_force() {
        let s = soup(1500, 21);
        let (o, d) = random_rays(1500, 22);
        let k = 4;
        let h = nearest_hits(&s, &o, &d, k, &Query::new(0.0, f32::INFINITY)).unwrap();
        for i in 0..o.len() {
            let mut want: Vec<(f64, u32)> = Vec::new();
            for (t, tri) in brute(&s, o[i], d[i], f64::INFINITY) {
                let same = want
                    .last()
                    .is_some_and(|&(u, _)| (t - u).abs() <= 1e-6 * t.max(u));
                if !same {
                    want.push((t, tri));
                }
            }
            for m in 0..k {
                let (t, tri) = (h.t[i * k + m], h.triangle[i * k + m]);
                match want.get(m) {
                    None => assert_eq!((tri, t), (-1, f32::INFINITY), "ray {i} hit {m}"),
                    Some(&(wt, wtri)) => {
                        assert!(((t as f64 - wt) / wt).abs() < 1e-5, "ray {i} hit {m}");
                        assert_eq!(tri, wtri as i32, "ray {i} hit {m}");
                    }
                }
            }
        }
    }

    #[test]
    fn kept_hits_are_the_nearest_kept_triangle() {
        // Every other triangle kept: each ray's hit is the nearest kept one on its brute-force
        // list, by packets (camera rays) and one by one (random rays); all kept is cast_rays.
        let s = soup(1500, 31);
        let n = s.triangle_count();
        let mut keep = vec![0u64; n.div_ceil(64)];
        for i in (0..n).step_by(2) {
            keep[i / 64] |= 1 << (i % 64);
        }
        let q = Query::new(0.0, f32::INFINITY);
        let (mut o, mut d) = random_rays(1000, 32);
        let (co, cd) = camera_rays(32, [0.1, -0.2, 3.0]);
        o.extend(co);
        d.extend(cd);
        let h = cast_rays_kept(&s, &o, &d, &q, &keep).unwrap();
        let mut met = 0;
        for i in 0..o.len() {
            let want = brute(&s, o[i], d[i], f64::INFINITY)
                .into_iter()
                .find(|&(_, tri)| tri % 2 == 0);
            match want {
                None => assert_eq!(h.triangle[i], -1, "ray {i}"),
                Some((t, tri)) => {
                    assert_eq!(h.triangle[i], tri as i32, "ray {i}");
                    assert!(((h.t[i] as f64 - t) / t).abs() < 1e-5, "ray {i}");
                    met += 1;
                }
            }
        }
        assert!(met > 300, "{met}");
        let all = vec![u64::MAX; n.div_ceil(64)];
        let every = cast_rays_kept(&s, &o, &d, &q, &all).unwrap();
        let plain = cast_rays_with(&s, &o, &d, &q).unwrap();
        assert_eq!(every.triangle, plain.triangle);
        assert_eq!(every.t, plain.t);
        assert!(cast_rays_kept(&s, &o, &d, &q, &keep[1..]).is_err());
    }

    #[test]
    fn all_hits_are_the_nearest_hits_without_a_k() {
        let s = soup(1500, 23);
        let (o, d) = random_rays(3000, 24);
        for threads in [Threads::All, Threads::One] {
            let q = Query {
                threads,
                ..Query::new(0.0, f32::INFINITY)
            };
            let all = all_hits(&s, &o, &d, &q).unwrap();
            assert_eq!(all.splits.len(), o.len() + 1);
            let k = all.splits.windows(2).map(|w| w[1] - w[0]).max().unwrap() as usize;
            assert!(k >= 2, "the soup must give some rays several hits");
            let h = nearest_hits(&s, &o, &d, k, &q).unwrap();
            for i in 0..o.len() {
                let (a, b) = (all.splits[i] as usize, all.splits[i + 1] as usize);
                assert_eq!(
                    &all.triangle[a..b],
                    &h.triangle[i * k..i * k + b - a],
                    "ray {i}"
                );
                assert_eq!(&all.t[a..b], &h.t[i * k..i * k + b - a], "ray {i}");
                assert!(h.triangle[i * k + b - a..(i + 1) * k]
                    .iter()
                    .all(|&t| t == -1));
            }
        }
    }

    #[test]
    fn bad_rays_are_rejected() {
        let (v, f) = icosphere(0);
        let s = Scene::from_arrays(v, f, None, None).unwrap();
        let q = Query::new(0.0, 1.0);
        let e = cast_rays(&s, &[[0.0; 3]], &[[0.0; 3]], 0.0, 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("directions[0]"), "{e}");
        assert!(cast_rays(&s, &[[0.0; 3]], &[], 0.0, 1.0).is_err());
        let nan = occluded(&s, &[[f32::NAN, 0.0, 0.0]], &[[1.0, 0.0, 0.0]], &q);
        assert!(nan.unwrap_err().to_string().contains("origins[0]"));
        let k0 = nearest_hits(&s, &[[0.0; 3]], &[[1.0, 0.0, 0.0]], 0, &q);
        assert!(k0.unwrap_err().to_string().contains("max_hits"));
        assert!(Threads::from_count(Some(0)).is_err());
        assert!(cast_rays(&s, &[[0.0; 3]], &[[1.0, 0.0, 0.0]], 2.0, 1.0).is_err());
    }
}
