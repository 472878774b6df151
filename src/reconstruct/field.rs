//! A view rendered from the visibility field (visibility-field.txt §4, Fig. 4): resample the
//! field along the camera's pixel rays to mark the cells they see, then rasterize only the
//! marked cells' triangles.
//!
//! Resampling: one pixel in every `subsample × subsample` block (the block's middle pixel,
//! `k·i + k/2` rounded down, at its centre) gives a line; where it crosses the uv and st rectangles gives (u, v, s, t)
//! (`Slab::line`). Without interpolation the sample holding that point is read; with it, its
//! neighbours too (§4.1): the 2 × 2 samples around (u, v) for `Uv`, around (s, t) for `St`, the
//! 16 around both for `UvSt` (always including the nearest). Every id stored there is marked.
//! In the paper's rule a pixel whose line runs from the st plane toward the uv plane, runs
//! parallel to either, or misses either rectangle marks nothing; several slabs add their marks.
//! The paper rasterizes the two projected planes in hardware to get (u, v, s, t) per pixel;
//! here the same linear intersection runs on the CPU.
//!
//! Conservative resampling (this package's, not the paper's): a slab answers a pixel only when
//! everything the pixel can see lies between its planes with no surface between the uv plane
//! and the near end ([`Slab::answers`]), and only when every sample read saw at most `trust`
//! cells; the other pixels are traced through the cell-sorted scene ([`trace_fallback`]) and
//! the cells they hit are marked: a camera no slab serves, or a sample that saw several cells,
//! leaves no hole; holes remain only where a cell smaller than a sample's beam slipped between
//! the rays of every sample read.
//!
//! Rendering: the scene's faces are kept sorted by cell (`Cells::triangles`), so the marked
//! cells are ranges of faces, drawn as one draw call per run of consecutive marked cells.

use std::time::Instant;

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::discretize::conventional::{walk, TraceFrame, Walk};
use crate::discretize::visibility_field::{clip_line, Field, Slab};
use crate::discretize::{discretize_ranges, push_range};
use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;
use crate::types::DepthImages;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interpolate {
    None,
    Uv,
    St,
    UvSt,
}

impl Interpolate {
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "none" => Self::None,
            "uv" => Self::Uv,
            "st" => Self::St,
            "uv+st" => Self::UvSt,
            _ => return None,
        })
    }
}

/// How a view resamples the field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resampling {
    pub interpolate: Interpolate,
    /// Side of the pixel blocks that share one line (>= 1).
    pub subsample: u32,
    /// The scene's bounds: answer a pixel only from a slab whose answer is what the pixel sees
    /// ([`Slab::answers`]) and when every sample it reads (the one holding the line and its
    /// interpolation neighbours) hit at most `trust` cells (`n`: none overflowed; 1: all saw
    /// one cell each), and list the other pixels for the fallback. `None`: the paper's rule,
    /// every slab the line crosses the right way.
    pub conservative: Option<[DVec3; 2]>,
    pub trust: u32,
}

/// What resampling found.
#[derive(Debug, Clone, Default)]
pub struct Marks {
    pub marked: Vec<bool>,
    /// Pixels resampled (after subsampling).
    pub pixels: usize,
    /// Of those, how many no slab answers (their lines miss, or run the wrong way).
    pub outside: usize,
    /// Of those, how many only samples that hit more cells than trusted hold (conservative
    /// resampling only).
    pub overflowed: usize,
    /// The pixels (`y * width + x`) the field cannot answer: `outside` and `overflowed` ones
    /// (conservative resampling only).
    pub fallback: Vec<usize>,
}

/// How the field answered one pixel's line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Answer {
    /// From a slab whose samples are trusted (or the line sees nothing).
    Field,
    /// Slabs hold the line, but each reads a sample that hit more cells than trusted.
    Overflowed,
    /// No slab holds the line.
    Outside,
}

/// Sample indices along one axis for the continuous coordinate `x` in [0, 1) over `n` samples:
/// the nearest only, or the two around it (the nearest among them).
fn around(x: f64, n: u32, both: bool) -> ([u32; 2], usize) {
    let last = n as i64 - 1;
    let f = x * n as f64;
    let nearest = (f.floor() as i64).clamp(0, last) as u32;
    if !both {
        return ([nearest, nearest], 1);
    }
    let i0 = (f - 0.5).floor() as i64;
    let a = i0.clamp(0, last) as u32;
    let b = (i0 + 1).clamp(0, last) as u32;
    if a == b {
        ([a, a], 1)
    } else {
        ([a, b], 2)
    }
}

/// Sample index of (iu, iv, is, it) in a field of dimensions `dims`.
fn sample_index([_, dv, ds, dt]: [u32; 4], [iu, iv, is, it]: [u32; 4]) -> usize {
    let d = |x: u32| x as usize;
    ((d(iu) * d(dv) + d(iv)) * d(ds) + d(is)) * d(dt) + d(it)
}

/// The samples one line read from a slab's field (per axis, the indices and how many), and the
/// most cells any of them hit: neighbouring pixels' lines mostly read the same samples (the
/// field is far coarser than the image), and a row of pixels then adds their cells once.
type SampleSet = ([([u32; 2], usize); 4], u16);

/// The cells stored at the samples around the line `q` (the one holding it and, per
/// `interpolate`, its neighbours), appended to `hit` unless `last` (this slab's previous line
/// in the row) read the same samples; returns the most cells any of those samples' rays hit.
fn read_samples(
    f: &Field,
    q: [f64; 4],
    (do_uv, do_st): (bool, bool),
    hit: &mut Vec<u32>,
    last: &mut Option<SampleSet>,
) -> u16 {
    let [du, dv, ds, dt] = f.dims;
    let axes = [
        around(q[0], du, do_uv),
        around(q[1], dv, do_uv),
        around(q[2], ds, do_st),
        around(q[3], dt, do_st),
    ];
    if let Some((seen, most)) = last {
        if *seen == axes {
            return *most;
        }
    }
    let [(us, nu), (vs, nv), (ss, ns), (ts, nt)] = axes;
    let n = f.n as usize;
    let mut most = 0u16;
    for &iu in &us[..nu] {
        for &iv in &vs[..nv] {
            for &is in &ss[..ns] {
                for &it in &ts[..nt] {
                    let s = sample_index(f.dims, [iu, iv, is, it]);
                    most = most.max(f.hits.get(s).copied().unwrap_or(u16::MAX));
                    let ids = &f.ids[s * n..(s + 1) * n];
                    hit.extend(ids.iter().filter(|&&id| id >= 0).map(|&id| id as u32));
                }
            }
        }
    }
    *last = Some((axes, most));
    most
}

/// Answer the line `o + λ·d` from the fields, appending the cells read to `hit` (`last`: per
/// slab, the samples the row's previous line read from it).
fn answer(
    fields: &[(Slab, &Field)],
    (o, d): (DVec3, DVec3),
    how: &Resampling,
    range: (f64, f64),
    hit: &mut Vec<u32>,
    last: &mut [Option<SampleSet>],
) -> Answer {
    let interp = match how.interpolate {
        Interpolate::None => (false, false),
        Interpolate::Uv => (true, false),
        Interpolate::St => (false, true),
        Interpolate::UvSt => (true, true),
    };
    let Some(bounds) = how.conservative else {
        let mut any = false;
        for ((slab, f), last) in fields.iter().zip(last.iter_mut()) {
            if let Some(q) = slab.line(o, d) {
                any = true;
                read_samples(f, q, interp, hit, last);
            }
        }
        return if any { Answer::Field } else { Answer::Outside };
    };
    // What the ray can see: its [near, far] range within the scene's bounds.
    let Some((box_from, box_to)) = clip_line(o, d, bounds) else {
        return Answer::Field;
    };
    let seen = [box_from.max(range.0), box_to.min(range.1)];
    if seen[0] > seen[1] {
        return Answer::Field;
    }
    let (mut held, mut answered) = (false, false);
    for ((slab, f), last) in fields.iter().zip(last.iter_mut()) {
        if let Some(q) = slab.answers(o, d, seen, box_from) {
            held = true;
            answered |= u32::from(read_samples(f, q, interp, hit, last)) <= how.trust;
        }
    }
    match (answered, held) {
        (true, _) => Answer::Field,
        (false, true) => Answer::Overflowed,
        (false, false) => Answer::Outside,
    }
}

/// One row of resampled pixels: the cells it marked, and the pixels the field did not answer.
type RowMarks = (Vec<u32>, Vec<(usize, Answer)>);

/// Mark the cells `camera` sees through the fields (one per slab).
pub fn resample(
    fields: &[(Slab, &Field)],
    cell_count: usize,
    camera: &Camera,
    how: Resampling,
) -> Result<Marks> {
    if how.subsample == 0 {
        return input_err!("subsample must be at least 1");
    }
    // The view's image, and per pixel what the field answered.
    crate::limits::check_views(
        "the field's view",
        std::slice::from_ref(camera),
        2 * crate::limits::IMAGE_BYTES,
    )?;
    for (_, f) in fields {
        let samples: usize = f.dims.iter().map(|&d| d as usize).product::<usize>();
        if f.ids.len() != samples * f.n as usize || f.hits.len() != samples {
            return input_err!(
                "a field holds {} ids and {} hit counts, its dimensions need {} and {samples}",
                f.ids.len(),
                f.hits.len(),
                samples * f.n as usize
            );
        }
        if let Some(&bad) = f.ids.iter().find(|&&c| c >= cell_count as i32) {
            return input_err!("the field names cell {bad}, but there are {cell_count} cells");
        }
    }
    let k = how.subsample as usize;
    let (w, h) = (camera.width as usize, camera.height as usize);
    let (cols, rows) = (w.div_ceil(k), h.div_ceil(k));
    let range = match how.conservative {
        Some([lo, hi]) => camera.clip_range([lo.as_vec3().to_array(), hi.as_vec3().to_array()]),
        None => (0.0, f64::INFINITY),
    };
    // Per row of resampled pixels: its marked cell ids and the pixels the field did not answer.
    let per_row: Vec<RowMarks> = (0..rows)
        .into_par_iter()
        .map(|r| {
            let mut hit = Vec::new();
            let mut missed = Vec::new();
            let mut last = vec![None; fields.len()];
            let y = (r * k + k / 2).min(h - 1);
            for c in 0..cols {
                let x = (c * k + k / 2).min(w - 1);
                let line = camera.ray_z1(DVec2::new(x as f64 + 0.5, y as f64 + 0.5));
                let a = answer(fields, line, &how, range, &mut hit, &mut last);
                if a != Answer::Field {
                    missed.push((y * w + x, a));
                }
            }
            hit.sort_unstable();
            hit.dedup();
            (hit, missed)
        })
        .collect();
    let mut marks = Marks {
        marked: vec![false; cell_count],
        pixels: rows * cols,
        ..Default::default()
    };
    for (hit, missed) in per_row {
        for (p, a) in missed {
            match a {
                Answer::Outside => marks.outside += 1,
                _ => marks.overflowed += 1,
            }
            if how.conservative.is_some() {
                marks.fallback.push(p);
            }
        }
        for c in hit {
            marks.marked[c as usize] = true;
        }
    }
    Ok(marks)
}

/// The scene's bounds, widened by a millionth of its diagonal (and at least 1e-30) so that
/// surfaces on the bounds stay inside: the box conservative resampling clips lines to.
pub fn scene_box(scene: &Scene) -> [DVec3; 2] {
    let [lo, hi] = scene.bounds_f64();
    let eps = (1e-6 * scene.diagonal()).max(1e-30);
    [lo - eps, hi + eps]
}

/// Build what the fallback traces (the frame and BVH of the cell-sorted scene), so that the
/// first view does not pay for it.
pub fn prepare_fallback(sorted: &Scene) -> Result<()> {
    let frame = TraceFrame::of(sorted)?;
    crate::trace::Bvh::of(frame.scene(sorted));
    Ok(())
}

/// Where a pixel centre lies within this many pixels of an edge of its traced triangle, the
/// raster (snapping vertices to its sub-pixel grid, 1/256 pixel on lavapipe) may draw the
/// neighbour across the edge: the fallback also traces the corners of a square this wide
/// around the centre, which straddle any line passing this close.
const EDGE: f64 = 1.0 / 32.0;
const AROUND: [[f64; 2]; 4] = [[EDGE, EDGE], [-EDGE, EDGE], [EDGE, -EDGE], [-EDGE, -EDGE]];

/// The fallback (conservative culling): trace the pixel rays of `pixels` through `sorted` (the
/// scene with its faces in cell order, `offsets` the cells' CSR offsets into them) as the CPU
/// backend of conventional images does, and mark the cells they hit. A pixel centre within
/// [`EDGE`] of its triangle's edge is where the raster may draw the neighbour across the edge
/// instead, so four rays around it mark the neighbours' cells too. Returns the cells it marked
/// that were not marked yet.
pub fn trace_fallback(
    sorted: &Scene,
    offsets: &[u32],
    camera: &Camera,
    pixels: Vec<usize>,
    marked: &mut [bool],
) -> Result<usize> {
    if pixels.is_empty() {
        return Ok(0);
    }
    let (near, far) = camera.clip_range(sorted.bounds());
    let frame = TraceFrame::of(sorted)?;
    let how = Walk {
        cull_backfaces: false,
        far,
        frame: Some(&frame),
    };
    let start = pixels.into_iter().map(|p| (p, near)).collect();
    let walked = walk(sorted, camera, start, how, |c| Ok(vec![false; c.len()]))?;
    let w = camera.width as usize;
    let centre = |p: usize| DVec2::new((p % w) as f64 + 0.5, (p / w) as f64 + 0.5);
    let on_edge: Vec<usize> = walked
        .found
        .par_iter()
        .filter(|&&(p, t)| near_edge(sorted.triangle(t as usize), camera, centre(p)))
        .map(|&(p, _)| p)
        .collect();
    let (origins, dirs): (Vec<[f32; 3]>, Vec<[f32; 3]>) = on_edge
        .iter()
        .flat_map(|&p| AROUND.map(|o| centre(p) + DVec2::from_array(o)))
        .map(|x| {
            let (o, d) = camera.ray_z1(x);
            (
                (o + d * near - frame.shift).as_vec3().to_array(),
                d.as_vec3().to_array(),
            )
        })
        .unzip();
    let around = crate::trace::cast_rays(
        frame.scene(sorted),
        &origins,
        &dirs,
        0.0,
        (far - near) as f32,
    )?;
    let mut added = 0;
    let found = walked.found.iter().map(|&(_, t)| t);
    for t in found.chain(around.triangle.iter().copied().filter(|&t| t >= 0)) {
        // The cell holding sorted face t: the last whose offset is <= t.
        let cell = offsets.partition_point(|&o| o <= t as u32) - 1;
        if !marked[cell] {
            marked[cell] = true;
            added += 1;
        }
    }
    Ok(added)
}

/// Whether the pixel position `x` lies within [`EDGE`] pixels of an edge of `tri` as `camera`
/// projects it (true when a vertex lies behind the camera, where the projection is no guide).
fn near_edge(tri: [DVec3; 3], camera: &Camera, x: DVec2) -> bool {
    let projected = tri.map(|p| camera.project(p));
    if projected
        .iter()
        .any(|&(_, depth)| depth.is_nan() || depth <= 0.0)
    {
        return true;
    }
    let q = projected.map(|(p, _)| p);
    (0..3).any(|i| {
        let (a, b) = (q[i], q[(i + 1) % 3]);
        let e = b - a;
        let len = e.length();
        len <= f64::MIN_POSITIVE || e.perp_dot(x - a).abs() / len < EDGE
    })
}

/// The face ranges `[a, b)` of the marked cells, consecutive cells merged; `offsets` is the
/// cells' CSR offsets into the cell-sorted faces.
pub fn ranges(offsets: &[u32], marked: &[bool]) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    for (c, _) in marked.iter().enumerate().filter(|(_, &m)| m) {
        push_range(&mut out, offsets[c], offsets[c + 1]);
    }
    out
}

/// Render only the marked cells of `sorted` (the scene with its faces in cell order; `order[i]`
/// is the original id of sorted face i) from `camera`: a depth image whose triangle ids are the
/// original scene's.
pub fn render_marked(
    sorted: &Scene,
    order: &[u32],
    offsets: &[u32],
    marked: &[bool],
    camera: &Camera,
) -> Result<(DepthImages, usize)> {
    if offsets.len() != marked.len() + 1 || order.len() != sorted.triangle_count() {
        return input_err!("the cells do not match the cell-sorted scene");
    }
    let start = Instant::now();
    let rs = ranges(offsets, marked);
    let drawn: usize = rs.iter().map(|&(a, b)| (b - a) as usize).sum();
    let mut img = discretize_ranges(sorted, std::slice::from_ref(camera), false, Some(&rs))?;
    for t in img.triangle.iter_mut().filter(|t| **t >= 0) {
        *t = order[*t as usize] as i32;
    }
    img.timings.add("ranges", start.elapsed().as_secs_f64());
    Ok((img, drawn))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neighbours_include_the_nearest_sample() {
        for i in 0..100 {
            let x = i as f64 / 100.0;
            let (one, _) = around(x, 7, false);
            let (two, n) = around(x, 7, true);
            assert!(two[..n].contains(&one[0]), "{x}");
        }
        assert_eq!(around(0.01, 4, true), ([0, 0], 1));
        assert_eq!(around(0.4, 4, true), ([1, 2], 2));
    }

    #[test]
    fn marked_cells_merge_into_ranges() {
        let offsets = [0, 2, 5, 7, 9, 12];
        let marked = [true, true, false, true, true];
        assert_eq!(ranges(&offsets, &marked), vec![(0, 5), (7, 12)]);
        assert_eq!(ranges(&offsets, &[false; 5]), vec![]);
    }
}
