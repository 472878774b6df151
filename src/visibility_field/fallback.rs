//! The fallback of conservative resampling: the pixels the field does not answer are traced
//! through the cell-sorted scene, and the cells they hit are marked; and the look along the
//! borders between cells in a drawn view, where a rasterizer's rounding may show a cell that
//! no line marked.

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::build::SortedScene;
use crate::camera::{Camera, Projector};
use crate::error::Result;
use crate::image::pixels::ViewRays;
use crate::input_err;
use crate::scene::adjacency::{EdgeNeighbours, NONE};
use crate::scene::Scene;

/// Where a pixel centre lies within this many pixels of an edge of its traced triangle, the
/// raster (snapping vertices to its sub-pixel grid, 1/256 pixel on lavapipe) may draw the
/// neighbour across the edge: the fallback also traces the corners of a square this wide
/// around the centre, which straddle any line passing this close.
const EDGE: f64 = 1.0 / 32.0;
/// Where a pixel centre lies within this many pixels of an edge, the triangle sharing the edge
/// is drawn too ([`across_near`]): lavapipe's raster snaps vertices to 1/256 pixel.
const FOLD: f64 = 1.0 / 256.0;
const AROUND: [[f64; 2]; 4] = [[EDGE, EDGE], [-EDGE, EDGE], [EDGE, -EDGE], [-EDGE, -EDGE]];

/// The fallback (conservative culling): trace the pixel rays of `pixels` through `sorted` (the
/// scene with its faces in cell order, `offsets` the cells' CSR offsets into them) as the CPU
/// backend of conventional images does (the same f32 rays between the same near and far
/// planes), and mark the cells they hit. A pixel centre within [`EDGE`] of its triangle's edge
/// is where the raster may draw the neighbour across the edge instead, so four rays around it
/// mark the neighbours' cells too. Returns the cells it marked that were not marked yet, and
/// each pixel with the sorted face its ray hit (−1: none), which is also its answer among the
/// marked cells ([`trace_sorted`] takes them as they are).
pub(crate) fn trace_fallback(
    sorted: &SortedScene,
    camera: &Camera,
    rays: &ViewRays,
    pixels: Vec<usize>,
    marked: &mut [bool],
) -> Result<(usize, Vec<(usize, i32)>)> {
    if pixels.is_empty() {
        return Ok((0, Vec::new()));
    }
    let (origins, dirs) = rays.at(camera, &pixels);
    let target = rays.target(sorted.scene);
    let hits = crate::trace::cast_rays_with(target, &origins, &dirs, &rays.range())?;
    let traced: Vec<(usize, i32)> = pixels.into_iter().zip(hits.triangle).collect();
    let w = camera.width as usize;
    let eye = camera.projector();
    let on_edge: Vec<(usize, usize, u8)> = traced
        .par_iter()
        .filter(|&&(_, t)| t >= 0)
        .map(|&(p, t)| {
            let tri = sorted.scene.triangle(t as usize);
            (p, t as usize, near_edges(tri, &eye, centre(p, w)))
        })
        .filter(|&(_, _, near)| near != 0)
        .collect();
    let across = look_across(sorted.scene, camera, rays, &on_edge)?;
    let found = traced.iter().map(|&(_, t)| t);
    let added = mark(sorted, found.chain(across), marked);
    Ok((added, traced))
}

/// The centre of pixel `p` (row-major in an image `w` wide), in pixels.
fn centre(p: usize, w: usize) -> DVec2 {
    DVec2::new((p % w) as f64 + 0.5, (p / w) as f64 + 0.5)
}

/// What may lie across the near edges of the pixels `on_edge` (pixel, sorted face, its edges
/// within [`EDGE`] of the pixel's centre, [`near_edges`]): what the four [`AROUND`] rays of
/// each hit, and the triangles sharing those edges where the raster's rounding may pick them
/// ([`across_near`]). Sorted faces, −1 for a ray that hit nothing.
fn look_across(
    sorted: &Scene,
    camera: &Camera,
    rays: &ViewRays,
    on_edge: &[(usize, usize, u8)],
) -> Result<Vec<i32>> {
    let w = camera.width as usize;
    let points: Vec<DVec2> = on_edge
        .iter()
        .flat_map(|&(p, _, _)| AROUND.map(|o| centre(p, w) + DVec2::from_array(o)))
        .collect();
    let mut found = trace_points(sorted, camera, rays, &points)?;
    let adjacent = EdgeNeighbours::of(sorted);
    let eye = camera.projector();
    found.extend(
        on_edge.iter().flat_map(|&(p, t, near)| {
            across_near(sorted, &adjacent, &eye, (t, near), centre(p, w))
        }),
    );
    Ok(found)
}

/// Mark the cells of the sorted faces `faces` (−1 ignored); returns how many were not marked.
fn mark(sorted: &SortedScene, faces: impl IntoIterator<Item = i32>, marked: &mut [bool]) -> usize {
    let cells = sorted_cells(sorted);
    let mut added = 0;
    for t in faces.into_iter().filter(|&t| t >= 0) {
        let c = cells.cell[t as usize] as usize;
        if !marked[c] {
            marked[c] = true;
            added += 1;
        }
    }
    added
}

/// Which edges of `tri` (bit `k`: from corner `k` to `k + 1`) pass within [`EDGE`] pixels of
/// the pixel position `x` as `camera` projects it (all of them when a vertex lies behind the
/// camera, where the projection is no guide, or an edge collapses to a point).
fn near_edges(tri: [DVec3; 3], camera: &Projector, x: DVec2) -> u8 {
    let projected = tri.map(|p| camera.project(p));
    if projected
        .iter()
        .any(|&(_, depth)| depth.is_nan() || depth <= 0.0)
    {
        return 0b111;
    }
    let q = projected.map(|(p, _)| p);
    let mut near = 0;
    for i in 0..3 {
        let (a, b) = (q[i], q[(i + 1) % 3]);
        let e = b - a;
        let len = e.length();
        if len <= f64::MIN_POSITIVE {
            return 0b111;
        }
        if e.perp_dot(x - a).abs() / len < EDGE {
            near |= 1 << i;
        }
    }
    near
}

/// The triangles sharing the edges of sorted face `t` that pass within [`FOLD`] pixels of the
/// centre `x` (of those `near` it, [`near_edges`]), where the raster, rounding, may give the
/// pixel to the neighbour across: a sliver seen edge on (thinner on screen than [`EDGE`]), which
/// no ray around the centre meets, or one folding back behind `t` beyond a silhouette, which
/// wins the pixel only where its plane is not behind `t`'s there. On khr_simple_instancing and
/// the Cornell box such pixels were the only ones of 1-7 visible cells in a view; without this
/// look, 54 visible cells instead of 15 went missing over the bench's views of every shared
/// scene (a tolerance of 1e-6 of the depth for the fold changed none of them, so it went).
/// All near edges' neighbours when `t` does not project (a vertex behind).
fn across_near(
    sorted: &Scene,
    adjacent: &EdgeNeighbours,
    camera: &Projector,
    (t, near): (usize, u8),
    x: DVec2,
) -> Vec<i32> {
    let tri = sorted.triangle(t);
    let q = tri.map(|v| camera.project(v));
    let projects = q.iter().all(|&(p, depth)| depth > 0.0 && p.is_finite());
    let (o, d) = camera.ray_z1(x);
    // Where the pixel's line meets a triangle's plane (λ along it; None: parallel).
    let meet = |v: [DVec3; 3]| {
        let n = (v[1] - v[0]).cross(v[2] - v[0]);
        let dn = d.dot(n);
        (dn != 0.0).then(|| (v[0] - o).dot(n) / dn)
    };
    let mine = meet(tri);
    (0..3)
        .filter(|k| near >> k & 1 == 1)
        .filter_map(|k| {
            let n = adjacent.0[t][k];
            if n == NONE {
                return None;
            }
            if !projects {
                return Some(n as i32);
            }
            let (a, b, c) = (q[k].0, q[(k + 1) % 3].0, q[(k + 2) % 3].0);
            let e = b - a;
            if e.perp_dot(x - a).abs() >= FOLD * e.length() {
                return None;
            }
            let other = sorted.triangle(n as usize);
            let m = other.map(|v| camera.project(v).0);
            let off = m
                .into_iter()
                .map(|v| e.perp_dot(v - a))
                .max_by(|u, v| u.abs().total_cmp(&v.abs()))
                .unwrap_or(0.0);
            let folds = off * e.perp_dot(c - a) > 0.0;
            let level = match (mine, meet(other)) {
                (Some(zt), Some(zn)) => zn <= zt,
                _ => true,
            };
            (!folds || level).then_some(n as i32)
        })
        .collect()
}

/// The cell of each face of a cell-sorted scene (cells are runs of faces), kept on the scene
/// for the offsets it was made from.
struct SortedCells {
    offsets: Vec<u32>,
    cell: Vec<u32>,
}

fn sorted_cells(sorted: &SortedScene) -> std::sync::Arc<SortedCells> {
    let offsets = sorted.offsets;
    let make = || {
        let mut cell = vec![0u32; sorted.scene.triangle_count()];
        for (c, w) in offsets.windows(2).enumerate() {
            cell[w[0] as usize..w[1] as usize].fill(c as u32);
        }
        SortedCells {
            offsets: offsets.to_vec(),
            cell,
        }
    };
    let kept = sorted.scene.derived(make);
    if kept.offsets == offsets {
        kept
    } else {
        std::sync::Arc::new(make())
    }
}

/// Look across the edges near the borders between cells in a drawn field view (`ids`: sorted
/// faces, −1 empty), and mark the cells found there. The field answered most pixels without a
/// ray, and the fallback's ray at some pixels found nothing where the raster still draws
/// something (an edge-on wall's silhouette), so nothing looked across the edges near those
/// centres; where an edge passes that close and the cell across was marked by no pixel, the
/// GPU's rounding may give the pixel to the triangle across, and the cell goes missing (1-7
/// of 78-503 visible cells per view on the Cornell box and khr_simple_instancing, each seen at
/// a single pixel). A pixel not `looked` at (where the fallback traced the triangle the image
/// shows, and looked across its edges) whose 4-neighbour shows another cell (or nothing), within
/// [`EDGE`] of an edge of its triangle, traces the four [`AROUND`] rays as the fallback does,
/// and within [`FOLD`] takes the triangle sharing the edge ([`across_near`]). Returns the
/// cells it marked.
pub(crate) fn look_across_borders(
    sorted: &SortedScene,
    camera: &Camera,
    rays: &ViewRays,
    ids: &[i32],
    looked: &[bool],
    marked: &mut [bool],
) -> Result<usize> {
    let cells = sorted_cells(sorted);
    let (w, h) = (camera.width as usize, camera.height as usize);
    if ids.len() != w * h || looked.len() != w * h {
        return input_err!(
            "{} and {} pixels for a {w}x{h} view",
            ids.len(),
            looked.len()
        );
    }
    let cell = |t: i32| {
        if t < 0 {
            u32::MAX
        } else {
            cells.cell[t as usize]
        }
    };
    let eye = camera.projector();
    let on_edge: Vec<(usize, usize, u8)> = (0..h)
        .into_par_iter()
        .flat_map_iter(|y| {
            let (cell, eye) = (&cell, &eye);
            (0..w).filter_map(move |x| {
                let p = y * w + x;
                let t = ids[p];
                if t < 0 || looked[p] {
                    return None;
                }
                let c = cell(t);
                let border = (x > 0 && cell(ids[p - 1]) != c)
                    || (x + 1 < w && cell(ids[p + 1]) != c)
                    || (y > 0 && cell(ids[p - w]) != c)
                    || (y + 1 < h && cell(ids[p + w]) != c);
                if !border {
                    return None;
                }
                let near = near_edges(sorted.scene.triangle(t as usize), eye, centre(p, w));
                (near != 0).then_some((p, t as usize, near))
            })
        })
        .collect();
    let across = look_across(sorted.scene, camera, rays, &on_edge)?;
    Ok(mark(sorted, across, marked))
}

/// The triangle (sorted face, −1 none) each pixel position in `points` sees between the view's
/// near and far planes, through the whole scene.
fn trace_points(
    sorted: &Scene,
    camera: &Camera,
    rays: &ViewRays,
    points: &[DVec2],
) -> Result<Vec<i32>> {
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let (near, far, frame) = (rays.near, rays.far, &rays.frame);
    let eye = camera.projector();
    let (origins, dirs): (Vec<[f32; 3]>, Vec<[f32; 3]>) = points
        .par_iter()
        .map(|&x| {
            let (o, d) = eye.ray_z1(x);
            (
                (o + d * near - frame.shift).as_vec3().to_array(),
                d.as_vec3().to_array(),
            )
        })
        .unzip();
    let scene = frame.scene(sorted);
    Ok(crate::trace::cast_rays(scene, &origins, &dirs, 0.0, (far - near) as f32)?.triangle)
}
