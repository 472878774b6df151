//! Watertight ray/triangle intersection: Woop, Benthin and Wald, "Watertight Ray/Triangle
//! Intersection", JCGT 2(1), 2013. The ray is sheared so that it runs along +z through the
//! origin; the 2D edge functions of a shared edge are then computed from identical inputs in
//! both triangles (and exactly negated), so a ray through an edge or vertex always hits at
//! least one of the triangles. Edge functions that round to zero are recomputed in f64 (§4.4).

use glam::Vec3A;

/// A triangle's three corners, in world space.
#[derive(Clone, Copy, Debug)]
pub struct Tri {
    pub v: [Vec3A; 3],
}

/// Per-ray constants of the shear transform (the paper's kx, ky, kz, Sx, Sy, Sz).
#[derive(Clone, Copy, Debug)]
pub struct RayShear {
    pub(crate) k: [usize; 3],
    pub(crate) s: [f32; 3],
}

impl RayShear {
    #[inline(always)]
    pub fn new(d: Vec3A) -> Self {
        Self::with_inverse(d, Vec3A::ONE / d)
    }

    /// The shear of `d`, given `inv` whose dominant component is `1 / d` there (the division
    /// is then not done twice).
    #[inline(always)]
    pub fn with_inverse(d: Vec3A, inv: Vec3A) -> Self {
        // Arithmetic and table lookups rather than branches: for incoherent rays every branch
        // on the direction would be a coin toss for the predictor. Components are picked from
        // arrays by index (a load), not from `Vec3A` (whose indexing is a three-way match).
        let a = d.abs();
        let x_wins = usize::from((a.x > a.y) & (a.x > a.z));
        let y_wins = usize::from(a.y > a.z) & (1 - x_wins);
        let kz = 2 - 2 * x_wins - y_wins;
        let dv = lanes(d);
        // Swap to keep the triangles' winding when the dominant component is negative.
        let neg = usize::from(dv[kz & 3] < 0.0);
        let [kx, ky] = AXES[(kz << 1 | neg) & 7];
        // One division: the shear constants need not be correctly rounded quotients, only the
        // same for every triangle the ray meets.
        let sz = lanes(inv)[kz & 3];
        Self {
            k: [kx, ky, kz],
            s: [dv[kx & 3] * sz, dv[ky & 3] * sz, sz],
        }
    }

    /// `p`'s components in the shear's axis order (kx, ky, kz).
    #[inline(always)]
    pub fn permute(&self, p: Vec3A) -> [f32; 3] {
        let p = lanes(p);
        self.k.map(|a| p[a & 3])
    }
}

/// (kx, ky) by `2 kz + (1 if d[kz] < 0)`: the two axes after kz in cyclic order, swapped when
/// the dominant component is negative, as Woop et al. (2013) choose them. The last two rows pad
/// the table to eight, so a masked index needs no bounds check.
const AXES: [[usize; 2]; 8] = [
    [1, 2],
    [2, 1],
    [2, 0],
    [0, 2],
    [0, 1],
    [1, 0],
    [0, 1],
    [0, 1],
];

/// A vector's components in an array of four (the fourth 0), to index with `& 3`.
#[inline(always)]
fn lanes(v: Vec3A) -> [f32; 4] {
    let [x, y, z] = v.to_array();
    [x, y, z, 0.0]
}

/// A hit of [`intersect`]: `t`, and the barycentric numerators `[bu, bv]` over their common
/// denominator `det` (barycentric (u, v) = (`bu / det`, `bv / det`)), whose sign says which
/// face the ray meets ([`Hit::front`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub b: [f32; 2],
    pub det: f32,
}

impl Hit {
    /// Whether the ray meets the triangle's front (the side its corners wind counter-clockwise
    /// seen from), by `det`'s sign: exact, since the hit's three edge functions share it.
    #[inline(always)]
    pub fn front(&self) -> bool {
        self.det > 0.0
    }
}

/// Intersect; returns the hit with `t_min <= t < t_max`, both faces counting.
#[inline(always)]
pub fn intersect(tri: &Tri, o: Vec3A, ray: &RayShear, t_min: f32, t_max: f32) -> Option<Hit> {
    let [sx, sy, sz] = ray.s;
    let [ax, ay, az] = ray.permute(tri.v[0] - o);
    let [bx, by, bz] = ray.permute(tri.v[1] - o);
    let [cx, cy, cz] = ray.permute(tri.v[2] - o);
    let (ax, ay) = (ax - sx * az, ay - sy * az);
    let (bx, by) = (bx - sx * bz, by - sy * bz);
    let (cx, cy) = (cx - sx * cz, cy - sy * cz);
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    let outside =
        |u: f32, v: f32, w: f32| (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0);
    // An f32 edge function may round to zero, never to the wrong sign: opposite nonzero signs
    // are final, and only a zero is redone in f64 (Woop et al. 2013, §4).
    if outside(u, v, w) {
        return None;
    }
    if u == 0.0 || v == 0.0 || w == 0.0 {
        let f = |p: f32, q: f32, r: f32, s: f32| (p as f64 * q as f64 - r as f64 * s as f64) as f32;
        u = f(cx, by, cy, bx);
        v = f(ax, cy, ay, cx);
        w = f(bx, ay, by, ax);
        if outside(u, v, w) {
            return None;
        }
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let t_scaled = u * (sz * az) + v * (sz * bz) + w * (sz * cz);
    let t = t_scaled / det;
    if !(t >= t_min && t < t_max) {
        return None;
    }
    Some(Hit { t, b: [v, w], det })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_edge_is_never_missed() {
        // Two triangles sharing the edge x = y; rays exactly through points of that edge.
        let t1 = Tri {
            v: [
                Vec3A::new(0., 0., 0.),
                Vec3A::new(1., 0., 0.),
                Vec3A::new(1., 1., 0.),
            ],
        };
        let t2 = Tri {
            v: [
                Vec3A::new(0., 0., 0.),
                Vec3A::new(1., 1., 0.),
                Vec3A::new(0., 1., 0.),
            ],
        };
        for i in 0..1000 {
            let s = i as f32 / 1000.0;
            let o = Vec3A::new(s * 0.37 + 0.1, s * 0.91 - 0.3, 2.0);
            let target = Vec3A::splat(s);
            let target = Vec3A::new(target.x, target.y, 0.0);
            let r = RayShear::new(target - o);
            let hit = intersect(&t1, o, &r, 0.0, f32::INFINITY).is_some()
                || intersect(&t2, o, &r, 0.0, f32::INFINITY).is_some();
            assert!(hit, "ray {i} slipped through the shared edge");
        }
    }

    #[test]
    fn barycentrics_reconstruct_the_hit_point() {
        let t = Tri {
            v: [
                Vec3A::new(0., 0., 0.),
                Vec3A::new(2., 0., 0.),
                Vec3A::new(0., 2., 0.),
            ],
        };
        let o = Vec3A::new(0.5, 0.25, 3.0);
        let h = intersect(&t, o, &RayShear::new(Vec3A::NEG_Z), 0.0, 10.0).unwrap();
        let (tt, [u, v]) = (h.t, h.b.map(|b| b / h.det));
        assert!((tt - 3.0).abs() < 1e-6);
        let p = t.v[0] * (1.0 - u - v) + t.v[1] * u + t.v[2] * v;
        assert!((p - Vec3A::new(0.5, 0.25, 0.0)).length() < 1e-6);
    }

    #[test]
    fn the_determinant_says_which_face_the_ray_meets() {
        // Counter-clockwise seen from +z: the front faces +z.
        let t = Tri {
            v: [
                Vec3A::new(0., 0., 0.),
                Vec3A::new(2., 0., 0.),
                Vec3A::new(0., 2., 0.),
            ],
        };
        for (o, d, front) in [
            (Vec3A::new(0.5, 0.25, 3.0), Vec3A::NEG_Z, true),
            (Vec3A::new(0.5, 0.25, -3.0), Vec3A::Z, false),
            (Vec3A::new(-1.0, 0.3, 1.0), Vec3A::new(1.5, 0.1, -1.2), true),
            (
                Vec3A::new(-1.0, 0.3, -1.0),
                Vec3A::new(1.5, 0.1, 1.2),
                false,
            ),
            (Vec3A::new(3.0, 0.4, 0.5), Vec3A::new(-2.5, 0.2, -0.8), true),
        ] {
            let h = intersect(&t, o, &RayShear::new(d), 0.0, 10.0).unwrap();
            assert_eq!(h.front(), front, "{o} {d}: det {}", h.det);
            assert!(h.b[0] * h.det > 0.0 && h.b[1] * h.det > 0.0);
        }
    }
}
