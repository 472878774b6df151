//! Tests of `trace::winding`.

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
/// sum is then within 0.06 of it.
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
        assert!((s - f).abs() < 0.06, "{i} {:?}: ray {f}, sum {s}", pts[i]);
    }
    by_ray
}

#[test]
fn closed_surfaces_take_one_ray_per_point_and_agree_with_the_sum() {
    let (v, f) = crate::trace::testdata::icosphere(3);
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

/// The faces of an icosphere whose centroids lie below z = 0.8: a sphere with its top cut
/// off (one border).
fn cut_sphere(v: &[[f32; 3]], f: &[[u32; 3]]) -> Vec<[u32; 3]> {
    f.iter()
        .copied()
        .filter(|t| t.iter().map(|&i| v[i as usize][2]).sum::<f32>() / 3.0 < 0.8)
        .collect()
}

#[test]
fn one_point_at_a_time_gives_what_the_batch_gives() {
    // The batch sorts its points and may take the ray or the sum per point; neither the
    // order nor the company of other points may change an answer (closed and open).
    let (v, f) = crate::trace::testdata::icosphere(3);
    let open = cut_sphere(&v, &f);
    for faces in [f.clone(), open] {
        let scene = Scene::from_arrays(v.clone(), faces, None, None).unwrap();
        let mut pts = probes(&scene);
        pts.extend_from_within(..50);
        let all = winding_numbers(&scene, &pts, Threads::All).unwrap();
        for (i, p) in pts.iter().enumerate().step_by(5) {
            let one = winding_numbers(&scene, &[*p], Threads::One).unwrap();
            assert_eq!(one[0].to_bits(), all[i].to_bits(), "{i} {p:?}");
        }
    }
}

/// The float64 winding number: every triangle's solid angle.
fn exact(scene: &Scene, p: [f32; 3]) -> f64 {
    let q = DVec3::from(p.map(f64::from));
    (0..scene.triangle_count())
        .map(|t| {
            let [a, b, c] = scene.triangle(t);
            solid_angle(a - q, b - q, c - q)
        })
        .sum::<f64>()
        / (4.0 * PI)
}

#[test]
fn an_open_surface_is_closed_by_its_cap_and_only_the_cap_is_summed() {
    // A sphere with its top cut off (one border): the cap pays, and the answer is the
    // crossings through sphere and cap less the cap's sum.
    let (v, f) = crate::trace::testdata::icosphere(3);
    let keep = cut_sphere(&v, &f);
    let scene = Scene::from_arrays(v, keep, None, None).unwrap();
    let closure = Closure::of(&scene);
    assert!(!closure.closed && cap_pays(&scene, closure.cap.as_ref().unwrap()));
    let pts = probes(&scene);
    let w = winding_numbers(&scene, &pts, Threads::All).unwrap();
    let bvh = Bvh::of(&scene);
    let summed = summed_winding(&scene, &bvh.tree, &pts, Threads::All).unwrap();
    let mut checked = 0;
    for (i, p) in pts.iter().enumerate().step_by(5) {
        let e = exact(&scene, *p);
        if (e - e.round()).abs() > 0.49 {
            continue; // on the surface
        }
        checked += 1;
        assert!((w[i] - e).abs() < 0.03, "{p:?}: {} vs {e}", w[i]);
        // No worse than the surface's own sum, give or take.
        assert!((w[i] - e).abs() <= (summed[i] - e).abs() + 0.01, "{p:?}");
    }
    assert!(checked > 500);
    let one = winding_numbers(&scene, &pts, Threads::One).unwrap();
    assert!(one.iter().zip(&w).all(|(a, b)| a.to_bits() == b.to_bits()));
}

#[test]
fn angles_sum_like_arctangents_through_every_turn() {
    // Triangles of a sphere seen from inside (4 pi in all, two turns of the product), from
    // outside (0), and random triangles around the origin, in f64.
    let (v, f) = crate::trace::testdata::icosphere(2);
    let mut rng = 99u64;
    let mut next = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    for q in [
        DVec3::ZERO,
        DVec3::new(0.3, -0.2, 0.1),
        DVec3::new(2.0, 0.5, 0.0),
    ] {
        let mut sum = Angles::new();
        let mut direct = 0.0;
        for t in &f {
            let [a, b, c] = t.map(|i| DVec3::from(v[i as usize].map(f64::from)) - q);
            sum.triangle(a, b, c);
            direct += solid_angle(a, b, c);
        }
        assert!(
            (sum.total() - direct).abs() < 1e-12,
            "{q}: {} vs {direct}",
            sum.total()
        );
    }
    for n in [1, 2, 5, 50, 500] {
        let mut sum = Angles::new();
        let mut direct = 0.0;
        for _ in 0..n {
            let [a, b, c] = [(); 3].map(|_| DVec3::new(next(), next(), next()));
            sum.triangle(a, b, c);
            direct += solid_angle(a, b, c);
        }
        assert!(
            (sum.total() - direct).abs() < 1e-11,
            "{n}: {} vs {direct}",
            sum.total()
        );
    }
    // Coordinates that need the scaling: tiny and huge triangles.
    for s in [1e-100, 1e100] {
        let mut sum = Angles::new();
        let [a, b, c] = [DVec3::X, DVec3::Y, DVec3::new(-1.0, -1.0, 0.5)].map(|p| p * s);
        sum.triangle(a, b, c);
        assert!((sum.total() - solid_angle(a, b, c)).abs() < 1e-12);
    }
}

#[test]
fn winding_numbers_are_one_inside_zero_outside_and_near_the_exact_sum() {
    let (v, f) = crate::trace::testdata::icosphere(4);
    let scene = Scene::from_arrays(v, f, None, None).unwrap();
    let pts: Vec<[f32; 3]> = (0..400)
        .map(|i| {
            let t = i as f32 / 400.0;
            [3.0 * t - 1.5, 0.7 * (t * 9.0).sin(), 0.3 * (t * 5.0).cos()]
        })
        .collect();
    let w = winding_numbers(&scene, &pts, Threads::All).unwrap();
    for (p, w) in pts.iter().zip(&w) {
        let exact = exact(&scene, *p);
        assert!((w - exact).abs() < 0.03, "{p:?}: {w} vs {exact}");
        let r = DVec3::from(p.map(f64::from)).length();
        if (r - 1.0).abs() > 0.02 {
            assert_eq!(*w >= 0.5, r < 1.0, "{p:?}: {w}");
        }
    }
}
