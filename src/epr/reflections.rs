//! Dynamic cube-mapped reflections three ways (eye-based-point-rendering.txt §4):
//!
//! - **EPR** (§4.1): eye-resolution points (`super::points`, Eq. 2-4) splatted into each
//!   reflector's six cube faces, which hold only point indices; eye-based deferred shading
//!   (§4.1.2): an off-screen texel is shaded only when a reflective eye pixel looks it up, each
//!   looked-up texel once; each reflective pixel averages `supersample` lookups along
//!   reflection directions from Poisson-distributed normals spread over the pixel's normal
//!   gradient (§4.1.3); further bounces follow the looked-up point's own reflector (§4.1.4),
//!   with no further geometry pass.
//! - **MVR**: each cube face rasterized conventionally, every covered texel shaded, mip-mapped
//!   (box-filtered) lookups at the level the pixel's reflection footprint needs (trilinear,
//!   within a face). A further bounce re-shades the reflective texels with lookups into the
//!   previous bounce's cubes.
//! - **iVIR**: points at the off-screen texel density (`Density::OffScreen`) splatted like EPR's,
//!   then shaded and looked up like MVR's.
//!
//! Cube maps are centred on each reflector's bounding sphere with their near plane on the
//! sphere, so the reflector's own triangles never enter its own cube map (EPR also clears their
//! visibility bits). All three methods follow glTF's sidedness in the cube maps: the back face
//! of a single-sided triangle is invisible there (MVR culls it, EPR and iVIR clear its bit for
//! the cube maps it turns its back to), a double-sided one is seen from both sides. Lookups
//! treat the environment as distant (no parallax correction), the same for all three methods.
//! All shading uses `shading::shade` with the cube's centre as the viewer.

use std::time::Instant;

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::points::{self, Density, Reflector};
use crate::camera::Camera;
use crate::error::Result;
use crate::image::{discretize_conventional, discretize_sided};
use crate::input_err;
use crate::scene::surface::{Footprint, Surfaces};
use crate::scene::Scene;
use crate::shading::{self, ShadeLight};
use crate::types::{DepthImages, Stats, Timings};

/// Radiance where a ray leaves the scene.
pub const BACKGROUND: [f64; 3] = [0.25, 0.3, 0.36];
/// Lookups per reflective pixel on bounces after the first (§4.1.4 uses 4).
pub const LATER_BOUNCE_SAMPLES: usize = 4;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    Epr,
    Mvr,
    Ivir,
}

impl Method {
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "epr" => Some(Self::Epr),
            "mvr" => Some(Self::Mvr),
            "ivir" => Some(Self::Ivir),
            _ => None,
        }
    }
}

#[derive(Debug, Clone)]
pub struct ReflectionOptions {
    pub method: Method,
    pub bounces: u32,
    pub supersample: usize,
    pub rho_scale: f64,
    pub seed: u64,
    /// Cube-map face resolution per reflector.
    pub resolutions: Vec<u32>,
}

#[derive(Debug, Clone)]
pub struct ReflectionResult {
    pub width: u32,
    pub height: u32,
    /// Linear RGB per eye pixel, row-major.
    pub image: Vec<[f32; 3]>,
    /// Whether each eye pixel shows a reflector.
    pub reflective: Vec<bool>,
    pub stats: Stats,
    pub timings: Timings,
}

/// Per texel of a cube map: the triangle seen (−1 none) and the world point.
type TexelSamples = (Vec<i32>, Vec<[f32; 3]>);

/// One reflector's cube map: six faces of `res`², texel samples as (triangle, world point).
struct Cube {
    res: u32,
    faces: Vec<Camera>,
    center: DVec3,
    triangle: Vec<i32>,
    position: Vec<[f32; 3]>,
}

impl Cube {
    /// The face and texel a direction from the centre lands on.
    fn texel(&self, dir: DVec3) -> usize {
        let face = Camera::cube_face(dir);
        let (px, _) = self.faces[face].project(self.center + dir);
        let r = self.res as f64;
        let x = px.x.clamp(0.0, r - 1.0) as usize;
        let y = px.y.clamp(0.0, r - 1.0) as usize;
        (face * self.res as usize + y) * self.res as usize + x
    }

    /// Continuous face coordinates (face, texel x, texel y) of a direction.
    fn coords(&self, dir: DVec3) -> (usize, DVec2) {
        let t = self.texel(dir);
        let face = t / (self.res as usize * self.res as usize);
        let (px, _) = self.faces[face].project(self.center + dir);
        (face, px)
    }
}

/// The options [`reflections`] accepts for `reflectors`.
fn check_options(reflectors: &[Reflector], opts: &ReflectionOptions) -> Result<()> {
    if opts.resolutions.len() != reflectors.len() || opts.resolutions.contains(&0) {
        return input_err!(
            "one cube-map resolution (>= 1) per reflector: {} reflectors, resolutions {:?}",
            reflectors.len(),
            opts.resolutions
        );
    }
    if opts.bounces == 0 || opts.bounces > 8 {
        return input_err!("bounces must be 1..=8, got {}", opts.bounces);
    }
    if opts.supersample == 0 || opts.supersample > 256 {
        return input_err!("supersample must be 1..=256, got {}", opts.supersample);
    }
    Ok(())
}

/// MVR's cube maps (§6 baseline): every face rasterized from the reflector's centre, with the
/// scene's sidedness. One raster call per resolution (a call needs one size): usually one in all.
fn mvr_cubes(scene: &Scene, reflectors: &[Reflector], resolutions: &[u32]) -> Result<Vec<Cube>> {
    let views = points::cube_views(reflectors, resolutions)?;
    let mut cubes = Vec::with_capacity(reflectors.len());
    let mut images: Vec<Option<TexelSamples>> = vec![None; reflectors.len()];
    let mut sizes: Vec<u32> = resolutions.to_vec();
    sizes.sort_unstable();
    sizes.dedup();
    for size in sizes {
        let ks: Vec<usize> = (0..reflectors.len())
            .filter(|&k| resolutions[k] == size)
            .collect();
        let cams: Vec<Camera> = ks
            .iter()
            .flat_map(|&k| views[6 * k..6 * k + 6].iter().cloned())
            .collect();
        let img = discretize_sided(scene, &cams)?;
        let per = 6 * size as usize * size as usize;
        for (j, &k) in ks.iter().enumerate() {
            images[k] = Some((
                img.triangle[j * per..(j + 1) * per].to_vec(),
                img.position[j * per..(j + 1) * per].to_vec(),
            ));
        }
    }
    for ((r, faces), img) in reflectors.iter().zip(views.chunks(6)).zip(images) {
        let faces = faces.to_vec();
        let (triangle, position) = img.unwrap_or_default();
        cubes.push(Cube {
            res: faces[0].width,
            faces,
            center: r.center,
            triangle,
            position,
        });
    }
    Ok(cubes)
}

/// EPR's and iVIR's cube maps (§3.5): one splat pass of `points` into every cube face, each at
/// its reflector's resolution; each texel takes the nearest point's triangle and centre.
fn splat_cubes(
    scene: &Scene,
    reflectors: &[Reflector],
    resolutions: &[u32],
    points: &crate::types::Points,
) -> Result<Vec<Cube>> {
    let views = points::cube_views(reflectors, resolutions)?;
    let mut cubes = Vec::with_capacity(reflectors.len());
    let (keys, _) = super::splat::splat_views(scene, points, &views, true)?;
    let mut index = Vec::with_capacity(reflectors.len());
    let mut at = 0;
    for &res in resolutions {
        let n = 6 * res as usize * res as usize;
        index.push(
            keys[at..at + n]
                .iter()
                .map(|&k| {
                    if k == u64::MAX {
                        -1
                    } else {
                        (k & 0xffff_ffff) as i64
                    }
                })
                .collect::<Vec<i64>>(),
        );
        at += n;
    }
    for (k, r) in reflectors.iter().enumerate() {
        let faces = views[6 * k..6 * k + 6].to_vec();
        let (tri, pos): (Vec<i32>, Vec<[f32; 3]>) = index[k]
            .iter()
            .map(|&i| match usize::try_from(i) {
                Ok(i) => (points.triangle[i], points.center[i]),
                Err(_) => (-1, [f32::NAN; 3]),
            })
            .unzip();
        cubes.push(Cube {
            res: resolutions[k],
            faces,
            center: r.center,
            triangle: tri,
            position: pos,
        });
    }
    Ok(cubes)
}

/// The reflectors' cube maps (§4.1): rendered (MVR), or splatted from points made at the
/// eye's density (EPR) or at the maps' own (iVIR); and how many points.
fn cube_maps(
    scene: &Scene,
    eye: &Camera,
    reflectors: &[Reflector],
    opts: &ReflectionOptions,
    timings: &mut Timings,
) -> Result<(Vec<Cube>, usize)> {
    let start = Instant::now();
    let density = match opts.method {
        Method::Mvr => {
            let cubes = mvr_cubes(scene, reflectors, &opts.resolutions)?;
            timings.add("views", start.elapsed().as_secs_f64());
            return Ok((cubes, 0));
        }
        Method::Epr => Density::Eye {
            rho_scale: opts.rho_scale,
        },
        Method::Ivir => Density::OffScreen,
    };
    let res = &opts.resolutions;
    let points = points::generate(scene, eye, reflectors, res, density, opts.seed)?;
    timings.add("points", start.elapsed().as_secs_f64());
    let start = Instant::now();
    let cubes = splat_cubes(scene, reflectors, res, &points)?;
    timings.add("views", start.elapsed().as_secs_f64());
    Ok((cubes, points.len()))
}

/// The bytes a method's buffers hold for `texels` cube-map texels and `points` points.
fn buffer_bytes(method: Method, texels: usize, points: usize, cubes: usize) -> usize {
    match method {
        // Index buffers of 64-bit keys, and the points (centre, length, triangle, normal,
        // material, one visibility word per 64 views).
        Method::Epr | Method::Ivir => {
            texels * 8 + points * (12 + 4 + 4 + 12 + 4 + 8 * (6 * cubes).div_ceil(64))
        }
        // G-buffer (triangle id, position) and colour with its mip chain (4/3).
        Method::Mvr => texels * (4 + 12) + texels * 12 * 4 / 3,
    }
}

/// Render reflections of `reflectors` seen from `eye`.
pub fn reflections(
    scene: &Scene,
    eye: &Camera,
    reflectors: &[Reflector],
    opts: &ReflectionOptions,
) -> Result<ReflectionResult> {
    let total = Instant::now();
    if reflectors.is_empty() {
        return input_err!("reflections need at least one reflector");
    }
    crate::counters::add(crate::counters::Op::CubeMaps, reflectors.len() as u64);
    check_options(reflectors, opts)?;
    let mut timings = Timings::new();
    let mut stats = Stats::new();

    // The eye's G-buffer.
    let start = Instant::now();
    let gbuf = discretize_conventional(scene, std::slice::from_ref(eye), false)?;
    timings.add("eye", start.elapsed().as_secs_f64());
    let mut owner = vec![-1i32; scene.triangle_count()];
    for (k, r) in reflectors.iter().enumerate() {
        for &t in &r.triangles {
            if let Some(o) = owner.get_mut(t as usize) {
                *o = k as i32;
            }
        }
    }

    let (cubes, point_count) = cube_maps(scene, eye, reflectors, opts, &mut timings)?;
    let texels: usize = cubes.iter().map(|c| c.triangle.len()).sum();

    let lights = shading::lights(scene, eye);
    let ctx = Shader {
        surfaces: scene.surfaces(),
        owner: &owner,
        cubes: &cubes,
        lights: &lights,
        bounces: opts.bounces,
        later_offsets: poisson(LATER_BOUNCE_SAMPLES),
    };
    let (w, h) = (eye.width as usize, eye.height as usize);
    let pixels = eye_pixels(&ctx.surfaces, eye, &gbuf, &owner);
    let (image, shading_ops) = match opts.method {
        Method::Epr => {
            let start = Instant::now();
            let (img, ops) = ctx.eye_deferred(&pixels, w, h, opts.supersample);
            timings.add("deferred", start.elapsed().as_secs_f64());
            (img, ops)
        }
        Method::Mvr | Method::Ivir => {
            let start = Instant::now();
            let (maps, ops) = ctx.shade_all(opts.bounces);
            timings.add("shade", start.elapsed().as_secs_f64());
            let start = Instant::now();
            let img = ctx.eye_mipmapped(&pixels, w, h, &maps);
            timings.add("deferred", start.elapsed().as_secs_f64());
            (img, ops)
        }
    };
    let reflective: Vec<bool> = pixels.iter().map(|p| p.reflector >= 0).collect();
    let buffer_bytes = buffer_bytes(opts.method, texels, point_count, cubes.len());
    stats.set("points", point_count as f64);
    stats.set("shading_ops", shading_ops as f64);
    stats.set("offscreen_pixels", texels as f64);
    stats.set("buffer_bytes", buffer_bytes as f64);
    stats.set(
        "reflective_pixels",
        reflective.iter().filter(|&&r| r).count() as f64,
    );
    timings.add("total", total.elapsed().as_secs_f64());
    Ok(ReflectionResult {
        width: eye.width,
        height: eye.height,
        image: image.into_iter().map(|c| c.as_vec3().to_array()).collect(),
        reflective,
        stats,
        timings,
    })
}

/// What the eye sees at one pixel.
#[derive(Clone, Copy)]
struct EyePixel {
    triangle: i32,
    position: DVec3,
    normal: DVec3,
    /// The eye image's colour there (its texture filtered over the pixel).
    albedo: [f32; 3],
    /// Unit direction from the eye to the surface.
    view: DVec3,
    reflector: i32,
}

fn eye_pixels(surfaces: &Surfaces, eye: &Camera, g: &DepthImages, owner: &[i32]) -> Vec<EyePixel> {
    let e = eye.eye();
    (0..g.triangle.len())
        .into_par_iter()
        .map(|i| {
            let t = g.triangle[i];
            if t < 0 {
                return EyePixel {
                    triangle: -1,
                    position: DVec3::ZERO,
                    normal: DVec3::ZERO,
                    albedo: [0.0; 3],
                    view: DVec3::ZERO,
                    reflector: -1,
                };
            }
            let p = DVec3::from_array(g.position[i].map(f64::from));
            let s = shading::pixel_surface(surfaces, t as usize, p, g.color[i]);
            let view = (p - e).normalize_or_zero();
            let n = toward(s.normal, view);
            EyePixel {
                triangle: t,
                position: p,
                normal: n,
                albedo: g.color[i],
                view,
                reflector: owner[t as usize],
            }
        })
        .collect()
}

/// The footprint of cube `cube`'s texel at `p`: the side a texel (90° over `res` texels)
/// spans at `p`'s distance from the cube's centre.
fn texel_footprint(cube: &Cube, p: DVec3) -> Footprint {
    Footprint::World((p - cube.center).length() * 2.0 / cube.res as f64)
}

fn reflect(d: DVec3, n: DVec3) -> DVec3 {
    d - 2.0 * d.dot(n) * n
}

/// `n`, flipped if need be to face against the viewing direction `view`.
fn toward(n: DVec3, view: DVec3) -> DVec3 {
    if n.dot(view) > 0.0 {
        -n
    } else {
        n
    }
}

/// The mirror direction at surface `s` seen from `from` (a cube map's centre).
fn reflected(s: &shading::Surface, from: DVec3) -> DVec3 {
    let view = (s.position - from).normalize_or_zero();
    reflect(view, toward(s.normal, view))
}

/// The normal offsets of a pixel: half the difference to the neighbouring pixels of the same
/// reflector on each axis (zero where there is none).
fn normal_gradient(px: &[EyePixel], w: usize, h: usize, i: usize) -> (DVec3, DVec3) {
    let (x, y) = (i % w, i / w);
    let k = px[i].reflector;
    let diff = |a: Option<usize>, b: Option<usize>| -> DVec3 {
        let ok = |j: Option<usize>| j.filter(|&j| px[j].reflector == k);
        match (ok(a), ok(b)) {
            (Some(a), Some(b)) => (px[b].normal - px[a].normal) / 2.0,
            (None, Some(b)) => px[b].normal - px[i].normal,
            (Some(a), None) => px[i].normal - px[a].normal,
            (None, None) => DVec3::ZERO,
        }
    };
    let left = (x > 0).then(|| i - 1);
    let right = (x + 1 < w).then(|| i + 1);
    let up = (y > 0).then(|| i - w);
    let down = (y + 1 < h).then(|| i + w);
    (diff(left, right), diff(up, down))
}

/// `n` well-spread points in [−0.5, 0.5]² (Mitchell's best candidate, fixed seed): the Poisson
/// distributed supersamples of §4.1.3, the same for every pixel.
fn poisson(n: usize) -> Vec<DVec2> {
    let mut state = 0x5eed_u64;
    let mut next = || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        (crate::random::mix64(state) >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut pts: Vec<DVec2> = Vec::with_capacity(n);
    if n == 1 {
        return vec![DVec2::ZERO];
    }
    for _ in 0..n {
        let mut best = DVec2::ZERO;
        let mut best_d = -1.0;
        for _ in 0..(10 * pts.len() + 1) {
            let c = DVec2::new(next(), next());
            let d = pts
                .iter()
                .map(|p| p.distance_squared(c))
                .fold(f64::INFINITY, f64::min);
            if d > best_d {
                best_d = d;
                best = c;
            }
        }
        pts.push(best);
    }
    pts
}

struct Shader<'a> {
    surfaces: Surfaces<'a>,
    owner: &'a [i32],
    cubes: &'a [Cube],
    lights: &'a [ShadeLight],
    bounces: u32,
    /// The lookups of bounces after the first (`poisson(LATER_BOUNCE_SAMPLES)`, made once).
    later_offsets: Vec<DVec2>,
}

impl Shader<'_> {
    /// Radiance of cube `c`'s texel `t` toward the cube's centre; `depth` bounces done so far.
    /// Counts shading evaluations in `ops`.
    fn texel_radiance(&self, c: usize, t: usize, depth: u32, ops: &mut u64) -> DVec3 {
        let cube = &self.cubes[c];
        let Ok(tri) = usize::try_from(cube.triangle[t]) else {
            return DVec3::from_array(BACKGROUND);
        };
        let p = DVec3::from_array(cube.position[t].map(f64::from));
        let s = shading::surface(&self.surfaces, tri, p, texel_footprint(cube, p));
        let k = self.owner[tri];
        if k >= 0 && depth < self.bounces {
            // A reflector seen in a reflector: follow its own cube map (§4.1.4).
            let r = reflected(&s, cube.center);
            let next = &self.cubes[k as usize];
            let mut sum = DVec3::ZERO;
            // Spread the later bounce over about one texel of the current cube.
            let spread = 2.0 / cube.res as f64;
            let (u, v) = r.any_orthonormal_pair();
            for o in &self.later_offsets {
                let d = (r + (u * o.x + v * o.y) * spread).normalize_or(r);
                let tt = next.texel(d);
                sum += self.texel_radiance(k as usize, tt, depth + 1, ops);
            }
            *ops += 1;
            return s.albedo * sum / self.later_offsets.len() as f64;
        }
        *ops += 1;
        shading::shade(&s, cube.center, self.lights)
    }

    /// EPR's eye-based deferred shading: each reflective pixel looks up `samples` texels; each
    /// distinct texel looked up is shaded once.
    fn eye_deferred(
        &self,
        px: &[EyePixel],
        w: usize,
        h: usize,
        samples: usize,
    ) -> (Vec<DVec3>, u64) {
        let offsets = poisson(samples);
        let per = offsets.len().max(1);
        // Texel t of cube c is texel base[c] + t of all the cubes.
        let mut base = vec![0usize];
        for cube in self.cubes {
            base.push(base[base.len() - 1] + cube.triangle.len());
        }
        // The reflective pixels and the texels each looks up, `per` after `per`.
        let reflective: Vec<usize> = (0..px.len())
            .filter(|&i| px[i].reflector >= 0 && px[i].triangle >= 0)
            .collect();
        let mut lookups = vec![0usize; reflective.len() * per];
        lookups
            .par_chunks_mut(per)
            .zip(&reflective)
            .for_each(|(out, &i)| {
                let p = &px[i];
                let (gx, gy) = normal_gradient(px, w, h, i);
                let c = p.reflector as usize;
                for (o, slot) in offsets.iter().zip(out.iter_mut()) {
                    let n = (p.normal + gx * o.x + gy * o.y).normalize_or(p.normal);
                    *slot = base[c] + self.cubes[c].texel(reflect(p.view, n));
                }
            });
        // Each distinct texel once, in the order of first lookup; lookups become its slot.
        let mut slot = vec![usize::MAX; base[base.len() - 1]];
        let mut unique: Vec<usize> = Vec::new();
        for l in lookups.iter_mut() {
            let s = &mut slot[*l];
            if *s == usize::MAX {
                *s = unique.len();
                unique.push(*l);
            }
            *l = *s;
        }
        let shaded: Vec<(DVec3, u64)> = unique
            .par_iter()
            .map(|&g| {
                let c = base.partition_point(|&b| b <= g) - 1;
                let mut ops = 0;
                let r = self.texel_radiance(c, g - base[c], 1, &mut ops);
                (r, ops)
            })
            .collect();
        let ops = shaded.iter().map(|s| s.1).sum();
        let mut row = vec![usize::MAX; px.len()];
        for (r, &i) in reflective.iter().enumerate() {
            row[i] = r;
        }
        let image = self.eye_image(px, |i, _| {
            let sum: DVec3 = lookups[row[i] * per..(row[i] + 1) * per]
                .iter()
                .map(|&s| shaded[s].0)
                .sum();
            sum / per as f64
        });
        (image, ops)
    }

    /// The eye image: the sky where the eye sees nothing, direct shading where it sees no
    /// reflector, and the albedo times `reflected(i, pixel)` on the reflectors' pixels.
    fn eye_image(
        &self,
        px: &[EyePixel],
        reflected: impl Fn(usize, &EyePixel) -> DVec3 + Sync,
    ) -> Vec<DVec3> {
        (0..px.len())
            .into_par_iter()
            .map(|i| {
                let p = &px[i];
                if p.triangle < 0 {
                    return DVec3::from_array(BACKGROUND);
                }
                let s = shading::pixel_surface(
                    &self.surfaces,
                    p.triangle as usize,
                    p.position,
                    p.albedo,
                );
                if p.reflector < 0 {
                    return shading::shade(&s, p.position - p.view, self.lights);
                }
                s.albedo * reflected(i, p)
            })
            .collect()
    }

    /// MVR / iVIR: shade every covered texel of every cube, `bounces` times (each later bounce
    /// re-shades the reflective texels from the previous bounce's maps), and build mip chains.
    fn shade_all(&self, bounces: u32) -> (Vec<Vec<Mip>>, u64) {
        let mut ops = 0u64;
        // First bounce: direct shading of every covered texel.
        let mut colour: Vec<Vec<DVec3>> = self
            .cubes
            .iter()
            .map(|cube| {
                (0..cube.triangle.len())
                    .into_par_iter()
                    .map(|t| match usize::try_from(cube.triangle[t]) {
                        Ok(tri) => {
                            let p = DVec3::from_array(cube.position[t].map(f64::from));
                            let s =
                                shading::surface(&self.surfaces, tri, p, texel_footprint(cube, p));
                            shading::shade(&s, cube.center, self.lights)
                        }
                        Err(_) => DVec3::from_array(BACKGROUND),
                    })
                    .collect()
            })
            .collect();
        ops += self
            .cubes
            .iter()
            .map(|c| c.triangle.iter().filter(|&&t| t >= 0).count() as u64)
            .sum::<u64>();
        for _ in 1..bounces {
            let previous = colour.clone();
            for (c, cube) in self.cubes.iter().enumerate() {
                let redo: Vec<(usize, DVec3)> = (0..cube.triangle.len())
                    .into_par_iter()
                    .filter_map(|t| {
                        let tri = usize::try_from(cube.triangle[t]).ok()?;
                        let k = self.owner[tri];
                        if k < 0 {
                            return None;
                        }
                        let p = DVec3::from_array(cube.position[t].map(f64::from));
                        let s = shading::surface(&self.surfaces, tri, p, texel_footprint(cube, p));
                        let next = &self.cubes[k as usize];
                        let r = next.texel(reflected(&s, cube.center));
                        Some((t, s.albedo * previous[k as usize][r]))
                    })
                    .collect();
                ops += redo.len() as u64;
                for (t, v) in redo {
                    colour[c][t] = v;
                }
            }
        }
        let maps = self
            .cubes
            .iter()
            .zip(colour)
            .map(|(cube, col)| {
                let n = cube.res as usize;
                (0..6)
                    .map(|f| Mip::build(col[f * n * n..(f + 1) * n * n].to_vec(), n))
                    .collect()
            })
            .collect();
        (maps, ops)
    }

    /// The eye image from shaded, mip-mapped cube maps: each reflective pixel samples the
    /// level whose texels match its reflection footprint.
    fn eye_mipmapped(&self, px: &[EyePixel], w: usize, h: usize, maps: &[Vec<Mip>]) -> Vec<DVec3> {
        self.eye_image(px, |i, p| {
            let (gx, gy) = normal_gradient(px, w, h, i);
            let r = reflect(p.view, p.normal);
            let rx = reflect(p.view, (p.normal + gx).normalize_or(p.normal));
            let ry = reflect(p.view, (p.normal + gy).normalize_or(p.normal));
            let cube = &self.cubes[p.reflector as usize];
            // Footprint in texels: angle spanned × texels per radian at the face centre.
            let spread = (rx - r).length().max((ry - r).length());
            let texels = spread * cube.res as f64 / 2.0;
            let level = texels.max(1.0).log2();
            let (face, at) = cube.coords(r);
            maps[p.reflector as usize][face].sample(at, level)
        })
    }
}

/// A face's colour and its box-filtered mip chain.
struct Mip {
    levels: Vec<(usize, Vec<DVec3>)>,
}

impl Mip {
    fn build(base: Vec<DVec3>, n: usize) -> Self {
        let mut levels = vec![(n, base)];
        while let Some((m, prev)) = levels.last().filter(|l| l.0 > 1) {
            let half = m.div_ceil(2);
            let mut next = vec![DVec3::ZERO; half * half];
            for y in 0..half {
                for x in 0..half {
                    let mut sum = DVec3::ZERO;
                    let mut k = 0.0;
                    for dy in 0..2 {
                        for dx in 0..2 {
                            let (sx, sy) = (2 * x + dx, 2 * y + dy);
                            if sx < *m && sy < *m {
                                sum += prev[sy * m + sx];
                                k += 1.0;
                            }
                        }
                    }
                    next[y * half + x] = sum / k;
                }
            }
            levels.push((half, next));
        }
        Self { levels }
    }

    /// Trilinear sample at pixel position `at` (level-0 texel units) and fractional `level`.
    fn sample(&self, at: DVec2, level: f64) -> DVec3 {
        let top = (self.levels.len() - 1) as f64;
        let level = level.clamp(0.0, top);
        let l0 = level.floor() as usize;
        let l1 = (l0 + 1).min(self.levels.len() - 1);
        let f = level - l0 as f64;
        self.bilinear(l0, at) * (1.0 - f) + self.bilinear(l1, at) * f
    }

    fn bilinear(&self, l: usize, at: DVec2) -> DVec3 {
        let (n, data) = &self.levels[l];
        let n0 = self.levels[0].0 as f64;
        let p = at * (*n as f64 / n0) - DVec2::splat(0.5);
        let x0 = p.x.floor();
        let y0 = p.y.floor();
        let (fx, fy) = (p.x - x0, p.y - y0);
        let get = |x: f64, y: f64| {
            let xi = (x.max(0.0) as usize).min(n - 1);
            let yi = (y.max(0.0) as usize).min(n - 1);
            data[yi * n + xi]
        };
        (get(x0, y0) * (1.0 - fx) + get(x0 + 1.0, y0) * fx) * (1.0 - fy)
            + (get(x0, y0 + 1.0) * (1.0 - fx) + get(x0 + 1.0, y0 + 1.0) * fx) * fy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poisson_points_are_spread_and_fixed() {
        let a = poisson(25);
        assert_eq!(a, poisson(25));
        assert!(a.iter().all(|p| p.x.abs() <= 0.5 && p.y.abs() <= 0.5));
        let mut min = f64::INFINITY;
        for i in 0..a.len() {
            for j in 0..i {
                min = min.min(a[i].distance(a[j]));
            }
        }
        // 25 points in a unit square: a jittered grid would give ~0.1; best candidate more.
        assert!(min > 0.08, "{min}");
    }

    #[test]
    fn mip_levels_average_and_sample() {
        let base: Vec<DVec3> = (0..16).map(|i| DVec3::splat(i as f64)).collect();
        let m = Mip::build(base, 4);
        assert_eq!(m.levels.len(), 3);
        assert!((m.levels[2].1[0].x - 7.5).abs() < 1e-12);
        // Level 0 at a texel centre is that texel.
        assert!((m.sample(DVec2::new(1.5, 2.5), 0.0).x - 9.0).abs() < 1e-12);
    }
}
