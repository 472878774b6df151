//! What every query shares: the tree, the rays and their range, set up for traversal, and the
//! loop that traces a range of them: as packets where eight in a row are coherent, one by one,
//! or several in turns (`interleave`) where the tree outgrows the cache.

use std::ops::Range;

use glam::{Vec3, Vec3A};

use super::interleave::{self, Flights};
use super::node::Bvh8;
use super::query::Query;
use super::refine::{self, Pending};
use super::sinks::BlockHit;
use super::traverse::{coherent, traverse, Kernel, PacketStack, Ray, Sink, Stack, WIDTH};

/// What every query shares: the tree, the rays and the range.
pub(crate) struct Rays<'a> {
    pub bvh: &'a Bvh8,
    pub origins: &'a [[f32; 3]],
    pub directions: &'a [[f32; 3]],
    pub range: (f32, f32),
    /// How far apart the origins of a packet's rays may lie (`traverse::coherent`).
    pub origin_extent: f32,
    /// Whether closest-hit rays that do not travel as packets are traced in turns
    /// (`interleave`): where the tree (a two-level tree's objects' trees included) is larger
    /// than [`INTERLEAVE_BYTES`].
    pub interleave: bool,
}

/// Trees larger than this trace their closest-hit rays in turns (`interleave`), on x86-64 (where
/// the traversal asks the cache for nodes ahead). One thread, 786K incoherent rays, 8 flights
/// against one ray at a time, interleaved rounds: `khr_metal_rough_spheres_notex` (60 MB) 1.58x,
/// `scenes.shapes(detail=5)` (24 MB) 1.2-1.3x, `shapes(detail=4)` (7.6 MB) 1.07-1.12x,
/// `khr_toy_car` (6.5 MB) 0.95-1.01x.
pub const INTERLEAVE_BYTES: usize = 8 << 20;

impl<'a> Rays<'a> {
    pub fn new(
        bvh: &'a Bvh8,
        origins: &'a [[f32; 3]],
        directions: &'a [[f32; 3]],
        q: &Query,
    ) -> Self {
        Self {
            bvh,
            origins,
            directions,
            range: (q.t_min, q.t_max),
            origin_extent: 0.05 * bvh.diagonal(),
            interleave: cfg!(target_arch = "x86_64") && bvh.bytes() > INTERLEAVE_BYTES,
        }
    }
}

/// Traversal stacks and a group of rays, kept from ray to ray.
pub(crate) struct Scratch<S> {
    single: Stack,
    packet: PacketStack,
    /// The group of [`WIDTH`] rays being traced, and their directions as given.
    rays: [Ray; WIDTH],
    dirs: [Vec3A; WIDTH],
    /// Rays left to trace in turns (`Rays::trace`), and the flights that trace them.
    lone: Vec<u32>,
    flights: Flights<S>,
}

impl<S> Scratch<S> {
    pub fn new() -> Self {
        let none = Ray::new(Vec3A::ZERO, Vec3A::X, 0.0);
        Self {
            single: Stack::new(),
            packet: PacketStack::new(),
            rays: [none; WIDTH],
            dirs: [Vec3A::X; WIDTH],
            lone: Vec::new(),
            flights: Flights::default(),
        }
    }
}

/// One ray in traversal form.
#[derive(Clone, Copy)]
pub(crate) struct Traced {
    pub d: Vec3A,
    pub ray: Ray,
    pub t_far: f32,
}

impl Rays<'_> {
    /// Trace rays `base + j` for `j` in `range`, each into a fresh sink `sink(j)`, handed to
    /// `done(j, sink)` (not necessarily in order). Runs of eight coherent rays go as packets
    /// where the kernel and the sink can; the others one by one, or in turns (`interleave`)
    /// where the tree is large and the sink allows it ([`Sink::INTERLEAVE`]).
    ///
    /// Rays are set up in place, in `scratch`, by a plain loop: built with `array::from_fn`
    /// and copied into the packet's arrays, the setup of a group was a call the compiler did
    /// not inline (so compiled without AVX2) plus two copies of 1 KB, and took 40% of the time
    /// of rays that miss the scene (786K rays that miss `khr_glass_vase_flowers`: 72 -> 39 ms;
    /// its incoherent rays, which mostly hit, 3-5% faster against embreex).
    #[inline(always)]
    pub fn trace<K: Kernel, S: Sink + Copy>(
        &self,
        k: K,
        base: usize,
        range: Range<usize>,
        scratch: &mut Scratch<S>,
        sink: impl Fn(usize) -> S,
        mut done: impl FnMut(usize, S),
    ) {
        let turns = S::INTERLEAVE && self.interleave;
        scratch.lone.clear();
        let mut j = range.start;
        while j < range.end {
            if K::PACKETS && S::PACKETS && j + WIDTH <= range.end {
                for i in 0..WIDTH {
                    (scratch.rays[i], scratch.dirs[i]) = self.traversal_ray(base + j + i);
                }
                if coherent(&scratch.rays, &scratch.dirs, self.origin_extent) {
                    let mut sinks: [S; WIDTH] = std::array::from_fn(|i| sink(j + i));
                    let all = (1 << WIDTH) - 1;
                    if k.packet(
                        self.bvh,
                        &scratch.rays,
                        all,
                        &mut sinks,
                        &mut scratch.packet,
                    ) {
                        for (i, s) in sinks.into_iter().enumerate() {
                            done(j + i, s);
                        }
                        j += WIDTH;
                        continue;
                    }
                }
                if turns {
                    scratch.lone.extend(j as u32..(j + WIDTH) as u32);
                } else {
                    for i in 0..WIDTH {
                        let mut s = sink(j + i);
                        traverse(k, self.bvh, &scratch.rays[i], &mut s, &mut scratch.single);
                        done(j + i, s);
                    }
                }
                j += WIDTH;
                continue;
            }
            if turns {
                scratch.lone.push(j as u32);
            } else {
                let (ray, _) = self.traversal_ray(base + j);
                let mut s = sink(j);
                traverse(k, self.bvh, &ray, &mut s, &mut scratch.single);
                done(j, s);
            }
            j += 1;
        }
        if !scratch.lone.is_empty() {
            let lone = &scratch.lone;
            interleave::traverse(
                k,
                self.bvh,
                0..lone.len(),
                &mut scratch.flights,
                #[inline(always)]
                |i| {
                    let j = lone[i] as usize;
                    (self.traversal_ray(base + j).0, sink(j))
                },
                #[inline(always)]
                |i, s| done(lone[i] as usize, s),
            );
        }
    }

    /// Ray `i` as given: origin and direction.
    #[inline(always)]
    pub fn input(&self, i: usize) -> (Vec3A, Vec3A) {
        (
            Vec3A::from(Vec3::from(self.origins[i])),
            Vec3A::from(Vec3::from(self.directions[i])),
        )
    }

    /// Ray `i` set up for traversal, and its direction as given.
    #[inline(always)]
    pub fn traversal_ray(&self, i: usize) -> (Ray, Vec3A) {
        let (o, d) = self.input(i);
        (Ray::new(o, d, self.range.0), d)
    }

    #[inline(always)]
    pub fn ray(&self, i: usize) -> Traced {
        let (ray, d) = self.traversal_ray(i);
        Traced {
            d,
            ray,
            t_far: self.range.1,
        }
    }

    /// The world corners of the triangle `h` hit: its block's, or in a two-level tree its
    /// object's moved by its instance's transform.
    #[inline(always)]
    pub fn corners(&self, h: &BlockHit) -> [[f32; 3]; 3] {
        match &self.bvh.inst {
            None => self.bvh.blocks[h.block as usize].corners(h.lane as usize),
            Some(inst) => inst.world_corners(h.block, h.lane, h.inst),
        }
    }

    /// The range a batch of [`Rays::pending`] hits is refined with: the query's on a flat
    /// tree; on a two-level tree none, each hit's own being checked by [`Rays::settle`].
    #[inline(always)]
    pub fn refine_range(&self) -> (f32, f32) {
        match self.bvh.inst {
            None => self.range,
            Some(_) => (f32::NEG_INFINITY, f32::INFINITY),
        }
    }

    /// Hit `h` of ray `i` ready for the f64 refinement, and the shift of its parameter: on a
    /// flat tree the world triangle and the ray as given (shift 0); on a two-level tree the
    /// object's own triangle and the ray in its instance's frame (`Instance::ray_in`), so that
    /// a hit is refined on the exact pose, as it was found (the posed scene's f32 vertices are
    /// that pose rounded).
    #[inline(always)]
    pub fn pending(&self, i: usize, h: &BlockHit) -> (Pending, f32) {
        match &self.bvh.inst {
            None => (
                Pending {
                    v: self.bvh.blocks[h.block as usize].corners(h.lane as usize),
                    o: self.origins[i],
                    d: self.directions[i],
                    t: h.t,
                    bary: h.bary(),
                },
                0.0,
            ),
            Some(inst) => {
                let (ray, _) = self.traversal_ray(i);
                let (o, d, s) = inst.instances[h.inst as usize].frame_of(&ray);
                let p = Pending {
                    v: inst.objects.blocks[h.block as usize].corners(h.lane as usize),
                    o: o.to_array(),
                    d: d.to_array(),
                    t: h.t - s,
                    bary: h.bary(),
                };
                (p, s)
            }
        }
    }

    /// A refined hit `p` of [`Rays::pending`] (with its shift `s`) in the world: its `t`
    /// shifted back, or, where that leaves the query's range, the hit as found (`h`).
    #[inline(always)]
    pub fn settle(&self, p: &Pending, s: f32, h: &BlockHit) -> (f32, [f32; 2]) {
        if s == 0.0 && self.bvh.inst.is_none() {
            return (p.t, p.bary);
        }
        let t = p.t + s;
        if t >= self.range.0 && t < self.range.1 {
            (t, p.bary)
        } else {
            (h.t, h.bary())
        }
    }

    /// The hit in the caller's units, refined in f64.
    #[inline(always)]
    pub fn report(&self, i: usize, h: &BlockHit) -> Hit {
        let (mut p, s) = self.pending(i, h);
        refine::refine_one(&mut p, self.refine_range());
        let (t, bary) = self.settle(&p, s, h);
        Hit {
            t,
            triangle: h.triangle,
            bary,
        }
    }
}

/// A reported hit, in the caller's units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Hit {
    pub t: f32,
    pub triangle: u32,
    pub bary: [f32; 2],
}
