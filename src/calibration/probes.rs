//! The probes that measure this machine for `auto`'s cost model ([`calibrate`]): two
//! procedural tori, traced and drawn from three views each.

use std::time::Instant;

use glam::DVec3;

use super::{CostModel, CpuCosts, GpuCosts, Workload, CPU_SHAPE, LAVAPIPE_SHAPE};
use crate::camera::Camera;
use crate::error::Result;
use crate::gpu;
use crate::image::conventional::{discretize_conventional, discretize_traced};
use crate::scene::Scene;

/// What the probes' time over the shape's prediction comes to on the kind of machine the
/// shapes were fitted on (the ray caster's, lavapipe's): the tori are not the shared scenes, so
/// a factor is divided by these to be 1 there. Refitted when the probes began to run the two
/// backends side by side (`round`): the mean over two runs of `bench backends` (64 rows each,
/// 2-core AMD EPYC, lavapipe, each run calibrating afresh) of the constants that make the
/// median of measured over predicted time 1: 1.29 and 0.99 for the ray caster, 0.98 and 1.07
/// for lavapipe. The ratio of the two factors still moved by about 30% between those two
/// runs' calibrations. Before: 1.70, 1.18 (issue 72); 1.12, 1.21.
const PROBE_FACTOR_ON_SHAPE_MACHINE: (f64, f64) = (1.14, 1.03);

/// The probe tori: `2·k²` triangles each.
pub(super) const PROBE_K: [u32; 2] = [48, 256];
/// A torus of `2·k²` triangles (`k` around each circle), its tube bumpy: a closed surface whose
/// far side hides behind its near one, as a scanned or modelled object's does.
fn probe_scene(k: u32) -> Result<Scene> {
    let tau = std::f32::consts::TAU;
    let mut vertices = Vec::with_capacity((k * k) as usize);
    for i in 0..k {
        for j in 0..k {
            let (u, v) = (tau * i as f32 / k as f32, tau * j as f32 / k as f32);
            let r = 0.15 + 0.012 * (u * 23.0).sin() * (v * 17.0).cos();
            let ring = 0.35 + r * v.cos();
            vertices.push([ring * u.cos(), ring * u.sin(), r * v.sin()]);
        }
    }
    let at = |i: u32, j: u32| (i % k) * k + (j % k);
    let mut faces = Vec::with_capacity((2 * k * k) as usize);
    for i in 0..k {
        for j in 0..k {
            faces.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            faces.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    Scene::from_arrays(vertices, faces, None, None)
}

/// The probe's views of the torus: `side`² pixels from `distance` times the near eye's
/// distance (near: the torus covers about a third of the frame and its box three quarters;
/// from 2.5 times as far, a twentieth and a tenth).
fn probe_camera(side: u32, distance: f64) -> Result<Camera> {
    Camera::look_at(
        DVec3::new(0.42, -1.26, 1.12) * distance,
        DVec3::ZERO,
        DVec3::Z,
        0.9,
        side,
        side,
        None,
        None,
    )
}

/// The best of three runs of `run` (each returns its seconds), after one that warms caches.
fn best_of_three(mut run: impl FnMut() -> Result<f64>) -> Result<f64> {
    run()?;
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        best = best.min(run()?);
    }
    Ok(best)
}

/// The seconds `f` takes.
fn seconds<T>(f: impl FnOnce() -> Result<T>) -> Result<f64> {
    let start = Instant::now();
    f()?;
    Ok(start.elapsed().as_secs_f64())
}

/// `(a, b)` of `y = a + b·x` through two points, `b` at least 0.
fn through(x: [f64; 2], y: [f64; 2]) -> (f64, f64) {
    let b = ((y[1] - y[0]) / (x[1] - x[0])).max(0.0);
    (y[0] - b * x[0], b)
}

/// The probe's views: near at 384² and 768², far at 768².
struct ProbeViews {
    cams: [Camera; 3],
    pixels: [f64; 3],
}

impl ProbeViews {
    fn new() -> Result<Self> {
        let cams = [
            probe_camera(384, 1.0)?,
            probe_camera(768, 1.0)?,
            probe_camera(768, 2.5)?,
        ];
        let pixels = cams
            .each_ref()
            .map(|c| f64::from(c.width) * f64::from(c.height));
        Ok(Self { cams, pixels })
    }

    fn one(&self, i: usize) -> &[Camera] {
        std::slice::from_ref(&self.cams[i])
    }
}

/// Rounds of probes every calibration measures ([`rounds`]), and the most it measures while
/// they disagree ([`settled`]).
const ROUNDS: usize = 2;
const MAX_ROUNDS: usize = 4;

/// How far (relative) a round's time may lie above a backend's best round and still confirm
/// it ([`settled`]).
const AGREE: f64 = 0.15;

/// One round of the probes: view by view (each probe view of each torus), the ray caster's
/// best of three warm calls and, where there is a raster backend, the raster's, the two side by
/// side (which goes first alternates from view to view and round to round), so that load
/// passing through the machine meets both backends within a view's time, not one backend's
/// whole share of the probes. Returns each view's best seconds, the ray caster's and the
/// raster's. `time(raster, scene, view)` makes one call and times it.
fn round(
    n_scenes: usize,
    n_views: usize,
    raster: bool,
    k: usize,
    time: &mut impl FnMut(bool, usize, usize) -> Result<f64>,
) -> Result<Round> {
    let mut out = Round {
        cpu: Vec::new(),
        gpu: raster.then(Vec::new),
    };
    for scene in 0..n_scenes {
        for view in 0..n_views {
            let order: &[bool] = match (raster, (scene * n_views + view + k).is_multiple_of(2)) {
                (false, _) => &[false],
                (true, true) => &[false, true],
                (true, false) => &[true, false],
            };
            for &r in order {
                // After a warm call: caches and threads as a run of the backend's own calls
                // leaves them, as the calls `auto` predicts find them.
                let best = best_of_three(|| time(r, scene, view))?;
                match (r, out.gpu.as_mut()) {
                    (true, Some(gpu)) => gpu.push(best),
                    _ => out.cpu.push(best),
                }
            }
        }
    }
    Ok(out)
}

/// A round's best seconds per view: the ray caster's, and the raster's where there is one.
#[derive(Debug, Clone)]
struct Round {
    cpu: Vec<f64>,
    gpu: Option<Vec<f64>>,
}

/// The probes' rounds: [`ROUNDS`] of them, and more (up to [`MAX_ROUNDS`]) until each
/// backend's best round is confirmed by another ([`settled`]).
fn rounds(
    n_scenes: usize,
    n_views: usize,
    raster: bool,
    mut time: impl FnMut(bool, usize, usize) -> Result<f64>,
) -> Result<Vec<Round>> {
    let mut out = Vec::with_capacity(MAX_ROUNDS);
    while out.len() < ROUNDS || (out.len() < MAX_ROUNDS && !settled(&out)) {
        out.push(round(n_scenes, n_views, raster, out.len(), &mut time)?);
    }
    Ok(out)
}

/// Whether each backend's best round (its views' seconds summed) is confirmed: another round
/// within [`AGREE`] of it. A round that load hit, on one backend or both, stands apart, and
/// one more round is measured instead of trusting the best of the rest.
fn settled(rounds: &[Round]) -> bool {
    let sum = |v: &[f64]| v.iter().sum::<f64>();
    let confirmed = |sums: Vec<f64>| {
        let best = sums.iter().copied().fold(f64::INFINITY, f64::min);
        sums.iter().filter(|&&s| s <= best * (1.0 + AGREE)).count() >= 2
    };
    let gpu: Vec<f64> = rounds
        .iter()
        .filter_map(|r| r.gpu.as_deref())
        .map(sum)
        .collect();
    confirmed(rounds.iter().map(|r| sum(&r.cpu)).collect()) && (gpu.is_empty() || confirmed(gpu))
}

/// The two factors (this machine's time over the shape's prediction, `shape`: the ray
/// caster's, and the raster's where there is one): each view's best over the rounds, summed.
/// Load that passes through some rounds, on one backend or both, moves neither factor while
/// each view has a clear round; the rounds go on until a second round confirms the best.
fn factors(rounds: &[Round], shape: (f64, f64)) -> (f64, Option<f64>) {
    let best = |views: Vec<&Vec<f64>>| -> f64 {
        let n = views.first().map_or(0, |v| v.len());
        (0..n)
            .map(|i| views.iter().map(|v| v[i]).fold(f64::INFINITY, f64::min))
            .sum()
    };
    let cpu = best(rounds.iter().map(|r| &r.cpu).collect()) / shape.0;
    let gpu: Vec<&Vec<f64>> = rounds.iter().filter_map(|r| r.gpu.as_ref()).collect();
    (cpu, (!gpu.is_empty()).then(|| best(gpu) / shape.1))
}

/// What the probes would take on the machine a shape was fitted on: `model`'s predictions
/// summed over the probe views (`cpu`: the ray caster's, else the raster's).
fn probe_shape_seconds(
    scenes: &[Scene; 2],
    views: &ProbeViews,
    model: &CostModel,
    cpu: bool,
) -> f64 {
    let mut sum = 0.0;
    for scene in scenes {
        for i in 0..views.cams.len() {
            let w = Workload::of(scene, views.one(i));
            sum += if cpu {
                model.predict_cpu(&w)
            } else {
                model.predict_gpu(&w).unwrap_or(0.0)
            };
        }
    }
    sum
}

/// The model on this machine. The ray caster and a software rasterizer keep the shape of
/// their costs ([`CPU_SHAPE`], [`LAVAPIPE_SHAPE`]) and are scaled by one factor each: the
/// probes' measured time over the time the shape predicts for them. One factor from the sum
/// of six calls is steady where six coefficients fitted to the differences between them are
/// not: on a shared 2-core machine the best of three runs of one call still varies by 10-20%,
/// and the differences by far more. `auto` decides by the two factors' ratio, so the probes
/// measure it robustly ([`rounds`], [`factors`]): the two backends in turn, view by view, so
/// that passing load meets both; each view at its best round; and more rounds while the
/// rounds' sums disagree. (The calibration of a fresh-clone `make test` once ran beside cargo and came out
/// 2.2 times too slow for the ray caster alone, when its probes ran before the raster's.) The
/// BVH build is timed as it is. A hardware GPU, whose costs have another shape (a fixed cost
/// per call, little per pixel), gets lines through its near views: per call and per triangle
/// from the two tori, per pixel from the two sizes.
pub(super) fn calibrate() -> Result<CostModel> {
    let start = Instant::now();
    let scenes = [probe_scene(PROBE_K[0])?, probe_scene(PROBE_K[1])?];
    let views = ProbeViews::new()?;
    let t = scenes.each_ref().map(|s| s.triangle_count() as f64);
    let shape = CostModel {
        gpu: Ok(LAVAPIPE_SHAPE),
        cpu: CPU_SHAPE,
        calibration_seconds: 0.0,
        source: "shape".into(),
    };

    // The large probe's BVH build (timed by the ray caster) and its upload (by the raster).
    let built = discretize_traced(&scenes[1], views.one(0), false)?;
    let build_per_triangle = built.timings.get("bvh").unwrap_or(0.0) / t[1];
    let ctx = gpu::context();
    let uploaded = match &ctx {
        Ok(_) => Ok(discretize_conventional(&scenes[1], views.one(0), false)?),
        Err(e) => Err(e.to_string()),
    };
    // A software rasterizer shares the CPU with the ray caster: the two are probed in turn, and
    // its factor comes with the ray caster's. A hardware GPU gets lines of its own (below).
    let software = matches!(&ctx, Ok(c) if c.info.device_type == wgpu::DeviceType::Cpu);
    let predicted = (
        probe_shape_seconds(&scenes, &views, &shape, true),
        probe_shape_seconds(&scenes, &views, &shape, false),
    );
    let measured = rounds(scenes.len(), views.cams.len(), software, |raster, s, v| {
        let (scene, cams) = (&scenes[s], views.one(v));
        seconds(|| {
            if raster {
                discretize_conventional(scene, cams, false)
            } else {
                discretize_traced(scene, cams, false)
            }
        })
    })?;
    let (k_cpu, k_gpu) = factors(&measured, predicted);
    let cpu = CpuCosts {
        build_per_triangle,
        ..CPU_SHAPE.scaled(k_cpu / PROBE_FACTOR_ON_SHAPE_MACHINE.0)
    };

    let gpu = uploaded.and_then(|first| {
        let upload_per_triangle = first.timings.get("upload").unwrap_or(0.0) / t[1];
        let costs = match k_gpu {
            Some(k) => LAVAPIPE_SHAPE.scaled(k / PROBE_FACTOR_ON_SHAPE_MACHINE.1),
            None => hardware_lines(&scenes, &views, t).map_err(|e| e.to_string())?,
        };
        Ok(GpuCosts {
            upload_per_triangle,
            ..costs
        })
    });
    Ok(CostModel {
        gpu,
        cpu,
        calibration_seconds: start.elapsed().as_secs_f64(),
        source: "probes".into(),
    })
}

/// A hardware GPU's costs: per scene, the line through its two near views' times gives the
/// cost per pixel and per call; the two scenes give how the latter grows with the triangles.
fn hardware_lines(scenes: &[Scene; 2], views: &ProbeViews, t: [f64; 2]) -> Result<GpuCosts> {
    let mut fits = Vec::with_capacity(2);
    for scene in scenes {
        let mut y = [0.0; 2];
        for (i, y) in y.iter_mut().enumerate() {
            *y = best_of_three(|| seconds(|| discretize_conventional(scene, views.one(i), false)))?;
        }
        let p = [views.pixels[0], views.pixels[1]];
        let slope = (y[1] - y[0]) / (p[1] - p[0]);
        fits.push((slope, y[0] - slope * p[0]));
    }
    let (per_call, per_triangle) = through(t, [fits[0].1, fits[1].1]);
    Ok(GpuCosts {
        per_call: per_call.max(0.0),
        per_triangle,
        per_pixel: ((fits[0].0 + fits[1].0) / 2.0).max(0.0),
        per_box_pixel: 0.0,
        upload_per_triangle: 0.0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibration::{Backend, Workload};

    /// Probe calls per round: two tori, three views, two backends, four calls each.
    const CALLS: usize = 48;

    const SHAPE: (f64, f64) = (6.0, 3.0);

    /// The rounds of the probes on a machine whose every call takes 1 s on the ray caster and
    /// 0.5 s on the raster (factors 1 against `SHAPE`), times `load(call, raster)` (calls
    /// counted from 0 in the order they are made).
    fn probed(load: impl Fn(usize, bool) -> f64) -> Vec<Round> {
        let mut calls = 0;
        rounds(2, 3, true, |raster, _, _| {
            calls += 1;
            Ok(if raster { 0.5 } else { 1.0 } * load(calls - 1, raster))
        })
        .unwrap()
    }

    /// What `auto` picks with these factors, over workloads either side of the crossover.
    fn choices((k_cpu, k_gpu): (f64, Option<f64>)) -> Vec<Backend> {
        let model = CostModel {
            gpu: Ok(LAVAPIPE_SHAPE.scaled(k_gpu.unwrap())),
            cpu: CPU_SHAPE.scaled(k_cpu),
            calibration_seconds: 0.0,
            source: "test".into(),
        };
        [1_000u64, 30_000, 100_000, 300_000, 1_000_000, 4_000_000]
            .into_iter()
            .map(|triangles| {
                let w = Workload {
                    triangles,
                    pixels: 1 << 20,
                    images: 1,
                    bvh_built: true,
                    uploaded: true,
                    fits_gpu: true,
                    box_fraction: 0.6,
                };
                model.decide(&w).backend
            })
            .collect()
    }

    #[test]
    fn a_quiet_machine_settles_in_two_rounds() {
        let r = probed(|_, _| 1.0);
        assert_eq!(r.len(), ROUNDS);
        assert_eq!(factors(&r, SHAPE), (1.0, Some(1.0)));
    }

    #[test]
    fn load_on_one_backend_does_not_change_the_choice() {
        let quiet = choices(factors(&probed(|_, _| 1.0), SHAPE));
        // Both kinds of choice occur, so a wrong factor would show.
        assert!(
            quiet.contains(&Backend::Cpu) && quiet.contains(&Backend::Gpu),
            "{quiet:?}"
        );
        let round = |call: usize| call / CALLS;
        let loads: [&dyn Fn(usize, bool) -> f64; 5] = [
            // The ray caster's calls slowed 2.2x in the first round, in every other call.
            &|c, raster| if round(c) == 0 && !raster { 2.2 } else { 1.0 },
            &|c, raster| if c % 2 == 0 && !raster { 2.2 } else { 1.0 },
            // The raster's slowed 3x in the second round.
            &|c, raster| if round(c) == 1 && raster { 3.0 } else { 1.0 },
            // Both in the first round.
            &|c, _| if round(c) == 0 { 1.7 } else { 1.0 },
            // The machine busy (2.2x) for the first 60 calls, whichever backend makes them:
            // the probes once ran all the ray caster's calls first, and cargo compiling
            // beside them slowed those alone.
            &|c, _| if c < 60 { 2.2 } else { 1.0 },
        ];
        for (i, load) in loads.iter().enumerate() {
            let r = probed(load);
            assert!(r.len() <= MAX_ROUNDS);
            let f = factors(&r, SHAPE);
            assert_eq!(f, (1.0, Some(1.0)), "load {i}: {} rounds", r.len());
            assert_eq!(choices(f), quiet, "load {i}");
        }
    }

    #[test]
    fn a_round_that_load_hit_is_measured_again() {
        let r = probed(|c, raster| if c / CALLS == 0 && !raster { 2.2 } else { 1.0 });
        assert_eq!(r.len(), ROUNDS + 1);
        // A machine that never settles stops at the cap, each view at its best round.
        let r = probed(|c, raster| {
            if raster {
                1.0
            } else {
                1.0 + 0.3 * (c / CALLS + 1) as f64
            }
        });
        assert_eq!(r.len(), MAX_ROUNDS);
        assert_eq!(factors(&r, SHAPE).1, Some(1.0));
        assert!((factors(&r, SHAPE).0 - 1.3).abs() < 1e-12);
        // Without a raster, the ray caster's rounds alone.
        let mut calls = 0;
        let alone = rounds(2, 3, false, |_, _, _| {
            calls += 1;
            Ok(if calls <= 24 { 2.0 } else { 1.0 })
        })
        .unwrap();
        assert_eq!(alone.len(), ROUNDS + 1);
        assert_eq!(factors(&alone, SHAPE), (1.0, None));
    }
}
