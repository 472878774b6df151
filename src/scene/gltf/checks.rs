//! What is checked before and while a glTF file is read: glTF 1.0 refused by name, the indices
//! that gltf's validator would follow unchecked, each accessor's type and byte range, and the
//! `EXT_mesh_gpu_instancing` attributes.

use glam::{DMat4, DQuat, DVec3};
use gltf::accessor::{DataType, Dimensions};

use super::Loader;
use crate::error::Result;

/// What makes channel `ch` of animation `anim` unreadable before the glTF reader touches it
/// (its accessors unwrap these): a sampler, node or accessor index out of range. `None` when it
/// can be read. (A target path or interpolation that glTF 2.0 does not name, §3.11, refuses the
/// whole file in `prevalidate`.)
pub(super) fn channel_problem(doc: &gltf::Document, anim: usize, ch: usize) -> Option<String> {
    let root = doc.as_json();
    let a = &root.animations[anim];
    let c = &a.channels[ch];
    let Some(sampler) = a.samplers.get(c.sampler.value()) else {
        return Some(format!(
            "sampler {} does not exist (the animation has {})",
            c.sampler.value(),
            a.samplers.len()
        ));
    };
    if c.target.node.value() >= root.nodes.len() {
        return Some(format!(
            "target node {} does not exist (the file has {} nodes)",
            c.target.node.value(),
            root.nodes.len()
        ));
    }
    for (what, index) in [("input", sampler.input), ("output", sampler.output)] {
        if index.value() >= root.accessors.len() {
            return Some(format!(
                "its {what} accessor {} does not exist",
                index.value()
            ));
        }
    }
    None
}

/// The `asset.version` of a glTF 1.0 file (JSON, or binary glTF 1.0: a GLB header of version
/// 1), which the glTF 2.0 reader cannot parse; `None` for anything else.
pub(super) fn version_one(bytes: &[u8]) -> Option<String> {
    if bytes.len() >= 8 && &bytes[..4] == b"glTF" {
        let version = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]);
        return (version == 1).then(|| "1.0 (binary glTF)".to_string());
    }
    let json: serde_json::Value = serde_json::from_slice(bytes).ok()?;
    let version = json.get("asset")?.get("version")?;
    let v = version
        .as_str()
        .map_or_else(|| version.to_string(), str::to_string);
    v.trim().starts_with('1').then_some(v)
}

pub(super) fn refuse_version_one(version: &str) -> String {
    format!(
        "glTF {version} is not supported: scenesample reads glTF 2.0 (asset.version \"2.0\"); \
         convert the file to glTF 2.0 first (Khronos' glTF 1.0 to 2.0 converters, or Blender's \
         importer and exporter)"
    )
}

/// Checks gltf's validator needs before it runs (it indexes accessors without bounds checks),
/// and the one requirement it enforces that we relax: the spec requires `min`/`max` on POSITION
/// accessors, but exporters omit them and nothing here reads them (bounds come from the data),
/// so missing ones are filled with placeholders rather than rejecting the file.
pub(super) fn prevalidate(root: &mut gltf::json::Root) -> std::result::Result<(), String> {
    use gltf::json::validation::Checked;
    for (i, a) in root.animations.iter().enumerate() {
        for (c, ch) in a.channels.iter().enumerate() {
            if let Checked::Invalid = ch.target.path {
                return Err(format!(
                    "animation {i} channel {c}: its target path is not one glTF 2.0 names \
                     (translation, rotation, scale, weights)"
                ));
            }
        }
        for (k, sampler) in a.samplers.iter().enumerate() {
            if let Checked::Invalid = sampler.interpolation {
                return Err(format!(
                    "animation {i} sampler {k}: its interpolation is not one glTF 2.0 names \
                     (STEP, LINEAR, CUBICSPLINE)"
                ));
            }
        }
    }
    let n = root.accessors.len();
    let mut positions = Vec::new();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let refs = prim
                .attributes
                .iter()
                .map(|(k, v)| (format!("attribute {k:?}"), v.value()));
            let refs = refs.chain(
                prim.indices
                    .iter()
                    .map(|i| ("indices".to_string(), i.value())),
            );
            for (what, i) in refs {
                if i >= n {
                    return Err(format!("mesh {m} primitive {p} {what} refers to accessor {i}, but the file has {n} accessors"));
                }
            }
            for (t, target) in prim.targets.iter().flatten().enumerate() {
                let refs = [&target.positions, &target.normals, &target.tangents];
                for i in refs.into_iter().flatten().map(|i| i.value()) {
                    if i >= n {
                        return Err(format!("mesh {m} primitive {p} morph target {t} refers to accessor {i}, but the file has {n} accessors"));
                    }
                }
            }
            for (k, v) in &prim.attributes {
                if matches!(k, Checked::Valid(gltf::json::mesh::Semantic::Positions)) {
                    positions.push(v.value());
                }
            }
        }
    }
    let nodes = root.nodes.len();
    for (k, skin) in root.skins.iter().enumerate() {
        let joints = skin.joints.iter().chain(&skin.skeleton).map(|j| j.value());
        if let Some(j) = joints.into_iter().find(|&j| j >= nodes) {
            return Err(format!(
                "skin {k} names node {j}, but the file has {nodes} nodes"
            ));
        }
        if let Some(i) = skin.inverse_bind_matrices.map(|i| i.value()) {
            if i >= n {
                return Err(format!("skin {k} inverseBindMatrices refers to accessor {i}, but the file has {n} accessors"));
            }
        }
    }
    for (k, node) in root.nodes.iter().enumerate() {
        if let Some(s) = node.skin.map(|s| s.value()) {
            if s >= root.skins.len() {
                return Err(format!(
                    "node {k} names skin {s}, but the file has {} skins",
                    root.skins.len()
                ));
            }
        }
    }
    for i in positions {
        let a = &mut root.accessors[i];
        for bound in [&mut a.min, &mut a.max] {
            bound.get_or_insert_with(|| serde_json::json!([0.0, 0.0, 0.0]));
        }
    }
    Ok(())
}

impl Loader<'_> {
    /// `EXT_mesh_gpu_instancing`: per-instance TRS matrices, or `None` without the extension.
    pub(super) fn instances(&self, node: &gltf::Node) -> Result<Option<Vec<DMat4>>> {
        let Some(ext) = node.extension_value("EXT_mesh_gpu_instancing") else {
            return Ok(None);
        };
        let attrs = ext
            .get("attributes")
            .and_then(|a| a.as_object())
            .ok_or_else(|| {
                self.err(format!(
                    "node {}: EXT_mesh_gpu_instancing has no attributes",
                    node.index()
                ))
            })?;
        let read = |key: &str, dims: Dimensions| -> Result<Option<Vec<Vec<f32>>>> {
            let Some(idx) = attrs.get(key).and_then(|v| v.as_u64()) else {
                return Ok(None);
            };
            let what = format!("node {} instancing {key}", node.index());
            let acc = self
                .doc
                .accessors()
                .nth(idx as usize)
                .ok_or_else(|| self.err(format!("{what}: accessor {idx} does not exist")))?;
            self.check_accessor(&acc, &what, &[dims], &[DataType::F32])?;
            let n = dims.multiplicity();
            let get = |b: gltf::Buffer| self.buffers.get(b.index()).map(Vec::as_slice);
            let rows: Vec<Vec<f32>> = match n {
                3 => gltf::accessor::Iter::<[f32; 3]>::new(acc, get)
                    .map(|i| i.map(|v| v.to_vec()).collect()),
                _ => gltf::accessor::Iter::<[f32; 4]>::new(acc, get)
                    .map(|i| i.map(|v| v.to_vec()).collect()),
            }
            .ok_or_else(|| self.err(format!("{what}: accessor {idx} could not be read")))?;
            Ok(Some(rows))
        };
        let t = read("TRANSLATION", Dimensions::Vec3)?;
        let r = read("ROTATION", Dimensions::Vec4)?;
        let s = read("SCALE", Dimensions::Vec3)?;
        let count = [&t, &r, &s]
            .iter()
            .filter_map(|x| x.as_ref().map(Vec::len))
            .max()
            .unwrap_or(0);
        if [&t, &r, &s]
            .iter()
            .any(|x| x.as_ref().is_some_and(|v| v.len() != count))
        {
            return Err(self.err(format!(
                "node {}: EXT_mesh_gpu_instancing attributes have different counts",
                node.index()
            )));
        }
        let mats = (0..count)
            .map(|i| {
                let tr = t.as_ref().map_or(DVec3::ZERO, |v| {
                    DVec3::new(v[i][0] as f64, v[i][1] as f64, v[i][2] as f64)
                });
                let ro = r.as_ref().map_or(DQuat::IDENTITY, |v| {
                    DQuat::from_xyzw(
                        v[i][0] as f64,
                        v[i][1] as f64,
                        v[i][2] as f64,
                        v[i][3] as f64,
                    )
                    .normalize()
                });
                let sc = s.as_ref().map_or(DVec3::ONE, |v| {
                    DVec3::new(v[i][0] as f64, v[i][1] as f64, v[i][2] as f64)
                });
                DMat4::from_scale_rotation_translation(sc, ro, tr)
            })
            .collect();
        Ok(Some(mats))
    }

    /// Check an accessor's type and that every byte it reads lies inside its buffer view and
    /// buffer (including sparse index/value views).
    pub(super) fn check_accessor(
        &self,
        acc: &gltf::Accessor,
        what: &str,
        dims: &[Dimensions],
        types: &[DataType],
    ) -> Result<()> {
        let i = acc.index();
        if !dims.contains(&acc.dimensions()) || !types.contains(&acc.data_type()) {
            return Err(self.err(format!(
                "{what}: accessor {i} has type {:?} {:?}, expected one of {dims:?} with components {types:?}",
                acc.dimensions(),
                acc.data_type()
            )));
        }
        if acc.count() == 0 {
            return Err(self.err(format!("{what}: accessor {i} has count 0")));
        }
        let elem = acc.size();
        if let Some(view) = acc.view() {
            let stride = view.stride().unwrap_or(elem);
            let need = acc.offset() + stride * (acc.count() - 1) + elem;
            self.check_view(&view, need, &format!("{what}: accessor {i}"))?;
        }
        if let Some(sp) = acc.sparse() {
            let n = sp.count();
            let idx = sp.indices();
            let isz = match idx.index_type() {
                gltf::accessor::sparse::IndexType::U8 => 1,
                gltf::accessor::sparse::IndexType::U16 => 2,
                gltf::accessor::sparse::IndexType::U32 => 4,
            };
            self.check_view(
                &idx.view(),
                idx.offset() + n * isz,
                &format!("{what}: accessor {i} sparse indices"),
            )?;
            let vals = sp.values();
            self.check_view(
                &vals.view(),
                vals.offset() + n * elem,
                &format!("{what}: accessor {i} sparse values"),
            )?;
        }
        Ok(())
    }

    pub(super) fn check_view(
        &self,
        view: &gltf::buffer::View,
        need: usize,
        what: &str,
    ) -> Result<()> {
        if need > view.length() {
            return Err(self.err(format!(
                "{what} reads {need} bytes but buffer view {} has {}",
                view.index(),
                view.length()
            )));
        }
        let buf = &self.buffers[view.buffer().index()];
        if view.offset() + view.length() > buf.len() {
            return Err(self.err(format!(
                "buffer view {} (bytes {}..{}) lies outside buffer {} ({} bytes)",
                view.index(),
                view.offset(),
                view.offset() + view.length(),
                view.buffer().index(),
                buf.len()
            )));
        }
        Ok(())
    }
}
