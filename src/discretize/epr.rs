//! Eye-based point generation (eye-based-point-rendering.txt §3.1-3.4, §4.1.1) and the iVIR
//! density it is compared with.
//!
//! Per triangle:
//! 1. Visibility (§3.1): one bit per off-screen view. The paper tests the vertices against
//!    frusta enlarged by 20%; a large triangle can span a frustum with every vertex outside it
//!    (a floor under a cube map's −Y face), so we keep a view unless all three vertices lie
//!    outside one plane of its 20%-enlarged frustum — conservative for every triangle. A
//!    reflector's own triangles are left out of its own cube map (they surround its centre).
//! 2. Density (§3.2, §4.1.1, Eq. 2-3): the spacing of the points is the eye's pixel footprint
//!    at the distance light travels from the triangle via the nearest reflector to the eye,
//!    `s = d_r · θ_pixel / ρ_scale`, with `d_r = |e − cp| + |cp − cc|`, `cc` the triangle's
//!    circumcentre and `cp` the point of the reflector's bounding sphere closest to the line from
//!    `cc` to the eye. The spacing never drops below what the finest cube map can show (the
//!    paper's cap at the maximal off-screen resolution) nor below `sqrt(area / MAX_PER_TRIANGLE)`
//!    (a reflector touching the eye or the triangle must not make the point count unbounded).
//!    iVIR instead spaces points by the off-screen texel: `s = d_rt · 2 / resolution`.
//! 3. Stochastic culling (§3.2): a triangle of at most 1/10 EPR pixel (area / s²) is dropped with
//!    probability `1 − 10·A`, from a hash of (seed, triangle index): deterministic and
//!    independent of thread order.
//! 4. Points (§3.3): wgpu here has no conservative rasterization, so the "EPR space"
//!    rasterization is done exactly on the CPU: the triangle, in its own plane with x along its
//!    longest edge, is covered by a lattice of cells of side `s` centred on its bounding box, and
//!    every cell that overlaps the triangle (separating-axis test) gives one point at the cell's
//!    centre, with `length = s` (Eq. 4 with the cell as the sample's area). A triangle whose
//!    bounding box fits in one cell gives one point at its box centre, its length the box's
//!    larger side, so that the square still covers the whole triangle.

use std::time::Instant;

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use crate::camera::{Camera, Projection};
use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;
use crate::splat::Points;

/// Most points one triangle may produce.
pub const MAX_PER_TRIANGLE: f64 = 65536.0;
/// How much the view frusta are enlarged for the visibility bits (§3.1).
pub const FRUSTUM_MARGIN: f64 = 1.2;

/// A reflective object: a bounding sphere, and the triangles it is made of (left out of its own
/// cube map).
#[derive(Debug, Clone)]
pub struct Reflector {
    pub center: DVec3,
    pub radius: f64,
    pub triangles: Vec<u32>,
}

/// How the spacing of the points is chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Density {
    /// EPR: the eye's pixel footprint via the nearest reflector (Eq. 2-3), times 1/ρ_scale.
    Eye { rho_scale: f64 },
    /// iVIR: the off-screen texel at the triangle's distance from the reflector.
    OffScreen,
}

/// The reflectors' cube-map views, six per reflector in `Camera::cube` order, each at its own
/// resolution, with the near plane on the reflector's bounding sphere.
pub fn cube_views(reflectors: &[Reflector], resolutions: &[u32]) -> Result<Vec<Camera>> {
    let mut out = Vec::with_capacity(6 * reflectors.len());
    for (r, &res) in reflectors.iter().zip(resolutions) {
        out.extend(Camera::cube(r.center, res, Some(r.radius.max(1e-9)), None)?);
    }
    Ok(out)
}

/// The eye's angular pixel size (radians per pixel at unit distance) or, for an orthographic
/// eye, its pixel size in world units (`None` distance dependence).
fn eye_pixel(eye: &Camera) -> (f64, bool) {
    match eye.projection {
        Projection::Perspective { yfov } => (2.0 * (yfov / 2.0).tan() / eye.height as f64, true),
        Projection::Orthographic { ymag, .. } => (2.0 * ymag / eye.height as f64, false),
    }
}

/// Points for the cube maps of `reflectors` (resolution per reflector), seen by `eye`.
pub fn generate(
    scene: &Scene,
    eye: &Camera,
    reflectors: &[Reflector],
    resolutions: &[u32],
    density: Density,
    seed: u64,
) -> Result<Points> {
    let total = Instant::now();
    if reflectors.is_empty() {
        return input_err!("EPR points need at least one reflector");
    }
    if resolutions.len() != reflectors.len() {
        return input_err!(
            "{} reflectors but {} cube-map resolutions",
            reflectors.len(),
            resolutions.len()
        );
    }
    if let Density::Eye { rho_scale } = density {
        if !(rho_scale.is_finite() && rho_scale > 0.0) {
            return input_err!("rho_scale must be finite and > 0, got {rho_scale}");
        }
    }
    for (i, r) in reflectors.iter().enumerate() {
        if !(r.center.is_finite() && r.radius.is_finite() && r.radius >= 0.0) {
            return input_err!(
                "reflector {i} has centre {:?} and radius {}: both must be finite, the radius >= 0",
                r.center,
                r.radius
            );
        }
        if resolutions[i] == 0 {
            return input_err!("reflector {i} has a cube-map resolution of 0");
        }
    }
    let views = cube_views(reflectors, resolutions)?;
    let words = views.len().div_ceil(64).max(1);
    let start = Instant::now();
    let frusta: Vec<Frustum> = views.iter().map(Frustum::of).collect();
    // Which reflector, if any, each triangle belongs to.
    let mut owner = vec![u32::MAX; scene.triangle_count()];
    for (k, r) in reflectors.iter().enumerate() {
        for &t in &r.triangles {
            if let Some(o) = owner.get_mut(t as usize) {
                *o = k as u32;
            }
        }
    }
    let (pixel, perspective) = eye_pixel(eye);
    let e = eye.eye();
    let diag = {
        let [lo, hi] = scene.bounds();
        (DVec3::from(hi.map(f64::from)) - DVec3::from(lo.map(f64::from))).length()
    };
    let floor = diag * 1e-9;
    let verts = scene.vertices();
    let faces = scene.faces();
    let per_triangle: Vec<TrianglePoints> = faces
        .par_iter()
        .enumerate()
        .map(|(t, f)| {
            let p = f.map(|i| DVec3::from(verts[i as usize].map(f64::from)));
            let mut bits = vec![0u64; words];
            for (v, fr) in frusta.iter().enumerate() {
                if owner[t] == (v / 6) as u32 {
                    continue;
                }
                if fr.may_see(&p) {
                    bits[v / 64] |= 1 << (v % 64);
                }
            }
            if bits.iter().all(|&b| b == 0) {
                return TrianglePoints::Invisible;
            }
            let cc = circumcentre(&p);
            let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
            // The finest spacing any cube map that sees the triangle can show.
            let mut cap = f64::INFINITY;
            let mut via = f64::INFINITY;
            for (k, r) in reflectors.iter().enumerate() {
                if owner[t] == k as u32
                    || (0..6).all(|f| bits[(6 * k + f) / 64] >> ((6 * k + f) % 64) & 1 == 0)
                {
                    continue;
                }
                let d_rt = ((cc - r.center).length() - r.radius).max(floor);
                cap = cap.min(d_rt * 2.0 / resolutions[k] as f64);
                let cp = closest_on_sphere_to_segment(r.center, r.radius, cc, e);
                via = via.min((e - cp).length() + (cp - cc).length());
            }
            let s = match density {
                Density::Eye { rho_scale } => {
                    let eye_s = if perspective {
                        via.max(floor) * pixel
                    } else {
                        pixel
                    };
                    (eye_s / rho_scale).max(cap)
                }
                Density::OffScreen => cap,
            };
            let s = s.max((area / MAX_PER_TRIANGLE).sqrt()).max(floor);
            let epr_area = area / (s * s);
            if epr_area <= 0.1 && unit_hash(seed, t as u64) >= 10.0 * epr_area {
                return TrianglePoints::Culled;
            }
            TrianglePoints::Points(bits, cover(&p, s))
        })
        .collect();

    let mut out = Points {
        view_count: views.len(),
        ..Default::default()
    };
    let (mut invisible, mut culled, mut sampled) = (0usize, 0usize, 0usize);
    let materials = scene.material_ids();
    for (t, tp) in per_triangle.into_iter().enumerate() {
        let (bits, pts) = match tp {
            TrianglePoints::Invisible => {
                invisible += 1;
                continue;
            }
            TrianglePoints::Culled => {
                culled += 1;
                continue;
            }
            TrianglePoints::Points(bits, pts) => (bits, pts),
        };
        sampled += 1;
        let n = normal(scene, t);
        for (c, l) in pts {
            out.center.push(c.as_vec3().to_array());
            out.length.push(l as f32);
            out.triangle.push(t as i32);
            out.normal.push(n);
            out.material.push(materials[t]);
            out.views.extend_from_slice(&bits);
        }
    }
    let generate_seconds = start.elapsed().as_secs_f64();
    out.timings = vec![
        ("points".into(), generate_seconds),
        ("total".into(), total.elapsed().as_secs_f64()),
    ];
    out.stats = vec![
        ("points".into(), out.len() as f64),
        ("triangles_sampled".into(), sampled as f64),
        ("triangles_culled".into(), culled as f64),
        ("triangles_outside_views".into(), invisible as f64),
    ];
    Ok(out)
}

enum TrianglePoints {
    Invisible,
    Culled,
    Points(Vec<u64>, Vec<(DVec3, f64)>),
}

fn normal(scene: &Scene, t: usize) -> [f32; 3] {
    let v = scene.vertices();
    let f = scene.faces()[t].map(|i| DVec3::from(v[i as usize].map(f64::from)));
    (f[1] - f[0])
        .cross(f[2] - f[0])
        .normalize_or_zero()
        .as_vec3()
        .to_array()
}

/// A uniform number in [0, 1) from (seed, i): SplitMix64's finaliser.
fn unit_hash(seed: u64, i: u64) -> f64 {
    let z = seed
        .wrapping_mul(0x9e37_79b9_7f4a_7c15)
        .wrapping_add(i)
        .wrapping_add(0x9e37_79b9_7f4a_7c15);
    (mix64(z) >> 11) as f64 / (1u64 << 53) as f64
}

/// SplitMix64's finaliser: a well-mixed 64-bit hash of `z`.
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The circumcentre of a triangle; its centroid when the triangle is degenerate.
fn circumcentre(p: &[DVec3; 3]) -> DVec3 {
    let a = p[1] - p[0];
    let b = p[2] - p[0];
    let n = a.cross(b);
    let d = 2.0 * n.length_squared();
    if d <= f64::MIN_POSITIVE {
        return (p[0] + p[1] + p[2]) / 3.0;
    }
    let c = p[0] + (n.cross(a) * b.length_squared() + b.cross(n) * a.length_squared()) / d;
    if c.is_finite() {
        c
    } else {
        (p[0] + p[1] + p[2]) / 3.0
    }
}

/// The point of the sphere (centre, radius) closest to the segment a-b: the sphere point toward
/// the segment's closest point to the centre (the centre itself when that point is the centre).
fn closest_on_sphere_to_segment(center: DVec3, radius: f64, a: DVec3, b: DVec3) -> DVec3 {
    let ab = b - a;
    let t = if ab.length_squared() > 0.0 {
        ((center - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let q = a + ab * t;
    let to = q - center;
    let d = to.length();
    if d <= radius {
        // The segment enters the sphere: the path touches the reflector at q.
        q
    } else {
        center + to * (radius / d)
    }
}

/// A view frustum's side planes, enlarged by `FRUSTUM_MARGIN`, and its viewing half-space, as
/// (normal, offset) with inside meaning `n·p + d >= 0`.
struct Frustum {
    planes: Vec<(DVec3, f64)>,
}

impl Frustum {
    fn of(cam: &Camera) -> Self {
        Self {
            planes: cam.frustum_planes(FRUSTUM_MARGIN, 0.0, DVec3::ZERO),
        }
    }

    /// False only when all three vertices lie outside one plane.
    fn may_see(&self, p: &[DVec3; 3]) -> bool {
        self.planes
            .iter()
            .all(|&(n, d)| p.iter().any(|&q| n.dot(q) + d >= 0.0))
    }
}

/// Conservative coverage of triangle `p` by a lattice of cells of side `s` in its own plane
/// (x along its longest edge), the lattice centred on the triangle's bounding box: one
/// (centre, length) per overlapping cell.
fn cover(p: &[DVec3; 3], s: f64) -> Vec<(DVec3, f64)> {
    let edges = [p[1] - p[0], p[2] - p[1], p[0] - p[2]];
    let longest = (0..3)
        .max_by(|&i, &j| {
            edges[i]
                .length_squared()
                .total_cmp(&edges[j].length_squared())
        })
        .unwrap_or(0);
    let n = edges[0].cross(-edges[2]);
    let u = edges[longest].normalize_or_zero();
    let v = n.normalize_or_zero().cross(u);
    if u == DVec3::ZERO || v == DVec3::ZERO {
        // Degenerate: one point covering its extent.
        let lo = p[0].min(p[1]).min(p[2]);
        let hi = p[0].max(p[1]).max(p[2]);
        return vec![((lo + hi) / 2.0, (hi - lo).max_element().max(s * 1e-6))];
    }
    let o = p[0];
    let q = p.map(|x| DVec2::new((x - o).dot(u), (x - o).dot(v)) / s);
    let lo = q[0].min(q[1]).min(q[2]);
    let hi = q[0].max(q[1]).max(q[2]);
    let ext = hi - lo;
    let to_world = |c: DVec2| o + (u * c.x + v * c.y) * s;
    if ext.x <= 1.0 && ext.y <= 1.0 {
        return vec![(to_world((lo + hi) / 2.0), ext.max_element() * s)];
    }
    let cells = DVec2::new(ext.x.ceil().max(1.0), ext.y.ceil().max(1.0));
    let origin = (lo + hi) / 2.0 - cells / 2.0;
    let mut out = Vec::new();
    for j in 0..cells.y as usize {
        for i in 0..cells.x as usize {
            let c0 = origin + DVec2::new(i as f64, j as f64);
            if cell_overlaps(&q, c0) {
                out.push((to_world(c0 + DVec2::splat(0.5)), s));
            }
        }
    }
    out
}

/// Does the unit cell [c0, c0 + 1]² overlap the 2D triangle q? (Separating axes: the cell's
/// axes are covered by the lattice spanning the triangle's box; the triangle's edges remain.)
fn cell_overlaps(q: &[DVec2; 3], c0: DVec2) -> bool {
    let orient = (q[1] - q[0]).perp_dot(q[2] - q[0]).signum();
    for k in 0..3 {
        let a = q[k];
        let b = q[(k + 1) % 3];
        let e = b - a;
        // Inward normal (left of a->b for a counter-clockwise triangle).
        let inward = DVec2::new(-e.y, e.x) * orient;
        let corner = c0 + DVec2::new((inward.x > 0.0) as u8 as f64, (inward.y > 0.0) as u8 as f64);
        if inward.dot(corner - a) < 0.0 {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_cover_the_triangle_and_no_more_than_its_neighbourhood() {
        let p = [
            DVec3::ZERO,
            DVec3::new(10.0, 0.0, 0.0),
            DVec3::new(0.0, 10.0, 0.0),
        ];
        let pts = cover(&p, 1.0);
        // Area 50 cells, plus at most about one cell per unit of perimeter (34.1) crossed.
        assert!(pts.len() >= 50 && pts.len() <= 90, "{}", pts.len());
        // Every point of the triangle lies in some cell (within half a side of a centre, in
        // the lattice's axes: here x along the hypotenuse).
        for a in 0..=20 {
            for b in 0..=(20 - a) {
                let x = DVec3::new(a as f64 * 0.5, b as f64 * 0.5, 0.0);
                let u = (p[2] - p[1]).normalize();
                let v = DVec3::Z.cross(u);
                assert!(
                    pts.iter().any(|(c, _)| {
                        let d = x - *c;
                        d.dot(u).abs() <= 0.5 + 1e-9 && d.dot(v).abs() <= 0.5 + 1e-9
                    }),
                    "{x} uncovered"
                );
            }
        }
    }

    #[test]
    fn a_triangle_inside_one_cell_gives_one_point_covering_it() {
        let p = [
            DVec3::ZERO,
            DVec3::new(0.3, 0.0, 0.0),
            DVec3::new(0.0, 0.2, 0.0),
        ];
        let pts = cover(&p, 1.0);
        assert_eq!(pts.len(), 1);
        // x runs along the longest edge (the hypotenuse), the box's larger side.
        assert!((pts[0].1 - 0.13f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn the_hash_is_uniform_enough_and_deterministic() {
        let xs: Vec<f64> = (0..10000).map(|i| unit_hash(7, i)).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        assert!((mean - 0.5).abs() < 0.02);
        assert!(xs.iter().all(|x| (0.0..1.0).contains(x)));
        assert_eq!(unit_hash(7, 3), unit_hash(7, 3));
        assert_ne!(unit_hash(7, 3), unit_hash(8, 3));
    }

    #[test]
    fn the_sphere_point_nearest_a_segment() {
        let c = closest_on_sphere_to_segment(
            DVec3::ZERO,
            1.0,
            DVec3::new(-5.0, 3.0, 0.0),
            DVec3::new(5.0, 3.0, 0.0),
        );
        assert!((c - DVec3::new(0.0, 1.0, 0.0)).length() < 1e-12);
    }
}
