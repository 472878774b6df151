//! A view's pixel lines as the resamplers read them (visibility-field.txt §4): which pixels are
//! resampled, where each one's line crosses each slab's planes, what it can see inside the
//! scene's bounds, and which samples of each slab's field it reads. [`resample`](super::resample)
//! reads them by blocks, [`reference`](super::reference) one pixel at a time.

use glam::{DVec2, DVec3};

use super::build::{clip_line, Field, Slab, SlabFrom};
use crate::camera::{Camera, Projection, Projector};
use crate::error::Result;
use crate::input_err;

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
pub(super) fn around(x: f64, n: u32, both: bool) -> ([u32; 2], usize) {
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
pub(super) fn sample_index([_, dv, ds, dt]: [u32; 4], [iu, iv, is, it]: [u32; 4]) -> usize {
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

/// A block of resampled pixels: inclusive columns `c0..=c1` and rows `r0..=r1`.
pub(super) type Block = [usize; 4];

/// The samples one line reads from a slab's field: per axis, the indices and how many.
pub(super) type Axes = [([u32; 2], usize); 4];

/// The samples around the line `q`: the one holding it and, per `interpolate` (uv, st), its
/// neighbours.
pub(super) fn axes_of(f: &Samples, q: [f64; 4], (do_uv, do_st): (bool, bool)) -> Axes {
    let [du, dv, ds, dt] = f.dims;
    [
        around(q[0], du, do_uv),
        around(q[1], dv, do_uv),
        around(q[2], ds, do_st),
        around(q[3], dt, do_st),
    ]
}

/// `g` of the index of every sample in `axes`.
pub(super) fn each_sample(f: &Samples, axes: &Axes, mut g: impl FnMut(usize)) {
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
pub(super) fn most_hits(f: &Samples, axes: &Axes) -> u16 {
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
    pub(super) fn reads(axes: &Axes) -> Self {
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
    pub(super) fn axes(first: [u32; 4], two: u8) -> Axes {
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

pub(super) fn seen_of((o, d): (DVec3, DVec3), bounds: [DVec3; 2], range: (f64, f64)) -> Seen {
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
    pub(super) k: usize,
    size: (usize, usize),
    pub cols: usize,
    pub rows: usize,
    pub(super) eye: Projector,
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
    pub(super) fn of(
        eye: &Projector,
        slab: &Slab,
        from: &Option<SlabFrom>,
        (w, h): (usize, usize),
    ) -> Self {
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
    pub(super) fn at(&self, x: usize, y: usize) -> ([f64; 4], [f64; 4]) {
        let (x, y) = (x as f64, y as f64);
        let v: [f64; 8] = std::array::from_fn(|k| self.at0[k] + x * self.dx[k] + y * self.dy[k]);
        ([v[0], v[1], v[2], v[3]], [v[4], v[5], v[6], v[7]])
    }
}

/// A view's size against the memory limit, and each field's arrays against its dimensions.
pub(super) fn check(fields: &[(Slab, Samples)], camera: &Camera, how: &Resampling) -> Result<()> {
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
}
