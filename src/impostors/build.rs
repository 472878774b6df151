//! Multi-cell orthographic impostors (multi-cell-orthographic-impostors.txt §3.1, §4.3).
//!
//! - Cells: the scene's bounding box made cubic is the octree's root; the cells are its
//!   non-empty leaves at `depth` (2^depth per axis). A triangle is in a cell when it overlaps
//!   the cell's box (separating-axis test); for drawing a cell as triangles, each triangle is
//!   given to the one cell holding its centroid, so nothing is drawn twice.
//! - Views: the face centres of an icosahedron subdivided `subdivisions` times (20·4^s
//!   directions: 320 for s = 2), around each cell's circumscribed sphere (§3.1).
//! - Images: for each cell and direction, a `resolution²` image of the cell seen from that
//!   direction: orthographic (the paper's choice; the view spans the sphere's diameter) or
//!   perspective with field of view `fov` from `radius / sin(fov/2)`. Rays are cast on the CPU
//!   through a BVH of only the cell's triangles: with `grow` every triangle that intersects the
//!   cell's bounding sphere, whole (§4.3, "filling the gap"); without it the triangles
//!   overlapping the box, each ray clipped to the box, so only the geometry inside the cell is
//!   seen. A texel holds the lit colour of what it sees (`lit`, view-independent, so that one
//!   image serves every viewer on its side) and its camera-space depth. Every image is cropped
//!   to the bounding rectangle of its covered texels.

use std::time::Instant;

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use crate::camera::{Camera, Projection};
use crate::error::Result;
use crate::input_err;
use crate::scene::surface::{Footprint, Surfaces};
use crate::scene::Scene;
use crate::shading::{self, Prelit};
use crate::trace::cast_rays;
use crate::types::Timings;

/// The colour a surface point is drawn with, by impostor images and triangles alike: the
/// package's shading model, view-independent (`shading::diffuse`: ambient plus two-sided
/// Lambert of the base colour under `env`, `normal` the shading normal).
pub fn lit(color: [f32; 3], normal: DVec3, position: DVec3, env: &Prelit) -> [f32; 3] {
    let s = shading::Surface {
        position,
        normal,
        albedo: DVec3::from_array(color.map(f64::from)),
        metallic: 0.0,
        roughness: 1.0,
    };
    shading::diffuse(&s, env).as_vec3().to_array()
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ImpostorProjection {
    Orthographic,
    /// Field of view (radians) of the camera at `radius / sin(fov / 2)`.
    Perspective(f64),
}

#[derive(Debug, Clone)]
pub struct ImpostorOptions {
    pub depth: u32,
    pub subdivisions: u32,
    pub resolution: u32,
    pub projection: ImpostorProjection,
    pub grow: bool,
}

/// One octree leaf.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cell {
    pub lo: DVec3,
    pub size: f64,
    /// Leaf coordinates (x, y, z) in 0..2^depth.
    pub index: [u32; 3],
}

impl Cell {
    pub fn center(&self) -> DVec3 {
        self.lo + DVec3::splat(self.size / 2.0)
    }
    /// Radius of the circumscribed sphere.
    pub fn radius(&self) -> f64 {
        self.size * 3f64.sqrt() / 2.0
    }
}

#[derive(Debug, Clone, Default)]
pub struct Impostors {
    pub cells: Vec<Cell>,
    pub directions: Vec<DVec3>,
    pub resolution: u32,
    /// Per (cell, direction): x0, y0, width, height of the content in the full image.
    pub crops: Vec<[u32; 4]>,
    /// Stored image size: the largest crop.
    pub height: usize,
    pub width: usize,
    /// (C, D, height, width) RGBA8: each crop at the top left, alpha 255 where covered.
    pub color: Vec<[u8; 4]>,
    /// (C, D, height, width) camera-space depth, +inf where empty.
    pub depth: Vec<f32>,
    /// Triangles in each cell's images.
    pub triangle_counts: Vec<u32>,
    /// CSR by centroid: the triangles that draw each cell as geometry.
    pub offsets: Vec<u32>,
    pub triangles: Vec<u32>,
    /// The scene's vertex count: a view checks that the scene it is given is the one the
    /// impostors were made from.
    pub vertices: usize,
    pub rays: u64,
    pub timings: Timings,
}

/// Unit directions to the face centres of an icosahedron subdivided `s` times (20·4^s).
pub fn icosahedron_directions(s: u32) -> Vec<DVec3> {
    let (v, f) = crate::scene::shapes::icosahedron();
    let mut tris: Vec<[DVec3; 3]> = f.iter().map(|t| t.map(|i| v[i as usize])).collect();
    for _ in 0..s {
        tris = tris
            .iter()
            .flat_map(|&[a, b, c]| {
                let (ab, bc, ca) = (
                    (a + b).normalize(),
                    (b + c).normalize(),
                    (c + a).normalize(),
                );
                [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
            })
            .collect();
    }
    tris.iter()
        .map(|[a, b, c]| (*a + *b + *c).normalize())
        .collect()
}

/// Does the triangle overlap the axis-aligned box (centre `c`, half size `h`)? The separating
/// axis test of Akenine-Möller: box axes, the triangle's normal, and the 9 edge cross products.
pub fn triangle_box_overlap(p: &[DVec3; 3], c: DVec3, h: f64) -> bool {
    let v = p.map(|x| x - c);
    let hv = DVec3::splat(h);
    // Box axes.
    let lo = v[0].min(v[1]).min(v[2]);
    let hi = v[0].max(v[1]).max(v[2]);
    if lo.cmpgt(hv).any() || hi.cmplt(-hv).any() {
        return false;
    }
    let e = [v[1] - v[0], v[2] - v[1], v[0] - v[2]];
    let separated = |axis: DVec3| {
        if axis.length_squared() <= 1e-30 {
            return false;
        }
        let r = h * (axis.x.abs() + axis.y.abs() + axis.z.abs());
        let d = v.map(|x| x.dot(axis));
        let (mn, mx) = (d[0].min(d[1]).min(d[2]), d[0].max(d[1]).max(d[2]));
        mn > r || mx < -r
    };
    if separated(e[0].cross(e[1])) {
        return false;
    }
    for ei in e {
        for a in [DVec3::X, DVec3::Y, DVec3::Z] {
            if separated(a.cross(ei)) {
                return false;
            }
        }
    }
    true
}

/// Distance from `c` to the triangle (closest point), for the sphere test.
fn sphere_overlap(p: &[DVec3; 3], c: DVec3, r: f64) -> bool {
    crate::trace::points::point_triangle_distance(c, p) <= r
}

/// The octree's leaves: the root box's low corner, the leaf size, the non-empty leaves, and the
/// triangles overlapping each.
struct Leaves {
    root: DVec3,
    leaf: f64,
    cells: Vec<Cell>,
    in_box: Vec<Vec<u32>>,
}

/// The non-empty leaves at `depth` of the octree over the scene's cubic bounds.
fn octree(scene: &Scene, depth: u32) -> Leaves {
    let [lo, hi] = scene.bounds_f64();
    let size = (hi - lo).max_element().max(scene.diagonal() * 1e-9);
    let centre = (lo + hi) / 2.0;
    let root = centre - DVec3::splat(size / 2.0);
    let n = 1u32 << depth;
    let leaf = size / n as f64;
    // Candidate leaves of each triangle from its bounding box, then the exact overlap test.
    let per_tri: Vec<Vec<u32>> = (0..scene.triangle_count())
        .into_par_iter()
        .map(|t| {
            let p = scene.triangle(t);
            let a = p[0].min(p[1]).min(p[2]);
            let b = p[0].max(p[1]).max(p[2]);
            let cell = |x: DVec3| {
                ((x - root) / leaf)
                    .floor()
                    .clamp(DVec3::ZERO, DVec3::splat((n - 1) as f64))
            };
            let (i0, i1) = (cell(a), cell(b));
            let mut out = Vec::new();
            for z in i0.z as u32..=i1.z as u32 {
                for y in i0.y as u32..=i1.y as u32 {
                    for x in i0.x as u32..=i1.x as u32 {
                        let c = root + (DVec3::new(x as f64, y as f64, z as f64) + 0.5) * leaf;
                        if triangle_box_overlap(&p, c, leaf / 2.0 * (1.0 + 1e-9)) {
                            out.push((z * n + y) * n + x);
                        }
                    }
                }
            }
            out
        })
        .collect();
    let mut by_leaf: std::collections::BTreeMap<u32, Vec<u32>> = Default::default();
    for (t, leaves) in per_tri.iter().enumerate() {
        for &l in leaves {
            by_leaf.entry(l).or_default().push(t as u32);
        }
    }
    let mut cells = Vec::new();
    let mut tris = Vec::new();
    for (l, ts) in by_leaf {
        let (x, y, z) = (l % n, (l / n) % n, l / (n * n));
        cells.push(Cell {
            lo: root + DVec3::new(x as f64, y as f64, z as f64) * leaf,
            size: leaf,
            index: [x, y, z],
        });
        tris.push(ts);
    }
    Leaves {
        root,
        leaf,
        cells,
        in_box: tris,
    }
}

/// The camera of cell `cell`'s image along direction `d` (looking along −d).
pub fn impostor_camera(
    cell: &Cell,
    d: DVec3,
    res: u32,
    projection: ImpostorProjection,
) -> Result<Camera> {
    let (c, r) = (cell.center(), cell.radius());
    let up = if d.z.abs() < 0.9 { DVec3::Z } else { DVec3::Y };
    match projection {
        ImpostorProjection::Orthographic => {
            // Far enough that the sphere lies in front; the view spans its diameter.
            let eye = c + d * (2.0 * r);
            let pose = crate::camera::look_at_pose(eye, c, up)?;
            let projection = Projection::Orthographic { xmag: r, ymag: r };
            Camera::new(pose, projection, res, res, Some(r * 1e-3), Some(4.0 * r))
        }
        ImpostorProjection::Perspective(fov) => {
            let dist = r / (fov / 2.0).sin();
            Camera::look_at(c + d * dist, c, up, fov, res, res, None, None)
        }
    }
}

/// The options [`build`] accepts, and a scene it can build from.
fn check_options(scene: &Scene, opts: &ImpostorOptions) -> Result<()> {
    if opts.depth > 10 {
        return input_err!("octree depth {} is too deep (at most 10)", opts.depth);
    }
    if opts.subdivisions > 5 {
        return input_err!(
            "subdivisions {} gives too many views (at most 5)",
            opts.subdivisions
        );
    }
    if opts.resolution == 0 || opts.resolution > 4096 {
        return input_err!("resolution must be in 1..=4096, got {}", opts.resolution);
    }
    if let ImpostorProjection::Perspective(fov) = opts.projection {
        if !(fov > 0.0 && fov < std::f64::consts::PI) {
            return input_err!("fov must be in (0, pi) radians, got {fov}");
        }
    }
    if scene.triangle_count() == 0 {
        return input_err!("the scene has no triangles");
    }
    Ok(())
}

/// The triangles each cell draws as geometry, by centroid so each once: the triangle ids
/// sorted by cell, and each cell's offset into them (CSR).
fn triangles_by_centroid(
    scene: &Scene,
    depth: u32,
    root: DVec3,
    leaf: f64,
    cells: &[Cell],
    in_box: &[Vec<u32>],
) -> (Vec<u32>, Vec<u32>) {
    let centroid_cell: Vec<usize> = {
        let lookup: std::collections::HashMap<[u32; 3], usize> = cells
            .iter()
            .enumerate()
            .map(|(i, c)| (c.index, i))
            .collect();
        let n = 1u32 << depth;
        (0..scene.triangle_count())
            .map(|t| {
                let p = scene.triangle(t);
                let k = (((p[0] + p[1] + p[2]) / 3.0 - root) / leaf)
                    .floor()
                    .clamp(DVec3::ZERO, DVec3::splat((n - 1) as f64));
                let key = [k.x as u32, k.y as u32, k.z as u32];
                // A centroid may fall in a leaf the triangle does not overlap only through
                // rounding; then any cell it overlaps takes it.
                lookup.get(&key).copied().unwrap_or_else(|| {
                    in_box
                        .iter()
                        .position(|ts| ts.binary_search(&(t as u32)).is_ok())
                        .unwrap_or(0)
                })
            })
            .collect()
    };
    let mut order: Vec<u32> = (0..scene.triangle_count() as u32).collect();
    order.sort_by_key(|&t| (centroid_cell[t as usize], t));
    let mut offsets = vec![0u32; cells.len() + 1];
    for &t in &order {
        offsets[centroid_cell[t as usize] + 1] += 1;
    }
    for i in 0..cells.len() {
        offsets[i + 1] += offsets[i];
    }
    (order, offsets)
}

/// Every image's rays for `cell`: clipped to the cell's box without `grow`.
fn cell_rays(cams: &[Camera], cell: &Cell, res: usize, grow: bool) -> Vec<ImageRays> {
    let (lo, hi) = (cell.lo, cell.lo + DVec3::splat(cell.size));
    cams.par_iter()
        .map(|cam| {
            let mut o = Vec::with_capacity(res * res);
            let mut dir = Vec::with_capacity(res * res);
            let mut t0 = Vec::with_capacity(res * res);
            for y in 0..res {
                for x in 0..res {
                    let (org, d) = cam.ray_z1(DVec2::new(x as f64 + 0.5, y as f64 + 0.5));
                    let (a, b) = if grow {
                        (0.0, 1e30)
                    } else {
                        slab_range(org, d, lo, hi)
                    };
                    if b <= a {
                        // Misses the box: cast anyway (one batch), its hit ignored.
                        o.push(org.as_vec3().to_array());
                        dir.push(d.as_vec3().to_array());
                        t0.push(f64::INFINITY);
                    } else if grow {
                        o.push(org.as_vec3().to_array());
                        dir.push(d.as_vec3().to_array());
                        t0.push(0.0);
                    } else {
                        o.push((org + d * a).as_vec3().to_array());
                        dir.push((d * (b - a)).as_vec3().to_array());
                        t0.push(a);
                    }
                }
            }
            (o, dir, t0)
        })
        .collect()
}

/// Images cropped to their covered texels, all stored at the largest crop's size.
struct Cropped {
    /// Per image: x, y, width, height of its crop in the full image (all 0 when empty).
    crops: Vec<[u32; 4]>,
    width: usize,
    height: usize,
    color: Vec<[u8; 4]>,
    depth: Vec<f32>,
}

/// Crop every `res`² image of `full_color` / `full_depth` to its covered texels.
fn crop(full_color: &[[u8; 4]], full_depth: &[f32], res: usize) -> Cropped {
    let crops: Vec<[u32; 4]> = full_color
        .par_chunks(res * res)
        .map(|img| {
            let (mut x0, mut y0, mut x1, mut y1) = (res, res, 0, 0);
            for (k, px) in img.iter().enumerate() {
                if px[3] > 0 {
                    let (x, y) = (k % res, k / res);
                    x0 = x0.min(x);
                    y0 = y0.min(y);
                    x1 = x1.max(x + 1);
                    y1 = y1.max(y + 1);
                }
            }
            if x1 == 0 {
                [0, 0, 0, 0]
            } else {
                [x0 as u32, y0 as u32, (x1 - x0) as u32, (y1 - y0) as u32]
            }
        })
        .collect();
    let width = crops
        .iter()
        .map(|c| c[2] as usize)
        .max()
        .unwrap_or(0)
        .max(1);
    let height = crops
        .iter()
        .map(|c| c[3] as usize)
        .max()
        .unwrap_or(0)
        .max(1);
    let mut color = vec![[0u8; 4]; crops.len() * height * width];
    let mut depth = vec![f32::INFINITY; crops.len() * height * width];
    color
        .par_chunks_mut(height * width)
        .zip(depth.par_chunks_mut(height * width))
        .enumerate()
        .for_each(|(i, (col, dep))| {
            let [x0, y0, w, h] = crops[i].map(|v| v as usize);
            for y in 0..h {
                for x in 0..w {
                    let src = i * res * res + (y0 + y) * res + x0 + x;
                    col[y * width + x] = full_color[src];
                    dep[y * width + x] = full_depth[src];
                }
            }
        });
    Cropped {
        crops,
        width,
        height,
        color,
        depth,
    }
}

/// The colour and depth of every uncropped image (`cells x views` images of `res²` texels)
/// within the memory limit.
fn check_images(cells: usize, views: usize, res: usize) -> Result<()> {
    crate::limits::check(
        || format!("{cells} cells x {views} views x {res}x{res} texels of impostor images"),
        crate::limits::product(&[cells as u64, views as u64, res as u64, res as u64]),
        8,
    )
}

/// Render every cell's images (§3.1 step 4).
pub fn build(scene: &Scene, opts: &ImpostorOptions) -> Result<Impostors> {
    let total = Instant::now();
    check_options(scene, opts)?;
    let start = Instant::now();
    let Leaves {
        root,
        leaf,
        cells,
        in_box,
    } = octree(scene, opts.depth);
    let directions = icosahedron_directions(opts.subdivisions);
    let (order, offsets) = triangles_by_centroid(scene, opts.depth, root, leaf, &cells, &in_box);
    let cell_seconds = start.elapsed().as_secs_f64();

    let res = opts.resolution as usize;
    let d_count = directions.len();
    check_images(cells.len(), d_count, res)?;
    let start = Instant::now();
    let mut full_color = vec![[0u8; 4]; cells.len() * d_count * res * res];
    let mut full_depth = vec![f32::INFINITY; cells.len() * d_count * res * res];
    let mut counts = Vec::with_capacity(cells.len());
    let mut rays = 0u64;
    let verts = scene.vertices();
    let surfaces = scene.surfaces();
    let lights = Prelit::of(scene);
    crate::process::add_total(cells.len() as u64);
    for (ci, cell) in cells.iter().enumerate() {
        crate::process::check()?;
        crate::process::advance(1);
        // An image spans the cell's sphere: what one texel covers on the surface.
        let texel_side = 2.0 * cell.radius() / res as f64;
        let set = if opts.grow {
            triangles_in_sphere(scene, cell)
        } else {
            in_box[ci].clone()
        };
        counts.push(set.len() as u32);
        let faces: Vec<[u32; 3]> = set.iter().map(|&t| scene.faces()[t as usize]).collect();
        let sub = Scene::from_arrays(verts.to_vec(), faces, None, Some(scene.colors().to_vec()))?;
        let cams = directions
            .iter()
            .map(|&d| impostor_camera(cell, d, opts.resolution, opts.projection))
            .collect::<Result<Vec<_>>>()?;
        let per_image = cell_rays(&cams, cell, res, opts.grow);
        let origins: Vec<[f32; 3]> = per_image.iter().flat_map(|p| p.0.iter().copied()).collect();
        let dirs: Vec<[f32; 3]> = per_image.iter().flat_map(|p| p.1.iter().copied()).collect();
        let t_max = if opts.grow { f32::MAX } else { 1.0 };
        let hits = cast_rays(&sub, &origins, &dirs, 0.0, t_max)?;
        rays += origins.len() as u64;
        let base = ci * d_count * res * res;
        full_color[base..base + d_count * res * res]
            .par_chunks_mut(res * res)
            .zip(full_depth[base..base + d_count * res * res].par_chunks_mut(res * res))
            .enumerate()
            .for_each(|(di, (col, dep))| {
                for k in 0..res * res {
                    let i = di * res * res + k;
                    let Ok(local) = usize::try_from(hits.triangle[i]) else {
                        continue;
                    };
                    if per_image[di].2[k].is_infinite() {
                        continue;
                    }
                    let t = set[local] as usize;
                    let uv = hits.barycentric[i].map(f64::from);
                    let footprint = Footprint::World(texel_side);
                    (col[k], dep[k]) = texel((&surfaces, &lights), t, uv, footprint, &cams[di]);
                }
            });
    }
    let render_seconds = start.elapsed().as_secs_f64();

    // Crop every image to its covered texels.
    let start = Instant::now();
    let Cropped {
        crops,
        width,
        height,
        color,
        depth,
    } = crop(&full_color, &full_depth, res);
    let crop_seconds = start.elapsed().as_secs_f64();
    Ok(Impostors {
        cells,
        directions,
        resolution: opts.resolution,
        crops,
        height,
        width,
        color,
        depth,
        triangle_counts: counts,
        offsets,
        triangles: order,
        vertices: scene.vertices().len(),
        rays,
        timings: Timings::from([
            ("cells", cell_seconds),
            ("render", render_seconds),
            ("crop", crop_seconds),
            ("total", total.elapsed().as_secs_f64()),
        ]),
    })
}

/// One image's rays: origins, directions, and where each starts along its pixel ray (+inf:
/// the ray misses the cell and its hit is ignored).
type ImageRays = (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<f64>);

/// The triangles that reach into the sphere around a cell (the grown cells' triangle set).
fn triangles_in_sphere(scene: &Scene, cell: &Cell) -> Vec<u32> {
    let (c, r) = (cell.center(), cell.radius());
    (0..scene.triangle_count() as u32)
        .into_par_iter()
        .filter(|&t| sphere_overlap(&scene.triangle(t as usize), c, r))
        .collect()
}

/// One impostor texel: triangle `t` hit at barycentric `(u, v)`, its colour (sampled over the
/// texel's `footprint`) lit with its shading normal under the pre-lit environment (8-bit RGBA),
/// and the hit's depth along `cam`.
fn texel(
    (surfaces, lights): (&Surfaces, &Prelit),
    t: usize,
    [u, v]: [f64; 2],
    footprint: Footprint,
    cam: &Camera,
) -> ([u8; 4], f32) {
    let base = surfaces.color(t, [u, v], footprint);
    let p = surfaces.scene().triangle(t);
    let p_hit = p[0] * (1.0 - u - v) + p[1] * u + p[2] * v;
    let normal = DVec3::from_array(surfaces.shading_normal(t, [u, v]).map(f64::from));
    let c = lit(base, normal, p_hit, lights);
    (
        [to8(c[0]), to8(c[1]), to8(c[2]), 255],
        cam.project(p_hit).1 as f32,
    )
}

fn to8(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The parameter range [a, b] of the ray `o + t·d` inside the box (empty when b <= a).
fn slab_range(o: DVec3, d: DVec3, lo: DVec3, hi: DVec3) -> (f64, f64) {
    let (mut a, mut b) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..3 {
        if d[k].abs() < 1e-300 {
            if o[k] < lo[k] || o[k] > hi[k] {
                return (1.0, 0.0);
            }
            continue;
        }
        let (t0, t1) = ((lo[k] - o[k]) / d[k], (hi[k] - o[k]) / d[k]);
        a = a.max(t0.min(t1));
        b = b.min(t0.max(t1));
    }
    (a.max(0.0), b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosahedron_views_are_unit_and_spread() {
        for s in 0..3 {
            let d = icosahedron_directions(s);
            assert_eq!(d.len(), 20 * 4usize.pow(s));
            assert!(d.iter().all(|v| (v.length() - 1.0).abs() < 1e-12));
            let mean = d.iter().copied().sum::<DVec3>() / d.len() as f64;
            assert!(mean.length() < 1e-9, "{mean}");
        }
    }

    #[test]
    fn triangle_box_overlap_cases() {
        let p = [DVec3::ZERO, DVec3::X, DVec3::Y];
        assert!(triangle_box_overlap(&p, DVec3::new(0.2, 0.2, 0.0), 0.1));
        assert!(!triangle_box_overlap(&p, DVec3::new(0.2, 0.2, 0.5), 0.1));
        // Beyond the hypotenuse: only the edge-cross-product axis separates it.
        assert!(!triangle_box_overlap(&p, DVec3::new(0.7, 0.7, 0.0), 0.1));
        assert!(triangle_box_overlap(&p, DVec3::new(0.5, 0.5, 0.0), 0.1));
    }
}
