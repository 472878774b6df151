//! Pixel-centre rays and the f64 resolve that every depth image shares (non-redundant-rendering
//! §3: a sample is the exact point where a pixel-centre ray meets the triangle the pixel sees):
//! the rays of a camera ([`PixelRays`]), rounded to f32 for the ray caster in the frame it
//! casts in ([`TraceFrame`]), and each triangle's plane ([`SurfacePlane`]), which turns a
//! pixel's triangle id into depth, position, normal and colour. Conventional images, peeling,
//! the raster rule's edge settling and the visibility field's views all take them from here.

use std::sync::Arc;
use std::time::Instant;

use glam::{DVec3, Vec3};

use crate::scene::surface::{Corners, Footprint, Surfaces};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::limits::huge_pages;
use crate::scene::Scene;
use crate::trace::Query;
use crate::types::{DepthImages, Timings};

/// Every triangle's [`SurfacePlane`], in face order: a scene's cached resolve data.
pub(crate) struct ScenePlanes(pub Vec<SurfacePlane>);

impl std::ops::Deref for ScenePlanes {
    type Target = [SurfacePlane];
    fn deref(&self) -> &[SurfacePlane] {
        &self.0
    }
}

/// Every pixel-centre ray of `cam` in `frame` (origin on the camera, direction with camera z
/// −1, so `t` is the depth), rounded to f32 for the ray caster, row-major.
pub(crate) fn pixel_rays_f32(cam: &Camera, frame: &TraceFrame) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let rays = PixelRays::new(cam);
    (0..cam.width as usize * cam.height as usize)
        .into_par_iter()
        .map(|p| ray_f32(&rays, cam, frame, p))
        .unzip()
}

/// [`pixel_rays_f32`] of the pixels `pixels` (row-major indices) only.
pub(crate) fn pixel_rays_f32_at(
    cam: &Camera,
    frame: &TraceFrame,
    pixels: &[usize],
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let rays = PixelRays::new(cam);
    pixels
        .par_iter()
        .map(|&p| ray_f32(&rays, cam, frame, p))
        .unzip()
}

/// Pixel `p`'s ray as [`pixel_rays_f32`] gives it.
#[inline]
fn ray_f32(rays: &PixelRays, cam: &Camera, frame: &TraceFrame, p: usize) -> ([f32; 3], [f32; 3]) {
    let w = cam.width as usize;
    let (o, d) = rays.ray(p % w, p / w);
    (
        (o - frame.shift).as_vec3().to_array(),
        d.as_vec3().to_array(),
    )
}

/// Where the CPU backend casts its rays. A scene far from the origin (its centre farther than
/// its diagonal) is traced in a copy centred on the origin, as the GPU path rasterizes it
/// relative to its centre: float32 ray origins and vertices then keep the precision of the
/// scene's own extent instead of its distance from the origin. The copy (and its BVH) is made
/// once and kept on the scene.
pub(crate) struct TraceFrame {
    centred: Option<Scene>,
    pub(crate) shift: DVec3,
}

impl TraceFrame {
    pub(crate) fn of(scene: &Scene) -> Result<Arc<TraceFrame>> {
        let centre = scene.center();
        if centre.length() <= scene.diagonal() {
            return Ok(scene.derived(|| TraceFrame {
                centred: None,
                shift: DVec3::ZERO,
            }));
        }
        let mut failed = None;
        let frame = scene.derived(|| {
            let vertices = scene
                .vertices()
                .iter()
                .map(|v| {
                    (Vec3::from_array(*v).as_dvec3() - centre)
                        .as_vec3()
                        .to_array()
                })
                .collect();
            match Scene::from_arrays(vertices, scene.faces().to_vec(), None, None) {
                Ok(s) => TraceFrame {
                    centred: Some(s),
                    shift: centre,
                },
                Err(e) => {
                    failed = Some(e);
                    TraceFrame {
                        centred: None,
                        shift: DVec3::ZERO,
                    }
                }
            }
        });
        match failed {
            Some(e) => Err(e),
            None => Ok(frame),
        }
    }

    /// The scene the rays are cast in: the centred copy, or `scene` itself.
    pub(crate) fn scene<'a>(&'a self, scene: &'a Scene) -> &'a Scene {
        self.centred.as_ref().unwrap_or(scene)
    }
}

/// Where a camera's pixel rays meet a scene on the CPU: the frame they are cast in
/// ([`TraceFrame`]) and the camera's near and far planes around the scene's bounds. Worked out
/// once per view and shared by every pass that traces it.
pub(crate) struct ViewRays {
    pub frame: Arc<TraceFrame>,
    pub near: f64,
    pub far: f64,
}

impl ViewRays {
    pub(crate) fn of(scene: &Scene, cam: &Camera) -> Result<Self> {
        let (near, far) = cam.clip_range(scene.bounds());
        Ok(ViewRays {
            frame: TraceFrame::of(scene)?,
            near,
            far,
        })
    }

    /// The range of `t` the rays accept: from the near plane to the far one (in f32, as the
    /// GPU's depth range).
    pub(crate) fn range(&self) -> Query {
        Query::new(self.near as f32, (self.far as f32).max(self.near as f32))
    }

    /// The pixel-centre rays of `pixels` (row-major indices), as [`pixel_rays_f32_at`].
    pub(crate) fn at(&self, cam: &Camera, pixels: &[usize]) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
        pixel_rays_f32_at(cam, &self.frame, pixels)
    }

    /// The scene the rays are cast in (`TraceFrame::scene`).
    pub(crate) fn target<'a>(&'a self, scene: &'a Scene) -> &'a Scene {
        self.frame.scene(scene)
    }
}

/// Depth images from per-pixel triangle ids (row-major, image after image, −1 where empty):
/// every field resolved in f64 from the pixel-centre ray and the triangle, as for conventional
/// images. Returns the images and the resolve time.
pub(crate) fn resolve_ids(
    scene: &Scene,
    cameras: &[Camera],
    ids: Vec<i32>,
) -> Result<(DepthImages, f64)> {
    let start = Instant::now();
    let planes = SurfacePlane::of(scene);
    let mut img = DepthImages::allocate(cameras)?;
    let rays: Vec<PixelRays> = cameras.iter().map(PixelRays::new).collect();
    let n = ids.len();
    img.triangle = ids;
    resolve_into(&mut img, 0..n, &rays, &planes, &scene.surfaces());
    Ok((img, start.elapsed().as_secs_f64()))
}

/// Per-camera constants of the pixel-centre rays (see `Camera::ray_z1`): the ray through pixel
/// (x, y) is `origin(x, y) + t·dir(x, y)` with camera-space z of `dir` equal to −1, so `t` is
/// the depth.
pub(crate) struct PixelRays {
    eye: DVec3,
    /// World-space steps per pixel along x and y, and the ray at pixel (0, 0)'s corner.
    dx: DVec3,
    dy: DVec3,
    corner: DVec3,
    orthographic: bool,
    forward: DVec3,
}

impl PixelRays {
    pub(crate) fn new(cam: &Camera) -> Self {
        let (o00, d00) = cam.ray_z1(glam::DVec2::ZERO);
        let (o10, d10) = cam.ray_z1(glam::DVec2::X);
        let (o01, d01) = cam.ray_z1(glam::DVec2::Y);
        let orthographic = matches!(
            cam.projection,
            crate::camera::Projection::Orthographic { .. }
        );
        if orthographic {
            Self {
                eye: o00,
                dx: o10 - o00,
                dy: o01 - o00,
                corner: o00,
                orthographic,
                forward: d00,
            }
        } else {
            Self {
                eye: o00,
                dx: d10 - d00,
                dy: d01 - d00,
                corner: d00,
                orthographic,
                forward: cam.forward(),
            }
        }
    }

    pub(crate) fn ray(&self, x: usize, y: usize) -> (DVec3, DVec3) {
        self.ray_at(x as f64 + 0.5, y as f64 + 0.5)
    }

    /// The ray through image point `(x, y)` in pixels from the top-left corner (pixel centres
    /// at half-integers).
    pub(crate) fn ray_at(&self, x: f64, y: f64) -> (DVec3, DVec3) {
        let p = self.corner + self.dx * x + self.dy * y;
        if self.orthographic {
            (p, self.forward)
        } else {
            (self.eye, p)
        }
    }
}

impl DepthImages {
    /// Output buffers for one image per camera. Zeroed allocations are lazily mapped pages: the
    /// resolve pass is the first and only writer of every pixel (misses included).
    /// Zeroed images for `cameras`; an error, not an abort, when the host cannot hold them.
    pub(crate) fn allocate(cameras: &[Camera]) -> Result<Self> {
        let (w, h) = (cameras[0].width, cameras[0].height);
        let total = w as usize * h as usize * cameras.len();
        let bytes = total as u128 * 56;
        let too_big = || {
            Error::GpuLimit(format!(
                "{} images of {w}x{h} need {bytes} bytes of host memory, which could not be \
                 allocated; use fewer or smaller images",
                cameras.len()
            ))
        };
        // Probe once for the whole amount, then allocate with `vec!`, whose zeroed memory comes
        // from the kernel lazily (filling it here would double the cost of large images).
        let mut probe: Vec<u8> = Vec::new();
        probe
            .try_reserve_exact(usize::try_from(bytes).map_err(|_| too_big())?)
            .map_err(|_| too_big())?;
        drop(probe);
        let img = Self {
            n: cameras.len(),
            width: w,
            height: h,
            depth: vec![0.0; total],
            triangle: vec![0; total],
            normal: vec![[0.0; 3]; total],
            shading_normal: vec![[0.0; 3]; total],
            position: vec![[0.0; 3]; total],
            color: vec![[0.0; 3]; total],
            cameras: cameras.to_vec(),
            method: "conventional".into(),
            timings: Timings::new(),
        };
        huge_pages(&img.depth);
        huge_pages(&img.triangle);
        for field in [&img.normal, &img.shading_normal, &img.position, &img.color] {
            huge_pages(field);
        }
        Ok(img)
    }
}

/// One pixel's outputs, each a slot of its image's field.
struct Pixel<'a> {
    depth: &'a mut f32,
    position: &'a mut [f32; 3],
    normal: &'a mut [f32; 3],
    shading_normal: &'a mut [f32; 3],
    color: &'a mut [f32; 3],
}

/// Resolve the pixels `range` (whole rows) of `img` from their triangle ids, parallel over rows.
pub(crate) fn resolve_into(
    img: &mut DepthImages,
    range: std::ops::Range<usize>,
    rays: &[PixelRays],
    planes: &[SurfacePlane],
    surfaces: &Surfaces,
) {
    let (w, h) = (img.width as usize, img.height as usize);
    let first_row = range.start / w;
    let ids = &img.triangle[range.clone()];
    img.depth[range.clone()]
        .par_chunks_mut(w)
        .zip(img.position[range.clone()].par_chunks_mut(w))
        .zip(img.normal[range.clone()].par_chunks_mut(w))
        .zip(img.shading_normal[range.clone()].par_chunks_mut(w))
        .zip(img.color[range].par_chunks_mut(w))
        .enumerate()
        .for_each(|(r, ((((depth, pos), nrm), shading), col))| {
            let row = first_row + r;
            let cam = &rays[row / h];
            for x in 0..w {
                let px = Pixel {
                    depth: &mut depth[x],
                    position: &mut pos[x],
                    normal: &mut nrm[x],
                    shading_normal: &mut shading[x],
                    color: &mut col[x],
                };
                resolve_one(ids[r * w + x], cam, (x, row % h), planes, surfaces, px);
            }
        });
}

/// Pixel (x, y) of one image, seeing triangle `id` (−1: nothing): the exact point where the
/// pixel-centre ray meets the triangle's plane, and what the surface is there (its colour for
/// the pixel's footprint, from the neighbouring pixels' rays on the same plane).
#[inline(always)]
fn resolve_one(
    id: i32,
    cam: &PixelRays,
    (x, y): (usize, usize),
    planes: &[SurfacePlane],
    surfaces: &Surfaces,
    px: Pixel,
) {
    let Ok(t) = usize::try_from(id) else {
        *px.depth = f32::INFINITY;
        *px.position = [f32::NAN; 3];
        *px.normal = [0.0; 3];
        *px.shading_normal = [0.0; 3];
        *px.color = [0.0; 3];
        return;
    };
    let plane = &planes[t];
    let (o, d) = cam.ray(x, y);
    let s = plane.intersect(o, d, cam.forward);
    *px.depth = s.depth as f32;
    *px.position = s.point.as_vec3().to_array();
    *px.normal = plane.normal.as_vec3().to_array();
    *px.shading_normal = plane.corners.shading_normal(s.b);
    // Only a texture's lookup needs the footprint.
    let footprint = if plane.corners.textured() {
        plane.footprint(cam, (x, y), s.unclamped)
    } else {
        Footprint::Point
    };
    *px.color = surfaces.color_of(&plane.corners, s.b, footprint);
}

/// Give the pixels `changed` (flat indices over all images) of resolved images `img` the
/// triangle ids `ids` holds for them, and resolve those pixels again; every other pixel is
/// kept. The same values as [`resolve_ids`] over everything, at the cost of the few pixels.
pub(crate) fn resolve_pixels(
    scene: &Scene,
    cameras: &[Camera],
    img: &mut DepthImages,
    ids: &[i32],
    changed: &[usize],
) -> f64 {
    let start = Instant::now();
    let planes = SurfacePlane::of(scene);
    let surfaces = scene.surfaces();
    let rays: Vec<PixelRays> = cameras.iter().map(PixelRays::new).collect();
    let (w, h) = (img.width as usize, img.height as usize);
    for &p in changed {
        img.triangle[p] = ids[p];
        let (i, y, x) = (p / (w * h), p / w % h, p % w);
        let px = Pixel {
            depth: &mut img.depth[p],
            position: &mut img.position[p],
            normal: &mut img.normal[p],
            shading_normal: &mut img.shading_normal[p],
            color: &mut img.color[p],
        };
        resolve_one(ids[p], &rays[i], (x, y), &planes, &surfaces, px);
    }
    start.elapsed().as_secs_f64()
}

/// Per-triangle data for resolving pixels, in f64: a corner, the unit normal and the gradients
/// of the barycentrics over the plane. Computed once per scene (cached on it), so a pixel costs
/// a few dot products on one contiguous record; what the surface looks like there comes from
/// the scene's [`Surfaces`].
#[derive(Debug, Clone)]
pub(crate) struct SurfacePlane {
    a: DVec3,
    normal: DVec3,
    /// b1 = (p − a)·g1 and b2 = (p − a)·g2 for a point p on the plane.
    g1: DVec3,
    g2: DVec3,
    /// Degenerate triangles have no plane: their centroid stands in.
    centroid: Option<DVec3>,
    /// The corners' colours and shading normals.
    corners: Corners,
}

impl SurfacePlane {
    fn new(surfaces: &Surfaces, i: usize) -> Self {
        let scene = surfaces.scene();
        let [a, b, c] = scene.triangle(i);
        let (e1, e2) = (b - a, c - a);
        let n = e1.cross(e2);
        let nn = n.length_squared();
        let degenerate = scene.is_degenerate(i) || nn == 0.0 || !nn.is_finite();
        Self {
            a,
            normal: if degenerate {
                DVec3::ZERO
            } else {
                n / nn.sqrt()
            },
            g1: if degenerate {
                DVec3::ZERO
            } else {
                e2.cross(n) / nn
            },
            g2: if degenerate {
                DVec3::ZERO
            } else {
                n.cross(e1) / nn
            },
            centroid: degenerate.then(|| (a + b + c) / 3.0),
            corners: Corners::of(surfaces, i),
        }
    }

    /// The scene's planes, built in parallel on first use and cached on the scene.
    pub(crate) fn of(scene: &Scene) -> Arc<ScenePlanes> {
        scene.derived(|| {
            let surfaces = scene.surfaces();
            ScenePlanes(
                (0..scene.triangle_count())
                    .into_par_iter()
                    .map(|i| Self::new(&surfaces, i))
                    .collect(),
            )
        })
    }

    /// The `t` at which the ray `o + t·d` meets the plane (the depth, when camera-space z of `d`
    /// is −1); not finite for an edge-on or degenerate triangle.
    pub(crate) fn ray_depth(&self, o: DVec3, d: DVec3) -> f64 {
        self.normal.dot(self.a - o) / self.normal.dot(d)
    }

    /// Where the ray `o + t·d` (camera-space z of `d` is −1, so `t` is depth) meets the plane.
    /// The rasteriser said the triangle covers this pixel centre, so the ray meets the plane
    /// unless the triangle is edge-on or degenerate; then the centroid stands in.
    fn intersect(&self, o: DVec3, d: DVec3, forward: DVec3) -> SurfacePoint {
        let t = self.ray_depth(o, d);
        let (point, depth, b1, b2) = match self.centroid {
            Some(c) => (c, (c - o).dot(forward), 1.0 / 3.0, 1.0 / 3.0),
            None if t.is_finite() => {
                let p = o + d * t;
                let r = p - self.a;
                (p, t, r.dot(self.g1), r.dot(self.g2))
            }
            None => {
                let c = self.a;
                (c, (c - o).dot(forward), 0.0, 0.0)
            }
        };
        // Clamped to the triangle for the attributes (a pixel the raster rule gave to the
        // triangle may lie a rounding outside it).
        let (c1, c2) = (b1.clamp(0.0, 1.0), b2.clamp(0.0, 1.0));
        let s = (c1 + c2).max(1.0);
        SurfacePoint {
            depth,
            point,
            b: [c1 / s, c2 / s],
            unclamped: [b1, b2],
        }
    }

    /// The barycentrics `(b1, b2)` where the ray `o + t·d` meets the plane, not clamped;
    /// `None` for a degenerate or edge-on triangle.
    fn barycentrics(&self, o: DVec3, d: DVec3) -> Option<[f64; 2]> {
        if self.centroid.is_some() {
            return None;
        }
        let t = self.ray_depth(o, d);
        let r = o + d * t - self.a;
        let b = [r.dot(self.g1), r.dot(self.g2)];
        (t.is_finite() && b[0].is_finite() && b[1].is_finite()).then_some(b)
    }

    /// The footprint of pixel `(x, y)` (whose centre's ray meets the plane at barycentrics `b`)
    /// on this triangle: the change of the barycentrics to the next pixel's centre along x and
    /// along y, their rays met on the same plane (ray differentials, exact for a planar
    /// triangle: what a GPU's screen-space derivatives give a 2×2 quad inside it). A
    /// neighbour's ray that misses the plane (edge-on) gives no footprint: the finest level.
    fn footprint(&self, cam: &PixelRays, (x, y): (usize, usize), b: [f64; 2]) -> Footprint {
        let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
        let at = |px: f64, py: f64| {
            let (o, d) = cam.ray_at(px, py);
            self.barycentrics(o, d)
        };
        match (at(cx + 1.0, cy), at(cx, cy + 1.0)) {
            (Some(bx), Some(by)) => Footprint::Barycentric {
                dx: [bx[0] - b[0], bx[1] - b[1]],
                dy: [by[0] - b[0], by[1] - b[1]],
            },
            _ => Footprint::Point,
        }
    }
}

struct SurfacePoint {
    depth: f64,
    point: DVec3,
    /// Barycentrics `(b1, b2)` clamped into the triangle, and as met.
    b: [f64; 2],
    unclamped: [f64; 2],
}
