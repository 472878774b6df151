//! Eight coherent rays traversed together, one per AVX2 lane (ray packets: Wald, Slusallek,
//! Benthin and Wagner, "Interactive Rendering with Coherent Ray Tracing", 2001), visiting each
//! node's children in the octant order of Fuetterling et al. 2017 that all eight rays share.
//!
//! A single ray's traversal is one long chain of dependent loads and compares; eight rays in
//! the lanes of one register share that chain's latency, one node fetch and one stack. Each
//! lane's box test is the single-ray test's arithmetic, and leaves are tested ray by ray with
//! the single-ray kernel, so a packet reports exactly the hits its rays would report alone (the
//! closest-hit tie-break, `BlockHit::before`, does not depend on the visiting order).

use std::arch::x86_64::*;

use super::node::{leaf_blocks, node_at, Bvh8, EMPTY, LEAF, STACK};
use super::token::Avx2;
use super::traverse::{Kernel, Lanes, PacketStack, Ray, WIDTH};

/// Traverse `bvh` with the eight `rays` (lanes not in `active` hold copies and are ignored),
/// giving each lane's leaf hits to `sinks`.
///
/// # Safety
/// Must run inside a function compiled for AVX2 (the `Avx2` token proves the CPU has it).
#[inline(always)]
pub fn traverse<S: Lanes>(
    k: Avx2,
    bvh: &Bvh8,
    rays: &[Ray; WIDTH],
    mut active: u32,
    sinks: &mut S,
    stack: &mut PacketStack,
) {
    // SAFETY: `k` proves AVX2; every load reads a whole array of the right size.
    unsafe {
        macro_rules! lanes {
            ($($f:tt)+) => {
                _mm256_setr_ps(
                    rays[0].$($f)+, rays[1].$($f)+, rays[2].$($f)+, rays[3].$($f)+,
                    rays[4].$($f)+, rays[5].$($f)+, rays[6].$($f)+, rays[7].$($f)+,
                )
            };
        }
        let o = [lanes!(o.x), lanes!(o.y), lanes!(o.z)];
        let inv = [lanes!(inv.x), lanes!(inv.y), lanes!(inv.z)];
        let inv_far = [lanes!(inv_far.x), lanes!(inv_far.y), lanes!(inv_far.z)];
        let t_min = lanes!(t_min);
        let (near, far, shift) = (rays[0].near, rays[0].far, rays[0].octant_shift);
        let mut t_far = [0.0f32; WIDTH];
        for (lane, t) in t_far.iter_mut().enumerate() {
            *t = sinks.t_far(lane);
        }
        let mut sp = 0usize;
        let (mut cur, mut mask) = (0u32, active);
        'visit: loop {
            if cur & LEAF == 0 {
                let n = node_at(&bvh.nodes, cur);
                let t_far_v = _mm256_loadu_ps(t_far.as_ptr());
                // Children entered, by rank (nearest first for this octant).
                let mut entered = [(0u32, 0u32); 8];
                let mut count = 0;
                for rank in 0..8 {
                    let slot = (n.order[rank] >> shift) as usize & 7;
                    let child = n.child[slot];
                    if child == EMPTY {
                        // Empty slots come last in every order.
                        break;
                    }
                    macro_rules! slab {
                        ($a:expr) => {
                            (
                                _mm256_mul_ps(
                                    _mm256_sub_ps(_mm256_set1_ps(n.row(near[$a])[slot]), o[$a]),
                                    inv[$a],
                                ),
                                _mm256_mul_ps(
                                    _mm256_sub_ps(_mm256_set1_ps(n.row(far[$a])[slot]), o[$a]),
                                    inv_far[$a],
                                ),
                            )
                        };
                    }
                    let ((x0, x1), (y0, y1), (z0, z1)) = (slab!(0), slab!(1), slab!(2));
                    let t_in = _mm256_max_ps(_mm256_max_ps(x0, y0), _mm256_max_ps(z0, t_min));
                    let t_out = _mm256_min_ps(_mm256_min_ps(x1, y1), _mm256_min_ps(z1, t_far_v));
                    let m = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_in, t_out)) as u32;
                    entered[count] = (child, m & mask);
                    count += usize::from(m & mask != 0);
                }
                if count > 0 {
                    for &(child, m) in entered[1..count].iter().rev() {
                        debug_assert!(sp < STACK);
                        stack.node.get_unchecked_mut(sp).write(child);
                        stack.lanes.get_unchecked_mut(sp).write(m);
                        sp += 1;
                    }
                    (cur, mask) = entered[0];
                    continue 'visit;
                }
            } else {
                leaf(k, bvh, rays, (cur, mask), &mut active, sinks, &mut t_far);
            }
            // Pop the next entry some active lane still needs.
            loop {
                if sp == 0 || active == 0 {
                    return;
                }
                sp -= 1;
                let m = stack.lanes.get_unchecked(sp).assume_init() & active;
                if m != 0 {
                    (cur, mask) = (stack.node.get_unchecked(sp).assume_init(), m);
                    continue 'visit;
                }
            }
        }
    }
}

/// Test leaf `cur`'s triangles against each lane of `mask`, ray by ray with the single-ray
/// kernel; a lane whose sink is done leaves `active`, and each lane's `t_far` follows its
/// sink.
#[inline(always)]
fn leaf<S: Lanes>(
    k: Avx2,
    bvh: &Bvh8,
    rays: &[Ray; WIDTH],
    (cur, mask): (u32, u32),
    active: &mut u32,
    sinks: &mut S,
    t_far: &mut [f32; WIDTH],
) {
    let mut m = mask;
    while m != 0 {
        let lane = m.trailing_zeros() as usize;
        m &= m - 1;
        let ray = &rays[lane];
        for b in leaf_blocks(cur) {
            // SAFETY: a leaf's blocks are blocks of its BVH.
            let block = unsafe { bvh.blocks.get_unchecked(b) };
            let h = k.tri4(block, ray, ray, t_far[lane]);
            if h.mask != 0 && sinks.take(bvh, lane, b, &h) {
                *active &= !(1 << lane);
                break;
            }
        }
        t_far[lane] = sinks.t_far(lane);
    }
}
