//! Point queries on the ray-casting BVH (the same tree, built once per scene): the closest point
//! of the scene's surface to each query point. The winding numbers (`winding`) share the
//! per-point machinery here: chunks over the cores, Morton order, the AVX2 dispatch.
//!
//! Closest points: best-first descent. A node's eight child boxes are measured against the
//! point in one 8-lane pass; the children nearer than the best distance so far are pushed
//! farthest first, so the nearest is visited next. Leaves test their triangles exactly, in f64
//! (closest point by Voronoi region, as in Ericson, *Real-Time Collision Detection*, §5.1.5), so
//! distances agree with a float64 brute force. Equal distances go to the smaller triangle id,
//! whatever order the tree visits them in.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::node::{leaf_blocks, node_at, node_ref, Bvh8, EMPTY, LEAF, STACK};
use super::query::Threads;
use super::schedule::on_threads;
use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;

/// Points per parallel task.
const CHUNK: usize = 512;

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
        let (bvh, built) = super::bvh::bvh_for_with(scene, threads, true)?;
        let start = Instant::now();
        let limit = max_distance as f64;
        // Each answer packed as it is found (28 bytes, not the 72 of an `Option<Near>`).
        let found = chunked(
            threads,
            points,
            bvh.tree.nodes.len() > 1,
            // Inlined into `dispatch`'s AVX2 copy: a closure does not inherit the target
            // features of the function that calls it, and compiled apart it ran the 8-lane box
            // tests on SSE and called out for each triangle's closest point.
            #[inline(always)]
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

pub(super) fn check_points(points: &[[f32; 3]]) -> Result<()> {
    if let Some(i) = points.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
        return input_err!("points[{i}] is not finite: {:?}", points[i]);
    }
    Ok(())
}

/// A traversal stack, made once per chunk of points rather than once per point (it is 4 KiB,
/// and clearing it per point cost more than a small scene's whole query), and the previous
/// point's answer.
pub(super) struct Scratch {
    near: Vec<(f32, u32)>,
    pub(super) refs: Vec<u32>,
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
pub(super) fn chunked<T: Send + Copy>(
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

/// The ten low bits of `x` moved to every third bit (bit i to bit 3i).
pub(super) fn spread_bits(x: u64) -> u64 {
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
/// bit for bit. A plain loop, not an iterator's `map`: the closure `map` takes would be compiled
/// apart, without AVX2, and `f` (inlined into it) with it.
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
    let mut out = Vec::with_capacity(chunk.len());
    for &p in chunk {
        out.push(f(s, p));
    }
    out
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
#[inline(always)]
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

/// Distance from `q` to the segment a-b.
fn point_segment_distance(q: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let t = if ab.length_squared() > 0.0 {
        ((q - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (q - (a + ab * t)).length()
}

/// Distance from `q` to the triangle `p` (its closed surface): to the plane where `q` projects
/// inside the triangle, otherwise to the nearest edge.
pub fn point_triangle_distance(q: DVec3, p: &[DVec3; 3]) -> f64 {
    let edges = (0..3).map(|k| point_segment_distance(q, p[k], p[(k + 1) % 3]));
    let nearest_edge = edges.fold(f64::INFINITY, f64::min);
    let n = (p[1] - p[0]).cross(p[2] - p[0]);
    let len = n.length();
    if len.is_nan() || len <= 0.0 {
        return nearest_edge;
    }
    let n = n / len;
    let h = n.dot(q - p[0]);
    let r = q - n * h;
    let inside = (0..3).all(|k| (p[(k + 1) % 3] - p[k]).cross(r - p[k]).dot(n) >= 0.0);
    if inside {
        h.abs()
    } else {
        nearest_edge
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let (v, f) = crate::trace::testdata::icosphere(3);
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
        let (v, f) = crate::trace::testdata::icosphere(3);
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
        for (i, p) in pts.iter().enumerate().step_by(7) {
            let one = closest_points(&scene, &[*p], f32::INFINITY, Threads::One).unwrap();
            assert_eq!(one.triangle[0], all.triangle[i], "{i}");
            assert_eq!(one.distance[0].to_bits(), all.distance[i].to_bits(), "{i}");
            assert_eq!(
                one.point[0].map(f32::to_bits),
                all.point[i].map(f32::to_bits)
            );
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
}
