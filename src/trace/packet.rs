//! Eight coherent rays traversed together, one per AVX2 lane (ray packets: Wald, Slusallek,
//! Benthin and Wagner, "Interactive Rendering with Coherent Ray Tracing", 2001), visiting each
//! node's children in the octant order of Fuetterling et al. 2017 that all eight rays share.
//!
//! A single ray's traversal is one long chain of dependent loads and compares; eight rays in
//! the lanes of one register share that chain's latency, one node fetch and one stack. Each
//! lane's box test is the single-ray test's arithmetic, and leaves are tested ray by ray with
//! the single-ray kernel, so a packet reports exactly the hits its rays would report alone (the
//! closest-hit tie-break, `BlockHit::before`, does not depend on the visiting order).
//!
//! At each node the packet's interval bounds ([`Frustum`], Overbeck et al. 2008) first cull, for
//! all eight children at once, the boxes no lane can enter; only the rest get the lane-by-lane
//! test (on camera rays of the tiled bunny, 79% of the children are culled this way). Below a
//! node that at most [`SWITCH`] lanes enter, each goes on alone with the single-ray traversal
//! (Embree's hybrid mode switches the same way): 74% of those rays finish alone.
//!
//! On a two-level tree (a rigid pose), the packet traverses the top tree, and the lanes that
//! reach an instance together enter it together ([`instance`]): each moved into the object's
//! frame as a lone ray would be, then one packet through the object's subtree, whose sinks see
//! the frame's distances (`traverse::InFrame`). Posed 2M-triangle tilings, camera rays, one
//! thread: 0.50-0.66x the flat tree's time before, 0.75-0.80x with packets.

use std::arch::x86_64::*;

use glam::Vec3A;

use super::node::{leaf_first, node_at, Bvh8, Node8, EMPTY, LEAF, STACK};
use super::token::Avx2;
use super::traverse::{
    coherent, walk, Kernel, Lanes, PacketStack, Ray, Sink, Stack, Tri4Hit, WIDTH,
};

/// A packet's lanes go on alone below a node that at most this many of them enter (Embree's
/// hybrid traversal switches the same way): the packet tests each child's box for all eight
/// lanes, a lone ray all eight boxes at once.
const SWITCH: u32 = 4;

/// Traverse `bvh` from its node `root` with the eight `rays` (lanes not in `active` hold copies
/// and are ignored), giving each lane's leaf hits to `sinks`. In a two-level tree's top tree,
/// the lanes that reach an instance enter it together where they can ([`instance`]).
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
    root: u32,
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
        let frustum = Frustum::of(o, inv, inv_far, t_min);
        let mut t_far: [f32; WIDTH] = std::array::from_fn(|lane| sinks.t_far(lane));
        let mut sp = 0usize;
        let (mut cur, mut mask) = (root, active);
        'visit: loop {
            let many = mask.count_ones() > SWITCH;
            if cur & LEAF != 0 && many && entered(k, bvh, rays, cur, mask, sinks) {
                // The lanes entered the instance as a packet: each lane's bound follows its sink.
                follow(sinks, mask, &mut active, &mut t_far);
            } else if cur & LEAF != 0 || !many {
                // A leaf, or too few lanes left for a packet to pay: each lane goes on alone
                // (at a leaf, the single-ray test of its blocks, ray by ray).
                alone(
                    k,
                    bvh,
                    rays,
                    (cur, mask),
                    &mut active,
                    sinks,
                    &mut t_far,
                    stack,
                );
            } else {
                let n = node_at(&bvh.nodes, cur);
                let t_far_v = _mm256_loadu_ps(t_far.as_ptr());
                // The children some lane may enter; only those get the lane-by-lane test below.
                let candidates = match &frustum {
                    Some(f) => f.children(n, near, far, t_far_v),
                    None => 0xFF,
                };
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
                    if candidates >> slot & 1 == 0 {
                        continue;
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
            }
            match pop(stack, &mut sp, active) {
                Some(next) => (cur, mask) = next,
                None => return,
            }
        }
    }
}

/// Whether the lanes `mask` at `leaf` entered a two-level tree's instance as one packet
/// ([`instance`]; only world lanes can, see `Lanes::sinks`).
#[inline(always)]
fn entered<L: Lanes>(
    k: Avx2,
    bvh: &Bvh8,
    rays: &[Ray; WIDTH],
    leaf: u32,
    mask: u32,
    lanes: &mut L,
) -> bool {
    match lanes.sinks() {
        Some(sinks) if bvh.inst.is_some() => instance(k, bvh, rays, leaf, mask, sinks),
        _ => false,
    }
}

/// After lanes `mask` traced on elsewhere: each one's bound follows its sink, and a lane whose
/// sink is done leaves `active`.
#[inline(always)]
fn follow<L: Lanes>(sinks: &L, mask: u32, active: &mut u32, t_far: &mut [f32; WIDTH]) {
    let mut m = mask;
    while m != 0 {
        let lane = m.trailing_zeros() as usize;
        m &= m - 1;
        t_far[lane] = sinks.t_far(lane);
        if sinks.done(lane) {
            *active &= !(1 << lane);
        }
    }
}

/// The lanes `mask` of `rays` at `leaf` of a two-level tree's top tree `top`, entering its
/// instance as one packet: each lane moved into the instance's frame as a lone ray would be
/// (`Instance::ray_in`), then traversed from the instance's subtree as a packet whose sinks see
/// the frame's distances ([`InFrame`]). False, with nothing traced, where `top` is not a
/// two-level tree or the moved lanes do not make a packet (their directions must share an
/// octant).
#[inline(always)]
fn instance<S: Sink>(
    k: Avx2,
    top: &Bvh8,
    rays: &[Ray; WIDTH],
    leaf: u32,
    mask: u32,
    sinks: &mut [S; WIDTH],
) -> bool {
    let Some(inst) = &top.inst else {
        return false;
    };
    // SAFETY: top leaves name one entry of `refs` each (`instances::pose`).
    let to = unsafe { *inst.refs.get_unchecked(leaf_first(leaf)) };
    let instance = &inst.instances[to.inst as usize];
    // Lanes outside `mask` copy the first lane of it.
    let first = mask.trailing_zeros() as usize;
    let mut frame = [rays[first]; WIDTH];
    let mut dirs = [Vec3A::ZERO; WIDTH];
    let mut shift = [0.0f32; WIDTH];
    for lane in 0..WIDTH {
        let from = if mask >> lane & 1 == 1 { lane } else { first };
        (frame[lane], shift[lane]) = instance.ray_in(&rays[from]);
        dirs[lane] = frame[lane].d;
    }
    // The moved origins lie where each lane enters the object's box, as far apart as the
    // packet's footprint there: only the directions need to agree (the bounds take the
    // origins' spread).
    if !coherent(&frame, &dirs, f32::INFINITY) {
        return false;
    }
    let mut lanes = InFrame {
        sinks,
        shift,
        inst: to.inst,
    };
    traverse(
        k,
        &inst.objects,
        &frame,
        mask,
        &mut lanes,
        &mut PacketStack::new(),
        to.node,
    );
    true
}

/// A world sink seen from inside an instance's frame, as `traverse::visit_two` treats it there: its
/// distances less the frame's `shift`, and its hits given back as the instance's
/// ([`Sink::take_in`], with the shift added back).
pub(crate) struct Shifted<'a, S> {
    pub sink: &'a mut S,
    pub shift: f32,
    pub inst: u32,
}

impl<S: Sink> Sink for Shifted<'_, S> {
    const ORDERED: bool = S::ORDERED;
    const PREFETCH: bool = S::PREFETCH;
    const PACKETS: bool = S::PACKETS;

    #[inline(always)]
    fn t_far(&self) -> f32 {
        self.sink.t_far() - self.shift
    }

    #[inline(always)]
    fn take(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit) -> bool {
        let mut h = *h;
        for t in &mut h.t {
            *t += self.shift;
        }
        self.sink.take_in(bvh, block, &h, self.inst)
    }

    #[inline(always)]
    fn done(&self) -> bool {
        self.sink.done()
    }

    #[inline(always)]
    fn count(&mut self, nodes: u32, blocks: u32) {
        self.sink.count(nodes, blocks)
    }
}

/// A packet's lanes inside one instance of a two-level tree (`packet::instance`): each lane's
/// sink is its world sink, [`Shifted`] by the lane's own shift into the frame.
pub(crate) struct InFrame<'a, S> {
    pub sinks: &'a mut [S; WIDTH],
    pub shift: [f32; WIDTH],
    pub inst: u32,
}

impl<S: Sink> Lanes for InFrame<'_, S> {
    type Sink = S;

    #[inline(always)]
    fn sinks(&mut self) -> Option<&mut [S; WIDTH]> {
        None
    }

    #[inline(always)]
    fn t_far(&self, lane: usize) -> f32 {
        self.sinks[lane].t_far() - self.shift[lane]
    }

    #[inline(always)]
    fn done(&self, lane: usize) -> bool {
        self.sinks[lane].done()
    }

    #[inline(always)]
    fn subtree<K: Kernel>(
        &mut self,
        k: K,
        bvh: &Bvh8,
        lane: usize,
        ray: &Ray,
        root: u32,
        stack: &mut Stack,
    ) -> bool {
        let mut sink = Shifted {
            sink: &mut self.sinks[lane],
            shift: self.shift[lane],
            inst: self.inst,
        };
        walk(k, bvh, root, ray, &mut sink, stack);
        sink.done()
    }
}

/// Pop the next entry of `stack` (height `sp`) that some lane of `active` still needs, with those
/// lanes; none when the stack is spent or every lane is done.
#[inline(always)]
fn pop(stack: &PacketStack, sp: &mut usize, active: u32) -> Option<(u32, u32)> {
    while *sp > 0 && active != 0 {
        *sp -= 1;
        // SAFETY: entries below the height were written by `traverse`.
        let m = unsafe { stack.lanes.get_unchecked(*sp).assume_init() } & active;
        if m != 0 {
            return Some((unsafe { stack.node.get_unchecked(*sp).assume_init() }, m));
        }
    }
    None
}

/// A packet's interval bounds (Overbeck, Ramamoorthi and Mark 2008, "Large Ray Packets for
/// Real-Time Whitted Ray Tracing", §3): per axis, the lanes' smallest and largest origin, inverse
/// direction and widened inverse, each spread over all eight lanes, and the smallest `t_min`.
pub(crate) struct Frustum {
    o: [[__m256; 3]; 2],
    inv: [[__m256; 3]; 2],
    inv_far: [[__m256; 3]; 2],
    t_min: __m256,
}

impl Frustum {
    /// The bounds of the lanes' origins `o`, inverses `inv` and `inv_far`, and `t_min`; none
    /// where an inverse is not finite (a direction component below about 1e-25, `Ray::new`):
    /// a product could then be 0 · inf.
    #[inline(always)]
    pub(crate) fn of(
        o: [__m256; 3],
        inv: [__m256; 3],
        inv_far: [__m256; 3],
        t_min: __m256,
    ) -> Option<Self> {
        // SAFETY: called only inside AVX2 code (`traverse`, the tests after detection).
        unsafe {
            macro_rules! bounds {
                ($v:expr) => {
                    [
                        [
                            spread::<false>($v[0]),
                            spread::<false>($v[1]),
                            spread::<false>($v[2]),
                        ],
                        [
                            spread::<true>($v[0]),
                            spread::<true>($v[1]),
                            spread::<true>($v[2]),
                        ],
                    ]
                };
            }
            let f = Self {
                o: bounds!(o),
                inv: bounds!(inv),
                inv_far: bounds!(inv_far),
                t_min: spread::<false>(t_min),
            };
            let (zero, mut big) = (_mm256_setzero_ps(), _mm256_setzero_ps());
            for a in 0..3 {
                for [lo, hi] in [f.inv, f.inv_far].map(|v| [v[0][a], v[1][a]]) {
                    big = _mm256_max_ps(big, _mm256_max_ps(hi, _mm256_sub_ps(zero, lo)));
                }
            }
            let finite = _mm256_cmp_ps::<_CMP_LE_OQ>(big, _mm256_set1_ps(f32::MAX));
            (_mm256_movemask_ps(finite) == 0xFF).then_some(f)
        }
    }

    /// The children of `n` that some lane may enter before its `t_far` (`near`, `far`: the
    /// rows of the packet's octant), as a bit mask by slot, all eight at once: a slab test of the
    /// bounds, whose entry distance is at most each lane's and whose exit at least each lane's.
    /// Each bound is the extreme of the four corner products `(plane - o) · inv`, which bound
    /// the product over the box of origins and inverses; rounding is monotonic, so they bound
    /// each lane's f32 products too.
    #[inline(always)]
    pub(crate) fn children(
        &self,
        n: &Node8,
        near: [usize; 3],
        far: [usize; 3],
        t_far: __m256,
    ) -> u32 {
        // SAFETY: AVX2 (see `of`); `near` and `far` are a ray's row offsets.
        unsafe {
            let (mut lo, mut hi) = (self.t_min, spread::<true>(t_far));
            for a in 0..3 {
                let (o_lo, o_hi) = (self.o[0][a], self.o[1][a]);
                let pn = _mm256_loadu_ps(n.row(near[a]).as_ptr());
                let pf = _mm256_loadu_ps(n.row(far[a]).as_ptr());
                let (n0, n1) = (_mm256_sub_ps(pn, o_hi), _mm256_sub_ps(pn, o_lo));
                let (f0, f1) = (_mm256_sub_ps(pf, o_hi), _mm256_sub_ps(pf, o_lo));
                let (i_lo, i_hi) = (self.inv[0][a], self.inv[1][a]);
                let (g_lo, g_hi) = (self.inv_far[0][a], self.inv_far[1][a]);
                let l = _mm256_min_ps(
                    _mm256_min_ps(_mm256_mul_ps(n0, i_lo), _mm256_mul_ps(n0, i_hi)),
                    _mm256_min_ps(_mm256_mul_ps(n1, i_lo), _mm256_mul_ps(n1, i_hi)),
                );
                let u = _mm256_max_ps(
                    _mm256_max_ps(_mm256_mul_ps(f0, g_lo), _mm256_mul_ps(f0, g_hi)),
                    _mm256_max_ps(_mm256_mul_ps(f1, g_lo), _mm256_mul_ps(f1, g_hi)),
                );
                (lo, hi) = (_mm256_max_ps(lo, l), _mm256_min_ps(hi, u));
            }
            _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(lo, hi)) as u32
        }
    }
}

/// Every lane of `v` set to the smallest of its lanes (`MAX`: the largest). (No closures here
/// or in its callers: a closure is not compiled for AVX2, and its intrinsics would be calls.)
#[inline(always)]
unsafe fn spread<const MAX: bool>(v: __m256) -> __m256 {
    // SAFETY: called only from `traverse`, inside AVX2 code.
    unsafe {
        macro_rules! pick {
            ($a:expr, $b:expr) => {
                if MAX {
                    _mm256_max_ps($a, $b)
                } else {
                    _mm256_min_ps($a, $b)
                }
            };
        }
        let v = pick!(v, _mm256_permute2f128_ps::<1>(v, v));
        let v = pick!(v, _mm256_shuffle_ps::<0b01_00_11_10>(v, v));
        pick!(v, _mm256_shuffle_ps::<0b10_11_00_01>(v, v))
    }
}

/// Trace each lane of `mask` alone through the subtree at `cur` ([`Lanes::subtree`]); a lane
/// whose sink is done leaves `active`, and each lane's `t_far` follows its sink.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn alone<S: Lanes>(
    k: Avx2,
    bvh: &Bvh8,
    rays: &[Ray; WIDTH],
    (cur, mask): (u32, u32),
    active: &mut u32,
    sinks: &mut S,
    t_far: &mut [f32; WIDTH],
    stack: &mut PacketStack,
) {
    let mut m = mask;
    while m != 0 {
        let lane = m.trailing_zeros() as usize;
        m &= m - 1;
        if sinks.subtree(k, bvh, lane, &rays[lane], cur, &mut stack.single) {
            *active &= !(1 << lane);
        }
        t_far[lane] = sinks.t_far(lane);
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3A;

    use super::*;

    /// A lane's own slab test of slot `slot`, as `traverse` does it lane by lane (scalar f32
    /// arithmetic rounds as the vector lanes do).
    fn enters(n: &Node8, r: &Ray, slot: usize, t_far: f32) -> bool {
        let (o, inv, inv_far) = (r.o.to_array(), r.inv.to_array(), r.inv_far.to_array());
        // SAFETY: a ray's row offsets.
        let plane = |off: usize| unsafe { n.row(off)[slot] };
        let near: [f32; 3] = std::array::from_fn(|a| (plane(r.near[a]) - o[a]) * inv[a]);
        let far: [f32; 3] = std::array::from_fn(|a| (plane(r.far[a]) - o[a]) * inv_far[a]);
        let t_in = near[0].max(near[1]).max(near[2].max(r.t_min));
        let t_out = far[0].min(far[1]).min(far[2].min(t_far));
        t_in <= t_out
    }

    /// The frustum keeps every child that some lane's own test enters: over random packets (a
    /// shared origin or scattered ones, narrow and wide cones, near-zero direction components)
    /// and random boxes, thin ones among them, the frustum culls often and wrongly never.
    #[test]
    fn the_frustum_keeps_every_child_a_lane_enters() {
        if Avx2::detect().is_none() {
            return;
        }
        let mut seed = 12_345u32;
        let mut uniform = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        let (mut kept, mut culled, mut packets) = (0u32, 0u32, 0u32);
        for round in 0..4000 {
            let cone = [0.02, 0.2, 0.6][round % 3];
            let scatter = [0.0, 0.0, 0.3][round / 3 % 3];
            let centre = Vec3A::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5) * 4.0;
            let mut axis = Vec3A::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5);
            if round % 7 == 0 {
                axis.x = 0.0;
            }
            let rays: [Ray; WIDTH] = std::array::from_fn(|_| {
                let jitter = Vec3A::new(uniform(), uniform(), uniform()) - 0.5;
                let spot = Vec3A::new(uniform(), uniform(), uniform()) - 0.5;
                let d = axis + jitter * cone;
                let d = Vec3A::select(d.abs().cmplt(Vec3A::splat(1e-3)), axis, d);
                Ray::new(centre + spot * scatter, d, uniform() * 0.1)
            });
            if rays.iter().any(|r| r.octant_shift != rays[0].octant_shift) {
                continue;
            }
            packets += 1;
            let mut n = Node8::EMPTY;
            for slot in 0..8 {
                // A box around a point ahead of the packet, from very thin to wide.
                let ahead = rays[0].o + rays[0].d * (uniform() * 8.0);
                let at = ahead + (Vec3A::new(uniform(), uniform(), uniform()) - 0.5) * 0.5;
                let half =
                    Vec3A::new(uniform(), uniform(), uniform()) * [1e-4, 0.05, 0.5][slot % 3];
                for a in 0..3 {
                    n.b[a][slot] = at[a] - half[a];
                    n.b[a + 3][slot] = at[a] + half[a];
                }
                n.child[slot] = slot as u32;
            }
            let t_far: [f32; WIDTH] = std::array::from_fn(|_| {
                if uniform() < 0.5 {
                    f32::INFINITY
                } else {
                    uniform() * 10.0
                }
            });
            // SAFETY: AVX2 was detected.
            let mask = unsafe {
                macro_rules! lanes {
                    ($($f:tt)+) => {
                        _mm256_setr_ps(
                            rays[0].$($f)+, rays[1].$($f)+, rays[2].$($f)+, rays[3].$($f)+,
                            rays[4].$($f)+, rays[5].$($f)+, rays[6].$($f)+, rays[7].$($f)+,
                        )
                    };
                }
                let f = Frustum::of(
                    [lanes!(o.x), lanes!(o.y), lanes!(o.z)],
                    [lanes!(inv.x), lanes!(inv.y), lanes!(inv.z)],
                    [lanes!(inv_far.x), lanes!(inv_far.y), lanes!(inv_far.z)],
                    lanes!(t_min),
                )
                .expect("finite inverses");
                f.children(
                    &n,
                    rays[0].near,
                    rays[0].far,
                    _mm256_loadu_ps(t_far.as_ptr()),
                )
            };
            for slot in 0..8 {
                let any = (0..WIDTH).any(|l| enters(&n, &rays[l], slot, t_far[l]));
                assert!(
                    !any || mask >> slot & 1 == 1,
                    "round {round}: slot {slot} culled"
                );
                kept += u32::from(any);
                culled += u32::from(mask >> slot & 1 == 0);
            }
        }
        assert!(
            packets > 1000 && kept > 1000 && culled > 1000,
            "{packets} {kept} {culled}"
        );
    }
}
