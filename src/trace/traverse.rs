//! Traversal of the 8-wide BVH (`node`): the ray's constants, the kernels' interface, the
//! stack, and the loop every query runs.
//!
//! Traversal is depth first with a short stack. A node whose ray hits several children pushes
//! them sorted by entry distance (an 8-lane sorting network on AVX2) and descends into the
//! nearest; entries popped beyond the closest hit so far are skipped. The same loop serves every
//! query through a [`Sink`] (`sinks`): closest hit, any hit, the k nearest hits, crossings.
//! Any-hit rays may instead visit children in an order the builder fixed, the likeliest to stop
//! a ray for its cost first and the boxes around the ray's start last (`Kernel::push_any`).

use std::mem::MaybeUninit;

use glam::Vec3A;

use super::node::{
    leaf_blocks, leaf_first, node_at, node_offset, Bvh8, Instanced, Node8, Tri4, LEAF, ROW_BYTES,
    STACK,
};
use super::watertight::RayShear;

/// A ray's constants for traversal (its direction as given, not normalised).
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub o: Vec3A,
    /// The direction as given (a two-level tree moves it into each object's frame).
    pub d: Vec3A,
    pub inv: Vec3A,
    /// `inv` widened by [`WIDEN`]: exit distances computed with it come out a few ulps long.
    pub inv_far: Vec3A,
    /// Per axis, the byte offset in a `Node8` of the row of `b` holding each box's near plane,
    /// and of its far plane (see [`Node8::row`]).
    pub(crate) near: [usize; 3],
    pub(crate) far: [usize; 3],
    pub shear: RayShear,
    /// The origin in the shear's axis order (kx, ky, kz).
    pub o_k: [f32; 3],
    pub t_min: f32,
    /// 3 × the direction's octant (bit a set when component a is negative): where this ray's
    /// order lies in `Node8::order`.
    pub octant_shift: u32,
}

impl Ray {
    /// The ray from `o` along `d`, traced in units of `d`'s length (no normalisation: every
    /// test is invariant to the direction's scale, and the square root and divisions it would
    /// take sit at the head of every ray's dependency chain).
    #[inline(always)]
    pub fn new(o: Vec3A, d: Vec3A, t_min: f32) -> Self {
        // Components this small (relative to the largest) get a huge but finite inverse of the
        // same sign, so the slab products never meet 0 · inf.
        let tiny = Vec3A::splat(1e-20 * d.abs().max_element());
        let inv = Vec3A::ONE / Vec3A::select(d.abs().cmplt(tiny), tiny.copysign(d), d);
        let row = |a: usize| a + 3 * usize::from(inv[a] < 0.0);
        let near = std::array::from_fn(|a| ROW_BYTES * row(a));
        let shear = RayShear::with_inverse(d, inv);
        Self {
            o,
            d,
            inv,
            inv_far: inv * WIDEN,
            near,
            far: std::array::from_fn(|a| ROW_BYTES * ((row(a) + 3) % 6)),
            shear,
            o_k: shear.permute(o),
            t_min,
            octant_shift: 3 * (0..3).map(|a| u32::from(inv[a] < 0.0) << a).sum::<u32>(),
        }
    }
}

/// Boxes whose exit distance rounds to just below the entry distance are still entered: exits
/// are computed with the inverse direction widened by a few ulps (PBRT's 1 + 2γ₃; Embree's
/// robust mode does the same), so the f32 slab test never rejects a box the ray grazes, and
/// the watertight triangle test decides alone.
pub const WIDEN: f32 = 1.0 + 4.0 * f32::EPSILON;

/// Four triangles' test results: lanes hit within `[t_min, t_far)`, their `t` (+inf in the
/// other lanes), and for each lane the barycentric numerators and their common denominator
/// (barycentric (u, v) = (`bu / det`, `bv / det`)).
#[derive(Clone, Copy, Debug)]
pub struct Tri4Hit {
    pub mask: u32,
    pub t: [f32; 4],
    pub bu: [f32; 4],
    pub bv: [f32; 4],
    pub det: [f32; 4],
}

impl Tri4Hit {
    /// No lane hit.
    pub const NONE: Tri4Hit = Tri4Hit {
        mask: 0,
        t: [f32::INFINITY; 4],
        bu: [0.0; 4],
        bv: [0.0; 4],
        det: [1.0; 4],
    };
}

/// The arithmetic of traversal, one implementation per instruction set. Every implementation
/// gives bit-identical results (the portable one is the reference in the tests).
pub trait Kernel: Copy {
    /// Whether [`Kernel::packet`] traces packets.
    const PACKETS: bool = false;
    /// What a node test leaves for ordering the children it hit. (A ray's constants are read
    /// from its [`Ray`] where they are used: a broadcast load costs what reloading a spilled
    /// register would.)
    type D: Copy;
    /// The entry distance of child `lane` left by `node`.
    fn dist(self, d: &Self::D, lane: u32) -> f32;
    /// The children of `n` whose boxes the ray enters before `t_far`, as a bit mask.
    fn node(self, n: &Node8, r: &Ray, t_far: f32) -> (u32, Self::D);
    /// Push the children in `mask` (three or more) onto `s` above `sp`, farthest first (by
    /// entry distance); return the nearest, unpushed.
    fn push_sorted(self, n: &Node8, mask: u32, d: Self::D, s: &mut Stack, sp: &mut usize) -> u32;
    /// Push the children in `mask` (three or more; `descend` orders two by a compare, the same
    /// way, and the kernels take any two or more) for an any-hit query and return the first to
    /// visit, unpushed: the node's any-hit order ([`Node8::any_slot`]), with the boxes that hold
    /// the ray's start (entry distance `t_min`) below the rest. A shadow ray leaves a surface,
    /// which those boxes hold and which rarely blocks it. The entries' distances are 0: an any-hit
    /// query never shortens its range, so nothing on its stack is culled.
    fn push_any(
        self,
        n: &Node8,
        mask: u32,
        d: Self::D,
        t_min: f32,
        s: &mut Stack,
        sp: &mut usize,
    ) -> u32;
    /// The watertight test of a block's four triangles.
    fn tri4(self, b: &Tri4, r: &Ray, ray: &Ray, t_far: f32) -> Tri4Hit;
    /// Refine hits in f64 (`refine`), as `refine::refine_one` does one by one.
    fn refine(self, p: &mut [super::refine::Pending], range: (f32, f32));
    /// Trace eight coherent rays as one packet (lanes not in `active` are ignored), if this
    /// kernel can; false leaves them to be traced one by one.
    #[inline(always)]
    fn packet<L: Lanes>(
        self,
        _bvh: &Bvh8,
        _rays: &[Ray; WIDTH],
        _active: u32,
        _sinks: &mut L,
        _stack: &mut PacketStack,
    ) -> bool {
        false
    }
}

/// The traversal stack: node references with their entry distances (rounded down). Its height
/// lives in the traversal loop, in a register.
pub struct Stack {
    pub node: [MaybeUninit<u32>; STACK],
    pub dist: [MaybeUninit<f32>; STACK],
}

impl Default for Stack {
    fn default() -> Self {
        Self::new()
    }
}

impl Stack {
    #[inline(always)]
    pub fn new() -> Self {
        Self {
            node: [MaybeUninit::uninit(); STACK],
            dist: [MaybeUninit::uninit(); STACK],
        }
    }

    #[inline(always)]
    pub fn push(&mut self, sp: &mut usize, node: u32, dist: f32) {
        debug_assert!(*sp < STACK);
        // SAFETY: the builder bounds the tree's depth so the stack never exceeds STACK.
        unsafe {
            self.node.get_unchecked_mut(*sp).write(node);
            self.dist.get_unchecked_mut(*sp).write(dist);
        }
        *sp += 1;
    }

    /// The next entry whose box starts no farther than `t_far`, if any.
    #[inline(always)]
    pub(crate) fn pop(&self, sp: &mut usize, t_far: f32) -> Option<u32> {
        while *sp > 0 {
            *sp -= 1;
            // SAFETY: entries below `sp` were written by `push` or a kernel's `push_sorted` or
            // `push_any`.
            let (node, dist) = unsafe {
                (
                    self.node.get_unchecked(*sp).assume_init(),
                    self.dist.get_unchecked(*sp).assume_init(),
                )
            };
            if dist <= t_far {
                return Some(node);
            }
        }
        None
    }
}

/// How far before the object's box a moved origin stays (`Instance::ray_in`), relative to
/// the parameter where the ray enters the box: a few ulps of it, for the rounding of that
/// parameter.
const ENTRY_MARGIN: f32 = 1e-5;

impl super::node::Instance {
    /// The world ray `w` in this instance's frame, and the shift `s` of its parameter: the
    /// object-space ray `o' + u·d'` (`u >= 0`) meets what the world ray meets at `t = s + u`.
    ///
    /// The origin is first moved along the ray to where it enters the object's world box (a
    /// hair before: [`ENTRY_MARGIN`]; not back before `t_min`), then mapped by the f64 inverse
    /// and rounded once to f32; the direction is mapped by the f32 linear part. An origin far
    /// from the object (by `D`) would otherwise be rounded in the object's frame by ulps of `D`
    /// across the ray, not only along it as the world's watertight test rounds it: a mesh 1e5
    /// away missed 3% of the rays a flat tree of its posed corners found. Now the origin's error
    /// is a few ulps of the object's size, the direction's `2^-24·3·|M⁻¹|·|d|` (an f32 product
    /// of three terms), both relative to the object, as a flat tree's corners are rounded. Each
    /// reported hit is refined in f64 in the same frame (`Rays::pending`), so reported `t` and
    /// barycentrics are the exact pose's. Nothing of the object lies
    /// before its box, so `u` starts at 0 (distances in a frame are never negative, as the
    /// traversal's sort keys need).
    #[inline(always)]
    pub fn ray_in(&self, w: &Ray) -> (Ray, f32) {
        let (o, d, s) = self.frame_of(w);
        (Ray::new(o, d, 0.0), s)
    }

    /// [`Instance::ray_in`]'s origin, direction and shift, without the traversal's set-up of
    /// the ray (what a hit's refinement needs, `Rays::pending`).
    #[inline(always)]
    pub fn frame_of(&self, w: &Ray) -> (Vec3A, Vec3A, f32) {
        let (t0, t1) = ((self.lo - w.o) * w.inv, (self.hi - w.o) * w.inv);
        let entry = t0.min(t1).max_element();
        let s = (entry - ENTRY_MARGIN * entry.abs()).max(w.t_min);
        let near = w.o.as_dvec3() + f64::from(s) * w.d.as_dvec3();
        let o = self.to_object.transform_point3(near).as_vec3a();
        (o, self.linear * w.d, s)
    }
}

/// Rays in a packet (`packet`).
pub const WIDTH: usize = 8;

/// What each ray of a packet collects: one [`Sink`] per lane.
pub trait Lanes {
    /// Lane `lane`'s current bound: hits at or beyond it are not wanted.
    fn t_far(&self, lane: usize) -> f32;
    /// Trace lane `lane`'s `ray` alone through the subtree (or leaf) at `root`, giving its
    /// hits to the lane's sink: a packet's leaves and its hybrid switch. True when the lane
    /// needs no more.
    fn subtree<K: Kernel>(
        &mut self,
        k: K,
        bvh: &Bvh8,
        lane: usize,
        ray: &Ray,
        root: u32,
        stack: &mut Stack,
    ) -> bool;
    /// Whether lane `lane`'s sink wants no more hits.
    fn done(&self, lane: usize) -> bool;
    /// The sink type of each lane.
    type Sink: Sink;
    /// The lanes' own sinks, where they are world sinks (a two-level tree's instance is entered
    /// as a packet only from them: `packet::instance`); none inside an instance's frame.
    fn sinks(&mut self) -> Option<&mut [Self::Sink; WIDTH]>;
}

impl<S: Sink> Lanes for [S; WIDTH] {
    #[inline(always)]
    fn t_far(&self, lane: usize) -> f32 {
        self[lane].t_far()
    }

    #[inline(always)]
    fn done(&self, lane: usize) -> bool {
        self[lane].done()
    }

    type Sink = S;

    #[inline(always)]
    fn sinks(&mut self) -> Option<&mut [S; WIDTH]> {
        Some(self)
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
        let sink = &mut self[lane];
        let (mut cur, mut sp) = (root, 0usize);
        if let Some(inst) = &bvh.inst {
            // A node or leaf of a two-level tree's top tree: on from there as a lone ray would.
            let mut at = TwoLevel::new(ray);
            while let Some(next) = visit_two(k, bvh, inst, cur, &mut at, sink, stack, &mut sp) {
                cur = next;
            }
        } else {
            walk(k, bvh, root, ray, sink, stack);
        }
        sink.done()
    }
}

/// Whether `rays` (with directions `d`) can travel as one packet: their directions share an
/// octant (so they share each box's near and far planes), their origins lie within
/// `origin_extent` of each other on every axis, and their directions within about 14 degrees
/// (camera rays of neighbouring pixels do; shuffled or random rays do not, and go one by one).
#[inline(always)]
pub fn coherent(rays: &[Ray; WIDTH], d: &[Vec3A; WIDTH], origin_extent: f32) -> bool {
    // Octants first: rays in random order almost never share one, and then nothing else is
    // computed.
    let octant = rays[0].octant_shift;
    if rays.iter().any(|r| r.octant_shift != octant) {
        return false;
    }
    let (mut lo, mut hi) = (rays[0].o, rays[0].o);
    // Directions scaled to a largest component of 1: the spread of each component then
    // measures the angle between them, with no square root.
    let unit = |d: Vec3A| d / d.abs().max_element();
    let (mut dlo, mut dhi) = (unit(d[0]), unit(d[0]));
    for i in 1..WIDTH {
        (lo, hi) = (lo.min(rays[i].o), hi.max(rays[i].o));
        let u = unit(d[i]);
        (dlo, dhi) = (dlo.min(u), dhi.max(u));
    }
    (hi - lo).max_element() <= origin_extent && (dhi - dlo).max_element() <= 0.25
}

/// A packet's stack: node references with the lanes that entered them; and a single ray's, for
/// the lanes that leave the packet (`Lanes::subtree`).
pub struct PacketStack {
    pub node: [MaybeUninit<u32>; STACK],
    pub lanes: [MaybeUninit<u32>; STACK],
    pub single: Stack,
}

impl Default for PacketStack {
    fn default() -> Self {
        Self::new()
    }
}

impl PacketStack {
    #[inline(always)]
    pub fn new() -> Self {
        Self {
            node: [MaybeUninit::uninit(); STACK],
            lanes: [MaybeUninit::uninit(); STACK],
            single: Stack::new(),
        }
    }
}

/// Where hits go. `t_far` bounds the search (hits at or beyond it are not reported).
pub trait Sink {
    /// Whether children are visited strictly nearest first (closest hits), or in the builder's
    /// any-hit order (see [`Kernel::push_any`]).
    const ORDERED: bool = true;
    /// Whether the descent asks the cache for every child it enters (`prefetch_children`).
    const PREFETCH: bool = Self::ORDERED;
    /// Whether runs of coherent rays may travel as packets (`Kernel::packet`).
    const PACKETS: bool = true;
    /// Whether rays may be traced in turns where the tree is large (`interleave`; only for
    /// `PREFETCH` sinks: a turn finds the lines of the node it visits asked for already).
    const INTERLEAVE: bool = false;
    fn t_far(&self) -> f32;
    /// Take block `block`'s hits; return true to stop the traversal.
    fn take(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit) -> bool;
    /// Take the hits of block `block` of a two-level tree's objects (`bvh`), found through
    /// instance `inst` (`instances`): their `t` is the world ray's. Sinks that report where a
    /// hit lies or which triangle it is record the instance; the others take it as `take`.
    #[inline(always)]
    fn take_in(&mut self, bvh: &Bvh8, block: usize, h: &Tri4Hit, inst: u32) -> bool {
        let _ = inst;
        self.take(bvh, block, h)
    }
    /// Whether the sink wants no more hits: true once `take` has returned true (an any-hit
    /// query that has one). A packet's lane that went on alone reads it (`Lanes::subtree`), so
    /// every sink whose `take` can stop a traversal says so here too.
    #[inline(always)]
    fn done(&self) -> bool {
        false
    }
    /// A block worth testing before the traversal starts (see `sinks::AnyHit::hint`).
    #[inline(always)]
    fn hint(&self) -> Option<usize> {
        None
    }
    /// Note a visit: a node (`nodes` 1) or a leaf block (`blocks` 1). Nothing, but for the
    /// sinks that measure how much work a traversal order costs (`sinks::Counted`).
    #[inline(always)]
    fn count(&mut self, nodes: u32, blocks: u32) {
        let _ = (nodes, blocks);
    }
}

/// Visit the tree along `ray`, giving every leaf block's hits to `sink`. `stack` is scratch
/// space, reused from ray to ray.
#[inline(always)]
pub fn traverse<K: Kernel, S: Sink>(k: K, bvh: &Bvh8, ray: &Ray, sink: &mut S, stack: &mut Stack) {
    if let Some(inst) = &bvh.inst {
        return traverse_top(k, bvh, inst, ray, sink, stack);
    }
    let r = ray;
    // Not `Option::is_some_and` with a closure: a closure does not inherit the caller's target
    // features, and the block test's AVX2 intrinsics would become calls.
    if let Some(b) = sink.hint() {
        if block_stops(k, bvh, b, r, ray, sink) {
            return;
        }
    }
    walk(k, bvh, 0, ray, sink, stack);
}

/// Visit the subtree of the flat tree `bvh` at `root` (a node or a leaf) along `ray`, giving
/// every leaf block's hits to `sink`: a traversal, a packet's lane on its own, a lane inside an
/// instance's frame.
#[inline(always)]
pub(crate) fn walk<K: Kernel, S: Sink>(
    k: K,
    bvh: &Bvh8,
    root: u32,
    ray: &Ray,
    sink: &mut S,
    stack: &mut Stack,
) {
    let (mut cur, mut sp) = (root, 0usize);
    while let Some(next) = visit(k, bvh, cur, ray, ray, sink, stack, &mut sp) {
        cur = next;
    }
}

/// [`traverse`] on a two-level tree (`instances`), step by step ([`visit_two`]). Hints
/// (`Sink::hint`) name blocks of one frame and are not taken here.
#[inline(always)]
fn traverse_top<K: Kernel, S: Sink>(
    k: K,
    top: &Bvh8,
    inst: &Instanced,
    ray: &Ray,
    sink: &mut S,
    stack: &mut Stack,
) {
    let mut at = TwoLevel::new(ray);
    let (mut cur, mut sp) = (0u32, 0usize);
    while let Some(next) = visit_two(k, top, inst, cur, &mut at, sink, stack, &mut sp) {
        cur = next;
    }
}

/// Where a ray's traversal of a two-level tree is: in the top tree with the world ray, or in
/// an instance's subtree with the ray moved into that instance's frame. One stack serves both:
/// the entries at and above `base` are the instance's (their distances in its frame, the
/// world's less `shift`), those below the top tree's (world distances); `visit_two` culls each
/// by its own.
pub struct TwoLevel {
    pub world: Ray,
    /// The instance of `frame` (`u32::MAX` before any).
    pub inst: u32,
    /// The ray in `inst`'s frame (written when the first instance is entered), whose parameter
    /// is the world's less `shift` (`Instance::ray_in`).
    pub frame: MaybeUninit<Ray>,
    pub shift: f32,
    /// The stack height where the current instance's entries begin; `usize::MAX` in the top tree.
    pub base: usize,
}

impl TwoLevel {
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        Self {
            world: *ray,
            inst: u32::MAX,
            frame: MaybeUninit::uninit(),
            shift: 0.0,
            base: usize::MAX,
        }
    }
}

/// One step of a traversal of a two-level tree, as [`visit`] is of a flat one: a node of the
/// top tree (world ray), the entry into an instance (the ray moved into its frame, kept while
/// the next leaves are the same instance's: re-braided leaves of one instance often follow each
/// other), or a node or leaf of an instance's subtree (its blocks' hits go to
/// [`Sink::take_in`] with the instance).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn visit_two<K: Kernel, S: Sink>(
    k: K,
    top: &Bvh8,
    inst: &Instanced,
    cur: u32,
    at: &mut TwoLevel,
    sink: &mut S,
    stack: &mut Stack,
    sp: &mut usize,
) -> Option<u32> {
    let objects = &*inst.objects;
    let mut cur = cur;
    loop {
        // The tree and the ray of where the traversal is, by selects rather than a branch: a
        // ray that leaves and enters instances would make it a coin toss at every node.
        let inside = at.base != usize::MAX;
        // SAFETY: `base` is set (below) only once an instance was entered and `frame` written.
        let ray = if inside {
            unsafe { at.frame.assume_init_ref() }
        } else {
            &at.world
        };
        let tree = if inside { objects } else { top };
        // Distances in the instance's frame are the world's less its shift.
        let shift = if inside { at.shift } else { 0.0 };
        let t_far = sink.t_far() - shift;
        if cur & LEAF == 0 {
            sink.count(1, 0);
            let n = node_at(&tree.nodes, cur);
            let (mask, d) = k.node(n, ray, t_far);
            if mask != 0 {
                // Nothing is asked for in a two-level tree's top tree: it is small (it stays in the
                // cache), and its leaves name no blocks of its own, so their addresses would be
                // wild (a prefetch of an unmapped address never faults, but waits for the page
                // walk: 20% of a trace's time).
                let from = inside.then_some(objects);
                return Some(descend::<K, S>(k, from, n, mask, d, ray, stack, sp));
            }
        } else if inside {
            for b in leaf_blocks(cur) {
                sink.count(0, 1);
                debug_assert!(b < objects.blocks.len());
                // SAFETY: leaf references of the objects' tree index its blocks.
                let block = unsafe { objects.blocks.get_unchecked(b) };
                let mut h = k.tri4(block, ray, ray, sink.t_far() - shift);
                if h.mask != 0 {
                    for t in &mut h.t {
                        *t += shift;
                    }
                    if sink.take_in(objects, b, &h, at.inst) {
                        return None;
                    }
                }
            }
        } else {
            // Enter the instance, and visit its subtree's first node in the same step.
            // SAFETY: top leaves name one entry of `refs` each (`instances::pose`).
            let to = unsafe { *inst.refs.get_unchecked(leaf_first(cur)) };
            if to.inst != at.inst {
                at.inst = to.inst;
                let (frame, shift) = inst.instances[to.inst as usize].ray_in(&at.world);
                at.frame.write(frame);
                at.shift = shift;
            }
            at.base = *sp;
            cur = to.node;
            continue;
        }
        break;
    }
    // The next entry whose box starts no farther than the sink's bound, each entry's distance
    // in its own frame: the instance's above `base`, the world's below (where the traversal
    // returns to the top tree).
    let t_far = sink.t_far();
    while *sp > 0 {
        *sp -= 1;
        let inside = *sp >= at.base;
        // SAFETY: entries below `sp` were written by `push` or a kernel's push.
        let (node, dist) = unsafe {
            (
                stack.node.get_unchecked(*sp).assume_init(),
                stack.dist.get_unchecked(*sp).assume_init(),
            )
        };
        if !inside {
            at.base = usize::MAX;
        }
        if dist <= t_far - if inside { at.shift } else { 0.0 } {
            return Some(node);
        }
    }
    None
}

/// One step of a traversal: visit node or leaf `cur` and return the next to visit (a child
/// entered, or the stack's top), or `None` when the traversal has ended (the sink wants no
/// more, or the stack is spent). `traverse` loops over it; `interleave` takes one step per turn.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn visit<K: Kernel, S: Sink>(
    k: K,
    bvh: &Bvh8,
    cur: u32,
    r: &Ray,
    ray: &Ray,
    sink: &mut S,
    stack: &mut Stack,
    sp: &mut usize,
) -> Option<u32> {
    if cur & LEAF == 0 {
        sink.count(1, 0);
        let n = node_at(&bvh.nodes, cur);
        let (mask, d) = k.node(n, r, sink.t_far());
        if mask != 0 {
            return Some(descend::<K, S>(k, Some(bvh), n, mask, d, ray, stack, sp));
        }
    } else {
        for b in leaf_blocks(cur) {
            sink.count(0, 1);
            if block_stops(k, bvh, b, r, ray, sink) {
                return None;
            }
        }
    }
    stack.pop(sp, sink.t_far())
}

/// The child of `n` to visit next, of those in `mask` (not empty) that the ray enters, by the
/// order `S` asks for: the nearest, or the first in the any-hit order. The others are pushed
/// onto `stack` above `sp`, the last to visit first. Sinks that prefetch (`Sink::PREFETCH`) also
/// ask the cache for every child entered (`prefetch_children`), in `prefetch_from` (the tree
/// of `n`; none in a two-level tree's top tree).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn descend<K: Kernel, S: Sink>(
    k: K,
    prefetch_from: Option<&Bvh8>,
    n: &Node8,
    mask: u32,
    d: K::D,
    ray: &Ray,
    stack: &mut Stack,
    sp: &mut usize,
) -> u32 {
    if S::PREFETCH {
        if let Some(bvh) = prefetch_from {
            prefetch_children(bvh, n, mask);
        }
    }
    let first = mask.trailing_zeros();
    let rest = mask & (mask - 1);
    if rest == 0 {
        return n.child[first as usize];
    }
    if !S::ORDERED {
        if rest & (rest - 1) == 0 {
            // Two children: by a compare, as for closest hits (the vector push cost 3-9% more
            // on the occlusion rays of `bench rays`). A box around the start goes after one
            // that is not; otherwise the lower rank goes first.
            let second = rest.trailing_zeros();
            let (ca, cb) = (n.child[first as usize], n.child[second as usize]);
            let key = |lane: u32| {
                u32::from(k.dist(&d, lane) <= ray.t_min) << 3 | n.any_rank(lane as usize)
            };
            let (next, later) = if key(first) < key(second) {
                (ca, cb)
            } else {
                (cb, ca)
            };
            stack.push(sp, later, 0.0);
            return next;
        }
        return k.push_any(n, mask, d, ray.t_min, stack, sp);
    }
    if rest & (rest - 1) == 0 {
        // Two children: the nearer next, the other pushed. Both references are loaded before
        // the comparison, which then only selects.
        let second = rest.trailing_zeros();
        let (ca, cb) = (n.child[first as usize], n.child[second as usize]);
        let a = sort_key(k.dist(&d, first), first);
        let b = sort_key(k.dist(&d, second), second);
        let (near, far, far_key) = if a < b { (ca, cb, b) } else { (cb, ca, a) };
        stack.push(sp, far, key_dist(far_key));
        near
    } else {
        k.push_sorted(n, mask, d, stack, sp)
    }
}

/// Test block `b` and give its hits to `sink`; true when the sink wants no more.
#[inline(always)]
pub(crate) fn block_stops<K: Kernel, S: Sink>(
    k: K,
    bvh: &Bvh8,
    b: usize,
    r: &Ray,
    ray: &Ray,
    sink: &mut S,
) -> bool {
    debug_assert!(b < bvh.blocks.len());
    // SAFETY: leaf references index `blocks` (checked by the builder's tests), and hints are
    // blocks an earlier ray hit in this tree.
    let block = unsafe { bvh.blocks.get_unchecked(b) };
    let h = k.tri4(block, r, ray, sink.t_far());
    h.mask != 0 && sink.take(bvh, b, &h)
}

/// Ask the cache for what the children in `mask` will read: an inner child's four lines (boxes
/// and references), a leaf's first block. Embree's traversal prefetches its children the same
/// way. It pays where the tree outgrows the core's cache: a closest-hit ray pops most children
/// it pushes, and by then their lines are in (on the 1M-triangle spheres scene, shuffled and
/// incoherent rays ran 1.25–1.3× faster). Any-hit rays stop early and leave many pushed
/// children unread, but asking for them still paid (one thread, 400K incoherent occlusion
/// segments, AMD EPYC: 1.09-1.16x on `khr_toy_car` and `stanford_bunny`, 0.97-1.03x on the
/// shadow rays of a light), and it lets them go in turns on large trees.
#[inline(always)]
fn prefetch_children(bvh: &Bvh8, n: &Node8, mask: u32) {
    let mut m = mask;
    while m != 0 {
        let c = n.child[m.trailing_zeros() as usize];
        m &= m - 1;
        prefetch(bvh, c);
    }
}

/// Ask the cache for what visiting `c` (a reference of `bvh`, a flat tree or a two-level tree's
/// objects) will read first: an inner node's four lines, or its first block's.
#[inline(always)]
fn prefetch(bvh: &Bvh8, c: u32) {
    let nodes = bvh.nodes.as_ptr() as usize;
    let blocks = bvh.blocks.as_ptr() as usize;
    // Both addresses, then a select by mask arithmetic: a branch on inner or leaf would be a
    // coin toss for the predictor at every child.
    let inner = nodes.wrapping_add(node_offset(c));
    let leaf = blocks.wrapping_add(leaf_first(c) * size_of::<Tri4>());
    let is_leaf = ((c >> 31) as usize).wrapping_neg();
    let p = (inner ^ ((inner ^ leaf) & is_leaf)) as *const u8;
    for l in 0..4 {
        prefetch_line(p.wrapping_add(64 * l));
    }
}

/// Ask the cache for the line at `p`: a hint, which never faults, whatever the address (a
/// no-op off x86-64).
#[inline(always)]
pub(crate) fn prefetch_line<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch reads nothing and never faults.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>(p as *const i8);
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// A child's sort key: its entry distance's bits with the sign cleared (distances are never
/// negative, but may be −0) and the low three bits replaced by its slot. Keys order like the
/// distances, up to those three bits.
#[inline(always)]
pub fn sort_key(dist: f32, slot: u32) -> u32 {
    (dist.to_bits() & 0x7FFF_FFF8) | slot
}

/// The distance kept on the stack for a key: rounded down, so it never culls a box it should
/// enter.
#[inline(always)]
pub fn key_dist(key: u32) -> f32 {
    f32::from_bits(key & 0x7FFF_FFF8)
}
