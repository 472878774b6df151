//! A view from multi-cell impostors (multi-cell-orthographic-impostors.txt §3.2, §3.4 runtime):
//! frustum culling of the cells, a sort by distance, the nearest cells drawn as triangles until
//! the triangle budget is met, every other cell as the impostor image whose direction makes the
//! smallest angle with the direction from the cell to the eye, drawn as a billboard through the
//! cell's centre facing that direction. As in the paper, nothing is corrected per pixel: a
//! billboard texel is looked up where the pixel's ray meets the billboard's plane, and its depth
//! is the plane's. Billboards and triangles are depth-tested against each other.
//!
//! Triangles are rasterized on the GPU (the cells' faces, sorted by cell, drawn as ranges) and
//! lit like the impostor images (`super::build::lit`); billboards are composited on the
//! CPU.

use std::time::Instant;

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use crate::camera::{Camera, Projection, Projector};
use crate::error::Result;
use crate::image::{discretize_ranges, push_range};
use crate::impostors::build::{impostor_camera, lit, ImpostorProjection, Impostors};
use crate::input_err;
use crate::scene::Scene;
use crate::types::{DepthImages, Stats, Timings};

/// How each cell was drawn.
pub const CULLED: i32 = -2;
pub const TRIANGLES: i32 = -1;

#[derive(Debug, Clone)]
pub struct ImpostorView {
    pub width: u32,
    pub height: u32,
    /// Linear RGB, black where nothing is drawn.
    pub color: Vec<[f32; 3]>,
    /// Camera-space depth, +inf where nothing is drawn.
    pub depth: Vec<f32>,
    /// Per cell: `CULLED`, `TRIANGLES`, or the index of the impostor direction used.
    pub used: Vec<i32>,
    pub stats: Stats,
    pub timings: Timings,
}

/// The lit colour and depth of a depth image of `scene` (black / +inf where empty): each
/// pixel's colour lit with its shading normal, as the impostors' texels are.
pub fn lit_image(scene: &Scene, img: &DepthImages) -> (Vec<[f32; 3]>, Vec<f32>) {
    let lights = crate::shading::Prelit::of(scene);
    let color = img
        .triangle
        .par_iter()
        .zip(img.color.par_iter().zip(&img.position))
        .zip(&img.shading_normal)
        .map(|((&t, (&c, p)), n)| {
            if t < 0 {
                [0.0; 3]
            } else {
                let p = DVec3::from_array(p.map(f64::from));
                lit(c, DVec3::from_array(n.map(f64::from)), p, &lights)
            }
        })
        .collect();
    (color, img.depth.clone())
}

/// Render every triangle of `scene` from `camera`, lit as the impostors are: the reference.
pub fn render_lit(scene: &Scene, camera: &Camera) -> Result<(Vec<[f32; 3]>, Vec<f32>, f64)> {
    let start = Instant::now();
    let img = discretize_ranges(scene, std::slice::from_ref(camera), false, None)?;
    let (c, d) = lit_image(scene, &img);
    Ok((c, d, start.elapsed().as_secs_f64()))
}

/// The view from `camera`. `sorted` is the scene with its faces in the impostors' cell order
/// (`Impostors::triangles`), needed when `triangle_budget > 0`; `None` as budget means no
/// limit.
pub fn reconstruct(
    imp: &Impostors,
    projection: ImpostorProjection,
    sorted: Option<&Scene>,
    camera: &Camera,
    triangle_budget: Option<u64>,
    screen_threshold: f64,
) -> Result<ImpostorView> {
    let total = Instant::now();
    check_inputs(imp, sorted, triangle_budget, screen_threshold)?;
    // Colour and depth of the impostors and of the triangles drawn, and the composite.
    crate::limits::check_views(
        "the impostor view",
        std::slice::from_ref(camera),
        2 * crate::limits::IMAGE_BYTES,
    )?;
    let (w, h) = (camera.width as usize, camera.height as usize);

    let start = Instant::now();
    let order = cells_in_view(imp, sorted, camera);
    let cull_seconds = start.elapsed().as_secs_f64();
    let Choice {
        used,
        ranges,
        drawn,
    } = choose(imp, camera, &order, triangle_budget, screen_threshold);

    let start = Instant::now();
    let (mut color, mut depth) = match (sorted, ranges.is_empty()) {
        (Some(s), false) => {
            let img = discretize_ranges(s, std::slice::from_ref(camera), false, Some(&ranges))?;
            lit_image(s, &img)
        }
        _ => (vec![[0.0; 3]; w * h], vec![f32::INFINITY; w * h]),
    };
    let triangle_seconds = start.elapsed().as_secs_f64();

    // 4. Billboards, depth-tested: set up nearest first, then drawn in bands of rows on all
    // cores, each band taking the billboards in that order (so every pixel sees the same
    // sequence of depth tests however the bands are shared out).
    let start = Instant::now();
    let mut billboards = Vec::new();
    for &c in &order {
        if let Ok(k) = usize::try_from(used[c]) {
            billboards.extend(Billboard::new(imp, projection, c, k, camera)?);
        }
    }
    let eye = PixelRays::of(camera);
    let band = BAND_ROWS * w;
    let billboard_pixels: u64 = color
        .par_chunks_mut(band)
        .zip(depth.par_chunks_mut(band))
        .enumerate()
        .map(|(b, (color, depth))| {
            let rows = b * BAND_ROWS..b * BAND_ROWS + color.len() / w;
            let bands = billboards.iter();
            bands
                .map(|bb| bb.draw(&eye, rows.clone(), w, color, depth))
                .sum::<u64>()
        })
        .sum();
    let impostor_seconds = start.elapsed().as_secs_f64();
    let count = |u: i32| used.iter().filter(|&&x| x == u).count() as f64;
    let impostors = used.iter().filter(|&&x| x >= 0).count() as f64;
    Ok(ImpostorView {
        width: camera.width,
        height: camera.height,
        color,
        depth,
        stats: Stats::from([
            ("cells_culled", count(CULLED)),
            ("cells_triangles", count(TRIANGLES)),
            ("cells_impostors", impostors),
            ("triangles_drawn", drawn as f64),
            ("billboard_pixels", billboard_pixels as f64),
        ]),
        used,
        timings: Timings::from([
            ("cull", cull_seconds),
            ("triangles", triangle_seconds),
            ("impostors", impostor_seconds),
            ("total", total.elapsed().as_secs_f64()),
        ]),
    })
}

/// Refuses a cell table that does not add up, a budget without the scene, a scene other than
/// the impostors' own, and a negative or non-finite threshold.
fn check_inputs(
    imp: &Impostors,
    sorted: Option<&Scene>,
    triangle_budget: Option<u64>,
    screen_threshold: f64,
) -> Result<()> {
    if imp.offsets.len() != imp.cells.len() + 1 {
        return input_err!("the impostors' cell table is inconsistent");
    }
    if triangle_budget != Some(0) && sorted.is_none() {
        return input_err!("a triangle budget needs the scene (scene=...)");
    }
    if let Some(s) = sorted {
        if s.triangle_count() != imp.triangles.len() || s.vertices().len() != imp.vertices {
            return input_err!("the scene is not the one the impostors were made from");
        }
    }
    if !(screen_threshold.is_finite() && screen_threshold >= 0.0) {
        return input_err!("screen_threshold must be finite and >= 0, got {screen_threshold}");
    }
    Ok(())
}

/// Steps 1 and 2: the cells that reach into the view (the sphere around a cell's box, or
/// around its own triangles, is not wholly outside a frustum plane), nearest first.
fn cells_in_view(imp: &Impostors, sorted: Option<&Scene>, camera: &Camera) -> Vec<usize> {
    let c_count = imp.cells.len();
    let eye = camera.eye();
    let planes = camera.frustum_planes(1.0, 0.0, DVec3::ZERO);
    let tri_spheres: Vec<(DVec3, f64)> = (0..c_count)
        .map(|c| {
            let (a, b) = (imp.offsets[c] as usize, imp.offsets[c + 1] as usize);
            let Some(s) = sorted else {
                return (imp.cells[c].center(), 0.0);
            };
            let mut lo = DVec3::splat(f64::INFINITY);
            let mut hi = DVec3::splat(f64::NEG_INFINITY);
            for i in a..b {
                for p in s.triangle(i) {
                    lo = lo.min(p);
                    hi = hi.max(p);
                }
            }
            if a == b {
                (imp.cells[c].center(), 0.0)
            } else {
                ((lo + hi) / 2.0, (hi - lo).length() / 2.0)
            }
        })
        .collect();
    let outside = |c: DVec3, r: f64| planes.iter().any(|&(n, d)| n.dot(c) + d < -r);
    let mut order: Vec<usize> = (0..c_count)
        .filter(|&c| {
            let cell = &imp.cells[c];
            let (tc, tr) = tri_spheres[c];
            !(outside(cell.center(), cell.radius()) && outside(tc, tr))
        })
        .collect();
    order.sort_by(|&a, &b| {
        let da = (imp.cells[a].center() - eye).length_squared();
        let db = (imp.cells[b].center() - eye).length_squared();
        da.total_cmp(&db).then(a.cmp(&b))
    });
    order
}

/// What step 3 decided per cell: `used` is `CULLED`, `TRIANGLES` or the impostor direction;
/// `ranges` the sorted triangle ranges to draw; `drawn` their triangle count.
struct Choice {
    used: Vec<i32>,
    ranges: Vec<(u32, u32)>,
    drawn: u64,
}

/// Step 3: triangles for the nearest cells while the budget lasts (and, with a threshold,
/// while they look big enough); the rest as impostors.
fn choose(
    imp: &Impostors,
    camera: &Camera,
    order: &[usize],
    triangle_budget: Option<u64>,
    screen_threshold: f64,
) -> Choice {
    let mut used = vec![CULLED; imp.cells.len()];
    let mut left = triangle_budget.unwrap_or(u64::MAX);
    let mut budget_open = triangle_budget != Some(0);
    let mut ranges: Vec<(u32, u32)> = Vec::new();
    let mut drawn = 0u64;
    for &c in order {
        let n = (imp.offsets[c + 1] - imp.offsets[c]) as u64;
        let big = screen_threshold == 0.0
            || projected_size(camera, imp.cells[c].center(), imp.cells[c].radius())
                >= screen_threshold;
        if budget_open && big && n <= left {
            left -= n;
            drawn += n;
            used[c] = TRIANGLES;
            push_range(&mut ranges, imp.offsets[c], imp.offsets[c + 1]);
        } else {
            // A cell too small on screen is an impostor whatever the budget; the first one
            // that does not fit ends the triangles (the budget is met).
            if big && n > left {
                budget_open = false;
            }
            used[c] = best_direction(imp, c, camera) as i32;
        }
    }
    ranges.sort_unstable();
    Choice {
        used,
        ranges,
        drawn,
    }
}

/// The on-screen diameter of a sphere in pixels (perspective: at its centre's depth).
fn projected_size(camera: &Camera, c: DVec3, r: f64) -> f64 {
    let (_, z) = camera.project(c);
    if z <= r {
        return f64::INFINITY;
    }
    2.0 * r / camera.pixel_footprint(z)
}

/// The impostor direction with the smallest angle to the direction from the cell to the eye
/// (for an orthographic eye, to the eye's backward axis).
pub fn best_direction(imp: &Impostors, c: usize, camera: &Camera) -> usize {
    let to_eye = match camera.projection {
        Projection::Perspective { .. } => {
            (camera.eye() - imp.cells[c].center()).normalize_or_zero()
        }
        Projection::Orthographic { .. } => -camera.forward(),
    };
    let mut best = 0;
    let mut best_dot = f64::NEG_INFINITY;
    for (k, d) in imp.directions.iter().enumerate() {
        let dot = d.dot(to_eye);
        if dot > best_dot {
            best_dot = dot;
            best = k;
        }
    }
    best
}

/// Rows of the view each thread composites at a time.
const BAND_ROWS: usize = 8;

/// One cell's impostor image placed as a billboard: the plane through the cell's centre facing
/// the impostor's direction, and the pixels its square may cover.
struct Billboard<'a> {
    centre: DVec3,
    facing: DVec3,
    /// The impostor's camera, which maps a point of the plane to its texel.
    image: Projector,
    rows: std::ops::Range<usize>,
    columns: std::ops::Range<usize>,
    /// The image's crop: x, y, width, height.
    crop: [i64; 4],
    /// The cell's image along this direction, rows of `width` texels.
    texels: &'a [[u8; 4]],
    width: usize,
}

impl<'a> Billboard<'a> {
    /// Cell `c`'s impostor `k` seen from `camera`; `None` when its image is empty.
    fn new(
        imp: &'a Impostors,
        projection: ImpostorProjection,
        c: usize,
        k: usize,
        camera: &Camera,
    ) -> Result<Option<Self>> {
        let cell = &imp.cells[c];
        let facing = imp.directions[k];
        let icam = impostor_camera(cell, facing, imp.resolution, projection)?;
        let crop = imp.crops[c * imp.directions.len() + k];
        if crop[2] == 0 {
            return Ok(None);
        }
        let centre = cell.center();
        // The pixels it may cover: those of the image's cropped rectangle on the plane, with a
        // pixel's margin for rounding (the plane's map to the view is projective, so the
        // rectangle's corners bound what lies inside it).
        let plane_depth = icam.project(centre).1;
        let (w, h) = (camera.width as usize, camera.height as usize);
        let mut lo = DVec2::splat(f64::INFINITY);
        let mut hi = DVec2::splat(f64::NEG_INFINITY);
        let mut behind = false;
        let [cx, cy, cw, ch] = crop.map(f64::from);
        for (a, b) in [(cx, cy), (cx + cw, cy), (cx + cw, cy + ch), (cx, cy + ch)] {
            let corner = icam.unproject(DVec2::new(a, b), plane_depth);
            let (px, z) = camera.project(corner);
            if !(z > 0.0 && px.is_finite()) {
                behind = true;
                break;
            }
            lo = lo.min(px);
            hi = hi.max(px);
        }
        let (columns, rows) = if behind {
            (0..w, 0..h)
        } else {
            let at = |v: f64, n: usize| (v.max(0.0) as usize).min(n);
            (
                at(lo.x.floor() - 1.0, w)..at(hi.x.ceil() + 1.0, w),
                at(lo.y.floor() - 1.0, h)..at(hi.y.ceil() + 1.0, h),
            )
        };
        let size = imp.height * imp.width;
        let base = (c * imp.directions.len() + k) * size;
        Ok(Some(Billboard {
            centre,
            facing,
            image: icam.projector(),
            rows,
            columns,
            crop: crop.map(i64::from),
            texels: &imp.color[base..base + size],
            width: imp.width,
        }))
    }

    /// Where the ray (`o`, `dir`) meets the plane, in homogeneous form: the texel position
    /// times k, k, the ray's depth there times m, and m. Affine along a row of pixels.
    fn homogeneous(&self, o: DVec3, dir: DVec3) -> [f64; 5] {
        let along = self.facing.dot(self.centre - o);
        let m = dir.dot(self.facing);
        let h = self.image.project_homogeneous(o * m + dir * along, m);
        [h.x, h.y, h.z, along, m]
    }

    /// Composite the billboard into the view's rows `rows` (`color` and `depth` hold just
    /// those rows, `w` pixels each); returns the pixels written. Each pixel's ray meets the
    /// plane, the texel there is looked up, and the plane's depth is tested. Along a row the
    /// texel position and the depth are ratios of affine functions of the column, set up from
    /// the row's first two pixels.
    fn draw(
        &self,
        eye: &PixelRays,
        rows: std::ops::Range<usize>,
        w: usize,
        color: &mut [[f32; 3]],
        depth: &mut [f32],
    ) -> u64 {
        let [cx, cy, cw, ch] = self.crop;
        let x0 = self.columns.start as f64;
        let mut written = 0;
        for y in rows.start.max(self.rows.start)..rows.end.min(self.rows.end) {
            let (o, dir) = eye.at(x0, y as f64);
            let first = self.homogeneous(o, dir);
            let next = self.homogeneous(o + eye.step.0, dir + eye.step.1);
            let slope: [f64; 5] = std::array::from_fn(|k| next[k] - first[k]);
            let at = |k: usize, i: f64| first[k] + slope[k] * i;
            let row = (y - rows.start) * w;
            for x in self.columns.clone() {
                let i = x as f64 - x0;
                // The ray's direction has camera-space z −1: t is the plane's depth here.
                let m = at(4, i);
                if m.abs() < 1e-12 {
                    continue;
                }
                let t = at(3, i) / m;
                if t <= 0.0 {
                    continue;
                }
                let k = at(2, i);
                let (tx, ty) = (at(0, i) / k, at(1, i) / k);
                if !(tx.is_finite() && ty.is_finite()) {
                    continue;
                }
                let (tx, ty) = (tx.floor() as i64 - cx, ty.floor() as i64 - cy);
                if tx < 0 || ty < 0 || tx >= cw || ty >= ch {
                    continue;
                }
                let rgba = self.texels[ty as usize * self.width + tx as usize];
                if rgba[3] == 0 {
                    continue;
                }
                let (z, i) = (t as f32, row + x);
                if z < depth[i] {
                    depth[i] = z;
                    color[i] = [rgba[0], rgba[1], rgba[2]].map(|v| v as f32 / 255.0);
                    written += 1;
                }
            }
        }
        written
    }
}

/// A view's pixel rays ([`Camera::ray_z1`]) as affine functions of the pixel, so that a row is
/// walked by adding a step: origin and direction at pixel (0, 0) and their change per column
/// and per row.
struct PixelRays {
    first: (DVec3, DVec3),
    step: (DVec3, DVec3),
    down: (DVec3, DVec3),
}

impl PixelRays {
    fn of(camera: &Camera) -> Self {
        let p = camera.projector();
        let first = p.ray_z1(DVec2::new(0.5, 0.5));
        let right = p.ray_z1(DVec2::new(1.5, 0.5));
        let below = p.ray_z1(DVec2::new(0.5, 1.5));
        PixelRays {
            first,
            step: (right.0 - first.0, right.1 - first.1),
            down: (below.0 - first.0, below.1 - first.1),
        }
    }

    /// The ray through the centre of pixel (`x`, `y`).
    fn at(&self, x: f64, y: f64) -> (DVec3, DVec3) {
        let o = self.first.0 + self.step.0 * x + self.down.0 * y;
        let d = self.first.1 + self.step.1 * x + self.down.1 * y;
        (o, d)
    }
}
