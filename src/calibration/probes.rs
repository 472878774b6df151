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
use crate::types::DepthImages;

/// What the probes' time over the shape's prediction comes to on the kind of machine the
/// shapes were fitted on (the ray caster's, lavapipe's): the tori are not the shared scenes, so
/// a factor is divided by these to be 1 there. Refitted when issue 72 made the resolve (shared
/// by both backends) sample textures and normals, which the untextured tori feel otherwise
/// than the shared scenes: the mean over two runs of `bench backends` (64 rows each, 2-core
/// AMD EPYC, lavapipe) of the constants that make the median of measured over predicted time
/// 1 (1.89 and 1.51 for the ray caster, 1.17 and 1.20 for lavapipe: the probes' factor itself
/// varies by about 25% between processes on that machine). Before: 1.12, 1.21.
const PROBE_FACTOR_ON_SHAPE_MACHINE: (f64, f64) = (1.70, 1.18);

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

/// The best of three timed runs of `f`, after one that warms caches.
fn best_of_three(mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    f()?;
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let start = Instant::now();
        f()?;
        best = best.min(start.elapsed().as_secs_f64());
    }
    Ok(best)
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

/// The best of three warm calls of `call` on each probe view of each torus, summed.
fn probe_seconds(
    scenes: &[Scene; 2],
    views: &ProbeViews,
    call: impl Fn(&Scene, &[Camera]) -> Result<DepthImages>,
) -> Result<f64> {
    let mut sum = 0.0;
    for scene in scenes {
        for i in 0..views.cams.len() {
            sum += best_of_three(|| call(scene, views.one(i)).map(|_| ()))?;
        }
    }
    Ok(sum)
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
/// and the differences by far more. The BVH build is timed as it is. A hardware GPU, whose
/// costs have another shape (a fixed cost per call, little per pixel), gets lines through
/// its near views: per call and per triangle from the two tori, per pixel from the two sizes.
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

    // CPU: the large probe's BVH build (timed by the ray caster), then warm traces.
    let built = discretize_traced(&scenes[1], views.one(0), false)?;
    let build_per_triangle = built.timings.get("bvh").unwrap_or(0.0) / t[1];
    let traced = probe_seconds(&scenes, &views, |s, c| discretize_traced(s, c, false))?;
    let k = traced
        / probe_shape_seconds(&scenes, &views, &shape, true)
        / PROBE_FACTOR_ON_SHAPE_MACHINE.0;
    let cpu = CpuCosts {
        build_per_triangle,
        ..CPU_SHAPE.scaled(k)
    };

    let gpu = match gpu::context() {
        Err(e) => Err(e.to_string()),
        Ok(ctx) => {
            let first = discretize_conventional(&scenes[1], views.one(0), false)?;
            let upload_per_triangle = first.timings.get("upload").unwrap_or(0.0) / t[1];
            let costs = if ctx.info.device_type == wgpu::DeviceType::Cpu {
                let drawn =
                    probe_seconds(&scenes, &views, |s, c| discretize_conventional(s, c, false))?;
                let shaped = probe_shape_seconds(&scenes, &views, &shape, false);
                LAVAPIPE_SHAPE.scaled(drawn / shaped / PROBE_FACTOR_ON_SHAPE_MACHINE.1)
            } else {
                hardware_lines(&scenes, &views, t)?
            };
            Ok(GpuCosts {
                upload_per_triangle,
                ..costs
            })
        }
    };
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
            *y = best_of_three(|| discretize_conventional(scene, views.one(i), false).map(|_| ()))?;
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
