//! Surfaces rebuilt from depth-image samples (non-redundant-rendering.txt §4): the conventional
//! depth-image `mesh`, the `hybrid` reconstruction of Algorithm 4, and oriented square `points`.
//! All three read the same per-sample data — world position, geometric normal, triangle id and
//! the camera — and return one triangle soup with, per face, the sample it came from.

pub mod hybrid;
pub mod mesh;
pub mod points;

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::error::Result;
use crate::input_err;
use crate::types::{DepthImages, Timings};

pub use hybrid::reconstruct_hybrid;
pub use mesh::reconstruct_mesh;
pub use points::reconstruct_points;

/// Two samples belong to one surface when each lies within this many pixel footprints of the
/// other's tangent plane (or both hold the same triangle).
pub const CONTINUITY: f64 = 1.0;
/// No generated vertex lies farther from its sample than this many pixel footprints: a
/// tangent-plane corner at a grazing angle is pulled back onto the plane facing the camera.
pub const MAX_STRETCH: f64 = 8.0;

/// A reconstruction: a triangle soup in world space.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub vertices: Vec<[f32; 3]>,
    pub faces: Vec<[u32; 3]>,
    /// Flat index (image · H · W + row · W + column) of the sample each face came from.
    pub sample: Vec<i64>,
    pub timings: Timings,
}

impl Mesh {
    /// Append another image's part, renumbering its vertices.
    fn append(&mut self, part: Mesh) {
        let base = self.vertices.len() as u32;
        self.vertices.extend_from_slice(&part.vertices);
        self.faces
            .extend(part.faces.iter().map(|f| f.map(|v| v + base)));
        self.sample.extend_from_slice(&part.sample);
    }
}

/// One image's samples as the reconstructions read them.
pub(crate) struct ImageView<'a> {
    pub cam: &'a Camera,
    pub width: usize,
    pub height: usize,
    pub triangle: &'a [i32],
    pub position: &'a [[f32; 3]],
    pub normal: &'a [[f32; 3]],
    pub depth: &'a [f32],
    /// Flat index of this image's first sample.
    pub base: i64,
}

impl<'a> ImageView<'a> {
    pub fn of(images: &'a DepthImages, i: usize) -> Self {
        let npx = images.width as usize * images.height as usize;
        let r = i * npx..(i + 1) * npx;
        Self {
            cam: &images.cameras[i],
            width: images.width as usize,
            height: images.height as usize,
            triangle: &images.triangle[r.clone()],
            position: &images.position[r.clone()],
            normal: &images.normal[r.clone()],
            depth: &images.depth[r],
            base: (i * npx) as i64,
        }
    }

    pub fn valid(&self, k: usize) -> bool {
        self.triangle[k] >= 0 && self.position[k].iter().all(|v| v.is_finite())
    }

    /// The sample's world point, rebuilt in f64 from its camera and float32 depth (relative
    /// precision ~1e-7 of the depth) rather than read from the float32 world position, which
    /// far from the origin is quantized to the coordinates' ulp (1 unit at 1e7).
    pub fn point(&self, k: usize) -> DVec3 {
        let d = self.depth[k] as f64;
        if !d.is_finite() {
            return DVec3::from_array(self.position[k].map(f64::from));
        }
        let (x, y) = ((k % self.width) as f64 + 0.5, (k / self.width) as f64 + 0.5);
        self.cam.unproject(glam::DVec2::new(x, y), d)
    }

    /// The sample's unit normal, or zero when it has none (zero or non-finite).
    pub fn unit_normal(&self, k: usize) -> DVec3 {
        let n = DVec3::from_array(self.normal[k].map(f64::from));
        let len = n.length();
        if len.is_finite() && len > 1e-12 {
            n / len
        } else {
            DVec3::ZERO
        }
    }

    /// Pixel footprint at the sample (see `Camera::pixel_footprint`).
    pub fn footprint(&self, k: usize) -> f64 {
        let d = self.depth[k] as f64;
        let f = self
            .cam
            .pixel_footprint(if d.is_finite() { d } else { 0.0 });
        if f.is_finite() && f > 0.0 {
            f
        } else {
            f64::MIN_POSITIVE
        }
    }
}

/// A sample as the continuity test reads it.
pub(crate) struct Surfel {
    pub point: DVec3,
    pub normal: DVec3,
    pub footprint: f64,
    pub triangle: i32,
}

impl ImageView<'_> {
    pub fn surfel(&self, k: usize) -> Surfel {
        Surfel {
            point: self.point(k),
            normal: self.unit_normal(k),
            footprint: self.footprint(k),
            triangle: self.triangle[k],
        }
    }
}

/// Do two samples belong to one surface? The same triangle, or each within `CONTINUITY`
/// footprints of the other's tangent plane.
pub(crate) fn continuous(a: &Surfel, b: &Surfel) -> bool {
    if a.triangle == b.triangle {
        return true;
    }
    if a.normal == DVec3::ZERO || b.normal == DVec3::ZERO {
        return false;
    }
    (a.normal.dot(b.point - a.point)).abs() <= CONTINUITY * a.footprint
        && (b.normal.dot(a.point - b.point)).abs() <= CONTINUITY * b.footprint
}

/// Where the ray through pixel position `pixel` (corners at integer coordinates) meets the
/// tangent plane of sample `k`, held within `MAX_STRETCH` footprints of the sample: a plane
/// seen edge-on, a missing normal or a far intersection falls back to the point on the ray at
/// the sample's camera depth. Always finite for a finite sample.
pub(crate) fn on_tangent_plane(img: &ImageView<'_>, k: usize, pixel: DVec2) -> DVec3 {
    let s = img.point(k);
    let n = img.unit_normal(k);
    let (o, d) = img.cam.ray_z1(pixel);
    // `d` has camera z of −1, so the point at camera depth z is o + z·d.
    let depth = (s - img.cam.eye()).dot(img.cam.forward());
    let fallback = o + d * depth;
    let denom = n.dot(d);
    if n != DVec3::ZERO && denom.abs() > 1e-12 {
        let t = n.dot(s - o) / denom;
        let p = o + d * t;
        if t > 0.0 && p.is_finite() && (p - s).length() <= MAX_STRETCH * img.footprint(k) {
            return p;
        }
    }
    if fallback.is_finite() {
        fallback
    } else {
        s
    }
}

/// Check the images a reconstruction reads.
pub(crate) fn check(images: &DepthImages) -> Result<()> {
    let npx = images.width as usize * images.height as usize * images.n;
    if images.cameras.len() != images.n {
        return input_err!("{} cameras for {} images", images.cameras.len(), images.n);
    }
    for (name, len) in [
        ("triangle", images.triangle.len()),
        ("position", images.position.len()),
        ("normal", images.normal.len()),
        ("depth", images.depth.len()),
    ] {
        if len != npx {
            return input_err!(
                "{name} holds {len} pixels, expected {npx} ({} images of {}x{})",
                images.n,
                images.width,
                images.height
            );
        }
    }
    for c in &images.cameras {
        if (c.width, c.height) != (images.width, images.height) {
            return input_err!(
                "a camera is {}x{} but the images are {}x{}",
                c.width,
                c.height,
                images.width,
                images.height
            );
        }
    }
    Ok(())
}

/// Reconstruct every image in parallel with `one` and join the parts in image order.
pub(crate) fn per_image(n: usize, one: impl Fn(usize) -> Mesh + Sync + Send) -> Mesh {
    let parts: Vec<Mesh> = (0..n).into_par_iter().map(one).collect();
    let mut out = Mesh::default();
    for p in parts {
        out.append(p);
    }
    out
}

/// Push the world point as an f32 vertex and return its index.
pub(crate) fn push_vertex(m: &mut Mesh, p: DVec3) -> u32 {
    m.vertices.push(p.as_vec3().to_array());
    (m.vertices.len() - 1) as u32
}
