//! Signed ray crossings: for each ray, the triangles it crosses counted +1 where it leaves
//! through a triangle's back (the ray goes the way the front faces) and −1 where it enters
//! through a front. On a closed surface (`scene::adjacency::Closure`) the count along a ray
//! from a point to infinity is the generalized winding number at the point, exactly (the
//! crossing-number form of the winding number; for a closed mesh without overlaps, the parity
//! of Open3D's occupancy ray).
//!
//! A count is only as good as each crossing's side and sign, so a ray whose count could be
//! wrong reports [`AMBIGUOUS`] instead:
//! - it meets an edge or a corner exactly (an edge function of the watertight test is zero):
//!   both triangles of an edge count such a hit, and the ray may touch a surface without
//!   crossing it;
//! - it starts within `near` of the plane of a triangle it meets, in either direction: the
//!   sign of `t` there is within the rounding of the test (a point on or next to the surface).
//!
//! The caller answers those rays another way (the winding number's own sum).

use glam::{DVec3, Vec3A};

use super::dispatch::{dispatch, Job};
use super::driver::drive_with;
use super::node::Bvh8;
use super::query::{Query, Threads};
use super::rays::{Rays, Scratch};
use super::schedule::run;
use super::traverse::{Kernel, Sink, Tri4Hit};
use crate::error::Result;
use crate::scene::Scene;

/// A count that could be wrong (see the module's notes).
pub const AMBIGUOUS: i32 = i32::MIN;

/// The signed crossings of each whole ray (`t >= 0`, in units of its direction's length), or
/// [`AMBIGUOUS`] for a ray that meets an edge or a corner exactly, or whose origin lies within
/// `near` of the plane of a triangle it meets at `t >= -back` (the triangles just behind the
/// origin are checked too: where the origin is that close, `t`'s sign is not to be trusted).
/// Progress counts the rays.
pub fn crossings(
    scene: &Scene,
    origins: &[[f32; 3]],
    directions: &[[f32; 3]],
    threads: Threads,
    near: f32,
    back: f32,
) -> Result<Vec<i32>> {
    let q = Query {
        t_min: 0.0,
        t_max: f32::INFINITY,
        threads,
        report: true,
    };
    let (count, _) = drive_with(scene, origins, directions, &q, true, |bvh| {
        let mut count = vec![0i32; origins.len()];
        let behind = Query { t_min: -back, ..q };
        let rays = Rays::new(bvh, origins, directions, &behind);
        let job = CrossJob {
            rays: &rays,
            near: f64::from(near),
        };
        run(&q, &mut count[..], 1, |base, out| dispatch(&job, base, out))?;
        Ok(count)
    })?;
    Ok(count)
}

struct CrossJob<'a> {
    rays: &'a Rays<'a>,
    near: f64,
}

impl Job for CrossJob<'_> {
    type Out<'o> = &'o mut [i32];

    #[inline(always)]
    fn chunk<K: Kernel>(&self, k: K, base: usize, out: &mut [i32]) {
        let mut scratch = Scratch::new();
        let rays = self.rays;
        rays.trace(
            k,
            base,
            0..out.len(),
            &mut scratch,
            #[inline(always)]
            |j| Cross {
                o: rays.origins[base + j],
                near: self.near,
                t_far: rays.range.1,
                count: 0,
            },
            #[inline(always)]
            |j, sink| out[j] = sink.count,
        );
    }
}

/// One ray's count so far.
#[derive(Clone, Copy)]
struct Cross {
    o: [f32; 3],
    near: f64,
    t_far: f32,
    count: i32,
}

impl Sink for Cross {
    /// Every hit counts: no order helps.
    const ORDERED: bool = false;

    #[inline(always)]
    fn t_far(&self) -> f32 {
        self.t_far
    }

    #[inline(always)]
    fn take(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit) -> bool {
        let mut m = h.mask;
        while m != 0 {
            let lane = m.trailing_zeros() as usize;
            m &= m - 1;
            let (bu, bv, det) = (h.bu[lane], h.bv[lane], h.det[lane]);
            // The edge functions are bu, bv and det − bu − bv, all of det's sign. The third is
            // zero only if det == bu + bv as rounded (which a tiny nonzero one may also give:
            // such a ray is answered the other way too).
            let on_edge = bu == 0.0 || bv == 0.0 || det == bu + bv;
            if on_edge || self.near_plane(bvh.blocks[block].corners(lane)) {
                self.count = AMBIGUOUS;
                return true;
            }
            if h.t[lane] >= 0.0 {
                self.count += if det > 0.0 { -1 } else { 1 };
            }
        }
        false
    }
}

impl Cross {
    /// Whether the origin lies within `near` of the plane of triangle `v`, in f64 where an f32
    /// estimate comes within twice `near` (its error is a few ulps of the coordinates, and
    /// `near` is hundreds: the estimate alone settles all but the points next to the plane).
    #[inline(always)]
    fn near_plane(&self, v: [[f32; 3]; 3]) -> bool {
        let [a, b, c] = v.map(Vec3A::from);
        let n = (b - a).cross(c - a);
        let h = n.dot(Vec3A::from(self.o) - a);
        let near = 2.0 * self.near as f32;
        let limit = near * near * n.length_squared();
        // (Only where f32 holds the bound at full precision: not for coordinates so small or so
        // large that it underflows or overflows.)
        if limit.is_normal() && h * h > limit {
            return false;
        }
        let [a, b, c] = v.map(|p| DVec3::from(p.map(f64::from)));
        let n = (b - a).cross(c - a);
        let h = n.dot(DVec3::from(self.o.map(f64::from)) - a);
        h * h <= self.near * self.near * n.length_squared()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cube of 12 triangles wound counter-clockwise seen from outside, [-1, 1]^3.
    fn cube() -> Scene {
        let v: Vec<[f32; 3]> = (0..8)
            .map(|i| [0, 1, 2].map(|a| if i >> a & 1 == 1 { 1.0 } else { -1.0 }))
            .collect();
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let f: Vec<[u32; 3]> = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        Scene::from_arrays(v, f, None, None).unwrap()
    }

    fn count(scene: &Scene, o: [f32; 3], d: [f32; 3]) -> i32 {
        crossings(scene, &[o], &[d], Threads::One, 1e-5, 1e-2).unwrap()[0]
    }

    #[test]
    fn inside_counts_one_outside_zero_and_edges_are_ambiguous() {
        let s = cube();
        let d = [1.0, 0.0131, 0.0077];
        assert_eq!(count(&s, [0.1, 0.2, 0.3], d), 1);
        assert_eq!(count(&s, [0.9, -0.7, 0.5], [-0.3, 1.0, 0.2]), 1);
        assert_eq!(count(&s, [-3.0, 0.2, 0.3], d), 0);
        assert_eq!(count(&s, [3.0, 0.2, 0.3], d), 0);
        // Through the diagonal edge of the +x face's two triangles (y = z there).
        assert_eq!(count(&s, [0.0, 0.25, 0.25], [1.0, 0.0, 0.0]), AMBIGUOUS);
        // On the surface, and just inside it.
        assert_eq!(count(&s, [1.0, 0.2, 0.3], d), AMBIGUOUS);
        assert_eq!(count(&s, [0.999_999_9, 0.2, 0.3], d), AMBIGUOUS);
        assert_eq!(count(&s, [-0.999_999_9, 0.2, 0.3], d), AMBIGUOUS);
        // Turned inside out, the inside counts -1.
        let flipped = Scene::from_arrays(
            s.vertices().to_vec(),
            s.faces().iter().map(|f| [f[0], f[2], f[1]]).collect(),
            None,
            None,
        )
        .unwrap();
        assert_eq!(count(&flipped, [0.1, 0.2, 0.3], d), -1);
    }
}
