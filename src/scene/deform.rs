//! Deforming meshes: a scene whose every vertex moved (cloth, a soft body, a deforming scan),
//! its faces, objects and materials unchanged. Its BVH is not built again: it is refit from the
//! object trees of the scene it deforms (`trace::refit`, Wald et al. 2007 §4), unless the refit
//! tree would trace too slowly (`trace::bvh`: a surface-area cost past
//! [`crate::trace::REFIT_LIMIT`] times the rest pose's), when it is built afresh.

use std::sync::Arc;

use rayon::prelude::*;

use super::{Scene, SceneParts};
use crate::error::Result;
use crate::input_err;

impl Scene {
    /// This scene with its vertices at `vertices` (one per vertex of this scene, finite), and
    /// per-vertex `normals` if given (else none: normals that came with the scene no longer fit
    /// it). Faces, their ids and colours, objects, materials, lights and cameras stay; the
    /// result has no animations (its vertices are the caller's) and is not posed.
    pub fn deformed(
        self: &Arc<Self>,
        vertices: Vec<[f32; 3]>,
        normals: Option<Vec<[f32; 3]>>,
    ) -> Result<Scene> {
        let n = self.vertices().len();
        if vertices.len() != n {
            return input_err!(
                "deformed needs one position per vertex of the scene: {n}, got {}",
                vertices.len()
            );
        }
        if let Some(i) = first_not_finite(&vertices) {
            return input_err!("deformed vertex {i} is not finite: {:?}", vertices[i]);
        }
        if let Some(ns) = &normals {
            if ns.len() != n {
                return input_err!(
                    "deformed normals need one per vertex of the scene: {n}, got {}",
                    ns.len()
                );
            }
            if let Some(i) = first_not_finite(ns) {
                return input_err!("deformed normal {i} is not finite: {:?}", ns[i]);
            }
            // A zero normal has no direction to shade with.
            if let Some(i) = ns.iter().position(|v| *v == [0.0; 3]) {
                return input_err!("deformed normal {i} is zero; normals need a direction");
            }
        }
        let parts = SceneParts {
            vertices,
            normals,
            materials: self.parts.materials.clone(),
            objects: self.parts.objects.clone(),
            lights: self.parts.lights.clone(),
            cameras: self.parts.cameras.clone(),
            ..Default::default()
        };
        let mut out = Scene::assemble(parts, self.shared.clone(), None);
        out.refit_from = Some(self.tree_source());
        Ok(out)
    }

    /// The scene as loaded whose object trees this scene's BVH can be refit from: the base of a
    /// pose, the source of a deformation, or the scene itself.
    pub fn tree_source(self: &Arc<Self>) -> Arc<Scene> {
        match (&self.pose, &self.refit_from) {
            (Some(p), _) => p.base.clone(),
            (None, Some(s)) => s.clone(),
            (None, None) => self.clone(),
        }
    }

    /// The scene this deformed scene's BVH is refit from (`None` for any other scene).
    pub fn refit_from(&self) -> Option<&Arc<Scene>> {
        self.refit_from.as_ref()
    }
}

/// The first row of `rows` with a coordinate that is not finite: chunks checked in parallel,
/// each with a loop the compiler vectorises, and the first bad chunk searched row by row.
fn first_not_finite(rows: &[[f32; 3]]) -> Option<usize> {
    const CHUNK: usize = 1 << 15;
    let bad = rows
        .par_chunks(CHUNK)
        .map(|c| {
            !c.as_flattened()
                .iter()
                .fold(true, |ok, x| ok & x.is_finite())
        })
        .collect::<Vec<bool>>()
        .iter()
        .position(|&b| b)?;
    let at = bad * CHUNK;
    rows[at..]
        .iter()
        .position(|v| v.iter().any(|x| !x.is_finite()))
        .map(|i| at + i)
}
