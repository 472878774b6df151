//! Conventional depth images (non-redundant-rendering.txt §3: every camera samples every surface
//! it sees). The GPU rasterises the id of the nearest triangle at each pixel centre
//! (`gpu::depth`); this module resolves each id into depth, world position, geometric normal and
//! base colour by intersecting the pixel-centre ray with that triangle's plane in f64. That is
//! the exact point perspective-correct interpolation approximates, so precision depends neither
//! on the hardware depth buffer, nor on f32 interpolation, nor on the scene's distance from the
//! world origin.

use std::time::Instant;

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::error::Result;
use crate::gpu;
use crate::input_err;
use crate::scene::Scene;

/// `n` images of `height`×`width`, row-major, image after image.
#[derive(Debug, Clone, Default)]
pub struct DepthImages {
    pub n: usize,
    pub width: u32,
    pub height: u32,
    /// Camera-space z (positive), +inf where no surface.
    pub depth: Vec<f32>,
    /// Scene face index, −1 where no surface.
    pub triangle: Vec<i32>,
    /// Unit world geometric normal from the triangle's winding (not flipped toward the camera);
    /// zero where no surface or the triangle is degenerate.
    pub normal: Vec<[f32; 3]>,
    /// World position of the surface point; NaN where no surface.
    pub position: Vec<[f32; 3]>,
    /// Linear base colour interpolated from the vertices; zero where no surface.
    pub color: Vec<[f32; 3]>,
    pub cameras: Vec<Camera>,
    /// (stage, seconds), in the order the stages ran.
    pub timings: Vec<(String, f64)>,
}

/// Render one conventional depth image per camera. Cameras may differ in pose and projection
/// but must share a resolution. No back-face culling unless `cull_backfaces`.
pub fn discretize_conventional(
    scene: &Scene,
    cameras: &[Camera],
    cull_backfaces: bool,
) -> Result<DepthImages> {
    let total = Instant::now();
    let Some(first) = cameras.first() else {
        return input_err!("discretize needs at least one camera");
    };
    if let Some((i, c)) = cameras
        .iter()
        .enumerate()
        .find(|(_, c)| (c.width, c.height) != (first.width, first.height))
    {
        return input_err!(
            "cameras of one call must share a resolution: camera 0 is {}x{}, camera {i} is {}x{}",
            first.width,
            first.height,
            c.width,
            c.height
        );
    }
    let ctx = gpu::context()?;
    let raw = gpu::depth::rasterize(&ctx, scene, cameras, cull_backfaces)?;
    let start = Instant::now();
    let mut img = resolve(scene, cameras, raw.triangle);
    let resolve_seconds = start.elapsed().as_secs_f64();
    img.timings = vec![
        ("upload".into(), raw.upload_seconds),
        ("raster".into(), raw.raster_seconds),
    ];
    if let Some(g) = raw.gpu_seconds {
        img.timings.push(("raster_gpu".into(), g));
    }
    img.timings.push(("readback".into(), raw.readback_seconds));
    img.timings.push(("resolve".into(), resolve_seconds));
    img.timings
        .push(("total".into(), total.elapsed().as_secs_f64()));
    Ok(img)
}

/// Per-camera constants of the pixel-centre rays (see `Camera::ray_z1`): the ray through pixel
/// (x, y) is `origin(x, y) + t·dir(x, y)` with camera-space z of `dir` equal to −1, so `t` is
/// the depth.
struct PixelRays {
    eye: DVec3,
    /// World-space steps per pixel along x and y, and the ray at pixel (0, 0)'s corner.
    dx: DVec3,
    dy: DVec3,
    corner: DVec3,
    orthographic: bool,
    forward: DVec3,
}

impl PixelRays {
    fn new(cam: &Camera) -> Self {
        let (o00, d00) = cam.ray_z1(glam::DVec2::ZERO);
        let (o10, d10) = cam.ray_z1(glam::DVec2::X);
        let (o01, d01) = cam.ray_z1(glam::DVec2::Y);
        let orthographic = matches!(
            cam.projection,
            crate::camera::Projection::Orthographic { .. }
        );
        if orthographic {
            Self {
                eye: o00,
                dx: o10 - o00,
                dy: o01 - o00,
                corner: o00,
                orthographic,
                forward: d00,
            }
        } else {
            Self {
                eye: o00,
                dx: d10 - d00,
                dy: d01 - d00,
                corner: d00,
                orthographic,
                forward: cam.forward(),
            }
        }
    }

    fn ray(&self, x: usize, y: usize) -> (DVec3, DVec3) {
        let p = self.corner + self.dx * (x as f64 + 0.5) + self.dy * (y as f64 + 0.5);
        if self.orthographic {
            (p, self.forward)
        } else {
            (self.eye, p)
        }
    }
}

/// Resolve triangle ids into the image fields (parallel over rows).
pub fn resolve(scene: &Scene, cameras: &[Camera], triangle: Vec<i32>) -> DepthImages {
    let (w, h) = (cameras[0].width as usize, cameras[0].height as usize);
    let total = w * h * cameras.len();
    let mut img = DepthImages {
        n: cameras.len(),
        width: w as u32,
        height: h as u32,
        // Zeroed allocations are lazily mapped pages: the parallel pass below is the first and
        // only writer of every pixel (misses included), so nothing is filled twice.
        depth: vec![0.0; total],
        triangle,
        normal: vec![[0.0; 3]; total],
        position: vec![[0.0; 3]; total],
        color: vec![[0.0; 3]; total],
        cameras: cameras.to_vec(),
        timings: vec![],
    };
    let rays: Vec<PixelRays> = cameras.iter().map(PixelRays::new).collect();
    let colors = scene.colors();
    let ids = &img.triangle;
    img.depth
        .par_chunks_mut(w)
        .zip(img.position.par_chunks_mut(w))
        .zip(img.normal.par_chunks_mut(w))
        .zip(img.color.par_chunks_mut(w))
        .enumerate()
        .for_each(|(row, (((depth, pos), nrm), col))| {
            let cam = &rays[row / h];
            for x in 0..w {
                let Ok(t) = usize::try_from(ids[row * w + x]) else {
                    depth[x] = f32::INFINITY;
                    pos[x] = [f32::NAN; 3];
                    continue;
                };
                let (o, d) = cam.ray(x, row % h);
                let s = surface_point(scene, t, o, d, cam.forward);
                depth[x] = s.depth as f32;
                pos[x] = s.point.as_vec3().to_array();
                nrm[x] = s.normal.as_vec3().to_array();
                let [ca, cb, cc] = scene.faces()[t].map(|i| Vec3::from(colors[i as usize]));
                let [b0, b1, b2] = s.bary.map(|b| b as f32);
                col[x] = (ca * b0 + cb * b1 + cc * b2).to_array();
            }
        });
    img
}

struct SurfacePoint {
    depth: f64,
    point: DVec3,
    /// Unit geometric normal (zero for a degenerate triangle).
    normal: DVec3,
    /// Barycentrics of the point, clamped to the triangle (for attribute interpolation).
    bary: [f64; 3],
}

/// Where the ray `o + t·d` (camera-space z of `d` is −1, so `t` is depth) meets triangle `t`'s
/// plane. The rasteriser said the triangle covers this pixel centre, so the ray meets the plane
/// unless the triangle is edge-on or degenerate; then the triangle's centroid stands in.
fn surface_point(scene: &Scene, tri: usize, o: DVec3, d: DVec3, forward: DVec3) -> SurfacePoint {
    let [a, b, c] = scene.triangle(tri);
    let (e1, e2) = (b - a, c - a);
    let n = e1.cross(e2);
    let nn = n.length_squared();
    let denom = n.dot(d);
    let t = n.dot(a - o) / denom;
    if nn == 0.0 || !t.is_finite() || scene.is_degenerate(tri) {
        let p = (a + b + c) / 3.0;
        let normal = scene.face_normal(tri);
        return SurfacePoint {
            depth: (p - o).dot(forward),
            point: p,
            normal,
            bary: [1.0 / 3.0; 3],
        };
    }
    let p = o + d * t;
    let r = p - a;
    let b1 = r.cross(e2).dot(n) / nn;
    let b2 = e1.cross(r).dot(n) / nn;
    let clamp = |v: f64| v.clamp(0.0, 1.0);
    let (b1, b2) = (clamp(b1), clamp(b2));
    let s = b1 + b2;
    let (b1, b2) = if s > 1.0 { (b1 / s, b2 / s) } else { (b1, b2) };
    SurfacePoint {
        depth: t,
        point: p,
        normal: n / nn.sqrt(),
        bary: [1.0 - b1 - b2, b1, b2],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// A unit square at z = 0 seen from z = 2 (or from far away, far from the origin).
    fn square(offset: f32) -> Scene {
        let v = vec![[-1., -1., 0.], [1., -1., 0.], [1., 1., 0.], [-1., 1., 0.]];
        let v = v
            .into_iter()
            .map(|p: [f32; 3]| [p[0] + offset, p[1], p[2] + offset])
            .collect();
        Scene::from_arrays(v, vec![[0, 1, 2], [0, 2, 3]], None, None).unwrap()
    }

    fn gpu_or_skip() -> bool {
        match gpu::context() {
            Ok(_) => true,
            Err(e) => {
                eprintln!("skipping: {e}");
                false
            }
        }
    }

    #[test]
    fn square_depth_and_ids() {
        if !gpu_or_skip() {
            return;
        }
        for offset in [0.0f32, 1e5] {
            let s = square(offset);
            let o = offset as f64;
            let cam = Camera::look_at(
                DVec3::new(o, 0.0, 2.0 + o),
                DVec3::new(o, 0.0, o),
                DVec3::Y,
                1.2,
                16,
                12,
                None,
                None,
            )
            .unwrap();
            let img = discretize_conventional(&s, &[cam], false).unwrap();
            let covered = img.triangle.iter().filter(|&&t| t >= 0).count();
            assert!(covered > 50 && covered < 16 * 12, "{covered}");
            for k in 0..img.depth.len() {
                if img.triangle[k] >= 0 {
                    assert!(
                        (img.depth[k] - 2.0).abs() < 1e-6,
                        "depth {} at {k} (offset {offset})",
                        img.depth[k]
                    );
                    assert_eq!(img.normal[k], [0.0, 0.0, 1.0]);
                } else {
                    assert_eq!(img.depth[k], f32::INFINITY);
                }
            }
        }
    }
}
