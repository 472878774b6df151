//! Light visibility that both papers' shadows share: soft shadows (non-redundant-rendering.txt
//! §5) and omnidirectional shadows (eye-based-point-rendering.txt §5) both shade the points an
//! eye sees (`eye_points`), take exact visibility toward each light sample from BVH rays
//! (`raytraced`, their reference) and turn visibility bits into per-pixel results
//! (`per_pixel`).

use glam::{DVec2, DVec3};

use crate::camera::Camera;
use crate::error::Result;
use crate::gpu;
use crate::scene::Scene;
use crate::types::DepthImages;

/// Per output pixel, from the visibility bits of the covered pixels (per sample, bit k of word
/// w is covered pixel 32w + k): whether each sample is visible (sample fastest; true where no
/// surface) and the visible fraction (1 where no surface).
pub(crate) fn per_pixel(bits: &[u32], mask: &[bool], samples: usize) -> (Vec<bool>, Vec<f32>) {
    let covered = mask.iter().filter(|&&m| m).count();
    let words = covered.div_ceil(32).max(1);
    let mut visible = vec![true; mask.len() * samples];
    let mut visibility = vec![1.0f32; mask.len()];
    let mut k = 0;
    for (px, &m) in mask.iter().enumerate() {
        if !m {
            continue;
        }
        let mut lit = 0u32;
        for s in 0..samples {
            let bit = (bits[s * words + k / 32] >> (k % 32)) & 1 == 1;
            visible[px * samples + s] = bit;
            lit += bit as u32;
        }
        visibility[px] = lit as f32 / samples as f32;
        k += 1;
    }
    (visible, visibility)
}

/// World points and eye-facing unit normals of the covered pixels (in pixel order), and the
/// coverage mask.
pub(crate) fn eye_points(seen: &DepthImages, eye: &Camera) -> (Vec<DVec3>, Vec<DVec3>, Vec<bool>) {
    let mut points = Vec::new();
    let mut normals = Vec::new();
    let mut mask = Vec::with_capacity(seen.triangle.len());
    let w = seen.width as usize;
    for (k, &t) in seen.triangle.iter().enumerate() {
        let p = DVec3::from_array(seen.position[k].map(f64::from));
        let ok = t >= 0 && p.is_finite();
        mask.push(ok);
        if !ok {
            continue;
        }
        let n = DVec3::from_array(seen.normal[k].map(f64::from));
        let n = if n.length() > 1e-12 {
            n.normalize()
        } else {
            DVec3::ZERO
        };
        let (x, y) = ((k % w) as f64 + 0.5, (k / w) as f64 + 0.5);
        let (_, ray) = eye.ray_z1(DVec2::new(x, y));
        points.push(p);
        normals.push(if n.dot(ray) > 0.0 { -n } else { n });
    }
    (points, normals, mask)
}

/// Shadow rays as `occluded` takes them: origins and (segment-long) directions.
type Segments = (Vec<[f32; 3]>, Vec<[f32; 3]>);

/// Exact visibility: a ray from each light sample toward each point, started
/// `ABS_BIAS · diagonal` after the sample and stopped as far short of the point (so that
/// neither the point's own surface nor a surface through the sample blocks it); a hit between
/// blocks the sample. A point facing away from a sample, or within twice that distance of it,
/// does not see it.
pub(crate) fn raytraced(
    scene: &Scene,
    samples: &[DVec3],
    points: &[DVec3],
    normals: &[DVec3],
    diagonal: f64,
) -> Result<Vec<u32>> {
    let words = points.len().div_ceil(32).max(1);
    let mut bits = vec![0u32; words * samples.len()];
    let eps = gpu::shadow::ABS_BIAS * diagonal;
    let q = crate::trace::Query::new(0.0, 1.0);
    for (s, &l) in samples.iter().enumerate() {
        // Only points facing the sample, and not within twice the offset of it, get a ray.
        let (traced, (origins, dirs)): (Vec<usize>, Segments) = points
            .iter()
            .zip(normals)
            .enumerate()
            .filter(|&(_, (&p, &n))| n.dot(l - p) > 0.0 && (p - l).length() > 2.0 * eps)
            .map(|(k, (&p, _))| {
                let r = p - l;
                let len = r.length();
                let unit = r / len;
                (
                    k,
                    (
                        (l + unit * eps).as_vec3().to_array(),
                        (unit * (len - 2.0 * eps)).as_vec3().to_array(),
                    ),
                )
            })
            .unzip();
        // Any hit on the segment blocks the sample: an any-hit query.
        let blocked = crate::trace::occluded(scene, &origins, &dirs, &q)?.hit;
        for (&k, &b) in traced.iter().zip(&blocked) {
            if !b {
                bits[s * words + k / 32] |= 1 << (k % 32);
            }
        }
    }
    Ok(bits)
}
