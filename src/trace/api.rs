//! The ray queries: closest hit (`cast_rays`), the k nearest hits (`nearest_hits`), closest
//! hits among kept triangles (`cast_rays_kept`), any hit (`occluded`), every hit (`all_hits`)
//! and how many (`count_hits`). Each goes through the one driver (`driver::drive`) with its
//! job (`jobs`).

use super::dispatch::dispatch;
use super::driver::{drive, Seconds};
use super::jobs::{
    any_plan, AllJob, AnyJob, AnyPlan, ClosestFront, ClosestJob, CountJob, NearestJob,
};
use super::query::Query;
use super::rays::{Hit, Rays};
use super::schedule::{collect, run, FreshHits, CHUNK};
use super::sinks::{Closest, ClosestKept};
use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;

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

impl RayHits {
    /// `n` rays of `k` entries, not yet written: no zeroing on the calling thread (glibc
    /// reuses freed memory for a call's outputs, and zeroing them was 6-8% of a camera-ray call,
    /// done before the threads started). Every job writes its chunk's entries "no hit" before
    /// its hits (`jobs::no_hits`), on its own thread, and [`RayHits::fill`] then takes them.
    fn fresh(n: usize, k: usize) -> Self {
        Self {
            k,
            t: Vec::with_capacity(n * k),
            triangle: Vec::with_capacity(n * k),
            barycentric: Vec::with_capacity(n * k),
            ..Self::default()
        }
    }

    /// The outputs' memory, for the chunks' jobs to write.
    fn spare(&mut self, len: usize) -> FreshHits<'_> {
        (
            &mut self.t.spare_capacity_mut()[..len],
            &mut self.triangle.spare_capacity_mut()[..len],
            &mut self.barycentric.spare_capacity_mut()[..len],
        )
    }

    /// Run `f` over the chunks of the `n × k` fresh outputs (`schedule::run`), then take
    /// them as written.
    fn fill(
        mut self,
        q: &Query,
        n: usize,
        f: impl Fn(usize, FreshHits<'_>) + Sync,
    ) -> Result<Self> {
        let (k, len) = (self.k, n * self.k);
        run(q, self.spare(len), k, f)?;
        // SAFETY: `run` returned Ok, so every chunk's job ran, and each writes every entry of
        // its chunk first (`jobs::no_hits`); the chunks tile the `len` entries.
        unsafe {
            self.t.set_len(len);
            self.triangle.set_len(len);
            self.barycentric.set_len(len);
        }
        Ok(self)
    }

    fn timed(mut self, s: Seconds) -> Self {
        (self.bvh_build_seconds, self.trace_seconds) = (s.build, s.trace);
        self
    }
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
/// within [`SAME_HIT`](crate::types::SAME_HIT) (relative) are one surface met twice (coincident
/// or duplicated triangles) and count once: in `(t, index)` order, a hit within the tolerance
/// of the hit that began the current surface joins it, and the surface is reported as that
/// first hit (`jobs::Nearest`; the answer does not depend on the traversal's order, so
/// coherent rays travel as packets).
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
/// One hit per ray is the closest-hit query (packets for coherent rays, [`cast_rays`]'s tie
/// rule), with or without back faces; more go the k-nearest way, ray by ray.
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
    let (hits, s) = drive(scene, origins, directions, q, |bvh| {
        let hits = RayHits::fresh(n, k);
        let rays = Rays::new(bvh, origins, directions, q);
        if k == 1 && !front_only {
            let job = ClosestJob::new(&rays);
            hits.fill(q, n, |base, out| dispatch(&job, base, out))
        } else if k == 1 {
            let sink = ClosestFront {
                closest: Closest::new(rays.range.1),
                rays: &rays,
                d: glam::Vec3::ZERO,
            };
            let job = ClosestJob(&rays, sink);
            hits.fill(q, n, |base, out| dispatch(&job, base, out))
        } else {
            let job = NearestJob(&rays, k, front_only);
            hits.fill(q, n, |base, out| dispatch(&job, base, out))
        }
    })?;
    Ok(hits.timed(s))
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
    let (hits, s) = drive(scene, origins, directions, q, |bvh| {
        let rays = Rays::new(bvh, origins, directions, q);
        let sink = ClosestKept {
            closest: Closest::new(rays.range.1),
            keep,
        };
        let job = ClosestJob(&rays, sink);
        RayHits::fresh(n, 1).fill(q, n, |base, out| dispatch(&job, base, out))
    })?;
    Ok(hits.timed(s))
}

/// Whether anything lies along each ray within `[t_min, t_max)`: the traversal stops at the
/// first hit it finds, in whatever order.
///
/// How is decided once per call by a probe of 256 of the rays (`jobs::any_plan`; the answer
/// does not depend on it): nearest first or in the builder's any-hit order, whichever visits
/// fewer nodes and blocks, and whether each ray first tries the block that stopped its
/// neighbour. Neither order wins everywhere (one thread, AMD EPYC, nearest first against the
/// any-hit order): shadow segments from surface points towards a small light 0.60-0.77x on
/// `khr_toy_car`, `balloon` and `stanford_bunny` (toy car: 15.7 visits a ray against 9.7);
/// short segments in random directions from the same points 1.0-1.16x; segments between random
/// points 1.0-1.23x. Hints: 1.10-1.18x on the shadow rays of `khr_glass_vase_flowers` and
/// `intel_sponza_curtains` (a neighbour's block stops 19-38% of them), 0.93-1.0x where it stops
/// under 15%.
pub fn occluded(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    q: &Query,
) -> Result<Occlusion> {
    let (hit, s) = drive(scene, origins, directions, q, |bvh| {
        let mut hit = vec![false; origins.len()];
        let rays = Rays::new(bvh, origins, directions, q);
        let plan = any_plan(&rays, origins.len());
        occluded_as(q, &rays, plan, &mut hit)?;
        Ok(hit)
    })?;
    Ok(Occlusion {
        hit,
        bvh_build_seconds: s.build,
        trace_seconds: s.trace,
    })
}

/// Trace `rays` for [`occluded`] as `plan` says, into `hit`.
fn occluded_as(q: &Query, rays: &Rays, plan: AnyPlan, hit: &mut [bool]) -> Result<()> {
    match (plan.nearest, plan.hint) {
        (true, true) => run(q, hit, 1, |b, o| {
            dispatch(&AnyJob::<true, true>(rays), b, o)
        }),
        (true, false) => run(q, hit, 1, |b, o| {
            dispatch(&AnyJob::<true, false>(rays), b, o)
        }),
        (false, true) => run(q, hit, 1, |b, o| {
            dispatch(&AnyJob::<false, true>(rays), b, o)
        }),
        (false, false) => run(q, hit, 1, |b, o| {
            dispatch(&AnyJob::<false, false>(rays), b, o)
        }),
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
    let (count, s) = drive(scene, origins, directions, q, |bvh| {
        let mut count = vec![0u32; origins.len()];
        let rays = Rays::new(bvh, origins, directions, q);
        let job = CountJob(&rays);
        run(q, &mut count[..], 1, |base, out| dispatch(&job, base, out))?;
        Ok(count)
    })?;
    Ok(HitCounts {
        count,
        bvh_build_seconds: s.build,
        trace_seconds: s.trace,
    })
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
/// only. Hits within [`SAME_HIT`](crate::types::SAME_HIT) of each other count once, as in
/// [`nearest_hits`].
pub fn all_hits(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    q: &Query,
) -> Result<AllHits> {
    let n = origins.len();
    let (mut all, s) = drive(scene, origins, directions, q, |bvh| {
        let rays = Rays::new(bvh, origins, directions, q);
        let parts = collect(q, n, |c, len| {
            let (mut counts, mut hits) = (Vec::with_capacity(len), Vec::new());
            dispatch(&AllJob(&rays, len), c * CHUNK, (&mut counts, &mut hits));
            Ok((counts, hits))
        })?;
        Ok(ragged(n, parts))
    })?;
    (all.bvh_build_seconds, all.trace_seconds) = (s.build, s.trace);
    Ok(all)
}

/// Each chunk's hit counts and hits, in chunk order, as one ragged [`AllHits`].
fn ragged(n: usize, parts: Vec<(Vec<u32>, Vec<Hit>)>) -> AllHits {
    let total: usize = parts.iter().map(|p| p.1.len()).sum();
    let mut out = AllHits {
        splits: Vec::with_capacity(n + 1),
        t: Vec::with_capacity(total),
        triangle: Vec::with_capacity(total),
        barycentric: Vec::with_capacity(total),
        ..AllHits::default()
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
    out
}
