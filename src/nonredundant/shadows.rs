//! Soft shadows from a discretized scene (non-redundant-rendering.txt §5, Algorithm 5): the
//! scene is discretized from the area light (non-redundant or conventional images from its
//! corners, or peeling layers from its centre), the images are reconstructed into meshes
//! (§4), and every light sample shadow-maps the meshes on the GPU (`gpu::shadow`). Two
//! references: shadow maps of the original triangles (`Geometry`, the paper's ground truth) and
//! exact visibility by BVH ray casts (`Raytraced`).

use std::time::Instant;

use glam::DVec3;

use crate::calibration::{Backend, BackendChoice};
use crate::camera::Camera;
use crate::error::Result;
use crate::gpu;
use crate::image::discretize_conventional;
use crate::input_err;
use crate::nonredundant::reconstruct::{reconstruct_hybrid, reconstruct_mesh, reconstruct_points};
use crate::nonredundant::{discretize_nonredundant, discretize_peeling, Redundancy};
use crate::scene::Scene;
use crate::shadow_rays::{eye_points, per_pixel, raytraced};
use crate::types::{DepthImages, Timings};

/// A rectangular area light: corners `center ± u/2 ± v/2`, emitting on both sides.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AreaLight {
    pub center: DVec3,
    pub u: DVec3,
    pub v: DVec3,
}

impl AreaLight {
    pub fn new(center: DVec3, u: DVec3, v: DVec3) -> Result<Self> {
        if !(center.is_finite() && u.is_finite() && v.is_finite()) {
            return input_err!("the light's center, u and v must be finite");
        }
        let n = u.cross(v);
        let scale = (u.length() * v.length()).max(f64::MIN_POSITIVE);
        if n.length() <= 1e-12 * scale || n.length().is_nan() {
            return input_err!("the light's u and v must be non-zero and not parallel");
        }
        Ok(Self { center, u, v })
    }

    /// Stratified samples at the centres of an `nu × nv` grid, row by row along v.
    pub fn samples(&self, nu: u32, nv: u32) -> Vec<DVec3> {
        let mut out = Vec::with_capacity((nu * nv) as usize);
        for b in 0..nv {
            for a in 0..nu {
                let s = (a as f64 + 0.5) / nu as f64 - 0.5;
                let t = (b as f64 + 0.5) / nv as f64 - 0.5;
                out.push(self.center + self.u * s + self.v * t);
            }
        }
        out
    }

    pub fn corners(&self) -> [DVec3; 4] {
        let (hu, hv) = (self.u * 0.5, self.v * 0.5);
        [
            self.center - hu - hv,
            self.center + hu - hv,
            self.center + hu + hv,
            self.center - hu + hv,
        ]
    }

    /// The light's unit normal on the side of `target`.
    pub fn facing(&self, target: DVec3) -> DVec3 {
        let n = self.u.cross(self.v).normalize();
        if n.dot(target - self.center) >= 0.0 {
            n
        } else {
            -n
        }
    }
}

/// How the occluders are represented.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Discretization {
    Nonredundant,
    Conventional,
    Peeling,
    Geometry,
    Raytraced,
}

impl Discretization {
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "nonredundant" => Self::Nonredundant,
            "conventional" => Self::Conventional,
            "peeling" => Self::Peeling,
            "geometry" => Self::Geometry,
            "raytraced" => Self::Raytraced,
            _ => return None,
        })
    }
}

/// Which reconstruction turns the light's depth images into occluders.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reconstruction {
    Hybrid,
    Mesh,
    Points,
}

#[derive(Clone, Debug)]
pub struct ShadowOptions {
    /// Light samples along u and v.
    pub samples: (u32, u32),
    pub discretization: Discretization,
    /// Resolution of the light's depth images (square).
    pub resolution: u32,
    /// Depth images from the light's four corners (`false`: one from its centre); peeling
    /// always uses the centre.
    pub corners: bool,
    pub reconstruction: Reconstruction,
    /// Resolution of each light sample's shadow map (square).
    pub shadow_resolution: u32,
    /// Peeling layers.
    pub layers: u32,
}

pub struct ShadowResult {
    pub width: u32,
    pub height: u32,
    /// Fraction of light samples visible from each output pixel (1 where no surface).
    pub visibility: Vec<f32>,
    /// Per pixel, per light sample (sample fastest).
    pub visible: Vec<bool>,
    /// Output pixels that see a surface.
    pub mask: Vec<bool>,
    /// Occluder triangles each shadow map drew (0 for `Raytraced`).
    pub occluder_triangles: usize,
    pub timings: Timings,
}

/// A shadow or depth camera at `at` facing `dir`, square, whose view holds every corner of the
/// scene's bounding box (2% margin; yfov at most 170°).
pub fn light_camera(
    scene: &Scene,
    at: DVec3,
    dir: DVec3,
    up_hint: DVec3,
    res: u32,
) -> Result<Camera> {
    let [lo, hi] = scene.bounds();
    let up = {
        let u = up_hint - dir * dir.dot(up_hint);
        if u.length() > 1e-9 {
            u.normalize()
        } else {
            dir.any_orthonormal_vector()
        }
    };
    let right = dir.cross(up);
    let mut tan_max: f64 = 1e-3;
    for k in 0..8 {
        let c = DVec3::new(
            if k & 1 == 0 { lo[0] } else { hi[0] } as f64,
            if k & 2 == 0 { lo[1] } else { hi[1] } as f64,
            if k & 4 == 0 { lo[2] } else { hi[2] } as f64,
        );
        let r = c - at;
        let z = r.dot(dir);
        let t = if z > 1e-12 {
            r.dot(right).abs().max(r.dot(up).abs()) / z
        } else {
            f64::INFINITY
        };
        tan_max = tan_max.max(t);
    }
    let limit = (85f64).to_radians();
    let half = (tan_max * 1.02).atan().min(limit);
    Camera::look_at(at, at + dir, up, 2.0 * half, res, res, None, None)
}

/// Algorithm 5 with the output image of `eye`.
pub fn soft_shadows(
    scene: &Scene,
    eye: &Camera,
    light: &AreaLight,
    opts: &ShadowOptions,
) -> Result<ShadowResult> {
    let total = Instant::now();
    let (nu, nv) = opts.samples;
    if nu == 0 || nv == 0 {
        return input_err!("samples must be positive, got {nu}x{nv}");
    }
    if opts.resolution == 0 || opts.shadow_resolution == 0 {
        return input_err!("resolution and shadow_resolution must be positive");
    }
    // A visibility bit per eye pixel and light sample, and one shadow map at a time.
    let (w, h) = (eye.width as u64, eye.height as u64);
    crate::limits::check(
        || format!("{nu}x{nv} light samples for {w}x{h} eye pixels"),
        crate::limits::product(&[w, h, nu as u64, nv as u64]).div_ceil(8),
        1,
    )?;
    let side = opts.shadow_resolution as u64;
    crate::limits::check(
        || format!("a shadow map of {side}x{side}"),
        crate::limits::product(&[side, side]),
        8,
    )?;
    let mut timings = Timings::new();

    // The output image's surface points, with normals facing the eye.
    let start = Instant::now();
    let seen = discretize_conventional(scene, std::slice::from_ref(eye), false)?;
    let (points, normals, mask) = eye_points(&seen, eye);
    timings.add("eye", start.elapsed().as_secs_f64());

    let samples = light.samples(nu, nv);
    let diagonal = scene.diagonal();
    let s_count = samples.len();
    let (occluder_triangles, bits) = match opts.discretization {
        Discretization::Raytraced => {
            let start = Instant::now();
            let bits = raytraced(scene, &samples, &points, &normals, diagonal)?;
            timings.add("shadow", start.elapsed().as_secs_f64());
            (0, bits)
        }
        d => {
            // Steps 1-2 (none for `Geometry`, which draws the scene's own triangles).
            let mesh = if d == Discretization::Geometry {
                None
            } else {
                let start = Instant::now();
                let (images, offset) = discretize_light(scene, light, d, opts)?;
                timings.add("discretize", start.elapsed().as_secs_f64());
                let start = Instant::now();
                let mesh = match (opts.reconstruction, offset) {
                    (Reconstruction::Hybrid, Some(offset)) => reconstruct_hybrid(&images, &offset)?,
                    (Reconstruction::Hybrid, None) => {
                        return input_err!("hybrid reconstruction needs the offset images")
                    }
                    (Reconstruction::Points, _) => reconstruct_points(&images)?,
                    (Reconstruction::Mesh, _) => reconstruct_mesh(&images)?,
                };
                timings.add("reconstruct", start.elapsed().as_secs_f64());
                Some(mesh)
            };
            let (vertices, faces) = match &mesh {
                Some(m) => (&m.vertices[..], &m.faces[..]),
                None => (scene.vertices(), scene.faces()),
            };
            let start = Instant::now();
            let bits = shadow_maps(
                scene,
                vertices,
                faces,
                light,
                &samples,
                &points,
                &normals,
                opts.shadow_resolution,
            )?;
            timings.add("shadow", start.elapsed().as_secs_f64());
            (faces.len(), bits)
        }
    };

    let (visible, visibility) = per_pixel(&bits, &mask, s_count);
    timings.add("total", total.elapsed().as_secs_f64());
    Ok(ShadowResult {
        width: eye.width,
        height: eye.height,
        visibility,
        visible,
        mask,
        occluder_triangles,
        timings,
    })
}

type LightImages = (DepthImages, Option<DepthImages>);

/// Step 1: the light's depth images (and, for hybrid reconstruction, their offset images).
fn discretize_light(
    scene: &Scene,
    light: &AreaLight,
    d: Discretization,
    opts: &ShadowOptions,
) -> Result<LightImages> {
    let dir = light.facing(scene.center());
    let up = light.v;
    let res = opts.resolution;
    let views: Vec<DVec3> = if opts.corners && d != Discretization::Peeling {
        light.corners().to_vec()
    } else {
        vec![light.center]
    };
    let cams = views
        .iter()
        .map(|&at| light_camera(scene, at, dir, up, res))
        .collect::<Result<Vec<_>>>()?;
    let render = |cams: &[Camera]| -> Result<DepthImages> {
        match d {
            Discretization::Nonredundant => {
                let gpu = BackendChoice::Fixed(Backend::Gpu);
                discretize_nonredundant(scene, cams, Redundancy::Pixel, false, gpu).map(|r| r.0)
            }
            Discretization::Conventional => discretize_conventional(scene, cams, false),
            _ => discretize_peeling(scene, &cams[0], opts.layers as usize, false),
        }
    };
    let images = render(&cams)?;
    let offset = if opts.reconstruction == Reconstruction::Hybrid {
        let corners = cams
            .iter()
            .map(Camera::corner_camera)
            .collect::<Result<Vec<_>>>()?;
        Some(render(&corners)?)
    } else {
        None
    };
    Ok((images, offset))
}

/// Steps 4-9: one shadow map of the occluders per light sample.
#[allow(clippy::too_many_arguments)]
fn shadow_maps(
    scene: &Scene,
    vertices: &[[f32; 3]],
    faces: &[[u32; 3]],
    light: &AreaLight,
    samples: &[DVec3],
    points: &[DVec3],
    normals: &[DVec3],
    res: u32,
) -> Result<Vec<u32>> {
    let ctx = gpu::context()?;
    let dir = light.facing(scene.center());
    let cams = samples
        .iter()
        .map(|&at| light_camera(scene, at, dir, light.v, res))
        .collect::<Result<Vec<_>>>()?;
    // Depth range from everything drawn or tested: the scene, the occluders and the points.
    let mut lo = DVec3::from_array(scene.bounds()[0].map(f64::from));
    let mut hi = DVec3::from_array(scene.bounds()[1].map(f64::from));
    for v in vertices {
        let p = DVec3::from_array(v.map(f64::from));
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let bounds = [lo.as_vec3().to_array(), hi.as_vec3().to_array()];
    let (bits, _) = gpu::shadow::visibility(
        &ctx,
        vertices,
        faces,
        scene.center(),
        bounds,
        &cams,
        points,
        normals,
        scene.diagonal(),
    )?;
    Ok(bits)
}
