//! Points and their splatting into many off-screen views at once
//! (eye-based-point-rendering.txt §3.4-3.5).
//!
//! A point is a world-space square: its centre, its side `length` (Eq. 4), the triangle it
//! samples (the square lies in that triangle's plane, aligned with its longest edge) and a
//! visibility bit string saying which views may see it (§3.1). `splat` scatters every point into
//! every view whose bit is set, on the GPU (`gpu::splat`, `shaders/splat.wgsl`): the pixels of the
//! bounding box of the square's projection, optionally only those overlapping the projected
//! triangle, keep the nearest point through a 64-bit atomic on (depth bits << 32 | index).

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::camera::Camera;
use crate::error::Result;
use crate::gpu;
use crate::input_err;
use crate::scene::Scene;
pub use crate::types::{Points, Timings};

/// Off-screen buffers filled by `splat`: one W×H buffer per view.
#[derive(Debug, Clone)]
pub struct SplatBuffers {
    pub width: u32,
    pub height: u32,
    pub views: usize,
    /// (depth bits << 32 | point index), `u64::MAX` where no point landed; view-major.
    pub packed: Vec<u64>,
    pub timings: Timings,
}

impl SplatBuffers {
    /// Camera-space depth per pixel, +inf where empty.
    pub fn depth(&self) -> Vec<f32> {
        self.packed
            .iter()
            .map(|&k| {
                if k == u64::MAX {
                    f32::INFINITY
                } else {
                    f32::from_bits((k >> 32) as u32)
                }
            })
            .collect()
    }

    /// Point index per pixel, −1 where empty.
    pub fn index(&self) -> Vec<i32> {
        self.packed
            .iter()
            .map(|&k| {
                if k == u64::MAX {
                    -1
                } else {
                    (k & 0xffff_ffff) as u32 as i32
                }
            })
            .collect()
    }
}

/// Splat `points` (which sample `scene`) into one buffer per camera; all cameras share one
/// resolution and the points' bit strings describe exactly these views.
pub fn splat(
    scene: &Scene,
    points: &Points,
    cameras: &[Camera],
    clip_to_triangle: bool,
) -> Result<SplatBuffers> {
    let Some(first) = cameras.first() else {
        return input_err!("splat needs at least one view");
    };
    if let Some(c) = cameras
        .iter()
        .find(|c| (c.width, c.height) != (first.width, first.height))
    {
        return input_err!(
            "every view must have one resolution: {}x{} and {}x{} given (pass resolution= to \
             resize them)",
            first.width,
            first.height,
            c.width,
            c.height
        );
    }
    let (packed, timings) = splat_views(scene, points, cameras, clip_to_triangle)?;
    Ok(SplatBuffers {
        width: first.width,
        height: first.height,
        views: cameras.len(),
        packed,
        timings,
    })
}

/// Like `splat`, for views of any sizes: the keys of every view, one after another (each
/// row-major at its own resolution), and the timings.
pub fn splat_views(
    scene: &Scene,
    points: &Points,
    cameras: &[Camera],
    clip_to_triangle: bool,
) -> Result<(Vec<u64>, Timings)> {
    let total = Instant::now();
    if cameras.is_empty() {
        return input_err!("splat needs at least one view");
    }
    // The packed keys, then depth and index per texel.
    crate::limits::check_views("the splat buffers", cameras, 16)?;
    if points.view_count != cameras.len() {
        return input_err!(
            "the points' visibility strings describe {} views, but {} views were given",
            points.view_count,
            cameras.len()
        );
    }
    points.validate(scene)?;
    if points.len() >= u32::MAX as usize {
        return input_err!(
            "{} points: a splat key holds a 32-bit point index, so at most {} points",
            points.len(),
            u32::MAX - 1
        );
    }
    let start = Instant::now();
    let ctx = gpu::context()?;
    let device_seconds = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let geometry = square_geometry(scene, points);
    let prepare_seconds = start.elapsed().as_secs_f64();
    let input = gpu::splat::PointBuffersIn {
        geometry: &geometry,
        bits: &points.views,
        words: points.words(),
    };
    let (packed, stats) = gpu::splat::splat(
        &ctx,
        &input,
        cameras,
        scene.center(),
        scene.bounds(),
        clip_to_triangle,
    )?;
    Ok((
        packed,
        Timings::from([
            ("device", device_seconds),
            ("prepare", prepare_seconds),
            ("pairs", stats.pairs_seconds),
            ("upload", stats.upload_seconds),
            ("splat", stats.splat_seconds),
            ("readback", stats.readback_seconds),
            ("total", total.elapsed().as_secs_f64()),
        ]),
    ))
}

/// Per point, what the splat shader reads (`gpu::splat::GEOMETRY_FLOATS` floats, positions
/// relative to the scene centre): the centre and half the side; the square's unit axes, u along
/// the triangle's longest edge and v across it in the triangle's plane (x and y for a
/// degenerate triangle); the triangle's vertices relative to the centre in (u, v) coordinates,
/// zero for a degenerate triangle, which the shader then does not clip to. Computed once per
/// point in f64, so the GPU does per (point, view) pair only what depends on the view.
fn square_geometry(scene: &Scene, points: &Points) -> Vec<[f32; gpu::splat::GEOMETRY_FLOATS]> {
    let origin = scene.center();
    points
        .center
        .par_iter()
        .zip(&points.length)
        .zip(&points.triangle)
        .map(|((p, &length), &t)| {
            let c = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let [v0, v1, v2] = scene.triangle(t as usize);
            let edges = [v1 - v0, v2 - v1, v0 - v2];
            let along = edges
                .iter()
                .copied()
                .reduce(|a, e| {
                    if e.length_squared() > a.length_squared() {
                        e
                    } else {
                        a
                    }
                })
                .unwrap_or(DVec3::X);
            let n = edges[0].cross(-edges[2]);
            let (la, ln) = (along.length(), n.length());
            let flat = !(la > 0.0 && ln > 0.0);
            let (u, v) = if flat {
                (DVec3::X, DVec3::Y)
            } else {
                let u = along / la;
                (u, (n / ln).cross(u))
            };
            let rel = c - origin;
            let mut g = [0f32; gpu::splat::GEOMETRY_FLOATS];
            g[..4].copy_from_slice(&[rel.x as f32, rel.y as f32, rel.z as f32, 0.5 * length]);
            g[4..7].copy_from_slice(&u.as_vec3().to_array());
            g[7..10].copy_from_slice(&v.as_vec3().to_array());
            if !flat {
                for (k, w) in [v0, v1, v2].into_iter().enumerate() {
                    let d = w - c;
                    g[10 + 2 * k] = d.dot(u) as f32;
                    g[11 + 2 * k] = d.dot(v) as f32;
                }
            }
            g
        })
        .collect()
}
