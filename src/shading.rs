//! The package's one shading model: every lit pixel — rendered frames (`render`), reflections
//! (eye-based-point-rendering.txt §4.2 uses a physically based shader for all of EPR, iVIR and
//! MVR), impostors and their reference, and the demo — goes through [`shade`] or its
//! view-independent part [`diffuse`].
//!
//! Lambertian diffuse for the non-metallic part plus a GGX / Smith / Schlick specular lobe,
//! under the scene's punctual lights (`KHR_lights_punctual`: colour × intensity, inverse-square
//! falloff, glTF range and spot cones), area lights (a unit-radiance disc seen from the point:
//! irradiance π·cos, no falloff), or, when there is no light at all, one default directional
//! light; plus [`AMBIENT`]. Each light's contribution may be scaled by a visibility (shadows).

use glam::DVec3;

use crate::camera::Camera;
use crate::error::Result;
use crate::input_err;
use crate::scene::surface::{Footprint, Surfaces};
use crate::scene::{LightKind, Scene};
use crate::types::DepthImages;

/// Ambient radiance as a fraction of the albedo.
pub const AMBIENT: f64 = 0.08;

/// A frame's lights leave its view dark when fewer than this share of the pixels that see a
/// surface get direct light at least as bright as their ambient light: [`frame`] then adds the
/// default light, as for a scene with no light at all (the toy car's only light, a small
/// emissive part inside it, lights 0.4% of a view of it).
pub const DARK_VIEW: f64 = 0.1;

/// Radiance of the default light, arriving when a scene has no light.
pub const DEFAULT_RADIANCE: f64 = 3.0;

/// The default light's direction (unit, from a surface toward the light) where no eye fixes
/// one: view-independent shading ([`diffuse`], the impostors). It is (3, 5, 8) / √98; the
/// impostors' own constant before the shading model was unified, (3, 5, 8) / (3√11), was 0.995
/// long and used unnormalized, which lit their images up to 0.5% darker than this.
pub const DEFAULT_TO_LIGHT: [f64; 3] = [
    0.303_045_763_365_663_25,
    0.505_076_272_276_105_4,
    0.808_122_035_641_768_5,
];

/// What kind of light a [`ShadeLight`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Directional,
    Point,
    Spot,
    /// An area light, seen from the surface as a unit-radiance source toward its centre.
    Area,
}

impl From<LightKind> for Kind {
    fn from(k: LightKind) -> Self {
        match k {
            LightKind::Directional => Kind::Directional,
            LightKind::Point => Kind::Point,
            LightKind::Spot => Kind::Spot,
        }
    }
}

/// A light as the shader uses it.
#[derive(Debug, Clone, Copy)]
pub struct ShadeLight {
    kind: Kind,
    position: DVec3,
    /// Unit direction the light travels (for directional and spot lights).
    direction: DVec3,
    radiance: DVec3,
    range: Option<f64>,
    cone: Option<(f64, f64)>,
}

impl ShadeLight {
    /// A white directional light of [`DEFAULT_RADIANCE`] arriving along `to_light` (from the
    /// surface toward the light).
    pub fn default_toward(to_light: DVec3) -> Self {
        ShadeLight {
            kind: Kind::Directional,
            position: DVec3::ZERO,
            direction: -to_light.normalize_or(DVec3::Z),
            radiance: DVec3::splat(DEFAULT_RADIANCE),
            range: None,
            cone: None,
        }
    }

    /// An area light centred at `center`: each point sees it as a unit-radiance source in the
    /// direction of its centre (irradiance π·cos θ, so a white Lambertian surface facing it is
    /// lit to its albedo), with no falloff.
    pub fn area(center: DVec3) -> Self {
        ShadeLight {
            kind: Kind::Area,
            position: center,
            direction: DVec3::NEG_Z,
            radiance: DVec3::splat(std::f64::consts::PI),
            range: None,
            cone: None,
        }
    }
}

/// The default light seen from an eye: from its upper left-behind (`up − forward + 0.5·left`
/// from the surface toward the light).
pub fn default_light(eye: &Camera) -> ShadeLight {
    let (forward, up) = (eye.forward(), eye.world_to_camera_rotation().row(1));
    let left = up.cross(forward);
    ShadeLight::default_toward(up - forward + 0.5 * left)
}

/// The scene's lights, or the default light as seen from the eye when it has none.
pub fn lights(scene: &Scene, eye: &Camera) -> Vec<ShadeLight> {
    let ls = punctual(scene);
    if ls.is_empty() {
        return vec![default_light(eye)];
    }
    ls
}

/// The scene's punctual lights, in order (empty when it has none).
pub fn punctual(scene: &Scene) -> Vec<ShadeLight> {
    scene
        .lights()
        .iter()
        .map(|l| ShadeLight {
            kind: l.kind.into(),
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

/// The direction from `p` toward light `l` and the irradiance it brings (before cos θ).
fn arriving(l: &ShadeLight, p: DVec3) -> (DVec3, DVec3) {
    match l.kind {
        Kind::Directional => (-l.direction, l.radiance),
        Kind::Area => ((l.position - p).normalize_or(DVec3::Z), l.radiance),
        Kind::Point | Kind::Spot => {
            let d = l.position - p;
            let r2 = d.length_squared().max(1e-12);
            let mut e = l.radiance / r2;
            if let Some(range) = l.range {
                let x = (r2.sqrt() / range).powi(4);
                e *= (1.0 - x).clamp(0.0, 1.0).powi(2);
            }
            let to = d / r2.sqrt();
            if let (Kind::Spot, Some((inner, outer))) = (l.kind, l.cone) {
                let cd = (-to).dot(l.direction);
                let (ci, co) = (inner.cos(), outer.cos());
                e *= ((cd - co) / (ci - co).max(1e-4)).clamp(0.0, 1.0).powi(2);
            }
            (to, e)
        }
    }
}

/// Outgoing radiance of `s` toward `viewer`.
pub fn shade(s: &Surface, viewer: DVec3, lights: &[ShadeLight]) -> DVec3 {
    shade_visible(s, viewer, lights, |_| 1.0)
}

/// The light every surface gets without any light: [`AMBIENT`] of its albedo.
fn ambient(s: &Surface) -> DVec3 {
    s.albedo * AMBIENT
}

/// Rec. 709 luminance of linear RGB.
fn luminance(c: DVec3) -> f64 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// [`shade`] with light `i`'s contribution scaled by `visibility(i)` (the fraction of it that
/// reaches the point: shadows).
pub fn shade_visible(
    s: &Surface,
    viewer: DVec3,
    lights: &[ShadeLight],
    visibility: impl Fn(usize) -> f64,
) -> DVec3 {
    let v = (viewer - s.position).normalize_or_zero();
    let mut n = s.normal;
    if n.dot(v) < 0.0 {
        n = -n;
    }
    let alpha = (s.roughness.clamp(0.03, 1.0)).powi(2);
    let f0 = DVec3::splat(0.04).lerp(s.albedo, s.metallic);
    let diffuse = s.albedo * (1.0 - s.metallic) / std::f64::consts::PI;
    let mut out = ambient(s);
    for (i, l) in lights.iter().enumerate() {
        let (to_light, e) = arriving(l, s.position);
        let nl = n.dot(to_light);
        let seen = visibility(i);
        if nl <= 0.0 || seen <= 0.0 {
            continue;
        }
        let e = e * seen;
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

/// The lighting of pre-lit, view-independent images (the impostors and their triangle
/// reference, multi-cell-orthographic-impostors.txt §3.1 pre-lights its images once for every
/// view): a brighter ambient than [`AMBIENT`], so that the unlit side of a shape keeps its
/// detail as the paper's images do, and the scene's lights, or the default light from
/// [`DEFAULT_TO_LIGHT`] with the radiance that lights a facing white surface to
/// `1 − PRELIT_AMBIENT`.
#[derive(Debug, Clone)]
pub struct Prelit {
    pub ambient: f64,
    pub lights: Vec<ShadeLight>,
}

/// Ambient share of pre-lit images.
pub const PRELIT_AMBIENT: f64 = 0.3;

impl Prelit {
    pub fn of(scene: &Scene) -> Self {
        let mut lights = punctual(scene);
        if lights.is_empty() {
            let mut l = ShadeLight::default_toward(DVec3::from_array(DEFAULT_TO_LIGHT));
            l.radiance = DVec3::splat((1.0 - PRELIT_AMBIENT) * std::f64::consts::PI);
            lights.push(l);
        }
        Prelit {
            ambient: PRELIT_AMBIENT,
            lights,
        }
    }
}

/// The view-independent part of [`shade`] under `env`: ambient plus Lambertian diffuse of the
/// whole base colour, lit from whichever side the light is on (no viewer decides which side is
/// seen, and no specular lobe, which depends on the viewer).
pub fn diffuse(s: &Surface, env: &Prelit) -> DVec3 {
    let mut out = s.albedo * env.ambient;
    for l in &env.lights {
        let (to_light, e) = arriving(l, s.position);
        out += s.albedo / std::f64::consts::PI * e * s.normal.dot(to_light).abs();
    }
    out
}

/// A frame: the lit colour of every pixel of `gbuffer` (one image from `camera`), black where it
/// has no surface. `lights` are shaded in order, light i scaled at each pixel by
/// `visibility[i]` when given (row-major, one value per pixel). With no lights, or where they
/// leave the view dark ([`DARK_VIEW`]), the default light is added; the flag says whether it
/// was.
pub fn frame(
    scene: &Scene,
    camera: &Camera,
    gbuffer: &DepthImages,
    lights: &[ShadeLight],
    visibility: &[Option<Vec<f32>>],
) -> Result<(Vec<[f32; 3]>, bool)> {
    use rayon::prelude::*;
    let pixels = camera.width as usize * camera.height as usize;
    let sizes = [
        gbuffer.triangle.len(),
        gbuffer.position.len(),
        gbuffer.color.len(),
    ];
    if gbuffer.n != 1 || sizes.iter().any(|&n| n != pixels) {
        return input_err!(
            "a frame shades one {}x{} image; got {} image(s) of {} pixels",
            camera.width,
            camera.height,
            gbuffer.n,
            gbuffer.triangle.len() / gbuffer.n.max(1)
        );
    }
    if visibility.len() != lights.len() {
        return input_err!(
            "{} lights but {} visibility maps",
            lights.len(),
            visibility.len()
        );
    }
    if let Some(v) = visibility.iter().flatten().find(|v| v.len() != pixels) {
        return input_err!(
            "a visibility map has {} values for {pixels} pixels",
            v.len()
        );
    }
    let eye = camera.eye();
    let surfaces = scene.surfaces();
    let shaded = |lights: &[ShadeLight], visibility: &[Option<Vec<f32>>]| {
        (0..pixels)
            .into_par_iter()
            .map(|px| {
                let t = gbuffer.triangle[px];
                if t < 0 {
                    return ([0.0; 3], false);
                }
                let p = DVec3::from_array(gbuffer.position[px].map(f64::from));
                let s = pixel_surface(&surfaces, t as usize, p, gbuffer.color[px]);
                let seen = |i: usize| visibility[i].as_ref().map_or(1.0, |v| v[px] as f64);
                let c = shade_visible(&s, eye, lights, seen);
                let a = luminance(ambient(&s));
                (c.as_vec3().to_array(), a > 0.0 && luminance(c) >= 2.0 * a)
            })
            .collect::<Vec<_>>()
    };
    if lights.is_empty() {
        let out = shaded(&[default_light(camera)], &[None]);
        return Ok((out.into_iter().map(|(c, _)| c).collect(), true));
    }
    let out = shaded(lights, visibility);
    let seen = gbuffer.triangle.iter().filter(|&&t| t >= 0).count();
    let lit = out.iter().filter(|(_, lit)| *lit).count();
    let dark = seen > 0 && (lit as f64) < DARK_VIEW * seen as f64;
    if !dark {
        return Ok((out.into_iter().map(|(c, _)| c).collect(), false));
    }
    let mut more = lights.to_vec();
    more.push(default_light(camera));
    let mut vis = visibility.to_vec();
    vis.push(None);
    Ok((
        shaded(&more, &vis).into_iter().map(|(c, _)| c).collect(),
        true,
    ))
}

/// The surface of triangle `t` at `p` (`scene::surface`): its colour sampled for `footprint`
/// (the material's texture filtered over it), its shading normal turned to the geometric
/// normal's side, and the material's metallic and roughness (0 and 1 without a material).
pub fn surface(surfaces: &Surfaces, t: usize, p: DVec3, footprint: Footprint) -> Surface {
    let b = surfaces.barycentrics(t, p);
    let albedo = surfaces.color(t, b, footprint);
    surface_with(surfaces, t, p, b, albedo)
}

/// [`surface`] at a point whose colour `albedo` was resolved already (an image's pixel, its
/// texture filtered over the pixel's footprint).
pub fn pixel_surface(surfaces: &Surfaces, t: usize, p: DVec3, albedo: [f32; 3]) -> Surface {
    let b = surfaces.barycentrics(t, p);
    surface_with(surfaces, t, p, b, albedo)
}

fn surface_with(surfaces: &Surfaces, t: usize, p: DVec3, b: [f64; 2], albedo: [f32; 3]) -> Surface {
    let scene = surfaces.scene();
    let geometric = scene.face_normal(t);
    let n = DVec3::from_array(surfaces.shading_normal(t, b).map(f64::from));
    // Keep the interpolated normal on the geometric side of the face: the side a ray or an
    // eye meets is the one lit (a file whose normals disagree with its winding shades alike).
    let normal = if n.dot(geometric) < 0.0 { -n } else { n };
    let (metallic, roughness) = usize::try_from(scene.material_ids()[t])
        .ok()
        .and_then(|m| scene.materials().get(m))
        .map(|m| (m.metallic as f64, m.roughness as f64))
        .unwrap_or((0.0, 1.0));
    Surface {
        position: p,
        normal,
        albedo: DVec3::from_array(albedo.map(f64::from)),
        metallic,
        roughness,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_light_direction_is_unit() {
        let l = DVec3::from_array(DEFAULT_TO_LIGHT);
        assert!((l.length() - 1.0).abs() < 1e-15, "{}", l.length());
        // A white surface facing it is lit to 1 under the pre-lit environment.
        let env = Prelit {
            ambient: PRELIT_AMBIENT,
            lights: vec![{
                let mut d = ShadeLight::default_toward(l);
                d.radiance = DVec3::splat((1.0 - PRELIT_AMBIENT) * std::f64::consts::PI);
                d
            }],
        };
        let facing = Surface {
            position: DVec3::ZERO,
            normal: l,
            albedo: DVec3::ONE,
            metallic: 0.0,
            roughness: 1.0,
        };
        assert!((diffuse(&facing, &env) - DVec3::ONE).abs().max_element() < 1e-12);
    }

    /// A rough, grey (albedo 0.5) dielectric at the origin facing +z.
    fn grey_facing_z() -> Surface {
        Surface {
            position: DVec3::ZERO,
            normal: DVec3::Z,
            albedo: DVec3::splat(0.5),
            metallic: 0.0,
            roughness: 1.0,
        }
    }

    #[test]
    fn lambert_under_a_head_on_light() {
        let s = grey_facing_z();
        let l = ShadeLight {
            kind: Kind::Directional,
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
    fn visibility_scales_each_light_and_prelit_is_two_sided() {
        let s = grey_facing_z();
        let head_on = ShadeLight::default_toward(DVec3::Z);
        let eye = DVec3::new(0.0, 0.0, 5.0);
        let lit = shade(&s, eye, &[head_on]);
        let half = shade_visible(&s, eye, &[head_on], |_| 0.5);
        let dark = shade_visible(&s, eye, &[head_on], |_| 0.0);
        assert!((dark.x - 0.5 * AMBIENT).abs() < 1e-12);
        assert!(((half.x - dark.x) * 2.0 - (lit.x - dark.x)).abs() < 1e-12);
        // Pre-lit: ambient 0.3 plus 0.7 under the default light head on, from either side.
        let mut env = Prelit {
            ambient: PRELIT_AMBIENT,
            lights: vec![ShadeLight::default_toward(DVec3::Z)],
        };
        env.lights[0].radiance = DVec3::splat((1.0 - PRELIT_AMBIENT) * std::f64::consts::PI);
        let front = diffuse(&s, &env);
        let back = diffuse(
            &Surface {
                normal: -DVec3::Z,
                ..s
            },
            &env,
        );
        assert!((front.x - 0.5).abs() < 1e-12 && (back.x - front.x).abs() < 1e-12);
        // An area light lights a facing white surface to its albedo.
        let area = shade_visible(
            &s,
            eye,
            &[ShadeLight::area(DVec3::new(0.0, 0.0, 2.0))],
            |_| 1.0,
        );
        assert!(area.x > 0.5 * 0.9, "{area}");
    }
}
