//! The float64 refinement of reported hits: the watertight f32 test decides *which* triangle a
//! ray hits; Möller–Trumbore in f64 on the same f32 inputs then makes *where* (`t` and the
//! barycentrics) precise even for tiny triangles far from the ray origin.
//!
//! The arithmetic is written once, generic over a lane type, so the scalar version and the
//! AVX2 version (four hits at a time, `avx2`) perform the same IEEE operations in the same
//! order and agree bit for bit.

use std::ops::{Add, Div, Mul, Sub};

/// A hit waiting for refinement: the triangle's corners, the ray as given, and the f32 result
/// (kept when the f64 one is unusable).
#[derive(Clone, Copy, Debug, Default)]
pub struct Pending {
    pub v: [[f32; 3]; 3],
    pub o: [f32; 3],
    pub d: [f32; 3],
    pub t: f32,
    pub bary: [f32; 2],
}

/// What the refinement needs of a number type.
pub trait Lane:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
}

impl Lane for f64 {}

#[inline(always)]
fn sub<L: Lane>(a: [L; 3], b: [L; 3]) -> [L; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline(always)]
fn cross<L: Lane>(a: [L; 3], b: [L; 3]) -> [L; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline(always)]
fn dot<L: Lane>(a: [L; 3], b: [L; 3]) -> L {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Möller–Trumbore: `[det, u, v, t]` of the ray `o + t·d` and the triangle `v`.
#[inline(always)]
pub fn moller_trumbore<L: Lane>(v: [[L; 3]; 3], o: [L; 3], d: [L; 3], one: L) -> [L; 4] {
    let (e1, e2) = (sub(v[1], v[0]), sub(v[2], v[0]));
    let p = cross(d, e2);
    let det = dot(e1, p);
    let tv = sub(o, v[0]);
    let q = cross(tv, e1);
    let inv_det = one / det;
    [
        det,
        dot(tv, p) * inv_det,
        dot(d, q) * inv_det,
        dot(e2, q) * inv_det,
    ]
}

/// Take the f64 result `[det, u, v, t]` unless it is unusable: the determinant vanishes (a ray
/// in the triangle's plane), `t` strays from the f32 one or leaves `[t_min, t_max)`.
#[inline(always)]
pub fn accept(p: &mut Pending, [det, u, v, t]: [f64; 4], (t_min, t_max): (f32, f32)) {
    if det == 0.0 || !det.is_finite() {
        return;
    }
    let close = (t - p.t as f64).abs() <= 1e-3 * (p.t as f64).abs().max(1e-30);
    let inside = t >= t_min as f64 && t < t_max as f64;
    if close && inside && u.is_finite() && v.is_finite() {
        p.t = t as f32;
        p.bary = [u as f32, v as f32];
    }
}

/// Refine one hit in f64.
#[inline(always)]
pub fn refine_one(p: &mut Pending, range: (f32, f32)) {
    let wide = |a: [f32; 3]| a.map(f64::from);
    let r = moller_trumbore(p.v.map(wide), wide(p.o), wide(p.d), 1.0);
    accept(p, r, range);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_t_and_barycentrics() {
        let mut p = Pending {
            v: [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]],
            o: [0.5, 0.25, 3.0],
            d: [0.0, 0.0, -2.0],
            t: 1.5001,
            bary: [0.0; 2],
        };
        refine_one(&mut p, (0.0, f32::INFINITY));
        assert_eq!((p.t, p.bary), (1.5, [0.25, 0.125]));
        // Outside the range: the f32 values stay.
        let mut q = Pending { t: 1.5, ..p };
        q.bary = [9.0, 9.0];
        refine_one(&mut q, (0.0, 1.0));
        assert_eq!(q.bary, [9.0, 9.0]);
    }
}
