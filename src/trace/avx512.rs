//! The AVX-512 kernel: the AVX2 kernel's algorithms (one 8-lane slab test per node, the 8-lane
//! sorting network, four triangles at once, eight-ray packets), compiled for AVX-512 (F, VL, BW,
//! DQ, CD), with the any-hit push packing its children by `vpcompressd` instead of a table of
//! permutations. Its arithmetic is the AVX2 kernel's operation for operation (no fused
//! multiply-adds), so every kernel gives bit-identical hits.
//!
//! The vectors stay 256 bits wide, as an 8-wide tree's nodes are: AVX-512 gives them 32
//! registers instead of 16, mask registers for the compares, and the compress; a 512-bit slab
//! test (near and far planes in one register) measured no faster, and AMD's Zen 4 splits each
//! 512-bit operation in two. Methods are `#[inline(always)]` and must be inlined into a function
//! compiled with the AVX-512 target features (see `trace::dispatch`); the [`Avx512`] token
//! (`token`), which only [`Avx512::detect`] makes, proves the CPU has them.

use std::arch::x86_64::*;

use super::node::{Bvh8, Node8, Tri4, ANY_SHIFT, STACK};
use super::refine::Pending;
pub use super::token::Avx512;
use super::traverse::{Kernel, Lanes, PacketStack, Ray, Stack, Tri4Hit, WIDTH};

impl Kernel for Avx512 {
    const PACKETS: bool = true;

    /// Entry distances and the lanes hit (the AVX2 kernel's).
    type D = (__m256, __m256);

    #[inline(always)]
    fn dist(self, d: &Self::D, lane: u32) -> f32 {
        self.avx2().dist(d, lane)
    }

    #[inline(always)]
    fn node(self, n: &Node8, r: &Ray, t_far: f32) -> (u32, Self::D) {
        self.avx2().node(n, r, t_far)
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
        // SAFETY: AVX-512 (the token); the stack has room for eight more entries.
        unsafe {
            // The slots in the any-hit order, last first (as the AVX2 kernel's push).
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
            let entered =
                _mm256_movepi32_mask(_mm256_castps_si256(_mm256_permutevar8x32_ps(hit, slots)));
            let start = _mm256_cmp_ps_mask::<_CMP_LE_OQ>(
                _mm256_permutevar8x32_ps(near, slots),
                _mm256_set1_ps(t_min),
            );
            let zero = _mm256_setzero_si256();
            debug_assert!(*sp + 16 <= STACK);
            // The boxes around the start at the bottom, then the rest; each group packed low
            // (the register form of the compress: its memory form is slow on Zen 4).
            for m in [entered & start, entered & !start] {
                let packed = _mm256_maskz_compress_epi32(m, child);
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
    fn push_sorted(self, n: &Node8, mask: u32, d: Self::D, s: &mut Stack, sp: &mut usize) -> u32 {
        self.avx2().push_sorted(n, mask, d, s, sp)
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
        super::packet::traverse(self.avx2(), bvh, rays, active, sinks, stack, 0);
        true
    }

    #[inline(always)]
    fn refine(self, p: &mut [Pending], range: (f32, f32)) {
        self.avx2().refine(p, range)
    }

    #[inline(always)]
    fn tri4(self, b: &Tri4, r: &Ray, ray: &Ray, t_far: f32) -> Tri4Hit {
        self.avx2().tri4(b, r, ray, t_far)
    }
}

#[cfg(test)]
mod tests {
    use super::super::portable::Portable;
    use super::*;

    #[target_feature(enable = "avx2,avx512f,avx512vl,avx512bw,avx512dq,avx512cd")]
    unsafe fn push_any(
        k: Avx512,
        n: &Node8,
        near: [f32; 8],
        hit: [f32; 8],
        s: &mut Stack,
        sp: &mut usize,
    ) -> u32 {
        let d = (
            _mm256_loadu_ps(near.as_ptr()),
            _mm256_loadu_ps(hit.as_ptr()),
        );
        k.push_any(n, 0, d, 0.0, s, sp)
    }

    /// The AVX-512 any-hit push leaves the stack as the portable one does, for every set of two
    /// or more children entered and every split between boxes around the start and the rest.
    #[test]
    fn push_any_matches_portable() {
        let Some(k) = Avx512::detect() else {
            return;
        };
        let mut node = Node8::EMPTY;
        node.child = std::array::from_fn(|i| 100 + i as u32);
        let mut seed = 7u32;
        for round in 0..64 {
            let mut slots: [u32; 8] = std::array::from_fn(|i| i as u32);
            for i in (1..8).rev() {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                slots.swap(i, (seed >> 16) as usize % (i + 1));
            }
            node.set_any_order(slots);
            let start_mask = (round * 53) as u32 & 0xFF;
            let near: [f32; 8] =
                std::array::from_fn(|i| if start_mask >> i & 1 == 1 { 0.0 } else { 0.5 });
            for mask in (0u32..256).filter(|m| m.count_ones() >= 2) {
                let hit: [f32; 8] = std::array::from_fn(|i| {
                    f32::from_bits(if mask >> i & 1 == 1 { u32::MAX } else { 0 })
                });
                let (mut a, mut b) = (Stack::new(), Stack::new());
                let (mut sa, mut sb) = (3usize, 3usize);
                let first_a = Portable.push_any(&node, mask, near, 0.0, &mut a, &mut sa);
                // SAFETY: AVX-512 was detected (the token).
                let first_b = unsafe { push_any(k, &node, near, hit, &mut b, &mut sb) };
                assert_eq!((first_a, sa), (first_b, sb), "mask {mask:08b}");
                for i in 3..sa {
                    // SAFETY: both pushes wrote entries 3..sa.
                    let (x, y) = unsafe { (a.node[i].assume_init(), b.node[i].assume_init()) };
                    assert_eq!(x, y, "mask {mask:08b}, entry {i}");
                }
            }
        }
    }
}
