//! Conventional depth images (non-redundant-rendering.txt §3: every camera samples every surface
//! it sees). The GPU rasterises the id of the nearest triangle at each pixel centre
//! (`gpu::depth`); this module resolves each id into depth, world position, geometric normal and
//! base colour by intersecting the pixel-centre ray with that triangle's plane in f64. That is
//! the exact point perspective-correct interpolation approximates, so precision depends neither
//! on the hardware depth buffer, nor on f32 interpolation, nor on the scene's distance from the
//! world origin.

use std::sync::Arc;
use std::time::Instant;

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::redundancy::Sample;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu;
use crate::input_err;
use crate::scene::Scene;
use crate::trace::{nearest_hits_facing, Query};
use crate::types::{DepthImages, Timings};

/// Every triangle's [`SurfacePlane`], in face order: a scene's cached resolve data.
pub(crate) struct ScenePlanes(pub Vec<SurfacePlane>);

impl std::ops::Deref for ScenePlanes {
    type Target = [SurfacePlane];
    fn deref(&self) -> &[SurfacePlane] {
        &self.0
    }
}

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
            near.depth[i] = other.depth[i];
            near.triangle[i] = other.triangle[i];
            near.normal[i] = other.normal[i];
            near.position[i] = other.position[i];
            near.color[i] = other.color[i];
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
    let (near, far) = cam.clip_range(scene.bounds());
    let frame = TraceFrame::of(scene)?;
    let (origins, dirs) = pixel_rays_f32(cam, &frame);
    let range = Query::new(near as f32, (far as f32).max(near as f32));
    let target = frame.scene(scene);
    let hits = nearest_hits_facing(target, &origins, &dirs, 1, &range, cull_backfaces)?;
    let mut out = hits.triangle;
    let (changes, edge_seconds) =
        super::raster_rule::settle_edges(scene, cam, cull_backfaces, &frame, &out, None)?;
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

/// Every pixel-centre ray of `cam` in `frame` (origin on the camera, direction with camera z
/// −1, so `t` is the depth), rounded to f32 for the ray caster, row-major.
pub(crate) fn pixel_rays_f32(cam: &Camera, frame: &TraceFrame) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let rays = PixelRays::new(cam);
    (0..cam.width as usize * cam.height as usize)
        .into_par_iter()
        .map(|p| ray_f32(&rays, cam, frame, p))
        .unzip()
}

/// [`pixel_rays_f32`] of the pixels `pixels` (row-major indices) only.
pub(crate) fn pixel_rays_f32_at(
    cam: &Camera,
    frame: &TraceFrame,
    pixels: &[usize],
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let rays = PixelRays::new(cam);
    pixels
        .par_iter()
        .map(|&p| ray_f32(&rays, cam, frame, p))
        .unzip()
}

/// Pixel `p`'s ray as [`pixel_rays_f32`] gives it.
#[inline]
fn ray_f32(rays: &PixelRays, cam: &Camera, frame: &TraceFrame, p: usize) -> ([f32; 3], [f32; 3]) {
    let w = cam.width as usize;
    let (o, d) = rays.ray(p % w, p / w);
    (
        (o - frame.shift).as_vec3().to_array(),
        d.as_vec3().to_array(),
    )
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
    let tolerance = super::redundancy::tolerance(scene);
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

/// Where the CPU backend casts its rays. A scene far from the origin (its centre farther than
/// its diagonal) is traced in a copy centred on the origin, as the GPU path rasterizes it
/// relative to its centre: float32 ray origins and vertices then keep the precision of the
/// scene's own extent instead of its distance from the origin. The copy (and its BVH) is made
/// once and kept on the scene.
pub(crate) struct TraceFrame {
    centred: Option<Scene>,
    pub(crate) shift: DVec3,
}

impl TraceFrame {
    pub(crate) fn of(scene: &Scene) -> Result<Arc<TraceFrame>> {
        let centre = scene.center();
        if centre.length() <= scene.diagonal() {
            return Ok(scene.derived(|| TraceFrame {
                centred: None,
                shift: DVec3::ZERO,
            }));
        }
        let mut failed = None;
        let frame = scene.derived(|| {
            let vertices = scene
                .vertices()
                .iter()
                .map(|v| {
                    (Vec3::from_array(*v).as_dvec3() - centre)
                        .as_vec3()
                        .to_array()
                })
                .collect();
            match Scene::from_arrays(vertices, scene.faces().to_vec(), None, None) {
                Ok(s) => TraceFrame {
                    centred: Some(s),
                    shift: centre,
                },
                Err(e) => {
                    failed = Some(e);
                    TraceFrame {
                        centred: None,
                        shift: DVec3::ZERO,
                    }
                }
            }
        });
        match failed {
            Some(e) => Err(e),
            None => Ok(frame),
        }
    }

    /// The scene the rays are cast in: the centred copy, or `scene` itself.
    pub(crate) fn scene<'a>(&'a self, scene: &'a Scene) -> &'a Scene {
        self.centred.as_ref().unwrap_or(scene)
    }
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
    let prepare_seconds = start.elapsed().as_secs_f64();
    let mut img = DepthImages::allocate(cameras)?;
    let rays: Vec<PixelRays> = cameras.iter().map(PixelRays::new).collect();
    let npx = first.width as usize * first.height as usize;
    let raw = raster(&ctx, &mut |at, ids| {
        let range = at * npx..at * npx + ids.len();
        img.triangle[range.clone()].copy_from_slice(ids);
        resolve_into(&mut img, range, &rays, &planes);
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

/// Depth images from per-pixel triangle ids (row-major, image after image, −1 where empty):
/// every field resolved in f64 from the pixel-centre ray and the triangle, as for conventional
/// images. Returns the images and the resolve time.
pub(crate) fn resolve_ids(
    scene: &Scene,
    cameras: &[Camera],
    ids: Vec<i32>,
) -> Result<(DepthImages, f64)> {
    let start = Instant::now();
    let planes = SurfacePlane::of(scene);
    let mut img = DepthImages::allocate(cameras)?;
    let rays: Vec<PixelRays> = cameras.iter().map(PixelRays::new).collect();
    let n = ids.len();
    img.triangle = ids;
    resolve_into(&mut img, 0..n, &rays, &planes);
    Ok((img, start.elapsed().as_secs_f64()))
}

/// Per-camera constants of the pixel-centre rays (see `Camera::ray_z1`): the ray through pixel
/// (x, y) is `origin(x, y) + t·dir(x, y)` with camera-space z of `dir` equal to −1, so `t` is
/// the depth.
pub(crate) struct PixelRays {
    eye: DVec3,
    /// World-space steps per pixel along x and y, and the ray at pixel (0, 0)'s corner.
    dx: DVec3,
    dy: DVec3,
    corner: DVec3,
    orthographic: bool,
    forward: DVec3,
}

impl PixelRays {
    pub(crate) fn new(cam: &Camera) -> Self {
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

    pub(crate) fn ray(&self, x: usize, y: usize) -> (DVec3, DVec3) {
        self.ray_at(x as f64 + 0.5, y as f64 + 0.5)
    }

    /// The ray through image point `(x, y)` in pixels from the top-left corner (pixel centres
    /// at half-integers).
    pub(crate) fn ray_at(&self, x: f64, y: f64) -> (DVec3, DVec3) {
        let p = self.corner + self.dx * x + self.dy * y;
        if self.orthographic {
            (p, self.forward)
        } else {
            (self.eye, p)
        }
    }
}

impl DepthImages {
    /// Output buffers for one image per camera. Zeroed allocations are lazily mapped pages: the
    /// resolve pass is the first and only writer of every pixel (misses included).
    /// Zeroed images for `cameras`; an error, not an abort, when the host cannot hold them.
    fn allocate(cameras: &[Camera]) -> Result<Self> {
        let (w, h) = (cameras[0].width, cameras[0].height);
        let total = w as usize * h as usize * cameras.len();
        let bytes = total as u128 * 44;
        let too_big = || {
            Error::GpuLimit(format!(
                "{} images of {w}x{h} need {bytes} bytes of host memory, which could not be \
                 allocated; use fewer or smaller images",
                cameras.len()
            ))
        };
        // Probe once for the whole amount, then allocate with `vec!`, whose zeroed memory comes
        // from the kernel lazily (filling it here would double the cost of large images).
        let mut probe: Vec<u8> = Vec::new();
        probe
            .try_reserve_exact(usize::try_from(bytes).map_err(|_| too_big())?)
            .map_err(|_| too_big())?;
        drop(probe);
        Ok(Self {
            n: cameras.len(),
            width: w,
            height: h,
            depth: vec![0.0; total],
            triangle: vec![0; total],
            normal: vec![[0.0; 3]; total],
            position: vec![[0.0; 3]; total],
            color: vec![[0.0; 3]; total],
            cameras: cameras.to_vec(),
            method: "conventional".into(),
            timings: Timings::new(),
        })
    }
}

/// Resolve the pixels `range` (whole rows) of `img` from their triangle ids, parallel over rows.
fn resolve_into(
    img: &mut DepthImages,
    range: std::ops::Range<usize>,
    rays: &[PixelRays],
    planes: &[SurfacePlane],
) {
    let (w, h) = (img.width as usize, img.height as usize);
    let first_row = range.start / w;
    let ids = &img.triangle[range.clone()];
    img.depth[range.clone()]
        .par_chunks_mut(w)
        .zip(img.position[range.clone()].par_chunks_mut(w))
        .zip(img.normal[range.clone()].par_chunks_mut(w))
        .zip(img.color[range].par_chunks_mut(w))
        .enumerate()
        .for_each(|(r, (((depth, pos), nrm), col))| {
            let row = first_row + r;
            let cam = &rays[row / h];
            for x in 0..w {
                let px = (&mut depth[x], &mut pos[x], &mut nrm[x], &mut col[x]);
                resolve_one(ids[r * w + x], cam, x, row % h, planes, px);
            }
        });
}

/// Pixel (x, y) of one image, seeing triangle `id` (−1: nothing).
#[inline(always)]
fn resolve_one(
    id: i32,
    cam: &PixelRays,
    x: usize,
    y: usize,
    planes: &[SurfacePlane],
    (depth, pos, nrm, col): (&mut f32, &mut [f32; 3], &mut [f32; 3], &mut [f32; 3]),
) {
    let Ok(t) = usize::try_from(id) else {
        *depth = f32::INFINITY;
        *pos = [f32::NAN; 3];
        *nrm = [0.0; 3];
        *col = [0.0; 3];
        return;
    };
    let (o, d) = cam.ray(x, y);
    let s = planes[t].intersect(o, d, cam.forward);
    *depth = s.depth as f32;
    *pos = s.point.as_vec3().to_array();
    *nrm = planes[t].normal.as_vec3().to_array();
    *col = s.color;
}

/// Give the pixels `changed` (flat indices over all images) of resolved images `img` the
/// triangle ids `ids` holds for them, and resolve those pixels again; every other pixel is
/// kept. The same values as [`resolve_ids`] over everything, at the cost of the few pixels.
pub(crate) fn resolve_pixels(
    scene: &Scene,
    cameras: &[Camera],
    img: &mut DepthImages,
    ids: &[i32],
    changed: &[usize],
) -> f64 {
    let start = Instant::now();
    let planes = SurfacePlane::of(scene);
    let rays: Vec<PixelRays> = cameras.iter().map(PixelRays::new).collect();
    let (w, h) = (img.width as usize, img.height as usize);
    for &p in changed {
        img.triangle[p] = ids[p];
        let (i, y, x) = (p / (w * h), p / w % h, p % w);
        let px = (
            &mut img.depth[p],
            &mut img.position[p],
            &mut img.normal[p],
            &mut img.color[p],
        );
        resolve_one(ids[p], &rays[i], x, y, &planes, px);
    }
    start.elapsed().as_secs_f64()
}

/// Per-triangle data for resolving pixels, in f64: a corner, the unit normal, the gradients of
/// the barycentrics over the plane, and the corner colours. Computed once per scene (cached on
/// it), so a pixel costs a few dot products on one contiguous record.
#[derive(Debug, Clone)]
pub(crate) struct SurfacePlane {
    a: DVec3,
    normal: DVec3,
    /// b1 = (p − a)·g1 and b2 = (p − a)·g2 for a point p on the plane.
    g1: DVec3,
    g2: DVec3,
    colors: [Vec3; 3],
    /// Degenerate triangles have no plane: their centroid stands in.
    centroid: Option<DVec3>,
}

impl SurfacePlane {
    fn new(scene: &Scene, i: usize) -> Self {
        let [a, b, c] = scene.triangle(i);
        let (e1, e2) = (b - a, c - a);
        let n = e1.cross(e2);
        let nn = n.length_squared();
        let colors = scene.faces()[i].map(|k| Vec3::from(scene.colors()[k as usize]));
        let degenerate = scene.is_degenerate(i) || nn == 0.0 || !nn.is_finite();
        Self {
            a,
            normal: if degenerate {
                DVec3::ZERO
            } else {
                n / nn.sqrt()
            },
            g1: if degenerate {
                DVec3::ZERO
            } else {
                e2.cross(n) / nn
            },
            g2: if degenerate {
                DVec3::ZERO
            } else {
                n.cross(e1) / nn
            },
            colors,
            centroid: degenerate.then(|| (a + b + c) / 3.0),
        }
    }

    /// The scene's planes, built in parallel on first use and cached on the scene.
    pub(crate) fn of(scene: &Scene) -> Arc<ScenePlanes> {
        scene.derived(|| {
            ScenePlanes(
                (0..scene.triangle_count())
                    .into_par_iter()
                    .map(|i| Self::new(scene, i))
                    .collect(),
            )
        })
    }

    /// The `t` at which the ray `o + t·d` meets the plane (the depth, when camera-space z of `d`
    /// is −1); not finite for an edge-on or degenerate triangle.
    pub(crate) fn ray_depth(&self, o: DVec3, d: DVec3) -> f64 {
        self.normal.dot(self.a - o) / self.normal.dot(d)
    }

    /// Where the ray `o + t·d` (camera-space z of `d` is −1, so `t` is depth) meets the plane.
    /// The rasteriser said the triangle covers this pixel centre, so the ray meets the plane
    /// unless the triangle is edge-on or degenerate; then the centroid stands in.
    fn intersect(&self, o: DVec3, d: DVec3, forward: DVec3) -> SurfacePoint {
        let t = self.ray_depth(o, d);
        let (point, depth, b1, b2) = match self.centroid {
            Some(c) => (c, (c - o).dot(forward), 1.0 / 3.0, 1.0 / 3.0),
            None if t.is_finite() => {
                let p = o + d * t;
                let r = p - self.a;
                (p, t, r.dot(self.g1), r.dot(self.g2))
            }
            None => {
                let c = self.a;
                (c, (c - o).dot(forward), 0.0, 0.0)
            }
        };
        // Clamped to the triangle: only colour interpolation uses them.
        let (b1, b2) = (b1.clamp(0.0, 1.0) as f32, b2.clamp(0.0, 1.0) as f32);
        let s = (b1 + b2).max(1.0);
        let (b1, b2) = (b1 / s, b2 / s);
        let [ca, cb, cc] = self.colors;
        SurfacePoint {
            depth,
            point,
            color: (ca * (1.0 - b1 - b2) + cb * b1 + cc * b2).to_array(),
        }
    }
}

struct SurfacePoint {
    depth: f64,
    point: DVec3,
    color: [f32; 3],
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
