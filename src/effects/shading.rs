//! One shading model shared by every reflection method (eye-based-point-rendering.txt §4.2 uses
//! a physically based shader for all of EPR, iVIR and MVR): Lambertian diffuse for the
//! non-metallic part plus a GGX / Smith / Schlick specular lobe, under the scene's punctual
//! lights (`KHR_lights_punctual`, with inverse-square falloff, glTF range and spot cones) or,
//! when it has none, one default directional light; plus a small ambient term. No shadows.

use glam::DVec3;

use crate::scene::{LightKind, Scene};

/// Ambient radiance as a fraction of the albedo.
pub const AMBIENT: f64 = 0.08;

/// A light as the shader uses it.
#[derive(Debug, Clone, Copy)]
pub struct ShadeLight {
    kind: LightKind,
    position: DVec3,
    /// Unit direction the light travels (for directional and spot lights).
    direction: DVec3,
    radiance: DVec3,
    range: Option<f64>,
    cone: Option<(f64, f64)>,
}

/// The scene's lights, or the default: a white directional light of intensity 3 arriving from
/// the eye's upper left-behind (`up − forward + 0.5·left` from the surface toward the light).
pub fn lights(scene: &Scene, eye_forward: DVec3, eye_up: DVec3) -> Vec<ShadeLight> {
    let ls = scene.lights();
    if ls.is_empty() {
        let left = eye_up.cross(eye_forward);
        let to_light = (eye_up - eye_forward + 0.5 * left).normalize_or(DVec3::Z);
        return vec![ShadeLight {
            kind: LightKind::Directional,
            position: DVec3::ZERO,
            direction: -to_light,
            radiance: DVec3::splat(3.0),
            range: None,
            cone: None,
        }];
    }
    ls.iter()
        .map(|l| ShadeLight {
            kind: l.kind,
            position: DVec3::from_array(l.position),
            direction: DVec3::from_array(l.direction).normalize_or(DVec3::NEG_Z),
            radiance: DVec3::from_array(l.color.map(f64::from)) * l.intensity as f64,
            range: l.range.map(f64::from),
            cone: match (l.inner_cone_angle, l.outer_cone_angle) {
                (Some(i), Some(o)) => Some((i as f64, o as f64)),
                (None, Some(o)) => Some((0.0, o as f64)),
                _ => None,
            },
        })
        .collect()
}

/// A surface to shade.
#[derive(Debug, Clone, Copy)]
pub struct Surface {
    pub position: DVec3,
    /// Unit shading normal (flipped toward the viewer here).
    pub normal: DVec3,
    pub albedo: DVec3,
    pub metallic: f64,
    pub roughness: f64,
}

/// Outgoing radiance of `s` toward `viewer`.
pub fn shade(s: &Surface, viewer: DVec3, lights: &[ShadeLight]) -> DVec3 {
    let v = (viewer - s.position).normalize_or_zero();
    let mut n = s.normal;
    if n.dot(v) < 0.0 {
        n = -n;
    }
    let alpha = (s.roughness.clamp(0.03, 1.0)).powi(2);
    let f0 = DVec3::splat(0.04).lerp(s.albedo, s.metallic);
    let diffuse = s.albedo * (1.0 - s.metallic) / std::f64::consts::PI;
    let mut out = s.albedo * AMBIENT;
    for l in lights {
        let (to_light, e) = match l.kind {
            LightKind::Directional => (-l.direction, l.radiance),
            LightKind::Point | LightKind::Spot => {
                let d = l.position - s.position;
                let r2 = d.length_squared().max(1e-12);
                let mut e = l.radiance / r2;
                if let Some(range) = l.range {
                    let x = (r2.sqrt() / range).powi(4);
                    e *= (1.0 - x).clamp(0.0, 1.0).powi(2);
                }
                let to = d / r2.sqrt();
                if let (LightKind::Spot, Some((inner, outer))) = (l.kind, l.cone) {
                    let cd = (-to).dot(l.direction);
                    let (ci, co) = (inner.cos(), outer.cos());
                    e *= ((cd - co) / (ci - co).max(1e-4)).clamp(0.0, 1.0).powi(2);
                }
                (to, e)
            }
        };
        let nl = n.dot(to_light);
        if nl <= 0.0 {
            continue;
        }
        let h = (to_light + v).normalize_or(n);
        let nh = n.dot(h).max(0.0);
        let nv = n.dot(v).max(1e-4);
        let vh = v.dot(h).max(0.0);
        let a2 = alpha * alpha;
        let dd = nh * nh * (a2 - 1.0) + 1.0;
        let ndf = a2 / (std::f64::consts::PI * dd * dd).max(1e-12);
        let k = alpha / 2.0;
        let g = (nv / (nv * (1.0 - k) + k)) * (nl / (nl * (1.0 - k) + k));
        let fresnel = f0 + (DVec3::ONE - f0) * (1.0 - vh).powi(5);
        let spec = fresnel * (ndf * g / (4.0 * nv * nl).max(1e-6));
        let kd = (DVec3::ONE - fresnel) * diffuse;
        out += (kd + spec) * e * nl;
    }
    out
}

/// The surface of triangle `t` at `p`: interpolated vertex normal (geometric when the scene has
/// none) and colour, and the material's metallic and roughness (0 and 1 without a material).
pub fn surface(scene: &Scene, t: usize, p: DVec3) -> Surface {
    let f = scene.faces()[t];
    let v = f.map(|i| DVec3::from_array(scene.vertices()[i as usize].map(f64::from)));
    let geometric = scene.face_normal(t);
    let w = barycentric(&v, p);
    let colors = scene.colors();
    let albedo = f
        .iter()
        .zip(w)
        .map(|(&i, wi)| DVec3::from_array(colors[i as usize].map(f64::from)) * wi)
        .sum::<DVec3>();
    let normal = match scene.normals() {
        Some(ns) => {
            let n = f
                .iter()
                .zip(w)
                .map(|(&i, wi)| DVec3::from_array(ns[i as usize].map(f64::from)) * wi)
                .sum::<DVec3>();
            let n = n.normalize_or_zero();
            // Keep the interpolated normal on the geometric side of the face.
            if n == DVec3::ZERO {
                geometric
            } else if n.dot(geometric) < 0.0 {
                -n
            } else {
                n
            }
        }
        None => geometric,
    };
    let (metallic, roughness) = usize::try_from(scene.material_ids()[t])
        .ok()
        .and_then(|m| scene.materials().get(m))
        .map(|m| (m.metallic as f64, m.roughness as f64))
        .unwrap_or((0.0, 1.0));
    Surface {
        position: p,
        normal,
        albedo,
        metallic,
        roughness,
    }
}

/// Barycentric weights of `p` (projected onto the triangle's plane), clamped into the triangle
/// so that points just outside it (splat centres) interpolate its edge values.
fn barycentric(v: &[DVec3; 3], p: DVec3) -> [f64; 3] {
    let e0 = v[1] - v[0];
    let e1 = v[2] - v[0];
    let d = p - v[0];
    let (a, b, c) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let (pd0, pd1) = (d.dot(e0), d.dot(e1));
    let den = a * c - b * b;
    if den.abs() <= f64::MIN_POSITIVE {
        return [1.0 / 3.0; 3];
    }
    let w1 = ((c * pd0 - b * pd1) / den).clamp(0.0, 1.0);
    let w2 = ((a * pd1 - b * pd0) / den).clamp(0.0, 1.0 - w1);
    [1.0 - w1 - w2, w1, w2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lambert_under_a_head_on_light() {
        let s = Surface {
            position: DVec3::ZERO,
            normal: DVec3::Z,
            albedo: DVec3::splat(0.5),
            metallic: 0.0,
            roughness: 1.0,
        };
        let l = ShadeLight {
            kind: LightKind::Directional,
            position: DVec3::ZERO,
            direction: DVec3::NEG_Z,
            radiance: DVec3::ONE,
            range: None,
            cone: None,
        };
        let c = shade(&s, DVec3::new(0.0, 0.0, 5.0), &[l]);
        // Diffuse 0.5/π·(1 − F) plus a small rough specular, plus ambient.
        assert!(c.x > 0.5 / std::f64::consts::PI * 0.9 && c.x < 0.5, "{c}");
        let dark = shade(&s, DVec3::new(0.0, 0.0, 5.0), &[]);
        assert!((dark.x - 0.5 * AMBIENT).abs() < 1e-12);
    }

    #[test]
    fn barycentric_weights_sum_to_one_and_clamp() {
        let v = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let w = barycentric(&v, DVec3::new(0.25, 0.25, 3.0));
        assert!((w[0] - 0.5).abs() < 1e-12 && (w[1] - 0.25).abs() < 1e-12);
        let w = barycentric(&v, DVec3::new(2.0, 2.0, 0.0));
        assert!(w.iter().all(|x| (0.0..=1.0).contains(x)));
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }
}
