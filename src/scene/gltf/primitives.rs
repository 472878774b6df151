//! A mesh instance's triangle primitives (glTF 2.0 §3.7.2) read into the scene: positions
//! placed in world space, indices, the vertices' base colour (the material's factor × COLOR_0),
//! normals (NORMAL, placed by the inverse transpose of the node's transform) and the texture
//! coordinates that the material's base-colour texture names. Attributes may be float32 or the
//! integer types `KHR_mesh_quantization` allows ([`super::accessors`]).

use glam::{DMat4, DVec3, DVec4};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;

use super::accessors::{NORMAL_TYPES, POSITION_TYPES, TEXCOORD_TYPES};
use super::{triangles, Loader};
use crate::error::Result;
use crate::scene::skin::normal_map;

/// One triangle primitive's vertex data, read and checked.
pub(super) struct Vertices {
    pub positions: Vec<[f32; 3]>,
    /// Triangle-list, strip or fan indices (every vertex in order when the file has none).
    pub indices: Vec<u32>,
    pub colors: Option<Vec<[f32; 4]>>,
    pub normals: Option<Vec<[f32; 3]>>,
    pub texcoords: Option<Vec<[f32; 2]>>,
}

impl Loader<'_> {
    /// Object `name`: the triangle primitives of `mesh` under `node`, placed by `world` (the
    /// node's world transform times `instance`, its `EXT_mesh_gpu_instancing` transform); a
    /// skin or morph targets place them instead (`skins.rs`), in their rest pose.
    pub(super) fn mesh(
        &mut self,
        mesh: &gltf::Mesh,
        node: &gltf::Node,
        world: DMat4,
        instance: DMat4,
        name: String,
    ) -> Result<()> {
        let object = self.parts.objects.len() as i32;
        self.parts.objects.push(name);
        let mut deform = self.deformation(mesh, node, instance, object as usize)?;
        // A skinned mesh ignores its node's transform, so its winding too (glTF 2.0 §3.7.4).
        let skinned = deform.as_ref().is_some_and(|d| d.skin.is_some());
        let flip = !skinned && world.determinant() < 0.0;
        let normals_to_world = normal_map(&world);
        for prim in mesh.primitives() {
            let what = format!("mesh {} primitive {}", mesh.index(), prim.index());
            match prim.mode() {
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan => {}
                other => {
                    self.warn(format!(
                        "{what}: {other:?} primitives are not triangles and were skipped"
                    ));
                    continue;
                }
            }
            let material = prim.material().index().map_or(-1, |i| i as i32);
            let v = self.read_primitive(&prim, &what, material)?;
            if let Some(d) = deform.as_mut() {
                self.add_primitive(d, &prim, &what, &v)?;
            }
            self.add_vertices(&v, material, world, normals_to_world);
            let offset = self.parts.vertices.len() as u32 - v.positions.len() as u32;
            for mut f in triangles(prim.mode(), &v.indices) {
                if flip {
                    f.swap(1, 2);
                }
                self.parts.faces.push(f.map(|i| i + offset));
                self.parts.material_ids.push(material);
                self.parts.object_ids.push(object);
            }
        }
        if let Some(d) = deform {
            self.place_deformable(d);
        }
        Ok(())
    }

    /// Append a primitive's vertices, placed by `world` (normals by `normals_to_world`), with
    /// the base colour factor of `material` times their COLOR_0. Normals and texture
    /// coordinates start (zero-filled for the vertices before) with the first primitive that
    /// has them; a vertex without one gets a zero row.
    fn add_vertices(
        &mut self,
        v: &Vertices,
        material: i32,
        world: DMat4,
        normals_to_world: glam::DMat3,
    ) {
        let parts = &mut self.parts;
        let before = parts.vertices.len();
        let n = v.positions.len();
        let factor = usize::try_from(material)
            .ok()
            .and_then(|i| parts.materials.get(i))
            .map_or([1.0; 4], |m| m.base_color_factor);
        for (k, p) in v.positions.iter().enumerate() {
            let w = world * DVec4::new(p[0] as f64, p[1] as f64, p[2] as f64, 1.0);
            parts.vertices.push(w.truncate().as_vec3().to_array());
            let c = v.colors.as_ref().map_or([1.0; 4], |c| c[k]);
            parts.colors.get_or_insert_with(Vec::new).push([
                factor[0] * c[0],
                factor[1] * c[1],
                factor[2] * c[2],
            ]);
        }
        match &v.normals {
            Some(ns) => {
                let out = parts.normals.get_or_insert_with(|| vec![[0.0; 3]; before]);
                out.extend(ns.iter().map(|n| {
                    let w = normals_to_world * DVec3::from(n.map(f64::from));
                    w.normalize_or_zero().as_vec3().to_array()
                }));
            }
            None => {
                if let Some(out) = parts.normals.as_mut() {
                    out.resize(before + n, [0.0; 3]);
                }
            }
        }
        match &v.texcoords {
            Some(uv) => parts
                .texcoords
                .get_or_insert_with(|| vec![[0.0; 2]; before])
                .extend_from_slice(uv),
            None => {
                if let Some(out) = parts.texcoords.as_mut() {
                    out.resize(before + n, [0.0; 2]);
                }
            }
        }
    }

    /// A triangle primitive's positions (finite), indices (in range), COLOR_0, NORMAL and the
    /// texture coordinates of `material`'s base-colour texture, checked.
    fn read_primitive(
        &mut self,
        prim: &gltf::Primitive,
        what: &str,
        material: i32,
    ) -> Result<Vertices> {
        let Some(pos_acc) = prim.get(&gltf::Semantic::Positions) else {
            return Err(self.err(format!("{what} has no POSITION attribute")));
        };
        let positions: Vec<[f32; 3]> = self.vectors(
            &pos_acc,
            &format!("{what} POSITION"),
            Dimensions::Vec3,
            POSITION_TYPES,
        )?;
        let buffers = &self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let indices: Vec<u32> = match prim.indices() {
            Some(acc) => {
                self.check_accessor(
                    &acc,
                    &format!("{what} indices"),
                    &[Dimensions::Scalar],
                    &[DataType::U8, DataType::U16, DataType::U32],
                )?;
                let idx: Vec<u32> = reader
                    .read_indices()
                    .ok_or_else(|| {
                        self.err(format!(
                            "{what}: index accessor {} could not be read",
                            acc.index()
                        ))
                    })?
                    .into_u32()
                    .collect();
                if let Some(k) = idx.iter().position(|&i| i as usize >= positions.len()) {
                    return Err(self.err(format!(
                        "{what}: index accessor {} has index {} at position {k}, but POSITION \
                         has {} vertices",
                        acc.index(),
                        idx[k],
                        positions.len()
                    )));
                }
                idx
            }
            None => (0..positions.len() as u32).collect(),
        };
        let colors: Option<Vec<[f32; 4]>> = match prim.get(&gltf::Semantic::Colors(0)) {
            Some(acc) => {
                self.check_accessor(
                    &acc,
                    &format!("{what} COLOR_0"),
                    &[Dimensions::Vec3, Dimensions::Vec4],
                    &[DataType::F32, DataType::U8, DataType::U16],
                )?;
                reader.read_colors(0).map(|c| c.into_rgba_f32().collect())
            }
            None => None,
        };
        let normals = match prim.get(&gltf::Semantic::Normals) {
            Some(acc) => Some(self.vectors(
                &acc,
                &format!("{what} NORMAL"),
                Dimensions::Vec3,
                NORMAL_TYPES,
            )?),
            None => None,
        };
        let texcoords = self.texcoords(prim, what, material)?;
        let n = positions.len();
        for (name, len) in [
            ("COLOR_0", colors.as_ref().map(Vec::len)),
            ("NORMAL", normals.as_ref().map(Vec::len)),
            ("TEXCOORD", texcoords.as_ref().map(Vec::len)),
        ] {
            if let Some(len) = len.filter(|&l| l != n) {
                return Err(self.err(format!("{what}: {name} has {len} entries for {n} vertices")));
            }
        }
        Ok(Vertices {
            positions,
            indices,
            colors,
            normals,
            texcoords,
        })
    }

    /// The texture coordinates of `material`'s base-colour texture on `prim` (the set it
    /// names); `None` when the material has no texture. A primitive without that set reads the
    /// texture at (0, 0), with a warning.
    fn texcoords(
        &mut self,
        prim: &gltf::Primitive,
        what: &str,
        material: i32,
    ) -> Result<Option<Vec<[f32; 2]>>> {
        let Some(set) = usize::try_from(material)
            .ok()
            .filter(|&m| self.parts.materials[m].base_color_texture.is_some())
            .map(|m| self.texcoord_sets[m])
        else {
            return Ok(None);
        };
        match prim.get(&gltf::Semantic::TexCoords(set)) {
            Some(acc) => Ok(Some(self.vectors(
                &acc,
                &format!("{what} TEXCOORD_{set}"),
                Dimensions::Vec2,
                TEXCOORD_TYPES,
            )?)),
            None => {
                self.warn(format!(
                    "{what} has no TEXCOORD_{set}, which its material's base-colour texture \
                     reads; the texture is read at (0, 0) there"
                ));
                Ok(None)
            }
        }
    }
}
