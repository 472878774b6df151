//! What a point of a triangle looks like, as viewers draw it: its colour (the vertices' base
//! colour interpolated, times the material's base-colour texture sampled at the point's
//! texture coordinate, [`super::texture`]) and its shading normal (the vertices' normals
//! interpolated). Every sample the package makes — depth images on both backends, peeled and
//! non-redundant layers, EPR points and the reflections shaded from them, impostor texels, the
//! field's views, ray hits — takes its colour and normal from here, at barycentric
//! coordinates `(b1, b2)` of a triangle (the point `(1 − b1 − b2)·v0 + b1·v1 + b2·v2`).
//!
//! Shading normals per vertex ([`ShadingNormals`]) are the scene's own (a file's `NORMAL`,
//! posed with the geometry), normalized; where a vertex has none (a zero row, or a scene
//! without normals), the area-weighted mean of the normals of the faces that use it. Where the
//! interpolated normal vanishes, the face's geometric normal stands in.

use std::sync::Arc;

use glam::{DVec2, DVec3, Vec3};

use super::texture::{Sampler, TextureRef};
use super::Scene;

/// The scene's unit shading normal per vertex (zero only for a vertex that no face with area
/// uses): its own where it has one, else area-weighted. Built once per scene, on first use.
pub struct ShadingNormals(pub Vec<[f32; 3]>);

impl ShadingNormals {
    fn of(scene: &Scene) -> Self {
        let given = scene.normals();
        let unit = |n: [f32; 3]| Vec3::from(n).normalize_or_zero();
        let mut out: Vec<Vec3> = match given {
            Some(ns) => ns.iter().map(|&n| unit(n)).collect(),
            None => vec![Vec3::ZERO; scene.vertices().len()],
        };
        let missing: Vec<bool> = out.iter().map(|n| *n == Vec3::ZERO).collect();
        if missing.contains(&true) {
            // Area-weighted: the sum of the faces' unnormalized normals (twice their area).
            let mut acc = vec![DVec3::ZERO; out.len()];
            for (t, f) in scene.faces().iter().enumerate() {
                if f.iter().all(|&k| !missing[k as usize]) {
                    continue;
                }
                let [a, b, c] = scene.triangle(t);
                let n = (b - a).cross(c - a);
                for &k in f {
                    acc[k as usize] += n;
                }
            }
            for (k, n) in out.iter_mut().enumerate() {
                if missing[k] {
                    *n = acc[k].normalize_or_zero().as_vec3();
                }
            }
        }
        ShadingNormals(out.into_iter().map(|n| n.to_array()).collect())
    }
}

/// How much of the surface a sample stands for, which picks the texture's mip level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Footprint {
    /// None given: the finest level, filtered as magnified.
    Point,
    /// The change of the barycentrics `(b1, b2)` from this pixel to the next one along x and
    /// along y (ray differentials: the neighbouring pixels' rays met on the triangle's plane).
    Barycentric { dx: [f64; 2], dy: [f64; 2] },
    /// A square of this side in world units on the surface (a point of a given size, an
    /// impostor texel): the triangle's texels-per-unit-length ratio scales it.
    World(f64),
}

/// A triangle's corner attributes: the vertices' base colours and unit shading normals, in
/// corner order, and how its material's texture maps onto it. What a sample of the triangle
/// interpolates; the image resolve keeps one per triangle with its plane, so that a pixel reads
/// one record.
#[derive(Debug, Clone, Copy)]
pub struct Corners {
    colors: [Vec3; 3],
    normals: [Vec3; 3],
    /// The triangle's unit geometric normal (zero when degenerate), where the normals cancel.
    face: Vec3,
    /// Its material's base-colour texture on it, if it has one.
    map: Option<TexMap>,
}

/// A base-colour texture on one triangle: the texture coordinate (through the material's
/// `KHR_texture_transform`, an affine map, so applied to the corners once) at corner 0 and
/// its changes along `b1` and `b2`, the same changes in level-0 texels, and the texels per
/// unit of length on the surface. What a lookup needs, without the material.
#[derive(Debug, Clone, Copy)]
struct TexMap {
    texture: usize,
    sampler: Sampler,
    at: DVec2,
    along: [DVec2; 2],
    texels: [DVec2; 2],
    /// √(texel area / surface area): a square of side s on the surface covers s·per_unit
    /// texels on a side (zero for a triangle without area).
    per_unit: f64,
}

impl TexMap {
    fn new(surfaces: &Surfaces, t: usize, r: &TextureRef) -> Option<TexMap> {
        let scene = surfaces.scene;
        let tex = scene.textures().get(r.texture)?;
        let uv = scene.texcoords();
        let [u0, u1, u2] = scene.faces()[t]
            .map(|k| uv.map_or(DVec2::ZERO, |uv| DVec2::from(uv[k as usize].map(f64::from))));
        let linear = |d: DVec2| DVec2::from(r.apply_linear(d.to_array()));
        let along = [linear(u1 - u0), linear(u2 - u0)];
        let size = DVec2::new(tex.width() as f64, tex.height() as f64);
        let texels = along.map(|a| a * size);
        let [p0, p1, p2] = scene.triangle(t);
        let area = (p1 - p0).cross(p2 - p0).length();
        let per_unit = if area > 0.0 {
            (texels[0].perp_dot(texels[1]).abs() / area).sqrt()
        } else {
            0.0
        };
        Some(TexMap {
            texture: r.texture,
            sampler: r.sampler,
            at: DVec2::from(r.apply(u0.to_array())),
            along,
            texels,
            per_unit: if per_unit.is_finite() { per_unit } else { 0.0 },
        })
    }
}

impl Corners {
    /// Triangle `t` of `surfaces`' scene.
    pub fn of(surfaces: &Surfaces, t: usize) -> Corners {
        let scene = surfaces.scene;
        let f = scene.faces()[t];
        let (colors, ns) = (scene.colors(), &surfaces.normals.0);
        Corners {
            colors: f.map(|k| Vec3::from(colors[k as usize])),
            normals: f.map(|k| Vec3::from(ns[k as usize])),
            face: scene.face_normal(t).as_vec3(),
            map: surfaces
                .texture_of(t)
                .and_then(|r| TexMap::new(surfaces, t, r)),
        }
    }

    /// Whether the triangle's material has a base-colour texture (its colour then depends on
    /// the sample's footprint).
    #[inline]
    pub fn textured(&self) -> bool {
        self.map.is_some()
    }

    /// The vertices' colour interpolated at `(b1, b2)`.
    #[inline]
    pub fn tint(&self, b: [f64; 2]) -> Vec3 {
        let (b1, b2) = (b[0] as f32, b[1] as f32);
        let [c0, c1, c2] = self.colors;
        c0 * (1.0 - b1 - b2) + c1 * b1 + c2 * b2
    }

    /// The unit shading normal at `(b1, b2)`: the vertices' normals interpolated and
    /// normalized (not turned toward any side); the geometric normal where they cancel.
    #[inline]
    pub fn shading_normal(&self, b: [f64; 2]) -> [f32; 3] {
        let (b1, b2) = (b[0] as f32, b[1] as f32);
        let [n0, n1, n2] = self.normals;
        let n = (n0 * (1.0 - b1 - b2) + n1 * b1 + n2 * b2).normalize_or_zero();
        if n == Vec3::ZERO { self.face } else { n }.to_array()
    }
}

/// The attributes of a scene's surface, ready to be sampled: the scene and its shading normals.
pub struct Surfaces<'a> {
    scene: &'a Scene,
    normals: Arc<ShadingNormals>,
}

impl Scene {
    /// Per-vertex unit shading normals ([`ShadingNormals`]), built on first use.
    pub fn shading_normals(&self) -> Arc<ShadingNormals> {
        self.derived(|| ShadingNormals::of(self))
    }

    /// The scene's surface attributes, to sample colours and normals at points of triangles.
    pub fn surfaces(&self) -> Surfaces<'_> {
        Surfaces {
            scene: self,
            normals: self.shading_normals(),
        }
    }
}

impl<'a> Surfaces<'a> {
    /// The scene whose surface this is.
    pub fn scene(&self) -> &'a Scene {
        self.scene
    }

    /// The base-colour texture of triangle `t`'s material, if it has one.
    #[inline]
    pub fn texture_of(&self, t: usize) -> Option<&TextureRef> {
        let m = usize::try_from(self.scene.material_ids()[t]).ok()?;
        self.scene.materials().get(m)?.base_color_texture.as_ref()
    }

    /// The barycentrics `(b1, b2)` of `p` on triangle `t` (projected onto its plane), clamped
    /// into the triangle, so that points just outside it (splat centres, rounded hits)
    /// interpolate its edge values; a degenerate triangle's centroid.
    pub fn barycentrics(&self, t: usize, p: DVec3) -> [f64; 2] {
        let v = self.scene.triangle(t);
        let (e0, e1, d) = (v[1] - v[0], v[2] - v[0], p - v[0]);
        let (a, b, c) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
        let (pd0, pd1) = (d.dot(e0), d.dot(e1));
        let den = a * c - b * b;
        if den.abs() <= f64::MIN_POSITIVE {
            return [1.0 / 3.0; 2];
        }
        inside([(c * pd0 - b * pd1) / den, (a * pd1 - b * pd0) / den])
    }

    /// Triangle `t`'s texture coordinate at `(b1, b2)`, as stored (before the material's
    /// texture transform); `None` for a scene without texture coordinates.
    pub fn texcoord(&self, t: usize, b: [f64; 2]) -> Option<[f64; 2]> {
        let uv = self.scene.texcoords()?;
        let f = self.scene.faces()[t];
        let c = f.map(|k| DVec2::from(uv[k as usize].map(f64::from)));
        Some((c[0] * (1.0 - b[0] - b[1]) + c[1] * b[0] + c[2] * b[1]).to_array())
    }

    /// Linear RGB base colour of triangle `t` at `(b1, b2)`: the vertices' colours interpolated,
    /// times the material's texture there (filtered for `footprint`) when it has one.
    pub fn color(&self, t: usize, b: [f64; 2], footprint: Footprint) -> [f32; 3] {
        self.color_of(&Corners::of(self, t), b, footprint)
    }

    /// [`Surfaces::color`] from a triangle's `corners`.
    #[inline]
    pub fn color_of(&self, corners: &Corners, b: [f64; 2], footprint: Footprint) -> [f32; 3] {
        let tint = corners.tint(b);
        match &corners.map {
            Some(m) => (tint * Vec3::from(self.texel(m, b, footprint))).to_array(),
            None => tint.to_array(),
        }
    }

    /// The texture `m` maps onto a triangle, sampled at `(b1, b2)` for `footprint`: linear RGB.
    #[inline]
    fn texel(&self, m: &TexMap, b: [f64; 2], footprint: Footprint) -> [f32; 3] {
        let at = m.at + m.along[0] * b[0] + m.along[1] * b[1];
        // The footprint's longer side, in level-0 texels.
        let rho = match footprint {
            Footprint::Point => 0.0,
            Footprint::Barycentric { dx, dy } => {
                // Squared sides, one square root (glam's length is a libm `hypot` call).
                let side = |d: [f64; 2]| (m.texels[0] * d[0] + m.texels[1] * d[1]).length_squared();
                side(dx).max(side(dy)).sqrt()
            }
            Footprint::World(s) => s * m.per_unit,
        };
        self.scene.textures()[m.texture].sample(at.to_array(), rho, &m.sampler)
    }

    /// Unit shading normal of triangle `t` at `(b1, b2)` ([`Corners::shading_normal`]).
    pub fn shading_normal(&self, t: usize, b: [f64; 2]) -> [f32; 3] {
        Corners::of(self, t).shading_normal(b)
    }
}

/// Barycentrics `(b1, b2)` clamped into the triangle (b1 first); the centroid for ones that
/// are not numbers.
fn inside([b1, b2]: [f64; 2]) -> [f64; 2] {
    if !(b1.is_finite() && b2.is_finite()) {
        return [1.0 / 3.0; 2];
    }
    let b1 = b1.clamp(0.0, 1.0);
    [b1, b2.clamp(0.0, 1.0 - b1)]
}

/// Where on each triangle a batch of samples lies: barycentrics `(b1, b2)` (a ray hit's
/// `(u, v)`), or world points (projected onto the triangle's plane).
pub enum Where<'a> {
    Barycentric(&'a [[f32; 2]]),
    Points(&'a [[f32; 3]]),
}

/// The attributes of a batch of samples of the surface, in order ([`attributes`]).
#[derive(Debug, Default)]
pub struct Attributes {
    /// Texture coordinates as the file has them (before a material's transform); NaN for a
    /// sample that sees nothing or a scene without texture coordinates.
    pub texcoord: Vec<[f32; 2]>,
    pub color: Vec<[f32; 3]>,
    pub shading_normal: Vec<[f32; 3]>,
    /// The triangle's unit geometric normal (from its winding).
    pub normal: Vec<[f32; 3]>,
}

/// One sample's texture coordinate, colour, shading normal and geometric normal.
type Row = ([f32; 2], [f32; 3], [f32; 3], [f32; 3]);

/// The attributes of samples `triangle[i]` at `at[i]` (−1: nothing there, zero attributes),
/// each texture filtered over a square of side `footprint[i]` world units (none: the finest
/// level). Every id must name a triangle of `scene` or be −1.
pub fn attributes(
    scene: &Scene,
    triangle: &[i32],
    at: Where,
    footprint: Option<&[f32]>,
) -> crate::error::Result<Attributes> {
    let n = triangle.len();
    let len = match &at {
        Where::Barycentric(b) => b.len(),
        Where::Points(p) => p.len(),
    };
    if len != n || footprint.is_some_and(|f| f.len() != n) {
        return crate::input_err!(
            "{n} triangle ids need as many positions and footprints, got {len} and {:?}",
            footprint.map(<[f32]>::len)
        );
    }
    let count = scene.triangle_count();
    if let Some(i) = triangle
        .iter()
        .position(|&t| t < -1 || t as i64 >= count as i64)
    {
        return crate::input_err!(
            "triangle[{i}] is {}: ids are -1 (nothing) or below the scene's {count} triangles",
            triangle[i]
        );
    }
    use rayon::prelude::*;
    let surfaces = scene.surfaces();
    let rows: Vec<Row> = (0..n)
        .into_par_iter()
        .with_min_len(1024)
        .map(|i| {
            let Ok(t) = usize::try_from(triangle[i]) else {
                return ([f32::NAN; 2], [0.0; 3], [0.0; 3], [0.0; 3]);
            };
            let b = match &at {
                Where::Barycentric(b) => inside(b[i].map(f64::from)),
                Where::Points(p) => surfaces.barycentrics(t, DVec3::from(p[i].map(f64::from))),
            };
            let footprint = match footprint.map(|f| f64::from(f[i])) {
                Some(s) if s > 0.0 && s.is_finite() => Footprint::World(s),
                _ => Footprint::Point,
            };
            let uv = surfaces
                .texcoord(t, b)
                .map_or([f32::NAN; 2], |uv| uv.map(|x| x as f32));
            (
                uv,
                surfaces.color(t, b, footprint),
                surfaces.shading_normal(t, b),
                scene.face_normal(t).as_vec3().to_array(),
            )
        })
        .collect();
    let mut out = Attributes::default();
    for (uv, c, s, g) in rows {
        out.texcoord.push(uv);
        out.color.push(c);
        out.shading_normal.push(s);
        out.normal.push(g);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::texture::{Rgba8, Sampler, Texture, IDENTITY_TRANSFORM};
    use crate::scene::{Material, SceneParts};

    /// A unit quad in z = 0 (two triangles), textured by a 2×2 image: red, green / blue, white.
    fn quad(normals: Option<Vec<[f32; 3]>>) -> Scene {
        let tex = Texture::new(Rgba8 {
            width: 2,
            height: 2,
            texels: vec![
                [255, 0, 0, 255],
                [0, 255, 0, 255],
                [0, 0, 255, 255],
                [255, 255, 255, 255],
            ],
        })
        .unwrap();
        let material = Material {
            base_color_texture: Some(TextureRef {
                texture: 0,
                sampler: Sampler::default().with_filters(Some(9728), None),
                transform: IDENTITY_TRANSFORM,
            }),
            ..Default::default()
        };
        Scene::new(SceneParts {
            vertices: vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]],
            faces: vec![[0, 1, 2], [0, 2, 3]],
            normals,
            colors: Some(vec![[1.0, 0.5, 1.0]; 4]),
            texcoords: Some(vec![[0., 0.], [1., 0.], [1., 1.], [0., 1.]]),
            textures: vec![Arc::new(tex)],
            material_ids: vec![0, 0],
            object_ids: vec![0, 0],
            materials: vec![material],
            objects: vec!["quad".into()],
            ..Default::default()
        })
        .unwrap()
    }

    #[test]
    fn colour_is_the_tint_times_the_texel_under_the_point() {
        let s = quad(None);
        let surf = s.surfaces();
        // Triangle 0 at (b1, b2) = (0.6, 0.1): uv (0.7, 0.1), the green texel (top right).
        let c = surf.color(0, [0.6, 0.1], Footprint::Point);
        assert_eq!(c, [0.0, 0.5, 0.0]);
        // Triangle 1 near vertex 3, uv (0.1, 0.9): blue (bottom left).
        let c = surf.color(1, [0.1, 0.8], Footprint::Point);
        assert_eq!(c, [0.0, 0.0, 1.0]);
        // A footprint of the whole quad reads the coarsest level, the mean.
        let c = surf.color(1, [0.1, 0.8], Footprint::World(1.0));
        assert!(
            (c[0] - 0.5).abs() < 0.01 && (c[1] - 0.25).abs() < 0.01,
            "{c:?}"
        );
    }

    #[test]
    fn barycentrics_sum_to_at_most_one_and_clamp() {
        let s = quad(None);
        let surf = s.surfaces();
        // Triangle 0 is (0,0,0), (1,0,0), (1,1,0): (0.75, 0.25) is b1 = 0.5, b2 = 0.25.
        let b = surf.barycentrics(0, DVec3::new(0.75, 0.25, 3.0));
        assert!(
            (b[0] - 0.5).abs() < 1e-12 && (b[1] - 0.25).abs() < 1e-12,
            "{b:?}"
        );
        let b = surf.barycentrics(0, DVec3::new(5.0, 9.0, 0.0));
        assert!(b.iter().all(|x| (0.0..=1.0).contains(x)) && b[0] + b[1] <= 1.0);
    }

    #[test]
    fn shading_normals_interpolate_or_fall_back_to_area_weighted() {
        let tilted = vec![[0., 0., 1.], [1., 0., 1.], [1., 0., 1.], [0., 0., 1.]];
        let s = quad(Some(tilted));
        let n = s.surfaces().shading_normal(0, [0.5, 0.0]);
        // The vertices' normals are made unit first, then blended.
        let expect = (Vec3::Z + Vec3::new(1.0, 0.0, 1.0).normalize()).normalize();
        assert!((Vec3::from(n) - expect).length() < 1e-6, "{n:?}");
        // Without normals, the flat quad's area-weighted normals are +z everywhere.
        assert_eq!(
            quad(None).surfaces().shading_normal(1, [0.3, 0.3]),
            [0., 0., 1.]
        );
        // A zero row is filled by the area-weighted normal.
        let partial = vec![[0., 0., 0.], [0., 0., 1.], [0., 0., 1.], [0., 0., 1.]];
        assert_eq!(quad(Some(partial)).shading_normals().0[0], [0., 0., 1.]);
    }
}
