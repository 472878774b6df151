//! glTF 2.0 loading (`.gltf` with external or data-URI buffers, `.glb`) into `SceneParts`:
//! every triangle primitive of every mesh instance (node hierarchy flattened with f64 world
//! transforms, `EXT_mesh_gpu_instancing` expanded), metallic-roughness materials,
//! `KHR_lights_punctual` lights and glTF cameras. Every accessor is bounds- and type-checked
//! before it is read, so a malformed file gives an error naming the element, never a panic.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use base64::Engine;
use glam::DMat4;
use gltf::mesh::Mode;

use super::animation::Placed;
use super::skin::{self, Rigging};
use super::{Light, LightKind, Scene, SceneParts};
use crate::camera::{rigid_from, Camera, Projection};
use crate::error::{Error, Result};

mod accessors;
mod checks;
mod clips;
mod draco;
mod materials;
mod meshopt;
mod pointer;
mod primitives;
mod skins;

use checks::{prevalidate, refuse_version_one, version_one};

/// Extensions whose content we read.
const HANDLED: &[&str] = &[
    "KHR_animation_pointer",
    "KHR_draco_mesh_compression",
    "KHR_lights_punctual",
    "EXT_mesh_gpu_instancing",
    "KHR_materials_emissive_strength",
    "KHR_mesh_quantization",
    "KHR_texture_transform",
    "EXT_meshopt_compression",
    "KHR_meshopt_compression",
];

/// Extensions we can honour when a file requires them: geometry is intact without them, and
/// only shading detail that no method here simulates is lost (a warning says so).
fn honourable(ext: &str) -> bool {
    HANDLED.contains(&ext) || ext.starts_with("KHR_materials_")
}

/// Default image height for glTF cameras (glTF cameras carry no resolution).
pub const CAMERA_HEIGHT: u32 = 512;

/// Load a glTF 2.0 file. Non-fatal problems (missing images, unknown extensions, point and
/// line primitives) are returned as `SceneParts::warnings`.
pub fn load(path: &Path) -> Result<Scene> {
    let parts = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| load_parts(path)))
        .unwrap_or_else(|p| {
            let msg = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            Err(file_err(
                path,
                format!("internal error while reading the file ({msg}); please report it"),
            ))
        })?;
    Scene::new(parts).map_err(|e| match e {
        Error::Scene(m) => Error::Scene(format!("{}: {m}", path.display())),
        other => other,
    })
}

fn file_err(path: &Path, message: impl Into<String>) -> Error {
    Error::SceneFile {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn scene_err(path: &Path, message: impl std::fmt::Display) -> Error {
    Error::Scene(format!("{}: {message}", path.display()))
}

fn load_parts(path: &Path) -> Result<SceneParts> {
    let bytes =
        std::fs::read(path).map_err(|e| file_err(path, format!("cannot read the file: {e}")))?;
    let unreadable = |e: &dyn std::fmt::Display| {
        let why = match version_one(&bytes) {
            Some(v) => refuse_version_one(&v),
            None => format!("not a readable glTF/GLB file (truncated or corrupt?): {e}"),
        };
        file_err(path, why)
    };
    let (json, blob) = if bytes.starts_with(b"glTF") {
        let glb = gltf::Glb::from_slice(&bytes).map_err(|e| unreadable(&e))?;
        (glb.json.into_owned(), glb.bin.map(|b| b.into_owned()))
    } else {
        (bytes.clone(), None)
    };
    let mut value: serde_json::Value = serde_json::from_slice(&json).map_err(|e| unreadable(&e))?;
    let mut warnings: Vec<String> = pointer::resolve_extension_channels(&mut value)
        .into_iter()
        .map(|m| format!("{}: {m}", path.display()))
        .collect();
    let mut root: gltf::json::Root = serde_json::from_value(value).map_err(|e| unreadable(&e))?;
    if root.asset.version.trim().starts_with('1') {
        return Err(file_err(path, refuse_version_one(&root.asset.version)));
    }
    for ext in &root.extensions_required {
        if !honourable(ext) {
            return Err(scene_err(
                path,
                format!("the file requires the extension {ext}, which scenesample cannot decode (e.g. compressed geometry); re-export it without {ext}"),
            ));
        }
    }
    for ext in &root.extensions_used {
        if !HANDLED.contains(&ext.as_str()) {
            warnings.push(format!(
                "{}: extension {ext} is not simulated and was ignored",
                path.display()
            ));
        }
    }
    // gltf's validator rejects required extensions it does not know; we checked them above.
    root.extensions_required.clear();
    prevalidate(&mut root).map_err(|m| scene_err(path, m))?;
    validate(&root).map_err(|e| scene_err(path, e))?;
    let doc = gltf::Document::from_json_without_validation(root);
    let base = path.parent().unwrap_or(Path::new("."));
    let mut buffers = load_buffers(path, &doc, base, blob)?;
    meshopt::decode_views(&doc, &mut buffers).map_err(|m| scene_err(path, m))?;
    let mut loader = Loader {
        path,
        doc: &doc,
        buffers,
        base,
        parts: SceneParts {
            warnings,
            ..Default::default()
        },
        images: HashMap::new(),
        texcoord_sets: Vec::new(),
        placed: Vec::new(),
        placed_lights: Vec::new(),
        placed_cameras: Vec::new(),
        parents: Vec::new(),
        rest: Vec::new(),
        rigging: Rigging::default(),
        skin_index: Default::default(),
    };
    loader.materials();
    loader.nodes()?;
    loader.animations()?;
    let mut parts = loader.parts;
    // A texture whose primitives all lack its coordinates is read at (0, 0).
    if parts.texcoords.is_none()
        && parts
            .materials
            .iter()
            .any(|m| m.base_color_texture.is_some())
    {
        parts.texcoords = Some(vec![[0.0; 2]; parts.vertices.len()]);
    }
    Ok(parts)
}

fn load_buffers(
    path: &Path,
    doc: &gltf::Document,
    base: &Path,
    mut blob: Option<Vec<u8>>,
) -> Result<Vec<Vec<u8>>> {
    let mut out = Vec::new();
    for b in doc.buffers() {
        // A meshopt fallback buffer's data is its compressed views', decoded into it later.
        if meshopt::is_fallback(&b) {
            // Probe for the memory first: an absurd byteLength is an error, not an abort.
            // The zeroed pages are mapped lazily; decoding touches only what views fill.
            let mut probe: Vec<u8> = Vec::new();
            probe.try_reserve_exact(b.length()).map_err(|_| {
                scene_err(
                    path,
                    format!(
                        "buffer {} (a meshopt fallback buffer) declares byteLength {}, which cannot be allocated",
                        b.index(),
                        b.length()
                    ),
                )
            })?;
            drop(probe);
            out.push(vec![0; b.length()]);
            continue;
        }
        let data = match b.source() {
            gltf::buffer::Source::Bin => blob.take().ok_or_else(|| {
                scene_err(
                    path,
                    format!(
                        "buffer {} refers to the GLB binary chunk, which is missing",
                        b.index()
                    ),
                )
            })?,
            gltf::buffer::Source::Uri(uri) => read_uri(uri, base)
                .map_err(|m| file_err(path, format!("buffer {} ('{uri}'): {m}", b.index())))?,
        };
        if data.len() < b.length() {
            return Err(file_err(
                path,
                format!(
                    "buffer {} has {} bytes but declares byteLength {} (truncated?)",
                    b.index(),
                    data.len(),
                    b.length()
                ),
            ));
        }
        out.push(data);
    }
    Ok(out)
}

/// Bytes of a data URI or of a file relative to `base` (percent-decoded).
fn read_uri(uri: &str, base: &Path) -> std::result::Result<Vec<u8>, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (meta, data) = rest
            .split_once(',')
            .ok_or("malformed data URI (no comma)")?;
        if !meta.ends_with(";base64") {
            return Err("only base64 data URIs are supported".into());
        }
        return base64::engine::general_purpose::STANDARD
            .decode(data)
            .map_err(|e| format!("bad base64 data URI: {e}"));
    }
    let file: PathBuf = base.join(percent_decode(uri));
    std::fs::read(&file).map_err(|e| format!("cannot read {}: {e}", file.display()))
}

fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

pub(super) struct Loader<'a> {
    path: &'a Path,
    doc: &'a gltf::Document,
    buffers: Vec<Vec<u8>>,
    base: &'a Path,
    parts: SceneParts,
    /// Per glTF image read so far, its index among the scene's textures (`None`: unreadable).
    images: HashMap<usize, Option<usize>>,
    /// Per material, the texture coordinate set its base-colour texture reads.
    texcoord_sets: Vec<u32>,
    /// Per object, where it hangs in the node hierarchy (for animations).
    placed: Vec<Placed>,
    /// The nodes of `parts.lights` and `parts.cameras`, in order, for animations to move.
    placed_lights: Vec<Placed>,
    placed_cameras: Vec<Placed>,
    /// Each node's parent and its world transform as loaded.
    parents: Vec<Option<usize>>,
    rest: Vec<DMat4>,
    /// The skins and the objects that skins or morph targets move.
    rigging: Rigging,
    skin_index: skins::SkinIndex,
}

impl Loader<'_> {
    fn err(&self, m: impl std::fmt::Display) -> Error {
        scene_err(self.path, m)
    }

    fn warn(&mut self, m: impl std::fmt::Display) {
        self.parts
            .warnings
            .push(format!("{}: {m}", self.path.display()));
    }

    fn nodes(&mut self) -> Result<()> {
        let doc = self.doc;
        let mut parents = vec![None; doc.nodes().len()];
        for n in doc.nodes() {
            for c in n.children() {
                parents[c.index()] = Some(n.index());
            }
        }
        let locals: Vec<DMat4> = doc.nodes().map(|n| local_of(&n)).collect();
        self.rest = skin::worlds(&parents, &locals);
        self.parents = parents;
        let roots: Vec<gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
            Some(s) => s.nodes().collect(),
            None => {
                let children: HashSet<usize> = doc
                    .nodes()
                    .flat_map(|n| n.children().map(|c| c.index()))
                    .collect();
                doc.nodes()
                    .filter(|n| !children.contains(&n.index()))
                    .collect()
            }
        };
        for n in roots {
            self.visit(n, DMat4::IDENTITY, &mut Vec::new())?;
        }
        Ok(())
    }

    fn visit(&mut self, node: gltf::Node, parent: DMat4, stack: &mut Vec<usize>) -> Result<()> {
        if stack.contains(&node.index()) {
            return Err(self.err(format!(
                "node {} is its own ancestor (node cycle {:?} -> {})",
                node.index(),
                stack,
                node.index()
            )));
        }
        let world = parent * local_of(&node);
        if !world.is_finite() {
            return Err(self.err(format!("node {} has a non-finite transform", node.index())));
        }
        stack.push(node.index());
        if let Some(mesh) = node.mesh() {
            let name = node
                .name()
                .or(mesh.name())
                .map(str::to_string)
                .unwrap_or_else(|| format!("node{}", node.index()));
            let place = |instance: DMat4| Placed {
                node: node.index(),
                instance,
                loaded: world * instance,
            };
            match self.instances(&node)? {
                None => {
                    self.placed.push(place(DMat4::IDENTITY));
                    self.mesh(&mesh, &node, world, DMat4::IDENTITY, name)?
                }
                Some(inst) => {
                    for (i, m) in inst.iter().enumerate() {
                        self.placed.push(place(*m));
                        self.mesh(&mesh, &node, world * *m, *m, format!("{name}#{i}"))?;
                    }
                }
            }
        }
        let at_node = Placed {
            node: node.index(),
            instance: DMat4::IDENTITY,
            loaded: world,
        };
        if let Some(light) = node.light() {
            self.light(&light, world);
            self.placed_lights.push(at_node.clone());
        }
        if let Some(cam) = node.camera() {
            self.camera(&cam, world, node.name())?;
            self.placed_cameras.push(at_node);
        }
        for child in node.children() {
            self.visit(child, world, stack)?;
        }
        stack.pop();
        Ok(())
    }

    fn light(&mut self, light: &gltf::khr_lights_punctual::Light, world: DMat4) {
        use gltf::khr_lights_punctual::Kind;
        let (kind, inner, outer) = match light.kind() {
            Kind::Directional => (LightKind::Directional, None, None),
            Kind::Point => (LightKind::Point, None, None),
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => (
                LightKind::Spot,
                Some(inner_cone_angle),
                Some(outer_cone_angle),
            ),
        };
        let mut placed = Light {
            name: light.name().unwrap_or("").to_string(),
            kind,
            color: light.color(),
            intensity: light.intensity(),
            range: light.range(),
            position: [0.0; 3],
            direction: [0.0; 3],
            inner_cone_angle: inner,
            outer_cone_angle: outer,
        };
        placed.place(&world);
        self.parts.lights.push(placed);
    }

    /// glTF cameras carry no resolution: height `CAMERA_HEIGHT`, width from the aspect ratio
    /// (perspective `aspectRatio`, else xmag/ymag, else square). Scale is removed from the pose.
    fn camera(&mut self, cam: &gltf::Camera, world: DMat4, node_name: Option<&str>) -> Result<()> {
        let pose = rigid_from(world);
        let h = CAMERA_HEIGHT;
        let width = |aspect: f64| ((h as f64 * aspect).round().max(1.0)) as u32;
        let mut c = match cam.projection() {
            gltf::camera::Projection::Perspective(p) => Camera::new(
                pose,
                Projection::Perspective {
                    yfov: p.yfov() as f64,
                },
                width(p.aspect_ratio().map_or(1.0, f64::from)),
                h,
                Some(p.znear() as f64),
                p.zfar().map(f64::from),
            ),
            gltf::camera::Projection::Orthographic(o) => Camera::new(
                pose,
                Projection::Orthographic {
                    xmag: o.xmag().abs() as f64,
                    ymag: o.ymag().abs() as f64,
                },
                width((o.xmag() / o.ymag()).abs() as f64),
                h,
                Some(o.znear().max(f32::MIN_POSITIVE) as f64),
                Some(o.zfar() as f64),
            ),
        }
        .map_err(|e| self.err(format!("camera {}: {e}", cam.index())))?;
        c.name = cam.name().or(node_name).map(str::to_string);
        self.parts.cameras.push(c);
        Ok(())
    }
}

/// A node's local transform (its matrix, or its TRS composed), in f64.
fn local_of(node: &gltf::Node) -> DMat4 {
    DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)))
}

/// gltf's validation of the document, but for one rule it adds to the spec: an accessor with
/// neither a buffer view nor sparse values is valid glTF (its values are zeros, §3.6.2.5), and
/// the accessors of a `KHR_draco_mesh_compression` primitive are such accessors.
fn validate(root: &gltf::json::Root) -> std::result::Result<(), gltf::Error> {
    use gltf::json::validation::{Error as Invalid, Validate};
    let mut errors = Vec::new();
    root.validate(root, gltf::json::Path::new, &mut |path, error| {
        let path = path();
        let dataless = path.as_str().starts_with("accessors[")
            && path.as_str().ends_with("].bufferView")
            && matches!(error, Invalid::Missing);
        if !dataless {
            errors.push((path, error));
        }
    });
    if errors.is_empty() {
        Ok(())
    } else {
        Err(gltf::Error::Validation(errors))
    }
}

/// Triangle lists from glTF primitive modes (glTF 2.0 §3.7.2.1): strips alternate winding,
/// fans pivot on the first vertex.
fn triangles(mode: Mode, idx: &[u32]) -> Vec<[u32; 3]> {
    match mode {
        Mode::Triangles => idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        Mode::TriangleStrip => (0..idx.len().saturating_sub(2))
            .map(|i| {
                if i % 2 == 0 {
                    [idx[i], idx[i + 1], idx[i + 2]]
                } else {
                    [idx[i + 1], idx[i], idx[i + 2]]
                }
            })
            .collect(),
        Mode::TriangleFan => (1..idx.len().saturating_sub(1))
            .map(|i| [idx[i], idx[i + 1], idx[0]])
            .collect(),
        _ => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_become_triangle_lists() {
        assert_eq!(
            triangles(Mode::TriangleStrip, &[0, 1, 2, 3]),
            vec![[0, 1, 2], [2, 1, 3]]
        );
        assert_eq!(
            triangles(Mode::TriangleFan, &[0, 1, 2, 3]),
            vec![[1, 2, 0], [2, 3, 0]]
        );
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("a%20b.bin"), "a b.bin");
        assert_eq!(percent_decode("100%"), "100%");
    }
}
