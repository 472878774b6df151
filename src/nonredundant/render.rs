//! Non-redundant rendering and depth peeling (non-redundant-rendering.txt §3.2, §6.1.1).
//!
//! Image 0 is a conventional image (§3), made by the backend that conventional images of the
//! same cameras get (`calibration::decide`), so the two are equal bit for bit.
//!
//! - Pixel redundancy: Algorithm 1 with Algorithm 3 on the GPU (`gpu::layered`): one raster pass
//!   per image, whose fragment stage discards a fragment that an earlier image already holds
//!   (same triangle at the pixel it reprojects to) before it reaches the depth test. An image 0
//!   traced on the CPU is handed to the passes, which test against it as against their own.
//! - Visibility redundancy: Algorithm 1 with Algorithm 2, exactly, on the CPU. For image i > 0
//!   every pixel-centre ray is walked front to back
//!   through the surfaces it crosses (BVH ray casts, each resuming just beyond the previous
//!   hit); each surface point met is a candidate sample, tested against every earlier image's
//!   viewpoint with a visibility ray (`redundancy::visible_from`); the first candidate visible
//!   from no earlier viewpoint is the pixel's sample. This is the nearest non-redundant sample
//!   along the ray, which is what Algorithm 1's z-buffer keeps.
//! - Depth peeling: k passes from one camera, pass i keeping the nearest fragment strictly
//!   beyond pass i−1's depth at its pixel (`gpu::layered`, `fs_peel`). A surface within a
//!   relative `trace::SAME_HIT` (1e-5) of the previous layer's depth is that layer met again
//!   (duplicated and coplanar faces), so depths strictly increase along each pixel. On the CPU
//!   (`discretize_peeling_traced`), each pixel ray gathers its k nearest distinct surfaces in
//!   one traversal instead, with the same tie rule.
//!
//! All three resolve depth, position, normal and colour from the triangle ids exactly as
//! conventional images do.

use std::time::Instant;

use glam::DVec3;

use super::redundancy::{self, Redundancy, Sample};
use crate::calibration::{self, Backend, BackendChoice, Decision};
use crate::camera::Camera;
use crate::error::Result;
use crate::gpu::layered;
use crate::image::conventional::{
    check_cameras, discretize_conventional, discretize_traced, resolve_streamed, walk, Walk,
};
use crate::image::pixels::{
    pixel_rays_f32, resolve_ids, resolve_pixels, PixelRays, SurfacePlane, TraceFrame,
};
use crate::input_err;
use crate::scene::Scene;
use crate::trace::{nearest_hits_facing, Query, SAME_HIT};
use crate::types::{DepthImages, Timings};

/// Non-redundant depth images, one per camera (shared resolution), image i free of samples
/// redundant with images 0..i under `redundancy`. Image 0 is the conventional image that
/// `calibration::discretize_with(scene, cameras, ..)` makes with `image0` (§3: the first image
/// is a conventional one), so the two agree bit for bit whichever backend that picks; the
/// later images are rendered on the GPU (pixel redundancy) or traced (visibility).
pub fn discretize_nonredundant(
    scene: &Scene,
    cameras: &[Camera],
    redundancy: Redundancy,
    cull_backfaces: bool,
    image0: BackendChoice,
) -> Result<(DepthImages, Decision)> {
    check_cameras(cameras)?;
    let decision = calibration::decide(scene, cameras, image0)?;
    let first = |b: Backend| match b {
        Backend::Gpu => discretize_conventional(scene, &cameras[..1], cull_backfaces),
        Backend::Cpu => discretize_traced(scene, &cameras[..1], cull_backfaces),
    };
    let images = match (redundancy, decision.backend) {
        (Redundancy::Pixel, Backend::Gpu) => layered_images(
            scene,
            cameras,
            layered::LayerTest::PixelRedundancy,
            cull_backfaces,
            None,
            "nonredundant",
        ),
        (Redundancy::Pixel, Backend::Cpu) => {
            let image0 = first(Backend::Cpu)?;
            layered_images(
                scene,
                cameras,
                layered::LayerTest::PixelRedundancy,
                cull_backfaces,
                Some(image0),
                "nonredundant",
            )
        }
        (Redundancy::Visibility, b) => visibility_images(scene, cameras, cull_backfaces, first(b)?),
    }?;
    Ok((images, decision))
}

/// `layers` depth-peeling layers from `camera`.
pub fn discretize_peeling(
    scene: &Scene,
    camera: &Camera,
    layers: usize,
    cull_backfaces: bool,
) -> Result<DepthImages> {
    check_layers(camera, layers)?;
    let cams = vec![camera.clone(); layers];
    let mut img = layered_images(
        scene,
        &cams,
        layered::LayerTest::Peel,
        cull_backfaces,
        None,
        "peeling",
    )?;
    merge_same_surfaces(&mut img);
    Ok(img)
}

/// `layers` depth-peeling layers from `camera` on the requested backend (the model counts
/// them as `layers` images: the GPU draws a pass per layer, the CPU gathers a pixel's layers
/// in one traversal, which costs about as much).
pub fn peeling_with(
    scene: &Scene,
    camera: &Camera,
    layers: usize,
    cull_backfaces: bool,
    choice: BackendChoice,
) -> Result<(DepthImages, Decision)> {
    check_layers(camera, layers)?;
    let cams = vec![camera.clone(); layers];
    let decision = calibration::decide(scene, &cams, choice)?;
    let images = match decision.backend {
        Backend::Gpu => discretize_peeling(scene, camera, layers, cull_backfaces),
        Backend::Cpu => discretize_peeling_traced(scene, camera, layers, cull_backfaces),
    }?;
    Ok((images, decision))
}

/// `layers` peeling layers of `camera`'s images: at least one, and within the memory limit
/// (checked before the layers' cameras are made).
pub(crate) fn check_layers(camera: &Camera, layers: usize) -> Result<()> {
    if layers == 0 {
        return input_err!("peeling needs at least one layer, got layers=0");
    }
    let (w, h) = (camera.width as u64, camera.height as u64);
    crate::limits::check(
        || format!("{layers} peeling layers of {w}x{h} pixels"),
        crate::limits::product(&[layers as u64, w, h]),
        crate::limits::IMAGE_BYTES,
    )
}

/// Depth peeling without the GPU (the `"cpu"` backend): each pixel-centre ray of `camera`
/// gathers its `layers` nearest distinct surfaces between the near and far planes in one BVH
/// traversal (`trace::nearest_hits_facing`, the `cast_rays(max_hits=k)` query: hits within a
/// relative [`SAME_HIT`] of each other are one surface; with `cull_backfaces` back faces are
/// passed through), cast in the scene's trace frame from the camera itself so that `t` is the
/// depth. The ids are resolved as every image's are and the same tie rule as the GPU path's is
/// applied to the f64 depths, so the layers agree with the GPU's except where a pixel centre
/// lies on an edge.
pub fn discretize_peeling_traced(
    scene: &Scene,
    camera: &Camera,
    layers: usize,
    cull_backfaces: bool,
) -> Result<DepthImages> {
    let total = Instant::now();
    check_layers(camera, layers)?;
    let cams = vec![camera.clone(); layers];
    let npx = camera.width as usize * camera.height as usize;
    if npx
        .checked_mul(layers)
        .is_none_or(|n| n > i32::MAX as usize)
    {
        return input_err!(
            "{layers} layers of {}x{} pixels are too many",
            camera.width,
            camera.height
        );
    }
    let (near, far) = camera.clip_range(scene.bounds());
    let frame = TraceFrame::of(scene)?;
    let target = frame.scene(scene);
    let w = camera.width as usize;
    let rays = PixelRays::new(camera);
    let (origins, dirs) = pixel_rays_f32(camera, &frame);
    let range = Query::new(near as f32, (far as f32).max(near as f32));
    let hits = nearest_hits_facing(target, &origins, &dirs, layers, &range, cull_backfaces)?;
    let mut rows = hits.triangle;
    // Layer 0 is a conventional image: its edge pixels follow the raster's rule as the CPU
    // backend's conventional images do, and the layers behind follow the new first surface.
    let first: Vec<i32> = rows.iter().step_by(layers).copied().collect();
    let (changes, settle_seconds) = crate::image::raster_rule::settle_edges(
        scene,
        camera,
        cull_backfaces,
        &frame,
        &first,
        None,
    )?;
    let planes = SurfacePlane::of(scene);
    for (p, t) in changes {
        let (o, d) = rays.ray(p % w, p / w);
        restart_layers(&planes, &mut rows[p * layers..(p + 1) * layers], t, o, d);
    }
    // Ray-major hits to layer-major images.
    let mut ids = vec![-1i32; npx * layers];
    for (p, row) in rows.chunks_exact(layers).enumerate() {
        for (l, &t) in row.iter().enumerate() {
            ids[l * npx + p] = t;
        }
    }
    let (mut img, resolve_seconds) = resolve_ids(scene, &cams, ids)?;
    img.method = "peeling".into();
    img.timings = Timings::from([
        ("bvh", hits.bvh_build_seconds),
        ("trace", hits.trace_seconds),
        ("edges", settle_seconds),
        ("resolve", resolve_seconds),
    ]);
    merge_same_surfaces(&mut img);
    // The tie pass counted its own seconds into "total"; the rest of the call joins them.
    let ties = img.timings.get("total").unwrap_or(0.0);
    img.timings
        .add("total", total.elapsed().as_secs_f64() - ties);
    Ok(img)
}

/// A pixel's layers (`row`, nearest first, −1 padded) once the raster's rule has made `first`
/// its first surface: nothing (−1) empties the pixel; a surface among the layers starts them
/// there; one in front of the old first surface goes before it; any other (the neighbour across
/// a shared edge, at the same depth) takes the first layer's place.
fn restart_layers(planes: &[SurfacePlane], row: &mut [i32], first: i32, o: DVec3, d: DVec3) {
    let depth = |t: i32| planes[t as usize].ray_depth(o, d);
    if first < 0 {
        row.fill(-1);
    } else if let Some(k) = row.iter().position(|&t| t == first) {
        row.copy_within(k.., 0);
        let n = row.len();
        row[n - k..].fill(-1);
    } else if row[0] < 0 || depth(first) < depth(row[0]) * (1.0 - SAME_HIT as f64) {
        row.copy_within(..row.len() - 1, 1);
        row[0] = first;
    } else {
        row[0] = first;
    }
}

/// Ties, decided exactly: a layer whose f64 depth at the pixel centre lies within a relative
/// [`SAME_HIT`] of the previous kept layer's is that surface met again (a duplicated or
/// coplanar face), so it is removed and the deeper layers move up; the freed last layers are
/// empty. So is a layer whose exact depth is not beyond the previous one at all (float32
/// rasterisation misordered two crossing faces there). Depths then strictly increase along each pixel, and the layers are the distinct
/// hits of `trace::nearest_hits` with the same tolerance. The GPU pass discards such
/// fragments already, by the same rule on its float32 depth (`fs_peel`), so this only catches
/// what float32 misjudged (a few 1e-7 relative; more on triangles spanning a large depth
/// range); where it does, the pixel's last layers are empty.
fn merge_same_surfaces(img: &mut DepthImages) {
    let start = Instant::now();
    let npx = img.width as usize * img.height as usize;
    let layers = img.n;
    // Most pixels need nothing: find the others with linear scans, layer pair by layer pair.
    let mut touch = vec![false; npx];
    for i in 1..layers {
        let (prev, this) = (
            &img.depth[(i - 1) * npx..i * npx],
            &img.depth[i * npx..(i + 1) * npx],
        );
        for (p, t) in touch.iter_mut().enumerate() {
            let (a, b) = (prev[p], this[p]);
            // A tie or an inversion (b finite), or a hole before a sample (a infinite).
            *t |= b.is_finite() && b - a <= SAME_HIT * b.max(a);
        }
    }
    for p in (0..npx).filter(|&p| touch[p]) {
        let mut kept = 0;
        let mut last = f32::NAN;
        for i in 0..layers {
            let at = i * npx + p;
            let d = img.depth[at];
            if img.triangle[at] < 0 {
                continue;
            }
            // Not beyond the last kept layer by more than the tolerance: the same surface, or
            // one the GPU ordered wrongly (its vertices snap to a fixed-point grid, which
            // moves a steep triangle's depth at the pixel centre; crossing faces can swap).
            if kept > 0 && d - last <= SAME_HIT * d.max(last) {
                continue;
            }
            last = d;
            let to = kept * npx + p;
            if to != at {
                img.move_pixel(to, at);
            }
            kept += 1;
        }
        for i in kept..layers {
            img.clear_pixel(i * npx + p);
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    img.timings.add("ties", seconds);
    img.timings.add("total", seconds);
}

/// The viewpoint depth peeling uses by default (§6.1.3): the centroid of the reference
/// viewpoints, with their mean orientation.
pub fn centroid_camera(cameras: &[Camera]) -> Result<Camera> {
    Camera::blend(cameras, &vec![1.0; cameras.len()])
}

/// Layered passes (`gpu::layered`), image 0 drawn by the first pass or given (`first`, the
/// CPU backend's conventional image, whose seconds join the timings as `image0`).
fn layered_images(
    scene: &Scene,
    cameras: &[Camera],
    test: layered::LayerTest,
    cull_backfaces: bool,
    first: Option<DepthImages>,
    method: &str,
) -> Result<DepthImages> {
    let start = Instant::now();
    let ids0 = first.as_ref().map(|f| f.triangle.as_slice());
    let mut img = resolve_streamed(scene, cameras, start, |ctx, on_image| {
        layered::render(ctx, scene, cameras, test, cull_backfaces, ids0, on_image)
    })?;
    if let Some(f) = &first {
        let seconds = f.timings.get("total").unwrap_or(0.0);
        img.timings.add("image0", seconds);
        img.timings.add("total", seconds);
    }
    if test == layered::LayerTest::PixelRedundancy {
        img = coincident_samples(scene, cameras, img, cull_backfaces)?;
    }
    img.method = method.into();
    Ok(img)
}

/// Algorithm 3 compares triangle ids; distinct triangles that are one surface (coplanar and
/// overlapping: a box's bottom on a floor, a decal; `redundancy::coincident_groups`) must count
/// as the same triangle too, or a sample of one is kept where an earlier image holds the other
/// at the same point. The GPU pass cannot see that, so the few samples of such triangles are
/// checked here, in f64: one that projects into an earlier image at a pixel holding a triangle
/// of its group is redundant, and its pixel ray is walked on (BVH casts, as for visibility
/// redundancy) to the first sample no earlier image holds, by triangle or group. Images are
/// fixed in order, each against the fixed earlier ones; the GPU's later images were tested
/// against the unfixed ones, which differ only at these pixels.
fn coincident_samples(
    scene: &Scene,
    cameras: &[Camera],
    img: DepthImages,
    cull_backfaces: bool,
) -> Result<DepthImages> {
    let coincident = scene.derived(|| redundancy::Coincident(redundancy::coincident_groups(scene)));
    let Some(groups) = coincident.0.as_ref() else {
        return Ok(img);
    };
    let start = Instant::now();
    let npx = img.width as usize * img.height as usize;
    let mut size = vec![0u32; groups.len()];
    for &g in groups {
        size[g as usize] += 1;
    }
    let shared = |t: i32| t >= 0 && size[groups[t as usize] as usize] > 1;
    let same = |a: i32, b: i32| {
        a == b || (shared(a) && shared(b) && groups[a as usize] == groups[b as usize])
    };
    let mut ids = img.triangle.clone();
    let mut fixed = 0usize;
    for i in 1..cameras.len() {
        let (before, rest) = ids.split_at_mut(i * npx);
        let image = &mut rest[..npx];
        let held = |t: i32, point: DVec3| {
            cameras[..i].iter().enumerate().any(|(j, cam)| {
                redundancy::pixel_of(cam, point)
                    .is_some_and(|(x, y)| same(before[j * npx + y * cam.width as usize + x], t))
            })
        };
        let cam = &cameras[i];
        let w = cam.width as usize;
        let rays = PixelRays::new(cam);
        let tolerance = redundancy::tolerance(scene);
        // Pixels whose sample an earlier image holds through a coincident triangle, walked on
        // from just beyond that sample.
        let walks: Vec<(usize, f64)> = (0..npx)
            .filter(|&p| shared(image[p]))
            .filter_map(|p| {
                let depth = img.depth[i * npx + p] as f64;
                let (o, d) = rays.ray(p % w, p / w);
                held(image[p], o + d * depth).then_some((p, depth + tolerance + 1e-5 * depth.abs()))
            })
            .collect();
        fixed += walks.len();
        for &(p, _) in &walks {
            image[p] = -1;
        }
        let redundant = |c: &[Sample]| Ok(c.iter().map(|s| held(s.triangle, s.point)).collect());
        for (p, t) in walk(scene, cam, walks, Walk::plain(cull_backfaces), redundant)?.found {
            image[p] = t;
        }
    }
    if fixed == 0 {
        return Ok(img);
    }
    // Only the pixels whose triangle changed are resolved again (samples of coincident
    // triangles: few), not every pixel of every image.
    let changed: Vec<usize> = (0..ids.len())
        .filter(|&p| ids[p] != img.triangle[p])
        .collect();
    let mut out = img;
    let resolve_seconds = resolve_pixels(scene, cameras, &mut out, &ids, &changed);
    out.timings.add(
        "coincident",
        start.elapsed().as_secs_f64() - resolve_seconds,
    );
    out.timings.add("coincident_resolve", resolve_seconds);
    out.timings.add("total", start.elapsed().as_secs_f64());
    Ok(out)
}

/// Algorithm 1 with Algorithm 2, exactly (see the module docs).
/// Algorithm 1 with Algorithm 2 after the conventional image 0 (`first`).
fn visibility_images(
    scene: &Scene,
    cameras: &[Camera],
    cull_backfaces: bool,
    first: DepthImages,
) -> Result<DepthImages> {
    let total = Instant::now();
    let raster_seconds = first.timings.get("total").unwrap_or(0.0);
    let start = Instant::now();
    let npx = cameras[0].width as usize * cameras[0].height as usize;
    let mut ids = first.triangle;
    ids.reserve(npx * (cameras.len() - 1));
    for i in 1..cameras.len() {
        ids.extend(walk_image(scene, cameras, i, cull_backfaces)?);
    }
    let walk_seconds = start.elapsed().as_secs_f64();
    let (mut img, resolve_seconds) = resolve_ids(scene, cameras, ids)?;
    img.method = "nonredundant".into();
    img.timings = Timings::from([
        ("image0", raster_seconds),
        ("walk", walk_seconds),
        ("resolve", resolve_seconds),
        ("total", total.elapsed().as_secs_f64()),
    ]);
    Ok(img)
}

/// Image `i` under visibility redundancy: the nearest sample along each pixel ray that no
/// viewpoint of images 0..i sees.
fn walk_image(
    scene: &Scene,
    cameras: &[Camera],
    i: usize,
    cull_backfaces: bool,
) -> Result<Vec<i32>> {
    let cam = &cameras[i];
    let npx = cam.width as usize * cam.height as usize;
    let (near, _) = cam.clip_range(scene.bounds());
    let tolerance = redundancy::tolerance(scene);
    let start = (0..npx).map(|p| (p, near)).collect();
    let mut out = vec![-1i32; npx];
    // Test the candidates against each earlier viewpoint in turn; redundant ones drop out.
    let redundant = |candidates: &[Sample]| -> Result<Vec<bool>> {
        let mut redundant = vec![false; candidates.len()];
        for cam_j in &cameras[..i] {
            let open: Vec<usize> = (0..candidates.len()).filter(|&c| !redundant[c]).collect();
            if open.is_empty() {
                break;
            }
            let samples: Vec<Sample> = open.iter().map(|&c| candidates[c]).collect();
            let seen = redundancy::visible_from(scene, &samples, cam_j, tolerance)?;
            for (k, &c) in open.iter().enumerate() {
                redundant[c] |= seen[k];
            }
        }
        Ok(redundant)
    };
    for (p, t) in walk(scene, cam, start, Walk::plain(cull_backfaces), redundant)?.found {
        out[p] = t;
    }
    Ok(out)
}
