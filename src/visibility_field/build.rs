//! The visibility field (visibility-field.txt §3): which grid cells of the scene's geometry are
//! first hit along the lines of a two-plane parameterization.
//!
//! - Cells (§3.2): every group of geometry (an object, or a connected component when the scene
//!   has a single object, or the scene as a whole) is divided by a grid over its bounding box;
//!   a triangle belongs to the cell holding its centroid, so each triangle is in exactly one
//!   cell. Only non-empty cells get ids, in (group, z, y, x) order; their triangles are listed
//!   cell after cell (CSR).
//! - Slab (§3): a line is given by where it crosses two rectangles, the uv and st planes, in
//!   rectangle coordinates (u, v) and (s, t) in [0, 1)². The field stores the lines running
//!   from the uv plane toward the st plane, and what is first hit between the two planes.
//! - Sampling with pre-filtering (§3.3): sample (iu, iv, is, it) casts `supersample⁴` rays
//!   through a `supersample × supersample` grid of positions in its uv cell and in its st cell
//!   (3 × 3 on each plane → 81 rays) and keeps the `n` cell ids hit most often (ties: the lower
//!   id first), −1 for the rest. The positions are the centres of a regular sub-grid (the
//!   paper's), or with `jitter` a seeded random point in each sub-cell (stratified).

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

pub use super::cells::{cells, Cells, Grid, Grouping, SortedScene};
pub use super::slab::{clip_line, CrossFrom, Rect, Slab, SlabFrom};
use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;
use crate::types::Timings;

/// A sampled visibility field of one slab.
#[derive(Debug, Clone)]
pub struct Field {
    /// (U, V, S, T).
    pub dims: [u32; 4],
    /// Ids per sample.
    pub n: u32,
    /// (U, V, S, T, n) row-major cell ids, −1 empty.
    pub ids: Vec<i32>,
    /// (U, V, S, T): how many distinct cells each sample's rays hit (at most 65535); more than
    /// `n` means the sample overflowed.
    pub hits: Vec<u16>,
    pub rays: u64,
    pub timings: Timings,
}

/// A field built for a scene ([`build`]): its cells, the cell-sorted scene its views draw
/// (sorted face `i` is the scene's `cells.triangles[i]`), one field per slab, and the seconds
/// spent on the cells and on what the fallback traces.
pub struct Built {
    pub cells: Cells,
    pub sorted: Scene,
    pub fields: Vec<Field>,
    pub cell_seconds: f64,
    pub bvh_seconds: f64,
}

/// The cells of `scene` (§3.2) and a field per slab (§3.3), with `n` ids per sample; and the
/// cell-sorted scene's trace frame, BVH and edge neighbours, which the fallback of every view
/// uses, so that the first view does not pay for them.
#[allow(clippy::too_many_arguments)]
pub fn build(
    scene: &Scene,
    slabs: &[Slab],
    uv: [u32; 2],
    st: [u32; 2],
    grid: Grid,
    grouping: Grouping,
    n: u32,
    supersample: Supersample,
) -> Result<Built> {
    if slabs.is_empty() {
        return input_err!("at least one slab is needed");
    }
    let start = Instant::now();
    let cells = cells(scene, grid, grouping)?;
    let sorted = scene.permuted(&cells.triangles)?;
    let cell_seconds = start.elapsed().as_secs_f64();
    let fields = sample(scene, slabs, uv, st, &cells, n, supersample)?;
    let start = Instant::now();
    prepare_views(&sorted)?;
    Ok(Built {
        cells,
        sorted,
        fields,
        cell_seconds,
        bvh_seconds: start.elapsed().as_secs_f64(),
    })
}

/// Build what every view's fallback uses on the cell-sorted scene (its trace frame, BVH and
/// edge neighbours, each cached on the scene), so that the first view does not pay for them:
/// after a build, and after a field is restored from its arrays.
pub fn prepare_views(sorted: &Scene) -> Result<()> {
    let frame = crate::image::pixels::TraceFrame::of(sorted)?;
    crate::trace::Bvh::of(frame.scene(sorted));
    crate::scene::adjacency::EdgeNeighbours::of(sorted);
    Ok(())
}

/// How a sample's rays are placed in its uv and st cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Supersample {
    /// Positions per axis of each plane's cell (3 → 3 × 3 per plane, 81 rays).
    pub per_axis: u32,
    /// `Some(seed)`: a seeded random point in each sub-cell; `None`: sub-cell centres.
    pub jitter: Option<u64>,
}

/// The `ss²` sub-positions of cell `cell` of a `dims` grid over `rect`: offsets `a(j)` along
/// its first axis (outer) and `b(j)` along its second (inner), in cells.
fn sub_positions(
    rect: &Rect,
    cell: [usize; 2],
    dims: [usize; 2],
    ss: usize,
    a: impl Fn(usize) -> f64,
    b: impl Fn(usize) -> f64,
) -> Vec<DVec3> {
    let mut out = Vec::with_capacity(ss * ss);
    for oa in (0..ss).map(&a) {
        for ob in (0..ss).map(&b) {
            let x = (cell[0] as f64 + oa) / dims[0] as f64;
            let y = (cell[1] as f64 + ob) / dims[1] as f64;
            out.push(rect.point(x, y));
        }
    }
    out
}

/// The rays of one uv sample `(iu, iv)` (§3.3, pre-filtering): from `ss²` sub-positions in
/// its uv cell to `ss²` sub-positions in every st cell, as origins and direction vectors
/// whose end (t = 1) lies on the st plane; `offset(at, j)` places sub-position j of stream `at`.
fn beam_rays(
    slab: &Slab,
    offset: &impl Fn(u64, usize) -> f64,
    dims: [u32; 4],
    ss: usize,
    [iu, iv]: [usize; 2],
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let [du, dv, ds, dt] = dims.map(|d| d as usize);
    let rays_per_uv = ds * dt * ss.pow(4);
    let mut origins = Vec::with_capacity(rays_per_uv);
    let mut dirs = Vec::with_capacity(rays_per_uv);
    for is in 0..ds {
        for it in 0..dt {
            // A distinct stream of jitter per sample and axis.
            let at = ((((iu * dv + iv) * ds + is) * dt + it) * 4) as u64;
            let uv = sub_positions(
                &slab.uv,
                [iu, iv],
                [du, dv],
                ss,
                |j| offset(at, j),
                |j| offset(at + 1, j),
            );
            let st = sub_positions(
                &slab.st,
                [is, it],
                [ds, dt],
                ss,
                |j| offset(at + 2, j),
                |j| offset(at + 3, j),
            );
            for a in &uv {
                for b in &st {
                    origins.push(a.as_vec3().to_array());
                    dirs.push((*b - *a).as_vec3().to_array());
                }
            }
        }
    }
    (origins, dirs)
}

/// Ranks the cells one sample's rays hit (§3.3: the cells seen most often first, ties by
/// cell index) and writes the first `out.len()` of them; returns how many distinct cells were
/// hit (more than `out.len()`: the sample overflowed, a line in its beam may see a cell it
/// does not list).
fn rank_cells(tris: &[i32], cell_of: &[u32], out: &mut [i32]) -> u16 {
    let mut hit: Vec<u32> = tris
        .iter()
        .filter(|&&t| t >= 0)
        .map(|&t| cell_of[t as usize])
        .collect();
    hit.sort_unstable();
    let mut counts: Vec<(usize, u32)> = Vec::new();
    for c in hit {
        match counts.last_mut() {
            Some((k, last)) if *last == c => *k += 1,
            _ => counts.push((1, c)),
        }
    }
    counts.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    for (slot, &(_, c)) in out.iter_mut().zip(&counts) {
        *slot = c as i32;
    }
    counts.len().min(u16::MAX as usize) as u16
}

/// Sample the field of each slab (§3.3): `uv` and `st` samples per plane, `n` ids per sample.
pub fn sample(
    scene: &Scene,
    slabs: &[Slab],
    uv: [u32; 2],
    st: [u32; 2],
    cells: &Cells,
    n: u32,
    supersample: Supersample,
) -> Result<Vec<Field>> {
    let dims = [uv[0], uv[1], st[0], st[1]];
    let per_axis = supersample.per_axis;
    if dims.contains(&0) || n == 0 || per_axis == 0 {
        return input_err!(
            "uv {uv:?}, st {st:?}, ids_per_sample {n} and supersample {per_axis} must all be \
             positive"
        );
    }
    if cells.cell_of.len() != scene.triangle_count() {
        return input_err!("the cells were made for another scene");
    }
    let samples: u64 = dims.iter().map(|&d| d as u64).product();
    let per_sample = (per_axis as u64).pow(4);
    // Ids as i32 and an overflow flag per sample; one uv sample's rays at a time.
    crate::limits::check(
        || {
            format!(
                "a field of {} slabs x {dims:?} samples x {n} ids",
                slabs.len()
            )
        },
        crate::limits::product(&[slabs.len() as u64, samples, n as u64]),
        5,
    )?;
    if samples * n as u64 > 1 << 31 || samples * per_sample > 1 << 36 {
        return input_err!(
            "{samples} samples x {n} ids ({per_sample} rays each) is too large a field"
        );
    }
    // Progress in slab samples (iu, iv, is, it) of every slab.
    crate::process::add_total(samples * slabs.len() as u64);
    slabs
        .iter()
        .map(|slab| sample_slab(scene, slab, dims, cells, n, supersample))
        .collect()
}

/// One slab's field (checked by [`sample`]).
fn sample_slab(
    scene: &Scene,
    slab: &Slab,
    dims: [u32; 4],
    cells: &Cells,
    n: u32,
    supersample: Supersample,
) -> Result<Field> {
    let Supersample {
        per_axis: supersample,
        jitter,
    } = supersample;
    let total = Instant::now();
    let samples: u64 = dims.iter().map(|&d| d as u64).product();
    let per_sample = (supersample as u64).pow(4);
    let ss = supersample as usize;
    // The offset of sub-position j along one axis of one plane in sample `at`.
    let offset = |at: u64, j: usize| -> f64 {
        let r = match jitter {
            Some(seed) => {
                let h =
                    crate::random::mix64(seed ^ crate::random::mix64(at * ss as u64 + j as u64));
                (h >> 11) as f64 / (1u64 << 53) as f64
            }
            None => 0.5,
        };
        (j as f64 + r) / ss as f64
    };
    let [du, dv, ds, dt] = dims.map(|d| d as usize);
    let mut ids = vec![-1i32; samples as usize * n as usize];
    let mut hit_counts = vec![0u16; samples as usize];
    let mut cast_seconds = 0.0;
    let mut rank_seconds = 0.0;
    // One uv sample at a time: its (S·T·ss⁴) rays in one batch.
    let st_count = ds * dt;
    // One (iu, iv) row of samples per progress step.
    for iu in 0..du {
        for iv in 0..dv {
            crate::process::check()?;
            crate::process::advance(st_count as u64);
            let start = Instant::now();
            let (origins, dirs) = beam_rays(slab, &offset, dims, ss, [iu, iv]);
            let hits = crate::trace::cast_rays(scene, &origins, &dirs, 0.0, 1.0)?;
            cast_seconds += start.elapsed().as_secs_f64();
            let start = Instant::now();
            let per = ss.pow(4);
            let row = (iu * dv + iv) * st_count;
            let base = row * n as usize;
            ids[base..base + st_count * n as usize]
                .par_chunks_mut(n as usize)
                .zip(hit_counts[row..row + st_count].par_iter_mut())
                .zip(hits.triangle.par_chunks(per))
                .for_each(|((out, count), tris)| *count = rank_cells(tris, &cells.cell_of, out));
            rank_seconds += start.elapsed().as_secs_f64();
        }
    }
    Ok(Field {
        dims,
        n,
        ids,
        hits: hit_counts,
        rays: samples * per_sample,
        timings: Timings::from([
            ("rays", cast_seconds),
            ("rank", rank_seconds),
            ("total", total.elapsed().as_secs_f64()),
        ]),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad(z: f32, size: f32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        (
            vec![
                [-size, -size, z],
                [size, -size, z],
                [size, size, z],
                [-size, size, z],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    /// Two square quads parallel to z = 0, each given as (z, half side), in one scene.
    fn two_quads(a: [f32; 2], b: [f32; 2]) -> Scene {
        let (mut v, mut f) = quad(a[0], a[1]);
        let (v2, f2) = quad(b[0], b[1]);
        f.extend(f2.iter().map(|t| t.map(|i| i + v.len() as u32)));
        v.extend(v2);
        Scene::from_arrays(v, f, None, None).unwrap()
    }

    #[test]
    fn lines_cross_the_slab_one_way() {
        let r = |z| Rect::new(DVec3::new(-1.0, -1.0, z), DVec3::X * 2.0, DVec3::Y * 2.0).unwrap();
        let slab = Slab {
            uv: r(0.0),
            st: r(1.0),
        };
        let q = slab
            .line(DVec3::new(0.0, 0.0, -1.0), DVec3::new(0.1, 0.0, 1.0))
            .unwrap();
        assert!(
            (q[0] - 0.55).abs() < 1e-12 && (q[2] - 0.6).abs() < 1e-12,
            "{q:?}"
        );
        // Backwards, parallel, outside.
        assert!(slab
            .line(DVec3::new(0.0, 0.0, 2.0), DVec3::new(0.0, 0.0, -1.0))
            .is_none());
        assert!(slab.line(DVec3::new(0.0, 0.0, 0.5), DVec3::X).is_none());
        assert!(slab.line(DVec3::new(5.0, 0.0, -1.0), DVec3::Z).is_none());
    }

    #[test]
    fn a_wall_hides_what_is_behind_it_from_every_line() {
        let scene = two_quads([0.3, 10.0], [0.6, 0.2]);
        let r = |z| Rect::new(DVec3::new(-1.0, -1.0, z), DVec3::X * 2.0, DVec3::Y * 2.0).unwrap();
        let slab = Slab {
            uv: r(0.0),
            st: r(1.0),
        };
        let c = cells(&scene, Grid::Cells([2, 2, 2]), Grouping::Objects).unwrap();
        assert_eq!(c.groups, 2);
        let hidden: Vec<i32> = (0..c.table.len())
            .filter(|&k| c.table[k][0] == c.table[c.cell_of[2] as usize][0])
            .map(|k| k as i32)
            .collect();
        let ss = Supersample {
            per_axis: 2,
            jitter: None,
        };
        let field = sample(&scene, &[slab], [4, 4], [4, 4], &c, 3, ss)
            .unwrap()
            .remove(0);
        let jittered = Supersample {
            jitter: Some(7),
            ..ss
        };
        let again = sample(&scene, &[slab], [4, 4], [4, 4], &c, 3, jittered)
            .unwrap()
            .remove(0);
        assert!(again.ids.iter().all(|id| !hidden.contains(id)));
        assert!(field.ids.iter().all(|id| !hidden.contains(id)));
        assert!(field.ids.iter().any(|&id| id >= 0));
        assert_eq!(field.rays, 4u64.pow(4) * 16);
    }

    #[test]
    fn six_slabs_hold_every_line_through_the_bounds() {
        let scene = two_quads([0.0, 1.0], [0.5, 0.3]);
        let slabs = Slab::six(&scene, 0.05).unwrap();
        assert_eq!(slabs.len(), 6);
        let [lo, hi] = scene.bounds_f64();
        let mut seed = 1u64;
        let mut rand = || {
            seed = crate::random::mix64(seed);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..2000 {
            // A point in the bounds, a direction, and an origin outside the bounds behind it.
            let p = lo + (hi - lo) * DVec3::new(rand(), rand(), rand());
            let d = DVec3::new(rand() - 0.5, rand() - 0.5, rand() - 0.5).normalize();
            let o = p - d * 10.0;
            let (a, b) = clip_line(o, d, [lo, hi]).unwrap();
            let held = slabs
                .iter()
                .filter(|s| s.answers(o, d, [a, b], a).is_some());
            assert!(held.count() >= 1, "{o} {d}");
        }
        // From inside the bounds nothing behind the camera may be answered.
        let o = (lo + hi) / 2.0;
        let d = DVec3::new(0.1, 0.2, 1.0);
        let (a, b) = clip_line(o, d, [lo, hi]).unwrap();
        assert!(slabs.iter().all(|s| s.answers(o, d, [0.0, b], a).is_none()));
        assert!(clip_line(DVec3::new(5.0, 5.0, 5.0), DVec3::X, [lo, hi]).is_none());
    }

    #[test]
    fn cells_partition_the_triangles() {
        let (v, f) = quad(0.0, 1.0);
        let scene = Scene::from_arrays(v, f, None, None).unwrap();
        let c = cells(&scene, Grid::Cells([4, 4, 1]), Grouping::Scene).unwrap();
        assert_eq!(c.offsets.last(), Some(&2));
        let mut all = c.triangles.clone();
        all.sort();
        assert_eq!(all, vec![0, 1]);
        for (t, &cell) in c.cell_of.iter().enumerate() {
            let range = c.offsets[cell as usize]..c.offsets[cell as usize + 1];
            assert!(c.triangles[range.start as usize..range.end as usize].contains(&(t as u32)));
        }
    }
}
