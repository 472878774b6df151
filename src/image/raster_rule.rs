//! The raster's answer at pixel centres that lie on an edge, for the CPU backend of conventional
//! images. A ray through a pixel centre hits the triangle that contains the centre exactly; the
//! GPU rasteriser instead snaps each vertex's window position to a fixed-point grid (1/256
//! pixel, the sub-pixel precision of Mesa's llvmpipe/lavapipe and of most GPUs) and applies
//! the top-left fill rule, so where a centre lies within that snapping of an edge the two can
//! name different triangles. This module re-decides such pixels the way the rasteriser does:
//!
//! 1. suspects: pixels whose traced triangle has an edge within [`NEAR_EDGE`] pixels of the
//!    centre, empty pixels beside a covered one, and pixels beside a nearer surface (a
//!    silhouette in front, whose snapped edge may cover the centre);
//! 2. candidates: the traced triangle and the first front surfaces hit by four rays a
//!    [`NEAR_EDGE`] of a pixel around the centre;
//! 3. each candidate's vertices go through the raster path's f32 transform (positions relative
//!    to the scene centre, the same clip matrix, perspective divide, viewport), are snapped to
//!    1/256 pixel, and the centre is tested with exact integer edge functions and the top-left
//!    rule; of the candidates that cover it, the nearest along the pixel ray wins.
//!
//! The emulation is not bit-exact (the GPU's own f32 arithmetic may round a vertex to the
//! neighbouring grid point), so a few edge pixels still differ; it leaves a pixel as traced when
//! a candidate crosses the near plane.

use glam::Vec4;
use rayon::prelude::*;

use super::pixels::{PixelRays, SurfacePlane, TraceFrame};
use crate::camera::Camera;
use crate::error::Result;
use crate::scene::Scene;
use crate::trace::{nearest_hits_facing, Query};

/// Sub-pixel steps of the rasteriser's fixed-point vertex positions.
const SUBPIXEL: f32 = 256.0;

/// How close to an edge (pixels) a centre must lie for the raster to be asked, and how far from
/// the centre the four candidate rays pass. Snapping moves an edge by at most about 1/512 px.
pub(crate) const NEAR_EDGE: f64 = 1.0 / 64.0;

/// A camera's raster view of the scene: a vertex's snapped window position, transformed as the
/// GPU path does (`gpu::depth`: positions relative to the scene centre rounded to f32, the f32
/// clip matrix, the perspective divide, the viewport with window y down), minus the half pixel
/// that puts pixel centres on integers, in fixed point ([`SUBPIXEL`] steps). A vertex behind the
/// eye (clipped by the near plane: the emulation does not clip) or too far off the image for 32
/// bits is [`Snap::OFF`].
///
/// A scene with more vertices than [`LAZY_VERTICES_PER_PIXEL`] per pixel has its vertices
/// snapped as candidate triangles are judged, not all up front, so that the pass costs what the
/// pixels near edges ask rather than what the scene holds; smaller scenes are snapped whole, in
/// parallel, which costs less than three vertices per pixel near an edge. Either way a vertex
/// gets the same arithmetic, and the same position.
struct Snap {
    clip: glam::Mat4,
    centre: glam::DVec3,
    half: [f32; 2],
    /// Every vertex's position, where the scene is snapped whole.
    window: Option<Vec<[i32; 2]>>,
}

/// Above this many vertices per pixel a view's vertices are snapped on demand (see [`Snap`]).
/// 1024x768 depth images, best of 5: a 4M-triangle tiling of `khr_toy_car` (2.6 vertices
/// per pixel) took 69 ms in its edge pass snapped whole and 45 ms on demand; a 2M-triangle
/// tiling of `stanford_bunny` (1.3 per pixel) 48 and 55 ms, `khr_toy_car` itself 9.5 and
/// 14.5 ms.
const LAZY_VERTICES_PER_PIXEL: usize = 2;

/// A triangle's snapped window positions.
type Fixed = [[i64; 2]; 3];

impl Snap {
    const OFF: [i32; 2] = [i32::MIN, i32::MIN];

    fn new(scene: &Scene, cam: &Camera) -> Self {
        let (near, far) = cam.clip_range(scene.bounds());
        let centre = scene.center();
        let clip = (cam.projection_matrix(near, far) * cam.view_matrix_relative(centre)).as_mat4();
        let half = [cam.width as f32 / 2.0, cam.height as f32 / 2.0];
        let mut snap = Self {
            clip,
            centre,
            half,
            window: None,
        };
        let pixels = cam.width as usize * cam.height as usize;
        if scene.vertices().len() <= LAZY_VERTICES_PER_PIXEL * pixels {
            let window = scene
                .vertices()
                .par_iter()
                .map(|&v| snap.vertex(v))
                .collect();
            snap.window = Some(window);
        }
        snap
    }

    /// Vertex `v`'s snapped window position, or [`Snap::OFF`].
    fn vertex(&self, v: [f32; 3]) -> [i32; 2] {
        let (clip, half) = (self.clip, self.half);
        let limit = (i32::MAX / 2) as f32;
        let p = (glam::Vec3::from_array(v).as_dvec3() - self.centre).as_vec3();
        let c = clip * Vec4::new(p.x, p.y, p.z, 1.0);
        if c.w.is_nan() || c.w <= 0.0 {
            return Self::OFF;
        }
        let inv = 1.0 / c.w;
        let x = c.x * inv * half[0] + half[0];
        let y = c.y * inv * -half[1] + half[1];
        let fixed = [(x - 0.5) * SUBPIXEL, (y - 0.5) * SUBPIXEL];
        if fixed.iter().all(|f| f.abs() < limit) {
            fixed.map(round_half_away)
        } else {
            Self::OFF
        }
    }

    /// Triangle `t`'s snapped corners, or `None` when one is [`Snap::OFF`].
    fn fixed(&self, scene: &Scene, t: usize) -> Option<Fixed> {
        let face = scene.faces()[t];
        let vertices = scene.vertices();
        let mut out = [[0i64; 2]; 3];
        for (k, &i) in face.iter().enumerate() {
            let v = match &self.window {
                Some(w) => w[i as usize],
                None => self.vertex(vertices[i as usize]),
            };
            if v == Self::OFF {
                return None;
            }
            out[k] = v.map(i64::from);
        }
        Some(out)
    }
}

/// `f.round() as i32` for `|f| < 2^30`, without the call to `roundf` that `f32::round` is on
/// x86-64 without SSE4.1 (2% of a CPU image): the truncation and the fraction `f - trunc(f)`
/// are exact in f32, so halves round away from zero as `round` does.
#[inline]
fn round_half_away(f: f32) -> i32 {
    let i = f as i32;
    let frac = f - i as f32;
    i + i32::from(frac >= 0.5) - i32::from(frac <= -0.5)
}

/// Whether the raster covers pixel `(x, y)`'s centre with the snapped triangle `v`: every edge
/// function non-negative, zero only on a top or left edge (window y points down).
fn covers(v: Fixed, x: usize, y: usize) -> bool {
    let p = [x as i64 * SUBPIXEL as i64, y as i64 * SUBPIXEL as i64];
    let area =
        (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[2][0] - v[0][0]) * (v[1][1] - v[0][1]);
    if area == 0 {
        return false;
    }
    // Order the corners so that the inside is where every edge function is positive.
    let v = if area > 0 { v } else { [v[0], v[2], v[1]] };
    (0..3).all(|i| {
        let (a, b) = (v[i], v[(i + 1) % 3]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let e = dx * (p[1] - a[1]) - dy * (p[0] - a[0]);
        e > 0 || (e == 0 && (dy < 0 || (dy == 0 && dx > 0)))
    })
}

/// The outward unit normal (pixels) and the distance (pixels, positive inside) of the pixel
/// centre from each edge of the snapped triangle `v`.
fn edges(v: Fixed, x: usize, y: usize) -> [([f64; 2], f64); 3] {
    let p = [x as f64 * SUBPIXEL as f64, y as f64 * SUBPIXEL as f64];
    let area =
        (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[2][0] - v[0][0]) * (v[1][1] - v[0][1]);
    let v = if area >= 0 { v } else { [v[0], v[2], v[1]] };
    std::array::from_fn(|i| {
        let (a, b) = (v[i].map(|c| c as f64), v[(i + 1) % 3].map(|c| c as f64));
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        // Not `hypot`, a call into libm: the corners are integers below 2^31, so the squares
        // cannot overflow and the root is as good.
        let len = (dx * dx + dy * dy).sqrt();
        if len == 0.0 {
            return ([0.0, 0.0], f64::INFINITY);
        }
        // Inside is where dx (p.y - a.y) - dy (p.x - a.x) > 0, i.e. along (-dy, dx).
        let inside = (dx * (p[1] - a[1]) - dy * (p[0] - a[0])) / len / SUBPIXEL as f64;
        ([dy / len, -dx / len], inside)
    })
}

/// One pixel to re-decide: its index, and the range of its candidate rays.
struct Suspect {
    pixel: usize,
    rays: std::ops::Range<usize>,
}

/// Re-decide the pixels of one traced image (`ids`, row-major, −1 empty) whose centres lie on an
/// edge, as the rasteriser would: returns the pixels that change, with their new triangle, and
/// the seconds the whole pass took (`ids` itself is left as it is).
///
/// A covered pixel can only lie within [`NEAR_EDGE`] of its triangle's edge if a 4-neighbour
/// names another triangle (the neighbour most across that edge lies beyond the edge's line,
/// outside the convex triangle), so the snapped transform is computed only for those pixels;
/// each edge that near gets one ray just across it. An empty pixel is re-decided when the
/// snapped triangle of a covered neighbour passes within [`NEAR_EDGE`] of its centre.
/// With `keep` (triangle bits, as `trace::cast_rays_kept` takes them) only those triangles
/// are drawn: the rays across edges pass through the others (for views drawn without culling
/// back faces, as the visibility field's are).
pub(crate) fn settle_edges(
    scene: &Scene,
    cam: &Camera,
    cull_backfaces: bool,
    frame: &TraceFrame,
    ids: &[i32],
    keep: Option<&[u64]>,
) -> Result<(Vec<(usize, i32)>, f64)> {
    debug_assert!(
        keep.is_none() || !cull_backfaces,
        "kept triangles are drawn unculled"
    );
    let start = std::time::Instant::now();
    let snap = Snap::new(scene, cam);
    let found = near_edge_pixels(scene, cam, &snap, ids);
    if found.is_empty() {
        return Ok((Vec::new(), start.elapsed().as_secs_f64()));
    }
    let mut suspects = Vec::with_capacity(found.len());
    let mut offsets = Vec::new();
    for (pixel, (across, count)) in found {
        let at = offsets.len();
        offsets.extend(across[..count].iter().map(|&o| (pixel, o)));
        suspects.push(Suspect {
            pixel,
            rays: at..offsets.len(),
        });
    }
    let planes = SurfacePlane::of(scene);
    let judge = Judge {
        scene,
        snap: &snap,
        planes: &planes[..],
        rays: PixelRays::new(cam),
        clip: cam.clip_range(scene.bounds()),
        ids,
        size: (cam.width as usize, cam.height as usize),
    };
    let across = judge.trace_across(cull_backfaces, frame, &offsets, keep)?;
    let decided: Vec<Option<i32>> = suspects
        .par_iter()
        .map(|s| judge.decide(s.pixel, &across[s.rays.clone()]))
        .collect();
    let changes = suspects
        .iter()
        .zip(decided)
        .filter_map(|(s, t)| t.filter(|&t| t != ids[s.pixel]).map(|t| (s.pixel, t)))
        .collect();
    Ok((changes, start.elapsed().as_secs_f64()))
}

/// The 4-neighbours of pixel `p` in a `w`×`h` image (None beyond the border).
fn neighbours(p: usize, (w, h): (usize, usize)) -> [Option<usize>; 4] {
    let (x, y) = (p % w, p / w);
    [
        (x > 0).then(|| p - 1),
        (x + 1 < w).then(|| p + 1),
        (y > 0).then(|| p - w),
        (y + 1 < h).then(|| p + w),
    ]
}

/// Up to three offsets (pixels), the first `.1` of them used: a suspect pixel's rays across its
/// near edges (in place, not a vector per pixel).
type Across = ([[f64; 2]; 3], usize);

/// Per suspect pixel, the offsets (pixels) of the rays that look across its near edges; none
/// for an empty pixel that a neighbour's triangle nearly covers (its candidates are those).
fn near_edge_pixels(scene: &Scene, cam: &Camera, snap: &Snap, ids: &[i32]) -> Vec<(usize, Across)> {
    let size = (cam.width as usize, cam.height as usize);
    (0..size.0 * size.1)
        .into_par_iter()
        .filter_map(|p| {
            let (x, y) = (p % size.0, p / size.0);
            let t = ids[p];
            let around = neighbours(p, size).into_iter().flatten().map(|q| ids[q]);
            if t < 0 {
                let near_one = around.filter(|&q| q >= 0).any(|q| {
                    snap.fixed(scene, q as usize)
                        .is_some_and(|v| edges(v, x, y).iter().all(|e| e.1 > -NEAR_EDGE))
                });
                return near_one.then_some((p, ([[0.0; 2]; 3], 0)));
            }
            if around.clone().all(|q| q == t) {
                return None;
            }
            let v = snap.fixed(scene, t as usize)?;
            let mut across: Across = ([[0.0; 2]; 3], 0);
            for (n, d) in edges(v, x, y) {
                if d.abs() < NEAR_EDGE {
                    let step = d + NEAR_EDGE / 2.0;
                    across.0[across.1] = [n[0] * step, n[1] * step];
                    across.1 += 1;
                }
            }
            (across.1 > 0).then_some((p, across))
        })
        .collect()
}

/// What suspect pixels are decided against: the snapped triangles, the resolve's planes for
/// their depth along a pixel's ray, the camera's pixel rays and clip range, and the traced
/// image. It casts the rays across near edges too, from the same rays and range.
struct Judge<'a> {
    scene: &'a Scene,
    snap: &'a Snap,
    planes: &'a [SurfacePlane],
    rays: PixelRays,
    clip: (f64, f64),
    ids: &'a [i32],
    size: (usize, usize),
}

impl Judge<'_> {
    /// The first front surface (or every surface, without culling) of one ray per (pixel,
    /// offset) between the camera's clip planes: the triangles just across each near edge, −1
    /// for none.
    fn trace_across(
        &self,
        cull_backfaces: bool,
        frame: &TraceFrame,
        offsets: &[(usize, [f64; 2])],
        keep: Option<&[u64]>,
    ) -> Result<Vec<i32>> {
        let w = self.size.0;
        let (origins, dirs): (Vec<[f32; 3]>, Vec<[f32; 3]>) = offsets
            .par_iter()
            .map(|&(p, [dx, dy])| {
                let (x, y) = ((p % w) as f64 + 0.5, (p / w) as f64 + 0.5);
                let (o, d) = self.rays.ray_at(x + dx, y + dy);
                (
                    (o - frame.shift).as_vec3().to_array(),
                    d.as_vec3().to_array(),
                )
            })
            .unzip();
        let (near, far) = self.clip;
        let range = Query::new(near as f32, (far as f32).max(near as f32));
        let target = frame.scene(self.scene);
        Ok(match keep {
            Some(keep) => crate::trace::cast_rays_kept(target, &origins, &dirs, &range, keep)?,
            None => nearest_hits_facing(target, &origins, &dirs, 1, &range, cull_backfaces)?,
        }
        .triangle)
    }

    /// The triangle the rasteriser gives pixel `p`: the nearest candidate (the traced triangle,
    /// or the neighbours' for an empty pixel, and those `across` its near edges) whose snapped
    /// triangle covers the centre. None leaves the pixel as traced.
    fn decide(&self, p: usize, across: &[i32]) -> Option<i32> {
        let (x, y) = (p % self.size.0, p / self.size.0);
        // At most three across and the traced triangle, or four neighbours: in place.
        let mut candidates = [-1i32; 7];
        let mut count = 0;
        let around = neighbours(p, self.size);
        let own = (self.ids[p] >= 0).then_some(self.ids[p]);
        let others = around.into_iter().flatten().map(|q| self.ids[q]);
        for t in across
            .iter()
            .copied()
            .chain(own)
            .chain(others.filter(|_| own.is_none()))
        {
            if t >= 0 {
                candidates[count] = t;
                count += 1;
            }
        }
        let candidates = &mut candidates[..count];
        candidates.sort_unstable();
        let mut kept = 0;
        for i in 0..count {
            if i == 0 || candidates[i] != candidates[kept - 1] {
                candidates[kept] = candidates[i];
                kept += 1;
            }
        }
        let candidates = &candidates[..kept];
        let (o, d) = self.rays.ray(x, y);
        let (near, far) = self.clip;
        let mut best: Option<(f64, i32)> = None;
        for &t in candidates {
            let v = self.snap.fixed(self.scene, t as usize)?; // crosses the near plane: as traced
            if !covers(v, x, y) {
                continue;
            }
            let z = self.planes[t as usize].ray_depth(o, d);
            if !(near..=far).contains(&z) {
                continue;
            }
            if best.is_none_or(|(bz, bt)| (z, t) < (bz, bt)) {
                best = Some((z, t));
            }
        }
        match best {
            Some((_, t)) => Some(t),
            // The traced triangle does not cover the centre, nor does what lies across its near
            // edges: background, when a ray across found nothing (a silhouette).
            None if self.ids[p] >= 0 && across.contains(&-1) => Some(-1),
            None => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Snapped whole or on demand, every triangle gets the same corners (the choice is by the
    /// view's size; here both are made for one view), including those behind the eye.
    /// The rounding without `roundf` is `f32::round` on halves, near halves, negatives and a
    /// spread of values up to the limit.
    #[test]
    fn rounding_is_round_half_away_from_zero() {
        let mut values = vec![0.0f32, -0.0, 0.5, -0.5, 1.5, -1.5, 2.5, -2.5, 1e9, -1e9];
        for k in [0.5f32, 1.5, 2.5, 1000.5, 123_456.5, 4_194_303.5] {
            for x in [k, -k] {
                values.extend([x, x.next_up(), x.next_down()]);
            }
        }
        let mut f = 0.37f32;
        while f < (i32::MAX / 2) as f32 {
            values.extend([f, -f, f.next_up(), f.next_down()]);
            f *= 1.7;
        }
        for v in values {
            assert_eq!(round_half_away(v), v.round() as i32, "{v}");
        }
    }

    #[test]
    fn vertices_snap_the_same_whole_or_on_demand() {
        let scene = crate::trace::testdata::spheres(3);
        let eye = glam::DVec3::new(3.0, 0.5, 0.2);
        let cam = Camera::look_at(
            eye,
            glam::DVec3::new(6.0, 0.0, 0.0),
            glam::DVec3::Y,
            1.2,
            64,
            48,
            None,
            None,
        )
        .unwrap();
        let whole = Snap::new(&scene, &cam);
        assert!(
            whole.window.is_some(),
            "642 vertices, 3072 pixels: snapped whole"
        );
        let lazy = Snap {
            window: None,
            ..Snap::new(&scene, &cam)
        };
        let (mut off, mut on) = (0, 0);
        for t in 0..scene.triangle_count() {
            let (a, b) = (whole.fixed(&scene, t), lazy.fixed(&scene, t));
            assert_eq!(a, b, "triangle {t}");
            (off, on) = (
                off + usize::from(a.is_none()),
                on + usize::from(a.is_some()),
            );
        }
        assert!(
            off > 0 && on > 0,
            "the eye sits among the spheres: {off} off, {on} on"
        );
    }

    #[test]
    fn the_top_left_rule_gives_a_shared_edge_to_one_triangle() {
        // A square split along its diagonal, corners on pixel centres (0,0)..(2,2): the centre
        // (1,1) lies on the diagonal, (0,1) and (1,0) on the outer edges.
        let s = SUBPIXEL as i64;
        let (a, b, c, d) = ([0, 0], [2 * s, 0], [2 * s, 2 * s], [0, 2 * s]);
        let (upper, lower) = ([a, b, c], [a, c, d]);
        for (x, y) in [(1, 1), (0, 1), (1, 0), (2, 1), (1, 2), (0, 0)] {
            let n = covers(upper, x, y) as u32 + covers(lower, x, y) as u32;
            let inside_square = x < 2 && y < 2; // the top-left rule keeps left and top edges
            assert_eq!(n, inside_square as u32, "pixel ({x}, {y})");
        }
        // Either winding covers the same pixels.
        assert_eq!(covers([a, c, b], 1, 0), covers(upper, 1, 0));
        assert!(
            !covers([a, a, c], 1, 1),
            "a degenerate triangle covers nothing"
        );
        // The centre (1, 1) lies on the diagonal and one pixel inside the upper triangle's other
        // two edges; the diagonal's outward normal points left and down (window y is down).
        let e = edges(upper, 1, 1);
        let diagonal = e
            .iter()
            .find(|e| e.1.abs() < 1e-12)
            .expect("on the diagonal");
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!((diagonal.0[0] + h).abs() < 1e-12 && (diagonal.0[1] - h).abs() < 1e-12);
        assert!(e.iter().filter(|e| (e.1 - 1.0).abs() < 1e-12).count() == 2);
    }
}
