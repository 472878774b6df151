//! `KHR_draco_mesh_compression`: a primitive whose indices and vertex attributes are one Draco
//! stream in a buffer view, its accessors left without data. The stream is decoded by
//! `draco-core` (a pure-Rust decoder whose output matches Google's Draco 1.5), and each glTF
//! attribute is the Draco attribute of the unique id the extension names, read in point order
//! and converted as its accessor says (normalized integers to [0, 1] or [−1, 1]).

use std::collections::HashMap;

use draco_core::{DataType, DecoderBuffer, FaceIndex, Mesh, MeshDecoder};

use super::Loader;
use crate::error::Result;

/// A decoded Draco primitive: its mesh and, per glTF attribute name, its Draco unique id.
pub(super) struct Draco {
    mesh: Mesh,
    ids: HashMap<String, u32>,
}

impl Loader<'_> {
    /// The decoded Draco stream of `prim` (named `what` in errors), or `None` when the
    /// primitive is not compressed. A stream that cannot be decoded refuses the file by name.
    pub(super) fn draco(&self, prim: &gltf::Primitive, what: &str) -> Result<Option<Draco>> {
        let Some(ext) = prim.extension_value("KHR_draco_mesh_compression") else {
            return Ok(None);
        };
        let err = |m: String| self.err(format!("{what}: KHR_draco_mesh_compression {m}"));
        let view = ext
            .get("bufferView")
            .and_then(serde_json::Value::as_u64)
            .and_then(|v| self.doc.views().nth(v as usize))
            .ok_or_else(|| err("names no buffer view that exists".into()))?;
        let bytes = self.buffers[view.buffer().index()]
            .get(view.offset()..view.offset() + view.length())
            .ok_or_else(|| err(format!("buffer view {} is out of bounds", view.index())))?;
        let ids = ext
            .get("attributes")
            .and_then(serde_json::Value::as_object)
            .ok_or_else(|| err("has no attributes".into()))?
            .iter()
            .map(|(k, v)| Some((k.clone(), u32::try_from(v.as_u64()?).ok()?)))
            .collect::<Option<HashMap<_, _>>>()
            .ok_or_else(|| err("has an attribute id that is not a number".into()))?;
        let mut mesh = Mesh::new();
        MeshDecoder::new()
            .decode(&mut DecoderBuffer::new(bytes), &mut mesh)
            .map_err(|e| err(format!("could not be decoded: {e}")))?;
        if mesh.num_faces() == 0 {
            return Err(err("decodes to no triangles".into()));
        }
        Ok(Some(Draco { mesh, ids }))
    }
}

impl Draco {
    /// How many vertices (Draco points) the primitive has.
    pub(super) fn count(&self) -> usize {
        self.mesh.num_points()
    }

    /// The triangles' vertex indices, as a triangle list.
    pub(super) fn indices(&self) -> Vec<u32> {
        (0..self.mesh.num_faces() as u32)
            .flat_map(|f| self.mesh.face(FaceIndex(f)).map(|p| p.0))
            .collect()
    }

    /// The values of glTF attribute `name` as `N` floats per vertex (`normalized`: integers
    /// mapped as glTF's normalized accessors are), or `None` when the stream does not carry it
    /// (an error names an id the stream lacks).
    pub(super) fn attribute<const N: usize>(
        &self,
        name: &str,
        normalized: bool,
    ) -> Option<std::result::Result<Vec<[f32; N]>, String>> {
        let id = *self.ids.get(name)?;
        let found = (0..self.mesh.num_attributes())
            .map(|k| self.mesh.attribute(k))
            .find(|a| a.unique_id() == id);
        let Some(a) = found else {
            return Some(Err(format!(
                "names Draco attribute {id} for {name}, which the stream does not have"
            )));
        };
        let n = self.count();
        let scale = match (normalized, a.data_type()) {
            (true, DataType::Int8) => Some((127.0, true)),
            (true, DataType::Uint8) => Some((255.0, false)),
            (true, DataType::Int16) => Some((32767.0, true)),
            (true, DataType::Uint16) => Some((65535.0, false)),
            (true, DataType::Uint32) => Some((4_294_967_295.0, false)),
            _ => None,
        };
        let flat = a.read_f32s(n, N);
        let rows = flat
            .chunks_exact(N)
            .map(|c| {
                std::array::from_fn(|k| match scale {
                    Some((s, signed)) if signed => (c[k] / s).max(-1.0),
                    Some((s, _)) => c[k] / s,
                    None => c[k],
                })
            })
            .collect();
        Some(Ok(rows))
    }
}
