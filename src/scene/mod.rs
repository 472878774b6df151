//! Scene: triangles with per-vertex base colour, per-triangle material and object ids, materials,
//! lights and cameras. Built from arrays (`from_arrays`), glTF 2.0 (`gltf::load`) or OBJ+MTL
//! (`obj::load`); validated
//! once at construction so every later stage can trust it.

pub mod adjacency;
pub mod animation;
pub mod deform;
pub mod gltf;
pub mod obj;
pub mod pose;
pub mod shapes;
pub mod skin;
pub mod surface;
pub mod texture;

use std::any::{Any, TypeId};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use glam::{DMat4, DVec3, DVec4, Vec3};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::error::Result;
use crate::{input_err, scene_err};

/// A glTF metallic-roughness material, reduced to what the methods use.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Linear RGBA: `base_color_factor` × the mean texel of the base-colour texture (sRGB decoded),
    /// or the factor alone when there is no texture or it could not be read: the material's one
    /// colour, for the methods that need one.
    pub base_color: [f32; 4],
    pub base_color_factor: [f32; 4],
    /// Whether `base_color` includes a texture average.
    pub base_color_textured: bool,
    /// The base-colour texture as samples read it (texture, sampler, transform), where it
    /// could be read; the scene's texture coordinates are the set it names.
    pub base_color_texture: Option<texture::TextureRef>,
    pub metallic: f32,
    pub roughness: f32,
    pub emissive: [f32; 3],
    pub double_sided: bool,
}

impl Default for Material {
    /// glTF's default material (spec §3.9.6): white, fully metallic and rough.
    fn default() -> Self {
        Self {
            name: String::new(),
            base_color: [1.0; 4],
            base_color_factor: [1.0; 4],
            base_color_textured: false,
            base_color_texture: None,
            metallic: 1.0,
            roughness: 1.0,
            emissive: [0.0; 3],
            double_sided: false,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightKind {
    Directional,
    Point,
    Spot,
}

/// A `KHR_lights_punctual` light placed in world space.
#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    pub name: String,
    pub kind: LightKind,
    pub color: [f32; 3],
    pub intensity: f32,
    pub range: Option<f32>,
    pub position: [f64; 3],
    /// Unit world direction the light points along (the node's −Z).
    pub direction: [f64; 3],
    pub inner_cone_angle: Option<f32>,
    pub outer_cone_angle: Option<f32>,
}

impl Light {
    /// Put the light where its node's world transform `world` puts it: at the node's origin,
    /// pointing along its −Z.
    pub fn place(&mut self, world: &DMat4) {
        let dir = (*world * DVec4::new(0.0, 0.0, -1.0, 0.0))
            .truncate()
            .normalize_or(DVec3::NEG_Z);
        self.position = world.w_axis.truncate().to_array();
        self.direction = dir.to_array();
    }
}

/// Everything that defines a scene's geometry and appearance, before validation.
#[derive(Clone, Debug, Default)]
pub struct SceneParts {
    pub vertices: Vec<[f32; 3]>,
    pub faces: Vec<[u32; 3]>,
    /// Per-vertex normals (a zero row: that vertex has none, and shading uses the
    /// area-weighted normal of its faces there, [`surface`]).
    pub normals: Option<Vec<[f32; 3]>>,
    /// Per-vertex linear RGB base colour (glTF: the base colour factor × COLOR_0; a textured
    /// material's texture multiplies it per sample, [`surface`]); white when `None`.
    pub colors: Option<Vec<[f32; 3]>>,
    /// Per-vertex texture coordinates: the set its material's base-colour texture names
    /// (0..1 spans the image, v down); `None` when no material has a texture.
    pub texcoords: Option<Vec<[f32; 2]>>,
    /// The decoded base-colour textures that materials refer to.
    pub textures: Vec<Arc<texture::Texture>>,
    /// Per-triangle material index into `materials`, −1 for glTF's default material.
    pub material_ids: Vec<i32>,
    /// Per-triangle object index into `objects`.
    pub object_ids: Vec<i32>,
    pub materials: Vec<Material>,
    pub objects: Vec<String>,
    pub lights: Vec<Light>,
    pub cameras: Vec<Camera>,
    pub warnings: Vec<String>,
    /// glTF node animations, with where each object hangs in the node hierarchy.
    pub animations: Option<Arc<animation::Animations>>,
}

/// A validated triangle scene. Immutable: the BVH and GPU buffers are cached on first use.
#[derive(Debug)]
pub struct Scene {
    /// Vertices, normals, materials, objects, lights, cameras and warnings (the faces, their
    /// ids and the colours live in `shared`).
    parts: SceneParts,
    /// What a scene shares with the scenes posed from it ([`pose`]).
    shared: Arc<Shared>,
    /// The vertices, their normals and what is derived from them: made with the scene, or for
    /// a rigid pose on first use, from `make` ([`Scene::posed`]: a pose is O(objects)).
    world: OnceLock<World>,
    make: Option<MakeWorld>,
    /// The scene this one was posed from and each object's transform ([`Scene::posed`]).
    pose: Option<pose::Pose>,
    /// The scene whose object trees this one's BVH is refit from ([`Scene::deformed`]).
    refit_from: Option<Arc<Scene>>,
    /// What the rooms derive from the scene (see [`Scene::derived`]).
    derived: Derived,
}

/// The faces, their material and object ids, the vertices' colours and texture coordinates,
/// and the textures: what poses leave as they are (but an animation that mirrors an object
/// rewinds its faces, `Scene::at`).
#[derive(Debug, Clone)]
pub(crate) struct Shared {
    faces: Vec<[u32; 3]>,
    material_ids: Vec<i32>,
    object_ids: Vec<i32>,
    colors: Vec<[f32; 3]>,
    texcoords: Option<Vec<[f32; 2]>>,
    textures: Vec<Arc<texture::Texture>>,
    /// How many distinct vertices the faces use, counted on first need (`bounds`).
    used: OnceLock<usize>,
}

/// A scene's vertices, their normals, the bounds of the vertices that triangles use and which
/// triangles are degenerate (found on first use: a deformation or a pose pays only for what it
/// is asked).
#[derive(Debug)]
struct World {
    vertices: Vec<[f32; 3]>,
    normals: Option<Vec<[f32; 3]>>,
    bounds: [[f32; 3]; 2],
    degenerate: OnceLock<(Vec<bool>, usize)>,
}

impl World {
    fn of(vertices: Vec<[f32; 3]>, normals: Option<Vec<[f32; 3]>>, shared: &Shared) -> Self {
        Self {
            bounds: bounds(&vertices, shared),
            vertices,
            normals,
            degenerate: OnceLock::new(),
        }
    }

    /// Per triangle whether it is degenerate, and how many are.
    fn degenerate(&self, faces: &[[u32; 3]]) -> &(Vec<bool>, usize) {
        self.degenerate.get_or_init(|| {
            let flags: Vec<bool> = faces
                .par_iter()
                .with_min_len(1 << 14)
                .map(|f| is_degenerate(&self.vertices, f))
                .collect();
            let count = flags.iter().filter(|d| **d).count();
            (flags, count)
        })
    }
}

/// How a scene makes its vertices and normals on first use.
pub(crate) struct MakeWorld(pub Box<dyn Fn() -> VerticesAndNormals + Send + Sync>);

/// A scene's vertices, and its normals when it has them.
pub(crate) type VerticesAndNormals = (Vec<[f32; 3]>, Option<Vec<[f32; 3]>>);

impl std::fmt::Debug for MakeWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "MakeWorld")
    }
}

/// One cached value per type, each built once.
type Slot = Arc<OnceLock<Arc<dyn Any + Send + Sync>>>;

/// The values derived from a scene by the code that uses it (its BVH, its GPU buffers, its
/// per-triangle planes, ...), keyed by their type, so that the scene names none of its users.
#[derive(Default)]
struct Derived(Mutex<HashMap<TypeId, Slot>>);

impl std::fmt::Debug for Derived {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.0.lock().map(|m| m.len()).unwrap_or(0);
        write!(f, "Derived({n} values)")
    }
}

impl Derived {
    fn slot<T: Any>(&self) -> Slot {
        // A panic elsewhere while the map was locked leaves it intact: keep using it.
        let mut map = self.0.lock().unwrap_or_else(|e| e.into_inner());
        map.entry(TypeId::of::<T>()).or_default().clone()
    }
}

impl Scene {
    /// Validate `parts` and build the scene. Faces keep their order, so triangle ids are the
    /// input's face indices.
    pub fn new(mut parts: SceneParts) -> Result<Self> {
        validate(&parts)?;
        let n = parts.vertices.len();
        // The one copy of the colours lives here; `parts.colors` is only the input.
        let colors = parts.colors.take().unwrap_or_else(|| vec![[1.0; 3]; n]);
        let shared = Arc::new(Shared {
            faces: std::mem::take(&mut parts.faces),
            material_ids: std::mem::take(&mut parts.material_ids),
            object_ids: std::mem::take(&mut parts.object_ids),
            colors,
            texcoords: parts.texcoords.take(),
            textures: std::mem::take(&mut parts.textures),
            used: OnceLock::new(),
        });
        Ok(Self::assemble(parts, shared, None))
    }

    /// The scene of checked `parts` (whose faces, ids and colours are `shared`'s).
    fn assemble(mut parts: SceneParts, shared: Arc<Shared>, pose: Option<pose::Pose>) -> Self {
        let vertices = std::mem::take(&mut parts.vertices);
        let normals = parts.normals.take();
        let world = OnceLock::from(World::of(vertices, normals, &shared));
        Self {
            parts,
            shared,
            world,
            make: None,
            pose,
            refit_from: None,
            derived: Derived::default(),
        }
    }

    /// The scene of checked `parts` (whose faces, ids and colours are `shared`'s) whose
    /// vertices and normals `make` makes on first use, checked finite beforehand.
    fn assemble_lazy(
        parts: SceneParts,
        shared: Arc<Shared>,
        pose: Option<pose::Pose>,
        make: MakeWorld,
    ) -> Self {
        Self {
            parts,
            shared,
            world: OnceLock::new(),
            make: Some(make),
            pose,
            refit_from: None,
            derived: Derived::default(),
        }
    }

    /// Whether the vertices are made (always but for a rigid pose not yet asked for them).
    pub fn has_vertices(&self) -> bool {
        self.world.get().is_some()
    }

    fn world(&self) -> &World {
        self.world.get_or_init(|| {
            let make = self
                .make
                .as_ref()
                .expect("a scene without vertices makes them");
            let (vertices, normals) = (make.0)();
            World::of(vertices, normals, &self.shared)
        })
    }

    /// The scene's `T`, built by `make` on first use and kept for the scene's lifetime (the
    /// scene is immutable). Concurrent first uses build it once; the others wait for it. A
    /// module caches what it derives from a scene under a type of its own.
    pub fn derived<T: Any + Send + Sync>(&self, make: impl FnOnce() -> T) -> Arc<T> {
        let slot = self.derived.slot::<T>();
        let value = slot
            .get_or_init(|| Arc::new(make()) as Arc<dyn Any + Send + Sync>)
            .clone();
        value
            .downcast::<T>()
            .unwrap_or_else(|_| unreachable!("slots are keyed by their value's type"))
    }

    /// The scene's `T` if [`Scene::derived`] has built it.
    pub fn derived_if_built<T: Any + Send + Sync>(&self) -> Option<Arc<T>> {
        let value = self.derived.slot::<T>().get()?.clone();
        value.downcast::<T>().ok()
    }

    /// The same scene with its faces (and their material and object ids) in `order`: face i of
    /// the result is face `order[i]` of this one. `order` must be a permutation.
    pub fn permuted(&self, order: &[u32]) -> Result<Self> {
        let n = self.triangle_count();
        let mut seen = vec![false; n];
        if order.len() != n
            || order
                .iter()
                .any(|&i| (i as usize) >= n || std::mem::replace(&mut seen[i as usize], true))
        {
            return input_err!("a face order must be a permutation of the {n} faces");
        }
        let pick = |v: &[i32]| order.iter().map(|&i| v[i as usize]).collect::<Vec<_>>();
        let mut parts = self.parts.clone();
        parts.vertices = self.vertices().to_vec();
        parts.normals = self.normals().map(<[_]>::to_vec);
        parts.faces = order.iter().map(|&i| self.faces()[i as usize]).collect();
        parts.material_ids = pick(self.material_ids());
        parts.object_ids = pick(self.object_ids());
        parts.colors = Some(self.colors().to_vec());
        parts.texcoords = self.texcoords().map(<[_]>::to_vec);
        parts.textures = self.textures().to_vec();
        parts.warnings.clear();
        Self::new(parts)
    }

    /// A scene from plain arrays: no materials (id −1), one object, white unless `colors`.
    pub fn from_arrays(
        vertices: Vec<[f32; 3]>,
        faces: Vec<[u32; 3]>,
        normals: Option<Vec<[f32; 3]>>,
        colors: Option<Vec<[f32; 3]>>,
    ) -> Result<Self> {
        let m = faces.len();
        Self::new(SceneParts {
            vertices,
            faces,
            normals,
            colors,
            material_ids: vec![-1; m],
            object_ids: vec![0; m],
            objects: vec!["mesh".to_string()],
            ..Default::default()
        })
    }

    /// The vertices (a rigid pose makes them on first use: [`Scene::posed`]).
    pub fn vertices(&self) -> &[[f32; 3]] {
        &self.world().vertices
    }
    pub fn faces(&self) -> &[[u32; 3]] {
        &self.shared.faces
    }

    /// What the scene shares with the scenes posed or deformed from it (faces, ids, colours).
    pub(crate) fn shared(&self) -> &Arc<Shared> {
        &self.shared
    }

    /// Whether the scene's faces are `shared`'s (the same storage, not equal copies).
    pub(crate) fn shares_faces(&self, shared: &Arc<Shared>) -> bool {
        Arc::ptr_eq(&self.shared, shared)
    }
    pub fn normals(&self) -> Option<&[[f32; 3]]> {
        self.world().normals.as_deref()
    }
    pub fn colors(&self) -> &[[f32; 3]] {
        &self.shared.colors
    }
    pub fn texcoords(&self) -> Option<&[[f32; 2]]> {
        self.shared.texcoords.as_deref()
    }
    pub fn textures(&self) -> &[Arc<texture::Texture>] {
        &self.shared.textures
    }
    pub fn material_ids(&self) -> &[i32] {
        &self.shared.material_ids
    }
    pub fn object_ids(&self) -> &[i32] {
        &self.shared.object_ids
    }
    pub fn materials(&self) -> &[Material] {
        &self.parts.materials
    }
    pub fn objects(&self) -> &[String] {
        &self.parts.objects
    }
    pub fn lights(&self) -> &[Light] {
        &self.parts.lights
    }
    pub fn cameras(&self) -> &[Camera] {
        &self.parts.cameras
    }
    pub fn warnings(&self) -> &[String] {
        &self.parts.warnings
    }
    pub fn triangle_count(&self) -> usize {
        self.shared.faces.len()
    }
    /// Axis-aligned bounds of the vertices that triangles use: `[min, max]`.
    pub fn bounds(&self) -> [[f32; 3]; 2] {
        self.world().bounds
    }
    pub fn degenerate_count(&self) -> usize {
        self.world().degenerate(&self.shared.faces).1
    }
    /// Whether triangle `i`'s back face may be seen: its material's `double_sided` (glTF's
    /// `doubleSided`). A triangle without a material (id −1, as in scenes built from bare
    /// arrays) says nothing about its sides and counts as double-sided, the way every image of
    /// the package draws both sides unless asked to cull.
    pub fn is_double_sided(&self, i: usize) -> bool {
        usize::try_from(self.shared.material_ids[i])
            .ok()
            .and_then(|m| self.parts.materials.get(m))
            .is_none_or(|m| m.double_sided)
    }
    /// Whether triangle `i` has (numerically) zero area.
    pub fn is_degenerate(&self, i: usize) -> bool {
        self.world().degenerate(&self.shared.faces).0[i]
    }

    /// [`Scene::bounds`] in f64: `[min, max]`.
    pub fn bounds_f64(&self) -> [DVec3; 2] {
        self.bounds().map(|b| Vec3::from(b).as_dvec3())
    }

    /// Centre of the bounds in f64: the origin of the camera-relative frame used on the GPU.
    pub fn center(&self) -> DVec3 {
        let [lo, hi] = self.bounds_f64();
        (lo + hi) * 0.5
    }

    /// Length of the bounds' diagonal (at least the smallest positive normal f32, never 0).
    pub fn diagonal(&self) -> f64 {
        let [lo, hi] = self.bounds_f64();
        (hi - lo).length().max(f32::MIN_POSITIVE as f64)
    }

    /// Unit geometric normal of triangle `i` from its winding (counter-clockwise front), in f64;
    /// zero for a degenerate triangle, so nothing downstream divides by its area.
    pub fn face_normal(&self, i: usize) -> DVec3 {
        let [a, b, c] = self.triangle(i);
        let n = (b - a).cross(c - a);
        let len = n.length();
        if self.is_degenerate(i) || len == 0.0 || !len.is_finite() {
            DVec3::ZERO
        } else {
            n / len
        }
    }

    /// The three world-space corners of triangle `i`, widened to f64.
    pub fn triangle(&self, i: usize) -> [DVec3; 3] {
        let f = self.shared.faces[i];
        let v = self.vertices();
        [0, 1, 2].map(|k| Vec3::from(v[f[k] as usize]).as_dvec3())
    }
}

fn validate(p: &SceneParts) -> Result<()> {
    let n = p.vertices.len();
    let m = p.faces.len();
    if m == 0 {
        return scene_err!("the scene has no triangles ({n} vertices, 0 faces)");
    }
    for (i, v) in p.vertices.iter().enumerate() {
        if let Some(k) = v.iter().position(|x| !x.is_finite()) {
            return scene_err!(
                "vertex {i} has a non-finite coordinate ({}={}); vertices must be finite",
                ["x", "y", "z"][k],
                v[k]
            );
        }
    }
    for (i, f) in p.faces.iter().enumerate() {
        if let Some(k) = f.iter().position(|&x| x as usize >= n) {
            return scene_err!(
                "face {i} refers to vertex {} but the scene has {n} vertices (valid: 0..{})",
                f[k],
                n.saturating_sub(1)
            );
        }
    }
    check_len("normals", p.normals.as_ref().map(Vec::len), n, "vertices")?;
    check_len("colors", p.colors.as_ref().map(Vec::len), n, "vertices")?;
    check_len(
        "texcoords",
        p.texcoords.as_ref().map(Vec::len),
        n,
        "vertices",
    )?;
    check_len("material_ids", Some(p.material_ids.len()), m, "faces")?;
    check_len("object_ids", Some(p.object_ids.len()), m, "faces")?;
    if let Some(normals) = &p.normals {
        if let Some(i) = normals
            .iter()
            .position(|v| v.iter().any(|x| !x.is_finite()))
        {
            return scene_err!("normal {i} is not finite: {:?}", normals[i]);
        }
    }
    if let Some(colors) = &p.colors {
        if let Some(i) = colors.iter().position(|v| v.iter().any(|x| !x.is_finite())) {
            return scene_err!("color {i} is not finite: {:?}", colors[i]);
        }
    }
    if let Some(uv) = &p.texcoords {
        if let Some(i) = uv.iter().position(|v| v.iter().any(|x| !x.is_finite())) {
            return scene_err!("texture coordinate {i} is not finite: {:?}", uv[i]);
        }
    }
    for (k, m) in p.materials.iter().enumerate() {
        if let Some(r) = &m.base_color_texture {
            if r.texture >= p.textures.len() {
                return scene_err!(
                    "material {k} names texture {} but there are {} textures",
                    r.texture,
                    p.textures.len()
                );
            }
            if p.texcoords.is_none() {
                return scene_err!(
                    "material {k} has a base-colour texture but the scene has no texture \
                     coordinates"
                );
            }
            if r.transform.iter().any(|x| !x.is_finite()) {
                return scene_err!("material {k}'s texture transform is not finite");
            }
        }
    }
    let nm = p.materials.len() as i32;
    if let Some(i) = p.material_ids.iter().position(|&k| k < -1 || k >= nm) {
        return scene_err!(
            "face {i} has material id {} but there are {nm} materials",
            p.material_ids[i]
        );
    }
    let no = p.objects.len() as i32;
    if let Some(i) = p.object_ids.iter().position(|&k| k < 0 || k >= no) {
        return scene_err!(
            "face {i} has object id {} but there are {no} objects",
            p.object_ids[i]
        );
    }
    Ok(())
}

fn check_len(name: &str, got: Option<usize>, want: usize, of: &str) -> Result<()> {
    match got {
        Some(g) if g != want => scene_err!("{name} has {g} rows but there are {want} {of}"),
        _ => Ok(()),
    }
}

/// The bounds of the vertices that `shared`'s faces use: of all of them, read in order, where
/// the faces use every one (the usual case, and a deformation's every frame), else of the
/// faces' corners.
fn bounds(vertices: &[[f32; 3]], shared: &Shared) -> [[f32; 3]; 2] {
    let empty = || (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    let faces = &shared.faces;
    let used = *shared.used.get_or_init(|| {
        let n = faces.iter().flatten().max().map_or(0, |&k| k as usize + 1);
        let mut seen = vec![false; n];
        for &k in faces.iter().flatten() {
            seen[k as usize] = true;
        }
        seen.iter().filter(|&&s| s).count()
    });
    let grow = |(lo, hi): (Vec3, Vec3), v: &[f32; 3]| {
        let v = Vec3::from(*v);
        (lo.min(v), hi.max(v))
    };
    // Chunks in parallel, joined in their order: which of -0 and +0 a tie keeps must not
    // depend on how the work was split.
    let chunks: Vec<(Vec3, Vec3)> = if used == vertices.len() {
        vertices
            .par_chunks(1 << 15)
            .map(|c| c.iter().fold(empty(), grow))
            .collect()
    } else {
        faces
            .par_chunks(1 << 14)
            .map(|c| {
                c.iter()
                    .flatten()
                    .fold(empty(), |bx, &k| grow(bx, &vertices[k as usize]))
            })
            .collect()
    };
    let (lo, hi) = chunks
        .into_iter()
        .fold(empty(), |(a, b), (c, d)| (a.min(c), b.max(d)));
    [lo.to_array(), hi.to_array()]
}

/// Zero area up to f64 rounding of the cross product: |e1 × e2| ≤ 1e-12·|e1|·|e2|, or a
/// repeated index.
fn is_degenerate(vertices: &[[f32; 3]], f: &[u32; 3]) -> bool {
    if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
        return true;
    }
    let [a, b, c] = f.map(|k| Vec3::from(vertices[k as usize]).as_dvec3());
    let (e1, e2) = (b - a, c - a);
    let cross = e1.cross(e2).length();
    cross <= 1e-12 * e1.length() * e2.length()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let v = vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]];
        (v, vec![[0, 1, 2], [0, 2, 3]])
    }

    #[test]
    fn keeps_face_order_and_bounds() {
        let (v, f) = quad();
        let s = Scene::from_arrays(v, f.clone(), None, None).unwrap();
        assert_eq!(s.faces(), &f[..]);
        assert_eq!(s.bounds(), [[0., 0., 0.], [1., 1., 0.]]);
        assert_eq!(s.face_normal(0), DVec3::Z);
    }

    #[test]
    fn rejects_bad_input_with_named_element() {
        let (mut v, f) = quad();
        v[2][1] = f32::NAN;
        let e = Scene::from_arrays(v, f, None, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("vertex 2"), "{e}");
        let (v, mut f) = quad();
        f[1][2] = 9;
        let e = Scene::from_arrays(v, f, None, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("face 1") && e.contains("vertex 9"), "{e}");
        let e = Scene::from_arrays(vec![], vec![], None, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("no triangles"), "{e}");
    }

    #[test]
    fn degenerate_triangles_are_counted_with_zero_normals() {
        let v = vec![[0., 0., 0.], [1., 0., 0.], [2., 0., 0.], [0., 1., 0.]];
        let s = Scene::from_arrays(v, vec![[0, 1, 2], [0, 1, 3], [3, 3, 1]], None, None).unwrap();
        assert_eq!(s.degenerate_count(), 2);
        assert_eq!(s.face_normal(0), DVec3::ZERO);
        assert!(s.face_normal(1).is_finite());
    }
}
