//! CPU ray casting: a 4-wide BVH (`bvh4`, built from obvhs's binary PLOC tree) built once per
//! scene, traversed in parallel with rayon, with the watertight ray/triangle test of `watertight`
//! and a float64 refinement of each hit. Consecutive rays are traced in packets of
//! `bvh4::PACKET` when they are coherent (neighbouring pixels of a camera), one by one otherwise;
//! both give the same hits. The loop is compiled twice and the AVX2 build chosen at run time.

pub mod bvh4;
pub mod watertight;

use std::sync::Arc;
use std::time::Instant;

use glam::{Vec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::{Boundable, BvhBuildParams};
use rayon::prelude::*;

use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;
use watertight::{RayShear, Tri};

/// A scene's BVH with its triangles stored in leaf order (cache-friendly traversal).
#[derive(Debug)]
pub struct Bvh {
    tree: bvh4::Bvh4,
    pub build_seconds: f64,
}

/// A triangle's box padded by a few ulps of its coordinates' magnitude, so that the f32 slab
/// tests can never reject a ray that grazes a box exactly at a triangle's vertex or edge: the
/// watertight triangle test then decides alone.
struct PaddedBox(Aabb);

impl Boundable for PaddedBox {
    fn aabb(&self) -> Aabb {
        self.0
    }
}

fn padded_box(t: &Tri) -> PaddedBox {
    let lo = t.v[0].min(t.v[1]).min(t.v[2]);
    let hi = t.v[0].max(t.v[1]).max(t.v[2]);
    let mag = lo.abs().max(hi.abs()).max_element() + (hi - lo).max_element();
    let pad = Vec3A::splat(8.0 * f32::EPSILON * mag + f32::MIN_POSITIVE);
    PaddedBox(Aabb::new(lo - pad, hi + pad))
}

impl Bvh {
    pub fn build(scene: &Scene) -> Self {
        let start = Instant::now();
        let v = scene.vertices();
        let tris: Vec<Tri> = scene
            .faces()
            .iter()
            .map(|f| Tri {
                v: f.map(|k| Vec3A::from(Vec3::from(v[k as usize]))),
            })
            .collect();
        let boxes: Vec<PaddedBox> = tris.iter().map(padded_box).collect();
        let tree = bvh4::Bvh4::build(&tris, &boxes, BvhBuildParams::medium_build());
        Self {
            tree,
            build_seconds: start.elapsed().as_secs_f64(),
        }
    }

    /// The scene's BVH, built on first use and cached for the scene's lifetime.
    pub fn of(scene: &Scene) -> Arc<Bvh> {
        scene
            .bvh
            .get_or_init(|| Arc::new(Bvh::build(scene)))
            .clone()
    }

    /// Closest hits of up to `bvh4::PACKET` rays (any direction lengths), refined in f64, each
    /// given to `sink` with its index in the packet (misses are not). Traces the rays as one packet when they are coherent,
    /// else one by one; both give the same hits.
    #[inline(always)]
    fn trace_packet(
        &self,
        origins: &[[f32; 3]],
        directions: &[[f32; 3]],
        (t_min, t_max): (f32, f32),
        coherence: &Coherence,
        mut sink: impl FnMut(usize, Hit),
    ) {
        const P: usize = bvh4::PACKET;
        let n = origins.len();
        debug_assert!(n <= P);
        // Fixed arrays (filled past `n` with copies of ray 0), built in place: no allocation.
        let at = |i: usize| if i < n { i } else { 0 };
        let o: [Vec3A; P] = std::array::from_fn(|i| Vec3A::from(Vec3::from(origins[at(i)])));
        let d: [Vec3A; P] = std::array::from_fn(|i| Vec3A::from(Vec3::from(directions[at(i)])));
        let len: [f32; P] = std::array::from_fn(|i| d[i].length());
        let unit: [Vec3A; P] = std::array::from_fn(|i| d[i] / len[i]);
        // Trace with unit directions, so the shear and slab arithmetic see the same magnitudes
        // at every direction scale; `refine` then yields t in the caller's units.
        let mut t_far: [f32; P] = std::array::from_fn(|i| t_max * len[i]);
        let mut best: [Option<bvh4::SlotHit>; P] = [None; P];
        let packed = n > 1 && coherence.holds(&o[..n], &unit[..n]) && {
            let rays: [bvh4::PacketRay; P] =
                std::array::from_fn(|i| bvh4::PacketRay::new(o[i], unit[i], t_min * len[i]));
            self.tree
                .closest_packet(&rays[..n], &mut t_far[..n], &mut best[..n])
        };
        if !packed {
            for i in 0..n {
                best[i] = self.tree.closest(
                    o[i],
                    unit[i],
                    &RayShear::new(unit[i]),
                    t_min * len[i],
                    t_max * len[i],
                );
            }
        }
        for (i, h) in best[..n].iter().enumerate() {
            let Some(h) = h else { continue };
            let hit = Hit {
                t: h.t / len[i],
                triangle: self.tree.ids[h.slot as usize],
                bary: h.bary,
                slot: h.slot as usize,
            };
            let tri = &self.tree.tris[hit.slot];
            sink(i, refine(tri, o[i], d[i], (t_min, t_max), hit));
        }
    }
}

/// When a packet of rays is traced together: its unit directions lie within a narrow cone and
/// its origins close together relative to the scene, as for rays through neighbouring pixels of
/// one camera. Incoherent packets would visit the union of their rays' nodes, so they are traced
/// ray by ray instead.
struct Coherence {
    origin_extent: f32,
}

impl Coherence {
    /// Largest spread of a unit direction's components within one packet (about 14 degrees).
    const DIRECTION_EXTENT: f32 = 0.25;

    fn for_scene(scene: &Scene) -> Self {
        Self {
            origin_extent: 0.05 * scene.diagonal() as f32,
        }
    }

    #[inline(always)]
    fn holds(&self, o: &[Vec3A], unit: &[Vec3A]) -> bool {
        let (mut olo, mut ohi) = (o[0], o[0]);
        let (mut dlo, mut dhi) = (unit[0], unit[0]);
        for i in 1..o.len() {
            (olo, ohi) = (olo.min(o[i]), ohi.max(o[i]));
            (dlo, dhi) = (dlo.min(unit[i]), dhi.max(unit[i]));
        }
        (ohi - olo).max_element() <= self.origin_extent
            && (dhi - dlo).max_element() <= Self::DIRECTION_EXTENT
    }
}

/// Recompute the winning triangle's `t` and barycentrics in f64 (Möller–Trumbore on the same
/// f32 inputs): the watertight f32 test decides *which* triangle is hit; this makes *where*
/// precise even for tiny triangles far from the ray origin. Keeps the f32 values when the f64
/// determinant vanishes (a ray in the triangle's plane) or the result leaves `[t_min, t_max]`.
#[inline(always)]
fn refine(tri: &Tri, origin: Vec3A, dir: Vec3A, (t_min, t_max): (f32, f32), hit: Hit) -> Hit {
    // `dir` is the caller's own direction, so `t` comes out in the caller's units.
    let [v0, v1, v2] = tri.v.map(|v| v.as_dvec3());
    let (o, d) = (origin.as_dvec3(), dir.as_dvec3());
    let (e1, e2) = (v1 - v0, v2 - v0);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return hit;
    }
    let tv = o - v0;
    let q = tv.cross(e1);
    let inv_det = 1.0 / det;
    let (u, v, t) = (tv.dot(p) * inv_det, d.dot(q) * inv_det, e2.dot(q) * inv_det);
    let close = (t - hit.t as f64).abs() <= 1e-3 * (hit.t as f64).abs().max(1e-30);
    let inside = t >= t_min as f64 && t < t_max as f64;
    if !(close && inside && u.is_finite() && v.is_finite()) {
        return hit;
    }
    Hit {
        t: t as f32,
        bary: [u as f32, v as f32],
        ..hit
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub triangle: u32,
    pub bary: [f32; 2],
    /// Index into the BVH's leaf-ordered triangles.
    slot: usize,
}

/// Results of `cast_rays`, one entry per ray.
#[derive(Debug, Default)]
pub struct RayHits {
    /// Distance in units of the direction's length; +inf on a miss.
    pub t: Vec<f32>,
    /// Triangle index (the scene's face index); −1 on a miss.
    pub triangle: Vec<i32>,
    /// Barycentric (u, v) of the hit: point = (1−u−v)·v0 + u·v1 + v·v2; (0, 0) on a miss.
    pub barycentric: Vec<[f32; 2]>,
    pub bvh_build_seconds: f64,
    pub trace_seconds: f64,
}

/// Cast rays and return the closest hit of each in `[t_min, t_max]` (units of each
/// direction's length). Directions need not be unit length but must be finite and non-zero.
pub fn cast_rays(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    t_min: f32,
    t_max: f32,
) -> Result<RayHits> {
    check_rays(origins, directions, t_min, t_max)?;
    crate::counters::add(&crate::counters::RAYS_CAST, origins.len() as u64);
    if scene.triangle_count() >= bvh4::MAX_TRIANGLES as usize {
        return input_err!(
            "cast_rays handles scenes of fewer than {} triangles; this one has {}",
            bvh4::MAX_TRIANGLES,
            scene.triangle_count()
        );
    }
    let had_bvh = scene.bvh.get().is_some();
    let bvh = Bvh::of(scene);
    let start = Instant::now();
    let n = origins.len();
    let mut t = vec![f32::INFINITY; n];
    let mut triangle = vec![-1i32; n];
    let mut barycentric = vec![[0.0f32; 2]; n];
    const CHUNK: usize = 1024;
    let job = Chunk {
        bvh: &bvh,
        origins,
        directions,
        range: (t_min, t_max),
        coherence: Coherence::for_scene(scene),
    };
    let avx2 = simd::has_avx2();
    t.par_chunks_mut(CHUNK)
        .zip(triangle.par_chunks_mut(CHUNK))
        .zip(barycentric.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(c, ((t, tri), bary))| {
            let out = (t, tri, bary);
            if avx2 {
                // SAFETY: the CPU was checked to support AVX2 and FMA.
                unsafe { job.run_avx2(c * CHUNK, out) }
            } else {
                job.run(c * CHUNK, out)
            }
        });
    Ok(RayHits {
        t,
        triangle,
        barycentric,
        bvh_build_seconds: if had_bvh { 0.0 } else { bvh.build_seconds },
        trace_seconds: start.elapsed().as_secs_f64(),
    })
}

/// One chunk of `cast_rays`'s work: consecutive rays traced in packets.
struct Chunk<'a> {
    bvh: &'a Bvh,
    origins: &'a [[f32; 3]],
    directions: &'a [[f32; 3]],
    range: (f32, f32),
    coherence: Coherence,
}

type ChunkOut<'o> = (&'o mut [f32], &'o mut [i32], &'o mut [[f32; 2]]);

impl Chunk<'_> {
    /// Trace rays `base..base + out.len()` into `out`.
    #[inline(always)]
    fn run(&self, base: usize, (t, tri, bary): ChunkOut<'_>) {
        for start in (0..t.len()).step_by(bvh4::PACKET) {
            let end = (start + bvh4::PACKET).min(t.len());
            let (o, d) = (
                &self.origins[base + start..base + end],
                &self.directions[base + start..base + end],
            );
            self.bvh
                .trace_packet(o, d, self.range, &self.coherence, |k, h| {
                    let k = start + k;
                    t[k] = h.t;
                    tri[k] = h.triangle as i32;
                    bary[k] = h.bary;
                });
        }
    }

    /// [`Chunk::run`] compiled for AVX2 (VEX-encoded three-operand SSE, BMI bit scans): the
    /// same arithmetic and results (Rust never contracts a·b + c into an FMA on its own), about a
    /// fifth faster where the CPU has it.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA ([`simd::has_avx2`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn run_avx2(&self, base: usize, out: ChunkOut<'_>) {
        self.run(base, out)
    }

    #[cfg(not(target_arch = "x86_64"))]
    unsafe fn run_avx2(&self, base: usize, out: ChunkOut<'_>) {
        self.run(base, out)
    }
}

mod simd {
    /// Whether the running CPU has AVX2 and FMA (checked once, cached by std).
    pub fn has_avx2() -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    }
}

fn check_rays(o: &[[f32; 3]], d: &[[f32; 3]], t_min: f32, t_max: f32) -> Result<()> {
    if o.len() != d.len() {
        return input_err!(
            "origins has {} rows but directions has {}; they must match",
            o.len(),
            d.len()
        );
    }
    if let Some(i) = o.iter().position(|v| v.iter().any(|x| !x.is_finite())) {
        return input_err!("origins[{i}] is not finite: {:?}", o[i]);
    }
    for (i, v) in d.iter().enumerate() {
        let len = Vec3::from(*v).length();
        if !(len.is_finite() && len > 0.0) {
            return input_err!("directions[{i}] must be finite and non-zero, got {v:?}");
        }
    }
    if t_min.is_nan() || t_max.is_nan() || t_min < 0.0 || t_max < t_min {
        return input_err!("need 0 <= t_min <= t_max, got t_min={t_min}, t_max={t_max}");
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// An icosphere subdivided `n` times: a closed mesh with shared edges and vertices.
    pub(crate) fn icosphere(n: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let (v0, f0) = crate::discretize::impostors::icosahedron();
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
        assert!(
            (h.barycentric[0][0] - 0.25).abs() < 1e-6 && (h.barycentric[0][1] - 0.5).abs() < 1e-6
        );
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
        let mut o = Vec::new();
        let mut d = Vec::new();
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
    }

    /// Packets and single rays find the same closest hits: camera-like coherent packets, and
    /// packets whose directions differ in sign on an axis (traced ray by ray).
    #[test]
    fn packets_agree_with_single_rays() {
        let (v, f) = icosphere(4);
        let s = Scene::from_arrays(v, f, None, None).unwrap();
        let bvh = Bvh::of(&s);
        let eye = Vec3A::new(0.3, 0.2, 3.0);
        let size = 256;
        let mut rays = Vec::new();
        for y in 0..size {
            for x in 0..size {
                let d = Vec3A::new(
                    (x as f32 + 0.5) / size as f32 - 0.5,
                    (y as f32 + 0.5) / size as f32 - 0.5,
                    -1.0,
                );
                rays.push((eye, d.normalize()));
            }
        }
        let (mut same, mut packed) = (0, 0);
        for packet in rays.chunks(bvh4::PACKET) {
            let prays: Vec<bvh4::PacketRay> = packet
                .iter()
                .map(|&(o, d)| bvh4::PacketRay::new(o, d, 0.0))
                .collect();
            let mut t_far = vec![f32::INFINITY; packet.len()];
            let mut best = vec![None; packet.len()];
            // Packets straddling the view's centre column mix direction signs and are refused.
            if !bvh.tree.closest_packet(&prays, &mut t_far, &mut best) {
                continue;
            }
            packed += 1;
            for (k, &(o, d)) in packet.iter().enumerate() {
                let single = bvh
                    .tree
                    .closest(o, d, &RayShear::new(d), 0.0, f32::INFINITY);
                let (a, b) = (
                    best[k].map(|h| (h.slot, h.t)),
                    single.map(|h| (h.slot, h.t)),
                );
                same += usize::from(a == b);
            }
        }
        // One packet per row straddles the centre column: 7 of 8 are traced as packets.
        assert!(
            packed >= rays.len() / bvh4::PACKET * 3 / 4,
            "{packed} packets traced"
        );
        assert_eq!(
            same,
            packed * bvh4::PACKET,
            "packet and single-ray hits differ"
        );
        // Opposite directions in one packet: no interval bound, so it is refused.
        let mixed = [
            bvh4::PacketRay::new(eye, Vec3A::NEG_Z, 0.0),
            bvh4::PacketRay::new(eye, Vec3A::Z, 0.0),
        ];
        let (mut t_far, mut best) = ([f32::INFINITY; 2], [None; 2]);
        assert!(!bvh.tree.closest_packet(&mixed, &mut t_far, &mut best));
        // cast_rays gives the same answers for coherent and shuffled (incoherent) orders.
        let (o, d): (Vec<[f32; 3]>, Vec<[f32; 3]>) = rays
            .iter()
            .map(|(o, d)| (o.to_array(), d.to_array()))
            .unzip();
        let coherent = cast_rays(&s, &o, &d, 0.0, f32::INFINITY).unwrap();
        let perm: Vec<usize> = (0..o.len()).map(|i| (i * 7919) % o.len()).collect();
        let (po, pd): (Vec<_>, Vec<_>) = perm.iter().map(|&i| (o[i], d[i])).unzip();
        let shuffled = cast_rays(&s, &po, &pd, 0.0, f32::INFINITY).unwrap();
        for (k, &i) in perm.iter().enumerate() {
            assert_eq!(shuffled.triangle[k], coherent.triangle[i]);
            assert_eq!(shuffled.t[k].to_bits(), coherent.t[i].to_bits());
        }
        // The AVX2 build of the loop gives bit-identical results to the portable one.
        if simd::has_avx2() {
            let job = Chunk {
                bvh: &bvh,
                origins: &o,
                directions: &d,
                range: (0.0, f32::INFINITY),
                coherence: Coherence::for_scene(&s),
            };
            let n = o.len();
            let mut a = (vec![f32::INFINITY; n], vec![-1; n], vec![[0.0; 2]; n]);
            let mut b = a.clone();
            job.run(0, (&mut a.0, &mut a.1, &mut a.2));
            // SAFETY: checked just above.
            unsafe { job.run_avx2(0, (&mut b.0, &mut b.1, &mut b.2)) };
            assert_eq!(a.1, b.1);
            assert!(a
                .0
                .iter()
                .zip(&b.0)
                .all(|(x, y)| x.to_bits() == y.to_bits()));
            assert!(a.2 == b.2);
        }
    }

    #[test]
    fn bad_rays_are_rejected() {
        let (v, f) = icosphere(0);
        let s = Scene::from_arrays(v, f, None, None).unwrap();
        let e = cast_rays(&s, &[[0.0; 3]], &[[0.0; 3]], 0.0, 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("directions[0]"), "{e}");
        assert!(cast_rays(&s, &[[0.0; 3]], &[], 0.0, 1.0).is_err());
    }
}
