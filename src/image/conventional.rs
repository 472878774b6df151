//! Conventional depth images (non-redundant-rendering.txt §3: every camera samples every surface
//! it sees). The GPU rasterises the id of the nearest triangle at each pixel centre
//! (`gpu::depth`); this module resolves each id into depth, world position, geometric normal and
//! base colour by intersecting the pixel-centre ray with that triangle's plane in f64. That is
//! the exact point perspective-correct interpolation approximates, so precision depends neither
//! on the hardware depth buffer, nor on f32 interpolation, nor on the scene's distance from the
//! world origin.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::pixels::{
    pixel_rays_f32, resolve_ids, resolve_into, PixelRays, SurfacePlane, TraceFrame, ViewRays,
};
use super::raster_rule;
use super::Sample;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu;
use crate::input_err;
use crate::scene::Scene;
use crate::trace::nearest_hits_facing;
use crate::types::{DepthImages, Timings};

/// Render one conventional depth image per camera. Cameras may differ in pose and projection
/// but must share a resolution. No back-face culling unless `cull_backfaces`.
pub fn discretize_conventional(
    scene: &Scene,
    cameras: &[Camera],
    cull_backfaces: bool,
) -> Result<DepthImages> {
    discretize_ranges(scene, cameras, cull_backfaces, None)
}

/// Conventional images under glTF's sidedness (`Material::double_sided`): the back faces of
/// single-sided triangles are not drawn, those of double-sided ones are. These are the
/// reflections' off-screen views (eye-based-point-rendering.txt §3.2 samples a triangle only for
/// the views it faces). One culled draw when every triangle is single-sided, one unculled draw
/// when every one is double-sided; otherwise the two kinds are drawn separately (culled and
/// not) and each pixel keeps the nearer.
pub fn discretize_sided(scene: &Scene, cameras: &[Camera]) -> Result<DepthImages> {
    let double: Vec<bool> = (0..scene.triangle_count())
        .map(|t| scene.is_double_sided(t))
        .collect();
    if !double.contains(&true) || !double.contains(&false) {
        return discretize_conventional(scene, cameras, !double.contains(&true));
    }
    // Runs of consecutive triangles of one kind: [a, b) ranges.
    let runs = |kind: bool| {
        let mut out = Vec::new();
        for (t, _) in double.iter().enumerate().filter(|(_, &d)| d == kind) {
            push_range(&mut out, t as u32, t as u32 + 1);
        }
        out
    };
    let mut near = discretize_ranges(scene, cameras, true, Some(&runs(false)))?;
    let other = discretize_ranges(scene, cameras, false, Some(&runs(true)))?;
    for i in 0..near.depth.len() {
        if other.depth[i] < near.depth[i] {
            near.copy_pixel(i, &other, i);
        }
    }
    near.timings.merge(&other.timings);
    Ok(near)
}

/// Append the face range `[a, b)` to `ranges`, merged into the last one when it starts where
/// that one ends, so that `discretize_ranges` makes as few draws as it can.
pub fn push_range(ranges: &mut Vec<(u32, u32)>, a: u32, b: u32) {
    match ranges.last_mut() {
        Some(last) if last.1 == a => last.1 = b,
        _ => ranges.push((a, b)),
    }
}

/// Like `discretize_conventional`, drawing only the triangles in `ranges` (`[a, b)` index
/// ranges of the scene's faces, e.g. the visibility field's marked cells) when given.
pub fn discretize_ranges(
    scene: &Scene,
    cameras: &[Camera],
    cull_backfaces: bool,
    ranges: Option<&[(u32, u32)]>,
) -> Result<DepthImages> {
    let total = Instant::now();
    check_cameras(cameras)?;
    if let Some(rs) = ranges {
        let n = scene.triangle_count() as u32;
        if let Some(&(a, b)) = rs.iter().find(|&&(a, b)| a > b || b > n) {
            return input_err!("triangle range [{a}, {b}) is not within the scene's {n} faces");
        }
    }
    resolve_streamed(scene, cameras, total, |ctx, on_chunk| {
        gpu::depth::rasterize(ctx, scene, cameras, cull_backfaces, ranges, on_chunk)
    })
}

/// Conventional images without the GPU (the `"cpu"` backend): each camera's pixel-centre rays
/// cast through the scene's BVH on all cores between its near and far planes (back faces passed
/// through when culling), and each pixel's nearest triangle resolved by the same f64 code as
/// the raster path ([`resolve_ids`]). The images
/// equal the raster path's in every field and convention. Pixel centres on an edge are then
/// decided by the rasteriser's rule (`raster_rule`: snapped vertices, top-left fill), so
/// triangle ids differ from the raster path's only where its own f32 transform rounds a vertex
/// differently, or at depth ties.
pub fn discretize_traced(
    scene: &Scene,
    cameras: &[Camera],
    cull_backfaces: bool,
) -> Result<DepthImages> {
    let total = Instant::now();
    check_cameras(cameras)?;
    let first = &cameras[0];
    let npx = first.width as usize * first.height as usize;
    let mut ids = Vec::new();
    ids.try_reserve_exact(npx * cameras.len()).map_err(|_| {
        Error::Input(format!(
            "{} images of {}x{} do not fit in host memory",
            cameras.len(),
            first.width,
            first.height
        ))
    })?;
    let mut timings = Timings::new();
    for cam in cameras {
        crate::process::check()?;
        let (image, stages) = traced_ids(scene, cam, cull_backfaces)?;
        ids.extend_from_slice(&image);
        timings.merge(&stages);
    }
    let (mut img, resolve_seconds) = resolve_ids(scene, cameras, ids)?;
    img.timings = Timings::from([
        ("bvh", timings.get("bvh").unwrap_or(0.0)),
        ("trace", timings.get("trace").unwrap_or(0.0)),
        ("edges", timings.get("edges").unwrap_or(0.0)),
        ("resolve", resolve_seconds),
        ("total", total.elapsed().as_secs_f64()),
    ]);
    Ok(img)
}

/// The nearest triangle at each pixel centre of `cam` between its near and far planes (−1
/// where none; centres on an edge decided by the raster's rule), and the seconds spent
/// building the BVH (`bvh`, 0 when it was built), casting (`trace`) and on the edges (`edges`).
fn traced_ids(scene: &Scene, cam: &Camera, cull_backfaces: bool) -> Result<(Vec<i32>, Timings)> {
    let view = ViewRays::of(scene, cam)?;
    let (origins, dirs) = pixel_rays_f32(cam, &view.frame);
    let target = view.target(scene);
    let hits = nearest_hits_facing(target, &origins, &dirs, 1, &view.range(), cull_backfaces)?;
    let mut out = hits.triangle;
    let (changes, edge_seconds) =
        raster_rule::settle_edges(scene, cam, cull_backfaces, &view.frame, &out, None)?;
    for (p, t) in changes {
        out[p] = t;
    }
    Ok((
        out,
        Timings::from([
            ("bvh", hits.bvh_build_seconds),
            ("trace", hits.trace_seconds),
            ("edges", edge_seconds),
        ]),
    ))
}

/// How [`walk`] walks: culling back faces or not, up to which depth, and in which frame.
pub(crate) struct Walk<'a> {
    pub cull_backfaces: bool,
    /// Surfaces beyond this depth end the walk (the pixel stays empty).
    pub far: f64,
    /// Cast in this frame (the scene's centred copy far from the origin); `None`: the scene.
    pub frame: Option<&'a TraceFrame>,
}

impl Walk<'_> {
    /// No far plane, in the scene's own frame.
    pub(crate) fn plain(cull_backfaces: bool) -> Self {
        Walk {
            cull_backfaces,
            far: f64::INFINITY,
            frame: None,
        }
    }
}

/// What a walk found: `(pixel, triangle)` for the pixels that found a sample, and the seconds
/// its ray casts spent building the BVH (0 when it was built) and tracing.
pub(crate) struct Walked {
    pub found: Vec<(usize, i32)>,
    pub bvh_seconds: f64,
    pub trace_seconds: f64,
}

/// Walk pixel rays of `cam` front to back: each `(pixel, depth)` of `start` casts from that
/// depth, and every surface it meets is a candidate sample, which `redundant` tests (a batch
/// at a time); the first candidate not redundant (nor a culled back face) is the pixel's
/// sample. A walk resumes just beyond each rejected surface, past the tolerance that makes two
/// surfaces the same point, so it always advances. Non-redundant images under visibility
/// redundancy, and the coincident-triangle fix-up, test each candidate against the earlier
/// images.
pub(crate) fn walk(
    scene: &Scene,
    cam: &Camera,
    start: Vec<(usize, f64)>,
    how: Walk,
    mut redundant: impl FnMut(&[Sample]) -> Result<Vec<bool>>,
) -> Result<Walked> {
    let w = cam.width as usize;
    let rays = PixelRays::new(cam);
    let tolerance = super::tolerance(scene);
    let (target, shift) = match how.frame {
        Some(f) => (f.scene(scene), f.shift),
        None => (scene, DVec3::ZERO),
    };
    let mut walked = Walked {
        found: Vec::new(),
        bvh_seconds: 0.0,
        trace_seconds: 0.0,
    };
    let mut active = start;
    while !active.is_empty() {
        // Resume from depth `from`: the ray's direction has camera z −1, so t is depth.
        let (origins, dirs): (Vec<[f32; 3]>, Vec<[f32; 3]>) = active
            .par_iter()
            .map(|&(p, from)| {
                let (o, d) = rays.ray(p % w, p / w);
                (
                    (o + d * from - shift).as_vec3().to_array(),
                    d.as_vec3().to_array(),
                )
            })
            .unzip();
        let hits = crate::trace::cast_rays(target, &origins, &dirs, 0.0, f32::INFINITY)?;
        walked.bvh_seconds += hits.bvh_build_seconds;
        walked.trace_seconds += hits.trace_seconds;
        // (pixel, depth of the surface met, candidate index or none for a culled back face)
        let mut met = Vec::new();
        let mut candidates = Vec::new();
        for (k, &(p, from)) in active.iter().enumerate() {
            let tri = hits.triangle[k];
            let depth = from + hits.t[k] as f64;
            if tri < 0 || depth > how.far {
                continue; // nothing (left) along this ray: the pixel stays empty
            }
            let (o, d) = rays.ray(p % w, p / w);
            let [a, b, c] = scene.triangle(tri as usize);
            if how.cull_backfaces && (b - a).cross(c - a).dot(d) >= 0.0 {
                met.push((p, depth, None));
                continue;
            }
            met.push((p, depth, Some(candidates.len())));
            candidates.push(Sample {
                triangle: tri,
                point: o + d * depth,
            });
        }
        let redundant = redundant(&candidates)?;
        let mut next = Vec::new();
        for (p, depth, c) in met {
            match c {
                Some(c) if !redundant[c] => walked.found.push((p, candidates[c].triangle)),
                _ => next.push((p, depth + tolerance + 1e-5 * depth.abs())),
            }
        }
        active = next;
    }
    Ok(walked)
}

/// The body every GPU discretization shares: `raster` renders the cameras' triangle ids and
/// hands each chunk of images to its callback as it arrives; each chunk is resolved here while
/// the GPU renders the next. `total` started when the call did.
pub(crate) fn resolve_streamed(
    scene: &Scene,
    cameras: &[Camera],
    total: Instant,
    raster: impl FnOnce(
        &gpu::GpuContext,
        &mut dyn FnMut(usize, &[i32]),
    ) -> Result<gpu::depth::RasterStats>,
) -> Result<DepthImages> {
    let first = &cameras[0];
    let start = Instant::now();
    let ctx = gpu::context()?;
    let device_seconds = start.elapsed().as_secs_f64();
    // The device's limits first: an image too large for it is refused before any host memory
    // is taken for it.
    gpu::raster::check_image_size(&ctx, first.width, first.height)?;
    let start = Instant::now();
    let planes = SurfacePlane::of(scene);
    let surfaces = scene.surfaces();
    let prepare_seconds = start.elapsed().as_secs_f64();
    let mut img = DepthImages::allocate(cameras)?;
    let rays: Vec<PixelRays> = cameras.iter().map(PixelRays::new).collect();
    let npx = first.width as usize * first.height as usize;
    let raw = raster(&ctx, &mut |at, ids| {
        let range = at * npx..at * npx + ids.len();
        img.triangle[range.clone()].copy_from_slice(ids);
        resolve_into(&mut img, range, &rays, &planes, &surfaces);
    })?;
    img.timings = raster_timings(
        device_seconds,
        prepare_seconds,
        &raw,
        raw.consumer_seconds,
        total,
    );
    Ok(img)
}

/// The stages of a GPU discretization, in the order they run: device creation, scene upload,
/// per-triangle preparation, raster (CPU side, and GPU timestamps when available), readback,
/// the f64 resolve, and the total since `total` started.
fn raster_timings(
    device_seconds: f64,
    prepare_seconds: f64,
    raw: &gpu::depth::RasterStats,
    resolve_seconds: f64,
    total: Instant,
) -> Timings {
    let mut t = Timings::from([
        ("device", device_seconds),
        ("upload", raw.upload_seconds),
        ("prepare", prepare_seconds),
        ("raster", raw.raster_seconds),
    ]);
    if let Some(g) = raw.gpu_seconds {
        t.add("raster_gpu", g);
    }
    t.add("readback", raw.readback_seconds);
    t.add("resolve", resolve_seconds);
    t.add("total", total.elapsed().as_secs_f64());
    t
}

/// At least one camera, all of one resolution.
pub(crate) fn check_cameras(cameras: &[Camera]) -> Result<()> {
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
    crate::limits::check_views("the depth images", cameras, crate::limits::IMAGE_BYTES)
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

    /// The CPU backend needs no GPU: from outside a closed icosahedron it sees the faces the
    /// pixel rays hit first (culled or not, the same: they face the eye), from inside it sees
    /// the far side unless back faces are culled, when every ray walks past all of them.
    #[test]
    fn traced_images_see_front_faces_and_cull_back_ones() {
        let (v, f) = crate::scene::shapes::icosahedron();
        let verts = v.iter().map(|p| p.as_vec3().to_array()).collect();
        let ico = Scene::from_arrays(verts, f.to_vec(), None, None).unwrap();
        let at = |eye: DVec3| {
            Camera::look_at(
                eye,
                DVec3::new(0.0, 0.0, 0.1),
                DVec3::Y,
                1.2,
                24,
                16,
                None,
                None,
            )
            .unwrap()
        };
        let outside = [at(DVec3::new(0.3, 0.2, 4.0))];
        let plain = discretize_traced(&ico, &outside, false).unwrap();
        let culled = discretize_traced(&ico, &outside, true).unwrap();
        assert_eq!(plain.triangle, culled.triangle);
        let (origins, dirs): (Vec<[f32; 3]>, Vec<[f32; 3]>) = (0..24 * 16)
            .map(|p| {
                let (o, d) = PixelRays::new(&outside[0]).ray(p % 24, p / 24);
                (o.as_vec3().to_array(), d.as_vec3().to_array())
            })
            .unzip();
        let hits = crate::trace::cast_rays(&ico, &origins, &dirs, 0.0, f32::INFINITY).unwrap();
        assert_eq!(plain.triangle, hits.triangle);
        assert!(plain.triangle.iter().any(|&t| t >= 0) && plain.triangle.contains(&-1));
        let inside = [at(DVec3::new(0.0, 0.0, 0.4))];
        let seen = discretize_traced(&ico, &inside, false).unwrap();
        assert!(seen.triangle.iter().all(|&t| t >= 0));
        let none = discretize_traced(&ico, &inside, true).unwrap();
        assert!(none.triangle.iter().all(|&t| t < 0));
        assert!(none.depth.iter().all(|d| d.is_infinite()));
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
