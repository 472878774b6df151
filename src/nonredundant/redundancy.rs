//! The two redundancy tests of non-redundant-rendering.txt §3.1, in f64 on the CPU, shared by
//! non-redundant rendering with visibility redundancy and by the sampling metrics (§6.1.2).
//!
//! - Pixel redundancy (Algorithm 3): a sample of triangle t at point a is redundant with image
//!   I_j when a projects into I_j at a pixel where I_j holds t.
//! - Visibility redundancy (Algorithm 2): a is redundant with I_j when the segment from I_j's
//!   viewpoint to a is unoccluded. We also require a to lie inside I_j's view volume (in front of
//!   the camera, projecting inside the image), the resolution-free limit of pixel redundancy.

pub use crate::image::{tolerance, Sample};
use glam::{DVec2, DVec3};

use crate::camera::{Camera, Projection};
use crate::error::Result;
use crate::scene::Scene;
use crate::sets::Sets;
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

/// Distinct triangles that are one surface: coplanar (unit normal within 1e-6 and plane offset
/// within 1e-6 of the scene's diagonal, either orientation) and overlapping with positive area
/// (touching along an edge does not count), such as a box's bottom on a floor or a decal.
/// A scene's coincident groups (see [`coincident_groups`]), cached on the scene.
pub struct Coincident(pub Option<Vec<u32>>);

/// Returns, per triangle, a representative of its group; `None` when no two triangles are
/// coincident. Exact duplicates are coincident too. Planes are compared through a rounded key,
/// so two planes straddling a rounding step stay apart (the test is conservative).
pub fn coincident_groups(scene: &Scene) -> Option<Vec<u32>> {
    use std::collections::HashMap;
    let n = scene.triangle_count();
    let step = scene.diagonal().max(f64::MIN_POSITIVE) * 1e-6;
    let mut buckets: HashMap<[i64; 4], Vec<(u32, [DVec2; 3])>> = HashMap::new();
    for t in 0..n {
        let [a, b, c] = scene.triangle(t);
        let normal = (b - a).cross(c - a);
        let len = normal.length();
        if len.is_nan() || len <= 0.0 {
            continue;
        }
        let mut u = normal / len;
        let k = u.abs().max_position();
        if u[k] < 0.0 {
            u = -u;
        }
        let key = [
            (u.x * 1e6).round() as i64,
            (u.y * 1e6).round() as i64,
            (u.z * 1e6).round() as i64,
            (u.dot(a) / step).round() as i64,
        ];
        // In the plane: drop the dominant axis of the normal.
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        let flat = [a, b, c].map(|p| DVec2::new(p[i], p[j]));
        buckets.entry(key).or_default().push((t as u32, flat));
    }
    let mut sets = Sets::new(n);
    let mut any = false;
    for (_, mut tris) in buckets.into_iter().filter(|(_, v)| v.len() > 1) {
        // Sweep along x: only triangles whose x ranges overlap are tested.
        let lo_x = |t: &[DVec2; 3]| t.iter().map(|p| p.x).fold(f64::INFINITY, f64::min);
        let hi_x = |t: &[DVec2; 3]| t.iter().map(|p| p.x).fold(f64::NEG_INFINITY, f64::max);
        tris.sort_by(|a, b| lo_x(&a.1).total_cmp(&lo_x(&b.1)));
        let mut open: Vec<usize> = Vec::new();
        for k in 0..tris.len() {
            let start = lo_x(&tris[k].1);
            open.retain(|&m| hi_x(&tris[m].1) > start);
            for &m in &open {
                if overlap(&tris[k].1, &tris[m].1, step) {
                    any |= sets.union(tris[k].0, tris[m].0);
                }
            }
            open.push(k);
        }
    }
    any.then(|| (0..n as u32).map(|t| sets.find(t)).collect())
}

/// Whether two triangles of a plane overlap by more than `eps` (2D separating axes; sharing an
/// edge or a corner is not overlapping).
fn overlap(a: &[DVec2; 3], b: &[DVec2; 3], eps: f64) -> bool {
    for tri in [a, b] {
        for e in 0..3 {
            let d = tri[(e + 1) % 3] - tri[e];
            let axis = DVec2::new(-d.y, d.x);
            let len = axis.length();
            if len == 0.0 {
                return false;
            }
            let axis = axis / len;
            let span = |t: &[DVec2; 3]| {
                let p = t.map(|p| p.dot(axis));
                (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]))
            };
            let ((a0, a1), (b0, b1)) = (span(a), span(b));
            if a1 <= b0 + eps || b1 <= a0 + eps {
                return false;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coplanar_overlapping_triangles_group_and_neighbours_do_not() {
        // A floor quad (two triangles sharing a diagonal), a decal inside it facing down, and a
        // parallel quad just above (1e-3 of the scene: a different plane).
        let v = vec![
            [0.0, 0.0, 0.0],
            [4.0, 0.0, 0.0],
            [4.0, 4.0, 0.0],
            [0.0, 4.0, 0.0],
            [2.0, 0.5, 0.0],
            [3.0, 0.5, 0.0],
            [3.0, 1.5, 0.0],
            [1.0, 1.0, 0.004],
            [2.0, 1.0, 0.004],
            [1.0, 2.0, 0.004],
        ];
        let f = vec![[0, 1, 2], [0, 2, 3], [4, 6, 5], [7, 8, 9]];
        let s = Scene::from_arrays(v, f, None, None).unwrap();
        let g = coincident_groups(&s).unwrap();
        // The decal overlaps the first floor triangle only; the floor's halves merely touch.
        assert_eq!(g[2], g[0]);
        assert_ne!(g[1], g[0]);
        assert_eq!(g[3], 3);
        let alone = Scene::from_arrays(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
            None,
            None,
        )
        .unwrap();
        assert!(coincident_groups(&alone).is_none());
    }
}
