//! The two redundancy tests of non-redundant-rendering.txt §3.1, in f64 on the CPU, shared by
//! non-redundant rendering with visibility redundancy and by the sampling metrics (§6.1.2).
//!
//! - Pixel redundancy (Algorithm 3): a sample of triangle t at point a is redundant with image
//!   I_j when a projects into I_j at a pixel where I_j holds t.
//! - Visibility redundancy (Algorithm 2): a is redundant with I_j when the segment from I_j's
//!   viewpoint to a is unoccluded. We also require a to lie inside I_j's view volume (in front of
//!   the camera, projecting inside the image), the resolution-free limit of pixel redundancy.

use glam::{DVec2, DVec3};

use crate::camera::{Camera, Projection};
use crate::error::Result;
use crate::scene::Scene;
use crate::trace;

/// Which redundancy definition a test uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Redundancy {
    Pixel,
    Visibility,
}

impl Redundancy {
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "pixel" => Some(Self::Pixel),
            "visibility" => Some(Self::Visibility),
            _ => None,
        }
    }
}

/// A sample: the triangle it lies on and its world point.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    pub triangle: i32,
    pub point: DVec3,
}

/// The pixel of `cam` that `p` falls in, if p is in front of the camera and inside the image.
pub fn pixel_of(cam: &Camera, p: DVec3) -> Option<(usize, usize)> {
    let (px, depth): (DVec2, f64) = cam.project(p);
    let in_front = match cam.projection {
        Projection::Perspective { .. } => depth > 0.0,
        Projection::Orthographic { .. } => depth >= 0.0,
    };
    let (w, h) = (cam.width as f64, cam.height as f64);
    (in_front && px.x >= 0.0 && px.y >= 0.0 && px.x < w && px.y < h)
        .then_some((px.x as usize, px.y as usize))
}

/// Algorithm 3: does the image (`cam`, row-major triangle `ids`) hold `s.triangle` at the pixel
/// `s.point` projects to?
pub fn pixel_redundant(s: &Sample, cam: &Camera, ids: &[i32]) -> bool {
    pixel_of(cam, s.point).is_some_and(|(x, y)| ids[y * cam.width as usize + x] == s.triangle)
}

/// Algorithm 2 for many samples at once: whether each sample is inside `cam`'s view volume and
/// unoccluded from its viewpoint (for an orthographic camera, along its view direction). One
/// any-hit ray from the viewpoint toward the sample, stopped `tolerance` (plus a relative
/// `DEPTH_TOLERANCE`) short of it: the sample is visible when nothing lies on that segment (its
/// own triangle and neighbours sharing the point lie beyond it). `tolerance` is a world
/// distance; see [`tolerance`].
pub fn visible_from(
    scene: &Scene,
    samples: &[Sample],
    cam: &Camera,
    tolerance: f64,
) -> Result<Vec<bool>> {
    let mut visible = vec![false; samples.len()];
    let mut which = Vec::new();
    let mut origins = Vec::new();
    let mut dirs = Vec::new();
    let fwd = cam.forward();
    for (i, s) in samples.iter().enumerate() {
        if pixel_of(cam, s.point).is_none() {
            continue;
        }
        let origin = match cam.projection {
            Projection::Perspective { .. } => cam.eye(),
            Projection::Orthographic { .. } => s.point - fwd * (s.point - cam.eye()).dot(fwd),
        };
        let d = s.point - origin;
        let len = d.length();
        // The segment stops this far short of the sample: what lies within it of the sample
        // (its own triangle, a neighbour sharing the point) does not hide it.
        let keep = 1.0 - (tolerance + DEPTH_TOLERANCE * len) / len;
        if len == 0.0 || keep <= 0.0 {
            visible[i] = true;
            continue;
        }
        which.push(i);
        origins.push(origin.as_vec3().to_array());
        dirs.push((d * keep).as_vec3().to_array());
    }
    if which.is_empty() {
        return Ok(visible);
    }
    // An any-hit query: only whether something lies on the segment matters.
    let q = trace::Query::new(0.0, 1.0);
    let hidden = trace::occluded(scene, &origins, &dirs, &q)?.hit;
    for (k, &i) in which.iter().enumerate() {
        visible[i] = !hidden[k];
    }
    Ok(visible)
}

/// Part of the visibility test's tolerance proportional to the sample's distance.
const DEPTH_TOLERANCE: f64 = 1e-5;

/// The distance within which another surface counts as the sample itself in the visibility
/// test, to which `visible_from` adds 1e-5 of the sample's distance from the viewpoint: well
/// above f32 rounding of positions and hits, well below any feature a depth image resolves.
pub fn tolerance(scene: &Scene) -> f64 {
    1e-5 * scene.diagonal()
}
