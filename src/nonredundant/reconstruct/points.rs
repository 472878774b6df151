//! Point-based reconstruction (non-redundant-rendering.txt §4): one oriented square splat per
//! sample, in the sample's tangent plane, with the area of the pixel's footprint on that plane
//! (side `f / sqrt(|cos θ|)`, f the pixel footprint, θ the angle between the normal and the
//! view ray), |cos θ| held at ≥ 1 / MAX_STRETCH² so no side exceeds `MAX_STRETCH` footprints.
//! Edges follow the camera's right axis projected onto the plane. A sample without a normal
//! faces the camera.

use std::time::Instant;

use glam::DVec3;

use super::{check, per_image, push_vertex, ImageView, Mesh, MAX_STRETCH};
use crate::error::Result;
use crate::types::{DepthImages, Timings};

/// One square (two triangles, both with the sample's index) per sample.
pub fn reconstruct_points(images: &DepthImages) -> Result<Mesh> {
    check(images)?;
    let start = Instant::now();
    let mut m = per_image(images.n, |i| image_points(&ImageView::of(images, i)));
    m.timings = Timings::from([("points", start.elapsed().as_secs_f64())]);
    Ok(m)
}

fn image_points(img: &ImageView<'_>) -> Mesh {
    let mut m = Mesh::default();
    let rot = glam::DMat3::from_mat4(img.cam.pose);
    let (right, up) = (rot.x_axis, rot.y_axis);
    for k in 0..img.width * img.height {
        if !img.valid(k) {
            continue;
        }
        let s = img.point(k);
        let f = img.footprint(k);
        let view = match img.cam.projection {
            crate::camera::Projection::Perspective { .. } => (s - img.cam.eye()).normalize(),
            crate::camera::Projection::Orthographic { .. } => img.cam.forward(),
        };
        let mut n = img.unit_normal(k);
        if n == DVec3::ZERO || !view.is_finite() {
            n = -img.cam.forward();
        }
        let cos = n.dot(view).abs().max(1.0 / (MAX_STRETCH * MAX_STRETCH));
        let half = 0.5 * f / cos.sqrt();
        let mut t1 = right - n * n.dot(right);
        if t1.length() < 1e-6 {
            t1 = up - n * n.dot(up);
        }
        let t1 = t1.normalize();
        let t2 = n.cross(t1);
        let c = [
            s + (-t1 + t2) * half,
            s + (t1 + t2) * half,
            s + (t1 - t2) * half,
            s + (-t1 - t2) * half,
        ];
        let ids = c.map(|p| push_vertex(&mut m, p));
        m.faces.push([ids[0], ids[3], ids[2]]);
        m.faces.push([ids[2], ids[1], ids[0]]);
        let flat = img.base + k as i64;
        m.sample.extend([flat, flat]);
    }
    m
}
