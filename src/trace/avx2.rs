//! The AVX2 kernel: one 8-lane slab test per node, an 8-lane sorting network for the children
//! a ray enters, and the watertight test of four triangles at once. Its arithmetic is the
//! portable kernel's, operation for operation (no fused multiply-adds), so both give
//! bit-identical hits; it is only faster.
//!
//! Its methods are `#[inline(always)]` and must be inlined into a function compiled with
//! `#[target_feature(enable = "avx2")]` (see `trace::dispatch`); the [`Avx2`] token
//! (`token`), which only [`Avx2::detect`] makes, proves the CPU has the instructions.

use std::arch::x86_64::*;

use std::ops::{Add, Div, Mul, Sub};

use super::node::{Bvh8, Node8, Tri4, ANY_SHIFT, STACK};
use super::portable;
use super::refine::{self, moller_trumbore, Lane, Pending};
pub use super::token::Avx2;
use super::traverse::{Kernel, Lanes, PacketStack, Ray, Stack, Tri4Hit, WIDTH};

impl Kernel for Avx2 {
    const PACKETS: bool = true;

    /// Entry distances and the lanes hit.
    type D = (__m256, __m256);

    #[inline(always)]
    fn dist(self, (near, _): &Self::D, lane: u32) -> f32 {
        // SAFETY: AVX2 (the token). A permute, not a round trip through memory.
        unsafe {
            _mm256_cvtss_f32(_mm256_permutevar8x32_ps(
                *near,
                _mm256_set1_epi32(lane as i32),
            ))
        }
    }

    #[inline(always)]
    fn node(self, n: &Node8, r: &Ray, t_far: f32) -> (u32, Self::D) {
        // No closures here or below: a closure would not inherit the caller's AVX2 target
        // feature, and its intrinsics would become calls.
        macro_rules! slab {
            ($a:expr, $o:expr, $inv:expr, $inv_far:expr) => {{
                let o = _mm256_broadcast_ss(&$o);
                (
                    _mm256_mul_ps(
                        _mm256_sub_ps(_mm256_load_ps(n.row(r.near[$a]).as_ptr()), o),
                        _mm256_broadcast_ss(&$inv),
                    ),
                    _mm256_mul_ps(
                        _mm256_sub_ps(_mm256_load_ps(n.row(r.far[$a]).as_ptr()), o),
                        _mm256_broadcast_ss(&$inv_far),
                    ),
                )
            }};
        }
        unsafe {
            let (x0, x1) = slab!(0, r.o.x, r.inv.x, r.inv_far.x);
            let (y0, y1) = slab!(1, r.o.y, r.inv.y, r.inv_far.y);
            let (z0, z1) = slab!(2, r.o.z, r.inv.z, r.inv_far.z);
            let t_min = _mm256_broadcast_ss(&r.t_min);
            let near = _mm256_max_ps(_mm256_max_ps(x0, y0), _mm256_max_ps(z0, t_min));
            let far = _mm256_min_ps(
                _mm256_min_ps(x1, y1),
                _mm256_min_ps(z1, _mm256_set1_ps(t_far)),
            );
            let hit = _mm256_cmp_ps::<_CMP_LE_OQ>(near, far);
            (_mm256_movemask_ps(hit) as u32, (near, hit))
        }
    }

    #[inline(always)]
    fn push_any(
        self,
        n: &Node8,
        _: u32,
        (near, hit): Self::D,
        t_min: f32,
        s: &mut Stack,
        sp: &mut usize,
    ) -> u32 {
        unsafe {
            // The slots in the any-hit order, last first.
            let ranked = _mm256_srli_epi32::<{ ANY_SHIFT as i32 }>(_mm256_load_si256(
                n.order.as_ptr() as *const __m256i,
            ));
            let slots = _mm256_permutevar8x32_epi32(
                _mm256_and_si256(ranked, _mm256_set1_epi32(7)),
                _mm256_setr_epi32(7, 6, 5, 4, 3, 2, 1, 0),
            );
            let child = _mm256_permutevar8x32_epi32(
                _mm256_load_si256(n.child.as_ptr() as *const __m256i),
                slots,
            );
            let hit = _mm256_permutevar8x32_ps(hit, slots);
            let start = _mm256_cmp_ps::<_CMP_LE_OQ>(
                _mm256_permutevar8x32_ps(near, slots),
                _mm256_set1_ps(t_min),
            );
            let zero = _mm256_setzero_si256();
            debug_assert!(*sp + 16 <= STACK);
            // The boxes around the start at the bottom, then the rest; each group packed low.
            for group in [_mm256_and_ps(hit, start), _mm256_andnot_ps(start, hit)] {
                let m = _mm256_movemask_ps(group) as u32;
                let packed = _mm256_permutevar8x32_epi32(child, packed_lanes(m));
                _mm256_storeu_si256(s.node.as_mut_ptr().add(*sp) as *mut __m256i, packed);
                _mm256_storeu_si256(s.dist.as_mut_ptr().add(*sp) as *mut __m256i, zero);
                *sp += m.count_ones() as usize;
            }
            debug_assert!(*sp >= 2 && *sp + 8 <= STACK);
            *sp -= 1;
            s.node.get_unchecked(*sp).assume_init()
        }
    }

    #[inline(always)]
    fn push_sorted(
        self,
        n: &Node8,
        mask: u32,
        (near, hit): Self::D,
        s: &mut Stack,
        sp: &mut usize,
    ) -> u32 {
        unsafe {
            let slots = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
            let key_bits = _mm256_set1_epi32(KEY_BITS);
            let keys =
                _mm256_or_si256(_mm256_and_si256(_mm256_castps_si256(near), key_bits), slots);
            // Lanes not hit sort last.
            let keys = _mm256_blendv_epi8(_mm256_set1_epi32(-1), keys, _mm256_castps_si256(hit));
            let sorted = sort8_descending(keys);
            let child = _mm256_permutevar8x32_epi32(
                _mm256_load_si256(n.child.as_ptr() as *const __m256i),
                sorted,
            );
            let dist = _mm256_and_si256(sorted, key_bits);
            debug_assert!(*sp + 8 <= STACK);
            _mm256_storeu_si256(s.node.as_mut_ptr().add(*sp) as *mut __m256i, child);
            _mm256_storeu_si256(s.dist.as_mut_ptr().add(*sp) as *mut __m256i, dist);
            // Farthest at the bottom; the nearest (the last hit lane) is taken, not pushed.
            *sp += mask.count_ones() as usize - 1;
            s.node.get_unchecked(*sp).assume_init()
        }
    }

    #[inline(always)]
    fn packet<L: Lanes>(
        self,
        bvh: &Bvh8,
        rays: &[Ray; WIDTH],
        active: u32,
        sinks: &mut L,
        stack: &mut PacketStack,
    ) -> bool {
        super::packet::traverse(self, bvh, rays, active, sinks, stack, 0);
        true
    }

    #[inline(always)]
    fn refine(self, p: &mut [Pending], range: (f32, f32)) {
        let mut groups = p.chunks_exact_mut(4);
        for g in &mut groups {
            self.refine4(g, range);
        }
        for q in groups.into_remainder() {
            refine::refine_one(q, range);
        }
    }

    #[inline(always)]
    fn tri4(self, b: &Tri4, r: &Ray, ray: &Ray, t_far: f32) -> Tri4Hit {
        unsafe {
            let [kx, ky, kz] = r.shear.k;
            let sx = _mm_broadcast_ss(&r.shear.s[0]);
            let sy = _mm_broadcast_ss(&r.shear.s[1]);
            let sz = _mm_broadcast_ss(&r.shear.s[2]);
            let (ox, oy, oz) = (
                _mm_broadcast_ss(&r.o_k[0]),
                _mm_broadcast_ss(&r.o_k[1]),
                _mm_broadcast_ss(&r.o_k[2]),
            );
            // A corner relative to the origin, sheared so the ray runs along +z.
            macro_rules! corner {
                ($c:expr) => {{
                    let x = _mm_sub_ps(_mm_load_ps(b.v[$c][kx].as_ptr()), ox);
                    let y = _mm_sub_ps(_mm_load_ps(b.v[$c][ky].as_ptr()), oy);
                    let z = _mm_sub_ps(_mm_load_ps(b.v[$c][kz].as_ptr()), oz);
                    (
                        _mm_sub_ps(x, _mm_mul_ps(sx, z)),
                        _mm_sub_ps(y, _mm_mul_ps(sy, z)),
                        _mm_mul_ps(sz, z),
                    )
                }};
            }
            let ((ax, ay, az), (bx, by, bz), (cx, cy, cz)) = (corner!(0), corner!(1), corner!(2));
            let u = _mm_sub_ps(_mm_mul_ps(cx, by), _mm_mul_ps(cy, bx));
            let v = _mm_sub_ps(_mm_mul_ps(ax, cy), _mm_mul_ps(ay, cx));
            let w = _mm_sub_ps(_mm_mul_ps(bx, ay), _mm_mul_ps(by, ax));
            let zero = _mm_setzero_ps();
            // Not inside when two edge functions have opposite (nonzero) signs: an f32 edge
            // function may round to zero but never to the wrong sign. Unused lanes are NaN,
            // and min/max pass the NaN through (they return their second operand), so their
            // comparisons are false.
            let lo = _mm_min_ps(_mm_min_ps(u, v), w);
            let hi = _mm_max_ps(_mm_max_ps(u, v), w);
            let maybe = _mm_or_ps(_mm_cmpge_ps(lo, zero), _mm_cmple_ps(hi, zero));
            // Most blocks end here, before the depth and its division (as Embree's early out).
            if _mm_movemask_ps(maybe) == 0 {
                return Tri4Hit::NONE;
            }
            // A lane still in play with an edge function of zero: the scalar test redoes its
            // edge functions in f64, which may move it inside or out.
            let any_zero = _mm_and_ps(
                maybe,
                _mm_or_ps(_mm_cmpeq_ps(lo, zero), _mm_cmpeq_ps(hi, zero)),
            );
            if _mm_movemask_ps(any_zero) != 0 {
                return portable::tri4_scalar(b, ray, t_far);
            }
            // Three nonzero edge functions of one sign: inside, and their sum is nonzero.
            let inside = maybe;
            let det = _mm_add_ps(_mm_add_ps(u, v), w);
            let scaled = _mm_add_ps(
                _mm_add_ps(_mm_mul_ps(u, az), _mm_mul_ps(v, bz)),
                _mm_mul_ps(w, cz),
            );
            let t = _mm_div_ps(scaled, det);
            let in_range = _mm_and_ps(
                _mm_cmpge_ps(t, _mm_broadcast_ss(&r.t_min)),
                _mm_cmplt_ps(t, _mm_set1_ps(t_far)),
            );
            let ok = _mm_and_ps(inside, in_range);
            let mut h = Tri4Hit {
                mask: _mm_movemask_ps(ok) as u32,
                t: [0.0; 4],
                bu: [0.0; 4],
                bv: [0.0; 4],
                det: [0.0; 4],
            };
            if h.mask != 0 {
                _mm_storeu_ps(
                    h.t.as_mut_ptr(),
                    _mm_blendv_ps(_mm_set1_ps(f32::INFINITY), t, ok),
                );
                _mm_storeu_ps(h.bu.as_mut_ptr(), v);
                _mm_storeu_ps(h.bv.as_mut_ptr(), w);
                _mm_storeu_ps(h.det.as_mut_ptr(), det);
            }
            h
        }
    }
}

/// Four f64 lanes, for refining four hits at once. Made only inside `Avx2::refine`.
#[derive(Clone, Copy)]
struct F64x4(__m256d);

macro_rules! f64x4_op {
    ($tr:ident, $f:ident, $op:ident) => {
        impl $tr for F64x4 {
            type Output = F64x4;
            #[inline(always)]
            fn $f(self, o: F64x4) -> F64x4 {
                // SAFETY: values of this type exist only where AVX2 was detected.
                F64x4(unsafe { $op(self.0, o.0) })
            }
        }
    };
}
f64x4_op!(Add, add, _mm256_add_pd);
f64x4_op!(Sub, sub, _mm256_sub_pd);
f64x4_op!(Mul, mul, _mm256_mul_pd);
f64x4_op!(Div, div, _mm256_div_pd);
impl Lane for F64x4 {}

impl Avx2 {
    /// Four hits' f64 refinement at once, bit for bit the scalar `refine::refine_one`.
    #[inline(always)]
    fn refine4(self, p: &mut [Pending], range: (f32, f32)) {
        debug_assert_eq!(p.len(), 4);
        // SAFETY: AVX2 (the token).
        unsafe {
            macro_rules! lanes {
                ($($field:tt)+) => {
                    F64x4(_mm256_cvtps_pd(_mm_setr_ps(
                        p[0].$($field)+,
                        p[1].$($field)+,
                        p[2].$($field)+,
                        p[3].$($field)+,
                    )))
                };
            }
            let v = [
                [lanes!(v[0][0]), lanes!(v[0][1]), lanes!(v[0][2])],
                [lanes!(v[1][0]), lanes!(v[1][1]), lanes!(v[1][2])],
                [lanes!(v[2][0]), lanes!(v[2][1]), lanes!(v[2][2])],
            ];
            let o = [lanes!(o[0]), lanes!(o[1]), lanes!(o[2])];
            let d = [lanes!(d[0]), lanes!(d[1]), lanes!(d[2])];
            let r = moller_trumbore(v, o, d, F64x4(_mm256_set1_pd(1.0)));
            let mut out = [[0.0f64; 4]; 4];
            for (k, x) in r.iter().enumerate() {
                _mm256_storeu_pd(out[k].as_mut_ptr(), x.0);
            }
            for (i, q) in p.iter_mut().enumerate() {
                refine::accept(q, [out[0][i], out[1][i], out[2][i], out[3][i]], range);
            }
        }
    }
}

/// One layer of a sorting network: lane i meets lane `partner[i]`; the lanes set in `HI` keep
/// the larger value.
#[inline(always)]
unsafe fn layer<const HI: i32>(v: __m256i, partner: __m256i) -> __m256i {
    let q = _mm256_permutevar8x32_epi32(v, partner);
    _mm256_blend_epi32::<HI>(_mm256_min_epi32(v, q), _mm256_max_epi32(v, q))
}

/// Sort eight signed keys in descending order: Batcher's odd-even merge sort network (19
/// comparators in 6 layers), each layer one permute, min, max and blend.
#[inline(always)]
pub(crate) unsafe fn sort8_descending(v: __m256i) -> __m256i {
    let v = layer::<0x55>(v, _mm256_setr_epi32(1, 0, 3, 2, 5, 4, 7, 6));
    let v = layer::<0x33>(v, _mm256_setr_epi32(2, 3, 0, 1, 6, 7, 4, 5));
    let v = layer::<0x22>(v, _mm256_setr_epi32(0, 2, 1, 3, 4, 6, 5, 7));
    let v = layer::<0x0F>(v, _mm256_setr_epi32(4, 5, 6, 7, 0, 1, 2, 3));
    let v = layer::<0x0C>(v, _mm256_setr_epi32(0, 1, 4, 5, 2, 3, 6, 7));
    layer::<0x2A>(v, _mm256_setr_epi32(0, 2, 1, 4, 3, 6, 5, 7))
}

/// For each 8-bit mask, the indices of its set lanes packed low, a byte each.
static PACKED_LANES: [u64; 256] = {
    let mut table = [0u64; 256];
    let mut m = 0;
    while m < 256 {
        let (mut packed, mut count, mut lane) = (0u64, 0, 0);
        while lane < 8 {
            if m >> lane & 1 == 1 {
                packed |= (lane as u64) << (8 * count);
                count += 1;
            }
            lane += 1;
        }
        table[m] = packed;
        m += 1;
    }
    table
};

/// The permutation that moves the lanes set in `m` (8 bits) to the low lanes, in order.
#[inline(always)]
unsafe fn packed_lanes(m: u32) -> __m256i {
    debug_assert!(m < 256);
    _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(
        *PACKED_LANES.get_unchecked(m as usize) as i64
    ))
}

/// Keep only a distance's magnitude bits above the slot bits (see `traverse::sort_key`).
const KEY_BITS: i32 = 0x7FFF_FFF8;

#[cfg(test)]
mod tests {
    use super::*;

    #[target_feature(enable = "avx2")]
    unsafe fn sort(keys: [i32; 8]) -> [i32; 8] {
        let v = sort8_descending(_mm256_loadu_si256(keys.as_ptr() as *const __m256i));
        let mut out = [0i32; 8];
        _mm256_storeu_si256(out.as_mut_ptr() as *mut __m256i, v);
        out
    }

    #[target_feature(enable = "avx2")]
    unsafe fn push_any(
        k: Avx2,
        n: &Node8,
        mask: u32,
        near: [f32; 8],
        hit: [f32; 8],
        s: &mut Stack,
        sp: &mut usize,
    ) -> u32 {
        let d = (
            _mm256_loadu_ps(near.as_ptr()),
            _mm256_loadu_ps(hit.as_ptr()),
        );
        k.push_any(n, mask, d, 0.0, s, sp)
    }

    /// The AVX2 any-hit push leaves the stack as the portable one does, for every set of two or
    /// more children entered and every split between boxes around the start and the rest.
    #[test]
    fn push_any_matches_portable() {
        let Some(k) = Avx2::detect() else {
            return;
        };
        let mut node = Node8::EMPTY;
        node.child = std::array::from_fn(|i| 100 + i as u32);
        let mut seed = 1u32;
        for round in 0..64 {
            // A permutation of the slots as the any-hit order.
            let mut slots: [u32; 8] = std::array::from_fn(|i| i as u32);
            for i in (1..8).rev() {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                slots.swap(i, (seed >> 16) as usize % (i + 1));
            }
            node.set_any_order(slots);
            let start_mask = (round * 37) as u32 & 0xFF;
            let near: [f32; 8] =
                std::array::from_fn(|i| if start_mask >> i & 1 == 1 { 0.0 } else { 0.5 });
            for mask in (0u32..256).filter(|m| m.count_ones() >= 2) {
                let hit: [f32; 8] = std::array::from_fn(|i| {
                    f32::from_bits(if mask >> i & 1 == 1 { u32::MAX } else { 0 })
                });
                let (mut a, mut b) = (Stack::new(), Stack::new());
                let (mut sa, mut sb) = (3usize, 3usize);
                let first_a = portable::Portable.push_any(&node, mask, near, 0.0, &mut a, &mut sa);
                // SAFETY: AVX2 was detected (the token).
                let first_b = unsafe { push_any(k, &node, mask, near, hit, &mut b, &mut sb) };
                assert_eq!((first_a, sa), (first_b, sb), "mask {mask:08b}");
                for i in 3..sa {
                    // SAFETY: both pushes wrote entries 3..sa.
                    let (x, y) = unsafe { (a.node[i].assume_init(), b.node[i].assume_init()) };
                    assert_eq!(x, y, "mask {mask:08b}, entry {i}");
                }
            }
        }
    }

    /// The network sorts every 0/1 input (which proves it sorts everything, by the 0-1
    /// principle) and a few arbitrary ones.
    #[test]
    fn network_sorts_descending() {
        if Avx2::detect().is_none() {
            return;
        }
        let mut inputs: Vec<[i32; 8]> = (0..256)
            .map(|bits: i32| std::array::from_fn(|i| (bits >> i) & 1))
            .collect();
        inputs.push([5, -1, 7, 3, -1, 0, 9, 2]);
        inputs.push([i32::MAX, -1, 1 << 30, 8, 16, -1, -1, 24]);
        for keys in inputs {
            let mut want = keys;
            want.sort_unstable_by(|a, b| b.cmp(a));
            // SAFETY: AVX2 was detected above.
            assert_eq!(unsafe { sort(keys) }, want, "input {keys:?}");
        }
    }
}
