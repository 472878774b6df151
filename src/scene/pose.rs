//! Poses: a scene's objects moved by one affine transform each, without rebuilding what does
//! not change. A posed scene is an ordinary [`Scene`] (every query works on it unchanged) whose
//! faces, ids and colours are its base scene's, shared, and which remembers its base and the
//! transforms, so that the rooms that derive structures from a scene (the BVH) can derive
//! them from the base's by a refit instead of a rebuild.
//!
//! Each transform maps the object's vertices *as loaded* to their new place; posing a posed
//! scene poses its base again. Triangle ids stay the faces' indices.

use std::sync::Arc;

use glam::{DMat3, DMat4, DVec3};
use rayon::prelude::*;

use super::animation::ClipKey;
use super::skin::{normal_map, Posed};
use super::{MakeWorld, Scene, SceneParts, Shared, VerticesAndNormals};
use crate::error::Result;
use crate::input_err;

/// Where a posed scene comes from.
#[derive(Debug, Clone)]
pub struct Pose {
    /// The scene as loaded (never itself posed).
    pub base: Arc<Scene>,
    /// One per object of `base`.
    pub transforms: Arc<Vec<DMat4>>,
    /// Whether the faces of mirrored objects were wound the other way (`Scene::at`).
    pub rewinds: bool,
    /// A user's pose that a clip's pose was composed with (`posed(T).at(t)`: object `o` at
    /// `T[o] · A_t[o]`), kept so that the next `at` composes with it too; `None` otherwise.
    pub after: Option<Arc<Vec<DMat4>>>,
    /// Whether some vertices are not their object's transform of the base's: a clip's skins
    /// or morph targets moved them (`Scene::at`), or they were given (`Scene::posed_again`).
    /// The BVH of such a pose is refit as a deformed scene's is ([`Scene::deformed`]).
    pub deforms: bool,
}

/// The vertices of a pose besides its transforms: none, the objects a clip's skins or morph
/// targets moved (each object, its first vertex, and its vertices and normals in world space
/// before the user's pose), or every vertex (a pose made again from its vertices, with their
/// normals when it has them).
enum Moved<'a> {
    Rigid,
    Objects(&'a [(usize, usize, Posed)]),
    All(Vec<[f32; 3]>, Option<Vec<[f32; 3]>>),
}

/// What posing needs from a scene as loaded, built once per scene: each vertex's object, and
/// the vertices (with their normals and colours) and faces after every vertex that faces of
/// two objects share is split, one copy per object (the copies are appended, so vertices
/// that no two objects share keep their indices).
#[derive(Debug)]
pub struct Rig {
    pub(crate) shared: Arc<Shared>,
    pub vertices: Vec<[f32; 3]>,
    pub normals: Option<Vec<[f32; 3]>>,
    /// Per vertex its object, `u32::MAX` for a vertex no face uses.
    pub vertex_object: Vec<u32>,
}

impl Rig {
    fn of(scene: &Scene) -> Self {
        let n = scene.vertices().len();
        let mut vertices = scene.vertices().to_vec();
        let mut normals = scene.normals().map(<[_]>::to_vec);
        let mut colors = scene.colors().to_vec();
        let mut texcoords = scene.texcoords().map(<[_]>::to_vec);
        let mut vertex_object = vec![u32::MAX; n];
        let mut copies: std::collections::HashMap<(u32, u32), u32> = Default::default();
        let mut faces = scene.faces().to_vec();
        for (f, &o) in faces.iter_mut().zip(scene.object_ids()) {
            let o = o as u32;
            for k in f.iter_mut() {
                let owner = &mut vertex_object[*k as usize];
                if *owner == u32::MAX || *owner == o {
                    *owner = o;
                    continue;
                }
                let v = *k as usize;
                *k = *copies.entry((*k, o)).or_insert_with(|| {
                    vertices.push(vertices[v]);
                    if let Some(nr) = normals.as_mut() {
                        nr.push(nr[v]);
                    }
                    colors.push(colors[v]);
                    if let Some(uv) = texcoords.as_mut() {
                        uv.push(uv[v]);
                    }
                    vertex_object.push(o);
                    (vertices.len() - 1) as u32
                });
            }
        }
        Rig {
            shared: Arc::new(Shared {
                faces,
                material_ids: scene.material_ids().to_vec(),
                object_ids: scene.object_ids().to_vec(),
                colors,
                texcoords,
                textures: scene.textures().to_vec(),
                used: Default::default(),
            }),
            vertices,
            normals,
            vertex_object,
        }
    }

    pub fn faces(&self) -> &[[u32; 3]] {
        &self.shared.faces
    }
}

/// `p` moved by `m` (affine), in f64 and rounded once to f32: the one rounding a posed
/// vertex goes through (the BVH's triangle corners are gathered from the posed vertices).
#[inline(always)]
pub(crate) fn transform_point(m: &DMat4, p: [f32; 3]) -> [f32; 3] {
    let [x, y, z] = p.map(f64::from);
    let c = m.to_cols_array();
    std::array::from_fn(|a| (c[a] * x + c[4 + a] * y + c[8 + a] * z + c[12 + a]) as f32)
}

/// Check that `m` is finite and affine (its last row 0, 0, 0, 1).
pub fn check_affine(m: &DMat4, what: &str) -> Result<()> {
    if !m.is_finite() {
        return input_err!("the transform of {what} is not finite");
    }
    if m.row(3) != glam::DVec4::W {
        return input_err!(
            "the transform of {what} is not affine: its last row is {:?}, not [0, 0, 0, 1]",
            m.row(3).to_array()
        );
    }
    Ok(())
}

/// Whether `m`'s linear part is singular: its determinant within 1e-12 of the product of its
/// columns' lengths, or NaN or infinite, or a column zero.
pub(crate) fn singular(m: &DMat4) -> bool {
    let l = DMat3::from_mat4(*m);
    let scale = l.x_axis.length() * l.y_axis.length() * l.z_axis.length();
    let det = l.determinant();
    !matches!(
        det.abs().partial_cmp(&(1e-12 * scale)),
        Some(std::cmp::Ordering::Greater)
    ) || scale == 0.0
}

/// Check that `m` is a finite, non-singular affine transform (its last row 0, 0, 0, 1).
pub fn check_transform(m: &DMat4, what: &str) -> Result<()> {
    check_affine(m, what)?;
    if singular(m) {
        let l = DMat3::from_mat4(*m);
        return input_err!(
            "the transform of {what} is singular (determinant {})",
            l.determinant()
        );
    }
    Ok(())
}

impl Scene {
    /// The scene posed from, and each object's transform (`None` for a scene as loaded).
    pub fn pose(&self) -> Option<&Pose> {
        self.pose.as_ref()
    }

    /// The scene's animations (node hierarchy, clips, rigging), if it has any.
    pub fn animations_data(&self) -> Option<&Arc<super::animation::Animations>> {
        self.parts.animations.as_ref()
    }

    /// The scene's animation clips as (name, duration in seconds); empty without any.
    pub fn animations(&self) -> Vec<(String, f64)> {
        let clips = self.parts.animations.as_ref().map(|a| a.clips.as_slice());
        clips
            .unwrap_or_default()
            .iter()
            .map(|c| (c.name.clone(), c.duration))
            .collect()
    }

    /// The scene posed at `t` seconds into the animation clips `clips` (indices or names,
    /// played together; `t` clamped to each clip; where two key the same property of a node, the
    /// later one in `clips` wins). On a scene a user posed, the clips move each object first
    /// and the pose after (object `o` at `T[o] · A_t[o]`); a clip's pose of such a scene keeps
    /// the user's pose for its next `at`.
    pub fn at(self: &Arc<Self>, t: f64, clips: &[ClipKey]) -> Result<Scene> {
        let Some(a) = &self.parts.animations else {
            return input_err!("the scene has no animations");
        };
        if clips.is_empty() {
            return input_err!("at needs at least one animation clip");
        }
        let indices = clips
            .iter()
            .map(|&c| a.clip(c))
            .collect::<Result<Vec<_>>>()?;
        let mut at = a.at_clips(&indices, t)?;
        let after = match &self.pose {
            Some(p) if !p.rewinds => Some(p.transforms.clone()),
            Some(p) => p.after.clone(),
            None => None,
        };
        if let Some(user) = &after {
            for (m, u) in at.objects.iter_mut().zip(user.iter()) {
                *m = *u * *m;
            }
        }
        // Lights and cameras on animated nodes go where their nodes are at `t`; a camera's
        // pose keeps only the node's rotation and translation, as at load. Winding follows the
        // sign of each node's world determinant (glTF 2.0 §3.7.4), as at load.
        self.posed_with(
            &at.objects,
            true,
            after,
            Moved::Objects(&at.deformed),
            |parts| {
                for (light, w) in parts.lights.iter_mut().zip(&at.lights) {
                    if let Some(w) = w {
                        light.place(w);
                    }
                }
                for (camera, w) in parts.cameras.iter_mut().zip(&at.cameras) {
                    if let Some(w) = w {
                        camera.pose = crate::camera::rigid_from(*w);
                    }
                }
            },
        )
    }

    /// Every key time of animation `clip`, ascending, each once.
    pub fn key_times(&self, clip: ClipKey) -> Result<Vec<f64>> {
        let Some(a) = &self.parts.animations else {
            return input_err!("the scene has no animations");
        };
        a.key_times(a.clip(clip)?)
    }

    /// What posing `self` (a scene as loaded) needs, built on first use.
    pub fn rig(&self) -> Arc<Rig> {
        self.derived(|| Rig::of(self))
    }

    /// This scene's objects moved: object `o`'s vertices as loaded are mapped by
    /// `transforms[o]` (one per object, finite, affine and non-singular). Normals follow by the
    /// inverse transpose. The faces, ids, colours, materials and lights are shared with the
    /// scene as loaded; a vertex that faces of two objects share is split into one per object.
    /// The pose is O(objects): its vertices, normals, bounds and degenerate triangles are made
    /// on first use (its rays need none of them: they run on a two-level tree, `trace::instances`),
    /// once each objects' box is checked to stay within float32's range.
    pub fn posed(self: &Arc<Self>, transforms: &[DMat4]) -> Result<Scene> {
        self.posed_with(transforms, false, None, Moved::Rigid, |_| {})
    }

    /// A pose made again from what it is made of: [`Scene::posed`] (or, with `rewinds`, as
    /// [`Scene::at`] winds mirrored objects), with `lights` in place of the scene as loaded's
    /// when given, and `vertices` (one per vertex of the pose, finite) in place of the
    /// transformed ones when given (a pose whose skins or morph targets moved vertices), with
    /// their `normals` when given.
    /// Unpickling a posed scene takes this way, so that the scene it poses from travels with it.
    pub fn posed_again(
        self: &Arc<Self>,
        transforms: &[DMat4],
        rewinds: bool,
        lights: Option<Vec<crate::scene::Light>>,
        vertices: Option<Vec<[f32; 3]>>,
        normals: Option<Vec<[f32; 3]>>,
    ) -> Result<Scene> {
        let moved = vertices.map_or(Moved::Rigid, |v| Moved::All(v, normals));
        self.posed_with(transforms, rewinds, None, moved, |parts| {
            if let Some(lights) = lights {
                parts.lights = lights;
            }
        })
    }

    /// [`Scene::posed`], with `place` moving the lights and cameras (copied from the scene as
    /// loaded) before the scene is assembled. With `rewind`, the faces of the objects whose
    /// transform mirrors them (a negative determinant) are wound the other way, so that their
    /// counter-clockwise sides stay their fronts (the faces are then this pose's own).
    fn posed_with(
        self: &Arc<Self>,
        transforms: &[DMat4],
        rewind: bool,
        after: Option<Arc<Vec<DMat4>>>,
        moved: Moved,
        place: impl FnOnce(&mut SceneParts),
    ) -> Result<Scene> {
        let base = match &self.pose {
            Some(p) => p.base.clone(),
            None => self.clone(),
        };
        let objects = base.objects();
        if transforms.len() != objects.len() {
            return input_err!(
                "{} transforms for {} objects: give one per object",
                transforms.len(),
                objects.len()
            );
        }
        for (m, name) in transforms.iter().zip(objects) {
            let what = format!("object '{name}'");
            if rewind {
                // A clip's zero scale hides (or flattens) its object at that time.
                check_affine(m, &what)?;
            } else {
                check_transform(m, &what)?;
            }
        }
        let rig = base.rig();
        let deforms = match &moved {
            Moved::Rigid => false,
            Moved::Objects(objects) => !objects.is_empty(),
            Moved::All(..) => true,
        };
        // A rigid pose whose objects' boxes stay in float32's range makes its vertices on
        // first use: the pose itself is O(objects), and its rays need no world vertices.
        let lazy = !deforms && !matches!(moved, Moved::All(..)) && in_range(&base, transforms);
        let (vertices, normals) = if lazy {
            (Vec::new(), None)
        } else {
            let (vertices, normals) = moved_vertices(&rig, transforms, moved, after.as_deref())?;
            if let Some(i) = vertices
                .iter()
                .position(|v| v.iter().any(|x| !x.is_finite()))
            {
                let o = rig.vertex_object[i];
                return input_err!(
                    "the transform of object '{}' moves vertex {i} out of float32's range",
                    objects[o as usize]
                );
            }
            (vertices, normals)
        };
        let mut parts = SceneParts {
            vertices,
            normals,
            materials: base.parts.materials.clone(),
            objects: base.parts.objects.clone(),
            lights: base.parts.lights.clone(),
            cameras: base.parts.cameras.clone(),
            animations: base.parts.animations.clone(),
            ..Default::default()
        };
        place(&mut parts);
        let pose = Pose {
            base: base.clone(),
            transforms: Arc::new(transforms.to_vec()),
            rewinds: rewind,
            after,
            deforms,
        };
        // Determinants only where they decide something (a plain pose keeps the faces).
        let mirrored: Vec<bool> = if rewind {
            transforms.iter().map(|m| m.determinant() < 0.0).collect()
        } else {
            Vec::new()
        };
        let shared = if mirrored.contains(&true) {
            let mut s = (*rig.shared).clone();
            for (f, &o) in s.faces.iter_mut().zip(&s.object_ids) {
                if mirrored.get(o as usize).copied().unwrap_or(false) {
                    f.swap(1, 2);
                }
            }
            Arc::new(s)
        } else {
            rig.shared.clone()
        };
        if !lazy {
            return Ok(Scene::assemble(parts, shared, Some(pose)));
        }
        let moves = pose.transforms.clone();
        let make = MakeWorld(Box::new(move || {
            moved_vertices(&rig, &moves, Moved::Rigid, None).expect("a rigid pose's vertices")
        }));
        Ok(Scene::assemble_lazy(parts, shared, Some(pose), make))
    }
}

/// Each object's box (of its vertices as loaded, in f64; empty for an object without any),
/// made once per scene as loaded.
struct ObjectBoxes(Vec<[DVec3; 2]>);

/// Whether every object's box, moved by its transform, stays within float32's range: then so
/// does every vertex (each lies in its object's box, whose image holds the vertex's).
fn in_range(base: &Scene, transforms: &[DMat4]) -> bool {
    let boxes = base.derived(|| {
        let rig = base.rig();
        let mut b = vec![[DVec3::INFINITY, DVec3::NEG_INFINITY]; transforms.len()];
        for (v, &o) in rig.vertices.iter().zip(&rig.vertex_object) {
            if let Some(bx) = b.get_mut(o as usize) {
                let p = DVec3::from(v.map(f64::from));
                *bx = [bx[0].min(p), bx[1].max(p)];
            }
        }
        ObjectBoxes(b)
    });
    let limit = f64::from(f32::MAX) * 0.5;
    boxes.0.iter().zip(transforms).all(|([lo, hi], m)| {
        lo.x > hi.x
            || (0..8).all(|k| {
                let c = DVec3::new(
                    if k & 1 == 0 { lo.x } else { hi.x },
                    if k & 2 == 0 { lo.y } else { hi.y },
                    if k & 4 == 0 { lo.z } else { hi.z },
                );
                m.transform_point3(c).abs().max_element() < limit
            })
    })
}

/// The vertices and normals of a pose: each of `rig`'s moved by its object's transform
/// (normals by its inverse transpose, normalized), then those that `moved` gives instead (a
/// clip's skinned or morphed objects, placed by the user's pose `after` if any; or every vertex,
/// checked, with its normals when given: else the rig's, which no longer fit, are dropped).
fn moved_vertices(
    rig: &Rig,
    transforms: &[DMat4],
    moved: Moved,
    after: Option<&Vec<DMat4>>,
) -> Result<VerticesAndNormals> {
    if let Moved::All(vertices, normals) = moved {
        let n = rig.vertices.len();
        if vertices.len() != n || normals.as_ref().is_some_and(|ns| ns.len() != n) {
            return input_err!(
                "the pose's vertices and normals must be one per vertex ({n}), got {} and {:?}",
                vertices.len(),
                normals.as_ref().map(Vec::len)
            );
        }
        let finite = |v: &[[f32; 3]]| v.iter().position(|v| v.iter().any(|x| !x.is_finite()));
        if let Some(i) = finite(&vertices) {
            return input_err!("the pose's vertex {i} is not finite: {:?}", vertices[i]);
        }
        if let Some(i) = normals.as_deref().and_then(finite) {
            return input_err!("the pose's normal {i} is not finite");
        }
        return Ok((vertices, normals));
    }
    let identity = DMat4::IDENTITY;
    let of = |o: u32| transforms.get(o as usize).unwrap_or(&identity);
    let mut vertices: Vec<[f32; 3]> = rig
        .vertices
        .par_iter()
        .zip(&rig.vertex_object)
        .with_min_len(4096)
        .map(|(&p, &o)| transform_point(of(o), p))
        .collect();
    let normal_maps: Vec<DMat3> = transforms.iter().map(normal_map).collect();
    let mut normals: Option<Vec<[f32; 3]>> = rig.normals.as_ref().map(|ns| {
        ns.par_iter()
            .zip(&rig.vertex_object)
            .with_min_len(4096)
            .map(|(&n, &o)| match normal_maps.get(o as usize) {
                Some(m) => unit(*m * DVec3::from(n.map(f64::from))),
                None => n,
            })
            .collect()
    });
    if let Moved::Objects(objects) = moved {
        for (o, first, posed) in objects {
            let user = after.and_then(|a| a.get(*o)).copied();
            let out = &mut vertices[*first..*first + posed.positions.len()];
            out.par_iter_mut()
                .zip(&posed.positions)
                .with_min_len(4096)
                .for_each(|(v, p)| {
                    let p = user.map_or(*p, |m| m.transform_point3(*p));
                    *v = p.as_vec3().to_array();
                });
            if let Some(ns) = normals.as_mut() {
                let turn = user.map_or(DMat3::IDENTITY, |m| normal_map(&m));
                let out = &mut ns[*first..*first + posed.normals.len()];
                for (n, m) in out.iter_mut().zip(&posed.normals) {
                    *n = unit(turn * DVec3::from(m.map(f64::from)));
                }
            }
        }
    }
    Ok((vertices, normals))
}

/// `v` normalized (a zero vector stays zero), in f32.
fn unit(v: DVec3) -> [f32; 3] {
    v.normalize_or_zero().as_vec3().to_array()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_quads() -> Arc<Scene> {
        // Two objects sharing vertices 1 and 2.
        let v = vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [2., 0., 0.]];
        let f = vec![[0, 1, 2], [1, 3, 2]];
        let parts = SceneParts {
            vertices: v,
            faces: f,
            material_ids: vec![-1; 2],
            object_ids: vec![0, 1],
            objects: vec!["a".into(), "b".into()],
            ..Default::default()
        };
        Arc::new(Scene::new(parts).unwrap())
    }

    #[test]
    fn shared_vertices_are_split_and_ids_kept() {
        let s = two_quads();
        let up = DMat4::from_translation(DVec3::new(0.0, 0.0, 1.0));
        let p = s.posed(&[DMat4::IDENTITY, up]).unwrap();
        assert_eq!(p.triangle_count(), 2);
        assert_eq!(p.vertices().len(), 6);
        let f = p.faces()[1];
        for k in f {
            assert_eq!(p.vertices()[k as usize][2], 1.0);
        }
        for k in p.faces()[0] {
            assert_eq!(p.vertices()[k as usize][2], 0.0);
        }
        // Posing a posed scene starts from the scene as loaded.
        let q = Arc::new(p).posed(&[DMat4::IDENTITY; 2]).unwrap();
        assert!(q.vertices().iter().all(|v| v[2] == 0.0));
    }

    #[test]
    fn normals_follow_a_zero_scale_by_the_cofactor_matrix() {
        use glam::DVec3;
        // Non-singular: the inverse transpose, bit for bit as before.
        let m = DMat4::from_scale_rotation_translation(
            DVec3::new(2.0, -1.0, 0.5),
            glam::DQuat::from_rotation_z(0.3),
            DVec3::ONE,
        );
        assert_eq!(normal_map(&m), DMat3::from_mat4(m).inverse().transpose());
        // Flattened along z: every normal points along z; hidden: every normal is 0.
        let flat = normal_map(&DMat4::from_scale(DVec3::new(2.0, 3.0, 0.0)));
        let n = flat * DVec3::new(0.3, -0.2, 0.9);
        assert!(n.x == 0.0 && n.y == 0.0 && n.z > 0.0, "{n}");
        assert_eq!(normal_map(&DMat4::from_scale(DVec3::ZERO)), DMat3::ZERO);
    }

    #[test]
    fn bad_transforms_are_refused() {
        let s = two_quads();
        let bad = [
            DMat4::from_scale(DVec3::new(1.0, 0.0, 1.0)),
            DMat4::from_cols_array(&[f64::NAN; 16]),
            DMat4::from_cols_array(&[
                1., 0., 0., 1., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.,
            ]),
        ];
        for m in bad {
            assert!(s.posed(&[m, DMat4::IDENTITY]).is_err());
        }
        assert!(s.posed(&[DMat4::IDENTITY]).is_err());
        let huge = DMat4::from_scale(DVec3::splat(1e300));
        assert!(s.posed(&[huge, DMat4::IDENTITY]).is_err());
    }
}
