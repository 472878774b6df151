//! Point queries on the ray-casting BVH (the same tree, built once per scene): the closest point
//! of the scene's surface to each query point, and the generalized winding number (Jacobson,
//! Kavan and Sorkine-Hornung, "Robust Inside-Outside Segmentation using Generalized Winding
//! Numbers", SIGGRAPH 2013), summed hierarchically as Barill et al. do ("Fast Winding Numbers
//! for Soups and Clouds", SIGGRAPH 2018) with a first-order (dipole) term per node.
//!
//! Closest points: best-first descent. A node's eight child boxes are measured against the
//! point in one 8-lane pass; the children nearer than the best distance so far are pushed
//! farthest first, so the nearest is visited next. Leaves test their triangles exactly, in f64
//! (closest point by Voronoi region, as in Ericson, *Real-Time Collision Detection*, §5.1.5), so
//! distances agree with a float64 brute force. Equal distances go to the smaller triangle id,
//! whatever order the tree visits them in.
//!
//! Winding numbers: a node whose bounding sphere (around its area-weighted centroid, through
//! its farthest vertex) is farther than [`BETA`] radii from the point contributes its dipole, the area-weighted normals of its
//! triangles (`WindingData`, one small record per node, made on first use and cached with the
//! scene); nearer nodes are opened, and leaf triangles add their exact solid angle (Van
//! Oosterom and Strackee's formula).

use std::f64::consts::PI;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::bvh8::{leaf_blocks, node_at, node_index, node_ref, Bvh8, EMPTY, LEAF, STACK};
use super::{on_threads, Threads};
use crate::error::Result;
use crate::input_err;
use crate::scene::adjacency::Closure;
use crate::scene::Scene;

/// Points per parallel task.
const CHUNK: usize = 512;

/// A node is far enough for its dipole when its centroid lies farther than `BETA` times the
/// distance from it to its farthest vertex. With the first-order term the winding number then
/// stays within a few hundredths of the exact sum (0.021 at worst on the test sphere below), far
/// from the 0.5 that separates inside from outside anywhere but on the surface itself. Each 0.5
/// more of `BETA` costs about 40% more time (the toy car: 0.62 s for 200K points at 2.0, 1.06 s
/// at 2.5) for a third less error.
pub const BETA: f64 = 2.0;

/// The closest surface point of each query point.
#[derive(Debug, Default)]
pub struct ClosestPoints {
    pub point: Vec<[f32; 3]>,
    /// +inf where nothing lies within `max_distance`.
    pub distance: Vec<f32>,
    /// −1 where nothing lies within `max_distance`.
    pub triangle: Vec<i32>,
    /// (u, v) with point = (1−u−v)·v0 + u·v1 + v·v2; (0, 0) with no triangle.
    pub barycentric: Vec<[f32; 2]>,
    pub bvh_build_seconds: f64,
    pub query_seconds: f64,
}

/// The closest point of `scene`'s surface to each of `points` within `max_distance` (+inf: any
/// distance), on `threads`.
pub fn closest_points(
    scene: &Scene,
    points: &[[f32; 3]],
    max_distance: f32,
    threads: Threads,
) -> Result<ClosestPoints> {
    if max_distance.is_nan() || max_distance < 0.0 {
        return input_err!("max_distance must be >= 0, got {max_distance}");
    }
    check_points(points)?;
    on_threads(threads, || {
        let (bvh, built) = super::bvh_for(scene, threads)?;
        let start = Instant::now();
        let limit = max_distance as f64;
        // Each answer packed as it is found (28 bytes, not the 72 of an `Option<Near>`).
        let found = chunked(
            threads,
            points,
            bvh.tree.nodes.len() > 1,
            |s, p| match closest(&bvh.tree, s, p, limit * limit) {
                Some(n) => (
                    n.point.as_vec3().to_array(),
                    n.d2.sqrt() as f32,
                    n.triangle as i32,
                    [n.u as f32, n.v as f32],
                ),
                None => ([f32::NAN; 3], f32::INFINITY, -1, [0.0; 2]),
            },
        )?;
        let n = found.len();
        let mut out = ClosestPoints {
            point: Vec::with_capacity(n),
            distance: Vec::with_capacity(n),
            triangle: Vec::with_capacity(n),
            barycentric: Vec::with_capacity(n),
            bvh_build_seconds: built,
            query_seconds: 0.0,
        };
        for (p, d, t, b) in found {
            out.point.push(p);
            out.distance.push(d);
            out.triangle.push(t);
            out.barycentric.push(b);
        }
        out.query_seconds = start.elapsed().as_secs_f64();
        Ok(out)
    })?
}

/// The generalized winding number of `scene`'s surface at each of `points`: 1 inside a closed
/// mesh whose faces wind counter-clockwise seen from outside, 0 outside, fractions near holes.
///
/// On a closed surface ([`Closure`]) the winding number is an integer off the surface, and each
/// point's is found exactly by one ray ([`closed_winding`]); elsewhere, and for the rays that
/// cannot tell, by the hierarchical sum of solid angles ([`winding`]).
pub fn winding_numbers(scene: &Scene, points: &[[f32; 3]], threads: Threads) -> Result<Vec<f64>> {
    check_points(points)?;
    on_threads(threads, || {
        let (bvh, _) = super::bvh_for(scene, threads)?;
        // (Point indices are u32 there.)
        if Closure::of(scene).closed && points.len() < u32::MAX as usize {
            return closed_winding(scene, &bvh.tree, points, threads);
        }
        summed_winding(scene, &bvh.tree, points, threads)
    })?
}

/// The winding numbers by the hierarchical sum, every point.
fn summed_winding(
    scene: &Scene,
    bvh: &Bvh8,
    points: &[[f32; 3]],
    threads: Threads,
) -> Result<Vec<f64>> {
    let data = scene.derived(|| WindingData::of(bvh));
    chunked(threads, points, bvh.nodes.len() > 1, |s, p| {
        winding(bvh, &data, s, p)
    })
}

/// A ray's origin within this fraction of the largest coordinate of the scene's bounds from the
/// plane of a triangle it meets leaves the crossing count to the summed winding number (the
/// rounding of an f32 coordinate there is 2^-24 of it: this is 256 times that).
const NEAR: f32 = 1.0 / 65536.0;

/// [`closed_winding`] sorts its rays (by exit, then in Morton order) for trees larger than this,
/// which outgrow a core's L2 cache: neighbouring rays then find their nodes in the cache, and
/// travel as packets. A smaller tree stays in the cache, and the sort cost more than it saved
/// (100K points in the box of a 3K-triangle sphere: 11.8 ms sorted, 10.3 ms unsorted; of a
/// 328K-triangle one: 19 ms sorted, 31 ms unsorted; both cores of an Intel Xeon).
const SORT_BYTES: usize = 1 << 20;

/// The directions of the rays of [`closed_winding`], by the face of the scene's bounds nearest
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

/// The winding numbers of a closed surface: 0 outside its bounds; inside them, the signed
/// crossings of one ray from each point ([`super::crossings`]), the points grouped by the way
/// their rays leave and in Morton order within a group, so that neighbouring rays travel
/// together (as packets where the kernel has them). A ray that cannot tell (an edge met
/// exactly, or the point next to a triangle's plane) leaves its point to [`summed_winding`].
/// Each answer depends on its point alone.
fn closed_winding(
    scene: &Scene,
    bvh: &Bvh8,
    points: &[[f32; 3]],
    threads: Threads,
) -> Result<Vec<f64>> {
    let [lo, hi] = scene.bounds();
    let scale = (0..3).fold(0.0f32, |m, a| m.max(lo[a].abs()).max(hi[a].abs()));
    let cells: [f32; 3] = std::array::from_fn(|a| {
        let extent = f64::from(hi[a]) - f64::from(lo[a]);
        if extent > 0.0 {
            (511.0 / extent) as f32
        } else {
            0.0
        }
    });
    // Each point's exit (the high bits) and, where the rays are sorted, its cell of a 512^3 grid
    // over the bounds in Morton order (the low 27 bits); OUTSIDE, which sorts last, for a point
    // outside the bounds.
    const OUTSIDE: u32 = 6 << 27;
    let sort = bvh.bytes() > SORT_BYTES;
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
    let keys: Vec<u32> = if threads == Threads::One {
        points.iter().map(key).collect()
    } else {
        points.par_iter().map(key).collect()
    };
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
    let count =
        super::crossings::crossings(scene, &origins, &directions, threads, near, 1024.0 * near)?;
    let mut w = vec![0.0f64; points.len()];
    let mut unsure = Vec::new();
    for (&i, &c) in rays.iter().zip(&count) {
        if c == super::crossings::AMBIGUOUS {
            unsure.push(i);
        } else {
            w[i as usize] = f64::from(c);
        }
    }
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

fn check_points(points: &[[f32; 3]]) -> Result<()> {
    if let Some(i) = points.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
        return input_err!("points[{i}] is not finite: {:?}", points[i]);
    }
    Ok(())
}

/// A traversal stack, made once per chunk of points rather than once per point (it is 4 KiB,
/// and clearing it per point cost more than a small scene's whole query), and the previous
/// point's answer.
struct Scratch {
    near: Vec<(f32, u32)>,
    refs: Vec<u32>,
    /// The block and lane of the previous point's closest triangle.
    last: Option<(u32, u32)>,
}

/// `f` over every point, in parallel chunks (unless `threads` is one) that each first check for
/// an interruption and then count their points as the call's progress.
///
/// The points are visited in Morton order of their positions and the answers put back in the
/// caller's order. Each answer depends on its own point only, so the order changes nothing but
/// the time: neighbouring queries take the same paths through the tree, and the branches of the
/// descent and of the closest-point test are predicted (1.4-1.7x on the shared scenes' random
/// point sets, sort included). `sort` false (a tree of one node: no branches to predict)
/// keeps the caller's order.
fn chunked<T: Send + Copy>(
    threads: Threads,
    points: &[[f32; 3]],
    sort: bool,
    f: impl Fn(&mut Scratch, [f32; 3]) -> T + Sync,
) -> Result<Vec<T>> {
    let progress = crate::process::counter();
    if let Some(p) = &progress {
        p.add_total(points.len() as u64);
    }
    let each = |c: &[[f32; 3]]| -> Result<Vec<T>> {
        crate::process::check()?;
        let out = dispatch(c, &f);
        if let Some(p) = &progress {
            p.advance(c.len() as u64);
        }
        Ok(out)
    };
    let order = sort.then(|| morton_order(points, threads)).flatten();
    let sorted: Vec<[f32; 3]>;
    let visit = match &order {
        Some(o) => {
            sorted = o.iter().map(|&i| points[i as usize]).collect();
            &sorted[..]
        }
        None => points,
    };
    let parts: Vec<Vec<T>> = if threads == Threads::One {
        visit.chunks(CHUNK).map(each).collect::<Result<_>>()?
    } else {
        visit.par_chunks(CHUNK).map(each).collect::<Result<_>>()?
    };
    let mut out = Vec::with_capacity(points.len());
    match order {
        None => parts.into_iter().for_each(|p| out.extend(p)),
        Some(o) => {
            // Each answer written once, straight to its point's place.
            let Some(&first) = parts.first().and_then(|p| p.first()) else {
                return Ok(out);
            };
            out.resize(points.len(), first);
            for (&i, v) in o.iter().zip(parts.into_iter().flatten()) {
                out[i as usize] = v;
            }
        }
    }
    Ok(out)
}

/// The indices of `points` in Morton (Z-curve) order of their positions quantized to 1024 steps
/// per axis of their bounds, ties by index; `None` for too few points to repay the sort.
fn morton_order(points: &[[f32; 3]], threads: Threads) -> Option<Vec<u32>> {
    if points.len() < 2 * CHUNK || points.len() > u32::MAX as usize {
        return None;
    }
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    // In f64: the extent of finite f32 coordinates may overflow f32.
    let scale: [f64; 3] = std::array::from_fn(|a| {
        let extent = f64::from(hi[a]) - f64::from(lo[a]);
        if extent > 0.0 {
            1023.0 / extent
        } else {
            0.0
        }
    });
    let key = |(i, p): (usize, &[f32; 3])| {
        let mut code = 0u64;
        for a in 0..3 {
            let q = ((f64::from(p[a]) - f64::from(lo[a])) * scale[a]) as u64;
            code |= spread_bits(q.min(1023)) << a;
        }
        (code << 32) | i as u64
    };
    let mut keys: Vec<u64> = if threads == Threads::One {
        points.iter().enumerate().map(key).collect()
    } else {
        points.par_iter().enumerate().map(key).collect()
    };
    if threads == Threads::One {
        keys.sort_unstable();
    } else {
        keys.par_sort_unstable();
    }
    Some(keys.into_iter().map(|k| k as u32).collect())
}

/// The indices of `keys` in the order of their keys (30 bits), ties by index: a least
/// significant digit radix sort, 15 bits a pass (the points of [`closed_winding`]: a comparison
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

/// The ten low bits of `x` moved to every third bit (bit i to bit 3i).
fn spread_bits(x: u64) -> u64 {
    let mut x = x & 0x3ff;
    x = (x | (x << 16)) & 0x0300_00ff;
    x = (x | (x << 8)) & 0x0300_f00f;
    x = (x | (x << 4)) & 0x030c_30c3;
    (x | (x << 2)) & 0x0924_9249
}

/// `f` over a chunk of points, compiled for AVX2 where the CPU has it, so that the 8-lane box
/// tests use the full width.
#[inline(always)]
fn dispatch<T>(chunk: &[[f32; 3]], f: &impl Fn(&mut Scratch, [f32; 3]) -> T) -> Vec<T> {
    let mut s = Scratch {
        near: vec![(0.0, 0); STACK],
        refs: vec![0; STACK],
        last: None,
    };
    #[cfg(target_arch = "x86_64")]
    if super::avx2::Avx2::detect().is_some() {
        // SAFETY: the CPU has AVX2.
        return unsafe { map_avx2(chunk, &mut s, f) };
    }
    chunk.iter().map(|&p| f(&mut s, p)).collect()
}

/// Rust never fuses a multiply and an add on its own, so the results are the portable path's
/// bit for bit.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2")]
unsafe fn map_avx2<T>(
    chunk: &[[f32; 3]],
    s: &mut Scratch,
    f: &impl Fn(&mut Scratch, [f32; 3]) -> T,
) -> Vec<T> {
    chunk.iter().map(|&p| f(s, p)).collect()
}

/// The best candidate so far.
#[derive(Clone, Copy, Debug)]
struct Near {
    d2: f64,
    triangle: u32,
    point: DVec3,
    u: f64,
    v: f64,
    at: (u32, u32),
}

/// Squared distances from `q` to the eight child boxes of a node (+inf for empty slots).
#[inline(always)]
fn box_d2(b: &[[f32; 8]; 6], q: [f32; 3]) -> [f32; 8] {
    let mut d2 = [0.0f32; 8];
    for a in 0..3 {
        for k in 0..8 {
            let d = (b[a][k] - q[a]).max(q[a] - b[a + 3][k]).max(0.0);
            d2[k] += d * d;
        }
    }
    d2
}

/// Squared distances from `q` to the bounding boxes of a block's four triangles (corners
/// `v[corner][axis][lane]`).
#[inline(always)]
fn lane_bounds(v: &[[[f32; 4]; 3]; 3], q: [f32; 3]) -> [f32; 4] {
    let mut d2 = [0.0f32; 4];
    for a in 0..3 {
        for k in 0..4 {
            let lo = v[0][a][k].min(v[1][a][k]).min(v[2][a][k]);
            let hi = v[0][a][k].max(v[1][a][k]).max(v[2][a][k]);
            let d = (lo - q[a]).max(q[a] - hi).max(0.0);
            d2[k] += d * d;
        }
    }
    d2
}

/// The closest triangle of `bvh` to `q` within squared distance `limit2`.
#[inline(always)]
fn closest(bvh: &Bvh8, s: &mut Scratch, q: [f32; 3], limit2: f64) -> Option<Near> {
    let qd = DVec3::from(q.map(f64::from));
    let mut best: Option<Near> = None;
    let mut bound = limit2;
    if let Some((b, lane)) = s.last {
        let block = &bvh.blocks[b as usize];
        let [a, bb, c] = block
            .corners(lane as usize)
            .map(|v| DVec3::from(v.map(f64::from)));
        let (p, u, v) = closest_on_triangle(qd, a, bb, c);
        let d2 = (p - qd).length_squared();
        if d2 <= bound {
            best = Some(Near {
                d2,
                triangle: block.id[lane as usize],
                point: p,
                u,
                v,
                at: (b, lane),
            });
            bound = d2;
        }
    }
    // Measured already.
    let seed = best.map_or(u32::MAX, |n| n.triangle);
    // (squared box distance, reference); a box no nearer than the bound is skipped. At most
    // seven entries stay behind per level of a tree at most `MAX_DEPTH` deep: `STACK` holds them.
    let stack = &mut s.near[..STACK];
    stack[0] = (0.0, node_ref(0));
    let mut top = 1;
    while top > 0 {
        top -= 1;
        let (d2, r) = stack[top];
        // f32 box distances round: shrink them before comparing, so that a box holding a
        // triangle exactly at the bound is never skipped.
        if f64::from(d2) * (1.0 - 1e-5) > bound {
            continue;
        }
        if r & LEAF != 0 {
            for b in leaf_blocks(r) {
                let block = &bvh.blocks[b];
                let near = lane_bounds(&block.v, q);
                for (lane, &box_d2) in near.iter().enumerate() {
                    let id = block.id[lane];
                    // The triangle's box is a lower bound of its distance: most triangles of
                    // a leaf are farther than the best so far, and skip the exact test.
                    if id == u32::MAX || id == seed || f64::from(box_d2) * (1.0 - 1e-5) > bound {
                        continue;
                    }
                    let [a, bb, c] = block.corners(lane).map(|v| DVec3::from(v.map(f64::from)));
                    let (p, u, v) = closest_on_triangle(qd, a, bb, c);
                    let d2 = (p - qd).length_squared();
                    let better = match &best {
                        None => d2 <= bound,
                        Some(n) => d2 < n.d2 || (d2 == n.d2 && id < n.triangle),
                    };
                    if better {
                        best = Some(Near {
                            d2,
                            triangle: id,
                            point: p,
                            u,
                            v,
                            at: (b as u32, lane as u32),
                        });
                        bound = d2;
                    }
                }
            }
            continue;
        }
        let node = node_at(&bvh.nodes, r);
        let d2 = box_d2(&node.b, q);
        let mut near = [0u64; 8];
        let mut n = 0;
        for (&d, &c) in d2.iter().zip(&node.child) {
            if c != EMPTY && f64::from(d) * (1.0 - 1e-5) <= bound {
                let key = (u64::from(d.to_bits()) << 32) | u64::from(c);
                let mut j = n;
                while j > 0 && near[j - 1] < key {
                    near[j] = near[j - 1];
                    j -= 1;
                }
                near[j] = key;
                n += 1;
            }
        }
        for &k in &near[..n] {
            stack[top] = (f32::from_bits((k >> 32) as u32), k as u32);
            top += 1;
        }
    }
    s.last = best.map(|n| n.at);
    best
}

/// The point of triangle (a, b, c) closest to `p`, and its barycentric (u, v) (the point is
/// (1−u−v)·a + u·b + v·c), by the Voronoi region of the triangle `p` lies in. A degenerate
/// triangle (a segment or a point) gets the closest point of its edges.
#[inline]
pub fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> (DVec3, f64, f64) {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, 0.0, 0.0); // vertex a
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, 1.0, 0.0); // vertex b
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let t = d1 / (d1 - d3);
        return (a + ab * t, t, 0.0); // edge ab
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, 0.0, 1.0); // vertex c
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let t = d2 / (d2 - d6);
        return (a + ac * t, 0.0, t); // edge ac
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * t, 1.0 - t, t); // edge bc
    }
    let sum = va + vb + vc;
    if sum.is_nan() || sum <= 0.0 || sum.is_infinite() {
        return closest_on_edges(p, a, b, c);
    }
    let (u, v) = (vb / sum, vc / sum);
    (a + ab * u + ac * v, u, v) // face
}

/// The closest point of the three edges of a degenerate triangle.
fn closest_on_edges(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> (DVec3, f64, f64) {
    let on = |x: DVec3, y: DVec3| {
        let e = y - x;
        let l2 = e.length_squared();
        let t = if l2 > 0.0 {
            ((p - x).dot(e) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (x + e * t, t)
    };
    let (pab, t1) = on(a, b);
    let (pac, t2) = on(a, c);
    let (pbc, t3) = on(b, c);
    [(pab, t1, 0.0), (pac, 0.0, t2), (pbc, 1.0 - t3, t3)]
        .into_iter()
        .min_by(|x, y| {
            (x.0 - p)
                .length_squared()
                .total_cmp(&(y.0 - p).length_squared())
        })
        .expect("three edges")
}

/// Per node: the area-weighted centroid of its triangles, the radius of the sphere around it
/// that holds the node's box, and the dipole (the sum of its triangles' area-weighted normals,
/// half their edge cross products).
#[derive(Debug)]
pub struct WindingData {
    nodes: Vec<[f32; 7]>,
}

impl WindingData {
    pub fn of(bvh: &Bvh8) -> WindingData {
        let mut nodes = vec![[0.0f32; 7]; bvh.nodes.len()];
        if !bvh.blocks.is_empty() {
            gather(bvh, node_ref(0), &mut nodes);
        }
        WindingData { nodes }
    }

    /// Bytes held: the per-node records.
    pub fn bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<[f32; 7]>()
    }
}

/// Sums over a subtree: Σ area·centroid, Σ area, Σ area-weighted normal.
type Sums = (DVec3, f64, DVec3);

/// Fill `out` for the subtree at inner reference `r` and return its sums.
fn gather(bvh: &Bvh8, r: u32, out: &mut [[f32; 7]]) -> Sums {
    let node = node_at(&bvh.nodes, r);
    let mut sums: Sums = (DVec3::ZERO, 0.0, DVec3::ZERO);
    for &c in &node.child {
        let s = match c {
            EMPTY => continue,
            c if c & LEAF != 0 => leaf_sums(bvh, c),
            c => gather(bvh, c, out),
        };
        sums = (sums.0 + s.0, sums.1 + s.1, sums.2 + s.2);
    }
    let (lo, hi) = node.bounds();
    let (lo, hi) = (
        DVec3::from(lo.map(f64::from)),
        DVec3::from(hi.map(f64::from)),
    );
    let centre = if sums.1 > 0.0 {
        sums.0 / sums.1
    } else {
        (lo + hi) / 2.0
    };
    // The farthest vertex of the subtree from the centroid: its triangles lie within. (The
    // farthest box corner would also bound them, but a box's corners lie far from most
    // geometry; the tighter sphere lets the dipole answer for nodes twice as near.)
    let radius = farthest_vertex(bvh, r, centre);
    out[node_index(r)] = [
        centre.x as f32,
        centre.y as f32,
        centre.z as f32,
        sums.2.x as f32,
        sums.2.y as f32,
        sums.2.z as f32,
        // Rounded up, so the f32 radius never understates the f64 one.
        (radius * (1.0 + 1e-6)) as f32,
    ];
    sums
}

/// The largest distance from `centre` to a vertex of the subtree at inner reference `r`.
fn farthest_vertex(bvh: &Bvh8, r: u32, centre: DVec3) -> f64 {
    let node = node_at(&bvh.nodes, r);
    let mut far = 0.0f64;
    for &c in &node.child {
        far = far.max(match c {
            EMPTY => continue,
            c if c & LEAF != 0 => leaf_blocks(c)
                .flat_map(|b| {
                    let block = &bvh.blocks[b];
                    (0..4)
                        .filter(move |&l| block.id[l] != u32::MAX)
                        .flat_map(move |l| block.corners(l))
                })
                .map(|v| (DVec3::from(v.map(f64::from)) - centre).length())
                .fold(0.0, f64::max),
            c => farthest_vertex(bvh, c, centre),
        });
    }
    far
}

fn leaf_sums(bvh: &Bvh8, r: u32) -> Sums {
    let mut sums: Sums = (DVec3::ZERO, 0.0, DVec3::ZERO);
    for b in leaf_blocks(r) {
        let block = &bvh.blocks[b];
        for lane in (0..4).filter(|&l| block.id[l] != u32::MAX) {
            let [a, bb, c] = block.corners(lane).map(|v| DVec3::from(v.map(f64::from)));
            let n = (bb - a).cross(c - a) * 0.5;
            let area = n.length();
            sums.0 += (a + bb + c) / 3.0 * area;
            sums.1 += area;
            sums.2 += n;
        }
    }
    sums
}

/// The winding number of the tree's triangles at `q` (see the module's notes).
#[inline(always)]
fn winding(bvh: &Bvh8, data: &WindingData, s: &mut Scratch, q: [f32; 3]) -> f64 {
    if bvh.blocks.is_empty() {
        return 0.0;
    }
    let qd = DVec3::from(q.map(f64::from));
    let mut total = 0.0;
    let stack = &mut s.refs[..STACK];
    stack[0] = node_ref(0);
    let mut top = 1;
    while top > 0 {
        top -= 1;
        let r = stack[top];
        let d = &data.nodes[node_index(r)];
        let to = DVec3::new(d[0] as f64, d[1] as f64, d[2] as f64) - qd;
        let dist = to.length();
        if dist > BETA * d[6] as f64 {
            let dipole = DVec3::new(d[3] as f64, d[4] as f64, d[5] as f64);
            total += to.dot(dipole) / (dist * dist * dist);
            continue;
        }
        let node = node_at(&bvh.nodes, r);
        for &c in &node.child {
            if c == EMPTY {
                continue;
            }
            if c & LEAF == 0 {
                stack[top] = c;
                top += 1;
                continue;
            }
            for b in leaf_blocks(c) {
                let block = &bvh.blocks[b];
                for lane in (0..4).filter(|&l| block.id[l] != u32::MAX) {
                    let [a, bb, cc] = block.corners(lane).map(|v| DVec3::from(v.map(f64::from)));
                    total += solid_angle(a - qd, bb - qd, cc - qd);
                }
            }
        }
    }
    total / (4.0 * PI)
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
mod tests {
    use super::*;
    use crate::trace::Bvh;

    /// The closest triangle by squared distance, then the smaller id (the traversal's rule).
    fn brute(scene: &Scene, q: DVec3) -> (f64, u32) {
        let (d2, t) = (0..scene.triangle_count())
            .map(|t| {
                let [a, b, c] = scene.triangle(t);
                let (p, _, _) = closest_on_triangle(q, a, b, c);
                ((p - q).length_squared(), t as u32)
            })
            .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)))
            .unwrap();
        (d2.sqrt(), t)
    }

    #[test]
    fn closest_points_match_a_brute_force_in_f64() {
        let (v, f) = crate::trace::tests::icosphere(3);
        let scene = Scene::from_arrays(v, f, None, None).unwrap();
        let mut rng = 12345u64;
        let mut next = || {
            // xorshift64: a test's fixed stream of points, no dependency on discretize's hash.
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0
        };
        let pts: Vec<[f32; 3]> = (0..2000)
            .map(|_| [next() as f32, next() as f32, next() as f32])
            .collect();
        let got = closest_points(&scene, &pts, f32::INFINITY, Threads::All).unwrap();
        for (i, p) in pts.iter().enumerate() {
            let q = DVec3::from(p.map(f64::from));
            let (d, t) = brute(&scene, q);
            let g = got.distance[i] as f64;
            assert!((g - d).abs() <= 1e-6 * d.max(1e-6), "{i}: {g} vs {d}");
            assert_eq!(got.triangle[i] as u32, t, "{i}");
            // The point is on its triangle at the barycentrics reported.
            let [a, b, c] = scene.triangle(t as usize);
            let [u, v] = got.barycentric[i].map(f64::from);
            let at = a * (1.0 - u - v) + b * u + c * v;
            let pt = DVec3::from(got.point[i].map(f64::from));
            assert!((at - pt).length() < 1e-5, "{i}");
        }
        // Beyond max_distance: nothing.
        let near = closest_points(&scene, &[[0.0, 0.0, 5.0]], 1.0, Threads::One).unwrap();
        assert_eq!(near.triangle, vec![-1]);
        assert!(near.distance[0].is_infinite());
    }

    #[test]
    fn the_order_and_the_seed_change_no_answer() {
        let (v, f) = crate::trace::tests::icosphere(3);
        let scene = Scene::from_arrays(v, f, None, None).unwrap();
        // Points on a spiral through the sphere's surface, inside and out, plus exact repeats
        // (ties with their neighbours' seeds).
        let mut pts: Vec<[f32; 3]> = (0..3000)
            .map(|i| {
                let t = i as f32 * 0.01;
                let r = 0.5 + (i % 7) as f32 * 0.15;
                [r * t.cos(), r * t.sin(), (i % 13) as f32 * 0.1 - 0.6]
            })
            .collect();
        pts.extend_from_within(..100);
        let all = closest_points(&scene, &pts, f32::INFINITY, Threads::All).unwrap();
        let w = winding_numbers(&scene, &pts, Threads::All).unwrap();
        for (i, p) in pts.iter().enumerate().step_by(7) {
            let one = closest_points(&scene, &[*p], f32::INFINITY, Threads::One).unwrap();
            assert_eq!(one.triangle[0], all.triangle[i], "{i}");
            assert_eq!(one.distance[0].to_bits(), all.distance[i].to_bits(), "{i}");
            assert_eq!(
                one.point[0].map(f32::to_bits),
                all.point[i].map(f32::to_bits)
            );
            let w1 = winding_numbers(&scene, &[*p], Threads::One).unwrap();
            assert_eq!(w1[0].to_bits(), w[i].to_bits(), "{i}");
        }
    }

    #[test]
    fn spread_bits_interleaves() {
        assert_eq!(spread_bits(0b1), 0b1);
        assert_eq!(spread_bits(0b11), 0b1001);
        assert_eq!(spread_bits(0x3ff), 0x0924_9249);
        assert_eq!(spread_bits(0x400), 0, "only ten bits");
    }

    #[test]
    fn degenerate_triangles_give_their_edges() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::X * 2.0);
        let (p, u, v) = closest_on_triangle(DVec3::new(1.5, 1.0, 0.0), a, b, c);
        assert!((p - DVec3::new(1.5, 0.0, 0.0)).length() < 1e-12, "{p}");
        assert!((a * (1.0 - u - v) + b * u + c * v - p).length() < 1e-12);
        let (p, _, _) = closest_on_triangle(DVec3::ONE, a, a, a);
        assert_eq!(p, a);
    }

    /// Points around the unit icosphere: a shell of radii across the surface, points on its
    /// triangles, and points 1e-7 off them on either side.
    fn probes(scene: &Scene) -> Vec<[f32; 3]> {
        let mut pts = Vec::new();
        for i in 0..3000 {
            let t = i as f32 * 0.618;
            let r = 0.2 + (i % 17) as f32 * 0.09;
            let z = (i as f32 / 1500.0) - 1.0;
            let s = (1.0 - z * z).sqrt();
            pts.push([r * s * t.cos(), r * s * t.sin(), r * z]);
        }
        for t in (0..scene.triangle_count()).step_by(7) {
            let [a, b, c] = scene.triangle(t);
            let n = (b - a).cross(c - a).normalize();
            for (u, v) in [(0.2, 0.3), (0.5, 0.5), (0.0, 0.4), (1.0 / 3.0, 1.0 / 3.0)] {
                let on = a + (b - a) * u + (c - a) * v;
                for off in [0.0, 1e-7, -1e-7] {
                    pts.push((on + n * off).as_vec3().to_array());
                }
            }
        }
        pts
    }

    /// The closed-surface path (one ray each) against the hierarchical sum: each answer is the
    /// sum's own (a point its ray could not settle) or the integer the sum rounds to, and the
    /// sum is then within 0.05 of it.
    fn check_closed_against_summed(scene: &Scene, pts: &[[f32; 3]]) -> usize {
        assert!(Closure::of(scene).closed);
        let bvh = Bvh::of(scene);
        let fast = winding_numbers(scene, pts, Threads::All).unwrap();
        let summed = summed_winding(scene, &bvh.tree, pts, Threads::All).unwrap();
        let mut by_ray = 0;
        for (i, (f, s)) in fast.iter().zip(&summed).enumerate() {
            if f.to_bits() == s.to_bits() {
                continue;
            }
            by_ray += 1;
            assert_eq!(*f, s.round(), "{i} {:?}: ray {f}, sum {s}", pts[i]);
            assert!((s - f).abs() < 0.05, "{i} {:?}: ray {f}, sum {s}", pts[i]);
        }
        by_ray
    }

    #[test]
    fn closed_surfaces_take_one_ray_per_point_and_agree_with_the_sum() {
        let (v, f) = crate::trace::tests::icosphere(3);
        let scene = Scene::from_arrays(v.clone(), f.clone(), None, None).unwrap();
        let pts = probes(&scene);
        let by_ray = check_closed_against_summed(&scene, &pts);
        assert!(by_ray > pts.len() / 2, "{by_ray} of {} by ray", pts.len());
        // The same sphere as a triangle soup (every corner its own vertex, as an STL file).
        let soup: Vec<[f32; 3]> = f.iter().flat_map(|t| t.map(|i| v[i as usize])).collect();
        let faces: Vec<[u32; 3]> = (0..f.len() as u32)
            .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
            .collect();
        let soup = Scene::from_arrays(soup, faces, None, None).unwrap();
        assert!(check_closed_against_summed(&soup, &pts) > pts.len() / 2);
        // Turned inside out: -1 inside.
        let flipped: Vec<[u32; 3]> = f.iter().map(|t| [t[0], t[2], t[1]]).collect();
        let flipped = Scene::from_arrays(v, flipped, None, None).unwrap();
        assert!(check_closed_against_summed(&flipped, &pts) > pts.len() / 2);
        let w = winding_numbers(&flipped, &[[0.1, 0.2, -0.1]], Threads::One).unwrap();
        assert_eq!(w, vec![-1.0]);
        // Answers do not depend on the thread count.
        let one = winding_numbers(&scene, &pts, Threads::One).unwrap();
        let all = winding_numbers(&scene, &pts, Threads::All).unwrap();
        assert!(one
            .iter()
            .zip(&all)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
    }

    #[test]
    fn winding_numbers_are_one_inside_zero_outside_and_near_the_exact_sum() {
        let (v, f) = crate::trace::tests::icosphere(4);
        let scene = Scene::from_arrays(v, f, None, None).unwrap();
        let pts: Vec<[f32; 3]> = (0..400)
            .map(|i| {
                let t = i as f32 / 400.0;
                [3.0 * t - 1.5, 0.7 * (t * 9.0).sin(), 0.3 * (t * 5.0).cos()]
            })
            .collect();
        let w = winding_numbers(&scene, &pts, Threads::All).unwrap();
        for (p, w) in pts.iter().zip(&w) {
            let exact: f64 = (0..scene.triangle_count())
                .map(|t| {
                    let q = DVec3::from(p.map(f64::from));
                    let [a, b, c] = scene.triangle(t);
                    solid_angle(a - q, b - q, c - q)
                })
                .sum::<f64>()
                / (4.0 * PI);
            assert!((w - exact).abs() < 0.03, "{p:?}: {w} vs {exact}");
            let r = DVec3::from(p.map(f64::from)).length();
            if (r - 1.0).abs() > 0.02 {
                assert_eq!(*w >= 0.5, r < 1.0, "{p:?}: {w}");
            }
        }
    }
}
