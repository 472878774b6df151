//! A mesh instance's triangle primitives (glTF 2.0 §3.7.2) read into the scene: positions
//! placed in world space, indices, the vertices' base colour (the material's factor × COLOR_0),
//! normals (NORMAL, placed by the inverse transpose of the node's transform) and the texture
//! coordinates that the material's base-colour texture names. Attributes may be float32 or the
//! integer types `KHR_mesh_quantization` allows ([`super::accessors`]), or come from a
//! `KHR_draco_mesh_compression` stream ([`super::draco`]).

use glam::{DMat4, DVec3, DVec4};
use gltf::accessor::{DataType, Dimensions, Item};
use gltf::mesh::Mode;

use super::accessors::{NORMAL_TYPES, POSITION_TYPES, TEXCOORD_TYPES};
use super::draco::Draco;
use super::{triangles, Loader};
use crate::error::Result;
use crate::scene::skin::normal_map;

/// One triangle primitive's vertex data, read and checked.
pub(super) struct Vertices {
    pub positions: Vec<[f32; 3]>,
    /// Indices in `mode`'s order (every vertex in order when the file has none).
    pub indices: Vec<u32>,
    /// Triangles, a strip or a fan (a Draco stream decodes to triangles).
    pub mode: Mode,
    pub colors: Option<Vec<[f32; 4]>>,
    pub normals: Option<Vec<[f32; 3]>>,
    pub texcoords: Option<Vec<[f32; 2]>>,
    /// The decoded Draco stream of a compressed primitive, for its other attributes (joints
    /// and weights).
    pub draco: Option<Draco>,
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
            for mut f in triangles(v.mode, &v.indices) {
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
    /// texture coordinates of `material`'s base-colour texture, checked; from its Draco stream
    /// when it is compressed.
    fn read_primitive(
        &mut self,
        prim: &gltf::Primitive,
        what: &str,
        material: i32,
    ) -> Result<Vertices> {
        let draco = self.draco(prim, what)?;
        let d = draco.as_ref();
        let positions: Vec<[f32; 3]> = self
            .attribute(prim, d, gltf::Semantic::Positions, what, POSITION_TYPES)?
            .ok_or_else(|| self.err(format!("{what} has no POSITION attribute")))?;
        let (indices, mode) = match d {
            Some(d) => (d.indices(), Mode::Triangles),
            None => (self.indices(prim, what, positions.len())?, prim.mode()),
        };
        if let Some(k) = indices.iter().position(|&i| i as usize >= positions.len()) {
            return Err(self.err(format!(
                "{what}: index {} at position {k} is out of range: POSITION has {} vertices",
                indices[k],
                positions.len()
            )));
        }
        let colors = self.colors(prim, d, what)?;
        let normals = self.attribute(prim, d, gltf::Semantic::Normals, what, NORMAL_TYPES)?;
        let texcoords = self.texcoords(prim, d, what, material)?;
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
            mode,
            colors,
            normals,
            texcoords,
            draco,
        })
    }

    /// `prim`'s indices from its accessor (in range of `count` vertices is checked by the
    /// caller), or every vertex in order without one.
    fn indices(&self, prim: &gltf::Primitive, what: &str, count: usize) -> Result<Vec<u32>> {
        let Some(acc) = prim.indices() else {
            return Ok((0..count as u32).collect());
        };
        self.check_accessor(
            &acc,
            &format!("{what} indices"),
            &[Dimensions::Scalar],
            &[DataType::U8, DataType::U16, DataType::U32],
        )?;
        let buffers = &self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
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
        if let Some(k) = idx.iter().position(|&i| i as usize >= count) {
            return Err(self.err(format!(
                "{what}: index accessor {} has index {} at position {k}, but POSITION has \
                 {count} vertices",
                acc.index(),
                idx[k],
            )));
        }
        Ok(idx)
    }

    /// COLOR_0 of `prim` as RGBA (an RGB attribute is opaque), if it has one.
    fn colors(
        &self,
        prim: &gltf::Primitive,
        draco: Option<&Draco>,
        what: &str,
    ) -> Result<Option<Vec<[f32; 4]>>> {
        let semantic = gltf::Semantic::Colors(0);
        let Some(acc) = prim.get(&semantic) else {
            return Ok(None);
        };
        let types = &[DataType::F32, DataType::U8, DataType::U16];
        Ok(match acc.dimensions() {
            Dimensions::Vec3 => self
                .attribute::<3>(prim, draco, semantic, what, types)?
                .map(|c| c.into_iter().map(|[r, g, b]| [r, g, b, 1.0]).collect()),
            _ => self.attribute::<4>(prim, draco, semantic, what, types)?,
        })
    }

    /// Attribute `semantic` of `prim` as `N` floats per vertex (its accessor's component type
    /// one of `types`, integers converted as its `normalized` flag says), or `None` when the
    /// primitive has none: from the Draco stream `draco` when that carries it, else from the
    /// accessor, checked.
    pub(super) fn attribute<const N: usize>(
        &self,
        prim: &gltf::Primitive,
        draco: Option<&Draco>,
        semantic: gltf::Semantic,
        what: &str,
        types: &[DataType],
    ) -> Result<Option<Vec<[f32; N]>>>
    where
        [f32; N]: Item,
        [i8; N]: Item,
        [u8; N]: Item,
        [i16; N]: Item,
        [u16; N]: Item,
        [u32; N]: Item,
    {
        let Some(acc) = prim.get(&semantic) else {
            return Ok(None);
        };
        let name = semantic.to_string();
        let what = format!("{what} {name}");
        let dims = match N {
            1 => Dimensions::Scalar,
            2 => Dimensions::Vec2,
            3 => Dimensions::Vec3,
            _ => Dimensions::Vec4,
        };
        let decoded = draco.and_then(|d| d.attribute::<N>(&name, acc.normalized()));
        let rows = match decoded {
            Some(rows) => {
                let rows = rows.map_err(|m| self.err(format!("{what}: {m}")))?;
                if let Some(k) = rows.iter().position(|v| v.iter().any(|x| !x.is_finite())) {
                    return Err(self.err(format!("{what} has a non-finite value at index {k}")));
                }
                rows
            }
            None => self.vectors(&acc, &what, dims, types)?,
        };
        Ok(Some(rows))
    }

    /// The texture coordinates of `material`'s base-colour texture on `prim` (the set it
    /// names); `None` when the material has no texture. A primitive without that set reads the
    /// texture at (0, 0), with a warning.
    fn texcoords(
        &mut self,
        prim: &gltf::Primitive,
        draco: Option<&Draco>,
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
        let semantic = gltf::Semantic::TexCoords(set);
        match self.attribute(prim, draco, semantic, what, TEXCOORD_TYPES)? {
            Some(uv) => Ok(Some(uv)),
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
