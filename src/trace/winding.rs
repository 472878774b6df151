//! The generalized winding number (Jacobson, Kavan and Sorkine-Hornung, "Robust Inside-Outside
//! Segmentation using Generalized Winding Numbers", SIGGRAPH 2013) of a scene's surface at
//! points, on the ray-casting BVH.
//!
//! - Summed hierarchically as Barill et al. do ("Fast Winding Numbers for Soups and Clouds",
//!   SIGGRAPH 2018) with a first-order (dipole) term: a node whose bounding sphere (around its
//!   area-weighted centroid, through its farthest vertex) is farther than [`BETA`] radii from
//!   the point contributes its dipole, the area-weighted normals of its triangles
//!   (`WindingData`, one small record per node, made on first use and cached with the scene);
//!   nearer nodes are opened, and leaf triangles add their exact solid angle (Van Oosterom and
//!   Strackee's formula).
//! - On a closed surface (`scene::adjacency::Closure`), by one ray per point: the signed count
//!   of the triangles it crosses (`crossings`), an integer, exactly.

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use super::crossings::AMBIGUOUS;
use super::node::{leaf_blocks, node_at, node_index, node_ref, Bvh8, EMPTY, LEAF, STACK};
use super::points::{check_points, chunked, spread_bits, Scratch};
use super::query::Threads;
use super::schedule::on_threads;
use crate::error::Result;
use crate::scene::adjacency::Closure;
use crate::scene::Scene;

/// A node or a leaf block is far enough for its expansion (dipole and second-order term) when
/// its centroid lies farther than `BETA` times the distance from it to its farthest vertex.
/// The winding number is then within a few hundredths of the float64 sum (0.053 at worst seen:
/// the icosphere of the tests below), far from the 0.5 that separates inside from outside for
/// most points. A point whose sum lands within [`REFINE`] of 0.5 is summed again with
/// [`BETA_FINE`], whose error is below 1e-3 on every shared scene measured (5e-4 at worst on
/// the pine tree and the curtains), so that its side of 0.5 is the float64 sum's.
pub const BETA: f64 = 2.0;
pub const BETA_FINE: f64 = 6.0;
pub const REFINE: f64 = 0.1;

/// The generalized winding number of `scene`'s surface at each of `points`: 1 inside a closed
/// mesh whose faces wind counter-clockwise seen from outside, 0 outside, fractions near holes.
///
/// On a closed surface ([`Closure`]) the winding number is an integer off the surface, and each
/// point's is found exactly by one ray ([`crossing_winding`]). An open surface whose cap (the
/// triangles that close it) is small takes the same ray through it and its cap, less the cap's
/// own winding number, summed ([`winding`]): only the cap is summed. Elsewhere, and for the
/// rays that cannot tell, the surface's own sum answers.
pub fn winding_numbers(scene: &Scene, points: &[[f32; 3]], threads: Threads) -> Result<Vec<f64>> {
    check_points(points)?;
    on_threads(threads, || {
        let (bvh, _) = super::bvh::bvh_for_with(scene, threads, true)?;
        let closure = Closure::of(scene);
        // (Point indices are u32 there.)
        if points.len() < u32::MAX as usize {
            if closure.closed {
                return crossing_winding(scene, &bvh.tree, None, points, threads);
            }
            if let Some(cap) = closure.cap.as_ref().filter(|c| cap_pays(scene, c)) {
                return crossing_winding(scene, &bvh.tree, Some(cap), points, threads);
            }
        }
        summed_winding(scene, &bvh.tree, points, threads)
    })?
}

/// Whether a cap is small enough that a ray through the surface and the cap, and the cap's own
/// sum, cost less than the surface's sum: a cap of at most a quarter of the triangles.
fn cap_pays(scene: &Scene, cap: &Scene) -> bool {
    4 * cap.triangle_count() <= scene.triangle_count()
}

/// The winding numbers by the hierarchical sum, every point.
fn summed_winding(
    scene: &Scene,
    bvh: &Bvh8,
    points: &[[f32; 3]],
    threads: Threads,
) -> Result<Vec<f64>> {
    let mut w = summed(scene, bvh, points, threads, BETA)?;
    refine(scene, bvh, points, threads, &mut w, |_, v| v)?;
    Ok(w)
}

/// The hierarchical sum at every point, with `beta`.
fn summed(
    scene: &Scene,
    bvh: &Bvh8,
    points: &[[f32; 3]],
    threads: Threads,
    beta: f64,
) -> Result<Vec<f64>> {
    let data = scene.derived(|| WindingData::of(bvh));
    chunked(
        threads,
        points,
        bvh.nodes.len() > 1,
        // Inlined into the AVX2 copy of `dispatch` (see `points::closest_points`).
        #[inline(always)]
        |s, p| winding(bvh, &data, s, p, beta),
    )
}

/// Sum `scene` again with [`BETA_FINE`] at the points whose answer in `w` lies within
/// [`REFINE`] of 1/2, the answer becoming `answer(i, sum)`.
fn refine(
    scene: &Scene,
    bvh: &Bvh8,
    points: &[[f32; 3]],
    threads: Threads,
    w: &mut [f64],
    answer: impl Fn(usize, f64) -> f64,
) -> Result<()> {
    let near: Vec<usize> = (0..w.len())
        .filter(|&i| (w[i] - 0.5).abs() < REFINE)
        .collect();
    if near.is_empty() {
        return Ok(());
    }
    let pts: Vec<[f32; 3]> = near.iter().map(|&i| points[i]).collect();
    for (&i, v) in near
        .iter()
        .zip(summed(scene, bvh, &pts, threads, BETA_FINE)?)
    {
        w[i] = answer(i, v);
    }
    Ok(())
}

/// A ray's origin within this fraction of the largest coordinate of the scene's bounds from the
/// plane of a triangle it meets leaves the crossing count to the summed winding number (the
/// rounding of an f32 coordinate there is 2^-24 of it: this is 256 times that).
const NEAR: f32 = 1.0 / 65536.0;

/// [`crossing_winding`] sorts its rays (by exit, then in Morton order) for trees larger than this,
/// which outgrow a core's L2 cache: neighbouring rays then find their nodes in the cache, and
/// travel as packets. A smaller tree stays in the cache, and the sort cost more than it saved
/// (100K points in the box of a 3K-triangle sphere: 11.8 ms sorted, 10.3 ms unsorted; of a
/// 328K-triangle one: 19 ms sorted, 31 ms unsorted; both cores of an Intel Xeon).
const SORT_BYTES: usize = 1 << 20;

/// The directions of the rays of [`crossing_winding`], by the face of the scene's bounds nearest
/// the point (−x, +x, −y, +y, −z, +z): each leaves the bounds the short way, turned a little
/// off the axis, so that it does not run along the edges and faces of axis-aligned geometry.
const EXITS: [[f32; 3]; 6] = [
    [-1.0, 0.0131, -0.0077],
    [1.0, -0.0077, 0.0131],
    [0.0109, -1.0, 0.0061],
    [-0.0061, 1.0, 0.0109],
    [0.0083, 0.0149, -1.0],
    [-0.0149, 0.0083, 1.0],
];

/// A point outside the bounds, in [`exit_keys`]: sorts last.
const OUTSIDE: u32 = 6 << 27;

/// Each point's exit, the nearest face of the bounds (the high bits), and, with `sort`, its
/// cell of a 512^3 grid over the bounds in Morton order (the low 27 bits); [`OUTSIDE`] for a
/// point outside the bounds.
fn exit_keys(scene: &Scene, points: &[[f32; 3]], sort: bool, threads: Threads) -> Vec<u32> {
    let [lo, hi] = scene.bounds();
    let cells: [f32; 3] = std::array::from_fn(|a| {
        let extent = f64::from(hi[a]) - f64::from(lo[a]);
        if extent > 0.0 {
            (511.0 / extent) as f32
        } else {
            0.0
        }
    });
    let key = |p: &[f32; 3]| -> u32 {
        if (0..3).any(|a| p[a] < lo[a] || p[a] > hi[a]) {
            return OUTSIDE;
        }
        let mut exit = 0;
        let mut least = f32::INFINITY;
        let mut code = 0u32;
        for a in 0..3 {
            for (side, d) in [(0, p[a] - lo[a]), (1, hi[a] - p[a])] {
                if d < least {
                    (least, exit) = (d, 2 * a + side);
                }
            }
            if sort {
                // (A cell, for the order only: f32 rounding and the clamp are harmless.)
                let q = ((p[a] - lo[a]) * cells[a]) as i32;
                code |= (spread_bits(q.clamp(0, 511) as u64) as u32) << a;
            }
        }
        (exit as u32) << 27 | code
    };
    if threads == Threads::One {
        points.iter().map(key).collect()
    } else {
        points.par_iter().map(key).collect()
    }
}

/// The winding numbers of a closed surface, or of an open one closed by `cap`: the signed
/// crossings of one ray from each point through the surface and the cap ([`super::crossings`];
/// 0 outside the bounds, which hold the cap too), less the cap's summed winding number. Rays are
/// grouped by the way they leave the bounds and in Morton order within a group, so that
/// neighbouring rays travel together (as packets where the kernel has them). A ray that cannot
/// tell (an edge met exactly, or the point next to a triangle's plane) leaves its point to the
/// surface's own sum ([`summed_winding`]). Each answer depends on its point alone.
fn crossing_winding(
    scene: &Scene,
    bvh: &Bvh8,
    cap: Option<&Scene>,
    points: &[[f32; 3]],
    threads: Threads,
) -> Result<Vec<f64>> {
    let [lo, hi] = scene.bounds();
    let scale = (0..3).fold(0.0f32, |m, a| m.max(lo[a].abs()).max(hi[a].abs()));
    let sort = bvh.bytes() > SORT_BYTES;
    let keys = exit_keys(scene, points, sort, threads);
    let order = if sort {
        radix_order(&keys)
    } else {
        (0..keys.len() as u32)
            .filter(|&i| keys[i as usize] != OUTSIDE)
            .collect()
    };
    let rays = &order[..order.partition_point(|&i| keys[i as usize] != OUTSIDE)];
    if let Some(p) = crate::process::counter() {
        // The points outside the bounds, answered already (the rays count themselves).
        p.add_total((points.len() - rays.len()) as u64);
        p.advance((points.len() - rays.len()) as u64);
    }
    let origins: Vec<[f32; 3]> = rays.par_iter().map(|&i| points[i as usize]).collect();
    let directions: Vec<[f32; 3]> = rays
        .par_iter()
        .map(|&i| EXITS[(keys[i as usize] >> 27) as usize])
        .collect();
    let near = NEAR * scale;
    let cross = |s: &Scene| {
        super::crossings::crossings(s, &origins, &directions, threads, near, 1024.0 * near)
    };
    let mut count = cross(scene)?;
    if let Some(cap) = cap {
        for (c, k) in count.iter_mut().zip(cross(cap)?) {
            if k == AMBIGUOUS {
                *c = AMBIGUOUS;
            } else if *c != AMBIGUOUS {
                *c += k;
            }
        }
    }
    // Each point's crossings (0 outside the bounds), then less the cap's sum.
    let mut crossed = vec![0i32; points.len()];
    for (&i, &c) in rays.iter().zip(&count) {
        crossed[i as usize] = c;
    }
    let mut w: Vec<f64> = crossed.iter().map(|&c| f64::from(c)).collect();
    if let Some(cap) = cap {
        let cap_bvh = super::bvh::Bvh::of_with(cap, threads);
        let sum = summed(cap, &cap_bvh.tree, points, threads, BETA)?;
        w.iter_mut().zip(&sum).for_each(|(w, s)| *w -= s);
        let crossed = &crossed;
        refine(cap, &cap_bvh.tree, points, threads, &mut w, |i, s| {
            f64::from(crossed[i]) - s
        })?;
    }
    let unsure: Vec<u32> = rays
        .iter()
        .zip(&count)
        .filter(|(_, &c)| c == AMBIGUOUS)
        .map(|(&i, _)| i)
        .collect();
    if !unsure.is_empty() {
        let pts: Vec<[f32; 3]> = unsure.iter().map(|&i| points[i as usize]).collect();
        for (&i, v) in unsure
            .iter()
            .zip(summed_winding(scene, bvh, &pts, threads)?)
        {
            w[i as usize] = v;
        }
    }
    Ok(w)
}

/// The indices of `keys` in the order of their keys (30 bits), ties by index: a least
/// significant digit radix sort, 15 bits a pass (the points of [`crossing_winding`]: a comparison
/// sort of 100K of them took a fifth of the time of their rays on a small scene).
fn radix_order(keys: &[u32]) -> Vec<u32> {
    const DIGIT: u32 = 15;
    let mut order: Vec<u32> = (0..keys.len() as u32).collect();
    let mut spare = vec![0u32; keys.len()];
    for shift in [0, DIGIT] {
        let digit = |i: u32| ((keys[i as usize] >> shift) & ((1 << DIGIT) - 1)) as usize;
        let mut start = vec![0u32; 1 << DIGIT];
        for &i in &order {
            start[digit(i)] += 1;
        }
        let mut sum = 0;
        for s in start.iter_mut() {
            (*s, sum) = (sum, sum + *s);
        }
        for &i in &order {
            let d = digit(i);
            spare[start[d] as usize] = i;
            start[d] += 1;
        }
        std::mem::swap(&mut order, &mut spare);
    }
    order
}

/// Per inner node and per leaf block (four triangles): the area-weighted centroid of its
/// triangles, the radius of the sphere around it that holds them (through the farthest
/// vertex), and the dipole (the sum of their area-weighted normals, half their edge cross
/// products).
/// A record: centre (3), dipole (3), radius, and the first moment of the normals about the
/// centre, M = Σ N_t ⊗ (g_t − c) (9, row major), for the second-order term.
type Rec = [f32; 16];

#[derive(Debug)]
pub struct WindingData {
    nodes: Vec<Rec>,
    blocks: Vec<Rec>,
}

impl WindingData {
    pub fn of(bvh: &Bvh8) -> WindingData {
        let blocks: Vec<Rec> = (0..bvh.blocks.len())
            .into_par_iter()
            .map(|b| record(block_sums(bvh, b), block_corners(bvh, b)))
            .collect();
        let mut nodes = vec![[0.0f32; 16]; bvh.nodes.len()];
        if !bvh.blocks.is_empty() {
            gather(bvh, node_ref(0), &mut nodes);
        }
        WindingData { nodes, blocks }
    }

    /// Bytes held: the per-node and per-block records.
    pub fn bytes(&self) -> usize {
        (self.nodes.len() + self.blocks.len()) * std::mem::size_of::<Rec>()
    }
}

/// Sums over a set of triangles: Σ area·centroid, Σ area, Σ area-weighted normal.
type Sums = (DVec3, f64, DVec3);

fn add(a: Sums, b: Sums) -> Sums {
    (a.0 + b.0, a.1 + b.1, a.2 + b.2)
}

/// A record of [`WindingData`] for triangles with sums `sums` whose corners are `corners`
/// (three per triangle, in order).
fn record(sums: Sums, corners: impl Iterator<Item = [f32; 3]> + Clone) -> Rec {
    let centre = if sums.1 > 0.0 {
        sums.0 / sums.1
    } else {
        // No area: any corner (the dipole is zero; the radius then holds every corner).
        corners
            .clone()
            .next()
            .map_or(DVec3::ZERO, |v| DVec3::from(v.map(f64::from)))
    };
    // The farthest vertex from the centroid: the triangles lie within. (The farthest box corner
    // would also bound them, but a box's corners lie far from most geometry; the tighter sphere
    // lets the dipole answer for nodes twice as near.)
    let radius = corners
        .clone()
        .map(|v| (DVec3::from(v.map(f64::from)) - centre).length())
        .fold(0.0, f64::max);
    let mut m = [0.0f64; 9];
    let pts: Vec<DVec3> = corners.map(|v| DVec3::from(v.map(f64::from))).collect();
    for t in pts.chunks_exact(3) {
        let n = (t[1] - t[0]).cross(t[2] - t[0]) * 0.5;
        let g = (t[0] + t[1] + t[2]) / 3.0 - centre;
        for i in 0..3 {
            for j in 0..3 {
                m[3 * i + j] += n[i] * g[j];
            }
        }
    }
    let mut r = [0.0f32; 16];
    r[..7].copy_from_slice(&[
        centre.x as f32,
        centre.y as f32,
        centre.z as f32,
        sums.2.x as f32,
        sums.2.y as f32,
        sums.2.z as f32,
        // Rounded up, so the f32 radius never understates the f64 one.
        (radius * (1.0 + 1e-6)) as f32,
    ]);
    for k in 0..9 {
        r[7 + k] = m[k] as f32;
    }
    r
}

/// The corners of block `b`'s triangles.
fn block_corners(bvh: &Bvh8, b: usize) -> impl Iterator<Item = [f32; 3]> + Clone + '_ {
    let block = &bvh.blocks[b];
    (0..4)
        .filter(move |&l| block.id[l] != u32::MAX)
        .flat_map(move |l| block.corners(l))
}

fn block_sums(bvh: &Bvh8, b: usize) -> Sums {
    let block = &bvh.blocks[b];
    let mut sums: Sums = (DVec3::ZERO, 0.0, DVec3::ZERO);
    for lane in (0..4).filter(|&l| block.id[l] != u32::MAX) {
        let [a, bb, c] = block.corners(lane).map(|v| DVec3::from(v.map(f64::from)));
        let n = (bb - a).cross(c - a) * 0.5;
        let area = n.length();
        sums = add(sums, ((a + bb + c) / 3.0 * area, area, n));
    }
    sums
}

/// Fill `out` for the subtree at inner reference `r` and return its sums.
fn gather(bvh: &Bvh8, r: u32, out: &mut [Rec]) -> Sums {
    let node = node_at(&bvh.nodes, r);
    let mut sums: Sums = (DVec3::ZERO, 0.0, DVec3::ZERO);
    for &c in &node.child {
        let s = match c {
            EMPTY => continue,
            c if c & LEAF != 0 => leaf_blocks(c)
                .map(|b| block_sums(bvh, b))
                .fold(sums_zero(), add),
            c => gather(bvh, c, out),
        };
        sums = add(sums, s);
    }
    out[node_index(r)] = record(sums, subtree_corners(bvh, r));
    sums
}

fn sums_zero() -> Sums {
    (DVec3::ZERO, 0.0, DVec3::ZERO)
}

/// Every corner of the triangles under inner reference `r`.
fn subtree_corners(bvh: &Bvh8, r: u32) -> impl Iterator<Item = [f32; 3]> + Clone + '_ {
    let mut leaves = Vec::new();
    let mut todo = vec![r];
    while let Some(r) = todo.pop() {
        for &c in &node_at(&bvh.nodes, r).child {
            match c {
                EMPTY => {}
                c if c & LEAF != 0 => leaves.push(c),
                c => todo.push(c),
            }
        }
    }
    leaves
        .into_iter()
        .flat_map(leaf_blocks)
        .flat_map(move |b| block_corners(bvh, b))
}

/// Whether a record's sphere is farther than `beta` radii from `q`, and if so the solid angle of
/// its expansion: the dipole term N·f(c) and the second-order term M : Df(c), with
/// f(x) = (x − q)/|x − q|^3 (Barill et al. 2018, §3.2, to second order).
#[inline(always)]
fn expansion(d: &Rec, q: DVec3, beta: f64) -> Option<f64> {
    let to = DVec3::new(d[0] as f64, d[1] as f64, d[2] as f64) - q;
    let dist = to.length();
    (dist > beta * d[6] as f64).then(|| {
        let dipole = DVec3::new(d[3] as f64, d[4] as f64, d[5] as f64);
        let d3 = dist * dist * dist;
        let first = to.dot(dipole) / d3;
        // M : Df(c) with f(x) = (x - q)/|x - q|^3, Df = I/|y|^3 - 3 y y^T/|y|^5, y = c - q.
        let m = |i: usize, j: usize| d[7 + 3 * i + j] as f64;
        let trace = m(0, 0) + m(1, 1) + m(2, 2);
        let y = [to.x, to.y, to.z];
        let mut ymy = 0.0;
        for i in 0..3 {
            for j in 0..3 {
                ymy += y[i] * m(i, j) * y[j];
            }
        }
        first + trace / d3 - 3.0 * ymy / (d3 * dist * dist)
    })
}

/// The winding number of the tree's triangles at `q` (see the module's notes).
#[inline(always)]
fn winding(bvh: &Bvh8, data: &WindingData, s: &mut Scratch, q: [f32; 3], beta: f64) -> f64 {
    if bvh.blocks.is_empty() {
        return 0.0;
    }
    let qd = DVec3::from(q.map(f64::from));
    let mut sum = Angles::new();
    let stack = &mut s.refs[..STACK];
    stack[0] = node_ref(0);
    let mut top = 1;
    while top > 0 {
        top -= 1;
        let r = stack[top];
        if let Some(far) = expansion(&data.nodes[node_index(r)], qd, beta) {
            sum.far += far;
            continue;
        }
        for &c in &node_at(&bvh.nodes, r).child {
            if c == EMPTY {
                continue;
            }
            if c & LEAF == 0 {
                stack[top] = c;
                top += 1;
                continue;
            }
            for b in leaf_blocks(c) {
                if let Some(far) = expansion(&data.blocks[b], qd, beta) {
                    sum.far += far;
                    continue;
                }
                let block = &bvh.blocks[b];
                for lane in (0..4).filter(|&l| block.id[l] != u32::MAX) {
                    let [a, bb, cc] = block.corners(lane).map(|v| DVec3::from(v.map(f64::from)));
                    sum.triangle(a - qd, bb - qd, cc - qd);
                }
            }
        }
    }
    sum.total() / (4.0 * PI)
}

/// Solid angles of triangles summed without an arctangent each. A triangle's solid angle seen
/// from the origin is 2·atan2(det, div) (Van Oosterom and Strackee, 1983): twice the argument of
/// the complex number div + i·det. A sum of arguments is the argument of the product, plus a
/// turn for each time the running product's argument wrapped past ±π, which the signs of the
/// imaginary parts show: two factors in the upper half-plane (arguments in [0, π]) whose
/// product lands in the lower one went past π, and the other way round. The product is kept
/// scaled by powers of two (exact: the argument is unchanged) and one arctangent ends the sum.
/// Far nodes' dipole terms are summed apart, in `far`.
struct Angles {
    re: f64,
    im: f64,
    turns: i64,
    far: f64,
}

impl Angles {
    fn new() -> Self {
        Angles {
            re: 1.0,
            im: 0.0,
            turns: 0,
            far: 0.0,
        }
    }

    /// Add the solid angle of triangle (a, b, c), its corners relative to the point.
    #[inline(always)]
    fn triangle(&mut self, a: DVec3, b: DVec3, c: DVec3) {
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let det = a.dot(b.cross(c));
        let div = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
        if det == 0.0 && div == 0.0 {
            return; // atan2(0, 0): no angle
        }
        let (x, y) = scaled(div, det);
        let (re, im) = (self.re * x - self.im * y, self.re * y + self.im * x);
        let (upper, factor) = (!self.im.is_sign_negative(), !y.is_sign_negative());
        if upper == factor {
            let landed = !im.is_sign_negative();
            self.turns += i64::from(upper && !landed) - i64::from(!upper && landed);
        }
        (self.re, self.im) = scaled(re, im);
    }

    /// The sum of the solid angles.
    fn total(&self) -> f64 {
        2.0 * (self.im.atan2(self.re) + 2.0 * PI * self.turns as f64) + self.far
    }
}

/// (x, y) scaled by the power of two that brings the larger magnitude into [1, 2): exact, so the
/// argument of x + iy is unchanged. Values whose exponent a power of two cannot undo (zero,
/// subnormal, infinite or beyond 2^1022) are divided by their magnitude instead.
#[inline(always)]
fn scaled(x: f64, y: f64) -> (f64, f64) {
    let m = x.abs().max(y.abs());
    let e = (m.to_bits() >> 52) & 0x7ff;
    if e == 0 || e >= 2046 {
        return if m > 0.0 && m.is_finite() {
            (x / m, y / m)
        } else {
            (x, y)
        };
    }
    let s = f64::from_bits((2046 - e) << 52);
    (x * s, y * s)
}

/// The signed solid angle of triangle (a, b, c) seen from the origin (Van Oosterom and
/// Strackee, 1983): positive where the origin lies behind its counter-clockwise front.
pub fn solid_angle(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let det = a.dot(b.cross(c));
    let div = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    2.0 * det.atan2(div)
}

/// Bytes the winding data of `bvh` takes (for `bvh_stats`), if made.
pub fn winding_bytes(scene: &Scene) -> usize {
    scene
        .derived_if_built::<WindingData>()
        .map_or(0, |w| w.bytes())
}

#[cfg(test)]
#[path = "winding_tests.rs"]
mod tests;
