//! Omnidirectional soft shadows of a spherical light three ways (eye-based-point-rendering.txt
//! §5), plus exact ray-cast visibility as the reference:
//!
//! - **MVR**: every light sample renders the scene's triangles into the six faces of a depth
//!   cube map (one raster pass per face) and every eye point is tested against the face its
//!   direction from the sample falls in (`gpu::shadow`, raster and test on the GPU).
//! - **EPR** (§5.1): points spaced by the eye's pixel footprint at the nearest of the triangle's
//!   shadow volumes (Eq. 5, `super::points::generate_shadow`), splatted into all `6 × samples`
//!   cube faces in one compute pass (§3.5), the faces read back and tested on the CPU.
//! - **iVIR**: the same with points spaced by the cube-map texel at the triangle's distance from
//!   the nearest light sample.
//!
//! The cube maps of all three share one face resolution: given, or the adaptive one of Eq. 6
//! (`adaptive_resolution`). The receivers are the eye's visible surface points (a conventional
//! depth image from the eye), tested with the soft-shadow bias of `gpu::shadow` (texel and
//! slope terms) and the facing rule: a point facing away from a sample does not see it. A
//! splatted face stores each point's centre depth over its whole square; the point-based test
//! instead takes the occluder's depth where the receiver's own ray from the sample meets the
//! stored point's plane (clamped to the depths its square spans), the depth a rasterizer would
//! have stored for that surface.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::points::{self, Density};
use super::splat::{splat_views, Points};
use crate::camera::{Camera, Projection};
use crate::error::Result;
use crate::gpu;
use crate::image::discretize_conventional;
use crate::input_err;
use crate::scene::Scene;
use crate::shadow_rays::{eye_points, per_pixel, raytraced};
use crate::types::{Stats, Timings};

/// The smallest adaptive cube-map face resolution.
pub const MIN_RESOLUTION: u32 = 16;
/// The near plane of the shadow cube maps, as a fraction of the scene's diagonal.
pub const NEAR: f64 = 1e-5;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OmniMethod {
    Epr,
    Mvr,
    Ivir,
    Raytraced,
}

impl OmniMethod {
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "epr" => Some(Self::Epr),
            "mvr" => Some(Self::Mvr),
            "ivir" => Some(Self::Ivir),
            "raytraced" => Some(Self::Raytraced),
            _ => None,
        }
    }
}

#[derive(Debug, Clone)]
pub struct OmniOptions {
    pub samples: u32,
    pub method: OmniMethod,
    pub rho_scale: f64,
    /// Cube-map face resolution; `None`: Eq. 6, at most `max_resolution`.
    pub resolution: Option<u32>,
    pub max_resolution: u32,
    pub seed: u64,
}

#[derive(Debug, Clone)]
pub struct OmniResult {
    pub width: u32,
    pub height: u32,
    /// Fraction of light samples visible from each eye pixel's surface (1 where none).
    pub visibility: Vec<f32>,
    /// Per pixel, per light sample (sample fastest).
    pub visible: Vec<bool>,
    pub mask: Vec<bool>,
    pub samples: Vec<DVec3>,
    /// The cube-map face resolution used (0 for `Raytraced`).
    pub resolution: u32,
    pub stats: Stats,
    pub timings: Timings,
}

/// `n` samples of a spherical light: its centre for one sample, otherwise a Fibonacci lattice
/// on its surface (near-uniform, deterministic). Checked against the memory limit with the six
/// shadow views each sample gets (their maps are checked with their resolution later).
pub fn light_samples(center: DVec3, radius: f64, n: u32) -> Result<Vec<DVec3>> {
    crate::limits::check(
        || format!("{n} light samples"),
        n as u128,
        (std::mem::size_of::<DVec3>() + 6 * std::mem::size_of::<Camera>()) as u64,
    )?;
    if n == 1 {
        return Ok(vec![center]);
    }
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    Ok((0..n)
        .map(|i| {
            let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f64;
            center + DVec3::new(r * phi.cos(), r * phi.sin(), z) * radius
        })
        .collect())
}

/// Eq. 6: the face resolution at which a shadow-map texel, where it lands on a receiver the eye
/// sees, is no larger than the eye's pixel there. A face texel at distance d from a sample spans
/// at most `2 d / res`; the eye's pixel at distance `d_er` spans `θ_pixel · d_er`. With the
/// receivers known (the eye's depth image), `res = max over receivers of 2 d_lr / (θ_pixel ·
/// d_er)`, `d_lr` the receiver's distance from the farthest light sample, clamped to
/// [`MIN_RESOLUTION`, `max_resolution`] and rounded up to a multiple of 8.
pub fn adaptive_resolution(
    eye: &Camera,
    receivers: &[DVec3],
    center: DVec3,
    radius: f64,
    max_resolution: u32,
) -> u32 {
    let e = eye.eye();
    let need = receivers
        .iter()
        .map(|&p| {
            let footprint = match eye.projection {
                Projection::Perspective { .. } => eye.pixel_footprint((p - e).length()),
                Projection::Orthographic { .. } => eye.pixel_footprint(1.0),
            };
            2.0 * ((p - center).length() + radius) / footprint.max(f64::MIN_POSITIVE)
        })
        .fold(0.0, f64::max);
    let res = if need.is_finite() {
        need.ceil().min(max_resolution as f64) as u32
    } else {
        max_resolution
    };
    (res.max(MIN_RESOLUTION).div_ceil(8) * 8).min(max_resolution.max(MIN_RESOLUTION))
}

/// Eq. 6 for the surfaces `eye` sees (one conventional depth image from the eye).
pub fn eye_resolution(
    scene: &Scene,
    eye: &Camera,
    center: DVec3,
    radius: f64,
    max_resolution: u32,
) -> Result<u32> {
    if max_resolution == 0 {
        return input_err!("max_resolution must be at least 1");
    }
    let seen = discretize_conventional(scene, std::slice::from_ref(eye), false)?;
    let (points, _, _) = eye_points(&seen, eye);
    Ok(adaptive_resolution(
        eye,
        &points,
        center,
        radius,
        max_resolution,
    ))
}

/// Omnidirectional soft shadows of the sphere (`center`, `radius`) on what `eye` sees.
pub fn omni_shadows(
    scene: &Scene,
    eye: &Camera,
    center: DVec3,
    radius: f64,
    opts: &OmniOptions,
) -> Result<OmniResult> {
    let total = Instant::now();
    check_light(center, radius, opts)?;
    let mut timings = Timings::new();
    let mut stats = Stats::new();

    let start = Instant::now();
    let seen = discretize_conventional(scene, std::slice::from_ref(eye), false)?;
    let (points, normals, mask) = eye_points(&seen, eye);
    timings.add("eye", start.elapsed().as_secs_f64());

    let samples = light_samples(center, radius, opts.samples)?;
    let s_count = samples.len();
    let diagonal = scene.diagonal();
    let start = Instant::now();
    let res = match (opts.method, opts.resolution) {
        (OmniMethod::Raytraced, _) => 0,
        (_, Some(r)) => r,
        (_, None) => adaptive_resolution(eye, &points, center, radius, opts.max_resolution),
    };
    timings.add("resolution", start.elapsed().as_secs_f64());
    let near = NEAR * diagonal;
    let bits = match opts.method {
        OmniMethod::Raytraced => {
            let start = Instant::now();
            let bits = raytraced(scene, &samples, &points, &normals, diagonal)?;
            timings.add("shadow", start.elapsed().as_secs_f64());
            bits
        }
        OmniMethod::Mvr => mvr_bits(
            scene,
            &samples,
            (res, near),
            (&points, &normals),
            &mut timings,
            &mut stats,
        )?,
        OmniMethod::Epr | OmniMethod::Ivir => splatted_bits(
            scene,
            eye,
            &samples,
            (res, near),
            (&points, &normals),
            opts,
            &mut timings,
            &mut stats,
        )?,
    };

    let (visible, visibility) = per_pixel(&bits, &mask, s_count);
    stats.set("light_samples", s_count as f64);
    stats.set("views", if res == 0 { 0.0 } else { 6.0 * s_count as f64 });
    stats.set("resolution", res as f64);
    stats.set("receivers", points.len() as f64);
    timings.add("total", total.elapsed().as_secs_f64());
    Ok(OmniResult {
        width: eye.width,
        height: eye.height,
        visibility,
        visible,
        mask,
        samples,
        resolution: res,
        stats,
        timings,
    })
}

/// Refuses a non-finite or negative light, no light samples, a zero resolution and a
/// non-positive `rho_scale`.
fn check_light(center: DVec3, radius: f64, opts: &OmniOptions) -> Result<()> {
    if !(center.is_finite() && radius.is_finite() && radius >= 0.0) {
        return input_err!(
            "the light's centre {center:?} and radius {radius} must be finite, the radius >= 0"
        );
    }
    if opts.samples == 0 {
        return input_err!("light_samples must be at least 1");
    }
    if opts.max_resolution == 0 || opts.resolution == Some(0) {
        return input_err!("cube-map resolutions must be at least 1");
    }
    if !(opts.rho_scale.is_finite() && opts.rho_scale > 0.0) {
        return input_err!("rho_scale must be finite and > 0, got {}", opts.rho_scale);
    }
    Ok(())
}

/// MVR (§5): six rasterized shadow views per light sample; a receiver is lit by a sample when
/// every face's test passes (a point outside a face's view is lit by that face). Returns the
/// visibility bits, one word per 32 receivers, per light sample.
fn mvr_bits(
    scene: &Scene,
    samples: &[DVec3],
    (res, near): (u32, f64),
    (points, normals): (&[DVec3], &[DVec3]),
    timings: &mut Timings,
    stats: &mut Stats,
) -> Result<Vec<u32>> {
    let s_count = samples.len();
    let diagonal = scene.diagonal();
    let start = Instant::now();
    let cams = points::shadow_views(samples, res, near)?;
    let ctx = gpu::context()?;
    let (per_face, _) = gpu::shadow::visibility(
        &ctx,
        scene.vertices(),
        scene.faces(),
        scene.center(),
        scene.bounds(),
        &cams,
        points,
        normals,
        diagonal,
    )?;
    // A point outside a face's view is lit by that face: AND over the six.
    let words = points.len().div_ceil(32).max(1);
    let mut bits = vec![u32::MAX; words * s_count];
    for (v, face) in per_face.chunks(words).enumerate() {
        for (w, &b) in face.iter().enumerate() {
            bits[(v / 6) * words + w] &= b;
        }
    }
    timings.add("shadow", start.elapsed().as_secs_f64());
    stats.set(
        "triangles_drawn",
        (scene.triangle_count() * cams.len()) as f64,
    );
    Ok(bits)
}

/// EPR or iVIR (§5.1, splatted as §3.5): the shadow points of the eye's receivers, splatted
/// into six views per light sample and tested against the splatted keys. Returns the
/// visibility bits as `mvr_bits`.
#[allow(clippy::too_many_arguments)]
fn splatted_bits(
    scene: &Scene,
    eye: &Camera,
    samples: &[DVec3],
    (res, near): (u32, f64),
    (points, normals): (&[DVec3], &[DVec3]),
    opts: &OmniOptions,
    timings: &mut Timings,
    stats: &mut Stats,
) -> Result<Vec<u32>> {
    let diagonal = scene.diagonal();
    let density = if opts.method == OmniMethod::Epr {
        Density::Eye {
            rho_scale: opts.rho_scale,
        }
    } else {
        Density::OffScreen
    };
    let start = Instant::now();
    let pts = points::generate_shadow(scene, eye, samples, res, near, density, opts.seed)?;
    timings.add("points", start.elapsed().as_secs_f64());
    stats.extend(&pts.stats);
    let cams = points::shadow_views(samples, res, near)?;
    let start = Instant::now();
    // Clipped to the triangle: unclipped squares overhang silhouettes and over-shadow.
    let (keys, splat_timings) = splat_views(scene, &pts, &cams, true)?;
    timings.add("splat", start.elapsed().as_secs_f64());
    if let Some(gpu) = splat_timings.get("splat") {
        timings.add("splat_gpu", gpu);
    }
    let start = Instant::now();
    let bits = test_splatted(&keys, &pts, &cams, samples, points, normals, diagonal);
    timings.add("test", start.elapsed().as_secs_f64());
    stats.set(
        "buffer_bytes",
        (keys.len() * std::mem::size_of::<u64>()) as f64,
    );
    Ok(bits)
}

/// Test every receiver against the splatted cube faces of every light sample: bits as
/// `gpu::shadow::visibility` returns them (per sample, bit k of word w is receiver 32w + k).
fn test_splatted(
    keys: &[u64],
    pts: &Points,
    cams: &[Camera],
    samples: &[DVec3],
    receivers: &[DVec3],
    normals: &[DVec3],
    diagonal: f64,
) -> Vec<u32> {
    let res = cams[0].width as usize;
    let face_len = res * res;
    let words = receivers.len().div_ceil(32).max(1);
    let abs_bias = gpu::shadow::ABS_BIAS * diagonal;
    let lit = |k: usize, s: usize| -> bool {
        let (p, n, l) = (receivers[k], normals[k], samples[s]);
        let to_light = l - p;
        let dist = to_light.length();
        let c = n.dot(to_light) / dist.max(f64::MIN_POSITIVE);
        if c.is_nan() || c <= 0.0 {
            return false;
        }
        let f = 6 * s + Camera::cube_face(p - l);
        let cam = &cams[f];
        let (px, z) = cam.project(p);
        if !(px.is_finite() && z > 0.0) {
            return true;
        }
        let x = (px.x.max(0.0) as usize).min(res - 1);
        let y = (px.y.max(0.0) as usize).min(res - 1);
        let key = keys[f * face_len + y * res + x];
        if key == u64::MAX {
            return true;
        }
        let stored = f32::from_bits((key >> 32) as u32) as f64;
        let idx = (key & 0xffff_ffff) as usize;
        let tan = |cos: f64| (cos.abs().max(1e-12).recip().powi(2) - 1.0).max(0.0).sqrt();
        // The occluder's depth on the receiver's own ray: where the ray from the sample meets
        // the stored point's plane, kept within the depth its square spans around its centre.
        let occluder = match pts.normal.get(idx) {
            Some(no) => {
                let no = DVec3::from_array(no.map(f64::from));
                let c = DVec3::from_array(pts.center[idx].map(f64::from));
                let fwd = cam.forward();
                let spread = pts.length[idx] as f64
                    * std::f64::consts::FRAC_1_SQRT_2
                    * tan(no.dot(fwd)).min(1e6);
                let u = (p - l) / dist;
                let t = no.dot(c - l) / no.dot(u);
                let z_plane = t * u.dot(fwd);
                if z_plane.is_finite() {
                    z_plane.clamp(stored - spread, stored + spread)
                } else {
                    stored
                }
            }
            None => stored,
        };
        let bias = 1.5 * cam.pixel_footprint(z) * (1.0 + tan(c).min(8.0)) + abs_bias;
        z <= occluder + bias
    };
    let mut bits = vec![0u32; words * samples.len()];
    bits.par_chunks_mut(words).enumerate().for_each(|(s, out)| {
        for (w, word) in out.iter_mut().enumerate() {
            for b in 0..32 {
                let k = 32 * w + b;
                if k < receivers.len() && lit(k, s) {
                    *word |= 1 << b;
                }
            }
        }
    });
    bits
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn light_samples_lie_on_the_sphere_and_spread() {
        let c = DVec3::new(1.0, 2.0, 3.0);
        let s = light_samples(c, 0.5, 20).unwrap();
        assert_eq!(s.len(), 20);
        for p in &s {
            assert!(((*p - c).length() - 0.5).abs() < 1e-12);
        }
        let mean = s.iter().copied().sum::<DVec3>() / 20.0;
        assert!((mean - c).length() < 0.05, "{mean}");
        assert_eq!(light_samples(c, 0.5, 1).unwrap(), vec![c]);
    }

    #[test]
    fn the_adaptive_resolution_grows_as_receivers_near_the_eye() {
        let eye = Camera::look_at(
            DVec3::new(0.0, 0.0, 5.0),
            DVec3::ZERO,
            DVec3::Y,
            1.0,
            100,
            100,
            None,
            None,
        )
        .unwrap();
        let far = adaptive_resolution(&eye, &[DVec3::ZERO], DVec3::new(0.0, 3.0, 0.0), 0.0, 4096);
        let near = adaptive_resolution(
            &eye,
            &[DVec3::new(0.0, 0.0, 2.5)],
            DVec3::new(0.0, 3.0, 0.0),
            0.0,
            4096,
        );
        assert!(near > far, "{near} vs {far}");
        // 2 * 3 / (2 tan(0.5) / 100 * 5) = 109.8 -> 112.
        assert_eq!(far, 112);
        assert_eq!(
            adaptive_resolution(&eye, &[DVec3::ZERO], DVec3::new(0.0, 3.0, 0.0), 0.0, 64),
            64
        );
    }
}
