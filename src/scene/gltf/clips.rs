//! glTF animations read into [`Animations`]: the node hierarchy, each clip's channels (glTF 2.0
//! §3.11), checked key by key.

use std::sync::Arc;

use glam::{DQuat, DVec3};

use super::checks::channel_problem;
use super::Loader;
use crate::scene::animation::{Animations, Channel, Clip, Interpolation, Node, Property};

impl Loader<'_> {
    /// The animations (`animation::Animations`), kept only when the file has some: the node
    /// hierarchy, the clips, and the skins and deformable objects they move. A channel that
    /// cannot be read is skipped with a warning.
    pub(super) fn animations(&mut self) -> crate::error::Result<()> {
        let doc = self.doc;
        if doc.animations().next().is_none() {
            return Ok(());
        }
        let nodes = doc
            .nodes()
            .map(|n| {
                let (tr, r, sc) = n.transform().decomposed();
                Node {
                    parent: self.parents[n.index()],
                    local: super::local_of(&n),
                    trs: (
                        DVec3::from(tr.map(f64::from)),
                        DQuat::from_array(r.map(f64::from)).normalize(),
                        DVec3::from(sc.map(f64::from)),
                    ),
                }
            })
            .collect();
        let mut clips = Vec::new();
        for anim in doc.animations() {
            let mut channels = Vec::new();
            for ch in anim.channels() {
                let problem = channel_problem(doc, anim.index(), ch.index())
                    .map_or_else(|| self.channel(&ch), Err);
                match problem {
                    Ok(c) => channels.push(c),
                    Err(m) => self.warn(format!(
                        "animation {} channel {}: {m}; skipped",
                        anim.index(),
                        ch.index()
                    )),
                }
            }
            // Every channel counts, weights included (glTF 2.0 §3.11: a clip lasts until its
            // last key).
            let duration = channels
                .iter()
                .filter_map(|c| c.times.last())
                .fold(0.0f64, |a, &b| a.max(f64::from(b)));
            clips.push(Clip {
                name: anim
                    .name()
                    .map_or_else(|| format!("animation{}", anim.index()), str::to_string),
                duration,
                channels,
            });
        }
        let animations = Animations {
            nodes,
            rest: std::mem::take(&mut self.rest),
            objects: std::mem::take(&mut self.placed),
            lights: std::mem::take(&mut self.placed_lights),
            cameras: std::mem::take(&mut self.placed_cameras),
            clips,
            rigging: std::mem::take(&mut self.rigging),
        };
        // What a pickle's animations are checked for holds for a file's too (a skin's joint
        // in a loop of nodes outside the scene would make a pose walk that loop forever).
        let p = &self.parts;
        animations
            .check(
                p.objects.len(),
                p.lights.len(),
                p.cameras.len(),
                p.vertices.len(),
            )
            .map_err(|e| self.err(e))?;
        self.parts.animations = Some(Arc::new(animations));
        Ok(())
    }

    /// One channel's keys, checked: as many values per key as the property has (three, four,
    /// or for morph weights one per target of the node's mesh), all finite.
    fn channel(&self, ch: &gltf::animation::Channel) -> Result<Channel, String> {
        use gltf::animation::util::ReadOutputs;
        let buffers = &self.buffers;
        let reader = ch.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let times: Vec<f32> = reader
            .read_inputs()
            .ok_or("its key times cannot be read")?
            .collect();
        if times.iter().any(|t| !t.is_finite()) || times.windows(2).any(|w| w[1] < w[0]) {
            return Err("its key times are not finite and non-decreasing".into());
        }
        let node = ch.target().node();
        let (property, width, values): (Property, usize, Vec<f32>) = match reader
            .read_outputs()
            .ok_or("its values cannot be read")?
        {
            ReadOutputs::Translations(v) => (Property::Translation, 3, v.flatten().collect()),
            ReadOutputs::Scales(v) => (Property::Scale, 3, v.flatten().collect()),
            ReadOutputs::Rotations(v) => (Property::Rotation, 4, v.into_f32().flatten().collect()),
            ReadOutputs::MorphTargetWeights(v) => {
                let targets = node.mesh().map_or(0, |m| {
                    m.primitives()
                        .map(|p| p.morph_targets().len())
                        .max()
                        .unwrap_or(0)
                });
                if targets == 0 {
                    return Err(format!(
                        "it keys the morph weights of node {}, which has no morph targets",
                        node.index()
                    ));
                }
                (Property::Weights, targets, v.into_f32().collect())
            }
        };
        let interpolation = match ch.sampler().interpolation() {
            gltf::animation::Interpolation::Step => Interpolation::Step,
            gltf::animation::Interpolation::Linear => Interpolation::Linear,
            gltf::animation::Interpolation::CubicSpline => Interpolation::CubicSpline,
        };
        let per_key = width
            * if interpolation == Interpolation::CubicSpline {
                3
            } else {
                1
            };
        if times.is_empty() || values.len() != per_key * times.len() {
            return Err(format!(
                "{} values for {} key times ({per_key} per key expected)",
                values.len(),
                times.len()
            ));
        }
        if values.iter().any(|x| !x.is_finite()) {
            return Err("a value is not finite".into());
        }
        Ok(Channel {
            node: node.index(),
            property,
            interpolation,
            times,
            width,
            values,
        })
    }
}
