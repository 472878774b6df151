//! A slab (visibility-field.txt §3): two rectangles, the uv and st planes, and the lines that
//! cross them, with where a line from an eye crosses them and where a line meets a box.

use glam::{DVec2, DVec3};

use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;

/// A rectangle: the points `origin + a·u + b·v` for `a, b` in [0, 1].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    pub origin: DVec3,
    pub u: DVec3,
    pub v: DVec3,
    /// The unit normal and the Gram matrix's (u·u, u·v, v·v, determinant), made once: a view
    /// crosses every slab's two planes with each pixel's line.
    normal: DVec3,
    gram: [f64; 4],
}

impl Rect {
    pub fn new(origin: DVec3, u: DVec3, v: DVec3) -> Result<Self> {
        if !(origin.is_finite() && u.is_finite() && v.is_finite()) {
            return input_err!("a slab rectangle needs a finite origin and edges");
        }
        let n = u.cross(v).length();
        if n.is_nan() || n <= 1e-12 * u.length() * v.length() || n == 0.0 {
            return input_err!("a slab rectangle's edges must be non-zero and not parallel");
        }
        let (uu, uv, vv) = (u.dot(u), u.dot(v), v.dot(v));
        Ok(Self {
            origin,
            u,
            v,
            normal: u.cross(v).normalize(),
            gram: [uu, uv, vv, uu * vv - uv * uv],
        })
    }

    pub fn point(&self, a: f64, b: f64) -> DVec3 {
        self.origin + self.u * a + self.v * b
    }

    pub fn normal(&self) -> DVec3 {
        self.normal
    }

    /// Where the line `o + λ·d` crosses the rectangle's plane: (λ, rectangle coordinates).
    /// `None` when the line runs parallel to the plane (within 1e-12 of its length).
    pub fn cross(&self, o: DVec3, d: DVec3) -> Option<(f64, DVec2)> {
        self.from(o).cross(d)
    }

    /// The crossings of the lines through `o` ([`CrossFrom`]).
    pub fn from(&self, o: DVec3) -> CrossFrom {
        // p = a·u + b·v solved with the Gram matrix: a = p·ga, b = p·gb.
        let [uu, uv, vv, det] = self.gram;
        let ga = (self.u * vv - self.v * uv) / det;
        let gb = (self.v * uu - self.u * uv) / det;
        let q = o - self.origin;
        CrossFrom {
            normal: self.normal,
            c: -q.dot(self.normal),
            ga,
            gb,
            a0: q.dot(ga),
            b0: q.dot(gb),
        }
    }
}

/// [`Rect::cross`] for the lines through one point `o`, with what depends only on `o` worked
/// out once: a pinhole view crosses each plane with the lines through its eye, and
/// `o + λ·d - origin` has coordinates `a0 + λ·(d·ga)`, `b0 + λ·(d·gb)` with `λ = c / (d·n)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CrossFrom {
    normal: DVec3,
    c: f64,
    ga: DVec3,
    gb: DVec3,
    a0: f64,
    b0: f64,
}

impl CrossFrom {
    /// Where the line through the point along `d` crosses the plane (see [`Rect::cross`]).
    #[inline]
    pub fn cross(&self, d: DVec3) -> Option<(f64, DVec2)> {
        let dn = d.dot(self.normal);
        if dn * dn <= 1e-24 * d.length_squared() {
            return None;
        }
        let lambda = self.c / dn;
        let a = self.a0 + lambda * d.dot(self.ga);
        let b = self.b0 + lambda * d.dot(self.gb);
        (lambda.is_finite() && a.is_finite() && b.is_finite()).then_some((lambda, DVec2::new(a, b)))
    }

    /// The crossing as four terms affine in `d` (and in the point, for lines parallel to
    /// each other): the denominator `d·n`, the rectangle coordinates times it, and the plane's
    /// offset `c`, so that λ = c / (d·n) and (a, b) = (terms[1], terms[2]) / (d·n).
    #[inline]
    pub fn terms(&self, d: DVec3) -> [f64; 4] {
        let dn = d.dot(self.normal);
        [
            dn,
            self.a0 * dn + self.c * d.dot(self.ga),
            self.b0 * dn + self.c * d.dot(self.gb),
            self.c,
        ]
    }
}

/// Two rectangles parameterizing lines (§3): uv first, st second.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slab {
    pub uv: Rect,
    pub st: Rect,
}

impl Slab {
    /// The slab around `scene`: planes perpendicular to `axis` (default: the bounds' longest),
    /// uv a `margin` (fraction of the scene's extent along the axis, at least 1e-3 of its
    /// diagonal) before the bounds' low side, st as far beyond the high side; both rectangles
    /// cover the bounds' cross-section widened on every side by `widen` times the bounds'
    /// longest extent, so that oblique and perspective rays that cross the scene (even a flat
    /// one) still cross both planes.
    pub fn around(scene: &Scene, axis: Option<usize>, margin: f64, widen: f64) -> Result<Self> {
        let [lo, hi] = scene.bounds_f64();
        let ext = hi - lo;
        let axis = match axis {
            Some(a) if a < 3 => a,
            Some(a) => return input_err!("axis must be 0, 1 or 2, got {a}"),
            None => {
                if ext.x >= ext.y && ext.x >= ext.z {
                    0
                } else if ext.y >= ext.z {
                    1
                } else {
                    2
                }
            }
        };
        if !(margin.is_finite() && margin >= 0.0 && widen.is_finite() && widen >= 0.0) {
            return input_err!("margin and widen must be finite and >= 0");
        }
        let (a1, a2) = ((axis + 1) % 3, (axis + 2) % 3);
        let floor = 1e-3 * scene.diagonal();
        let gap = (margin * ext[axis]).max(floor);
        let e = |k: usize| DVec3::AXES[k];
        let pad = widen * ext.max_element();
        let side = |k: usize| (ext[k] + 2.0 * pad).max(floor);
        let corner = |along: f64| {
            let mut c = lo - e(a1) * pad - e(a2) * pad;
            c[axis] = along;
            c
        };
        let rect = |along| Rect::new(corner(along), e(a1) * side(a1), e(a2) * side(a2));
        Ok(Self {
            uv: rect(lo[axis] - gap)?,
            st: rect(hi[axis] + gap)?,
        })
    }

    /// The six slabs that answer every camera outside the scene's bounds (the several slabs of
    /// visibility-field.txt §6 that "cover visibility from all viewpoints"): both directions
    /// along each axis, planes `margin` of the extent along it (at least 1e-3 of the diagonal)
    /// beyond the bounds. A line whose direction is nearest to an axis makes at most 45° with it,
    /// so it crosses each plane within the axis's extent plus the gaps of the bounds' cross-
    /// section: the rectangles are widened by that much on every side, and every line through
    /// the bounds lies in the slab of its dominant axis and direction.
    pub fn six(scene: &Scene, margin: f64) -> Result<Vec<Self>> {
        if !(margin.is_finite() && margin >= 0.0) {
            return input_err!("margin must be finite and >= 0, got {margin}");
        }
        let [lo, hi] = scene.bounds_f64();
        let ext = hi - lo;
        let floor = 1e-3 * scene.diagonal();
        let e = |k: usize| DVec3::AXES[k];
        let mut out = Vec::with_capacity(6);
        for axis in 0..3 {
            let (a1, a2) = ((axis + 1) % 3, (axis + 2) % 3);
            let gap = (margin * ext[axis]).max(floor);
            let pad = ext[axis] + 2.0 * gap;
            let rect = |along: f64| {
                let mut c = lo - (e(a1) + e(a2)) * pad;
                c[axis] = along;
                let side = |k: usize| (ext[k] + 2.0 * pad).max(floor);
                Rect::new(c, e(a1) * side(a1), e(a2) * side(a2))
            };
            let (low, high) = (rect(lo[axis] - gap)?, rect(hi[axis] + gap)?);
            out.push(Self { uv: low, st: high });
            out.push(Self { uv: high, st: low });
        }
        Ok(out)
    }

    /// The line coordinates (u, v, s, t) of the ray `o + λ·d`, when it crosses the uv plane
    /// before the st plane (so that it runs the way the field was sampled) and both inside
    /// their rectangles; `None` otherwise (parallel to a plane, backwards, or outside).
    pub fn line(&self, o: DVec3, d: DVec3) -> Option<[f64; 4]> {
        self.from(o).line(d)
    }

    /// The line coordinates of the ray `o + λ·d` when this slab's answer is what the ray sees:
    /// everything the ray can see lies on `seen` = `[from, to]` (its visible range clipped to
    /// the scene's bounds) and `box_from` is where the whole line enters the bounds. The field
    /// stores the first surface between the planes, so the visible range must lie between
    /// them, and no surface may lie on the line between the uv plane and the near end of the
    /// visible range (behind the camera, or nearer than its near plane).
    pub fn answers(&self, o: DVec3, d: DVec3, seen: [f64; 2], box_from: f64) -> Option<[f64; 4]> {
        self.from(o).answers(d, seen, box_from)
    }

    /// [`Slab::line`] and [`Slab::answers`] for the lines through `o`.
    pub fn from(&self, o: DVec3) -> SlabFrom {
        SlabFrom {
            uv: self.uv.from(o),
            st: self.st.from(o),
        }
    }
}

/// A slab's planes crossed by the lines through one point ([`Slab::from`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlabFrom {
    uv: CrossFrom,
    st: CrossFrom,
}

impl SlabFrom {
    /// See [`Slab::line`].
    #[inline]
    pub fn line(&self, d: DVec3) -> Option<[f64; 4]> {
        self.crossing(d).map(|(q, _)| q)
    }

    /// [`SlabFrom::line`] and where (λ) the ray crosses the uv and st planes.
    #[inline]
    fn crossing(&self, d: DVec3) -> Option<([f64; 4], [f64; 2])> {
        let (l_uv, uv) = self.uv.cross(d)?;
        let (l_st, st) = self.st.cross(d)?;
        if l_st <= l_uv {
            return None;
        }
        let q = [uv.x, uv.y, st.x, st.y];
        q.iter()
            .all(|x| (0.0..1.0).contains(x))
            .then_some((q, [l_uv, l_st]))
    }

    /// Both planes' [`CrossFrom::terms`] for the line along `d`: uv's, then st's.
    #[inline]
    pub fn terms(&self, d: DVec3) -> ([f64; 4], [f64; 4]) {
        (self.uv.terms(d), self.st.terms(d))
    }

    /// See [`Slab::answers`].
    #[inline]
    pub fn answers(&self, d: DVec3, seen: [f64; 2], box_from: f64) -> Option<[f64; 4]> {
        let (q, [l_uv, l_st]) = self.crossing(d)?;
        let [from, to] = seen;
        let nothing_before = l_uv >= from || box_from >= from;
        (l_uv <= from && to <= l_st && nothing_before).then_some(q)
    }
}

/// Where the line `o + λ·d` (every λ) lies inside the box `[lo, hi]`: `(λ in, λ out)`, `None`
/// when it misses it.
pub fn clip_line(o: DVec3, d: DVec3, [lo, hi]: [DVec3; 2]) -> Option<(f64, f64)> {
    let (mut a, mut b) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..3 {
        if d[k] == 0.0 {
            if o[k] < lo[k] || o[k] > hi[k] {
                return None;
            }
            continue;
        }
        let (t0, t1) = ((lo[k] - o[k]) / d[k], (hi[k] - o[k]) / d[k]);
        a = a.max(t0.min(t1));
        b = b.min(t0.max(t1));
    }
    (a <= b).then_some((a, b))
}
