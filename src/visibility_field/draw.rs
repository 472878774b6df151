//! Drawing the marked cells (visibility-field.txt §4: only what the field says is visible).
//! The scene's faces are kept sorted by cell (`Cells::triangles`), so the marked cells are
//! ranges of faces: one draw call per run of consecutive marked cells on the GPU
//! ([`render_sorted`]), or traced on the CPU, each ray meeting only the marked cells' triangles
//! ([`trace_sorted`]).

use std::time::Instant;

use super::build::SortedScene;
use crate::camera::Camera;
use crate::error::Result;
use crate::image::pixels::{resolve_ids, ViewRays};
use crate::image::raster_rule::settle_edges;
use crate::image::{discretize_ranges, push_range};
use crate::types::DepthImages;

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
    sorted: &SortedScene,
    marked: &[bool],
    camera: &Camera,
) -> Result<(DepthImages, usize)> {
    sorted.check_marks(marked)?;
    let (mut img, drawn) = render_sorted(sorted, marked, camera)?;
    remap(&mut img, sorted.order);
    Ok((img, drawn))
}

/// Sorted faces' ids to the scene's.
pub(super) fn remap(img: &mut DepthImages, order: &[u32]) {
    for t in img.triangle.iter_mut().filter(|t| **t >= 0) {
        *t = order[*t as usize] as i32;
    }
}

/// [`render_marked`] with the sorted faces' ids.
pub(super) fn render_sorted(
    sorted: &SortedScene,
    marked: &[bool],
    camera: &Camera,
) -> Result<(DepthImages, usize)> {
    let start = Instant::now();
    let rs = ranges(sorted.offsets, marked);
    let drawn: usize = rs.iter().map(|&(a, b)| (b - a) as usize).sum();
    let cameras = std::slice::from_ref(camera);
    let mut img = discretize_ranges(sorted.scene, cameras, false, Some(&rs))?;
    img.timings.add("ranges", start.elapsed().as_secs_f64());
    Ok((img, drawn))
}

/// The image [`render_marked`] draws, without the GPU (a field view's `"cpu"` backend): traced
/// as the CPU backend of conventional images traces (`discretize_traced`), each pixel-centre
/// ray meeting only the marked cells' triangles (the BVH's traversal passes through the
/// others), centres on an edge decided by the raster's rule among them. `known`: pixels the
/// fallback already traced through the whole scene, with what they hit; the cell of what
/// they hit is marked, so that is their answer here too and they are not traced again.
/// Triangle ids are the sorted faces'.
pub(super) fn trace_sorted(
    sorted: &SortedScene,
    marked: &[bool],
    camera: &Camera,
    rays: &ViewRays,
    known: &[(usize, i32)],
) -> Result<(DepthImages, usize)> {
    let start = Instant::now();
    let scene = sorted.scene;
    let rs = ranges(sorted.offsets, marked);
    let drawn: usize = rs.iter().map(|&(a, b)| (b - a) as usize).sum();
    let mut keep = vec![0u64; scene.triangle_count().div_ceil(64)];
    for &(a, b) in &rs {
        set_bits(&mut keep, a as usize, b as usize);
    }
    let npx = camera.width as usize * camera.height as usize;
    let mut ids = vec![-1i32; npx];
    let mut done = vec![false; npx];
    for &(p, t) in known {
        ids[p] = t;
        done[p] = true;
    }
    let todo: Vec<usize> = (0..npx).filter(|&p| !done[p]).collect();
    let (origins, dirs) = rays.at(camera, &todo);
    let target = rays.target(scene);
    let hits = crate::trace::cast_rays_kept(target, &origins, &dirs, &rays.range(), &keep)?;
    for (&p, &t) in todo.iter().zip(&hits.triangle) {
        ids[p] = t;
    }
    let (changes, edge_seconds) =
        settle_edges(scene, camera, false, &rays.frame, &ids, Some(&keep))?;
    for (p, t) in changes {
        ids[p] = t;
    }
    let (mut img, resolve_seconds) = resolve_ids(scene, std::slice::from_ref(camera), ids)?;
    img.timings = crate::types::Timings::from([
        ("bvh", hits.bvh_build_seconds),
        ("trace", hits.trace_seconds),
        ("edges", edge_seconds),
        ("resolve", resolve_seconds),
        ("total", start.elapsed().as_secs_f64()),
    ]);
    Ok((img, drawn))
}

/// Set bits `[a, b)` of `bits`.
fn set_bits(bits: &mut [u64], a: usize, b: usize) {
    let mut i = a;
    while i < b {
        if i.is_multiple_of(64) && i + 64 <= b {
            bits[i / 64] = u64::MAX;
            i += 64;
        } else {
            bits[i / 64] |= 1 << (i % 64);
            i += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn marked_cells_merge_into_ranges() {
        let offsets = [0, 2, 5, 7, 9, 12];
        let marked = [true, true, false, true, true];
        assert_eq!(ranges(&offsets, &marked), vec![(0, 5), (7, 12)]);
        assert_eq!(ranges(&offsets, &[false; 5]), vec![]);
    }
}
