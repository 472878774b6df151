//! A view rendered from the visibility field (visibility-field.txt §4, Fig. 4): resample the
//! field along the camera's pixel rays to mark the cells they see, then rasterize only the
//! marked cells' triangles.
//!
//! Resampling: one pixel in every `subsample × subsample` block (the block's middle pixel,
//! `k·i + k/2` rounded down, at its centre) gives a line; where it crosses the uv and st rectangles gives (u, v, s, t)
//! (`Slab::line`). Without interpolation the sample holding that point is read; with it, its
//! neighbours too (§4.1): the 2 × 2 samples around (u, v) for `Uv`, around (s, t) for `St`, the
//! 16 around both for `UvSt` (always including the nearest). Every id stored there is marked.
//! In the paper's rule a pixel whose line runs from the st plane toward the uv plane, runs
//! parallel to either, or misses either rectangle marks nothing; several slabs add their marks.
//! The paper rasterizes the two projected planes in hardware to get (u, v, s, t) per pixel;
//! here the same linear intersection runs on the CPU.
//!
//! Conservative resampling (this package's, not the paper's): a slab answers a pixel only when
//! everything the pixel can see lies between its planes with no surface between the uv plane
//! and the near end ([`Slab::answers`]), and only when every sample read saw at most `trust`
//! cells; the other pixels are traced through the cell-sorted scene ([`trace_fallback`]) and
//! the cells they hit are marked: a camera no slab serves, or a sample that saw several cells,
//! leaves no hole; holes remain only where a cell smaller than a sample's beam slipped between
//! the rays of every sample read. Only trusted reads mark cells: an untrusted one's pixel is
//! answered elsewhere or traced.
//!
//! Rendering: the scene's faces are kept sorted by cell (`Cells::triangles`), so the marked
//! cells are ranges of faces, drawn as one draw call per run of consecutive marked cells on
//! the GPU ([`render_marked`]), or traced on the CPU, each ray meeting only the marked cells'
//! triangles ([`trace_sorted`]); [`draw_view`] does either.

use std::time::Instant;

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use crate::camera::{Camera, Projector};
use crate::discretize::conventional::{pixel_rays_f32_at, resolve_ids, TraceFrame};
use crate::discretize::raster_rule::settle_edges;
use crate::discretize::visibility_field::{clip_line, Field, Slab, SlabFrom};
use crate::discretize::{discretize_ranges, push_range};
use crate::error::Result;
use crate::input_err;
use crate::scene::adjacency::{EdgeNeighbours, NONE};
use crate::scene::Scene;
use crate::trace::Query;
use crate::types::DepthImages;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interpolate {
    None,
    Uv,
    St,
    UvSt,
}

impl Interpolate {
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "none" => Self::None,
            "uv" => Self::Uv,
            "st" => Self::St,
            "uv+st" => Self::UvSt,
            _ => return None,
        })
    }
}

/// How a view resamples the field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resampling {
    pub interpolate: Interpolate,
    /// Side of the pixel blocks that share one line (>= 1).
    pub subsample: u32,
    /// The scene's bounds: answer a pixel only from a slab whose answer is what the pixel sees
    /// ([`Slab::answers`]) and when every sample it reads (the one holding the line and its
    /// interpolation neighbours) hit at most `trust` cells (`n`: none overflowed; 1: all saw
    /// one cell each), and list the other pixels for the fallback. `None`: the paper's rule,
    /// every slab the line crosses the right way.
    pub conservative: Option<[DVec3; 2]>,
    pub trust: u32,
}

/// What resampling found.
#[derive(Debug, Clone, Default)]
pub struct Marks {
    pub marked: Vec<bool>,
    /// Pixels resampled (after subsampling).
    pub pixels: usize,
    /// Of those, how many no slab answers (their lines miss, or run the wrong way).
    pub outside: usize,
    /// Of those, how many only samples that hit more cells than trusted hold (conservative
    /// resampling only).
    pub overflowed: usize,
    /// The pixels (`y * width + x`) the field cannot answer: `outside` and `overflowed` ones
    /// (conservative resampling only).
    pub fallback: Vec<usize>,
}

/// Why the field did not answer a pixel's line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Answer {
    /// Slabs hold the line, but each reads a sample that hit more cells than trusted.
    Overflowed,
    /// No slab holds the line.
    Outside,
}

/// Sample indices along one axis for the continuous coordinate `x` in [0, 1) over `n` samples:
/// the nearest only, or the two around it (the nearest among them).
fn around(x: f64, n: u32, both: bool) -> ([u32; 2], usize) {
    let last = n as i64 - 1;
    let f = x * n as f64;
    let nearest = (f.floor() as i64).clamp(0, last) as u32;
    if !both {
        return ([nearest, nearest], 1);
    }
    let i0 = (f - 0.5).floor() as i64;
    let a = i0.clamp(0, last) as u32;
    let b = (i0 + 1).clamp(0, last) as u32;
    if a == b {
        ([a, a], 1)
    } else {
        ([a, b], 2)
    }
}

/// Sample index of (iu, iv, is, it) in a field of dimensions `dims`.
fn sample_index([_, dv, ds, dt]: [u32; 4], [iu, iv, is, it]: [u32; 4]) -> usize {
    let d = |x: u32| x as usize;
    ((d(iu) * d(dv) + d(iv)) * d(ds) + d(is)) * d(dt) + d(it)
}

/// A slab's field as resampling reads it, borrowed (a view reads the arrays it is given in
/// place: copying a balanced field's ids, 46 MB on the Cornell box, took longer than reading
/// them).
#[derive(Debug, Clone, Copy)]
pub struct Samples<'a> {
    /// (U, V, S, T).
    pub dims: [u32; 4],
    /// Ids per sample.
    pub n: u32,
    /// (U, V, S, T, n) row-major cell ids, −1 empty.
    pub ids: &'a [i32],
    /// (U, V, S, T): how many distinct cells each sample's rays hit.
    pub hits: &'a [u16],
}

impl<'a> From<&'a Field> for Samples<'a> {
    fn from(f: &'a Field) -> Self {
        Samples {
            dims: f.dims,
            n: f.n,
            ids: &f.ids,
            hits: &f.hits,
        }
    }
}

/// The samples one line reads from a slab's field: per axis, the indices and how many.
type Axes = [([u32; 2], usize); 4];

/// The samples around the line `q`: the one holding it and, per `interpolate` (uv, st), its
/// neighbours.
fn axes_of(f: &Samples, q: [f64; 4], (do_uv, do_st): (bool, bool)) -> Axes {
    let [du, dv, ds, dt] = f.dims;
    [
        around(q[0], du, do_uv),
        around(q[1], dv, do_uv),
        around(q[2], ds, do_st),
        around(q[3], dt, do_st),
    ]
}

/// `g` of the index of every sample in `axes`.
fn each_sample(f: &Samples, axes: &Axes, mut g: impl FnMut(usize)) {
    let [(us, nu), (vs, nv), (ss, ns), (ts, nt)] = axes;
    for &iu in &us[..*nu] {
        for &iv in &vs[..*nv] {
            for &is in &ss[..*ns] {
                for &it in &ts[..*nt] {
                    g(sample_index(f.dims, [iu, iv, is, it]));
                }
            }
        }
    }
}

/// The most cells any of the samples in `axes` saw.
fn most_hits(f: &Samples, axes: &Axes) -> u16 {
    let mut most = 0u16;
    each_sample(f, axes, |s| {
        most = most.max(f.hits.get(s).copied().unwrap_or(u16::MAX))
    });
    most
}

/// What one slab says about one resampled pixel's line, compact (compared at a block's
/// corners, cached per pixel): whether each sample read saw at most `trust` cells is worked
/// out only for the blocks that are taken ([`Trust`]), since it follows from the samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SlabRead {
    /// The line sees nothing inside the scene's bounds: answered, with nothing to read.
    Nothing,
    /// The slab does not answer the line.
    No,
    /// It answers by reading, per axis, sample `first` and (bit k of `two`) the next one.
    Reads { first: [u32; 4], two: u8 },
}

impl SlabRead {
    fn reads(axes: &Axes) -> Self {
        let mut two = 0;
        for (k, (_, n)) in axes.iter().enumerate() {
            two |= u8::from(*n == 2) << k;
        }
        SlabRead::Reads {
            first: axes.map(|(i, _)| i[0]),
            two,
        }
    }

    /// The samples read, per axis (for `Reads`).
    fn axes(first: [u32; 4], two: u8) -> Axes {
        std::array::from_fn(|k| {
            if two >> k & 1 == 1 {
                ([first[k], first[k] + 1], 2)
            } else {
                ([first[k], first[k]], 1)
            }
        })
    }
}

/// Where a pixel's line can see something: `(λ where the whole line enters the bounds, its
/// visible range [near end, far end] inside them)`, `None` when it sees nothing there. The
/// same for every slab, so worked out once per pixel.
type Seen = Option<(f64, [f64; 2])>;

fn seen_of((o, d): (DVec3, DVec3), bounds: [DVec3; 2], range: (f64, f64)) -> Seen {
    clip_line(o, d, bounds)
        .map(|(a, b)| (a, [a.max(range.0), b.min(range.1)]))
        .filter(|(_, [a, b])| a <= b)
}

/// How one slab's field answers the line `o + λ·d` (`seen`: [`seen_of`] the line, for
/// conservative resampling; `from`: the slab crossed from `o`, when every line starts there),
/// and the samples it reads.
fn read(
    (slab, f): &(Slab, Samples),
    from: Option<&SlabFrom>,
    (o, d): (DVec3, DVec3),
    how: &Resampling,
    seen: Seen,
) -> SlabRead {
    let interp = match how.interpolate {
        Interpolate::None => (false, false),
        Interpolate::Uv => (true, false),
        Interpolate::St => (false, true),
        Interpolate::UvSt => (true, true),
    };
    let from = from.copied().unwrap_or_else(|| slab.from(o));
    let q = if how.conservative.is_none() {
        from.line(d)
    } else {
        let Some((box_from, seen)) = seen else {
            return SlabRead::Nothing;
        };
        from.answers(d, seen, box_from)
    };
    match q {
        Some(q) => SlabRead::reads(&axes_of(f, q, interp)),
        None => SlabRead::No,
    }
}

/// Whether each sample a read takes saw at most `trust` cells, remembered for the reads met
/// before (a direct-mapped table: the reads along a block's boundary repeat a few keys).
struct Trust {
    table: Vec<Option<Trusted>>,
}

/// A [`Trust`] entry: slab, the read's `first` and `two`, and whether it is trusted.
type Trusted = (usize, [u32; 4], u8, bool);

impl Trust {
    const SIZE: usize = 4096;

    fn new() -> Self {
        Trust {
            table: vec![None; Self::SIZE],
        }
    }

    fn of(&mut self, slab: usize, f: &Samples, first: [u32; 4], two: u8, trust: u32) -> bool {
        let mut h = (slab as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ u64::from(two);
        for x in first {
            h = (h ^ u64::from(x)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
        let at = (h >> 52) as usize % Self::SIZE;
        if let Some((s, fi, tw, ok)) = self.table[at] {
            if s == slab && fi == first && tw == two {
                return ok;
            }
        }
        let ok = u32::from(most_hits(f, &SlabRead::axes(first, two))) <= trust;
        self.table[at] = Some((slab, first, two, ok));
        ok
    }
}

/// The most samples per axis a block's reads may span for [`span_of`]: two overlapping
/// interpolation pairs (wider spans took no less time on khr_cameras).
const SPAN: u32 = 3;

/// The samples, per axis an inclusive range of indices, that every line of a block reads from
/// when its four corners all read (`Reads`), though not the same samples: the (u, v) and
/// (s, t) of a block's lines lie within its corners', so each line's samples lie within the
/// corners' per axis. `None` when a corner does not read, or the span is wider than [`SPAN`]
/// on some axis (a box that wide marks cells no line of the block reads).
fn span_of(reads: &[SlabRead; 4], f: &Samples) -> Option<[[u32; 2]; 4]> {
    let mut span = [[u32::MAX, 0]; 4];
    for r in reads {
        let SlabRead::Reads { first, two } = *r else {
            return None;
        };
        for k in 0..4 {
            span[k][0] = span[k][0].min(first[k]);
            span[k][1] = span[k][1].max(first[k] + u32::from(two >> k & 1));
        }
    }
    (0..4)
        .all(|k| span[k][1] - span[k][0] < SPAN && span[k][1] < f.dims[k])
        .then_some(span)
}

/// `g` of every sample index in `span`.
fn each_in_span(f: &Samples, span: &[[u32; 2]; 4], mut g: impl FnMut(usize)) {
    for iu in span[0][0]..=span[0][1] {
        for iv in span[1][0]..=span[1][1] {
            for is in span[2][0]..=span[2][1] {
                for it in span[3][0]..=span[3][1] {
                    g(sample_index(f.dims, [iu, iv, is, it]));
                }
            }
        }
    }
}

/// Whether some sample in `span` saw at most `trust` cells, and whether some saw more: all of
/// them trusted is `[true, false]`, none `[false, true]`.
fn span_trust(f: &Samples, span: &[[u32; 2]; 4], trust: u32) -> [bool; 2] {
    let mut seen = [false; 2];
    each_in_span(f, span, |s| {
        let hits = u32::from(f.hits.get(s).copied().unwrap_or(u16::MAX));
        seen[usize::from(hits > trust)] = true;
    });
    seen
}

/// Per resampled pixel: some slab answered it (or it sees nothing), and some slab holds its
/// line; a pixel answered by none goes to the fallback, as overflowed when held.
const ANSWERED: u8 = 1;
const HELD: u8 = 2;

/// Side, in resampled pixels, of the blocks resampling starts from.
const BLOCK: usize = 32;

/// What rows of blocks found: the samples read (a bit per sample of every slab, in slab
/// order; empty until one is read), and the pixels the field did not answer.
type RowMarks = (Vec<u64>, Vec<(usize, Answer)>);

/// A worker's scratch for resampling rows of blocks, kept from one row of blocks to the next:
/// per resampled pixel of the row, its state bits, its slab read (current while its stamp is
/// `stamp`, which changes for each slab of each row, so nothing is cleared), and its line's
/// [`Seen`] (current while its stamp is `row`).
struct Band {
    state: Vec<u8>,
    reads: Vec<SlabRead>,
    read_stamp: Vec<u32>,
    stamp: u32,
    seen: Vec<Seen>,
    seen_stamp: Vec<u32>,
    row: u32,
    trust: Trust,
    todo: Vec<[usize; 4]>,
}

impl Band {
    fn new(len: usize) -> Self {
        Band {
            state: vec![0; len],
            reads: vec![SlabRead::No; len],
            read_stamp: vec![0; len],
            stamp: 0,
            seen: vec![None; len],
            seen_stamp: vec![0; len],
            row: 0,
            trust: Trust::new(),
            todo: Vec::new(),
        }
    }
}

/// Mark the cells `camera` sees through the fields (one per slab).
///
/// Pixels are resampled by blocks rather than one by one, and each slab on its own: the
/// resampled pixels of a block of `BLOCK x BLOCK` whose four corner pixels read the same
/// samples of a slab and get the same answer from it all do, and the block adds those samples'
/// cells once; a block whose corners differ is split in four, down to single pixels. The
/// pinhole projection maps the image linearly onto each slab plane's rectangle (a homography),
/// so the (u, v) and (s, t) of a block's pixels lie within its corners' and the sample indices
/// and the rectangle tests, monotone in them, agree inside when they agree at the corners; so
/// do the tests of the visible range against the planes for a camera outside the bounds, where
/// they always pass. A pixel's answer is then its slabs' answers merged. Taking the slabs one
/// at a time, a block is split only where that slab's samples change, not wherever any of the
/// six slabs' do. What changes is the cost: the field's resolution, not the image's, sets the
/// number of lines read (visibility-field.txt §4 reads the field per pixel on the GPU; on the
/// CPU that was 70-89% of a view). Where a line meets the bounds is worked out once per pixel
/// for all slabs, and whether the samples read are trusted once per block taken. A block whose
/// corners all read, from samples spanning at most [`SPAN`] per axis that are all trusted, is
/// taken whole with the cells of that span (with conservative resampling).
///
/// With conservative resampling a read that is not trusted marks nothing: its pixel is either
/// answered by another slab's trusted read, which marks what it sees, or traced, and the
/// fallback marks what the ray hits. (Marking the untrusted samples' ids as well drew 1.5-2.3x
/// the visible cells on the Cornell box and khr_simple_instancing; without them, 0.99-1.01x.)
pub fn resample(
    fields: &[(Slab, Samples)],
    cell_count: usize,
    camera: &Camera,
    how: Resampling,
) -> Result<Marks> {
    if how.subsample == 0 {
        return input_err!("subsample must be at least 1");
    }
    // The view's image, and per pixel what the field answered.
    crate::limits::check_views(
        "the field's view",
        std::slice::from_ref(camera),
        2 * crate::limits::IMAGE_BYTES,
    )?;
    for (_, f) in fields {
        let samples: usize = f.dims.iter().map(|&d| d as usize).product::<usize>();
        if f.ids.len() != samples * f.n as usize || f.hits.len() != samples {
            return input_err!(
                "a field holds {} ids and {} hit counts, its dimensions need {} and {samples}",
                f.ids.len(),
                f.hits.len(),
                samples * f.n as usize
            );
        }
    }
    let k = how.subsample as usize;
    let (w, h) = (camera.width as usize, camera.height as usize);
    let (cols, rows) = (w.div_ceil(k), h.div_ceil(k));
    let range = match how.conservative {
        Some([lo, hi]) => camera.clip_range([lo.as_vec3().to_array(), hi.as_vec3().to_array()]),
        None => (0.0, f64::INFINITY),
    };
    // The image pixel resampled pixel (c, r) stands for, and its line.
    let pixel = |c: usize, r: usize| ((c * k + k / 2).min(w - 1), (r * k + k / 2).min(h - 1));
    let eye = camera.projector();
    let line_at = |c: usize, r: usize| {
        let (x, y) = pixel(c, r);
        eye.ray_z1(DVec2::new(x as f64 + 0.5, y as f64 + 0.5))
    };
    // The outline the scene's bounds project to (None: a corner lies behind the camera, and
    // any block may reach them): a block whose corners' lines all miss the bounds may still
    // hold lines that meet them (a far scene smaller than a block, a flat one seen edge on, a
    // corner of the outline poking in between two block corners) unless it lies outside.
    let outline = how.conservative.map(|[lo, hi]| {
        let mut points = Vec::with_capacity(8);
        for i in 0..8 {
            let p = DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            let (px, z) = eye.project(p);
            if !(z > 0.0 && px.is_finite()) {
                return None;
            }
            points.push(px);
        }
        Some(convex_hull(points))
    });
    let may_reach = |c0: usize, c1: usize, r0: usize, r1: usize| {
        let Some(outline) = &outline else {
            return false;
        };
        let Some(hull) = outline else {
            return true;
        };
        let ((a, b), (c, d)) = (pixel(c0, r0), pixel(c1, r1));
        let m = k as f64 + 1.0;
        let lo = DVec2::new(a as f64 - m, b as f64 - m);
        let hi = DVec2::new(c as f64 + 1.0 + m, d as f64 + 1.0 + m);
        polygon_meets_box(hull, lo, hi)
    };
    // Where each slab's samples start among the bits.
    let mut base = vec![0usize; fields.len() + 1];
    for (k, (_, f)) in fields.iter().enumerate() {
        base[k + 1] = base[k] + f.hits.len();
    }
    let words = base[fields.len()].div_ceil(64);
    // Every line of a pinhole view starts at its eye: each slab's planes crossed from there.
    let perspective = matches!(
        camera.projection,
        crate::camera::Projection::Perspective { .. }
    );
    let froms: Vec<Option<SlabFrom>> = fields
        .iter()
        .map(|(slab, _)| perspective.then(|| slab.from(eye.ray_z1(DVec2::ZERO).0)))
        .collect();
    let band_len = cols * BLOCK.min(rows);
    let (read_bits, missed) = (0..rows.div_ceil(BLOCK))
        .into_par_iter()
        .fold(
            || (Vec::new(), Vec::new(), Band::new(band_len)),
            |(mut samples, mut missed, mut band), br| {
                // Blocks as inclusive ranges of resampled columns and rows.
                let (row0, row1) = (br * BLOCK, ((br + 1) * BLOCK).min(rows) - 1);
                let at = |c: usize, r: usize| (r - row0) * cols + c;
                let len = cols * (row1 - row0 + 1);
                band.state[..len].fill(0);
                band.row += 1;
                let b = &mut band;
                for (slab, field) in fields.iter().enumerate() {
                    b.stamp += 1;
                    b.todo.clear();
                    b.todo.extend(
                        (0..cols.div_ceil(BLOCK))
                            .rev()
                            .map(|bc| [bc * BLOCK, ((bc + 1) * BLOCK).min(cols) - 1, row0, row1]),
                    );
                    while let Some([c0, c1, r0, r1]) = b.todo.pop() {
                        // A small block (8x8 or less) whose lines earlier slabs all answered
                        // needs nothing more: their trusted reads marked what the lines see.
                        // (Scanning large blocks cost more than it saved.)
                        if how.conservative.is_some()
                            && (c1 - c0 + 1) * (r1 - r0 + 1) <= 64
                            && (r0..=r1).all(|r| {
                                b.state[at(c0, r)..=at(c1, r)]
                                    .iter()
                                    .all(|s| s & ANSWERED != 0)
                            })
                        {
                            continue;
                        }
                        let corners = [(c0, r0), (c1, r0), (c0, r1), (c1, r1)];
                        for &(c, r) in &corners {
                            let i = at(c, r);
                            if b.read_stamp[i] != b.stamp {
                                b.read_stamp[i] = b.stamp;
                                let line = line_at(c, r);
                                let seen = match how.conservative {
                                    Some(bounds) => {
                                        if b.seen_stamp[i] != b.row {
                                            b.seen_stamp[i] = b.row;
                                            b.seen[i] = seen_of(line, bounds, range);
                                        }
                                        b.seen[i]
                                    }
                                    None => None,
                                };
                                b.reads[i] = read(field, froms[slab].as_ref(), line, &how, seen);
                            }
                        }
                        let first = b.reads[at(c0, r0)];
                        let single = c0 == c1 && r0 == r1;
                        let unsure =
                            first == SlabRead::Nothing && !single && may_reach(c0, c1, r0, r1);
                        let same = corners[1..]
                            .iter()
                            .all(|&(c, r)| b.reads[at(c, r)] == first);
                        if !same && how.conservative.is_some() {
                            let reads = corners.map(|(c, r)| b.reads[at(c, r)]);
                            let span = span_of(&reads, &field.1);
                            // All trusted: every line of the block is answered; none: none is.
                            let bits = span.and_then(|span| {
                                match span_trust(&field.1, &span, how.trust) {
                                    [true, false] => Some((span, HELD | ANSWERED)),
                                    [false, true] => Some((span, HELD)),
                                    _ => None,
                                }
                            });
                            if let Some((span, bits)) = bits {
                                if bits & ANSWERED != 0 {
                                    if samples.is_empty() {
                                        samples = vec![0u64; words];
                                    }
                                    each_in_span(&field.1, &span, |s| {
                                        let bit = base[slab] + s;
                                        samples[bit / 64] |= 1 << (bit % 64);
                                    });
                                }
                                for r in r0..=r1 {
                                    b.state[at(c0, r)..=at(c1, r)]
                                        .iter_mut()
                                        .for_each(|s| *s |= bits);
                                }
                                continue;
                            }
                        }
                        if unsure || !same {
                            let (cm, rm) = ((c0 + c1) / 2, (r0 + r1) / 2);
                            for [a, bb] in [[rm + 1, r1], [r0, rm]] {
                                for [x, y] in [[cm + 1, c1], [c0, cm]] {
                                    if a <= bb && x <= y {
                                        b.todo.push([x, y, a, bb]);
                                    }
                                }
                            }
                            continue;
                        }
                        let bits = match first {
                            SlabRead::No => continue,
                            SlabRead::Nothing => ANSWERED,
                            SlabRead::Reads { first, two } => {
                                let trusted = how.conservative.is_none()
                                    || b.trust.of(slab, &field.1, first, two, how.trust);
                                // An untrusted read marks nothing: its lines are answered by
                                // another slab or traced, and either marks what they see.
                                if trusted {
                                    if samples.is_empty() {
                                        samples = vec![0u64; words];
                                    }
                                    let axes = SlabRead::axes(first, two);
                                    each_sample(&field.1, &axes, |s| {
                                        let bit = base[slab] + s;
                                        samples[bit / 64] |= 1 << (bit % 64);
                                    });
                                    HELD | ANSWERED
                                } else {
                                    HELD
                                }
                            }
                        };
                        for r in r0..=r1 {
                            b.state[at(c0, r)..=at(c1, r)]
                                .iter_mut()
                                .for_each(|s| *s |= bits);
                        }
                    }
                }
                for r in row0..=row1 {
                    for c in 0..cols {
                        let s = band.state[at(c, r)];
                        if s & ANSWERED == 0 {
                            let (x, y) = pixel(c, r);
                            let answer = if s & HELD != 0 {
                                Answer::Overflowed
                            } else {
                                Answer::Outside
                            };
                            missed.push((y * w + x, answer));
                        }
                    }
                }
                (samples, missed, band)
            },
        )
        .map(|(samples, missed, _)| (samples, missed))
        .reduce(RowMarks::default, |(mut a, mut ma), (b, mb)| {
            if a.is_empty() {
                a = b;
            } else if !b.is_empty() {
                a.iter_mut().zip(&b).for_each(|(x, y)| *x |= y);
            }
            ma.extend(mb);
            (a, ma)
        });
    let mut marks = Marks {
        marked: vec![false; cell_count],
        pixels: rows * cols,
        ..Default::default()
    };
    for (p, a) in missed {
        match a {
            Answer::Outside => marks.outside += 1,
            _ => marks.overflowed += 1,
        }
        if how.conservative.is_some() {
            marks.fallback.push(p);
        }
    }
    // In pixel order, whatever order the rows finished in.
    marks.fallback.sort_unstable();
    let set_bits = read_bits.iter().enumerate().flat_map(|(i, &word)| {
        (0..64)
            .filter(move |b| word >> b & 1 == 1)
            .map(move |b| i * 64 + b)
    });
    for bit in set_bits {
        let slab = base.partition_point(|&b| b <= bit) - 1;
        let f = &fields[slab].1;
        let (n, s) = (f.n as usize, bit - base[slab]);
        for &id in f.ids[s * n..(s + 1) * n].iter().filter(|&&id| id >= 0) {
            // Checked as read: only the samples a view reads, not the whole field each view.
            let Some(m) = marks.marked.get_mut(id as usize) else {
                return input_err!("the field names cell {id}, but there are {cell_count} cells");
            };
            *m = true;
        }
    }
    Ok(marks)
}

/// The convex hull of `points`, counter-clockwise in a y-up frame (Andrew's monotone chain);
/// fewer than three distinct points give those points.
fn convex_hull(mut points: Vec<DVec2>) -> Vec<DVec2> {
    points.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    points.dedup();
    if points.len() < 3 {
        return points;
    }
    let turn = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<DVec2> = Vec::with_capacity(2 * points.len());
    for pass in [points.clone(), points.into_iter().rev().collect()] {
        let start = hull.len();
        for p in pass {
            while hull.len() >= start + 2
                && turn(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

/// Whether the convex polygon `hull` and the box `[lo, hi]` overlap (separating axes: the
/// box's two and each edge's normal).
fn polygon_meets_box(hull: &[DVec2], lo: DVec2, hi: DVec2) -> bool {
    let (mut pmin, mut pmax) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    for &p in hull {
        pmin = pmin.min(p);
        pmax = pmax.max(p);
    }
    if pmax.x < lo.x || hi.x < pmin.x || pmax.y < lo.y || hi.y < pmin.y {
        return false;
    }
    let corners = [lo, DVec2::new(hi.x, lo.y), hi, DVec2::new(lo.x, hi.y)];
    for (i, &a) in hull.iter().enumerate() {
        let n = (hull[(i + 1) % hull.len()] - a).perp();
        let span = |pts: &mut dyn Iterator<Item = DVec2>| {
            pts.map(|p| n.dot(p))
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                    (l.min(v), h.max(v))
                })
        };
        let (h0, h1) = span(&mut hull.iter().copied());
        let (b0, b1) = span(&mut corners.iter().copied());
        if h1 < b0 || b1 < h0 {
            return false;
        }
    }
    true
}

/// The scene's bounds, widened by a millionth of its diagonal (and at least 1e-30) so that
/// surfaces on the bounds stay inside: the box conservative resampling clips lines to.
pub fn scene_box(scene: &Scene) -> [DVec3; 2] {
    let [lo, hi] = scene.bounds_f64();
    let eps = (1e-6 * scene.diagonal()).max(1e-30);
    [lo - eps, hi + eps]
}

/// Build what the fallback traces (the frame and BVH of the cell-sorted scene), so that the
/// first view does not pay for it.
pub fn prepare_fallback(sorted: &Scene) -> Result<()> {
    let frame = TraceFrame::of(sorted)?;
    crate::trace::Bvh::of(frame.scene(sorted));
    EdgeNeighbours::of(sorted);
    Ok(())
}

/// Where a pixel centre lies within this many pixels of an edge of its traced triangle, the
/// raster (snapping vertices to its sub-pixel grid, 1/256 pixel on lavapipe) may draw the
/// neighbour across the edge: the fallback also traces the corners of a square this wide
/// around the centre, which straddle any line passing this close.
const EDGE: f64 = 1.0 / 32.0;
/// Where a pixel centre lies within this many pixels of an edge, the triangle sharing the edge
/// is drawn too ([`across_near`]): lavapipe's raster snaps vertices to 1/256 pixel.
const FOLD: f64 = 1.0 / 256.0;
/// Relative depth within which a triangle folding back behind another at their shared edge
/// may still win the depth test there (a float32 depth buffer's rounding, with margin).
const DEPTH_ROUNDING: f64 = 1e-6;
const AROUND: [[f64; 2]; 4] = [[EDGE, EDGE], [-EDGE, EDGE], [EDGE, -EDGE], [-EDGE, -EDGE]];

/// The fallback (conservative culling): trace the pixel rays of `pixels` through `sorted` (the
/// scene with its faces in cell order, `offsets` the cells' CSR offsets into them) as the CPU
/// backend of conventional images does (the same f32 rays between the same near and far
/// planes), and mark the cells they hit. A pixel centre within [`EDGE`] of its triangle's edge
/// is where the raster may draw the neighbour across the edge instead, so four rays around it
/// mark the neighbours' cells too. Returns the cells it marked that were not marked yet, and
/// each pixel with the sorted face its ray hit (−1: none), which is also its answer among the
/// marked cells ([`trace_sorted`] takes them as they are).
pub fn trace_fallback(
    sorted: &Scene,
    offsets: &[u32],
    camera: &Camera,
    pixels: Vec<usize>,
    marked: &mut [bool],
) -> Result<(usize, Vec<(usize, i32)>)> {
    if pixels.is_empty() {
        return Ok((0, Vec::new()));
    }
    let (near, far) = camera.clip_range(sorted.bounds());
    let frame = TraceFrame::of(sorted)?;
    let (origins, dirs) = pixel_rays_f32_at(camera, &frame, &pixels);
    let range = Query::new(near as f32, (far as f32).max(near as f32));
    let hits = crate::trace::cast_rays_with(frame.scene(sorted), &origins, &dirs, &range)?;
    let traced: Vec<(usize, i32)> = pixels.into_iter().zip(hits.triangle).collect();
    let w = camera.width as usize;
    let centre = |p: usize| DVec2::new((p % w) as f64 + 0.5, (p / w) as f64 + 0.5);
    let eye = camera.projector();
    let on_edge: Vec<(usize, usize, u8)> = traced
        .par_iter()
        .filter(|&&(_, t)| t >= 0)
        .map(|&(p, t)| {
            (
                p,
                t as usize,
                near_edges(sorted.triangle(t as usize), &eye, centre(p)),
            )
        })
        .filter(|&(_, _, near)| near != 0)
        .collect();
    let across = look_across(sorted, camera, &on_edge)?;
    let found = traced.iter().map(|&(_, t)| t);
    let added = mark(sorted, offsets, found.chain(across), marked);
    Ok((added, traced))
}

/// What may lie across the near edges of the pixels `on_edge` (pixel, sorted face, its edges
/// within [`EDGE`] of the pixel's centre, [`near_edges`]): what the four [`AROUND`] rays of
/// each hit, and the triangles sharing those edges where the raster's rounding may pick them
/// ([`across_near`]). Sorted faces, −1 for a ray that hit nothing.
fn look_across(
    sorted: &Scene,
    camera: &Camera,
    on_edge: &[(usize, usize, u8)],
) -> Result<Vec<i32>> {
    let w = camera.width as usize;
    let centre = |p: usize| DVec2::new((p % w) as f64 + 0.5, (p / w) as f64 + 0.5);
    let points: Vec<DVec2> = on_edge
        .iter()
        .flat_map(|&(p, _, _)| AROUND.map(|o| centre(p) + DVec2::from_array(o)))
        .collect();
    let mut found = trace_points(sorted, camera, &points)?;
    let adjacent = EdgeNeighbours::of(sorted);
    let eye = camera.projector();
    found.extend(
        on_edge
            .iter()
            .flat_map(|&(p, t, near)| across_near(sorted, &adjacent, &eye, (t, near), centre(p))),
    );
    Ok(found)
}

/// Mark the cells of the sorted faces `faces` (−1 ignored); returns how many were not marked.
fn mark(
    sorted: &Scene,
    offsets: &[u32],
    faces: impl IntoIterator<Item = i32>,
    marked: &mut [bool],
) -> usize {
    let cells = sorted_cells(sorted, offsets);
    let mut added = 0;
    for t in faces.into_iter().filter(|&t| t >= 0) {
        let c = cells.cell[t as usize] as usize;
        if !marked[c] {
            marked[c] = true;
            added += 1;
        }
    }
    added
}

/// Which edges of `tri` (bit `k`: from corner `k` to `k + 1`) pass within [`EDGE`] pixels of
/// the pixel position `x` as `camera` projects it (all of them when a vertex lies behind the
/// camera, where the projection is no guide, or an edge collapses to a point).
fn near_edges(tri: [DVec3; 3], camera: &Projector, x: DVec2) -> u8 {
    let projected = tri.map(|p| camera.project(p));
    if projected
        .iter()
        .any(|&(_, depth)| depth.is_nan() || depth <= 0.0)
    {
        return 0b111;
    }
    let q = projected.map(|(p, _)| p);
    let mut near = 0;
    for i in 0..3 {
        let (a, b) = (q[i], q[(i + 1) % 3]);
        let e = b - a;
        let len = e.length();
        if len <= f64::MIN_POSITIVE {
            return 0b111;
        }
        if e.perp_dot(x - a).abs() / len < EDGE {
            near |= 1 << i;
        }
    }
    near
}

/// The triangles sharing the edges of sorted face `t` that pass within [`FOLD`] pixels of the
/// centre `x` (of those `near` it, [`near_edges`]), where the raster, rounding, may give the
/// pixel to the neighbour across: a sliver seen edge on (thinner on screen than [`EDGE`]), which
/// no ray around the centre meets, or one folding back behind `t` beyond a silhouette, which
/// wins the pixel only where its depth there is `t`'s to within the depth buffer's rounding.
/// On khr_simple_instancing and the Cornell box such pixels were the only ones of 1-7 visible
/// cells in a view. All near edges' neighbours when `t` does not project (a vertex behind).
fn across_near(
    sorted: &Scene,
    adjacent: &EdgeNeighbours,
    camera: &Projector,
    (t, near): (usize, u8),
    x: DVec2,
) -> Vec<i32> {
    let tri = sorted.triangle(t);
    let q = tri.map(|v| camera.project(v));
    let projects = q.iter().all(|&(p, depth)| depth > 0.0 && p.is_finite());
    let (o, d) = camera.ray_z1(x);
    // Where the pixel's line meets a triangle's plane (λ along it; None: parallel).
    let meet = |v: [DVec3; 3]| {
        let n = (v[1] - v[0]).cross(v[2] - v[0]);
        let dn = d.dot(n);
        (dn != 0.0).then(|| (v[0] - o).dot(n) / dn)
    };
    let mine = meet(tri);
    (0..3)
        .filter(|k| near >> k & 1 == 1)
        .filter_map(|k| {
            let n = adjacent.0[t][k];
            if n == NONE {
                return None;
            }
            if !projects {
                return Some(n as i32);
            }
            let (a, b, c) = (q[k].0, q[(k + 1) % 3].0, q[(k + 2) % 3].0);
            let e = b - a;
            if e.perp_dot(x - a).abs() >= FOLD * e.length() {
                return None;
            }
            let other = sorted.triangle(n as usize);
            let m = other.map(|v| camera.project(v).0);
            let off = m
                .into_iter()
                .map(|v| e.perp_dot(v - a))
                .max_by(|u, v| u.abs().total_cmp(&v.abs()))
                .unwrap_or(0.0);
            let folds = off * e.perp_dot(c - a) > 0.0;
            let level = match (mine, meet(other)) {
                (Some(zt), Some(zn)) => zn - zt <= DEPTH_ROUNDING * zt.abs(),
                _ => true,
            };
            (!folds || level).then_some(n as i32)
        })
        .collect()
}

/// The face ranges `[a, b)` of the marked cells, consecutive cells merged; `offsets` is the
/// cells' CSR offsets into the cell-sorted faces.
pub fn ranges(offsets: &[u32], marked: &[bool]) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    for (c, _) in marked.iter().enumerate().filter(|(_, &m)| m) {
        push_range(&mut out, offsets[c], offsets[c + 1]);
    }
    out
}

/// Render only the marked cells of `sorted` (the scene with its faces in cell order; `order[i]`
/// is the original id of sorted face i) from `camera`: a depth image whose triangle ids are the
/// original scene's.
pub fn render_marked(
    sorted: &Scene,
    order: &[u32],
    offsets: &[u32],
    marked: &[bool],
    camera: &Camera,
) -> Result<(DepthImages, usize)> {
    check_cells(sorted, order, offsets, marked)?;
    let (mut img, drawn) = render_sorted(sorted, offsets, marked, camera)?;
    remap(&mut img, order);
    Ok((img, drawn))
}

fn check_cells(sorted: &Scene, order: &[u32], offsets: &[u32], marked: &[bool]) -> Result<()> {
    if offsets.len() != marked.len() + 1 || order.len() != sorted.triangle_count() {
        return input_err!("the cells do not match the cell-sorted scene");
    }
    Ok(())
}

/// Sorted faces' ids to the scene's.
fn remap(img: &mut DepthImages, order: &[u32]) {
    for t in img.triangle.iter_mut().filter(|t| **t >= 0) {
        *t = order[*t as usize] as i32;
    }
}

/// [`render_marked`] with the sorted faces' ids.
fn render_sorted(
    sorted: &Scene,
    offsets: &[u32],
    marked: &[bool],
    camera: &Camera,
) -> Result<(DepthImages, usize)> {
    let start = Instant::now();
    let rs = ranges(offsets, marked);
    let drawn: usize = rs.iter().map(|&(a, b)| (b - a) as usize).sum();
    let mut img = discretize_ranges(sorted, std::slice::from_ref(camera), false, Some(&rs))?;
    img.timings.add("ranges", start.elapsed().as_secs_f64());
    Ok((img, drawn))
}

/// The image [`render_marked`] draws, without the GPU (a field view's `"cpu"` backend): traced
/// as the CPU backend of conventional images traces (`discretize_traced`), each pixel-centre
/// ray meeting only the marked cells' triangles (the BVH's traversal passes through the
/// others), centres on an edge decided by the raster's rule among them. `known`: pixels the
/// fallback already traced through the whole scene, with what they hit; the cell of what
/// they hit is marked, so that is their answer here too and they are not traced again.
/// Triangle ids are the sorted faces'.
fn trace_sorted(
    sorted: &Scene,
    offsets: &[u32],
    marked: &[bool],
    camera: &Camera,
    known: &[(usize, i32)],
) -> Result<(DepthImages, usize)> {
    let start = Instant::now();
    let rs = ranges(offsets, marked);
    let drawn: usize = rs.iter().map(|&(a, b)| (b - a) as usize).sum();
    let mut keep = vec![0u64; sorted.triangle_count().div_ceil(64)];
    for &(a, b) in &rs {
        set_bits(&mut keep, a as usize, b as usize);
    }
    let npx = camera.width as usize * camera.height as usize;
    let mut ids = vec![-1i32; npx];
    let mut done = vec![false; npx];
    for &(p, t) in known {
        ids[p] = t;
        done[p] = true;
    }
    let todo: Vec<usize> = (0..npx).filter(|&p| !done[p]).collect();
    let frame = TraceFrame::of(sorted)?;
    let (origins, dirs) = pixel_rays_f32_at(camera, &frame, &todo);
    let (near, far) = camera.clip_range(sorted.bounds());
    let range = Query::new(near as f32, (far as f32).max(near as f32));
    let hits = crate::trace::cast_rays_kept(frame.scene(sorted), &origins, &dirs, &range, &keep)?;
    for (&p, &t) in todo.iter().zip(&hits.triangle) {
        ids[p] = t;
    }
    let (changes, edge_seconds) = settle_edges(sorted, camera, false, &frame, &ids, Some(&keep))?;
    for (p, t) in changes {
        ids[p] = t;
    }
    let (mut img, resolve_seconds) = resolve_ids(sorted, std::slice::from_ref(camera), ids)?;
    img.timings = crate::types::Timings::from([
        ("bvh", hits.bvh_build_seconds),
        ("trace", hits.trace_seconds),
        ("edges", edge_seconds),
        ("resolve", resolve_seconds),
        ("total", start.elapsed().as_secs_f64()),
    ]);
    Ok((img, drawn))
}

/// A field view's image: the marked cells drawn on the GPU, or traced on the CPU (`cpu`,
/// [`trace_sorted`]), then, with `borders`, looked over along the borders between cells at
/// the pixels where the fallback did not trace the triangle shown ([`look_across_borders`]);
/// where that marks more
/// cells, they are drawn again with them. `known`: the fallback's pixels and what they hit.
/// Returns the image (the scene's triangle ids), the triangles drawn, and the cells the look
/// along the borders added.
#[allow(clippy::too_many_arguments)]
pub fn draw_view(
    sorted: &Scene,
    order: &[u32],
    offsets: &[u32],
    marked: &mut [bool],
    camera: &Camera,
    known: &[(usize, i32)],
    cpu: bool,
    borders: bool,
) -> Result<(DepthImages, usize, usize)> {
    check_cells(sorted, order, offsets, marked)?;
    let draw = |marked: &[bool]| {
        if cpu {
            trace_sorted(sorted, offsets, marked, camera, known)
        } else {
            render_sorted(sorted, offsets, marked, camera)
        }
    };
    let (mut img, mut drawn) = draw(marked)?;
    let start = Instant::now();
    let added = if borders {
        // The fallback looked across the edges near its pixels of the triangles it hit; where
        // the image shows those, that is done.
        let mut looked = vec![false; img.triangle.len()];
        for &(p, t) in known {
            looked[p] = t >= 0 && img.triangle[p] == t;
        }
        look_across_borders(sorted, offsets, camera, &img.triangle, &looked, marked)?
    } else {
        0
    };
    let border_seconds = start.elapsed().as_secs_f64();
    if added > 0 {
        (img, drawn) = draw(marked)?;
    }
    img.timings.add("borders", border_seconds);
    remap(&mut img, order);
    Ok((img, drawn, added))
}

/// The cell of each face of a cell-sorted scene (cells are runs of faces), kept on the scene
/// for the offsets it was made from.
struct SortedCells {
    offsets: Vec<u32>,
    cell: Vec<u32>,
}

fn sorted_cells(sorted: &Scene, offsets: &[u32]) -> std::sync::Arc<SortedCells> {
    let make = || {
        let mut cell = vec![0u32; sorted.triangle_count()];
        for (c, w) in offsets.windows(2).enumerate() {
            cell[w[0] as usize..w[1] as usize].fill(c as u32);
        }
        SortedCells {
            offsets: offsets.to_vec(),
            cell,
        }
    };
    let kept = sorted.derived(make);
    if kept.offsets == offsets {
        kept
    } else {
        std::sync::Arc::new(make())
    }
}

/// Look across the edges near the borders between cells in a drawn field view (`ids`: sorted
/// faces, −1 empty), and mark the cells found there. The field answered most pixels without a
/// ray, and the fallback's ray at some pixels found nothing where the raster still draws
/// something (an edge-on wall's silhouette), so nothing looked across the edges near those
/// centres; where an edge passes that close and the cell across was marked by no pixel, the
/// GPU's rounding may give the pixel to the triangle across, and the cell goes missing (1-7
/// of 78-503 visible cells per view on the Cornell box and khr_simple_instancing, each seen at
/// a single pixel). A pixel not `looked` at (where the fallback traced the triangle the image
/// shows, and looked across its edges) whose 4-neighbour shows another cell (or nothing), within
/// [`EDGE`] of an edge of its triangle, traces the four [`AROUND`] rays as the fallback does,
/// and within [`FOLD`] takes the triangle sharing the edge ([`across_near`]). Returns the
/// cells it marked.
pub fn look_across_borders(
    sorted: &Scene,
    offsets: &[u32],
    camera: &Camera,
    ids: &[i32],
    looked: &[bool],
    marked: &mut [bool],
) -> Result<usize> {
    let cells = sorted_cells(sorted, offsets);
    let (w, h) = (camera.width as usize, camera.height as usize);
    if ids.len() != w * h || looked.len() != w * h {
        return input_err!(
            "{} and {} pixels for a {w}x{h} view",
            ids.len(),
            looked.len()
        );
    }
    let cell = |t: i32| {
        if t < 0 {
            u32::MAX
        } else {
            cells.cell[t as usize]
        }
    };
    let eye = camera.projector();
    let centre = |p: usize| DVec2::new((p % w) as f64 + 0.5, (p / w) as f64 + 0.5);
    let on_edge: Vec<(usize, usize, u8)> = (0..h)
        .into_par_iter()
        .flat_map_iter(|y| {
            let (cell, eye) = (&cell, &eye);
            (0..w).filter_map(move |x| {
                let p = y * w + x;
                let t = ids[p];
                if t < 0 || looked[p] {
                    return None;
                }
                let c = cell(t);
                let border = (x > 0 && cell(ids[p - 1]) != c)
                    || (x + 1 < w && cell(ids[p + 1]) != c)
                    || (y > 0 && cell(ids[p - w]) != c)
                    || (y + 1 < h && cell(ids[p + w]) != c);
                if !border {
                    return None;
                }
                let near = near_edges(sorted.triangle(t as usize), eye, centre(p));
                (near != 0).then_some((p, t as usize, near))
            })
        })
        .collect();
    let across = look_across(sorted, camera, &on_edge)?;
    Ok(mark(sorted, offsets, across, marked))
}

/// The triangle (sorted face, −1 none) each pixel position in `points` sees between the view's
/// near and far planes, through the whole scene.
fn trace_points(sorted: &Scene, camera: &Camera, points: &[DVec2]) -> Result<Vec<i32>> {
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let (near, far) = camera.clip_range(sorted.bounds());
    let frame = TraceFrame::of(sorted)?;
    let eye = camera.projector();
    let (origins, dirs): (Vec<[f32; 3]>, Vec<[f32; 3]>) = points
        .par_iter()
        .map(|&x| {
            let (o, d) = eye.ray_z1(x);
            (
                (o + d * near - frame.shift).as_vec3().to_array(),
                d.as_vec3().to_array(),
            )
        })
        .unzip();
    let scene = frame.scene(sorted);
    Ok(crate::trace::cast_rays(scene, &origins, &dirs, 0.0, (far - near) as f32)?.triangle)
}

/// Set bits `[a, b)` of `bits`.
fn set_bits(bits: &mut [u64], a: usize, b: usize) {
    let mut i = a;
    while i < b {
        if i.is_multiple_of(64) && i + 64 <= b {
            bits[i / 64] = u64::MAX;
            i += 64;
        } else {
            bits[i / 64] |= 1 << (i % 64);
            i += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neighbours_include_the_nearest_sample() {
        for i in 0..100 {
            let x = i as f64 / 100.0;
            let (one, _) = around(x, 7, false);
            let (two, n) = around(x, 7, true);
            assert!(two[..n].contains(&one[0]), "{x}");
        }
        assert_eq!(around(0.01, 4, true), ([0, 0], 1));
        assert_eq!(around(0.4, 4, true), ([1, 2], 2));
    }

    #[test]
    fn a_polygon_meets_the_boxes_it_overlaps() {
        let p = |x, y| DVec2::new(x, y);
        let hull = convex_hull(vec![
            p(0.0, 0.0),
            p(4.0, 0.0),
            p(0.0, 4.0),
            p(1.0, 1.0),
            p(4.0, 0.0),
        ]);
        assert_eq!(hull.len(), 3, "{hull:?}");
        // Inside, across an edge, beside the hypotenuse, far away, and a sliver's box.
        assert!(polygon_meets_box(&hull, p(1.0, 1.0), p(1.5, 1.5)));
        assert!(polygon_meets_box(&hull, p(-1.0, 1.0), p(0.5, 2.0)));
        assert!(!polygon_meets_box(&hull, p(3.0, 3.0), p(5.0, 5.0)));
        assert!(!polygon_meets_box(&hull, p(10.0, 0.0), p(11.0, 1.0)));
        let sliver = convex_hull(vec![p(0.0, 0.0), p(10.0, 10.0), p(10.0, 10.0001)]);
        assert!(polygon_meets_box(&sliver, p(4.0, 3.0), p(6.0, 7.0)));
        assert!(!polygon_meets_box(&sliver, p(6.0, 3.0), p(7.0, 4.0)));
    }

    #[test]
    fn marked_cells_merge_into_ranges() {
        let offsets = [0, 2, 5, 7, 9, 12];
        let marked = [true, true, false, true, true];
        assert_eq!(ranges(&offsets, &marked), vec![(0, 5), (7, 12)]);
        assert_eq!(ranges(&offsets, &[false; 5]), vec![]);
    }
}
