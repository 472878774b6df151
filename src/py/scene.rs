//! `scenesample._core.Scene`: a validated scene shared by reference (cloning is free).

use std::path::PathBuf;
use std::sync::Arc;

use glam::DMat4;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use super::camera::PyCamera;
use super::convert::{array, faces, flat_i32, rows_array, rows_f32, rows_f64};
use super::errors::{input, IntoPy};
use crate::scene::animation::ClipKey;
use crate::scene::texture::{
    Mipmap, Rgba8, Sampler, Texture, TextureRef, Wrap, IDENTITY_TRANSFORM,
};
use crate::scene::{Light, LightKind, Material, Scene, SceneParts};

/// A clip as Python names it: an int is its index, a str its name (never parsed as a number).
#[derive(FromPyObject)]
pub enum Clip {
    Index(usize),
    Name(String),
}

impl Clip {
    fn key(&self) -> ClipKey<'_> {
        match self {
            Clip::Index(k) => ClipKey::Index(*k),
            Clip::Name(n) => ClipKey::Name(n),
        }
    }
}

#[pyclass(name = "Scene", module = "scenesample._core", frozen)]
pub struct PyScene {
    pub inner: Arc<Scene>,
}

#[pymethods]
impl PyScene {
    /// Load a glTF 2.0 file (.gltf or .glb).
    #[staticmethod]
    fn load_gltf(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let scene = super::run(py, || crate::scene::gltf::load(&path))?;
        Ok(Self {
            inner: Arc::new(scene),
        })
    }

    /// Load a Wavefront OBJ file and its MTL materials.
    #[staticmethod]
    fn load_obj(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let scene = super::run(py, || crate::scene::obj::load(&path))?;
        Ok(Self {
            inner: Arc::new(scene),
        })
    }

    #[staticmethod]
    #[pyo3(signature = (vertices, faces, normals=None, colors=None, material_ids=None, materials=None, object_ids=None, objects=None, lights=None, texcoords=None, textures=None, cameras=None, animations=None))]
    #[allow(clippy::too_many_arguments)]
    fn from_arrays(
        py: Python<'_>,
        vertices: &Bound<'_, PyAny>,
        faces: &Bound<'_, PyAny>,
        normals: Option<&Bound<'_, PyAny>>,
        colors: Option<&Bound<'_, PyAny>>,
        material_ids: Option<&Bound<'_, PyAny>>,
        materials: Option<Vec<Bound<'_, PyDict>>>,
        object_ids: Option<&Bound<'_, PyAny>>,
        objects: Option<Vec<String>>,
        lights: Option<Vec<Bound<'_, PyDict>>>,
        texcoords: Option<&Bound<'_, PyAny>>,
        textures: Option<Vec<Bound<'_, PyAny>>>,
        cameras: Option<Vec<PyCamera>>,
        animations: Option<String>,
    ) -> PyResult<Self> {
        let v = rows_f32::<3>(vertices, "vertices")?;
        let f = self::faces(faces, "faces", v.len())?;
        let n = normals.map(|n| rows_f32::<3>(n, "normals")).transpose()?;
        let c = colors.map(|c| rows_f32::<3>(c, "colors")).transpose()?;
        let uv = texcoords
            .map(|t| rows_f32::<2>(t, "texcoords"))
            .transpose()?;
        let m = f.len();
        let mut parts = SceneParts {
            vertices: v,
            faces: f,
            normals: n,
            colors: c,
            texcoords: uv,
            material_ids: vec![-1; m],
            object_ids: vec![0; m],
            objects: vec!["mesh".to_string()],
            ..Default::default()
        };
        if let Some(ids) = material_ids {
            parts.material_ids = flat_i32(ids, "material_ids")?;
        }
        if let Some(ts) = textures {
            parts.textures = ts
                .iter()
                .enumerate()
                .map(|(k, t)| texture(py, k, t))
                .collect::<PyResult<_>>()?;
        }
        if let Some(ms) = materials {
            parts.materials = ms
                .iter()
                .map(|d| material(py, d))
                .collect::<PyResult<_>>()?;
        }
        // A textured material's one colour: its factor times its texture's mean texel.
        for m in &mut parts.materials {
            if let Some(t) = m
                .base_color_texture
                .and_then(|r| parts.textures.get(r.texture))
            {
                let mean = t.mean();
                m.base_color = std::array::from_fn(|k| m.base_color_factor[k] * mean[k]);
            }
        }
        if let Some(ids) = object_ids {
            parts.object_ids = flat_i32(ids, "object_ids")?;
        }
        if let Some(names) = objects {
            parts.objects = names;
        }
        if let Some(ls) = lights {
            parts.lights = ls.iter().map(|d| light(py, d)).collect::<PyResult<_>>()?;
        }
        if let Some(cams) = cameras {
            parts.cameras = cams.into_iter().map(|c| c.inner).collect();
        }
        if let Some(text) = animations {
            let a = crate::scene::animation::Animations::from_json(
                &text,
                parts.objects.len(),
                parts.lights.len(),
                parts.cameras.len(),
                parts.vertices.len(),
            )
            .py_err(py)?;
            parts.animations = Some(Arc::new(a));
        }
        // Validated on the package's pool (its bounds pass is parallel), never on rayon's
        // global pool, whose threads a forked child would not have. Not through `run`, which
        // may run its work twice: `parts` is moved into the scene, not copied.
        let scene = py
            .detach(|| crate::process::install(None, move || Scene::new(parts)))
            .py_err(py)?
            .py_err(py)?;
        Ok(Self {
            inner: Arc::new(scene),
        })
    }

    /// This scene with its objects moved: `transforms` is (len(objects) * 4, 4) float64, the
    /// objects' 4×4 matrices stacked (row-major), each mapping its object as loaded. `rewinds`
    /// and `lights` remake a pose as it was (unpickling): mirrored objects wound the other way,
    /// as `at` does, and the lights as they were placed.
    #[pyo3(signature = (transforms, rewinds=false, lights=None, vertices=None, normals=None))]
    fn posed(
        &self,
        py: Python<'_>,
        transforms: &Bound<'_, PyAny>,
        rewinds: bool,
        lights: Option<Vec<Bound<'_, PyDict>>>,
        vertices: Option<&Bound<'_, PyAny>>,
        normals: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let rows = rows_f64::<4>(transforms, "transforms")?;
        if rows.len() % 4 != 0 {
            return Err(input(py, "transforms must stack 4x4 matrices".into()));
        }
        let ms: Vec<DMat4> = rows
            .chunks_exact(4)
            .map(|r| DMat4::from_cols_array_2d(&[r[0], r[1], r[2], r[3]]).transpose())
            .collect();
        let lights = match lights {
            Some(ls) => Some(
                ls.iter()
                    .map(|d| light(py, d))
                    .collect::<PyResult<Vec<_>>>()?,
            ),
            None => None,
        };
        let vertices = vertices.map(|v| rows_f32::<3>(v, "vertices")).transpose()?;
        let normals = normals.map(|v| rows_f32::<3>(v, "normals")).transpose()?;
        let scene = super::run(py, || {
            self.inner.posed_again(
                &ms,
                rewinds,
                lights.clone(),
                vertices.clone(),
                normals.clone(),
            )
        })?;
        Ok(Self {
            inner: Arc::new(scene),
        })
    }

    /// This scene with its vertices at `vertices` ((n_vertices, 3) float32, finite) and, if
    /// given, per-vertex `normals` ((n_vertices, 3)); its BVH is refit, not rebuilt.
    #[pyo3(signature = (vertices, normals=None))]
    fn deformed(
        &self,
        py: Python<'_>,
        vertices: &Bound<'_, PyAny>,
        normals: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let v = rows_f32::<3>(vertices, "vertices")?;
        let n = normals.map(|n| rows_f32::<3>(n, "normals")).transpose()?;
        // `run` takes an `Fn`: the arrays are handed over once, not copied.
        let given = std::sync::Mutex::new(Some((v, n)));
        let scene = super::run(py, || {
            let taken = given.lock().unwrap_or_else(|e| e.into_inner()).take();
            let (v, n) = taken.expect("run calls its work once");
            self.inner.deformed(v, n)
        })?;
        Ok(Self {
            inner: Arc::new(scene),
        })
    }

    /// The scene this one was posed from (as loaded), or None for a scene as loaded.
    #[getter]
    fn base(&self) -> Option<Self> {
        self.inner.pose().map(|p| Self {
            inner: p.base.clone(),
        })
    }

    /// Whether this pose winds mirrored objects' faces the other way (a pose made by `at`).
    #[getter]
    fn rewinds(&self) -> bool {
        self.inner.pose().is_some_and(|p| p.rewinds)
    }

    /// Whether some of this pose's vertices are not their object's transform of the base's
    /// (a clip's skins or morph targets moved them).
    #[getter]
    fn deforms(&self) -> bool {
        self.inner.pose().is_some_and(|p| p.deforms)
    }

    /// The animation clips as (name, duration in seconds).
    #[getter]
    fn animations(&self) -> Vec<(String, f64)> {
        self.inner.animations()
    }

    /// The animations as JSON text (what a pickle carries), or None without any.
    #[getter]
    fn animations_state(&self) -> Option<String> {
        self.inner.animations_data().map(|a| a.to_json())
    }

    /// (N, 2) float32 texture coordinates, or None.
    #[getter]
    fn texcoords<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.inner
            .texcoords()
            .map(|t| rows_array(py, t, &[t.len(), 2]))
            .transpose()
    }

    /// The base-colour textures: (H, W, 4) uint8 sRGB-encoded texels each, row 0 at the top.
    #[getter]
    fn textures<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyAny>>> {
        self.inner
            .textures()
            .iter()
            .map(|t| rows_array(py, &t.texels(), &[t.height(), t.width(), 4]))
            .collect()
    }

    /// Every key time of animation `clip` (an int index or a str name), ascending, each once.
    fn key_times<'py>(&self, py: Python<'py>, clip: Clip) -> PyResult<Bound<'py, PyAny>> {
        let times = super::run(py, || self.inner.key_times(clip.key()))?;
        Ok(numpy::PyArray1::from_vec(py, times).into_any())
    }

    /// The scene posed at `t` seconds into animation clips `clips` (int indices or str names),
    /// played together.
    fn at(&self, py: Python<'_>, t: f64, clips: Vec<Clip>) -> PyResult<Self> {
        let keys: Vec<ClipKey> = clips.iter().map(Clip::key).collect();
        let scene = super::run(py, || self.inner.at(t, &keys))?;
        Ok(Self {
            inner: Arc::new(scene),
        })
    }

    /// Each object's transform from the scene as loaded ((len(objects), 4, 4) float64,
    /// row-major), or None for a scene as loaded.
    #[getter]
    fn transforms<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        let Some(pose) = self.inner.pose() else {
            return Ok(None);
        };
        let rows: Vec<[f64; 4]> = pose
            .transforms
            .iter()
            .flat_map(|m| m.transpose().to_cols_array_2d())
            .collect();
        Ok(Some(rows_array(py, &rows, &[rows.len() / 4, 4, 4])?))
    }

    #[getter]
    fn vertices<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let v = self.inner.vertices();
        rows_array(py, v, &[v.len(), 3])
    }
    #[getter]
    fn faces<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let f = self.inner.faces();
        rows_array(py, f, &[f.len(), 3])
    }
    #[getter]
    fn normals<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.inner
            .normals()
            .map(|n| rows_array(py, n, &[n.len(), 3]))
            .transpose()
    }
    #[getter]
    fn colors<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let c = self.inner.colors();
        rows_array(py, c, &[c.len(), 3])
    }
    #[getter]
    fn material_ids<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let m = self.inner.material_ids();
        array(py, m.to_vec(), &[m.len()])
    }
    #[getter]
    fn object_ids<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let m = self.inner.object_ids();
        array(py, m.to_vec(), &[m.len()])
    }
    #[getter]
    fn objects(&self) -> Vec<String> {
        self.inner.objects().to_vec()
    }
    #[getter]
    fn triangle_count(&self) -> usize {
        self.inner.triangle_count()
    }
    #[getter]
    fn vertex_count(&self) -> usize {
        self.inner.vertices().len()
    }
    #[getter]
    fn degenerate_count(&self) -> usize {
        self.inner.degenerate_count()
    }
    #[getter]
    fn closed(&self, py: Python<'_>) -> PyResult<bool> {
        // Through `run`, as every parallel call: the weld and the edge sort run on the
        // package's pool, not rayon's global one, which a forked child would not have.
        let scene = &self.inner;
        Ok(super::run(py, || Ok(crate::scene::adjacency::Closure::of(scene)))?.closed)
    }
    #[getter]
    fn bounds<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        rows_array(py, &self.inner.bounds(), &[2, 3])
    }
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.inner.warnings().to_vec()
    }
    #[getter]
    fn materials<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for m in self.inner.materials() {
            let d = PyDict::new(py);
            d.set_item("name", &m.name)?;
            d.set_item("base_color", m.base_color.to_vec())?;
            d.set_item("base_color_factor", m.base_color_factor.to_vec())?;
            d.set_item("base_color_textured", m.base_color_textured)?;
            let texture = m
                .base_color_texture
                .as_ref()
                .map(|r| texture_dict(py, r))
                .transpose()?;
            d.set_item("base_color_texture", texture)?;
            d.set_item("metallic", m.metallic)?;
            d.set_item("roughness", m.roughness)?;
            d.set_item("emissive", m.emissive.to_vec())?;
            d.set_item("double_sided", m.double_sided)?;
            out.append(d)?;
        }
        Ok(out)
    }
    #[getter]
    fn lights<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for l in self.inner.lights() {
            let d = PyDict::new(py);
            let kind = match l.kind {
                LightKind::Directional => "directional",
                LightKind::Point => "point",
                LightKind::Spot => "spot",
            };
            d.set_item("name", &l.name)?;
            d.set_item("type", kind)?;
            d.set_item("color", l.color.to_vec())?;
            d.set_item("intensity", l.intensity)?;
            d.set_item("range", l.range)?;
            d.set_item("position", l.position.to_vec())?;
            d.set_item("direction", l.direction.to_vec())?;
            d.set_item("inner_cone_angle", l.inner_cone_angle)?;
            d.set_item("outer_cone_angle", l.outer_cone_angle)?;
            out.append(d)?;
        }
        Ok(out)
    }
    #[getter]
    fn cameras(&self) -> Vec<PyCamera> {
        self.inner
            .cameras()
            .iter()
            .cloned()
            .map(PyCamera::from)
            .collect()
    }

    fn __repr__(&self) -> String {
        let b = self.inner.bounds();
        format!(
            "Scene({} triangles, {} vertices, {} materials, {} lights, bounds {:?}..{:?})",
            self.inner.triangle_count(),
            self.inner.vertices().len(),
            self.inner.materials().len(),
            self.inner.lights().len(),
            b[0],
            b[1]
        )
    }
}

/// Texture `k` from an (H, W, 4) or (H, W, 3) uint8 array of sRGB-encoded texels (row 0 at the
/// top, as the file stores it).
fn texture(py: Python<'_>, k: usize, a: &Bound<'_, PyAny>) -> PyResult<Arc<Texture>> {
    let arr = a.cast::<numpy::PyArrayDyn<u8>>().map_err(|_| {
        input(
            py,
            format!("textures[{k}] must be a uint8 array of (H, W, 4) or (H, W, 3) texels"),
        )
    })?;
    let view = numpy::PyArrayMethods::readonly(arr);
    let a = view.as_array();
    let shape = a.shape().to_vec();
    if shape.len() != 3 || !(shape[2] == 3 || shape[2] == 4) || shape[0] == 0 || shape[1] == 0 {
        return Err(input(
            py,
            format!("textures[{k}] must have shape (H, W, 4) or (H, W, 3), got {shape:?}"),
        ));
    }
    let texels = a
        .outer_iter()
        .flat_map(|row| {
            row.outer_iter()
                .map(|t| [t[0], t[1], t[2], if shape[2] == 4 { t[3] } else { 255 }])
                .collect::<Vec<_>>()
        })
        .collect();
    let image = Rgba8 {
        width: shape[1] as u32,
        height: shape[0] as u32,
        texels,
    };
    Texture::new(image)
        .map(Arc::new)
        .map_err(|e| input(py, format!("textures[{k}]: {e}")))
}

/// A material's base-colour texture as a dict: `texture` (index into the scene's textures),
/// `wrap_s`, `wrap_t`, `mag_filter`, `min_filter` (glTF's sampler enums) and `transform`
/// (2×3 rows: `u' = a·u + b·v + c`, `v' = d·u + e·v + f`).
fn texture_dict<'py>(py: Python<'py>, r: &TextureRef) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let s = &r.sampler;
    let wrap = |w: Wrap| match w {
        Wrap::Repeat => 10497,
        Wrap::ClampToEdge => 33071,
        Wrap::MirroredRepeat => 33648,
    };
    let min = match (s.min_nearest, s.mipmap) {
        (true, Mipmap::None) => 9728,
        (false, Mipmap::None) => 9729,
        (true, Mipmap::Nearest) => 9984,
        (false, Mipmap::Nearest) => 9985,
        (true, Mipmap::Linear) => 9986,
        (false, Mipmap::Linear) => 9987,
    };
    d.set_item("texture", r.texture)?;
    d.set_item("wrap_s", wrap(s.wrap[0]))?;
    d.set_item("wrap_t", wrap(s.wrap[1]))?;
    d.set_item("mag_filter", if s.mag_nearest { 9728 } else { 9729 })?;
    d.set_item("min_filter", min)?;
    let t = r.transform;
    d.set_item("transform", vec![t[..3].to_vec(), t[3..].to_vec()])?;
    Ok(d)
}

/// A base-colour texture reference from a dict as [`texture_dict`] writes it (the sampler's
/// enums and the transform may be left out: REPEAT, LINEAR, LINEAR_MIPMAP_LINEAR, identity).
fn texture_ref(py: Python<'_>, d: &Bound<'_, PyDict>) -> PyResult<TextureRef> {
    let get =
        |k: &str| -> PyResult<Option<u32>> { d.get_item(k)?.map(|v| v.extract()).transpose() };
    let Some(texture) = d.get_item("texture")? else {
        return Err(input(
            py,
            "a base_color_texture needs its 'texture' index".into(),
        ));
    };
    let wrap = |k: &str| -> PyResult<Wrap> {
        match get(k)? {
            None => Ok(Wrap::Repeat),
            Some(v) => Wrap::from_gl(v).ok_or_else(|| {
                input(
                    py,
                    format!("{k} must be 10497, 33071 or 33648 (glTF's wrap modes), got {v}"),
                )
            }),
        }
    };
    let sampler = Sampler {
        wrap: [wrap("wrap_s")?, wrap("wrap_t")?],
        ..Sampler::default()
    }
    .with_filters(get("mag_filter")?, get("min_filter")?);
    let transform = match d.get_item("transform")? {
        None => IDENTITY_TRANSFORM,
        Some(v) => {
            let rows: Vec<Vec<f64>> = v.extract()?;
            if rows.len() != 2 || rows.iter().any(|r| r.len() != 3) {
                return Err(input(py, "a texture transform is 2x3 rows".into()));
            }
            [
                rows[0][0], rows[0][1], rows[0][2], rows[1][0], rows[1][1], rows[1][2],
            ]
        }
    };
    Ok(TextureRef {
        texture: texture.extract()?,
        sampler,
        transform,
    })
}

/// A material from a dict: `base_color` (RGB or RGBA, linear), `metallic`, `roughness`,
/// `emissive`, `name`, `double_sided`, and a `base_color_texture` (see [`texture_ref`]) with its
/// `base_color_factor` (default: `base_color`; the material's `base_color` is then the factor
/// times the texture's mean, set where the scene's textures are known); glTF's defaults for
/// what is missing.
fn material(py: Python<'_>, d: &Bound<'_, PyDict>) -> PyResult<Material> {
    let get = |k: &str| d.get_item(k);
    let color: Vec<f32> = match get("base_color")? {
        Some(v) => v.extract()?,
        None => vec![1.0, 1.0, 1.0, 1.0],
    };
    let mut rgba = [1.0f32; 4];
    for (dst, src) in rgba.iter_mut().zip(&color) {
        *dst = *src;
    }
    let emissive: Vec<f32> = match get("emissive")? {
        Some(v) => v.extract()?,
        None => vec![0.0; 3],
    };
    let mut em = [0.0f32; 3];
    for (dst, src) in em.iter_mut().zip(&emissive) {
        *dst = *src;
    }
    let texture = match get("base_color_texture")? {
        Some(v) if !v.is_none() => Some(texture_ref(py, v.cast::<PyDict>()?)?),
        _ => None,
    };
    let factor = match (get("base_color_factor")?, &texture) {
        (Some(v), Some(_)) => {
            let f: Vec<f32> = v.extract()?;
            let mut out = [1.0f32; 4];
            for (dst, src) in out.iter_mut().zip(&f) {
                *dst = *src;
            }
            out
        }
        _ => rgba,
    };
    Ok(Material {
        name: match get("name")? {
            Some(v) => v.extract()?,
            None => String::new(),
        },
        base_color: factor,
        base_color_factor: factor,
        base_color_textured: texture.is_some(),
        base_color_texture: texture,
        metallic: match get("metallic")? {
            Some(v) => v.extract()?,
            None => 1.0,
        },
        roughness: match get("roughness")? {
            Some(v) => v.extract()?,
            None => 1.0,
        },
        emissive: em,
        double_sided: match get("double_sided")? {
            Some(v) => v.extract()?,
            None => false,
        },
    })
}

/// A punctual light from a dict with the keys `Scene.lights` reports (`type` and `position` for
/// point and spot lights, `direction` for directional and spot lights; the rest optional).
fn light(py: Python<'_>, d: &Bound<'_, PyDict>) -> PyResult<Light> {
    let kind: String = match d.get_item("type")? {
        Some(v) => v.extract()?,
        None => return Err(input(py, "a light needs a 'type'".to_string())),
    };
    let kind = match kind.as_str() {
        "point" => LightKind::Point,
        "spot" => LightKind::Spot,
        "directional" => LightKind::Directional,
        other => {
            return Err(input(
                py,
                format!("light type must be 'point', 'spot' or 'directional', got {other:?}"),
            ))
        }
    };
    let vec3 = |k: &str, default: [f64; 3]| -> PyResult<[f64; 3]> {
        match d.get_item(k)? {
            Some(v) if !v.is_none() => {
                let x: Vec<f64> = v.extract()?;
                if x.len() != 3 || !x.iter().all(|c| c.is_finite()) {
                    return Err(input(py, format!("light {k} must be 3 finite numbers")));
                }
                Ok([x[0], x[1], x[2]])
            }
            _ => Ok(default),
        }
    };
    let opt = |k: &str| -> PyResult<Option<f32>> {
        match d.get_item(k)? {
            Some(v) if !v.is_none() => Ok(Some(v.extract()?)),
            _ => Ok(None),
        }
    };
    let direction = vec3("direction", [0.0, 0.0, -1.0])?;
    let len = direction.iter().map(|c| c * c).sum::<f64>().sqrt();
    if len <= 0.0 {
        return Err(input(py, "light direction must be non-zero".to_string()));
    }
    let color = vec3("color", [1.0, 1.0, 1.0])?;
    Ok(Light {
        name: match d.get_item("name")? {
            Some(v) if !v.is_none() => v.extract()?,
            _ => String::new(),
        },
        kind,
        color: color.map(|c| c as f32),
        intensity: opt("intensity")?.unwrap_or(1.0),
        range: opt("range")?,
        position: vec3("position", [0.0; 3])?,
        direction: direction.map(|c| c / len),
        inner_cone_angle: opt("inner_cone_angle")?,
        outer_cone_angle: opt("outer_cone_angle")?,
    })
}

/// The attributes of samples of `scene`'s surface: per sample its triangle id (−1: nothing)
/// and where on the triangle, as barycentrics (N, 2) or world points (N, 3); with per-sample
/// footprints (N,) in world units for the texture's level (none: the finest). A dict of
/// `texcoord` (N, 2), `color`, `shading_normal`, `normal` (N, 3).
#[pyfunction]
#[pyo3(signature = (scene, triangle, barycentric=None, points=None, footprint=None))]
pub fn surface_attributes<'py>(
    py: Python<'py>,
    scene: &PyScene,
    triangle: &Bound<'py, PyAny>,
    barycentric: Option<&Bound<'py, PyAny>>,
    points: Option<&Bound<'py, PyAny>>,
    footprint: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    use crate::scene::surface::{attributes, Where};
    let triangle = flat_i32(triangle, "triangle")?;
    let bary = barycentric
        .map(|b| rows_f32::<2>(b, "barycentric"))
        .transpose()?;
    let pts = points.map(|p| rows_f32::<3>(p, "points")).transpose()?;
    let footprint = footprint
        .map(|f| rows_f32::<1>(&f.call_method1("reshape", ((-1i64, 1i64),))?, "footprint"))
        .transpose()?
        .map(|f| f.into_iter().map(|[x]| x).collect::<Vec<f32>>());
    let at = match (&bary, &pts) {
        (Some(b), None) => Where::Barycentric(b),
        (None, Some(p)) => Where::Points(p),
        _ => {
            return Err(input(
                py,
                "give the samples' barycentric coordinates or their points, one of the two".into(),
            ))
        }
    };
    let s = scene.inner.clone();
    let a = super::run(py, || {
        attributes(&s, &triangle, at_again(&at), footprint.as_deref())
    })?;
    let n = triangle.len();
    let d = PyDict::new(py);
    d.set_item(
        "texcoord",
        super::convert::rows_owned(py, a.texcoord, &[n, 2])?,
    )?;
    d.set_item("color", super::convert::rows_owned(py, a.color, &[n, 3])?)?;
    d.set_item(
        "shading_normal",
        super::convert::rows_owned(py, a.shading_normal, &[n, 3])?,
    )?;
    d.set_item("normal", super::convert::rows_owned(py, a.normal, &[n, 3])?)?;
    Ok(d)
}

/// `at` borrowed again (`run` may call its work more than once).
fn at_again<'a>(at: &crate::scene::surface::Where<'a>) -> crate::scene::surface::Where<'a> {
    use crate::scene::surface::Where;
    match at {
        Where::Barycentric(b) => Where::Barycentric(b),
        Where::Points(p) => Where::Points(p),
    }
}
