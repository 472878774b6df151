//! glTF animations read into [`Animations`]: the node hierarchy, each clip's channels (glTF 2.0
//! §3.11), checked key by key.

use std::sync::Arc;

use glam::{DMat4, DQuat, DVec3};

use super::checks::channel_problem;
use super::Loader;
use crate::scene::animation::{Animations, Channel, Clip, Interpolation, Node, Property};

impl Loader<'_> {
    /// The node animations (`animation::Animations`), kept only when the file has some. A
    /// channel that cannot be read is skipped with a warning; skins and morph targets are not
    /// posed (a warning says so, once each).
    pub(super) fn animations(&mut self) {
        let doc = self.doc;
        if doc.skins().next().is_some() {
            self.warn("skins are not posed: skinned meshes stay in their rest pose");
        }
        if doc.animations().next().is_none() {
            return;
        }
        let mut parent = vec![None; doc.nodes().len()];
        for n in doc.nodes() {
            for c in n.children() {
                parent[c.index()] = Some(n.index());
            }
        }
        let nodes = doc
            .nodes()
            .map(|n| {
                let t = n.transform();
                let local =
                    DMat4::from_cols_array_2d(&t.clone().matrix().map(|c| c.map(f64::from)));
                let (tr, r, sc) = t.decomposed();
                Node {
                    parent: parent[n.index()],
                    local,
                    trs: (
                        DVec3::from(tr.map(f64::from)),
                        DQuat::from_array(r.map(f64::from)).normalize(),
                        DVec3::from(sc.map(f64::from)),
                    ),
                }
            })
            .collect();
        let mut clips = Vec::new();
        let mut morph = false;
        for anim in doc.animations() {
            let mut channels = Vec::new();
            // Key times of the channels read but not applied (morph target weights).
            let mut unapplied: Vec<f32> = Vec::new();
            for ch in anim.channels() {
                if let Some(m) = channel_problem(doc, anim.index(), ch.index()) {
                    self.warn(format!(
                        "animation {} channel {}: {m}; skipped",
                        anim.index(),
                        ch.index()
                    ));
                    continue;
                }
                match self.channel(&ch) {
                    Ok(Ok(c)) => channels.push(c),
                    Ok(Err(times)) => {
                        morph = true;
                        unapplied.extend(times);
                    }
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
                .chain(unapplied.last())
                .fold(0.0f64, |a, &b| a.max(f64::from(b)));
            clips.push(Clip {
                name: anim
                    .name()
                    .map_or_else(|| format!("animation{}", anim.index()), str::to_string),
                duration,
                channels,
                unapplied,
            });
        }
        if morph {
            self.warn("morph target weights are not animated: meshes keep their base shape");
        }
        self.parts.animations = Some(Arc::new(Animations {
            nodes,
            objects: std::mem::take(&mut self.placed),
            lights: std::mem::take(&mut self.placed_lights),
            cameras: std::mem::take(&mut self.placed_cameras),
            clips,
        }));
    }

    /// One channel's keys, checked; for morph target weights (not applied), only their key
    /// times (`Ok(Err(times))`).
    #[allow(clippy::type_complexity)]
    fn channel(
        &self,
        ch: &gltf::animation::Channel,
    ) -> std::result::Result<std::result::Result<Channel, Vec<f32>>, String> {
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
        let (property, values): (Property, Vec<[f32; 4]>) =
            match reader.read_outputs().ok_or("its values cannot be read")? {
                ReadOutputs::Translations(v) => (
                    Property::Translation,
                    v.map(|p| [p[0], p[1], p[2], 0.0]).collect(),
                ),
                ReadOutputs::Scales(v) => (
                    Property::Scale,
                    v.map(|p| [p[0], p[1], p[2], 0.0]).collect(),
                ),
                ReadOutputs::Rotations(v) => (Property::Rotation, v.into_f32().collect()),
                ReadOutputs::MorphTargetWeights(_) => return Ok(Err(times)),
            };
        let interpolation = match ch.sampler().interpolation() {
            gltf::animation::Interpolation::Step => Interpolation::Step,
            gltf::animation::Interpolation::Linear => Interpolation::Linear,
            gltf::animation::Interpolation::CubicSpline => Interpolation::CubicSpline,
        };
        let per_key = if interpolation == Interpolation::CubicSpline {
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
        if values.iter().flatten().any(|x| !x.is_finite()) {
            return Err("a value is not finite".into());
        }
        Ok(Ok(Channel {
            node: ch.target().node().index(),
            property,
            interpolation,
            times,
            values,
        }))
    }
}
