//! Which backend makes conventional depth images: the GPU raster path or the CPU ray-cast path
//! ([`crate::image::discretize_traced`]). Neither wins everywhere: a software rasterizer (lavapipe)
//! pays per triangle per image, the ray caster per pixel and a logarithm of the triangles, plus
//! a one-time BVH build. `"auto"` predicts both from a cost model measured on this machine.
//!
//! The model (seconds, for `n` images of `p` pixels of a scene of `t` triangles, of which a
//! fraction `b` see the scene's bounding box):
//!
//! - GPU: `g0 + n·(gt·t + gp·p)`, plus `gu·t` when the scene is not on the device yet;
//! - CPU: `c0 + n·(ct·t + p·ca + b·p·(cb + cl·log2 t))`, plus `cu·t` when the scene has no BVH
//!   yet. `ct·t` is each image's pass over the scene's vertices (which settles the pixels on an
//!   edge); `ca` what every pixel costs (its ray, its share of the resolve); a ray that meets
//!   the box pays for its traversal. `b` comes from a grid of at most 64×64 rays per image
//!   ([`box_fraction`]), so views where the scene is small ("sparse" views) are not priced as
//!   full ones. Below the small probe's triangles `log2 t` is held at the probe's: the line is
//!   not extrapolated.
//!
//! The shape of each model (the ratios between its coefficients) was fitted to `bench
//! backends`' real scenes on a 2-core AMD EPYC with lavapipe ([`CPU_SHAPE`],
//! [`LAVAPIPE_SHAPE`]). Probes (two to three seconds, up to twice that on a busy machine:
//! two procedural tori of ~5K and ~130K triangles, closed and bumpy like a scanned or modelled
//! object, seen from near at 384² and 768² and from far at 768²) measure how fast this machine
//! is: one factor per backend, the probes' time over the time the shape predicts for them
//! ([`calibrate`]; a hardware GPU gets lines through its probe times instead). Load that passes
//! while they run must not tilt `auto` (the ratio of the two factors decides): the two backends
//! are probed in turn, view by view, in rounds, until a second round confirms each backend's
//! best, and each view counts at its best round (`probes`). The probes run
//! once per machine: their result is kept in a small calibration file ([`cache`]), keyed by the
//! package version and build, the CPU, the worker threads and the adapter, and every process
//! reads it (a millisecond) instead.
//!
//! Same call, same result: the two backends' images differ at a few edge pixels, so the choice
//! must not depend on anything but the call and the machine. `auto` therefore decides from the
//! calibration file alone, never from timings taken in the process: the first process to need
//! the model measures it under a lock on the file and writes it, and every process (that one
//! included) uses what the file holds. Where no file can be kept (`SCENESAMPLE_CACHE_DIR=""`, a
//! read-only home) nothing is measured: `auto` uses the built-in model of [`CostModel::builtin`]
//! for the adapter's kind. The decision also ignores what the process has prepared: it predicts
//! a call once the scene's BVH and GPU copy exist (what a sweep or many views pay), whichever
//! calls ran before.

use std::sync::{Arc, Mutex};

use glam::DVec3;

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu;
use crate::image::conventional::{discretize_conventional, discretize_traced};
use crate::input_err;
use crate::scene::Scene;
use crate::types::DepthImages;

pub mod cache;
mod probes;
use probes::{calibrate, PROBE_K};

/// Where conventional images are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    Gpu,
    Cpu,
}

impl Backend {
    pub fn name(self) -> &'static str {
        match self {
            Backend::Gpu => "gpu",
            Backend::Cpu => "cpu",
        }
    }
}

/// A request: one backend, or the one the cost model predicts is faster.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendChoice {
    Auto,
    Fixed(Backend),
}

impl std::str::FromStr for BackendChoice {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "auto" => Ok(Self::Auto),
            "gpu" => Ok(Self::Fixed(Backend::Gpu)),
            "cpu" => Ok(Self::Fixed(Backend::Cpu)),
            _ => input_err!("backend must be one of 'auto', 'gpu', 'cpu', got {s:?}"),
        }
    }
}

/// The backend `auto` picked, why, and both predictions (seconds; `gpu` is `None` without an
/// adapter).
#[derive(Debug, Clone)]
pub struct Decision {
    pub backend: Backend,
    pub reason: String,
    pub gpu_seconds: Option<f64>,
    pub cpu_seconds: f64,
}

/// The size of a request and what is already prepared for it.
#[derive(Debug, Clone, Copy)]
pub struct Workload {
    pub triangles: u64,
    pub pixels: u64,
    pub images: u64,
    pub bvh_built: bool,
    pub uploaded: bool,
    /// Whether the images fit in the GPU's textures (true where that is not known).
    pub fits_gpu: bool,
    /// Of all pixels, the fraction whose ray meets the scene's bounding box ([`box_fraction`]).
    pub box_fraction: f64,
}

impl Workload {
    /// The request `cameras` make of `scene`, as `auto` weighs it: once prepared (BVH built,
    /// scene on the GPU), whatever this process has prepared already.
    pub fn of(scene: &Scene, cameras: &[Camera]) -> Self {
        let fits_gpu = match (gpu::context(), cameras.first()) {
            (Ok(ctx), Some(c)) => gpu::raster::check_image_size(&ctx, c.width, c.height).is_ok(),
            _ => true,
        };
        let bounds = scene.bounds_f64();
        let box_fraction = cameras.iter().map(|c| box_fraction(c, bounds)).sum::<f64>()
            / cameras.len().max(1) as f64;
        Self {
            triangles: scene.triangle_count() as u64,
            pixels: cameras
                .first()
                .map_or(0, |c| c.width as u64 * c.height as u64),
            images: cameras.len() as u64,
            bvh_built: true,
            uploaded: true,
            fits_gpu,
            box_fraction,
        }
    }
}

/// Of `cam`'s pixels, the fraction whose centre ray meets the box `bounds` ahead of the camera,
/// from an evenly spread grid of at most 64×64 of them (at most a few hundred microseconds of
/// slab tests, and a function of the camera and the box alone).
pub fn box_fraction(cam: &Camera, [lo, hi]: [DVec3; 2]) -> f64 {
    let rays = crate::image::pixels::PixelRays::new(cam);
    let (w, h) = (cam.width as usize, cam.height as usize);
    let (nx, ny) = (w.clamp(1, 64), h.clamp(1, 64));
    let mut hit = 0usize;
    for j in 0..ny {
        for i in 0..nx {
            let x = (i as f64 + 0.5) * w as f64 / nx as f64;
            let y = (j as f64 + 0.5) * h as f64 / ny as f64;
            let (o, d) = rays.ray_at(x, y);
            let inv = d.recip();
            let (a, b) = ((lo - o) * inv, (hi - o) * inv);
            // NaN (0 · ∞ on a face's plane) is dropped by min/max: the slab is not narrowed.
            let near = a.min(b).max_element().max(0.0);
            let far = a.max(b).min_element();
            hit += usize::from(near <= far);
        }
    }
    hit as f64 / (nx * ny) as f64
}

/// The fitted coefficients (see the module's formulas).
#[derive(Debug, Clone, Copy, Default)]
pub struct GpuCosts {
    pub per_call: f64,
    pub per_triangle: f64,
    pub per_pixel: f64,
    /// What a pixel that sees the scene's box adds (a software rasterizer's fragments).
    pub per_box_pixel: f64,
    pub upload_per_triangle: f64,
}

impl GpuCosts {
    /// Every cost of a call `k` times this one's (the upload's too).
    fn scaled(self, k: f64) -> Self {
        Self {
            per_call: self.per_call * k,
            per_triangle: self.per_triangle * k,
            per_pixel: self.per_pixel * k,
            per_box_pixel: self.per_box_pixel * k,
            upload_per_triangle: self.upload_per_triangle * k,
        }
    }
}

#[derive(Debug, Clone, Copy, Default)]
pub struct CpuCosts {
    pub per_call: f64,
    pub per_image_triangle: f64,
    pub per_pixel: f64,
    pub per_box_ray: f64,
    pub per_box_ray_log2: f64,
    pub build_per_triangle: f64,
}

impl CpuCosts {
    /// Every cost of a call `k` times this one's (the BVH build's too).
    fn scaled(self, k: f64) -> Self {
        Self {
            per_call: self.per_call * k,
            per_image_triangle: self.per_image_triangle * k,
            per_pixel: self.per_pixel * k,
            per_box_ray: self.per_box_ray * k,
            per_box_ray_log2: self.per_box_ray_log2 * k,
            build_per_triangle: self.build_per_triangle * k,
        }
    }
}

/// The shape of the ray caster's costs: the coefficients that fit `bench backends`' rows (every
/// shared scene, 640x480 and 1024², orbit and sparse views; non-negative least squares of the
/// relative error) on a 2-core AMD EPYC, both cores. The probes measure one factor: how much
/// slower or faster this machine's ray caster is (see [`calibrate`]).
const CPU_SHAPE: CpuCosts = CpuCosts {
    per_call: 1e-3,
    per_image_triangle: 1.5e-8,
    per_pixel: 4.15e-8,
    per_box_ray: 0.0,
    per_box_ray_log2: 3.8e-9,
    build_per_triangle: 4.5e-7,
};

/// The same for a software rasterizer (`wgpu::DeviceType::Cpu`: lavapipe, Mesa 22.3, on the
/// same machine), whose costs are shaped as the CPU's are: per triangle, per pixel, and per
/// fragment.
const LAVAPIPE_SHAPE: GpuCosts = GpuCosts {
    per_call: 1e-3,
    per_triangle: 2.15e-7,
    per_pixel: 1.15e-8,
    per_box_pixel: 1.7e-8,
    upload_per_triangle: 7e-8,
};

#[derive(Debug, Clone)]
pub struct CostModel {
    /// `Err(why)` when there is no adapter.
    pub gpu: std::result::Result<GpuCosts, String>,
    pub cpu: CpuCosts,
    /// Seconds the probes took in this process (0 when the model came from the cache file).
    pub calibration_seconds: f64,
    /// Where the coefficients came from: `"probes"`, or the calibration file's path.
    pub source: String,
}

/// This process's cost model, once read (or measured and written).
/// Not a `OnceLock` of the result: a calibration that fails (Ctrl-C during the probes) is not
/// kept, and the next `auto` call measures again.
static MODEL: Mutex<Option<Arc<CostModel>>> = Mutex::new(None);

impl CostModel {
    /// This process's model: the one this machine's calibration file holds, measured by the
    /// probes and written there on first use; the built-in one where no file can be kept.
    /// Calls run one at a time on the worker pool (`process::take_turn`), so holding the lock
    /// while the probes run blocks no one in this process; other processes wait on the file's.
    pub fn get() -> Result<Arc<CostModel>> {
        let mut slot = MODEL.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(model) = slot.as_ref() {
            return Ok(model.clone());
        }
        let adapter = gpu::context();
        let kind = adapter.as_ref().ok().map(|c| c.info.device_type);
        let machine = cache::machine(adapter.as_ref().ok().map(|c| &c.info));
        let has_gpu = adapter.as_ref().map(|_| ()).map_err(|e| e.to_string());
        // The file's model, when its GPU part matches whether there is an adapter now.
        let usable = |cached: Option<(CpuCosts, Option<GpuCosts>)>| match (cached, &has_gpu) {
            (Some((cpu, Some(gpu))), Ok(_)) => Some((cpu, Ok(gpu))),
            (Some((cpu, None)), Err(why)) => Some((cpu, Err(why.clone()))),
            _ => None,
        };
        let model = match cache::path() {
            None => Self::builtin(kind, has_gpu.clone(), "SCENESAMPLE_CACHE_DIR is empty"),
            Some(path) => {
                let from_file = |calibration_seconds| {
                    usable(cache::read(&path, &machine)).map(|(cpu, gpu)| CostModel {
                        gpu,
                        cpu,
                        calibration_seconds,
                        source: cache::display(&path),
                    })
                };
                match from_file(0.0) {
                    Some(m) => m,
                    None => {
                        // Measured under the file's lock: a process that waited for another's
                        // probes reads its model instead of measuring its own.
                        let measured = cache::locked(&path, || {
                            if from_file(0.0).is_some() {
                                return Ok(0.0);
                            }
                            let model = Self::measure(kind, &has_gpu)?;
                            // Unwritable: the built-in model below, as for every process.
                            let _ = cache::write(&path, &machine, &model);
                            Ok(model.calibration_seconds)
                        });
                        match measured? {
                            Ok(seconds) => from_file(seconds).unwrap_or_else(|| {
                                let why = "the probes' model could not be kept";
                                Self::builtin(kind, has_gpu.clone(), why)
                            }),
                            Err(why) => Self::builtin(kind, has_gpu.clone(), &why),
                        }
                    }
                }
            }
        };
        let model = Arc::new(model);
        *slot = Some(model.clone());
        Ok(model)
    }

    /// The probes' model, measured once more when the first looks implausible (timing noise
    /// from another process can flatten a slope to 0), and a slope still flat then taken from
    /// the built-in model: the file must hold a usable model, since every process uses it.
    fn measure(
        kind: Option<wgpu::DeviceType>,
        gpu: &std::result::Result<(), String>,
    ) -> Result<CostModel> {
        let mut model = crate::counters::uncounted(calibrate)?;
        if !model.plausible() {
            let first = model.calibration_seconds;
            model = crate::counters::uncounted(calibrate)?;
            model.calibration_seconds += first;
        }
        if !model.plausible() {
            model.mend(&Self::builtin(kind, gpu.clone(), "mending"));
        }
        Ok(model)
    }

    /// Replace each cost that does not grow with its work by `with`'s.
    fn mend(&mut self, with: &CostModel) {
        let c = &mut self.cpu;
        if c.build_per_triangle <= 0.0 {
            c.build_per_triangle = with.cpu.build_per_triangle;
        }
        if c.per_box_ray + c.per_box_ray_log2 * 100_000f64.log2() <= 0.0 {
            (c.per_box_ray, c.per_box_ray_log2) = (with.cpu.per_box_ray, with.cpu.per_box_ray_log2);
        }
        if let (Ok(g), Ok(w)) = (self.gpu.as_mut(), with.gpu.as_ref()) {
            if g.per_pixel <= 0.0 {
                g.per_pixel = w.per_pixel;
            }
            if g.per_triangle <= 0.0 {
                g.per_triangle = w.per_triangle;
            }
        }
    }

    /// The model `auto` uses where no calibration file can be kept (`why`): fixed
    /// coefficients, so that every process on the machine decides alike. The CPU's and a
    /// software rasterizer's (`wgpu::DeviceType::Cpu`: lavapipe) are the probes' on a 2-core
    /// AMD EPYC with lavapipe (Mesa 22.3), rounded, the per-ray, per-pixel and per-triangle
    /// costs divided by the worker threads / 2; a hardware GPU draws about a billion triangles
    /// and ten billion pixels a second, behind a fixed cost per call.
    pub fn builtin(
        kind: Option<wgpu::DeviceType>,
        gpu: std::result::Result<(), String>,
        why: &str,
    ) -> CostModel {
        let cores = rayon::current_num_threads().max(1) as f64 / 2.0;
        let cpu = CPU_SHAPE.scaled(1.0 / cores);
        let gpu = gpu.map(|()| match kind {
            Some(wgpu::DeviceType::Cpu) => LAVAPIPE_SHAPE.scaled(1.0 / cores),
            _ => GpuCosts {
                per_call: 3e-4,
                per_triangle: 1e-9,
                per_pixel: 1e-10,
                per_box_pixel: 0.0,
                upload_per_triangle: 2e-9,
            },
        });
        CostModel {
            gpu,
            cpu,
            calibration_seconds: 0.0,
            source: format!("built-in ({why})"),
        }
    }

    /// Whether every cost grows with the work it stands for: each backend's per-pixel cost at
    /// 100K triangles, the ray caster's per box ray, the raster's per triangle and the BVH build
    /// are positive.
    pub fn plausible(&self) -> bool {
        let probe = Workload {
            triangles: 100_000,
            pixels: 1 << 20,
            images: 1,
            bvh_built: true,
            uploaded: true,
            fits_gpu: true,
            box_fraction: 0.5,
        };
        let c = &self.cpu;
        let cpu = c.build_per_triangle > 0.0
            && c.per_box_ray + c.per_box_ray_log2 * 100_000f64.log2() > 0.0
            && self.predict_cpu(&Workload {
                pixels: 1 << 21,
                ..probe
            }) > self.predict_cpu(&probe);
        let gpu = self
            .gpu
            .as_ref()
            .map_or(true, |g| g.per_pixel > 0.0 && g.per_triangle > 0.0);
        cpu && gpu
    }

    pub fn predict_gpu(&self, w: &Workload) -> Option<f64> {
        let g = self.gpu.as_ref().ok()?;
        let (t, p, n) = (w.triangles as f64, w.pixels as f64, w.images as f64);
        let upload = if w.uploaded {
            0.0
        } else {
            g.upload_per_triangle * t
        };
        let per_pixel = g.per_pixel + w.box_fraction.clamp(0.0, 1.0) * g.per_box_pixel;
        Some(g.per_call + n * (g.per_triangle * t + per_pixel * p) + upload)
    }

    pub fn predict_cpu(&self, w: &Workload) -> f64 {
        let c = &self.cpu;
        let (t, p, n) = (w.triangles as f64, w.pixels as f64, w.images as f64);
        let build = if w.bvh_built {
            0.0
        } else {
            c.build_per_triangle * t
        };
        let log_t = t.max((2 * PROBE_K[0] * PROBE_K[0]) as f64).log2();
        let per_box_ray = (c.per_box_ray + c.per_box_ray_log2 * log_t).max(0.0);
        let per_pixel = c.per_pixel + w.box_fraction.clamp(0.0, 1.0) * per_box_ray;
        c.per_call + n * (c.per_image_triangle * t + p * per_pixel) + build
    }

    /// The faster predicted backend for `w`, and why.
    pub fn decide(&self, w: &Workload) -> Decision {
        let cpu = self.predict_cpu(w);
        let gpu = self.predict_gpu(w);
        let (backend, reason) = match (&self.gpu, gpu) {
            (Err(why), _) => (Backend::Cpu, format!("no GPU adapter ({why})")),
            (Ok(_), _) if w.triangles >= crate::trace::MAX_TRIANGLES as u64 => (
                Backend::Gpu,
                format!(
                    "{} triangles: the ray caster takes fewer than {}",
                    w.triangles,
                    crate::trace::MAX_TRIANGLES
                ),
            ),
            (Ok(_), _) if !w.fits_gpu => (
                Backend::Cpu,
                "the images exceed the GPU's largest texture".to_string(),
            ),
            (Ok(_), Some(g)) => {
                let backend = if g <= cpu { Backend::Gpu } else { Backend::Cpu };
                let bvh = if w.bvh_built { "built" } else { "not built" };
                let up = if w.uploaded {
                    "uploaded"
                } else {
                    "not uploaded"
                };
                (
                    backend,
                    format!(
                        "predicted gpu {:.1} ms vs cpu {:.1} ms ({} triangles, {} x {} pixels, \
                         {:.0}% of them on the scene's box; BVH {bvh}, scene {up}; model: {})",
                        g * 1e3,
                        cpu * 1e3,
                        w.triangles,
                        w.images,
                        w.pixels,
                        w.box_fraction * 100.0,
                        self.source
                    ),
                )
            }
            (Ok(_), None) => unreachable!("a GPU model always predicts"),
        };
        Decision {
            backend,
            reason,
            gpu_seconds: gpu,
            cpu_seconds: cpu,
        }
    }
}

/// Conventional images from the requested backend; the decision travels with the images.
pub fn discretize_with(
    scene: &Scene,
    cameras: &[Camera],
    cull_backfaces: bool,
    choice: BackendChoice,
) -> Result<(DepthImages, Decision)> {
    crate::image::conventional::check_cameras(cameras)?;
    let decision = decide(scene, cameras, choice)?;
    let images = match decision.backend {
        Backend::Gpu => discretize_conventional(scene, cameras, cull_backfaces),
        Backend::Cpu => discretize_traced(scene, cameras, cull_backfaces),
    }?;
    Ok((images, decision))
}

/// The backend for a request of `cameras`: the requested one, or the one the machine's model
/// predicts is faster for this scene and these cameras. It depends on nothing else, so every
/// method that makes "the conventional images of these cameras" (non-redundant rendering's
/// image 0) makes the same ones.
pub fn decide(scene: &Scene, cameras: &[Camera], choice: BackendChoice) -> Result<Decision> {
    Ok(match choice {
        BackendChoice::Fixed(backend) => Decision {
            backend,
            reason: "requested".into(),
            gpu_seconds: None,
            cpu_seconds: f64::NAN,
        },
        BackendChoice::Auto => CostModel::get()?.decide(&Workload::of(scene, cameras)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(gpu: bool) -> CostModel {
        CostModel {
            gpu: if gpu {
                Ok(GpuCosts {
                    per_call: 1e-3,
                    per_triangle: 4e-7,
                    per_pixel: 2e-8,
                    per_box_pixel: 1e-8,
                    upload_per_triangle: 2e-8,
                })
            } else {
                Err("no adapter".into())
            },
            cpu: CpuCosts {
                per_call: 1e-3,
                per_image_triangle: 4e-8,
                per_pixel: 3e-8,
                per_box_ray: 2e-8,
                per_box_ray_log2: 7e-9,
                build_per_triangle: 5e-7,
            },
            calibration_seconds: 0.0,
            source: "probes".into(),
        }
    }

    fn work(triangles: u64, bvh_built: bool) -> Workload {
        Workload {
            triangles,
            pixels: 1 << 20,
            images: 1,
            bvh_built,
            uploaded: true,
            fits_gpu: true,
            box_fraction: 0.5,
        }
    }

    #[test]
    fn box_fraction_counts_the_rays_that_meet_the_box() {
        let cam = |eye: DVec3, target: DVec3| {
            Camera::look_at(eye, target, DVec3::Z, 0.8, 320, 240, None, None).unwrap()
        };
        let unit = [DVec3::splat(-1.0), DVec3::splat(1.0)];
        // Inside the box every ray meets it; looking away from it, none do.
        let inside = cam(DVec3::ZERO, DVec3::X);
        assert_eq!(box_fraction(&inside, unit), 1.0);
        let away = cam(DVec3::new(5.0, 0.0, 0.0), DVec3::new(10.0, 0.0, 0.0));
        assert_eq!(box_fraction(&away, unit), 0.0);
        // Head on, the face's share of the frame: a square of side 2 at distance 4 (the near
        // face), through a vertical field of view of 0.8 rad on a 4:3 frame.
        let ahead = cam(DVec3::new(-5.0, 0.0, 0.0), DVec3::ZERO);
        let half_h = (0.4f64).tan() * 4.0;
        let want = (1.0 / (half_h * 4.0 / 3.0)).min(1.0) * (1.0 / half_h).min(1.0);
        let got = box_fraction(&ahead, unit);
        assert!((got - want).abs() < 0.03, "{got} vs {want}");
        // The same view from three times as far: a ninth as many, and the CPU's prediction
        // falls with it while the raster's per-triangle cost stays.
        let far = cam(DVec3::new(-15.0, 0.0, 0.0), DVec3::ZERO);
        let sparse = box_fraction(&far, unit);
        assert!(sparse < got / 6.0 && sparse > 0.0, "{sparse} vs {got}");
        let m = model(true);
        let at = |b: f64| Workload {
            box_fraction: b,
            ..work(100_000, true)
        };
        assert!(m.predict_cpu(&at(sparse)) < m.predict_cpu(&at(got)));
    }

    #[test]
    fn backends_parse_and_bad_names_are_refused() {
        assert_eq!(
            "auto".parse::<BackendChoice>().unwrap(),
            BackendChoice::Auto
        );
        assert_eq!(
            "cpu".parse::<BackendChoice>().unwrap(),
            BackendChoice::Fixed(Backend::Cpu)
        );
        let e = "metal".parse::<BackendChoice>().unwrap_err().to_string();
        assert!(e.contains("'auto', 'gpu', 'cpu'"), "{e}");
    }

    #[test]
    fn auto_weighs_size_bvh_and_adapter() {
        let m = model(true);
        // Small scenes rasterize faster; large ones trace faster once the BVH exists, but not
        // while it still has to be built.
        assert_eq!(m.decide(&work(100_000, true)).backend, Backend::Gpu);
        assert_eq!(m.decide(&work(5_000_000, true)).backend, Backend::Cpu);
        assert_eq!(m.decide(&work(5_000_000, false)).backend, Backend::Gpu);
        // Past the ray caster's limit only the raster path can run; past the GPU's largest
        // texture only the ray caster can.
        let huge = m.decide(&work(crate::trace::MAX_TRIANGLES as u64, true));
        assert_eq!(huge.backend, Backend::Gpu);
        let wide = m.decide(&Workload {
            fits_gpu: false,
            ..work(100_000, true)
        });
        assert_eq!(wide.backend, Backend::Cpu);
        assert!(wide.reason.contains("largest texture"), "{}", wide.reason);
        // Without an adapter, always the CPU, and the reason says so.
        let none = model(false).decide(&work(5_000_000, false));
        assert_eq!(none.backend, Backend::Cpu);
        assert!(none.reason.contains("no GPU adapter") && none.gpu_seconds.is_none());
    }

    #[test]
    fn the_builtin_models_are_plausible_and_say_why_they_are_used() {
        for kind in [
            None,
            Some(wgpu::DeviceType::Cpu),
            Some(wgpu::DeviceType::DiscreteGpu),
        ] {
            let gpu = if kind.is_some() {
                Ok(())
            } else {
                Err("none".into())
            };
            let m = CostModel::builtin(kind, gpu, "a test");
            assert!(m.plausible() && m.source == "built-in (a test)", "{kind:?}");
            assert_eq!(m.gpu.is_ok(), kind.is_some());
        }
        // A hardware GPU wins where lavapipe loses: a large scene's many pixels.
        let big = work(5_000_000, true);
        let soft = CostModel::builtin(Some(wgpu::DeviceType::Cpu), Ok(()), "t").decide(&big);
        let hard = CostModel::builtin(Some(wgpu::DeviceType::DiscreteGpu), Ok(()), "t");
        assert_eq!(soft.backend, Backend::Cpu);
        assert_eq!(hard.decide(&big).backend, Backend::Gpu);
    }

    #[test]
    fn the_calibration_file_round_trips_for_its_machine_only() {
        for gpu in [true, false] {
            let m = model(gpu);
            let v = cache::to_json(&m, "this machine");
            let (cpu, g) = cache::from_json(&v, "this machine").expect("its own machine");
            assert_eq!(cpu.per_box_ray_log2, m.cpu.per_box_ray_log2);
            assert_eq!(g.is_some(), gpu);
            if let (Some(g), Ok(mg)) = (g, &m.gpu) {
                assert_eq!(g.per_pixel, mg.per_pixel);
            }
            assert!(cache::from_json(&v, "another machine").is_none());
        }
        // A missing or non-numeric coefficient is not a model.
        let mut v = cache::to_json(&model(true), "m");
        v["cpu"]["per_box_ray"] = serde_json::Value::String("fast".into());
        assert!(cache::from_json(&v, "m").is_none());
        assert!(model(true).plausible() && model(false).plausible());
        let mut flat = model(true);
        if let Ok(g) = flat.gpu.as_mut() {
            g.per_pixel = 0.0;
        }
        (flat.cpu.per_box_ray, flat.cpu.per_box_ray_log2) = (0.0, -1e-9);
        assert!(!flat.plausible());
        // Mended from another model, a flat slope takes that model's; the others stay.
        let with = CostModel::builtin(Some(wgpu::DeviceType::Cpu), Ok(()), "t");
        flat.mend(&with);
        assert!(flat.plausible());
        assert_eq!(flat.cpu.per_box_ray_log2, with.cpu.per_box_ray_log2);
        assert_eq!(
            flat.cpu.build_per_triangle,
            model(true).cpu.build_per_triangle
        );
        let key = cache::machine(None);
        assert!(key.contains(env!("CARGO_PKG_VERSION")) && key.ends_with("gpu none"));
    }

    #[test]
    fn the_lock_runs_its_work_and_refuses_a_place_it_cannot_make() {
        let dir = std::env::temp_dir().join(format!("scenesample-lock-{}", std::process::id()));
        let path = dir.join("cost-model.json");
        assert_eq!(cache::locked(&path, || Ok(7)).unwrap(), Ok(7));
        assert_eq!(
            cache::locked(&path, || Ok(8)).unwrap(),
            Ok(8),
            "released after use"
        );
        // A lock file under a regular file cannot be made: the work is not run.
        let blocked = path.join("below-a-file.json");
        std::fs::write(&path, "{}").unwrap();
        let r = cache::locked(&blocked, || -> Result<()> { panic!("not to run") });
        assert!(r.unwrap().is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_calibration_file_keeps_each_machine() {
        let dir = std::env::temp_dir().join(format!("scenesample-cache-{}", std::process::id()));
        let path = dir.join("cost-model.json");
        let (a, b) = (model(true), model(false));
        cache::write(&path, "a", &a).unwrap();
        cache::write(&path, "b", &b).unwrap();
        assert!(cache::read(&path, "a").unwrap().1.is_some());
        assert!(cache::read(&path, "b").unwrap().1.is_none());
        assert!(cache::read(&path, "c").is_none());
        std::fs::write(&path, "{half a file").unwrap();
        assert!(cache::read(&path, "a").is_none());
        cache::write(&path, "a", &a).unwrap();
        assert!(cache::read(&path, "a").is_some());
        // A full file evicts other builds' models before this build's, whatever their order:
        // the other keys sort after this build's, so evicting the first key would take ours.
        let ours = |gpu: &str| format!("{}; cpu x; 2 threads; gpu {gpu}", cache::build());
        cache::write(&path, &ours("one"), &a).unwrap();
        for k in 0..20 {
            cache::write(&path, &format!("zz another build {k:02}"), &b).unwrap();
        }
        cache::write(&path, &ours("two"), &b).unwrap();
        assert!(cache::read(&path, &ours("one")).is_some());
        assert!(cache::read(&path, &ours("two")).is_some());
        assert!(cache::read(&path, "zz another build 19").is_some());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
