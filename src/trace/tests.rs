//! Tests of the ray queries.

use std::num::NonZeroUsize;

use glam::Vec3;

use super::api::{
    all_hits, cast_rays, cast_rays_kept, cast_rays_with, nearest_hits, nearest_hits_facing,
    occluded, RayHits,
};
use super::bvh::{bvh_for_with, Bvh};
use super::dispatch::{dispatch, Job};
use super::jobs::{any_plan, plan_of, AnyJob, AnyPlan, ClosestJob, Probe, ProbeJob};
use super::portable::Portable;
use super::query::{Query, Threads};
use super::rays::Rays;
use super::refine;
use super::testdata::{closest_on, icosphere, posed_and_flat, poses, rays_toward, Rng};
use crate::scene::Scene;

/// A cloud of random triangles of every size, with duplicated and coplanar ones mixed in.
fn soup(n: usize, seed: u64) -> Scene {
    let mut r = Rng(seed);
    let mut v = Vec::new();
    let mut f = Vec::new();
    for i in 0..n {
        let c = r.point(-1.0, 1.0);
        let s = 0.002 + 0.3 * r.next().powi(3);
        for _ in 0..3 {
            let p = r.point(-s, s);
            v.push([c[0] + p[0], c[1] + p[1], c[2] + p[2]]);
        }
        let b = 3 * i as u32;
        f.push([b, b + 1, b + 2]);
        if i % 17 == 0 {
            // The same triangle again, corners rotated: every hit on it ties.
            f.push([b + 1, b + 2, b]);
        }
    }
    Scene::from_arrays(v, f, None, None).unwrap()
}

fn random_rays(n: usize, seed: u64) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let mut r = Rng(seed);
    (0..n)
        .map(|_| {
            let o = r.point(-1.5, 1.5);
            let t = r.point(-1.0, 1.0);
            (o, [t[0] - o[0], t[1] - o[1], t[2] - o[2]])
        })
        .unzip()
}

/// Camera-like rays: one origin, directions over a small grid (coherent: packets).
fn camera_rays(size: usize, eye: [f32; 3]) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let mut o = Vec::new();
    let mut d = Vec::new();
    for y in 0..size {
        for x in 0..size {
            let u = (x as f32 + 0.5) / size as f32 - 0.5;
            let v = (y as f32 + 0.5) / size as f32 - 0.5;
            o.push(eye);
            d.push([u - 0.3 * eye[0], v - 0.3 * eye[1], -1.0]);
        }
    }
    (o, d)
}

/// Every hit of a ray by brute force in f64: (t, triangle), sorted.
fn brute(s: &Scene, o: [f32; 3], d: [f32; 3], t_max: f64) -> Vec<(f64, u32)> {
    let (o, d) = (o.map(f64::from), d.map(f64::from));
    let mut hits = Vec::new();
    for (i, f) in s.faces().iter().enumerate() {
        let v = f.map(|k| s.vertices()[k as usize].map(f64::from));
        let [det, u, w, t] = refine::moller_trumbore(v, o, d, 1.0);
        if det != 0.0 && u >= 0.0 && w >= 0.0 && u + w <= 1.0 && t >= 0.0 && t < t_max {
            // Ranked as reported: t in float32, then the smaller index.
            hits.push((t as f32 as f64, i as u32));
        }
    }
    hits.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    hits
}

#[test]
fn hits_closest_triangle_with_barycentrics() {
    let v = vec![
        [0., 0., 0.],
        [1., 0., 0.],
        [0., 1., 0.],
        [0., 0., -1.],
        [1., 0., -1.],
        [0., 1., -1.],
    ];
    let s = Scene::from_arrays(v, vec![[3, 4, 5], [0, 1, 2]], None, None).unwrap();
    let h = cast_rays(
        &s,
        &[[0.25, 0.5, 1.0]],
        &[[0.0, 0.0, -2.0]],
        0.0,
        f32::INFINITY,
    )
    .unwrap();
    assert_eq!(h.triangle, vec![1]);
    assert!(
        (h.t[0] - 0.5).abs() < 1e-6,
        "t in units of the direction's length"
    );
    assert!((h.barycentric[0][0] - 0.25).abs() < 1e-6 && (h.barycentric[0][1] - 0.5).abs() < 1e-6);
    let miss = cast_rays(
        &s,
        &[[2.0, 2.0, 1.0]],
        &[[0.0, 0.0, -1.0]],
        0.0,
        f32::INFINITY,
    )
    .unwrap();
    assert_eq!((miss.triangle[0], miss.t[0]), (-1, f32::INFINITY));
}

#[test]
fn no_ray_through_shared_vertices_or_edges() {
    let (v, f) = icosphere(3);
    let s = Scene::from_arrays(v.clone(), f.clone(), None, None).unwrap();
    let mut targets: Vec<Vec3> = v.iter().map(|p| Vec3::from(*p)).collect();
    for tri in &f {
        for k in 0..3 {
            let (a, b) = (
                Vec3::from(v[tri[k] as usize]),
                Vec3::from(v[tri[(k + 1) % 3] as usize]),
            );
            targets.push((a + b) * 0.5);
        }
    }
    let (mut o, mut d) = (Vec::new(), Vec::new());
    for (i, p) in targets.iter().enumerate() {
        // Deterministic directions spread over the sphere (golden-angle spiral).
        let z = 1.0 - 2.0 * ((i as f32 * 0.618_034) % 1.0);
        let phi = i as f32 * 2.399_963;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let out = Vec3::new(r * phi.cos(), r * phi.sin(), z);
        // Tilt the outward normal by at most ~40° so each ray enters the mesh at its target
        // (a ray that only grazes a convex mesh at a vertex may rightly miss).
        let n = p.normalize();
        let tangent = (out - n * out.dot(n)).normalize_or_zero();
        let origin = *p + (n + tangent * 0.8).normalize() * 3.0;
        o.push(origin.to_array());
        d.push((*p - origin).to_array());
    }
    let h = cast_rays(&s, &o, &d, 0.0, f32::INFINITY).unwrap();
    let misses = h.triangle.iter().filter(|&&t| t < 0).count();
    assert_eq!(
        misses,
        0,
        "{misses} of {} rays passed through the closed mesh",
        o.len()
    );
    assert!(occluded(&s, &o, &d, &Query::new(0.0, f32::INFINITY))
        .unwrap()
        .hit
        .iter()
        .all(|&h| h));
}

/// Closest hits are those of a float64 brute force: same triangle, `t` within 1e-6. On an
/// exact tie (the duplicated triangles) the smaller index wins, whatever the traversal.
#[test]
fn closest_hits_match_brute_force() {
    let s = soup(3000, 7);
    let (o, d) = random_rays(4000, 8);
    let h = cast_rays(&s, &o, &d, 0.0, f32::INFINITY).unwrap();
    let mut same = 0;
    for i in 0..o.len() {
        let b = brute(&s, o[i], d[i], f64::INFINITY);
        match b.first() {
            None => assert_eq!(h.triangle[i], -1, "ray {i}: brute force misses"),
            Some(&(t, tri)) => {
                assert!(
                    ((h.t[i] as f64 - t) / t).abs() < 1e-6,
                    "ray {i}: t {} vs {t}",
                    h.t[i]
                );
                // Triangles met at the same depth (duplicated faces, shared edges) rank by
                // their f32 depth, which the f64 one may order differently by an ulp: any
                // of them is right. Beyond that, f32 and f64 may disagree on which of two
                // triangles is first only rarely.
                let _ = tri;
                let tied = b.iter().take_while(|&&(u, _)| u <= t * (1.0 + 1e-6));
                same += usize::from(tied.clone().any(|&(_, k)| k as i32 == h.triangle[i]));
            }
        }
    }
    let hits = h.triangle.iter().filter(|&&t| t >= 0).count();
    assert!(
        same >= hits * 999 / 1000,
        "{same} of {hits} closest triangles agree"
    );
}

/// The AVX2 kernel, packets, single rays, the portable kernel, shuffled orders and every
/// thread setting give bit-identical hits.
#[test]
fn kernels_packets_orders_and_threads_agree() {
    let (v, f) = icosphere(4);
    let s = Scene::from_arrays(v, f, None, None).unwrap();
    let (mut o, mut d) = camera_rays(64, [0.3, 0.2, 3.0]);
    let (ro, rd) = random_rays(4096, 3);
    o.extend(ro);
    d.extend(rd);
    let q = Query::new(0.0, f32::INFINITY);
    let reference = cast_rays_with(&s, &o, &d, &q).unwrap();
    assert!(reference.triangle.iter().filter(|&&t| t >= 0).count() > 3000);
    let bits = |h: &RayHits| {
        h.t.iter()
            .map(|x| x.to_bits())
            .zip(h.triangle.iter().copied())
            .zip(h.barycentric.iter().map(|b| b.map(f32::to_bits)))
            .collect::<Vec<_>>()
    };
    for threads in [Threads::One, Threads::Count(NonZeroUsize::new(3).unwrap())] {
        let h = cast_rays_with(&s, &o, &d, &Query { threads, ..q }).unwrap();
        assert_eq!(bits(&h), bits(&reference), "{threads:?}");
    }
    let perm: Vec<usize> = (0..o.len()).map(|i| (i * 7919) % o.len()).collect();
    let (po, pd): (Vec<_>, Vec<_>) = perm.iter().map(|&i| (o[i], d[i])).unzip();
    let shuffled = cast_rays_with(&s, &po, &pd, &q).unwrap();
    for (k, &i) in perm.iter().enumerate() {
        assert_eq!(shuffled.triangle[k], reference.triangle[i]);
        assert_eq!(shuffled.t[k].to_bits(), reference.t[i].to_bits());
    }
    // The portable kernel (no packets) over the same rays.
    let bvh = Bvh::of(&s);
    let p = super::testdata::closest_on(&bvh.tree, &o, &d);
    let portable = RayHits {
        k: 1,
        t: p.0,
        triangle: p.1,
        barycentric: p.2,
        ..Default::default()
    };
    assert_eq!(bits(&portable), bits(&reference));
    // Rays traced in turns, as on trees larger than INTERLEAVE_BYTES: both kernels, a count
    // of rays that is not a multiple of the packets' eight, camera rays (packets, on AVX2)
    // and random ones (turns).
    let m = o.len() - 3;
    let mut turns = Rays::new(&bvh.tree, &o[..m], &d[..m], &q);
    turns.interleave = true;
    let job = ClosestJob::new(&turns);
    let a = super::testdata::written(m, |out| dispatch(&job, 0, out));
    let p = super::testdata::written(m, |out| job.chunk(Portable, 0, out));
    for (name, (t, tri, bary)) in [("dispatched", a), ("portable", p)] {
        let h = RayHits {
            k: 1,
            t,
            triangle: tri,
            barycentric: bary,
            ..Default::default()
        };
        assert_eq!(bits(&h), bits(&reference)[..m], "{name}, in turns");
    }
    let hit = occluded(&s, &o, &d, &q).unwrap().hit;
    assert_eq!(hit, hit_by_closest(&s, &o, &d, &q));
    // Every any-hit plan, both kernels, one by one and in turns.
    for turns in [false, true] {
        let mut rays = Rays::new(&bvh.tree, &o, &d, &q);
        rays.interleave = turns;
        for (name, any) in any_plans(&rays) {
            assert_eq!(any, hit, "{name}, in turns: {turns}");
        }
    }
}

/// `occluded` of every ray of `rays` by each any-hit plan (nearest first or not, hints or
/// not) on each kernel, named.
fn any_plans(rays: &Rays) -> Vec<(String, Vec<bool>)> {
    let n = rays.origins.len();
    let mut out = Vec::new();
    macro_rules! plan {
        ($nearest:expr, $hint:expr) => {{
            let job = AnyJob::<$nearest, $hint>(rays);
            let (mut portable, mut best) = (vec![false; n], vec![false; n]);
            job.chunk(Portable, 0, &mut portable);
            dispatch(&job, 0, &mut best);
            let name = format!("nearest {}, hints {}", $nearest, $hint);
            out.push((format!("{name}, portable"), portable));
            out.push((format!("{name}, dispatched"), best));
        }};
    }
    plan!(true, true);
    plan!(true, false);
    plan!(false, true);
    plan!(false, false);
    out
}

/// Whether `cast_rays` finds a hit in the range, per ray.
fn hit_by_closest(s: &Scene, o: &[[f32; 3]], d: &[[f32; 3]], q: &Query) -> Vec<bool> {
    let h = cast_rays_with(s, o, d, q).unwrap();
    h.triangle.iter().map(|&t| t >= 0).collect()
}

/// `occluded` is true exactly where `cast_rays` finds a hit in the range.
#[test]
fn occluded_agrees_with_closest_hits() {
    let s = soup(2000, 11);
    let (o, d) = random_rays(5000, 12);
    for t_max in [0.3, 1.0, f32::INFINITY] {
        let q = Query::new(0.05, t_max);
        let a = occluded(&s, &o, &d, &q).unwrap();
        let want = hit_by_closest(&s, &o, &d, &q);
        assert_eq!(a.hit, want, "t_max {t_max}");
        let bvh = Bvh::of(&s);
        for (name, any) in any_plans(&Rays::new(&bvh.tree, &o, &d, &q)) {
            assert_eq!(any, want, "t_max {t_max}, {name}");
        }
    }
}

/// Shadow rays in image order where every other segment ends short of the occluder its
/// neighbour meets (the hint each tries first), and some rays pass beside it: never a hit
/// beyond a segment's end, whatever the any-hit plan.
#[test]
fn occluded_segments_end_where_they_end() {
    // A quad at z = 1 over [0, 1]²; shadow rays rise from a grid over [-0.5, 1.5]².
    let v = [
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [1.0, 1.0, 1.0],
        [0.0, 1.0, 1.0],
    ];
    let s = Scene::from_arrays(v.to_vec(), vec![[0, 1, 2], [0, 2, 3]], None, None).unwrap();
    let (mut o, mut d) = (vec![], vec![]);
    for i in 0..64 {
        for j in 0..64 {
            o.push([
                -0.5 + 2.0 * j as f32 / 63.0,
                -0.5 + 2.0 * i as f32 / 63.0,
                0.0,
            ]);
            d.push([0.0, 0.0, if (i + j) % 2 == 0 { 2.0 } else { 0.5 }]);
        }
    }
    let q = Query::new(0.0, 1.0);
    let a = occluded(&s, &o, &d, &q).unwrap();
    let want = hit_by_closest(&s, &o, &d, &q);
    assert_eq!(a.hit, want);
    let bvh = Bvh::of(&s);
    let rays = Rays::new(&bvh.tree, &o, &d, &q);
    for (name, any) in any_plans(&rays) {
        assert_eq!(any, want, "{name}");
    }
    let blocked = want.iter().filter(|&&h| h).count();
    assert!(
        blocked > 500 && blocked < 4096 / 2,
        "{blocked} rays blocked"
    );
}

/// The k nearest hits are the brute force's, nearest first, ties (duplicated triangles)
/// counted once as the smaller index.
#[test]
fn nearest_hits_match_brute_force() {
    let s = soup(1500, 21);
    let (o, d) = random_rays(1500, 22);
    let k = 4;
    let h = nearest_hits(&s, &o, &d, k, &Query::new(0.0, f32::INFINITY)).unwrap();
    for i in 0..o.len() {
        let mut want: Vec<(f64, u32)> = Vec::new();
        for (t, tri) in brute(&s, o[i], d[i], f64::INFINITY) {
            let same = want
                .last()
                .is_some_and(|&(u, _)| (t - u).abs() <= 1e-6 * t.max(u));
            if !same {
                want.push((t, tri));
            }
        }
        for m in 0..k {
            let (t, tri) = (h.t[i * k + m], h.triangle[i * k + m]);
            match want.get(m) {
                None => assert_eq!((tri, t), (-1, f32::INFINITY), "ray {i} hit {m}"),
                Some(&(wt, wtri)) => {
                    assert!(((t as f64 - wt) / wt).abs() < 1e-5, "ray {i} hit {m}");
                    assert_eq!(tri, wtri as i32, "ray {i} hit {m}");
                }
            }
        }
    }
}

#[test]
fn kept_hits_are_the_nearest_kept_triangle() {
    // Every other triangle kept: each ray's hit is the nearest kept one on its brute-force
    // list, by packets (camera rays) and one by one (random rays); all kept is cast_rays.
    let s = soup(1500, 31);
    let n = s.triangle_count();
    let mut keep = vec![0u64; n.div_ceil(64)];
    for i in (0..n).step_by(2) {
        keep[i / 64] |= 1 << (i % 64);
    }
    let q = Query::new(0.0, f32::INFINITY);
    let (mut o, mut d) = random_rays(1000, 32);
    let (co, cd) = camera_rays(32, [0.1, -0.2, 3.0]);
    o.extend(co);
    d.extend(cd);
    let h = cast_rays_kept(&s, &o, &d, &q, &keep).unwrap();
    let mut met = 0;
    for i in 0..o.len() {
        let want = brute(&s, o[i], d[i], f64::INFINITY)
            .into_iter()
            .find(|&(_, tri)| tri % 2 == 0);
        match want {
            None => assert_eq!(h.triangle[i], -1, "ray {i}"),
            Some((t, tri)) => {
                assert_eq!(h.triangle[i], tri as i32, "ray {i}");
                assert!(((h.t[i] as f64 - t) / t).abs() < 1e-5, "ray {i}");
                met += 1;
            }
        }
    }
    assert!(met > 300, "{met}");
    let all = vec![u64::MAX; n.div_ceil(64)];
    let every = cast_rays_kept(&s, &o, &d, &q, &all).unwrap();
    let plain = cast_rays_with(&s, &o, &d, &q).unwrap();
    assert_eq!(every.triangle, plain.triangle);
    assert_eq!(every.t, plain.t);
    assert!(cast_rays_kept(&s, &o, &d, &q, &keep[1..]).is_err());
}

/// With back faces culled, one hit per ray is the nearest front face on the brute-force list
/// (counter-clockwise towards the ray), by packets (camera rays) and one by one (random rays):
/// the same `t`, and on a tie (duplicated faces, shared edges) one of the tied triangles; the
/// k-nearest path's first hit lies at the same depth.
#[test]
fn front_only_hits_are_the_nearest_front_face() {
    let s = soup(1500, 41);
    let q = Query::new(0.0, f32::INFINITY);
    let (mut o, mut d) = random_rays(1000, 42);
    let (co, cd) = camera_rays(32, [0.2, 0.1, 3.0]);
    o.extend(co);
    d.extend(cd);
    let front = |i: usize, tri: u32| {
        let [a, b, c] = s.faces()[tri as usize].map(|k| Vec3::from(s.vertices()[k as usize]));
        (b - a).cross(c - a).dot(Vec3::from(d[i])) < 0.0
    };
    let h = nearest_hits_facing(&s, &o, &d, 1, &q, true).unwrap();
    let two = nearest_hits_facing(&s, &o, &d, 2, &q, true).unwrap();
    let (mut met, mut same) = (0, 0);
    for i in 0..o.len() {
        let want: Vec<(f64, u32)> = brute(&s, o[i], d[i], f64::INFINITY)
            .into_iter()
            .filter(|&(_, tri)| front(i, tri))
            .collect();
        let Some(&(t, _)) = want.first() else {
            assert_eq!(h.triangle[i], -1, "ray {i}");
            continue;
        };
        assert!(((h.t[i] as f64 - t) / t).abs() < 1e-5, "ray {i}");
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-6 * a.max(b);
        assert!(close(two.t[2 * i], h.t[i]), "ray {i}");
        let mut tied = want.iter().take_while(|&&(u, _)| u <= t * (1.0 + 1e-6));
        same += usize::from(tied.any(|&(_, k)| k as i32 == h.triangle[i]));
        met += 1;
    }
    assert!(met > 300, "{met}");
    assert!(
        same >= met * 999 / 1000,
        "{same} of {met} front faces agree"
    );
}

#[test]
fn all_hits_are_the_nearest_hits_without_a_k() {
    let s = soup(1500, 23);
    let (o, d) = random_rays(3000, 24);
    for threads in [Threads::All, Threads::One] {
        let q = Query {
            threads,
            ..Query::new(0.0, f32::INFINITY)
        };
        let all = all_hits(&s, &o, &d, &q).unwrap();
        assert_eq!(all.splits.len(), o.len() + 1);
        let k = all.splits.windows(2).map(|w| w[1] - w[0]).max().unwrap() as usize;
        assert!(k >= 2, "the soup must give some rays several hits");
        let h = nearest_hits(&s, &o, &d, k, &q).unwrap();
        for i in 0..o.len() {
            let (a, b) = (all.splits[i] as usize, all.splits[i + 1] as usize);
            assert_eq!(
                &all.triangle[a..b],
                &h.triangle[i * k..i * k + b - a],
                "ray {i}"
            );
            assert_eq!(&all.t[a..b], &h.t[i * k..i * k + b - a], "ray {i}");
            assert!(h.triangle[i * k + b - a..(i + 1) * k]
                .iter()
                .all(|&t| t == -1));
        }
    }
}

#[test]
fn bad_rays_are_rejected() {
    let (v, f) = icosphere(0);
    let s = Scene::from_arrays(v, f, None, None).unwrap();
    let q = Query::new(0.0, 1.0);
    let e = cast_rays(&s, &[[0.0; 3]], &[[0.0; 3]], 0.0, 1.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("directions[0]"), "{e}");
    assert!(cast_rays(&s, &[[0.0; 3]], &[], 0.0, 1.0).is_err());
    let nan = occluded(&s, &[[f32::NAN, 0.0, 0.0]], &[[1.0, 0.0, 0.0]], &q);
    assert!(nan.unwrap_err().to_string().contains("origins[0]"));
    let k0 = nearest_hits(&s, &[[0.0; 3]], &[[1.0, 0.0, 0.0]], 0, &q);
    assert!(k0.unwrap_err().to_string().contains("max_hits"));
    assert!(Threads::from_count(Some(0)).is_err());
    assert!(cast_rays(&s, &[[0.0; 3]], &[[1.0, 0.0, 0.0]], 2.0, 1.0).is_err());
}

/// The any-hit probe counts visits, which every kernel makes alike: the same plan on both
/// kernels, and the plans a shadow batch and a random batch should get.
#[test]
fn the_any_hit_probe_is_a_count() {
    let s = soup(3000, 41);
    let bvh = Bvh::of(&s);
    let q = Query::new(0.0, 1.0);
    let (o, d) = random_rays(4096, 42);
    let rays = Rays::new(&bvh.tree, &o, &d, &q);
    let plan = any_plan(&rays, o.len());
    let mut portable = Probe::default();
    ProbeJob(&rays, o.len()).chunk(Portable, 0, &mut portable);
    assert_eq!(plan, plan_of(&portable));
    // Random rays in random order: a neighbour's block never stops the next.
    assert!(!plan.hint, "{plan:?}");
    // A small batch is not probed.
    let few = Rays::new(&bvh.tree, &o[..100], &d[..100], &q);
    assert_eq!(
        any_plan(&few, 100),
        AnyPlan {
            nearest: false,
            hint: true
        }
    );
}

#[test]
fn a_posed_flat_tree_finds_what_a_fresh_build_finds() {
    // The flat tree of a rigid pose (the point queries', winding numbers' and crossings'):
    // its base's object trees refit, bit for bit a fresh build's hits.
    let (base, posed, flat) = posed_and_flat(23);
    let (tree, _) = bvh_for_with(&posed, Threads::All, true).unwrap();
    assert!(tree.tree.inst.is_none());
    assert!(tree.stats().triangles == posed.triangle_count());
    let (o, d) = rays_toward(20_000, 7, posed.vertices());
    let (a, b) = (
        closest_on(&tree.tree, &o, &d),
        closest_on(&Bvh::of(&flat).tree, &o, &d),
    );
    assert!(b.1.iter().filter(|&&t| t >= 0).count() > 10_000);
    assert_eq!(a, b);
    // The same poses again: the same tree, bit for bit.
    let again = base.posed(&poses(23)).unwrap();
    let (tree, _) = bvh_for_with(&again, Threads::One, true).unwrap();
    assert_eq!(closest_on(&tree.tree, &o, &d), a);
}

/// On a two-level tree (a rigid pose), packets, which enter each instance together, find what
/// the portable kernel's lone rays find, bit for bit; so do the k nearest hits.
#[test]
fn two_level_packets_find_what_lone_rays_find() {
    let (_, posed, _) = super::testdata::posed_and_flat(6);
    let (o, d) = camera_rays(128, [0.1, 0.2, 6.0]);
    let tree = Bvh::of(&posed);
    assert!(
        tree.tree.inst.is_some(),
        "a rigid pose traces a two-level tree"
    );
    let h = cast_rays(&posed, &o, &d, 0.0, f32::INFINITY).unwrap();
    assert!(h.triangle.iter().filter(|&&t| t >= 0).count() > 1000);
    let p = closest_on(&tree.tree, &o, &d);
    let bits = |t: &[f32]| t.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(h.triangle, p.1);
    assert_eq!(bits(&h.t), bits(&p.0));
    let q = Query::new(0.0, f32::INFINITY);
    let two = nearest_hits(&posed, &o, &d, 2, &q).unwrap();
    let rays = Rays::new(&tree.tree, &o, &d, &q);
    let job = super::jobs::NearestJob(&rays, 2, false);
    let lone = super::testdata::written(2 * o.len(), |out| job.chunk(Portable, 0, out));
    assert_eq!(two.triangle, lone.1);
    assert_eq!(bits(&two.t), bits(&lone.0));
}

/// The k-nearest sink reports the same surfaces whatever order its hits arrive in (a chain
/// of hits each within the tolerance of the next, a duplicate, a triangle met twice), hits
/// at or beyond its bound being dropped as the traversal drops them.
#[test]
fn surfaces_do_not_depend_on_the_order_hits_arrive_in() {
    let scene = super::testdata::spheres(1);
    let bvh = Bvh::of(&scene);
    let (o, d) = ([[0.0, 0.0, 5.0]], [[0.0, 0.0, -1.0]]);
    let q = Query::new(0.0, f32::INFINITY);
    let rays = Rays::new(&bvh.tree, &o, &d, &q);
    let r = rays.ray(0);
    let e = crate::types::SAME_HIT;
    let hit = |t: f32, triangle: u32| super::rays::Hit {
        t,
        triangle,
        bary: [0.25, 0.5],
    };
    let hits = [
        hit(1.0, 7),
        hit(1.0 + 0.6 * e, 3),
        hit(1.0 + 1.2 * e, 9),
        hit(1.0 + 1.8 * e, 1),
        hit(2.0, 5),
        hit(2.0, 2),
        hit(3.0, 4),
        hit(3.0 + 0.5 * e, 0),
        hit(4.0, 8),
        hit(3.0, 4),
    ];
    // Greedy in (t, triangle) order: 1.0 takes 1 + 0.6e; 1 + 1.2e starts a surface and
    // takes 1 + 1.8e; 2.0 is triangle 2's; 3.0 takes 3 + 0.5e.
    let surfaces = [(1.0, 7), (1.0 + 1.2 * e, 9), (2.0, 2), (3.0, 4), (4.0, 8)];
    let mut seed = 5u32;
    for want in [1, 2, 3, 4, 5, 6, usize::MAX] {
        let expect = &surfaces[..want.min(surfaces.len())];
        for round in 0..300 {
            let mut order = hits;
            if round > 0 {
                for i in (1..order.len()).rev() {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    order.swap(i, (seed >> 16) as usize % (i + 1));
                }
            }
            let mut found = Vec::new();
            let mut sink = super::jobs::Nearest::new(&rays, 0, &r, want, false, &mut found);
            for h in order {
                if h.t < sink.t_far {
                    sink.add(h);
                }
            }
            sink.finish();
            let got: Vec<(f32, u32)> = found.iter().map(|h| (h.t, h.triangle)).collect();
            assert_eq!(got, expect, "want {want}, round {round}");
        }
    }
}
