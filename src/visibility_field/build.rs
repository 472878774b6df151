//! The visibility field (visibility-field.txt §3): which grid cells of the scene's geometry are
//! first hit along the lines of a two-plane parameterization.
//!
//! - Cells (§3.2): every group of geometry (an object, or a connected component when the scene
//!   has a single object, or the scene as a whole) is divided by a grid over its bounding box;
//!   a triangle belongs to the cell holding its centroid, so each triangle is in exactly one
//!   cell. Only non-empty cells get ids, in (group, z, y, x) order; their triangles are listed
//!   cell after cell (CSR).
//! - Slab (§3): a line is given by where it crosses two rectangles, the uv and st planes, in
//!   rectangle coordinates (u, v) and (s, t) in [0, 1)². The field stores the lines running
//!   from the uv plane toward the st plane, and what is first hit between the two planes.
//! - Sampling with pre-filtering (§3.3): sample (iu, iv, is, it) casts `supersample⁴` rays
//!   through a `supersample × supersample` grid of positions in its uv cell and in its st cell
//!   (3 × 3 on each plane → 81 rays) and keeps the `n` cell ids hit most often (ties: the lower
//!   id first), −1 for the rest. The positions are the centres of a regular sub-grid (the
//!   paper's), or with `jitter` a seeded random point in each sub-cell (stratified).

use std::collections::HashMap;
use std::time::Instant;

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;
use crate::types::Timings;

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

/// How geometry is grouped before the grid divides it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Grouping {
    /// Per object (glTF mesh / node); per connected component when the scene has one object.
    Objects,
    /// The scene as a whole.
    Scene,
}

/// The grid cells of a scene (§3.2).
#[derive(Debug, Clone, Default)]
pub struct Cells {
    /// Per triangle, its cell id.
    pub cell_of: Vec<u32>,
    /// Per cell: (group, x, y, z).
    pub table: Vec<[i32; 4]>,
    /// Per cell: the bounds of its grid box (low, high).
    pub bounds: Vec<[[f32; 3]; 2]>,
    /// CSR: the triangles of cell c are `triangles[offsets[c]..offsets[c + 1]]`.
    pub offsets: Vec<u32>,
    pub triangles: Vec<u32>,
    pub groups: usize,
}

/// A scene with its faces sorted by cell, as a field's views draw it: sorted face `i` is the
/// scene's face `order[i]`, and cell `c` holds sorted faces `offsets[c]..offsets[c + 1]`.
#[derive(Debug, Clone, Copy)]
pub struct SortedScene<'a> {
    pub scene: &'a Scene,
    pub order: &'a [u32],
    pub offsets: &'a [u32],
}

impl<'a> SortedScene<'a> {
    /// Checked: one `order` entry per face, and offsets rising from 0 to the face count.
    pub fn new(scene: &'a Scene, order: &'a [u32], offsets: &'a [u32]) -> Result<Self> {
        let faces = scene.triangle_count();
        let rising = offsets.windows(2).all(|w| w[0] <= w[1]);
        if order.len() != faces
            || offsets.first() != Some(&0)
            || offsets.last().map(|&o| o as usize) != Some(faces)
            || !rising
        {
            return input_err!(
                "the cells do not match the cell-sorted scene: {} faces, {} sorted ids, offsets \
                 from {:?} to {:?}",
                faces,
                order.len(),
                offsets.first(),
                offsets.last()
            );
        }
        Ok(SortedScene {
            scene,
            order,
            offsets,
        })
    }

    /// How many cells.
    pub fn cells(&self) -> usize {
        self.offsets.len() - 1
    }

    /// One mark per cell.
    pub fn check_marks(&self, marked: &[bool]) -> Result<()> {
        if marked.len() != self.cells() {
            return input_err!("{} marks for {} cells", marked.len(), self.cells());
        }
        Ok(())
    }
}

/// Group ids per triangle: connected components (triangles sharing a vertex position).
fn components(scene: &Scene) -> (Vec<u32>, usize) {
    let verts = scene.vertices();
    // Weld vertices by exact position, so that split (flat-shaded) vertices still connect.
    let mut weld: HashMap<[u32; 3], u32> = HashMap::with_capacity(verts.len());
    let key: Vec<u32> = verts
        .iter()
        .map(|p| {
            let n = weld.len() as u32;
            *weld.entry(p.map(f32::to_bits)).or_insert(n)
        })
        .collect();
    let mut parent: Vec<u32> = (0..weld.len() as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    for f in scene.faces() {
        let a = find(&mut parent, key[f[0] as usize]);
        for &i in &f[1..] {
            let b = find(&mut parent, key[i as usize]);
            if a != b {
                parent[b as usize] = a;
            }
        }
    }
    let mut label: HashMap<u32, u32> = HashMap::new();
    let groups: Vec<u32> = scene
        .faces()
        .iter()
        .map(|f| {
            let r = find(&mut parent, key[f[0] as usize]);
            let n = label.len() as u32;
            *label.entry(r).or_insert(n)
        })
        .collect();
    let count = label.len();
    (groups, count)
}

/// How many cells divide each group's bounding box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Grid {
    /// The same number along x, y and z of every group.
    Cells([u32; 3]),
    /// Cells about this wide: `ceil(extent / size)` along each axis of each group (at least
    /// one, at most `max` per axis).
    Size { size: f64, max: u32 },
}

impl Grid {
    fn check(&self) -> Result<()> {
        match *self {
            Grid::Cells(grid) => {
                if grid.contains(&0) {
                    return input_err!("grid must be positive along every axis, got {grid:?}");
                }
                if grid.iter().map(|&g| g as u64).product::<u64>() > 1 << 24 {
                    return input_err!("grid {grid:?} has more than 2^24 cells per group");
                }
            }
            Grid::Size { size, max } => {
                if !(size.is_finite() && size > 0.0) || max == 0 || max > 256 {
                    return input_err!(
                        "a cell size must be positive and finite with 1 to 256 cells per axis, \
                         got {size} and {max}"
                    );
                }
            }
        }
        Ok(())
    }

    /// The cells along x, y and z of a group whose bounds are `ext` wide.
    fn dims(&self, ext: DVec3) -> [u32; 3] {
        match *self {
            Grid::Cells(grid) => grid,
            Grid::Size { size, max } => ext
                .to_array()
                .map(|e| ((e / size).ceil() as u32).clamp(1, max)),
        }
    }
}

/// Divide the scene's geometry into cells: `grid` cells along x, y and z of each group's
/// bounding box.
pub fn cells(scene: &Scene, grid: Grid, grouping: Grouping) -> Result<Cells> {
    grid.check()?;
    let n = scene.triangle_count();
    let (group, groups) = match grouping {
        Grouping::Scene => (vec![0u32; n], usize::from(n > 0)),
        Grouping::Objects if scene.objects().len() > 1 => {
            let g: Vec<u32> = scene
                .object_ids()
                .iter()
                .map(|&o| o.max(0) as u32)
                .collect();
            let count = g.iter().map(|&x| x as usize + 1).max().unwrap_or(0);
            (g, count)
        }
        Grouping::Objects => components(scene),
    };
    let centroid = |t: usize| {
        let p = scene.triangle(t);
        (p[0] + p[1] + p[2]) / 3.0
    };
    let mut lo = vec![DVec3::splat(f64::INFINITY); groups];
    let mut hi = vec![DVec3::splat(f64::NEG_INFINITY); groups];
    for (t, f) in scene.faces().iter().enumerate() {
        let g = group[t] as usize;
        for &i in f {
            let p = DVec3::from_array(scene.vertices()[i as usize].map(f64::from));
            lo[g] = lo[g].min(p);
            hi[g] = hi[g].max(p);
        }
    }
    let dims: Vec<[u32; 3]> = (0..groups).map(|g| grid.dims(hi[g] - lo[g])).collect();
    let dims_f = |g: usize| DVec3::from_array(dims[g].map(f64::from));
    // (group, z, y, x) key of every triangle's cell.
    let keys: Vec<(u32, [u32; 3])> = (0..n)
        .map(|t| {
            let g = group[t] as usize;
            let size = (hi[g] - lo[g]).max(DVec3::splat(f64::MIN_POSITIVE));
            let r = ((centroid(t) - lo[g]) / size * dims_f(g)).floor();
            let c = |k: usize| (r[k].max(0.0) as u32).min(dims[g][k] - 1);
            (group[t], [c(0), c(1), c(2)])
        })
        .collect();
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.sort_by_key(|&t| {
        let (g, c) = keys[t as usize];
        (g, c[2], c[1], c[0], t)
    });
    let mut out = Cells {
        cell_of: vec![0; n],
        groups,
        ..Default::default()
    };
    let mut last = None;
    for (k, &t) in order.iter().enumerate() {
        let key = keys[t as usize];
        if last != Some(key) {
            last = Some(key);
            let (g, c) = key;
            let size = (hi[g as usize] - lo[g as usize]) / dims_f(g as usize);
            let cell_lo = lo[g as usize] + size * DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
            out.table
                .push([g as i32, c[0] as i32, c[1] as i32, c[2] as i32]);
            out.bounds.push([
                cell_lo.as_vec3().to_array(),
                (cell_lo + size).as_vec3().to_array(),
            ]);
            out.offsets.push(k as u32);
        }
        out.cell_of[t as usize] = (out.table.len() - 1) as u32;
    }
    out.offsets.push(n as u32);
    out.triangles = order;
    Ok(out)
}

/// A sampled visibility field of one slab.
#[derive(Debug, Clone)]
pub struct Field {
    /// (U, V, S, T).
    pub dims: [u32; 4],
    /// Ids per sample.
    pub n: u32,
    /// (U, V, S, T, n) row-major cell ids, −1 empty.
    pub ids: Vec<i32>,
    /// (U, V, S, T): how many distinct cells each sample's rays hit (at most 65535); more than
    /// `n` means the sample overflowed.
    pub hits: Vec<u16>,
    pub rays: u64,
    pub timings: Timings,
}

/// A field built for a scene ([`build`]): its cells, the cell-sorted scene its views draw
/// (sorted face `i` is the scene's `cells.triangles[i]`), one field per slab, and the seconds
/// spent on the cells and on what the fallback traces.
pub struct Built {
    pub cells: Cells,
    pub sorted: Scene,
    pub fields: Vec<Field>,
    pub cell_seconds: f64,
    pub bvh_seconds: f64,
}

/// The cells of `scene` (§3.2) and a field per slab (§3.3), with `n` ids per sample; and the
/// cell-sorted scene's trace frame, BVH and edge neighbours, which the fallback of every view
/// uses, so that the first view does not pay for them.
#[allow(clippy::too_many_arguments)]
pub fn build(
    scene: &Scene,
    slabs: &[Slab],
    uv: [u32; 2],
    st: [u32; 2],
    grid: Grid,
    grouping: Grouping,
    n: u32,
    supersample: Supersample,
) -> Result<Built> {
    if slabs.is_empty() {
        return input_err!("at least one slab is needed");
    }
    let start = Instant::now();
    let cells = cells(scene, grid, grouping)?;
    let sorted = scene.permuted(&cells.triangles)?;
    let cell_seconds = start.elapsed().as_secs_f64();
    let fields = sample(scene, slabs, uv, st, &cells, n, supersample)?;
    let start = Instant::now();
    let frame = crate::discretize::pixels::TraceFrame::of(&sorted)?;
    crate::trace::Bvh::of(frame.scene(&sorted));
    crate::scene::adjacency::EdgeNeighbours::of(&sorted);
    Ok(Built {
        cells,
        sorted,
        fields,
        cell_seconds,
        bvh_seconds: start.elapsed().as_secs_f64(),
    })
}

/// How a sample's rays are placed in its uv and st cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Supersample {
    /// Positions per axis of each plane's cell (3 → 3 × 3 per plane, 81 rays).
    pub per_axis: u32,
    /// `Some(seed)`: a seeded random point in each sub-cell; `None`: sub-cell centres.
    pub jitter: Option<u64>,
}

/// The `ss²` sub-positions of cell `cell` of a `dims` grid over `rect`: offsets `a(j)` along
/// its first axis (outer) and `b(j)` along its second (inner), in cells.
fn sub_positions(
    rect: &Rect,
    cell: [usize; 2],
    dims: [usize; 2],
    ss: usize,
    a: impl Fn(usize) -> f64,
    b: impl Fn(usize) -> f64,
) -> Vec<DVec3> {
    let mut out = Vec::with_capacity(ss * ss);
    for oa in (0..ss).map(&a) {
        for ob in (0..ss).map(&b) {
            let x = (cell[0] as f64 + oa) / dims[0] as f64;
            let y = (cell[1] as f64 + ob) / dims[1] as f64;
            out.push(rect.point(x, y));
        }
    }
    out
}

/// The rays of one uv sample `(iu, iv)` (§3.3, pre-filtering): from `ss²` sub-positions in
/// its uv cell to `ss²` sub-positions in every st cell, as origins and direction vectors
/// whose end (t = 1) lies on the st plane; `offset(at, j)` places sub-position j of stream `at`.
fn beam_rays(
    slab: &Slab,
    offset: &impl Fn(u64, usize) -> f64,
    dims: [u32; 4],
    ss: usize,
    [iu, iv]: [usize; 2],
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let [du, dv, ds, dt] = dims.map(|d| d as usize);
    let rays_per_uv = ds * dt * ss.pow(4);
    let mut origins = Vec::with_capacity(rays_per_uv);
    let mut dirs = Vec::with_capacity(rays_per_uv);
    for is in 0..ds {
        for it in 0..dt {
            // A distinct stream of jitter per sample and axis.
            let at = ((((iu * dv + iv) * ds + is) * dt + it) * 4) as u64;
            let uv = sub_positions(
                &slab.uv,
                [iu, iv],
                [du, dv],
                ss,
                |j| offset(at, j),
                |j| offset(at + 1, j),
            );
            let st = sub_positions(
                &slab.st,
                [is, it],
                [ds, dt],
                ss,
                |j| offset(at + 2, j),
                |j| offset(at + 3, j),
            );
            for a in &uv {
                for b in &st {
                    origins.push(a.as_vec3().to_array());
                    dirs.push((*b - *a).as_vec3().to_array());
                }
            }
        }
    }
    (origins, dirs)
}

/// Ranks the cells one sample's rays hit (§3.3: the cells seen most often first, ties by
/// cell index) and writes the first `out.len()` of them; returns how many distinct cells were
/// hit (more than `out.len()`: the sample overflowed, a line in its beam may see a cell it
/// does not list).
fn rank_cells(tris: &[i32], cell_of: &[u32], out: &mut [i32]) -> u16 {
    let mut hit: Vec<u32> = tris
        .iter()
        .filter(|&&t| t >= 0)
        .map(|&t| cell_of[t as usize])
        .collect();
    hit.sort_unstable();
    let mut counts: Vec<(usize, u32)> = Vec::new();
    for c in hit {
        match counts.last_mut() {
            Some((k, last)) if *last == c => *k += 1,
            _ => counts.push((1, c)),
        }
    }
    counts.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    for (slot, &(_, c)) in out.iter_mut().zip(&counts) {
        *slot = c as i32;
    }
    counts.len().min(u16::MAX as usize) as u16
}

/// Sample the field of each slab (§3.3): `uv` and `st` samples per plane, `n` ids per sample.
pub fn sample(
    scene: &Scene,
    slabs: &[Slab],
    uv: [u32; 2],
    st: [u32; 2],
    cells: &Cells,
    n: u32,
    supersample: Supersample,
) -> Result<Vec<Field>> {
    let dims = [uv[0], uv[1], st[0], st[1]];
    let per_axis = supersample.per_axis;
    if dims.contains(&0) || n == 0 || per_axis == 0 {
        return input_err!(
            "uv {uv:?}, st {st:?}, ids_per_sample {n} and supersample {per_axis} must all be \
             positive"
        );
    }
    if cells.cell_of.len() != scene.triangle_count() {
        return input_err!("the cells were made for another scene");
    }
    let samples: u64 = dims.iter().map(|&d| d as u64).product();
    let per_sample = (per_axis as u64).pow(4);
    // Ids as i32 and an overflow flag per sample; one uv sample's rays at a time.
    crate::limits::check(
        || {
            format!(
                "a field of {} slabs x {dims:?} samples x {n} ids",
                slabs.len()
            )
        },
        crate::limits::product(&[slabs.len() as u64, samples, n as u64]),
        5,
    )?;
    if samples * n as u64 > 1 << 31 || samples * per_sample > 1 << 36 {
        return input_err!(
            "{samples} samples x {n} ids ({per_sample} rays each) is too large a field"
        );
    }
    // Progress in slab samples (iu, iv, is, it) of every slab.
    crate::process::add_total(samples * slabs.len() as u64);
    slabs
        .iter()
        .map(|slab| sample_slab(scene, slab, dims, cells, n, supersample))
        .collect()
}

/// One slab's field (checked by [`sample`]).
fn sample_slab(
    scene: &Scene,
    slab: &Slab,
    dims: [u32; 4],
    cells: &Cells,
    n: u32,
    supersample: Supersample,
) -> Result<Field> {
    let Supersample {
        per_axis: supersample,
        jitter,
    } = supersample;
    let total = Instant::now();
    let samples: u64 = dims.iter().map(|&d| d as u64).product();
    let per_sample = (supersample as u64).pow(4);
    let ss = supersample as usize;
    // The offset of sub-position j along one axis of one plane in sample `at`.
    let offset = |at: u64, j: usize| -> f64 {
        let r = match jitter {
            Some(seed) => {
                let h = crate::discretize::epr::mix64(
                    seed ^ crate::discretize::epr::mix64(at * ss as u64 + j as u64),
                );
                (h >> 11) as f64 / (1u64 << 53) as f64
            }
            None => 0.5,
        };
        (j as f64 + r) / ss as f64
    };
    let [du, dv, ds, dt] = dims.map(|d| d as usize);
    let mut ids = vec![-1i32; samples as usize * n as usize];
    let mut hit_counts = vec![0u16; samples as usize];
    let mut cast_seconds = 0.0;
    let mut rank_seconds = 0.0;
    // One uv sample at a time: its (S·T·ss⁴) rays in one batch.
    let st_count = ds * dt;
    // One (iu, iv) row of samples per progress step.
    for iu in 0..du {
        for iv in 0..dv {
            crate::process::check()?;
            crate::process::advance(st_count as u64);
            let start = Instant::now();
            let (origins, dirs) = beam_rays(slab, &offset, dims, ss, [iu, iv]);
            let hits = crate::trace::cast_rays(scene, &origins, &dirs, 0.0, 1.0)?;
            cast_seconds += start.elapsed().as_secs_f64();
            let start = Instant::now();
            let per = ss.pow(4);
            let row = (iu * dv + iv) * st_count;
            let base = row * n as usize;
            ids[base..base + st_count * n as usize]
                .par_chunks_mut(n as usize)
                .zip(hit_counts[row..row + st_count].par_iter_mut())
                .zip(hits.triangle.par_chunks(per))
                .for_each(|((out, count), tris)| *count = rank_cells(tris, &cells.cell_of, out));
            rank_seconds += start.elapsed().as_secs_f64();
        }
    }
    Ok(Field {
        dims,
        n,
        ids,
        hits: hit_counts,
        rays: samples * per_sample,
        timings: Timings::from([
            ("rays", cast_seconds),
            ("rank", rank_seconds),
            ("total", total.elapsed().as_secs_f64()),
        ]),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad(z: f32, size: f32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        (
            vec![
                [-size, -size, z],
                [size, -size, z],
                [size, size, z],
                [-size, size, z],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    /// Two square quads parallel to z = 0, each given as (z, half side), in one scene.
    fn two_quads(a: [f32; 2], b: [f32; 2]) -> Scene {
        let (mut v, mut f) = quad(a[0], a[1]);
        let (v2, f2) = quad(b[0], b[1]);
        f.extend(f2.iter().map(|t| t.map(|i| i + v.len() as u32)));
        v.extend(v2);
        Scene::from_arrays(v, f, None, None).unwrap()
    }

    #[test]
    fn lines_cross_the_slab_one_way() {
        let r = |z| Rect::new(DVec3::new(-1.0, -1.0, z), DVec3::X * 2.0, DVec3::Y * 2.0).unwrap();
        let slab = Slab {
            uv: r(0.0),
            st: r(1.0),
        };
        let q = slab
            .line(DVec3::new(0.0, 0.0, -1.0), DVec3::new(0.1, 0.0, 1.0))
            .unwrap();
        assert!(
            (q[0] - 0.55).abs() < 1e-12 && (q[2] - 0.6).abs() < 1e-12,
            "{q:?}"
        );
        // Backwards, parallel, outside.
        assert!(slab
            .line(DVec3::new(0.0, 0.0, 2.0), DVec3::new(0.0, 0.0, -1.0))
            .is_none());
        assert!(slab.line(DVec3::new(0.0, 0.0, 0.5), DVec3::X).is_none());
        assert!(slab.line(DVec3::new(5.0, 0.0, -1.0), DVec3::Z).is_none());
    }

    #[test]
    fn a_wall_hides_what_is_behind_it_from_every_line() {
        let scene = two_quads([0.3, 10.0], [0.6, 0.2]);
        let r = |z| Rect::new(DVec3::new(-1.0, -1.0, z), DVec3::X * 2.0, DVec3::Y * 2.0).unwrap();
        let slab = Slab {
            uv: r(0.0),
            st: r(1.0),
        };
        let c = cells(&scene, Grid::Cells([2, 2, 2]), Grouping::Objects).unwrap();
        assert_eq!(c.groups, 2);
        let hidden: Vec<i32> = (0..c.table.len())
            .filter(|&k| c.table[k][0] == c.table[c.cell_of[2] as usize][0])
            .map(|k| k as i32)
            .collect();
        let ss = Supersample {
            per_axis: 2,
            jitter: None,
        };
        let field = sample(&scene, &[slab], [4, 4], [4, 4], &c, 3, ss)
            .unwrap()
            .remove(0);
        let jittered = Supersample {
            jitter: Some(7),
            ..ss
        };
        let again = sample(&scene, &[slab], [4, 4], [4, 4], &c, 3, jittered)
            .unwrap()
            .remove(0);
        assert!(again.ids.iter().all(|id| !hidden.contains(id)));
        assert!(field.ids.iter().all(|id| !hidden.contains(id)));
        assert!(field.ids.iter().any(|&id| id >= 0));
        assert_eq!(field.rays, 4u64.pow(4) * 16);
    }

    #[test]
    fn six_slabs_hold_every_line_through_the_bounds() {
        let scene = two_quads([0.0, 1.0], [0.5, 0.3]);
        let slabs = Slab::six(&scene, 0.05).unwrap();
        assert_eq!(slabs.len(), 6);
        let [lo, hi] = scene.bounds_f64();
        let mut seed = 1u64;
        let mut rand = || {
            seed = crate::discretize::epr::mix64(seed);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..2000 {
            // A point in the bounds, a direction, and an origin outside the bounds behind it.
            let p = lo + (hi - lo) * DVec3::new(rand(), rand(), rand());
            let d = DVec3::new(rand() - 0.5, rand() - 0.5, rand() - 0.5).normalize();
            let o = p - d * 10.0;
            let (a, b) = clip_line(o, d, [lo, hi]).unwrap();
            let held = slabs
                .iter()
                .filter(|s| s.answers(o, d, [a, b], a).is_some());
            assert!(held.count() >= 1, "{o} {d}");
        }
        // From inside the bounds nothing behind the camera may be answered.
        let o = (lo + hi) / 2.0;
        let d = DVec3::new(0.1, 0.2, 1.0);
        let (a, b) = clip_line(o, d, [lo, hi]).unwrap();
        assert!(slabs.iter().all(|s| s.answers(o, d, [0.0, b], a).is_none()));
        assert!(clip_line(DVec3::new(5.0, 5.0, 5.0), DVec3::X, [lo, hi]).is_none());
    }

    #[test]
    fn cells_partition_the_triangles() {
        let (v, f) = quad(0.0, 1.0);
        let scene = Scene::from_arrays(v, f, None, None).unwrap();
        let c = cells(&scene, Grid::Cells([4, 4, 1]), Grouping::Scene).unwrap();
        assert_eq!(c.offsets.last(), Some(&2));
        let mut all = c.triangles.clone();
        all.sort();
        assert_eq!(all, vec![0, 1]);
        for (t, &cell) in c.cell_of.iter().enumerate() {
            let range = c.offsets[cell as usize]..c.offsets[cell as usize + 1];
            assert!(c.triangles[range.start as usize..range.end as usize].contains(&(t as u32)));
        }
    }
}
