//! Skins and morph targets read from a glTF file into [`Rigging`] (glTF 2.0 §3.7.2.2 and
//! §3.7.3), and a deformable object's vertices placed in its rest pose: morphed by its default
//! weights, then skinned by its joints as loaded (or placed by its node without a skin).

use std::collections::HashMap;

use glam::DMat4;
use gltf::accessor::{DataType, Dimensions};

use super::accessors::{NORMAL_TYPES, POSITION_TYPES};
use super::draco::Draco;
use super::primitives::Vertices;
use super::Loader;
use crate::error::Result;
use crate::scene::skin::{Deformable, Place, Skin};

impl Loader<'_> {
    /// What moves the vertices of `mesh` under `node` (object `object`, whose vertices start at
    /// `first`): `None` when it has neither a skin nor morph targets. Its per-vertex data is
    /// empty until [`Loader::add_primitive`] reads each primitive.
    pub(super) fn deformation(
        &mut self,
        mesh: &gltf::Mesh,
        node: &gltf::Node,
        instance: DMat4,
        object: usize,
    ) -> Result<Option<Deformable>> {
        let targets = mesh
            .primitives()
            .map(|p| p.morph_targets().len())
            .max()
            .unwrap_or(0);
        let skin = match node.skin() {
            Some(_) if instance != DMat4::IDENTITY => {
                self.warn(format!(
                    "node {}: a skin under EXT_mesh_gpu_instancing is not applied; the \
                     instances are placed by their node",
                    node.index()
                ));
                None
            }
            Some(s) => Some(self.skin(&s)?),
            None => None,
        };
        if skin.is_none() && targets == 0 {
            return Ok(None);
        }
        let given = node.weights().or(mesh.weights()).unwrap_or(&[]);
        if !given.is_empty() && given.len() != targets {
            self.warn(format!(
                "mesh {}: {} default morph weights for {targets} targets; the missing ones are 0",
                mesh.index(),
                given.len()
            ));
        }
        let mut weights: Vec<f64> = given.iter().map(|&w| f64::from(w)).collect();
        weights.resize(targets, 0.0);
        if let Some(k) = weights.iter().position(|w| !w.is_finite()) {
            return Err(self.err(format!(
                "node {}: morph weight {k} is not finite",
                node.index()
            )));
        }
        Ok(Some(Deformable {
            object,
            node: node.index(),
            first: self.parts.vertices.len(),
            base: Vec::new(),
            targets: vec![Vec::new(); targets],
            normals: Vec::new(),
            normal_targets: vec![Vec::new(); targets],
            weights,
            skin,
            joints: Vec::new(),
            joint_weights: Vec::new(),
            influences: 0,
            instance,
        }))
    }

    /// Skin `skin` in `self.rigging` (read on its first use): its joints and inverse bind
    /// matrices, checked.
    fn skin(&mut self, skin: &gltf::Skin) -> Result<usize> {
        if let Some(&k) = self.skin_index.get(&skin.index()) {
            return Ok(k);
        }
        let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
        let what = format!("skin {}", skin.index());
        if joints.is_empty() {
            return Err(self.err(format!("{what} has no joints")));
        }
        let inverse_bind = match skin.inverse_bind_matrices() {
            None => vec![DMat4::IDENTITY; joints.len()],
            Some(acc) => {
                let what = format!("{what} inverseBindMatrices");
                self.check_accessor(&acc, &what, &[Dimensions::Mat4], &[DataType::F32])?;
                let buffers = &self.buffers;
                let reader = skin.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
                let ms: Vec<DMat4> = reader
                    .read_inverse_bind_matrices()
                    .ok_or_else(|| self.err(format!("{what} could not be read")))?
                    .map(|m| DMat4::from_cols_array_2d(&m.map(|c| c.map(f64::from))))
                    .collect();
                if ms.len() != joints.len() {
                    return Err(self.err(format!(
                        "{what}: {} matrices for {} joints",
                        ms.len(),
                        joints.len()
                    )));
                }
                if let Some(k) = ms.iter().position(|m| !m.is_finite()) {
                    return Err(self.err(format!("{what}: matrix {k} is not finite")));
                }
                ms
            }
        };
        self.rigging.skins.push(Skin {
            joints,
            inverse_bind,
        });
        let k = self.rigging.skins.len() - 1;
        self.skin_index.insert(skin.index(), k);
        Ok(k)
    }

    /// Primitive `prim`'s share of `d`: its mesh-space positions and normals (`v`), each morph
    /// target's POSITION and NORMAL displacements (zero where the target has none), and with a
    /// skin its JOINTS_n / WEIGHTS_n sets, checked (a weight that is not finite, or a joint past
    /// the skin's with a weight, refuses the file).
    pub(super) fn add_primitive(
        &mut self,
        d: &mut Deformable,
        prim: &gltf::Primitive,
        what: &str,
        v: &Vertices,
    ) -> Result<()> {
        let n = v.positions.len();
        for (k, target) in prim.morph_targets().enumerate() {
            let read = |acc: Option<gltf::Accessor>, name: &str, types| match acc {
                None => Ok(vec![[0.0; 3]; n]),
                Some(acc) => {
                    let what = format!("{what} morph target {k} {name}");
                    let deltas = self.vectors(&acc, &what, Dimensions::Vec3, types)?;
                    if deltas.len() != n {
                        return Err(self.err(format!(
                            "{what}: {} displacements for {n} vertices",
                            deltas.len()
                        )));
                    }
                    Ok(deltas)
                }
            };
            let moves = read(target.positions(), "POSITION", POSITION_TYPES)?;
            let turns = read(target.normals(), "NORMAL", NORMAL_TYPES)?;
            d.targets[k].extend(moves);
            d.normal_targets[k].extend(turns);
        }
        // Targets this primitive lacks (its mesh's others have more) displace nothing.
        for t in d.targets.iter_mut().chain(d.normal_targets.iter_mut()) {
            t.resize(d.base.len() + n, [0.0; 3]);
        }
        match &v.normals {
            Some(ns) => d.normals.extend_from_slice(ns),
            None => d.normals.resize(d.base.len() + n, [0.0; 3]),
        }
        if let Some(s) = d.skin {
            let count = self.rigging.skins[s].joints.len();
            let (joints, weights, sets) =
                self.influences(prim, v.draco.as_ref(), what, n, count)?;
            let width = 4 * sets;
            if width > d.influences {
                pad(&mut d.joints, d.influences, width);
                pad(&mut d.joint_weights, d.influences, width);
                d.influences = width;
            }
            for i in 0..n {
                for k in 0..d.influences {
                    let inside = k < width;
                    d.joints
                        .push(if inside { joints[i * width + k] } else { 0 });
                    d.joint_weights
                        .push(if inside { weights[i * width + k] } else { 0.0 });
                }
            }
        }
        d.base.extend_from_slice(&v.positions);
        Ok(())
    }

    /// The JOINTS_n / WEIGHTS_n sets of `prim` (`n` vertices, a skin of `count` joints):
    /// joints and weights, `4 × sets` per vertex. A vertex whose weights sum to 0 follows its
    /// first joint (a warning counts them).
    fn influences(
        &mut self,
        prim: &gltf::Primitive,
        draco: Option<&Draco>,
        what: &str,
        n: usize,
        count: usize,
    ) -> Result<(Vec<u16>, Vec<f32>, usize)> {
        let mut sets = 0;
        while prim.get(&gltf::Semantic::Joints(sets as u32)).is_some() {
            sets += 1;
        }
        if sets == 0 {
            return Err(self.err(format!("{what} is skinned but has no JOINTS_0")));
        }
        let width = 4 * sets;
        let mut joints = vec![0u16; n * width];
        let mut weights = vec![0f32; n * width];
        let buffers = &self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        for set in 0..sets {
            let j_what = format!("{what} JOINTS_{set}");
            let w_what = format!("{what} WEIGHTS_{set}");
            let (Some(ja), Some(wa)) = (
                prim.get(&gltf::Semantic::Joints(set as u32)),
                prim.get(&gltf::Semantic::Weights(set as u32)),
            ) else {
                return Err(self.err(format!("{j_what} has no matching WEIGHTS_{set}")));
            };
            let types = [DataType::U8, DataType::U16];
            self.check_accessor(&ja, &j_what, &[Dimensions::Vec4], &types)?;
            let types = [DataType::F32, DataType::U8, DataType::U16];
            self.check_accessor(&wa, &w_what, &[Dimensions::Vec4], &types)?;
            let decoded = |name: &str, normalized: bool| {
                draco.and_then(|d| d.attribute::<4>(name, normalized))
            };
            let js: Vec<[u16; 4]> = match decoded(&format!("JOINTS_{set}"), false) {
                Some(rows) => rows
                    .map_err(|m| self.err(format!("{j_what}: {m}")))?
                    .into_iter()
                    .map(|j| j.map(|x| x.clamp(0.0, 65535.0) as u16))
                    .collect(),
                None => reader
                    .read_joints(set as u32)
                    .ok_or_else(|| self.err(format!("{j_what} could not be read")))?
                    .into_u16()
                    .collect(),
            };
            let ws: Vec<[f32; 4]> = match decoded(&format!("WEIGHTS_{set}"), wa.normalized()) {
                Some(rows) => rows.map_err(|m| self.err(format!("{w_what}: {m}")))?,
                None => reader
                    .read_weights(set as u32)
                    .ok_or_else(|| self.err(format!("{w_what} could not be read")))?
                    .into_f32()
                    .collect(),
            };
            if js.len() != n || ws.len() != n {
                return Err(self.err(format!(
                    "{what}: JOINTS_{set} and WEIGHTS_{set} have {} and {} entries for {n} vertices",
                    js.len(),
                    ws.len()
                )));
            }
            for (i, (j, w)) in js.iter().zip(&ws).enumerate() {
                for k in 0..4 {
                    if !w[k].is_finite() || w[k] < 0.0 {
                        return Err(self.err(format!(
                            "{w_what}: vertex {i} has weight {} (weights are finite and not negative)",
                            w[k]
                        )));
                    }
                    if w[k] != 0.0 && usize::from(j[k]) >= count {
                        return Err(self.err(format!(
                            "{j_what}: vertex {i} names joint {} of a skin with {count}",
                            j[k]
                        )));
                    }
                    let at = i * width + 4 * set + k;
                    joints[at] = if w[k] != 0.0 { j[k] } else { 0 };
                    weights[at] = w[k];
                }
            }
        }
        let mut unweighted = 0;
        for i in 0..n {
            let ws = &mut weights[i * width..(i + 1) * width];
            if ws.iter().all(|&w| w == 0.0) {
                ws[0] = 1.0;
                unweighted += 1;
            }
        }
        if unweighted > 0 {
            self.warn(format!(
                "{what}: {unweighted} vertices have skin weights that sum to 0; each follows its \
                 first joint"
            ));
        }
        Ok((joints, weights, sets))
    }

    /// `d` placed in its rest pose: its vertices (the last `d.base.len()` of the scene's) are
    /// morphed by its default weights and skinned by its joints as loaded (or placed by its
    /// node and instance), and `d` joins the rigging.
    pub(super) fn place_deformable(&mut self, d: Deformable) {
        let mats = d.skin.map(|s| {
            let skin = &self.rigging.skins[s];
            skin.matrices(skin.joints.iter().map(|&j| self.rest[j]))
        });
        let place = match &mats {
            Some(m) => Place::Joints(m),
            None => Place::Node(self.rest[d.node] * d.instance),
        };
        let moved = d.place(&d.weights, &place);
        for (v, p) in self.parts.vertices[d.first..]
            .iter_mut()
            .zip(moved.positions)
        {
            *v = p.as_vec3().to_array();
        }
        if let Some(normals) = self.parts.normals.as_mut() {
            normals[d.first..d.first + moved.normals.len()].copy_from_slice(&moved.normals);
        }
        self.rigging.deformables.push(d);
    }
}

/// Rows of `from` numbers widened to `to`, zero-filled (for a primitive with more JOINTS_n
/// sets than the mesh's earlier ones).
fn pad<T: Copy + Default>(rows: &mut Vec<T>, from: usize, to: usize) {
    if from == 0 {
        return;
    }
    let old = std::mem::take(rows);
    for row in old.chunks_exact(from) {
        rows.extend_from_slice(row);
        rows.extend(std::iter::repeat_n(T::default(), to - from));
    }
}

/// The skins read so far, keyed by their index in the file.
pub(super) type SkinIndex = HashMap<usize, usize>;
