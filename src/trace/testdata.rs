//! Test data that the tests of several `trace` files share: an icosphere and a seeded generator.

use std::sync::Arc;

use glam::{DMat4, DQuat, DVec3, Vec3};

use super::node::Bvh8;
use super::query::Query;
use crate::scene::{Scene, SceneParts};

/// An icosphere subdivided `n` times: a closed mesh with shared edges and vertices.
pub(crate) fn icosphere(n: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let (v0, f0) = crate::scene::shapes::icosahedron();
    let mut v: Vec<Vec3> = v0.iter().map(|p| p.as_vec3()).collect();
    let mut f: Vec<[u32; 3]> = f0.to_vec();
    for _ in 0..n {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::new();
        for tri in &f {
            let m: Vec<u32> = (0..3)
                .map(|k| {
                    let (a, b) = (tri[k].min(tri[(k + 1) % 3]), tri[k].max(tri[(k + 1) % 3]));
                    *mid.entry((a, b)).or_insert_with(|| {
                        v.push(((v[a as usize] + v[b as usize]) * 0.5).normalize());
                        v.len() as u32 - 1
                    })
                })
                .collect();
            next.push([tri[0], m[0], m[2]]);
            next.push([tri[1], m[1], m[0]]);
            next.push([tri[2], m[2], m[1]]);
            next.push([m[0], m[1], m[2]]);
        }
        f = next;
    }
    (v.iter().map(|p| p.to_array()).collect(), f)
}

/// A deterministic generator (SplitMix64) for test data.
pub(crate) struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

    pub fn point(&mut self, lo: f32, hi: f32) -> [f32; 3] {
        [0; 3].map(|_| lo + (hi - lo) * self.next())
    }
}

/// `n` icospheres (`icosphere(2)`) in a row, one object each.
pub(crate) fn spheres(n: usize) -> Arc<Scene> {
    let (v, f) = icosphere(2);
    let mut parts = SceneParts::default();
    for k in 0..n {
        let off = parts.vertices.len() as u32;
        let x = 3.0 * k as f32;
        parts
            .vertices
            .extend(v.iter().map(|p| [p[0] + x, p[1], p[2]]));
        parts.faces.extend(f.iter().map(|t| t.map(|i| i + off)));
        parts
            .object_ids
            .extend(std::iter::repeat_n(k as i32, f.len()));
        parts.objects.push(format!("s{k}"));
    }
    parts.material_ids = vec![-1; parts.faces.len()];
    Arc::new(Scene::new(parts).unwrap())
}

/// The scene of `n` spheres, posed by [`poses`], and a fresh scene of the posed vertices.
pub(crate) fn posed_and_flat(n: usize) -> (Arc<Scene>, Scene, Scene) {
    let base = spheres(n);
    let posed = base.posed(&poses(n)).unwrap();
    let flat = Scene::from_arrays(
        posed.vertices().to_vec(),
        posed.faces().to_vec(),
        None,
        None,
    )
    .unwrap();
    (base, posed, flat)
}

/// A pose of `n` objects: each turned, scaled (mirrored where `k % 3 == 0`) and moved, one of
/// them far away.
pub(crate) fn poses(n: usize) -> Vec<DMat4> {
    (0..n)
        .map(|k| {
            let t = k as f64;
            let rot = DQuat::from_euler(glam::EulerRot::XYZ, 0.3 * t, 0.7 * t, 0.1 * t);
            let scale = DVec3::new(1.0 + 0.1 * t, 1.0, if k % 3 == 0 { -1.0 } else { 0.5 });
            let shift = DVec3::new(-2.0 * t, (t * 0.9).sin() * 4.0, 1e5 * f64::from(k == 5));
            DMat4::from_scale_rotation_translation(scale, rot, shift)
        })
        .collect()
}

/// Rays from around the scene toward points of `at`, give or take.
pub(crate) fn rays_toward(n: usize, seed: u64, at: &[[f32; 3]]) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let mut r = Rng(seed);
    let o: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            let p = r.point(0.0, 1.0);
            [p[0] * 80.0 - 60.0, p[1] * 40.0 - 20.0, p[2] * 40.0 - 20.0]
        })
        .collect();
    let d = o
        .iter()
        .map(|p| {
            let v = at[(r.next() * at.len() as f32) as usize % at.len()];
            std::array::from_fn(|a| v[a] - p[a] + 0.3 * (r.next() - 0.5))
        })
        .collect();
    (o, d)
}

/// `t`, triangle and barycentric of `n` rays, as `fill` writes them into fresh outputs.
pub(crate) type Hits3 = (Vec<f32>, Vec<i32>, Vec<[f32; 2]>);

/// The `n` hits that `fill` writes into fresh outputs (as a job's chunk does, `jobs::no_hits`
/// first).
pub(crate) fn written(n: usize, fill: impl FnOnce(super::schedule::FreshHits<'_>)) -> Hits3 {
    let (mut t, mut tri, mut bary): Hits3 = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    fill((
        &mut t.spare_capacity_mut()[..n],
        &mut tri.spare_capacity_mut()[..n],
        &mut bary.spare_capacity_mut()[..n],
    ));
    // SAFETY: `fill` is a job's chunk over all `n` rays, which writes every entry.
    unsafe {
        t.set_len(n);
        tri.set_len(n);
        bary.set_len(n);
    }
    (t, tri, bary)
}

/// Closest hits on `tree` itself (`t`, triangle, barycentric), with the portable kernel.
pub(crate) fn closest_on(tree: &Bvh8, o: &[[f32; 3]], d: &[[f32; 3]]) -> Hits3 {
    use super::dispatch::Job;
    let q = Query::new(0.0, f32::INFINITY);
    let rays = super::rays::Rays::new(tree, o, d, &q);
    let job = super::jobs::ClosestJob::new(&rays);
    written(o.len(), |out| job.chunk(super::portable::Portable, 0, out))
}
