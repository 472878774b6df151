//! Several single rays traversed in turns on one core, each fetching its next node while the
//! others work: asynchronous memory access chaining (Kocberber, Falsafi and Grot, "Asynchronous
//! Memory Access Chaining", PVLDB 9(4), 2015), applied to BVH traversal.
//!
//! One ray's traversal is a chain of dependent loads: the next node's address comes out of the
//! current node's test. Where the tree outgrows the core's cache, each link waits for memory,
//! and the processor cannot run ahead into the next ray, because every node ends in branches it
//! mispredicts. Here up to [`FLIGHTS`] rays are in flight. Each turn visits one node (or one
//! leaf) of one ray, picks that ray's next node and moves on to the next ray. The node's lines
//! were asked for when the ray entered it (`descend` prefetches every child the ray enters),
//! so by the time the turn comes back, they have arrived. Only sinks that ask for every child
//! they enter ([`Sink::PREFETCH`]: closest and any hits) are traced in turns.
//!
//! Each ray visits exactly the nodes and blocks, in exactly the order, that
//! [`traverse::traverse`](super::traverse::traverse) would: only the interleaving differs, so every
//! query reports the same hits.

use super::node::Bvh8;
use super::traverse::{block_stops, visit, visit_two, Kernel, Ray, Sink, Stack, TwoLevel};

/// Rays in flight at once.
pub const FLIGHTS: usize = 8;

/// One ray in flight: its constants, its sink, the node it visits next and its stack's height
/// and place in [`Flights::stacks`].
pub struct Flight<S> {
    /// The ray and the kernel's constants (`world`, `r`), and on a two-level tree where its
    /// traversal is (`traverse::visit_two`).
    at: TwoLevel,
    sink: S,
    cur: u32,
    sp: usize,
    stack: usize,
    /// The ray's index in the range being traced.
    j: usize,
}

/// Scratch space for [`traverse`], reused from call to call: the flights, and a stack for each
/// (apart, so that a ray's flight is a few hundred bytes, not 4 KB more). Allocated on first
/// use.
pub struct Flights<S> {
    flights: Vec<Flight<S>>,
    stacks: Vec<Stack>,
}

impl<S> Default for Flights<S> {
    fn default() -> Self {
        Self {
            flights: Vec::new(),
            stacks: Vec::new(),
        }
    }
}

/// Trace rays `range`, [`FLIGHTS`] at a time in turns. `start(j)` gives ray `j` and a fresh sink;
/// `done(j, sink)` takes each ray's sink when its traversal ends (in the order they end, not
/// the order of `range`).
#[inline(always)]
pub fn traverse<K: Kernel, S: Sink + Copy>(
    k: K,
    bvh: &Bvh8,
    range: std::ops::Range<usize>,
    scratch: &mut Flights<S>,
    start: impl FnMut(usize) -> (Ray, S),
    done: impl FnMut(usize, S),
) {
    match bvh.inst {
        None => turns::<K, S, false>(k, bvh, range, scratch, start, done),
        Some(_) => turns::<K, S, true>(k, bvh, range, scratch, start, done),
    }
}

/// [`traverse`] on a flat tree, or on a two-level one (`TWO`).
#[inline(always)]
fn turns<K: Kernel, S: Sink + Copy, const TWO: bool>(
    k: K,
    bvh: &Bvh8,
    range: std::ops::Range<usize>,
    scratch: &mut Flights<S>,
    mut start: impl FnMut(usize) -> (Ray, S),
    mut done: impl FnMut(usize, S),
) {
    debug_assert!(
        S::PREFETCH,
        "only sinks that prefetch the children they enter go in turns"
    );
    let Flights { flights, stacks } = scratch;
    flights.clear();
    let mut next = range.start;
    if stacks.is_empty() {
        stacks.resize_with(FLIGHTS, Stack::new);
    }
    while flights.len() < FLIGHTS {
        match launch::<K, S, TWO>(k, bvh, &mut next, range.end, &mut start, &mut done) {
            Some((ray, sink, j)) => flights.push(Flight {
                at: TwoLevel::new(&ray),
                sink,
                cur: 0,
                sp: 0,
                stack: flights.len(),
                j,
            }),
            None => break,
        }
    }
    let mut i = 0;
    while !flights.is_empty() {
        if i >= flights.len() {
            i = 0;
        }
        // SAFETY: `i < flights.len()`, just checked, and every flight's `stack` is a distinct
        // index below FLIGHTS.
        let f = unsafe { flights.get_unchecked_mut(i) };
        let stack = unsafe { stacks.get_unchecked_mut(f.stack) };
        if step::<K, S, TWO>(k, bvh, f, stack) {
            // Ended: hand over its sink, then launch the next ray in its place, with the same
            // stack. The flight is rewritten where it lies: moving it (some 400 bytes) cost a
            // call to memcpy per ray.
            done(f.j, f.sink);
            match launch::<K, S, TWO>(k, bvh, &mut next, range.end, &mut start, &mut done) {
                Some((ray, sink, j)) => {
                    if TWO {
                        f.at = TwoLevel::new(&ray);
                    } else {
                        f.at.world = ray;
                    }
                    (f.sink, f.cur, f.sp, f.j) = (sink, 0, 0, j);
                }
                None => {
                    flights.swap_remove(i);
                    continue;
                }
            }
        }
        i += 1;
    }
}

/// The next ray that needs a traversal: its constants, its sink and its index. On a flat
/// tree, a ray whose sink's hint block stops it (`Sink::hint`) is done here, as
/// `traverse::traverse` would be. `None` when the rays up to `end` are spent.
#[inline(always)]
fn launch<K: Kernel, S: Sink, const TWO: bool>(
    k: K,
    bvh: &Bvh8,
    next: &mut usize,
    end: usize,
    start: &mut impl FnMut(usize) -> (Ray, S),
    done: &mut impl FnMut(usize, S),
) -> Option<(Ray, S, usize)> {
    while *next < end {
        let j = *next;
        *next += 1;
        let (ray, mut sink) = start(j);
        // No closure around the block test (see `traverse::traverse`).
        if !TWO {
            if let Some(b) = sink.hint() {
                if block_stops(k, bvh, b, &ray, &ray, &mut sink) {
                    done(j, sink);
                    continue;
                }
            }
        }
        return Some((ray, sink, j));
    }
    None
}

/// Visit `f`'s current node or leaf and pick its next node (`traverse::visit`; the next node's lines
/// were asked for when the ray entered it, in `descend`, and asking again as it is popped cost
/// more than it found); true when the ray's traversal has ended.
#[inline(always)]
fn step<K: Kernel, S: Sink, const TWO: bool>(
    k: K,
    bvh: &Bvh8,
    f: &mut Flight<S>,
    stack: &mut Stack,
) -> bool {
    let next = match (TWO, &bvh.inst) {
        (true, Some(inst)) => visit_two(
            k,
            bvh,
            inst,
            f.cur,
            &mut f.at,
            &mut f.sink,
            stack,
            &mut f.sp,
        ),
        _ => visit(
            k,
            bvh,
            f.cur,
            &f.at.world,
            &f.at.world,
            &mut f.sink,
            stack,
            &mut f.sp,
        ),
    };
    match next {
        Some(next) => {
            f.cur = next;
            false
        }
        None => true,
    }
}
