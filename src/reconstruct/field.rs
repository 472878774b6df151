//! A view rendered from the visibility field (visibility-field.txt §4, Fig. 4): resample the
//! field along the camera's pixel rays to mark the cells they see, then rasterize only the
//! marked cells' triangles.
//!
//! Resampling: one pixel in every `subsample × subsample` block (the block's middle pixel,
//! `k·i + k/2` rounded down, at its centre) gives a line; where it crosses the uv and st rectangles gives (u, v, s, t)
//! (`Slab::line`). Without interpolation the sample holding that point is read; with it, its
//! neighbours too (§4.1): the 2 × 2 samples around (u, v) for `Uv`, around (s, t) for `St`, the
//! 16 around both for `UvSt` (always including the nearest). Every id stored there is marked.
//! A pixel whose line runs from the st plane toward the uv plane, runs parallel to either, or
//! misses either rectangle marks nothing; several slabs add their marks. The paper rasterizes
//! the two projected planes in hardware to get (u, v, s, t) per pixel; here the same linear
//! intersection runs on the CPU.
//!
//! Rendering: the scene's faces are kept sorted by cell (`Cells::triangles`), so the marked
//! cells are ranges of faces, drawn as one draw call per run of consecutive marked cells.

use std::time::Instant;

use glam::DVec2;
use rayon::prelude::*;

use crate::camera::Camera;
use crate::discretize::visibility_field::{Field, Slab};
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

/// What resampling found.
#[derive(Debug, Clone, Default)]
pub struct Marks {
    pub marked: Vec<bool>,
    /// Pixels resampled (after subsampling).
    pub pixels: usize,
    /// Of those, how many marked nothing because their line misses the slab.
    pub outside: usize,
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

/// Mark the cells `camera` sees through the fields (one per slab).
pub fn resample(
    fields: &[(Slab, &Field)],
    cell_count: usize,
    camera: &Camera,
    interpolate: Interpolate,
    subsample: u32,
) -> Result<Marks> {
    if subsample == 0 {
        return input_err!("subsample must be at least 1");
    }
    for (_, f) in fields {
        let expect: usize = f.dims.iter().map(|&d| d as usize).product::<usize>() * f.n as usize;
        if f.ids.len() != expect {
            return input_err!(
                "a field holds {} ids, its dimensions need {expect}",
                f.ids.len()
            );
        }
        if let Some(&bad) = f.ids.iter().find(|&&c| c >= cell_count as i32) {
            return input_err!("the field names cell {bad}, but there are {cell_count} cells");
        }
    }
    let k = subsample as usize;
    let (w, h) = (camera.width as usize, camera.height as usize);
    let (cols, rows) = (w.div_ceil(k), h.div_ceil(k));
    let (do_uv, do_st) = match interpolate {
        Interpolate::None => (false, false),
        Interpolate::Uv => (true, false),
        Interpolate::St => (false, true),
        Interpolate::UvSt => (true, true),
    };
    // Per row of resampled pixels: its marked cell ids and the pixels that missed.
    let per_row: Vec<(Vec<u32>, usize)> = (0..rows)
        .into_par_iter()
        .map(|r| {
            let mut hit = Vec::new();
            let mut outside = 0;
            let y = (r * k + k / 2).min(h - 1) as f64 + 0.5;
            for c in 0..cols {
                let x = (c * k + k / 2).min(w - 1) as f64 + 0.5;
                let (o, d) = camera.ray_z1(DVec2::new(x, y));
                let mut any_slab = false;
                for (slab, f) in fields {
                    let Some(q) = slab.line(o, d) else {
                        continue;
                    };
                    any_slab = true;
                    let [du, dv, ds, dt] = f.dims;
                    let (us, nu) = around(q[0], du, do_uv);
                    let (vs, nv) = around(q[1], dv, do_uv);
                    let (ss, ns) = around(q[2], ds, do_st);
                    let (ts, nt) = around(q[3], dt, do_st);
                    for &iu in &us[..nu] {
                        for &iv in &vs[..nv] {
                            for &is in &ss[..ns] {
                                for &it in &ts[..nt] {
                                    let sample = ((iu as usize * dv as usize + iv as usize)
                                        * ds as usize
                                        + is as usize)
                                        * dt as usize
                                        + it as usize;
                                    let n = f.n as usize;
                                    hit.extend(
                                        f.ids[sample * n..(sample + 1) * n]
                                            .iter()
                                            .filter(|&&id| id >= 0)
                                            .map(|&id| id as u32),
                                    );
                                }
                            }
                        }
                    }
                }
                if !any_slab {
                    outside += 1;
                }
            }
            hit.sort_unstable();
            hit.dedup();
            (hit, outside)
        })
        .collect();
    let mut marks = Marks {
        marked: vec![false; cell_count],
        pixels: rows * cols,
        outside: 0,
    };
    for (hit, outside) in per_row {
        marks.outside += outside;
        for c in hit {
            marks.marked[c as usize] = true;
        }
    }
    Ok(marks)
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
