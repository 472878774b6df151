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

use super::bvh8::{leaf_blocks, node_at, node_index, node_ref, Bvh8, EMPTY, LEAF, STACK};
use super::points::{check_points, chunked, spread_bits, Scratch};
use super::{on_threads, Threads};
use crate::error::Result;
use crate::scene::adjacency::Closure;
use crate::scene::Scene;

/// A node is far enough for its dipole when its centroid lies farther than `BETA` times the
/// distance from it to its farthest vertex. With the first-order term the winding number then
/// stays within a few hundredths of the exact sum (0.021 at worst on the test sphere below), far
/// from the 0.5 that separates inside from outside anywhere but on the surface itself. Each 0.5
/// more of `BETA` costs about 40% more time (the toy car: 0.62 s for 200K points at 2.0, 1.06 s
/// at 2.5) for a third less error.
pub const BETA: f64 = 2.0;

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
