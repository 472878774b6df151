//! Eye-based point generation (eye-based-point-rendering.txt §3.1-3.4, §4.1.1) and the iVIR
//! density it is compared with.
//!
//! Per triangle:
//! 1. Visibility (§3.1): one bit per off-screen view. The paper tests the vertices against
//!    frusta enlarged by 20%; a large triangle can span a frustum with every vertex outside it
//!    (a floor under a cube map's −Y face), so we keep a view unless all three vertices lie
//!    outside one plane of its 20%-enlarged frustum — conservative for every triangle. A
//!    reflector's own triangles are left out of its own cube map (they surround its centre), and
//!    so is a single-sided triangle (glTF `doubleSided` false) that turns its back to the
//!    reflector's centre: §3.2 samples a triangle only for the views it faces, and MVR's
//!    rasterizer culls the same back faces (`discretize_sided`).
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

use crate::random::mix64;
use crate::trace::points::point_triangle_distance;
use std::time::Instant;

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use crate::camera::{Camera, Projection};
use crate::error::Result;
use crate::input_err;
use crate::scene::surface::Footprint;
use crate::scene::Scene;
use crate::types::{Points, Stats, Timings};

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
    crate::limits::check_views("the reflectors' cube maps", &out, 16)?;
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
    let floor = scene.diagonal() * 1e-9;
    // A reflector does not see itself, nor the back of a single-sided triangle (§3.2: a
    // triangle is sampled only for the views it faces; its cube map's eye is its centre).
    let facing: Vec<(DVec3, DVec3, bool)> = (0..scene.triangle_count())
        .into_par_iter()
        .map(|t| {
            let v0 = scene.triangle(t)[0];
            (scene.face_normal(t), v0, scene.is_double_sided(t))
        })
        .collect();
    let skip = |t: usize, v: usize| {
        let k = v / 6;
        let (n, v0, double) = facing[t];
        owner[t] == k as u32 || !(double || n.dot(reflectors[k].center - v0) > 0.0)
    };
    let spacing = |t: usize, p: &[DVec3; 3], bits: &[u64]| {
        let cc = circumcentre(p);
        // The finest spacing any cube map that sees the triangle can show.
        let mut cap = f64::INFINITY;
        let mut via = f64::INFINITY;
        for (k, r) in reflectors.iter().enumerate() {
            if owner[t] == k as u32 || (0..6).all(|f| !bit(bits, 6 * k + f)) {
                continue;
            }
            let d_rt = ((cc - r.center).length() - r.radius).max(floor);
            cap = cap.min(d_rt * 2.0 / resolutions[k] as f64);
            let cp = closest_on_sphere_to_segment(r.center, r.radius, cc, e);
            via = via.min((e - cp).length() + (cp - cc).length());
        }
        match density {
            Density::Eye { rho_scale } => {
                let eye_s = if perspective {
                    via.max(floor) * pixel
                } else {
                    pixel
                };
                (eye_s / rho_scale).max(cap)
            }
            Density::OffScreen => cap,
        }
    };
    let mut out = sample_triangles(scene, &views, skip, spacing, seed)?;
    out.timings.add("total", total.elapsed().as_secs_f64());
    Ok(out)
}

/// The six cube-map views of each omnidirectional light sample (§5), in `Camera::cube` order,
/// sample after sample, with the near plane at `near`.
pub fn shadow_views(samples: &[DVec3], resolution: u32, near: f64) -> Result<Vec<Camera>> {
    crate::limits::check(
        || {
            let n = samples.len();
            format!("the shadow cube maps of {n} light samples at {resolution}x{resolution}")
        },
        crate::limits::product(&[
            6,
            samples.len() as u64,
            resolution as u64,
            resolution as u64,
        ]),
        16,
    )?;
    let mut out = Vec::with_capacity(6 * samples.len());
    for &l in samples {
        out.extend(Camera::cube(l, resolution, Some(near), None)?);
    }
    Ok(out)
}

/// Points for the shadow cube maps of omnidirectional light `samples` (all faces of one
/// `resolution`), seen by `eye` (§5.1, Eq. 5). The views are `shadow_views(samples,
/// resolution, near)`.
///
/// EPR spacing: the eye's pixel footprint at `d_ev`, the distance from the eye to the nearest
/// of the triangle's shadow volumes (one per light sample), divided by ρ_scale, and never finer
/// than the iVIR spacing, the cube-map texel at the triangle's distance from the nearest light
/// sample (`d_lt · 2 / resolution`; the paper's cap at `s_ortho`). The shadow volumes are taken
/// semi-infinite rather than cut at the light's far plane, which can only shorten `d_ev` (denser
/// points); an eye inside one gets `d_ev = 0` and so the capped iVIR spacing.
pub fn generate_shadow(
    scene: &Scene,
    eye: &Camera,
    samples: &[DVec3],
    resolution: u32,
    near: f64,
    density: Density,
    seed: u64,
) -> Result<Points> {
    let total = Instant::now();
    if samples.is_empty() {
        return input_err!("shadow points need at least one light sample");
    }
    if let Some(l) = samples.iter().find(|l| !l.is_finite()) {
        return input_err!("light sample {l:?} is not finite");
    }
    if resolution == 0 {
        return input_err!("the shadow cube maps need a resolution of at least 1");
    }
    if let Density::Eye { rho_scale } = density {
        if !(rho_scale.is_finite() && rho_scale > 0.0) {
            return input_err!("rho_scale must be finite and > 0, got {rho_scale}");
        }
    }
    let views = shadow_views(samples, resolution, near)?;
    let (pixel, perspective) = eye_pixel(eye);
    let e = eye.eye();
    let floor = scene.diagonal() * 1e-9;
    let spacing = |_t: usize, p: &[DVec3; 3], _bits: &[u64]| {
        let d_lt = samples
            .iter()
            .map(|&l| point_triangle_distance(l, p))
            .fold(f64::INFINITY, f64::min);
        let cap = d_lt.max(floor) * 2.0 / resolution as f64;
        match density {
            Density::Eye { rho_scale } => {
                let eye_s = if perspective {
                    let d_ev = samples
                        .iter()
                        .map(|&l| shadow_volume_distance(e, l, p))
                        .fold(f64::INFINITY, f64::min);
                    d_ev * pixel
                } else {
                    pixel
                };
                (eye_s / rho_scale).max(cap)
            }
            Density::OffScreen => cap,
        }
    };
    let mut out = sample_triangles(scene, &views, |_, _| false, spacing, seed)?;
    out.timings.add("total", total.elapsed().as_secs_f64());
    Ok(out)
}

/// Distance from `e` to the shadow volume that triangle `p` casts from a point light at `l`
/// (Fig. 9): the region behind the triangle as seen from `l`, unbounded. 0 when `e` is inside it
/// or a vertex touches the light. Otherwise the nearest of its boundary faces: the triangle
/// itself and three side wedges (each spanned from its edge away from the light, with the two
/// rays through the edge's ends as its other borders).
pub fn shadow_volume_distance(e: DVec3, l: DVec3, p: &[DVec3; 3]) -> f64 {
    let scale = (p[1] - p[0])
        .length()
        .max((p[2] - p[0]).length())
        .max((e - l).length());
    if p.iter().any(|&v| (v - l).length() <= 1e-12 * scale) {
        return 0.0;
    }
    // Inside: the segment from the light to the eye crosses the triangle.
    let n = (p[1] - p[0]).cross(p[2] - p[0]);
    let denom = n.dot(e - l);
    if denom != 0.0 {
        let t = n.dot(p[0] - l) / denom;
        if (0.0..=1.0).contains(&t) {
            let x = l + (e - l) * t;
            let sign = |k: usize| (p[(k + 1) % 3] - p[k]).cross(x - p[k]).dot(n);
            let (s0, s1, s2) = (sign(0), sign(1), sign(2));
            if (s0 >= 0.0 && s1 >= 0.0 && s2 >= 0.0) || (s0 <= 0.0 && s1 <= 0.0 && s2 <= 0.0) {
                return 0.0;
            }
        }
    }
    let mut d = point_triangle_distance(e, p);
    for k in 0..3 {
        let (a, b) = (p[k], p[(k + 1) % 3]);
        // The ray from a away from the light.
        let dir = (a - l).normalize();
        let t = (e - a).dot(dir).max(0.0);
        d = d.min((e - (a + dir * t)).length());
        // The wedge's interior: l + α(a − l) + β(b − l) with α, β >= 0 and α + β >= 1.
        let (u, v) = (a - l, b - l);
        let m = u.cross(v);
        if m.length_squared() <= 0.0 {
            continue;
        }
        let m = m.normalize();
        let w = e - l;
        let h = m.dot(w);
        let r = w - m * h;
        let (uu, uv, vv) = (u.dot(u), u.dot(v), v.dot(v));
        let det = uu * vv - uv * uv;
        if det.is_nan() || det <= 0.0 {
            continue;
        }
        let (ru, rv) = (r.dot(u), r.dot(v));
        let alpha = (ru * vv - rv * uv) / det;
        let beta = (rv * uu - ru * uv) / det;
        if alpha >= 0.0 && beta >= 0.0 && alpha + beta >= 1.0 {
            d = d.min(h.abs());
        }
    }
    d
}

/// Is bit `v` of a visibility string set?
fn bit(bits: &[u64], v: usize) -> bool {
    bits[v / 64] >> (v % 64) & 1 == 1
}

/// The shared part of point generation (§3.1-3.3) for any off-screen `views`: per triangle, its
/// visibility bits (view v left out when `skip(t, v)`), its spacing `spacing(t, vertices, bits)`
/// (floored so that one triangle gives at most `MAX_PER_TRIANGLE` points), stochastic culling of
/// sub-1/10-cell triangles and the exact conservative lattice coverage. Timings: `points`.
fn sample_triangles(
    scene: &Scene,
    views: &[Camera],
    skip: impl Fn(usize, usize) -> bool + Sync,
    spacing: impl Fn(usize, &[DVec3; 3], &[u64]) -> f64 + Sync,
    seed: u64,
) -> Result<Points> {
    let start = Instant::now();
    let words = views.len().div_ceil(64).max(1);
    let frusta: Vec<Frustum> = views.iter().map(Frustum::of).collect();
    let floor = scene.diagonal() * 1e-9;
    let verts = scene.vertices();
    let faces = scene.faces();
    // In blocks, so the caller sees progress (in triangles) and Ctrl-C is heard between them;
    // each block's points are appended in triangle order before the next block starts.
    const BLOCK: usize = 1 << 16;
    crate::process::add_total(faces.len() as u64);
    let mut out = Points {
        view_count: views.len(),
        ..Default::default()
    };
    let (mut invisible, mut culled, mut sampled) = (0usize, 0usize, 0usize);
    let materials = scene.material_ids();
    let surfaces = scene.surfaces();
    let mut per_triangle: Vec<TrianglePoints> = Vec::with_capacity(BLOCK.min(faces.len()));
    for (k, block) in faces.chunks(BLOCK).enumerate() {
        crate::process::check()?;
        per_triangle.clear();
        // The visibility bits are worked out in a scratch buffer per job and copied only for
        // a triangle that gets points (most of a large scene's are culled, §3.3).
        let work = block.par_iter().enumerate().map_init(
            || vec![0u64; words],
            |bits, (j, f)| {
                let t = k * BLOCK + j;
                let p = f.map(|i| DVec3::from(verts[i as usize].map(f64::from)));
                bits.fill(0);
                for (v, fr) in frusta.iter().enumerate() {
                    if !skip(t, v) && fr.may_see(&p) {
                        bits[v / 64] |= 1 << (v % 64);
                    }
                }
                if bits.iter().all(|&b| b == 0) {
                    return TrianglePoints::Invisible;
                }
                let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
                let s = spacing(t, &p, bits);
                let s = if s.is_nan() { floor } else { s };
                let s = s.max((area / MAX_PER_TRIANGLE).sqrt()).max(floor);
                let epr_area = area / (s * s);
                if epr_area <= 0.1 && unit_hash(seed, t as u64) >= 10.0 * epr_area {
                    return TrianglePoints::Culled;
                }
                let pts = cover(&p, s)
                    .into_iter()
                    .map(|(c, l)| {
                        let b = surfaces.barycentrics(t, c);
                        let color = surfaces.color(t, b, Footprint::World(l));
                        (c, l, color, surfaces.shading_normal(t, b))
                    })
                    .collect();
                TrianglePoints::Points(bits.clone(), pts)
            },
        );
        per_triangle.par_extend(work);
        for (j, tp) in per_triangle.drain(..).enumerate() {
            let t = k * BLOCK + j;
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
            for (c, l, color, shading) in pts {
                out.center.push(c.as_vec3().to_array());
                out.length.push(l as f32);
                out.triangle.push(t as i32);
                out.normal.push(n);
                out.shading_normal.push(shading);
                out.color.push(color);
                out.material.push(materials[t]);
                out.views.extend_from_slice(&bits);
            }
        }
        crate::process::advance(block.len() as u64);
    }
    out.timings = Timings::from([("points", start.elapsed().as_secs_f64())]);
    out.stats = Stats::from([
        ("points", out.len() as f64),
        ("triangles_sampled", sampled as f64),
        ("triangles_culled", culled as f64),
        ("triangles_outside_views", invisible as f64),
    ]);
    Ok(out)
}

/// What a triangle gives: nothing (outside every view, or culled), or its visibility bits and
/// its points (centre, side, colour over the point's square, shading normal).
enum TrianglePoints {
    Invisible,
    Culled,
    Points(Vec<u64>, Vec<(DVec3, f64, [f32; 3], [f32; 3])>),
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
    fn shadow_volume_distances() {
        let p = [
            DVec3::new(-1.0, -1.0, 0.0),
            DVec3::new(1.0, -1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ];
        let l = DVec3::new(0.0, 0.0, 2.0);
        // Straight behind the triangle: inside.
        assert_eq!(
            shadow_volume_distance(DVec3::new(0.0, 0.0, -5.0), l, &p),
            0.0
        );
        // Between the light and the triangle: the triangle is the nearest face.
        let d = shadow_volume_distance(DVec3::new(0.0, 0.0, 1.0), l, &p);
        assert!((d - 1.0).abs() < 1e-12, "{d}");
        // Beside the volume, level with the triangle's far side: the side wedge through the
        // edge y = -1 widens by 1/2 per unit of depth below the triangle.
        let e = DVec3::new(0.0, -3.0, -2.0);
        let d = shadow_volume_distance(e, l, &p);
        // The wedge's plane passes through l = (0, 0, 2) and the edge y = -1, z = 0: y = -(2 - z)/2.
        let plane_n = DVec3::new(0.0, 2.0, -1.0).normalize();
        let expect = (e - l).dot(plane_n).abs();
        assert!((d - expect).abs() < 1e-12, "{d} vs {expect}");
        // Brute force: the nearest of many points of the volume is never nearer than d.
        let mut best = f64::INFINITY;
        for i in 0..=40 {
            for j in 0..=(40 - i) {
                let a = i as f64 / 40.0;
                let b = j as f64 / 40.0;
                let q = p[0] * (1.0 - a - b) + p[1] * a + p[2] * b;
                for k in 0..200 {
                    let x = l + (q - l) * (1.0 + k as f64 * 0.05);
                    best = best.min((x - e).length());
                }
            }
        }
        assert!(best >= d - 1e-9 && best <= d + 0.1, "{best} vs {d}");
        // A vertex on the light.
        assert_eq!(shadow_volume_distance(e, p[0], &p), 0.0);
    }

    #[test]
    fn point_triangle_distance_inside_and_beside() {
        let p = [DVec3::ZERO, DVec3::X, DVec3::Y];
        assert!((point_triangle_distance(DVec3::new(0.2, 0.2, 3.0), &p) - 3.0).abs() < 1e-12);
        assert!((point_triangle_distance(DVec3::new(-1.0, 0.5, 0.0), &p) - 1.0).abs() < 1e-12);
        assert!((point_triangle_distance(DVec3::new(2.0, 0.0, 0.0), &p) - 1.0).abs() < 1e-12);
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
