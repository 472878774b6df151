//! Resampling the field along a view's pixel lines (visibility-field.txt §4, Fig. 4): which
//! cells each line's samples saw.
//!
//! One pixel in every `subsample × subsample` block (the block's middle pixel, `k·i + k/2`
//! rounded down, at its centre) gives a line; where it crosses the uv and st rectangles gives
//! (u, v, s, t) (`Slab::line`). Without interpolation the sample holding that point is read;
//! with it, its neighbours too (§4.1): the 2 × 2 samples around (u, v) for `Uv`, around (s, t)
//! for `St`, the 16 around both for `UvSt` (always including the nearest). Every id stored
//! there is marked. In the paper's rule a pixel whose line runs from the st plane toward the uv
//! plane, runs parallel to either, or misses either rectangle marks nothing; several slabs add
//! their marks. The paper rasterizes the two projected planes in hardware to get (u, v, s, t)
//! per pixel; here the same linear intersection runs on the CPU.
//!
//! Conservative resampling (this package's, not the paper's): a slab answers a pixel only when
//! everything the pixel can see lies between its planes with no surface between the uv plane
//! and the near end ([`Slab::answers`]), and only when every sample read saw at most `trust`
//! cells; the other pixels go to the fallback (`fallback`). Only trusted reads mark cells.
//! A slab reads only the pixels that the slabs before it did not answer.
//!
//! [`resample`] is the fast resampler (blocks of pixels); [`reference`](super::reference) is
//! the plain one it must agree with.

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::build::{clip_line, Field, Slab, SlabFrom};
use crate::camera::{Camera, Projection, Projector};
use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;

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
pub(super) enum Answer {
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
/// out only for the blocks that are taken ([`Lines::trusted`]), since it follows from the
/// samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum SlabRead {
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
pub(super) type Seen = Option<(f64, [f64; 2])>;

fn seen_of((o, d): (DVec3, DVec3), bounds: [DVec3; 2], range: (f64, f64)) -> Seen {
    clip_line(o, d, bounds)
        .map(|(a, b)| (a, [a.max(range.0), b.min(range.1)]))
        .filter(|(_, [a, b])| a <= b)
}

/// What every resampler takes from a view: its resampled pixels and their lines, where a line
/// can see something, and how each slab's field answers a line.
pub(super) struct Lines<'a> {
    pub fields: &'a [(Slab, Samples<'a>)],
    pub how: Resampling,
    /// Side of the pixel blocks that share a line, the image's size, the resampled grid's.
    k: usize,
    size: (usize, usize),
    pub cols: usize,
    pub rows: usize,
    eye: Projector,
    /// The camera's near and far planes around the bounds (conservative resampling).
    range: (f64, f64),
    /// Every line of a pinhole view starts at its eye: each slab's planes crossed from there.
    froms: Vec<Option<SlabFrom>>,
    /// Per slab, its planes' [`SlabFrom::terms`] as affine functions of the pixel.
    terms: Vec<PixelTerms>,
    /// Where each slab's samples start among the bits of marked samples, and their count.
    pub base: Vec<usize>,
}

impl<'a> Lines<'a> {
    pub fn new(
        fields: &'a [(Slab, Samples<'a>)],
        camera: &Camera,
        how: Resampling,
    ) -> Result<Self> {
        check(fields, camera, &how)?;
        let k = how.subsample as usize;
        let (w, h) = (camera.width as usize, camera.height as usize);
        let range = match how.conservative {
            Some([lo, hi]) => camera.clip_range([lo.as_vec3().to_array(), hi.as_vec3().to_array()]),
            None => (0.0, f64::INFINITY),
        };
        let eye = camera.projector();
        let perspective = matches!(camera.projection, Projection::Perspective { .. });
        let origin = eye.ray_z1(DVec2::ZERO).0;
        let froms = fields
            .iter()
            .map(|(slab, _)| perspective.then(|| slab.from(origin)))
            .collect();
        let terms = fields
            .iter()
            .zip(&froms)
            .map(|((slab, _), from)| PixelTerms::of(&eye, slab, from, (w, h)))
            .collect();
        let mut base = vec![0usize; fields.len() + 1];
        for (k, (_, f)) in fields.iter().enumerate() {
            base[k + 1] = base[k] + f.hits.len();
        }
        Ok(Lines {
            fields,
            how,
            k,
            size: (w, h),
            cols: w.div_ceil(k),
            rows: h.div_ceil(k),
            eye,
            range,
            froms,
            terms,
            base,
        })
    }

    /// The image pixel that resampled pixel (c, r) stands for.
    #[inline(always)]
    pub fn pixel(&self, c: usize, r: usize) -> (usize, usize) {
        let (k, (w, h)) = (self.k, self.size);
        ((c * k + k / 2).min(w - 1), (r * k + k / 2).min(h - 1))
    }

    /// The line through resampled pixel (c, r)'s centre.
    #[inline(always)]
    pub fn line(&self, c: usize, r: usize) -> (DVec3, DVec3) {
        let (x, y) = self.pixel(c, r);
        self.eye.ray_z1(DVec2::new(x as f64 + 0.5, y as f64 + 0.5))
    }

    /// Where the line can see something ([`Seen`]; conservative resampling only).
    #[inline(always)]
    pub fn seen(&self, line: (DVec3, DVec3)) -> Seen {
        self.how
            .conservative
            .and_then(|bounds| seen_of(line, bounds, self.range))
    }

    /// How slab `slab`'s field answers `line` (`seen`: [`Lines::seen`] of it), and the
    /// samples it reads.
    #[inline(always)]
    pub fn read(&self, slab: usize, (o, d): (DVec3, DVec3), seen: Seen) -> SlabRead {
        let (s, f) = &self.fields[slab];
        let interp = match self.how.interpolate {
            Interpolate::None => (false, false),
            Interpolate::Uv => (true, false),
            Interpolate::St => (false, true),
            Interpolate::UvSt => (true, true),
        };
        let from = self.froms[slab].unwrap_or_else(|| s.from(o));
        let q = if self.how.conservative.is_none() {
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

    /// Whether a read may mark cells: every sample it takes saw at most `trust` cells (always,
    /// under the paper's rule).
    #[inline]
    pub fn trusted(&self, slab: usize, first: [u32; 4], two: u8) -> bool {
        self.how.conservative.is_none()
            || u32::from(most_hits(&self.fields[slab].1, &SlabRead::axes(first, two)))
                <= self.how.trust
    }

    /// Set, in `bits` (made on first use), the bit of every sample a read takes.
    #[inline]
    pub fn set_read(&self, bits: &mut Vec<u64>, slab: usize, first: [u32; 4], two: u8) {
        if bits.is_empty() {
            *bits = vec![0u64; self.base[self.fields.len()].div_ceil(64)];
        }
        let axes = SlabRead::axes(first, two);
        each_sample(&self.fields[slab].1, &axes, |s| {
            let bit = self.base[slab] + s;
            bits[bit / 64] |= 1 << (bit % 64);
        });
    }

    /// The marks of the samples whose bits are set in `bits`, and of the pixels `missed`
    /// (`y * width + x`, and why: in any order).
    pub fn finish(
        &self,
        cell_count: usize,
        bits: &[u64],
        missed: Vec<(usize, Answer)>,
    ) -> Result<Marks> {
        let mut marks = Marks {
            marked: vec![false; cell_count],
            pixels: self.rows * self.cols,
            ..Default::default()
        };
        for (p, a) in missed {
            match a {
                Answer::Outside => marks.outside += 1,
                Answer::Overflowed => marks.overflowed += 1,
            }
            if self.how.conservative.is_some() {
                marks.fallback.push(p);
            }
        }
        // In pixel order, whatever order the rows finished in.
        marks.fallback.sort_unstable();
        let set = bits.iter().enumerate().flat_map(|(i, &word)| {
            (0..64)
                .filter(move |b| word >> b & 1 == 1)
                .map(move |b| i * 64 + b)
        });
        for bit in set {
            let slab = self.base.partition_point(|&b| b <= bit) - 1;
            let f = &self.fields[slab].1;
            let (n, s) = (f.n as usize, bit - self.base[slab]);
            for &id in f.ids[s * n..(s + 1) * n].iter().filter(|&&id| id >= 0) {
                // Checked as read: only the samples a view reads, not the whole field.
                let Some(m) = marks.marked.get_mut(id as usize) else {
                    return input_err!(
                        "the field names cell {id}, but there are {cell_count} cells"
                    );
                };
                *m = true;
            }
        }
        Ok(marks)
    }

    /// Whether slab `slab` may hold a line of `block` ([`SlabFrom::line`]'s tests): each test
    /// is the sign of a function affine in the pixel (the lines' directions are, and so are
    /// their origins in a parallel view; [`super::build::CrossFrom::terms`]) once both planes'
    /// denominators keep their signs over the block, so no line of the block is held when one
    /// of them is negative at all four corners (beyond a margin for rounding).
    pub fn may_hold(&self, slab: usize, [c0, c1, r0, r1]: Block) -> bool {
        let ((x0, y0), (x1, y1)) = (self.pixel(c0, r0), self.pixel(c1, r1));
        let t = &self.terms[slab];
        let corners = [(x0, y0), (x1, y0), (x0, y1), (x1, y1)].map(|(x, y)| t.at(x, y));
        let sign = |den: [f64; 4]| {
            let all = |f: fn(&f64) -> bool| den.iter().all(f);
            (all(|&x| x > 0.0) as i8) - (all(|&x| x < 0.0) as i8)
        };
        let (su, st) = (
            sign(corners.map(|(u, _)| u[0])),
            sign(corners.map(|(_, t)| t[0])),
        );
        if su == 0 || st == 0 {
            return true;
        }
        let (su, st) = (f64::from(su), f64::from(st));
        // Each test as (value, size): held needs value >= 0 (> 0) everywhere it holds. The
        // sizes are the terms' scales over the image, so that the rounding of the terms (and
        // of their affine reading) stays inside the margin.
        let [su0, su1, su2, su3, st0, st1, st2, st3] = t.scale;
        let tests = |(u, t): ([f64; 4], [f64; 4])| {
            [
                (su * u[1], su1),
                (su * (u[0] - u[1]), su0 + su1),
                (su * u[2], su2),
                (su * (u[0] - u[2]), su0 + su2),
                (st * t[1], st1),
                (st * (t[0] - t[1]), st0 + st1),
                (st * t[2], st2),
                (st * (t[0] - t[2]), st0 + st2),
                // The st plane after the uv plane: c_st / den_st > c_uv / den_uv.
                (su * st * (t[3] * u[0] - u[3] * t[0]), st3 * su0 + su3 * st0),
            ]
        };
        let at = corners.map(tests);
        !(0..9).any(|k| at.iter().all(|t| t[k].0 < -1e-9 * t[k].1))
    }

    /// The pixel (`y * width + x`) of resampled pixel (c, r).
    pub fn flat(&self, c: usize, r: usize) -> usize {
        let (x, y) = self.pixel(c, r);
        y * self.size.0 + x
    }
}

/// A slab's [`SlabFrom::terms`] at pixel centres, as the affine functions of the pixel they are
/// ([`Lines::may_hold`]): the values at the first pixel's centre and their steps per pixel
/// across and down, taken over the whole image so that rounding stays far below the tests'
/// margin.
struct PixelTerms {
    at0: [f64; 8],
    dx: [f64; 8],
    dy: [f64; 8],
    /// Each term's largest magnitude over the image.
    scale: [f64; 8],
}

impl PixelTerms {
    fn of(eye: &Projector, slab: &Slab, from: &Option<SlabFrom>, (w, h): (usize, usize)) -> Self {
        let terms = |x: f64, y: f64| {
            let (o, d) = eye.ray_z1(DVec2::new(x + 0.5, y + 0.5));
            let (u, t) = from.unwrap_or_else(|| slab.from(o)).terms(d);
            [u[0], u[1], u[2], u[3], t[0], t[1], t[2], t[3]]
        };
        let (wx, hy) = ((w.max(2) - 1) as f64, (h.max(2) - 1) as f64);
        let (a, b, c) = (terms(0.0, 0.0), terms(wx, 0.0), terms(0.0, hy));
        let (dx, dy): ([f64; 8], [f64; 8]) = (
            std::array::from_fn(|k| (b[k] - a[k]) / wx),
            std::array::from_fn(|k| (c[k] - a[k]) / hy),
        );
        PixelTerms {
            at0: a,
            dx,
            dy,
            scale: std::array::from_fn(|k| a[k].abs() + wx * dx[k].abs() + hy * dy[k].abs()),
        }
    }

    /// The terms at pixel (x, y)'s centre: uv's, then st's.
    #[inline(always)]
    fn at(&self, x: usize, y: usize) -> ([f64; 4], [f64; 4]) {
        let (x, y) = (x as f64, y as f64);
        let v: [f64; 8] = std::array::from_fn(|k| self.at0[k] + x * self.dx[k] + y * self.dy[k]);
        ([v[0], v[1], v[2], v[3]], [v[4], v[5], v[6], v[7]])
    }
}

/// A view's size against the memory limit, and each field's arrays against its dimensions.
fn check(fields: &[(Slab, Samples)], camera: &Camera, how: &Resampling) -> Result<()> {
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
    Ok(())
}

/// The most samples per axis a block's reads may span for [`span_of`]: two overlapping
/// interpolation pairs (wider spans took no less time on khr_cameras).
const SPAN: u32 = 3;

/// The samples, per axis an inclusive range of indices, that every line of a block reads from
/// when its four corners all read (`Reads`), though not the same samples: the (u, v) and
/// (s, t) of a block's lines lie within its corners', so each line's samples lie within the
/// corners' per axis. `None` when a corner does not read, or the span is wider than [`SPAN`]
/// on some axis.
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

/// What the span of a block's corner reads ([`span_of`]) settles for every line of the block,
/// whose reads all lie within it, without reading them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Span {
    /// Every sample in it saw more than `trust` cells: every line reads an untrusted sample,
    /// and the block is held but not answered.
    Untrusted,
    /// Every sample in it is trusted and holds only cells that the corners' reads hold: every
    /// line is answered, and the lines together mark exactly the corners' cells (when the
    /// corners' lines are not answered already, so that their reads count).
    Covered,
    /// Neither: the block is split.
    Unsettled,
}

fn span_case(reads: &[SlabRead; 4], f: &Samples, trust: u32) -> Span {
    let Some(span) = span_of(reads, f) else {
        return Span::Unsettled;
    };
    let mut seen = [false; 2];
    each_in_span(f, &span, |s| {
        let hits = u32::from(f.hits.get(s).copied().unwrap_or(u16::MAX));
        seen[usize::from(hits > trust)] = true;
    });
    match seen {
        [false, true] => return Span::Untrusted,
        [true, false] => {}
        _ => return Span::Unsettled,
    }
    // The corners' cells (a few), then every sample's against them.
    let n = f.n as usize;
    let ids = |s: usize| {
        f.ids[s * n..(s + 1) * n]
            .iter()
            .copied()
            .filter(|&id| id >= 0)
    };
    let mut cells: Vec<i32> = Vec::new();
    for r in reads {
        if let SlabRead::Reads { first, two } = *r {
            each_sample(f, &SlabRead::axes(first, two), |s| cells.extend(ids(s)));
        }
    }
    cells.sort_unstable();
    cells.dedup();
    let mut covered = true;
    each_in_span(f, &span, |s| {
        covered &= ids(s).all(|id| cells.binary_search(&id).is_ok());
    });
    if covered {
        Span::Covered
    } else {
        Span::Unsettled
    }
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

/// A block of resampled pixels: inclusive columns `c0..=c1` and rows `r0..=r1`.
type Block = [usize; 4];

/// A worker's scratch for resampling a band of rows of blocks, kept from one band to the next:
/// per resampled pixel of the band, its state bits, its slab read (current while its stamp is
/// `stamp`, which changes for each slab of each band, so nothing is cleared), and its line's
/// [`Seen`] (current while its stamp is `band`).
struct Band {
    rows: (usize, usize),
    cols: usize,
    state: Vec<u8>,
    reads: Vec<SlabRead>,
    read_stamp: Vec<u32>,
    stamp: u32,
    seen: Vec<Seen>,
    seen_stamp: Vec<u32>,
    band: u32,
    todo: Vec<Block>,
}

impl Band {
    fn new(len: usize) -> Self {
        Band {
            rows: (0, 0),
            cols: 0,
            state: vec![0; len],
            reads: vec![SlabRead::No; len],
            read_stamp: vec![0; len],
            stamp: 0,
            seen: vec![None; len],
            seen_stamp: vec![0; len],
            band: 0,
            todo: Vec::new(),
        }
    }

    /// Start the band of resampled rows `rows` (inclusive), `cols` wide.
    fn start(&mut self, rows: (usize, usize), cols: usize) {
        (self.rows, self.cols) = (rows, cols);
        self.state[..cols * (rows.1 - rows.0 + 1)].fill(0);
        self.band += 1;
    }

    #[inline(always)]
    fn at(&self, c: usize, r: usize) -> usize {
        (r - self.rows.0) * self.cols + c
    }

    /// Whether every pixel of `block` has state bit `bit`.
    fn all(&self, [c0, c1, r0, r1]: Block, bit: u8) -> bool {
        (r0..=r1).all(|r| {
            self.state[self.at(c0, r)..=self.at(c1, r)]
                .iter()
                .all(|s| s & bit != 0)
        })
    }

    /// Give every pixel of `block` the state bits `bits`.
    fn set(&mut self, [c0, c1, r0, r1]: Block, bits: u8) {
        for r in r0..=r1 {
            let (a, b) = (self.at(c0, r), self.at(c1, r));
            self.state[a..=b].iter_mut().for_each(|s| *s |= bits);
        }
    }

    /// Slab `slab`'s reads at the corners of `block` (each pixel's read once per slab).
    #[inline(always)]
    fn corner_reads(
        &mut self,
        lines: &Lines,
        slab: usize,
        [c0, c1, r0, r1]: Block,
    ) -> [SlabRead; 4] {
        let corners = [(c0, r0), (c1, r0), (c0, r1), (c1, r1)];
        let mut reads = [SlabRead::No; 4];
        for (k, &(c, r)) in corners.iter().enumerate() {
            let i = self.at(c, r);
            if self.read_stamp[i] != self.stamp {
                self.read_stamp[i] = self.stamp;
                let line = lines.line(c, r);
                if self.seen_stamp[i] != self.band {
                    self.seen_stamp[i] = self.band;
                    self.seen[i] = lines.seen(line);
                }
                self.reads[i] = lines.read(slab, line, self.seen[i]);
            }
            reads[k] = self.reads[i];
        }
        reads
    }

    /// Queue the four quarters of `block`.
    fn split(&mut self, [c0, c1, r0, r1]: Block) {
        let (cm, rm) = ((c0 + c1) / 2, (r0 + r1) / 2);
        for [a, b] in [[rm + 1, r1], [r0, rm]] {
            for [x, y] in [[cm + 1, c1], [c0, cm]] {
                if a <= b && x <= y {
                    self.todo.push([x, y, a, b]);
                }
            }
        }
    }

    /// The band's pixels that no slab answered.
    fn missed(&self, lines: &Lines, out: &mut Vec<(usize, Answer)>) {
        for r in self.rows.0..=self.rows.1 {
            for c in 0..self.cols {
                let s = self.state[self.at(c, r)];
                if s & ANSWERED == 0 {
                    let why = if s & HELD != 0 {
                        Answer::Overflowed
                    } else {
                        Answer::Outside
                    };
                    out.push((lines.flat(c, r), why));
                }
            }
        }
    }
}

/// Mark the cells `camera` sees through the fields (one per slab): the same marks, pixels
/// left to the fallback and counts as the plain per-pixel resampler ([`super::reference`]),
/// found by blocks.
///
/// Pixels are resampled by blocks rather than one by one, and each slab on its own: the
/// resampled pixels of a block of `BLOCK x BLOCK` whose four corner pixels read the same
/// samples of a slab and get the same answer from it all do, and the block adds those samples'
/// cells once; a block whose corners differ is split in four, down to single pixels. The
/// pinhole projection maps the image linearly onto each slab plane's rectangle (a homography),
/// so the (u, v) and (s, t) of a block's pixels lie within its corners' and the sample indices
/// and the rectangle tests, monotone in them, agree inside when they agree at the corners; so
/// do the tests of the visible range against the planes for a camera outside the bounds, where
/// they always pass. A block whose corners see nothing inside the bounds is split while the
/// bounds' projected outline may reach into it. Taking the slabs one at a time, a block is
/// split only where that slab's samples change, not wherever any of the six slabs' do. What
/// changes is the cost: the field's resolution, not the image's, sets the number of lines
/// read (visibility-field.txt §4 reads the field per pixel on the GPU; on the CPU that was
/// 70-89% of a view). Where a line meets the bounds is worked out once per pixel for all
/// slabs, and whether the samples read are trusted once per block taken.
///
/// With conservative resampling a read that is not trusted marks nothing: its pixel is either
/// answered by another slab's trusted read, which marks what it sees, or traced, and the
/// fallback marks what the ray hits. (Marking the untrusted samples' ids as well drew 1.5-2.3x
/// the visible cells on the Cornell box and khr_simple_instancing; without them, 0.99-1.01x.)
/// A slab reads only the lines that the slabs before it did not answer.
pub fn resample(
    fields: &[(Slab, Samples)],
    cell_count: usize,
    camera: &Camera,
    how: Resampling,
) -> Result<Marks> {
    let lines = Lines::new(fields, camera, how)?;
    let outline = lines.outline();
    let band_len = lines.cols * BLOCK.min(lines.rows);
    let (bits, missed) = (0..lines.rows.div_ceil(BLOCK))
        .into_par_iter()
        .fold(
            || (Vec::new(), Vec::new(), Band::new(band_len)),
            |(mut bits, mut missed, mut band), i| {
                let rows = (i * BLOCK, ((i + 1) * BLOCK).min(lines.rows) - 1);
                band.start(rows, lines.cols);
                for slab in 0..fields.len() {
                    resample_slab(&lines, &outline, &mut band, slab, &mut bits);
                }
                band.missed(&lines, &mut missed);
                (bits, missed, band)
            },
        )
        .map(|(bits, missed, _)| (bits, missed))
        .reduce(RowMarks::default, |(mut a, mut ma), (b, mb)| {
            if a.is_empty() {
                a = b;
            } else if !b.is_empty() {
                a.iter_mut().zip(&b).for_each(|(x, y)| *x |= y);
            }
            ma.extend(mb);
            (a, ma)
        });
    lines.finish(cell_count, &bits, missed)
}

/// One slab's reads over a band's blocks ([`resample`]): each block is skipped (every line
/// answered before), taken whole, or split in four.
fn resample_slab(lines: &Lines, outline: &Outline, b: &mut Band, slab: usize, bits: &mut Vec<u64>) {
    let conservative = lines.how.conservative.is_some();
    let (cols, (r0, r1)) = (lines.cols, b.rows);
    b.stamp += 1;
    b.todo.clear();
    let blocks = (0..cols.div_ceil(BLOCK)).rev();
    b.todo
        .extend(blocks.map(|i| [i * BLOCK, ((i + 1) * BLOCK).min(cols) - 1, r0, r1]));
    while let Some(block) = b.todo.pop() {
        let [c0, c1, r0, r1] = block;
        // A small block (8x8 or less) whose lines earlier slabs all answered needs nothing
        // more (scanning large blocks cost more than it saved; they are scanned before
        // marking, below).
        if conservative && (c1 - c0 + 1) * (r1 - r0 + 1) <= 64 && b.all(block, ANSWERED) {
            continue;
        }
        let reads = b.corner_reads(lines, slab, block);
        let first = reads[0];
        if reads[1..].iter().any(|&r| r != first) {
            let state = if conservative {
                take_span(lines, b, (slab, block), &reads, bits)
            } else {
                None
            };
            match state {
                Some(state) => b.set(block, state),
                None => b.split(block),
            }
            continue;
        }
        // Corners that see nothing, or that the slab does not hold, may surround lines that
        // see something, or that it holds (a far scene within a block).
        let unsure = match first {
            SlabRead::Nothing => outline.may_reach(lines, block),
            SlabRead::No => lines.may_hold(slab, block),
            SlabRead::Reads { .. } => false,
        };
        if unsure && (c0, r0) != (c1, r1) {
            b.split(block);
            continue;
        }
        let state = match first {
            SlabRead::No => continue,
            SlabRead::Nothing => ANSWERED,
            SlabRead::Reads { first, two } => take(lines, b, (slab, block), (first, two), bits),
        };
        b.set(block, state);
    }
}

/// A block whose corners read different samples of slab `slab`, settled by their span
/// ([`span_case`]): its state, and for a covered span whose corner lines no slab answered
/// before, the bits of the corners' samples; `None` when it must be split.
fn take_span(
    lines: &Lines,
    b: &Band,
    (slab, [c0, c1, r0, r1]): (usize, Block),
    reads: &[SlabRead; 4],
    bits: &mut Vec<u64>,
) -> Option<u8> {
    match span_case(reads, &lines.fields[slab].1, lines.how.trust) {
        Span::Untrusted => Some(HELD),
        Span::Covered => {
            let corners = [(c0, r0), (c1, r0), (c0, r1), (c1, r1)];
            if corners
                .iter()
                .any(|&(c, r)| b.state[b.at(c, r)] & ANSWERED != 0)
            {
                return None;
            }
            for r in reads {
                if let SlabRead::Reads { first, two } = *r {
                    lines.set_read(bits, slab, first, two);
                }
            }
            Some(HELD | ANSWERED)
        }
        Span::Unsettled => None,
    }
}

/// A block all of whose lines read `first` and `two` from slab `slab`: its state, and, when
/// the read is trusted, the bits of the samples read, unless slabs before answered every line
/// of the block (those read nothing more; the others all read these samples).
fn take(
    lines: &Lines,
    b: &Band,
    (slab, block): (usize, Block),
    (first, two): ([u32; 4], u8),
    bits: &mut Vec<u64>,
) -> u8 {
    if !lines.trusted(slab, first, two) {
        return HELD;
    }
    if lines.how.conservative.is_none() || !b.all(block, ANSWERED) {
        lines.set_read(bits, slab, first, two);
    }
    HELD | ANSWERED
}

/// The outline the scene's bounds project to in a view, for conservative resampling: a block
/// whose corners' lines all miss the bounds may still hold lines that meet them (a far scene
/// smaller than a block, a flat one seen edge on, a corner of the outline poking in between
/// two block corners) unless it lies outside.
enum Outline {
    /// The paper's rule: lines are not clipped to the bounds.
    Unused,
    /// A corner of the bounds lies behind the camera: any block may reach them.
    Anywhere,
    Hull(Vec<DVec2>),
}

impl Outline {
    /// Whether lines of `block` may meet the bounds.
    fn may_reach(&self, lines: &Lines, [c0, c1, r0, r1]: Block) -> bool {
        let hull = match self {
            Outline::Unused => return false,
            Outline::Anywhere => return true,
            Outline::Hull(hull) => hull,
        };
        let ((a, b), (c, d)) = (lines.pixel(c0, r0), lines.pixel(c1, r1));
        let m = lines.k as f64 + 1.0;
        let lo = DVec2::new(a as f64 - m, b as f64 - m);
        let hi = DVec2::new(c as f64 + 1.0 + m, d as f64 + 1.0 + m);
        polygon_meets_box(hull, lo, hi)
    }
}

impl Lines<'_> {
    fn outline(&self) -> Outline {
        let Some([lo, hi]) = self.how.conservative else {
            return Outline::Unused;
        };
        let mut points = Vec::with_capacity(8);
        for i in 0..8 {
            let p = DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            let (px, z) = self.eye.project(p);
            if !(z > 0.0 && px.is_finite()) {
                return Outline::Anywhere;
            }
            points.push(px);
        }
        Outline::Hull(convex_hull(points))
    }
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
}
