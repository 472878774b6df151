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

use super::build::Slab;
use super::lines::{each_sample, sample_index, Answer, Block, Lines, Seen, SlabRead};
pub use super::lines::{Interpolate, Marks, Resampling, Samples};
use crate::camera::Camera;
use crate::error::Result;
use crate::scene::Scene;

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
