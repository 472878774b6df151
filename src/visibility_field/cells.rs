//! The grid cells of a scene (visibility-field.txt §3.2): its geometry grouped (by object, by
//! connected component of welded vertices, or as a whole), each group's bounding box divided by
//! a grid, each triangle in the cell that holds its centroid, and the scene sorted by cell.

use std::collections::HashMap;

use glam::DVec3;

use crate::error::Result;
use crate::input_err;
use crate::scene::Scene;
use crate::sets::Sets;

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
    // Welded by position, so that split (flat-shaded) vertices still connect.
    let key = crate::scene::adjacency::weld(scene);
    let mut sets = Sets::new(key.iter().max().map_or(0, |&m| m as usize + 1));
    for f in scene.faces() {
        for &i in &f[1..] {
            sets.union(key[f[0] as usize], key[i as usize]);
        }
    }
    let mut label: HashMap<u32, u32> = HashMap::new();
    let groups: Vec<u32> = scene
        .faces()
        .iter()
        .map(|f| {
            let r = sets.find(key[f[0] as usize]);
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
