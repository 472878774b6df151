//! Conventional depth images (non-redundant-rendering.txt §3: every camera samples every surface
//! it sees). The GPU rasterises triangle ids and perspective-correct barycentrics
//! (`gpu::depth`); this module resolves them into depth, world position, geometric normal and
//! base colour in f64 from the scene's f32 vertices, so precision does not depend on the
//! hardware depth buffer or on the scene's distance from the world origin.

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
    let mut img = resolve(scene, cameras, &raw.bary, &raw.triangle);
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

/// Resolve triangle ids + barycentrics into the image fields (parallel over rows).
pub fn resolve(
    scene: &Scene,
    cameras: &[Camera],
    bary: &[[f32; 2]],
    triangle: &[i32],
) -> DepthImages {
    let (w, h) = (cameras[0].width as usize, cameras[0].height as usize);
    let npx = w * h;
    let total = npx * cameras.len();
    let mut img = DepthImages {
        n: cameras.len(),
        width: w as u32,
        height: h as u32,
        depth: vec![f32::INFINITY; total],
        triangle: triangle.to_vec(),
        normal: vec![[0.0; 3]; total],
        position: vec![[f32::NAN; 3]; total],
        color: vec![[0.0; 3]; total],
        cameras: cameras.to_vec(),
        timings: vec![],
    };
    let normals: Vec<DVec3> = (0..scene.triangle_count())
        .into_par_iter()
        .map(|i| scene.face_normal(i))
        .collect();
    let colors = scene.colors();
    img.depth
        .par_chunks_mut(w)
        .zip(img.position.par_chunks_mut(w))
        .zip(img.normal.par_chunks_mut(w))
        .zip(img.color.par_chunks_mut(w))
        .enumerate()
        .for_each(|(row, (((depth, pos), nrm), col))| {
            let cam = &cameras[row / h];
            let (eye, fwd) = (cam.eye(), cam.forward());
            for x in 0..w {
                let k = row * w + x;
                let Ok(t) = usize::try_from(triangle[k]) else {
                    continue;
                };
                let [b1, b2] = bary[k].map(f64::from);
                let b0 = 1.0 - b1 - b2;
                let [a, b, c] = scene.triangle(t);
                let p = a * b0 + b * b1 + c * b2;
                depth[x] = (p - eye).dot(fwd) as f32;
                pos[x] = p.as_vec3().to_array();
                nrm[x] = normals[t].as_vec3().to_array();
                let f = scene.faces()[t];
                let [ca, cb, cc] = f.map(|i| Vec3::from(colors[i as usize]));
                col[x] = (ca * b0 as f32 + cb * b1 as f32 + cc * b2 as f32).to_array();
            }
        });
    img
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
