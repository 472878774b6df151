//! glTF animations (glTF 2.0 §3.11, and Appendix C for the interpolations): per clip, channels
//! that key a node's translation, rotation, scale or morph target weights, sampled STEP, LINEAR
//! (rotations by spherical interpolation) or CUBICSPLINE (Hermite, with the keys' in- and
//! out-tangents). A clip at a time gives each object of the scene the transform from its place
//! as loaded to its place then, which [`Scene::posed`](super::Scene::posed) applies, and the
//! vertices of the objects that skins or morph targets move ([`super::skin`]).

use glam::{DMat4, DQuat, DVec3};

use super::skin::{Place, Posed, Rigging};
use crate::error::Result;
use crate::input_err;

/// A node's place in the hierarchy and its transform as loaded.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Node {
    pub parent: Option<usize>,
    /// The local transform as loaded (the node's matrix, or its TRS composed).
    pub local: DMat4,
    /// The local transform as translation, rotation and scale (decomposed from a matrix).
    pub trs: (DVec3, DQuat, DVec3),
}

/// Where an object of the scene comes from: its node, the instance transform under it
/// (`EXT_mesh_gpu_instancing`; identity otherwise), and the world transform it was loaded with.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Placed {
    pub node: usize,
    pub instance: DMat4,
    pub loaded: DMat4,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Property {
    Translation,
    Rotation,
    Scale,
    /// Morph target weights: one value per target.
    Weights,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Interpolation {
    Step,
    Linear,
    CubicSpline,
}

/// One animated property of one node: key times (seconds, non-decreasing) and per key `width`
/// values (xyz, a quaternion's xyzw, or one weight per morph target); CUBICSPLINE keys hold
/// in-tangent, value and out-tangent, in that order.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Channel {
    pub node: usize,
    pub property: Property,
    pub interpolation: Interpolation,
    pub times: Vec<f32>,
    pub width: usize,
    pub values: Vec<f32>,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Clip {
    pub name: String,
    /// The last key time over its channels, in seconds (weights channels included).
    pub duration: f64,
    pub channels: Vec<Channel>,
}

/// A scene's node hierarchy, where its objects hang in it, and its clips.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Animations {
    pub nodes: Vec<Node>,
    /// Each node's world transform as loaded.
    pub rest: Vec<DMat4>,
    pub objects: Vec<Placed>,
    /// The nodes of the scene's lights and cameras, in the scene's order.
    pub lights: Vec<Placed>,
    pub cameras: Vec<Placed>,
    pub clips: Vec<Clip>,
    /// The skins, and the objects that skins or morph targets move.
    pub rigging: Rigging,
}

impl Animations {
    /// The animations as JSON text (what a pickle of their scene carries).
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|e| unreachable!("plain data serializes: {e}"))
    }

    /// Animations read back from [`Animations::to_json`]'s text, checked against the scene
    /// they belong to (`objects` objects, `lights` lights, `cameras` cameras, `vertices`
    /// vertices): every index they hold names something that exists, so that no later pose
    /// indexes out of range. An error names what does not fit.
    pub fn from_json(
        text: &str,
        objects: usize,
        lights: usize,
        cameras: usize,
        vertices: usize,
    ) -> Result<Animations> {
        let a: Animations = match serde_json::from_str(text) {
            Ok(a) => a,
            Err(e) => return input_err!("the animations cannot be read: {e}"),
        };
        a.check(objects, lights, cameras, vertices)?;
        Ok(a)
    }

    pub fn check(
        &self,
        objects: usize,
        lights: usize,
        cameras: usize,
        vertices: usize,
    ) -> Result<()> {
        let nodes = self.nodes.len();
        let node_ok = |i: usize| i < nodes;
        let bad = |what: &str| -> Result<()> {
            input_err!("the animations do not fit their scene: {what}")
        };
        if self.rest.len() != nodes || self.nodes.iter().any(|n| !n.parent.is_none_or(node_ok)) {
            return bad("a node's parent or rest transform is missing");
        }
        // Every chain of parents ends at a root within `nodes` steps (no node is its own
        // ancestor: a pose walks the chains).
        for start in 0..nodes {
            let mut at = self.nodes[start].parent;
            let mut steps = 0;
            while let Some(p) = at {
                steps += 1;
                if steps > nodes {
                    return bad("a node is its own ancestor");
                }
                at = self.nodes[p].parent;
            }
        }
        for (places, count, what) in [
            (&self.objects, objects, "objects"),
            (&self.lights, lights, "lights"),
            (&self.cameras, cameras, "cameras"),
        ] {
            if places.len() != count || places.iter().any(|p| !node_ok(p.node)) {
                return bad(&format!("{} places for {count} {what}", places.len()));
            }
        }
        for c in &self.clips {
            for ch in &c.channels {
                let cubic = ch.interpolation == Interpolation::CubicSpline;
                let per_key = ch.width * if cubic { 3 } else { 1 };
                let width_ok = match ch.property {
                    Property::Translation | Property::Scale => ch.width == 3,
                    Property::Rotation => ch.width == 4,
                    Property::Weights => ch.width > 0,
                };
                if !node_ok(ch.node)
                    || !width_ok
                    || ch.times.is_empty()
                    || ch.values.len() != per_key * ch.times.len()
                {
                    return bad(&format!("a channel of clip {:?}", c.name));
                }
            }
        }
        let r = &self.rigging;
        for s in &r.skins {
            if s.joints.iter().any(|&j| !node_ok(j)) || s.inverse_bind.len() != s.joints.len() {
                return bad("a skin's joints");
            }
        }
        for d in &r.deformables {
            let n = d.base.len();
            let joints = d.skin.map(|s| r.skins.get(s).map_or(0, |s| s.joints.len()));
            let rows_ok =
                |rows: &Vec<Vec<[f32; 3]>>| rows.iter().all(|t| t.is_empty() || t.len() == n);
            if d.object >= objects
                || !node_ok(d.node)
                || d.first + n > vertices
                || d.normals.len() != n
                || d.targets.len() != d.normal_targets.len()
                || !rows_ok(&d.targets)
                || !rows_ok(&d.normal_targets)
                || joints == Some(0)
                || d.joints.len() != n * d.influences
                || d.joint_weights.len() != n * d.influences
                || d.joints
                    .iter()
                    .any(|&j| joints.is_some_and(|k| usize::from(j) >= k))
            {
                return bad(&format!("the deformation of object {}", d.object));
            }
        }
        Ok(())
    }
}

/// A clip sampled at one time: each object's transform from its place as loaded (the identity
/// exactly under no animated node), and the world transform of each light's and camera's node
/// (`None` under no animated node: it stays where it was loaded). An object that a skin moves
/// has the identity (its node's transform is ignored), and the objects whose skins or morph
/// weights the clip moves are in `deformed`.
#[derive(Debug, Clone)]
pub struct At {
    pub objects: Vec<DMat4>,
    /// Per moved deformable object: the object, its first vertex, and its vertices and
    /// normals in world space (in the order of the scene's).
    pub deformed: Vec<(usize, usize, Posed)>,
    pub lights: Vec<Option<DMat4>>,
    pub cameras: Vec<Option<DMat4>>,
}

/// `m` with its last row set to 0, 0, 0, 1: what a transform composed of affine ones is, up to
/// the rounding that a product or an inverse leaves in that row.
pub fn affine(mut m: DMat4) -> DMat4 {
    m.x_axis.w = 0.0;
    m.y_axis.w = 0.0;
    m.z_axis.w = 0.0;
    m.w_axis.w = 1.0;
    m
}

/// The map from an object's vertices as loaded back to its mesh's space: the inverse of `loaded`,
/// or where a zero scale made it singular (an object loaded hidden or flattened), its
/// pseudo-inverse, which recovers what the load kept (the directions the scale did not zero)
/// and maps the rest to the node's origin. So a clip that moves such a node's parents moves what
/// is left of it, and never makes a transform that is not finite.
pub fn undo(loaded: &DMat4) -> DMat4 {
    let l = glam::DMat3::from_mat4(*loaded);
    let size = l.x_axis.length_squared() + l.y_axis.length_squared() + l.z_axis.length_squared();
    let p = if l.determinant().abs() > 1e-12 * size.powf(1.5) {
        l.inverse()
    } else {
        // (LᵀL + εI)⁻¹Lᵀ: the pseudo-inverse where L's singular values are 0 or well above ε.
        let gram = l.transpose() * l;
        let eps = 1e-12 * size.max(f64::MIN_POSITIVE);
        (gram + glam::DMat3::from_diagonal(DVec3::splat(eps))).inverse() * l.transpose()
    };
    let p = if p.is_finite() { p } else { glam::DMat3::ZERO };
    // Inverted as an affine map (linear part, then translation), so that its last row is
    // 0, 0, 0, 1 exactly: a general 4×4 inverse rounds it to 0.9999999999999999 for some
    // rotations, which no later product would repair.
    let t = -(p * loaded.w_axis.truncate());
    DMat4::from_cols(
        p.x_axis.extend(0.0),
        p.y_axis.extend(0.0),
        p.z_axis.extend(0.0),
        t.extend(1.0),
    )
}

impl Channel {
    /// The property's value at `t` (clamped to the keys): `width` numbers.
    fn sample(&self, t: f64) -> Vec<f64> {
        let (times, w) = (&self.times, self.width);
        let n = times.len();
        let cubic = self.interpolation == Interpolation::CubicSpline;
        // Key k's part `part` (0 in-tangent, 1 value, 2 out-tangent; plain keys are values).
        let get = |k: usize, part: usize| -> Vec<f64> {
            let at = if cubic { 3 * k + part } else { k } * w;
            self.values[at..at + w]
                .iter()
                .map(|&x| f64::from(x))
                .collect()
        };
        if n == 1 || t <= f64::from(times[0]) {
            return get(0, 1);
        }
        if t >= f64::from(times[n - 1]) {
            return get(n - 1, 1);
        }
        // The key at or before t.
        let k = times.partition_point(|&x| f64::from(x) <= t) - 1;
        let (t0, t1) = (f64::from(times[k]), f64::from(times[k + 1]));
        let dt = t1 - t0;
        let s = if dt > 0.0 { (t - t0) / dt } else { 0.0 };
        let (a, b) = (get(k, 1), get(k + 1, 1));
        match self.interpolation {
            Interpolation::Step => a,
            Interpolation::Linear if self.property == Property::Rotation => {
                let q = |v: &[f64]| DQuat::from_xyzw(v[0], v[1], v[2], v[3]).normalize();
                q(&a).slerp(q(&b), s).to_array().to_vec()
            }
            Interpolation::Linear => a.iter().zip(&b).map(|(a, b)| a + s * (b - a)).collect(),
            Interpolation::CubicSpline => {
                let (out_a, in_b) = (get(k, 2), get(k + 1, 0));
                let (s2, s3) = (s * s, s * s * s);
                (0..w)
                    .map(|i| {
                        (2.0 * s3 - 3.0 * s2 + 1.0) * a[i]
                            + (s3 - 2.0 * s2 + s) * dt * out_a[i]
                            + (-2.0 * s3 + 3.0 * s2) * b[i]
                            + (s3 - s2) * dt * in_b[i]
                    })
                    .collect()
            }
        }
    }
}

/// How a caller names a clip: by its index among the scene's clips, or by its name (a name is
/// always a name, even one that reads as a number: clips named "1" and "0" exist).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClipKey<'a> {
    Index(usize),
    Name(&'a str),
}

impl Animations {
    /// The index of the clip `clip` names.
    pub fn clip(&self, clip: ClipKey) -> Result<usize> {
        let name = match clip {
            ClipKey::Index(k) if k < self.clips.len() => return Ok(k),
            ClipKey::Index(k) => {
                return input_err!("no animation {k}: the scene has {}", self.clips.len())
            }
            ClipKey::Name(name) => name,
        };
        match self.clips.iter().position(|c| c.name == name) {
            Some(k) => Ok(k),
            None => input_err!(
                "no animation named {name:?}: the scene has {} ({:?})",
                self.clips.len(),
                self.clips
                    .iter()
                    .map(|c| c.name.as_str())
                    .collect::<Vec<_>>()
            ),
        }
    }

    /// Each object's transform from its place as loaded to its place at `t` seconds into clip
    /// `clip` (`t` clamped to the clip, as glTF's samplers hold their first and last keys).
    /// Objects under no animated node keep the identity exactly.
    pub fn transforms(&self, clip: usize, t: f64) -> Result<Vec<DMat4>> {
        Ok(self.at(clip, t)?.objects)
    }

    /// Clip `clip` sampled at `t` seconds (clamped to the clip): objects, lights and cameras.
    pub fn at(&self, clip: usize, t: f64) -> Result<At> {
        self.at_clips(&[clip], t)
    }

    /// Every key time of clip `clip` over its channels, ascending, each once (seconds).
    pub fn key_times(&self, clip: usize) -> Result<Vec<f64>> {
        let Some(c) = self.clips.get(clip) else {
            return input_err!("no animation {clip}: the scene has {}", self.clips.len());
        };
        let mut times: Vec<f64> = c
            .channels
            .iter()
            .flat_map(|ch| &ch.times)
            .map(|&t| f64::from(t))
            .collect();
        times.sort_by(f64::total_cmp);
        times.dedup();
        Ok(times)
    }

    /// Clips `clips` played together, sampled at `t` seconds (clamped to each clip): objects,
    /// lights and cameras. Where two clips key the same property of a node, the later wins.
    pub fn at_clips(&self, clips: &[usize], t: f64) -> Result<At> {
        if !t.is_finite() {
            return input_err!("the time must be finite, got {t}");
        }
        let mut trs: Vec<Option<(DVec3, DQuat, DVec3)>> = vec![None; self.nodes.len()];
        let mut weights: Vec<Option<Vec<f64>>> = vec![None; self.nodes.len()];
        for &clip in clips {
            let Some(c) = self.clips.get(clip) else {
                return input_err!("no animation {clip}: the scene has {}", self.clips.len());
            };
            let t = t.clamp(0.0, c.duration);
            for ch in &c.channels {
                let v = ch.sample(t);
                if ch.property == Property::Weights {
                    weights[ch.node] = Some(v);
                    continue;
                }
                let (tr, rot, sc) = trs[ch.node].get_or_insert(self.nodes[ch.node].trs);
                match ch.property {
                    Property::Translation => *tr = DVec3::new(v[0], v[1], v[2]),
                    Property::Scale => *sc = DVec3::new(v[0], v[1], v[2]),
                    Property::Rotation => {
                        *rot = DQuat::from_xyzw(v[0], v[1], v[2], v[3]).normalize()
                    }
                    Property::Weights => {}
                }
            }
        }
        let mut at = self.sampled(&trs)?;
        self.deform(&trs, &weights, &mut at);
        Ok(at)
    }

    /// The deformable objects at the sampled `trs` and morph `weights` (per node, `None` where
    /// no clip keys them) written into `at`: a skinned object's transform is the identity, and
    /// its vertices are skinned where a joint moves or its weights are keyed; an unskinned one's
    /// vertices are morphed where its weights are keyed (else its transform places it).
    fn deform(
        &self,
        trs: &[Option<(DVec3, DQuat, DVec3)>],
        weights: &[Option<Vec<f64>>],
        at: &mut At,
    ) {
        let mut world = vec![None; self.nodes.len()];
        for d in &self.rigging.deformables {
            let keyed = weights[d.node].as_deref();
            let w = keyed.unwrap_or(&d.weights);
            let moved = match d.skin {
                Some(s) => {
                    at.objects[d.object] = DMat4::IDENTITY;
                    let skin = &self.rigging.skins[s];
                    let placed: Vec<Option<DMat4>> = skin
                        .joints
                        .iter()
                        .map(|&j| self.world_at(j, trs, &mut world))
                        .collect();
                    if keyed.is_none() && placed.iter().all(Option::is_none) {
                        continue;
                    }
                    let worlds = skin.joints.iter().zip(&placed);
                    let mats = skin.matrices(worlds.map(|(&j, w)| w.unwrap_or(self.rest[j])));
                    d.place(w, &Place::Joints(&mats))
                }
                None => {
                    if keyed.is_none() {
                        continue;
                    }
                    let node = self.world_at(d.node, trs, &mut world);
                    let place = node.unwrap_or(self.rest[d.node]) * d.instance;
                    d.place(w, &Place::Node(place))
                }
            };
            at.deformed.push((d.object, d.first, moved));
        }
    }

    /// Objects, lights and cameras from each node's sampled TRS (`None`: not animated).
    fn sampled(&self, trs: &[Option<(DVec3, DQuat, DVec3)>]) -> Result<At> {
        // World transforms at t of the nodes with an animated ancestor (or themselves).
        let mut world: Vec<Option<Option<DMat4>>> = vec![None; self.nodes.len()];
        let mut worlds = |places: &[Placed]| -> Vec<Option<DMat4>> {
            places
                .iter()
                .map(|p| self.world_at(p.node, trs, &mut world))
                .collect()
        };
        let objects = worlds(&self.objects)
            .into_iter()
            .zip(&self.objects)
            .map(|(w, p)| {
                w.map_or(DMat4::IDENTITY, |w| {
                    affine(w * p.instance * undo(&p.loaded))
                })
            })
            .collect();
        Ok(At {
            objects,
            deformed: Vec::new(),
            lights: worlds(&self.lights),
            cameras: worlds(&self.cameras),
        })
    }

    /// Node `i`'s world transform at the sampled `trs`, or `None` when neither it nor an
    /// ancestor is animated (memoised in `world`).
    fn world_at(
        &self,
        i: usize,
        trs: &[Option<(DVec3, DQuat, DVec3)>],
        world: &mut [Option<Option<DMat4>>],
    ) -> Option<DMat4> {
        if let Some(w) = world[i] {
            return w;
        }
        let n = &self.nodes[i];
        let local = trs[i].map(|(t, r, s)| DMat4::from_scale_rotation_translation(s, r, t));
        let parent = n.parent.map(|p| (p, self.world_at(p, trs, world)));
        let w = match (parent, local) {
            (None, None) | (Some((_, None)), None) => None,
            (None, Some(l)) => Some(l),
            (Some((p, pw)), l) => {
                let pw = pw.unwrap_or(self.rest[p]);
                Some(pw * l.unwrap_or(n.local))
            }
        };
        world[i] = Some(w);
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn channel(property: Property, interpolation: Interpolation, values: Vec<[f32; 4]>) -> Channel {
        Channel {
            node: 0,
            property,
            interpolation,
            times: vec![0.0, 1.0, 3.0],
            width: 4,
            values: values.into_iter().flatten().collect(),
        }
    }

    #[test]
    fn each_interpolation_between_and_at_keys() {
        let v = vec![[0., 0., 0., 0.], [2., 0., 0., 0.], [2., 4., 0., 0.]];
        let lin = channel(Property::Translation, Interpolation::Linear, v.clone());
        assert_eq!(lin.sample(0.5)[0], 1.0);
        assert_eq!(lin.sample(2.0), [2.0, 2.0, 0.0, 0.0]);
        assert_eq!(lin.sample(-1.0)[0], 0.0);
        assert_eq!(lin.sample(9.0)[1], 4.0);
        let step = channel(Property::Translation, Interpolation::Step, v);
        assert_eq!(step.sample(0.99)[0], 0.0);
        assert_eq!(step.sample(1.0)[0], 2.0);
        // Cubic: zero tangents give smoothstep between the values.
        let z = [0.0; 4];
        let cubic = channel(
            Property::Translation,
            Interpolation::CubicSpline,
            vec![
                z,
                [0., 0., 0., 0.],
                z,
                z,
                [1., 0., 0., 0.],
                z,
                z,
                [1., 0., 0., 0.],
                z,
            ],
        );
        assert_eq!(cubic.sample(0.5)[0], 0.5);
        assert!((cubic.sample(0.25)[0] - (3.0 * 0.0625 - 2.0 * 0.015625)).abs() < 1e-12);
    }
}
