//! The reference kernel: plain f32 arithmetic (SSE2 or NEON through the compiler), the
//! scalar watertight test lane by lane.

use super::node::{Node8, Tri4, ROW_BYTES};
use super::refine::{refine_one, Pending};
use super::traverse::{key_dist, sort_key, Kernel, Ray, Stack, Tri4Hit};
use super::watertight;

#[derive(Clone, Copy, Debug, Default)]
pub struct Portable;

impl Kernel for Portable {
    type D = [f32; 8];

    #[inline(always)]
    fn node(self, n: &Node8, r: &Ray, t_far: f32) -> (u32, [f32; 8]) {
        node_ray(n, r, t_far)
    }

    #[inline(always)]
    fn dist(self, d: &[f32; 8], lane: u32) -> f32 {
        d[lane as usize]
    }

    fn push_any(
        self,
        n: &Node8,
        mask: u32,
        d: [f32; 8],
        t_min: f32,
        s: &mut Stack,
        sp: &mut usize,
    ) -> u32 {
        // Each group last rank first, so that it is popped in rank order.
        let last_first = || {
            (0..8)
                .rev()
                .map(|r| n.any_slot(r))
                .filter(|k| mask >> k & 1 == 1)
        };
        for k in last_first().filter(|&k| d[k] <= t_min) {
            s.push(sp, n.child[k], 0.0);
        }
        for k in last_first().filter(|&k| d[k] > t_min) {
            s.push(sp, n.child[k], 0.0);
        }
        *sp -= 1;
        // SAFETY: pushed just above (`mask` has at least two children).
        unsafe { s.node.get_unchecked(*sp).assume_init() }
    }

    fn push_sorted(self, n: &Node8, mask: u32, d: [f32; 8], s: &mut Stack, sp: &mut usize) -> u32 {
        let mut keys = [0u32; 8];
        let mut count = 0;
        let mut m = mask;
        while m != 0 {
            let i = m.trailing_zeros();
            keys[count] = sort_key(d[i as usize], i);
            count += 1;
            m &= m - 1;
        }
        // Descending, as the AVX2 sorting network leaves them.
        keys[..count].sort_unstable_by(|a, b| b.cmp(a));
        for &key in &keys[..count - 1] {
            s.push(sp, n.child[(key & 7) as usize], key_dist(key));
        }
        n.child[(keys[count - 1] & 7) as usize]
    }

    #[inline(always)]
    fn tri4(self, b: &Tri4, _: &Ray, ray: &Ray, t_far: f32) -> Tri4Hit {
        tri4_scalar(b, ray, t_far)
    }

    #[inline(always)]
    fn refine(self, p: &mut [Pending], range: (f32, f32)) {
        for q in p {
            refine_one(q, range);
        }
    }
}

/// The portable node test.
#[inline(always)]
pub fn node_ray(n: &Node8, r: &Ray, t_far: f32) -> (u32, [f32; 8]) {
    let mut mask = 0;
    let mut t_in = [0.0; 8];
    #[allow(clippy::needless_range_loop)] // `i` indexes the node's rows as well
    for i in 0..8 {
        let slab = |a: usize| {
            (
                (n.b[r.near[a] / ROW_BYTES][i] - r.o[a]) * r.inv[a],
                (n.b[r.far[a] / ROW_BYTES][i] - r.o[a]) * r.inv_far[a],
            )
        };
        let ((x0, x1), (y0, y1), (z0, z1)) = (slab(0), slab(1), slab(2));
        // Pairwise, as the AVX2 kernel reduces (two steps of latency, not three).
        let near = max(max(x0, y0), max(z0, r.t_min));
        let far = min(min(x1, y1), min(z1, t_far));
        t_in[i] = near;
        mask |= u32::from(near <= far) << i;
    }
    (mask, t_in)
}

/// `_mm256_max_ps`'s rule (the second operand on ties), so both kernels agree bit for bit.
#[inline(always)]
fn max(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

#[inline(always)]
fn min(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// The scalar watertight test of each lane; AVX2 falls back to it too.
#[inline(always)]
pub fn tri4_scalar(b: &Tri4, ray: &Ray, t_far: f32) -> Tri4Hit {
    let mut h = Tri4Hit::NONE;
    for lane in 0..4 {
        if let Some(hit) = watertight::intersect(&b.tri(lane), ray.o, &ray.shear, ray.t_min, t_far)
        {
            h.mask |= 1 << lane;
            h.t[lane] = hit.t;
            [h.bu[lane], h.bv[lane]] = hit.b;
            h.det[lane] = hit.det;
        }
    }
    h
}
