//! The one path every ray query takes ([`drive`]): check the rays, count them, get the scene's
//! BVH (built now, on the query's threads, if it is not cached), and run the query's body on the
//! query's threads, timed.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::bvh::bvh_for_with;
use super::node::Bvh8;
use super::query::{Query, Threads};
use super::schedule::on_threads;
use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;

/// What a query cost: seconds building the BVH in this call (0 when it was cached) and tracing.
#[derive(Clone, Copy, Debug, Default)]
pub struct Seconds {
    pub build: f64,
    pub trace: f64,
}

/// Run `body` on the scene's BVH over the rays `origins`, `directions` (checked against `q`
/// first, and counted), on `q.threads`; what it made and what it cost.
pub fn drive<R: Send>(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    q: &Query,
    body: impl FnOnce(&Bvh8) -> Result<R> + Send,
) -> Result<(R, Seconds)> {
    drive_with(scene, origins, directions, q, false, body)
}

/// [`drive`], on the scene's flat tree where `flat` is set (for a sink that takes no instances:
/// `crossings`).
pub fn drive_with<R: Send>(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    q: &Query,
    flat: bool,
    body: impl FnOnce(&Bvh8) -> Result<R> + Send,
) -> Result<(R, Seconds)> {
    on_threads(q.threads, || {
        check_rays(origins, directions, q.t_min, q.t_max, q.threads)?;
        crate::counters::add(crate::counters::Op::RaysCast, origins.len() as u64);
        let (bvh, build) = bvh_for_with(scene, q.threads, flat)?;
        let start = Instant::now();
        let out = body(&bvh.tree)?;
        let trace = start.elapsed().as_secs_f64();
        Ok((out, Seconds { build, trace }))
    })?
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
