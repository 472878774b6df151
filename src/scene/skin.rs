//! Skins and morph targets, the two ways a glTF file moves a mesh's vertices rather than its
//! node: morph targets (glTF 2.0 §3.7.2.2) add weighted displacements to the base positions,
//! and a skin (§3.7.3) then blends its joints' matrices per vertex (linear blend skinning: a
//! vertex goes to `Σ_k w_k · W(joint_k) · IBM_k · p`, with `W` a joint's world transform and
//! `IBM` its inverse bind matrix). The skinned mesh's own node transform is ignored, as the
//! spec says. Everything is evaluated in f64 and rounded once to f32.

use glam::{DMat3, DMat4, DVec3};
use rayon::prelude::*;

/// A skin: its joints (node indices) and each joint's inverse bind matrix (the identity when
/// the file gives none).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Skin {
    pub joints: Vec<usize>,
    pub inverse_bind: Vec<DMat4>,
}

/// How `m` moves normals: the inverse transpose of its linear part; where that is singular (a
/// zero scale), its cofactor matrix (the inverse transpose times the determinant, which exists
/// for every matrix): a flattened object's normals then point across its plane, and a hidden
/// one's are 0 (normalised later, where they are not 0).
pub fn normal_map(m: &DMat4) -> DMat3 {
    let l = DMat3::from_mat4(*m);
    let inverse = l.inverse();
    if l.determinant() != 0.0 && inverse.is_finite() {
        return inverse.transpose();
    }
    let (x, y, z) = (l.x_axis, l.y_axis, l.z_axis);
    DMat3::from_cols(y.cross(z), z.cross(x), x.cross(y))
}

/// An object whose vertices morph targets or a skin move.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Deformable {
    /// The object, and its node.
    pub object: usize,
    pub node: usize,
    /// Its vertices are the scene's `first..first + base.len()`.
    pub first: usize,
    /// Positions in the mesh's own space: the POSITION attributes of its primitives, in order.
    pub base: Vec<[f32; 3]>,
    /// Per morph target, per vertex, its POSITION displacement (zero where a primitive's
    /// target has none).
    pub targets: Vec<Vec<[f32; 3]>>,
    /// Normals in the mesh's own space: the NORMAL attributes of its primitives, in order (a
    /// zero row where a primitive has none: shading then uses area-weighted normals).
    pub normals: Vec<[f32; 3]>,
    /// Per morph target, per vertex, its NORMAL displacement (zero where it has none).
    pub normal_targets: Vec<Vec<[f32; 3]>>,
    /// The weights where no clip keys them: the node's `weights`, else the mesh's, else 0.
    pub weights: Vec<f64>,
    /// The skin (an index into [`Rigging::skins`]), or `None`: the node's world transform
    /// (times `instance`) places the morphed mesh.
    pub skin: Option<usize>,
    /// Per vertex, `influences` joints (indices into the skin's joints) and their weights: the
    /// JOINTS_n / WEIGHTS_n sets, four per set.
    pub joints: Vec<u16>,
    pub joint_weights: Vec<f32>,
    pub influences: usize,
    /// The `EXT_mesh_gpu_instancing` transform under the node (identity without one).
    pub instance: DMat4,
}

/// Where a deformable object's morphed vertices go: by its node's world transform (times its
/// instance's), or by its skin's joint matrices (`W(joint) · IBM`, one per joint).
pub enum Place<'a> {
    Node(DMat4),
    Joints(&'a [DMat4]),
}

/// The skins and deformable objects of a scene.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Rigging {
    pub skins: Vec<Skin>,
    pub deformables: Vec<Deformable>,
}

/// Every node's world transform from each node's parent and local transform (a node with no
/// parent is a root; a parent chain that loops ends where it would repeat). The products go
/// from the root down, `((root · a) · b) · c`, as the loader places meshes.
pub fn worlds(parents: &[Option<usize>], locals: &[DMat4]) -> Vec<DMat4> {
    let mut out: Vec<Option<DMat4>> = vec![None; locals.len()];
    for i in 0..locals.len() {
        // The chain from node i up to a node already placed, a root, or a loop.
        let mut chain = Vec::new();
        let mut above = DMat4::IDENTITY;
        let mut k = Some(i);
        while let Some(j) = k {
            if let Some(w) = out[j] {
                above = w;
                break;
            }
            if chain.contains(&j) {
                break;
            }
            chain.push(j);
            k = parents[j];
        }
        for &j in chain.iter().rev() {
            above *= locals[j];
            out[j] = Some(above);
        }
    }
    out.into_iter()
        .map(|w| w.unwrap_or(DMat4::IDENTITY))
        .collect()
}

impl Skin {
    /// Each joint's matrix `W(joint) · IBM`, from `worlds`, its joints' world transforms in
    /// the order of `joints`.
    pub fn matrices(&self, worlds: impl IntoIterator<Item = DMat4>) -> Vec<DMat4> {
        worlds
            .into_iter()
            .zip(&self.inverse_bind)
            .map(|(w, ibm)| w * *ibm)
            .collect()
    }
}

/// A deformable object's vertices in world space, and their unit normals (zero where the
/// object has none).
#[derive(Debug, Clone)]
pub struct Posed {
    pub positions: Vec<DVec3>,
    pub normals: Vec<[f32; 3]>,
}

impl Deformable {
    /// Its vertices and normals in world space with morph target `weights` (one per target;
    /// missing ones are 0) placed by `place`: positions by the node's or the blended joints'
    /// matrix, normals (morphed by the targets' NORMAL displacements) by its inverse
    /// transpose ([`normal_map`]), normalized.
    pub fn place(&self, weights: &[f64], place: &Place) -> Posed {
        let active = |targets: &'_ [Vec<[f32; 3]>]| -> Vec<(f64, usize)> {
            weights
                .iter()
                .enumerate()
                .filter(|(k, w)| **w != 0.0 && targets.get(*k).is_some_and(|t| !t.is_empty()))
                .map(|(k, w)| (*w, k))
                .collect()
        };
        let (moving, turning) = (active(&self.targets), active(&self.normal_targets));
        let node_normals = match place {
            Place::Node(m) => Some(normal_map(m)),
            Place::Joints(_) => None,
        };
        let m = self.influences;
        let (positions, normals) = (0..self.base.len())
            .into_par_iter()
            .with_min_len(4096)
            .map(|i| {
                let mut p = DVec3::from(self.base[i].map(f64::from));
                for &(w, k) in &moving {
                    p += w * DVec3::from(self.targets[k][i].map(f64::from));
                }
                let mut n = DVec3::from(self.normals.get(i).map_or([0.0; 3], |n| n.map(f64::from)));
                if n != DVec3::ZERO {
                    for &(w, k) in &turning {
                        n += w * DVec3::from(self.normal_targets[k][i].map(f64::from));
                    }
                }
                let (p, n) = match place {
                    Place::Node(m) => (m.transform_point3(p), node_normals.unwrap() * n),
                    Place::Joints(mats) => {
                        let js = &self.joints[i * m..(i + 1) * m];
                        let ws = &self.joint_weights[i * m..(i + 1) * m];
                        let mut blend = DMat4::ZERO;
                        for (&j, &w) in js.iter().zip(ws) {
                            if w != 0.0 {
                                blend += mats[usize::from(j)] * f64::from(w);
                            }
                        }
                        let to_world = normal_map(&blend);
                        (blend.transform_point3(p), to_world * n)
                    }
                };
                (p, n.normalize_or_zero().as_vec3().to_array())
            })
            .unzip();
        Posed { positions, normals }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn worlds_compose_from_the_root_and_survive_a_loop() {
        let t = |x: f64| DMat4::from_translation(DVec3::new(x, 0.0, 0.0));
        let w = worlds(&[None, Some(0), Some(1)], &[t(1.0), t(2.0), t(4.0)]);
        assert_eq!(w[2].w_axis.x, 7.0);
        assert_eq!(w[1].w_axis.x, 3.0);
        // 0 -> 1 -> 0: no hang, finite transforms.
        let w = worlds(&[Some(1), Some(0)], &[t(1.0), t(2.0)]);
        assert!(w.iter().all(|m| m.is_finite()));
    }

    #[test]
    fn morph_then_blend_two_joints() {
        let d = Deformable {
            object: 0,
            node: 0,
            first: 0,
            base: vec![[1.0, 0.0, 0.0]],
            targets: vec![vec![[0.0, 2.0, 0.0]]],
            normals: vec![[1.0, 0.0, 0.0]],
            normal_targets: vec![vec![[0.0, 1.0, 0.0]]],
            weights: vec![0.0],
            skin: Some(0),
            joints: vec![0, 1, 0, 0],
            joint_weights: vec![0.25, 0.75, 0.0, 0.0],
            influences: 4,
            instance: DMat4::IDENTITY,
        };
        let mats = [
            DMat4::IDENTITY,
            DMat4::from_translation(DVec3::new(0.0, 0.0, 4.0)),
        ];
        let p = d.place(&[0.5], &Place::Joints(&mats));
        assert_eq!(p.positions[0], DVec3::new(1.0, 1.0, 3.0));
        // The normal (1, 0, 0) + 0.5 (0, 1, 0), blended by translations: only normalized.
        let expect = DVec3::new(1.0, 0.5, 0.0).normalize();
        let got = DVec3::from(p.normals[0].map(f64::from));
        assert!((got - expect).length() < 1e-6, "{:?}", p.normals);
        let p = d.place(
            &[],
            &Place::Node(DMat4::from_scale(DVec3::new(2.0, 1.0, 1.0))),
        );
        assert_eq!(p.positions[0], DVec3::new(2.0, 0.0, 0.0));
        // A stretch along x leaves a normal along x pointing along x.
        assert_eq!(p.normals[0], [1.0, 0.0, 0.0]);
    }
}
