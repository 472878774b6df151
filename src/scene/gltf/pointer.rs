//! Animation channels that target something other than a node's property through an extension
//! (`KHR_animation_pointer`, glTF 2.0 §3.11 extended): such a channel has no `target.node`,
//! which the glTF 2.0 schema otherwise requires, so it is resolved in the file's JSON before
//! the glTF reader parses it. A pointer to a node's translation, rotation, scale or morph
//! weights becomes the plain channel it means and plays; any other target (a material's
//! colour, a light's intensity, a camera's field of view, ...) is left out with a warning that
//! names it, since nothing here animates those.

use serde_json::Value;

/// The node properties a plain channel can key (glTF 2.0 §3.11).
const NODE_PATHS: [&str; 4] = ["translation", "rotation", "scale", "weights"];

/// Rewrite or remove, in the file's JSON `root`, every animation channel whose target names
/// an extension: a `KHR_animation_pointer` to `/nodes/{i}/{translation|rotation|scale|weights}`
/// becomes a channel of node `i`; the rest are removed. Returns one warning per removed channel
/// (the channel's animation and index in the file, and what it targets).
pub(super) fn resolve_extension_channels(root: &mut Value) -> Vec<String> {
    let mut notes = Vec::new();
    let Some(animations) = root.get_mut("animations").and_then(Value::as_array_mut) else {
        return notes;
    };
    for (a, anim) in animations.iter_mut().enumerate() {
        let Some(channels) = anim.get_mut("channels").and_then(Value::as_array_mut) else {
            continue;
        };
        let mut index = 0;
        channels.retain_mut(|ch| {
            let here = index;
            index += 1;
            match resolve(ch) {
                Ok(()) => true,
                Err(what) => {
                    notes.push(format!(
                        "animation {a} channel {here} targets {what}, which is not animated \
                         here; the channel was skipped"
                    ));
                    false
                }
            }
        });
    }
    notes
}

/// Make channel `ch` a plain one where its target's extension points at a node property; an
/// error names what it targets when it cannot be played. A channel whose target names no
/// extension is left as it is (the reader and its checks judge it).
fn resolve(ch: &mut Value) -> Result<(), String> {
    let Some(target) = ch.get_mut("target").and_then(Value::as_object_mut) else {
        return Ok(());
    };
    let Some(extensions) = target.get("extensions").and_then(Value::as_object) else {
        return Ok(());
    };
    if target.contains_key("node") && target.get("path").and_then(Value::as_str) != Some("pointer")
    {
        // A plain channel that also carries an extension: it plays as the plain channel.
        return Ok(());
    }
    let Some(pointer) = extensions
        .get("KHR_animation_pointer")
        .and_then(|p| p.get("pointer"))
        .and_then(Value::as_str)
    else {
        let names: Vec<&String> = extensions.keys().collect();
        return Err(format!("a target of the extension {names:?}"));
    };
    let parts: Vec<&str> = pointer.split('/').collect();
    match parts.as_slice() {
        ["", "nodes", node, path] if NODE_PATHS.contains(path) => {
            let Ok(node) = node.parse::<u64>() else {
                return Err(format!("the KHR_animation_pointer {pointer:?}"));
            };
            let path = (*path).to_string();
            target.insert("node".into(), Value::from(node));
            target.insert("path".into(), Value::from(path));
            target.remove("extensions");
            Ok(())
        }
        _ => Err(format!("the KHR_animation_pointer {pointer:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_pointers_play_and_other_pointers_are_skipped_by_name() {
        let mut root = serde_json::json!({"animations": [{"channels": [
            {"sampler": 0, "target": {"path": "pointer",
                "extensions": {"KHR_animation_pointer": {"pointer": "/nodes/2/rotation"}}}},
            {"sampler": 1, "target": {"path": "pointer",
                "extensions": {"KHR_animation_pointer":
                    {"pointer": "/materials/0/pbrMetallicRoughness/baseColorFactor"}}}},
            {"sampler": 2, "target": {"node": 1, "path": "scale"}},
        ]}]});
        let notes = resolve_extension_channels(&mut root);
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(notes[0].contains("channel 1") && notes[0].contains("baseColorFactor"));
        let channels = root["animations"][0]["channels"].as_array().unwrap();
        assert_eq!(channels.len(), 2);
        assert_eq!(
            channels[0]["target"],
            serde_json::json!({"node": 2, "path": "rotation"})
        );
        assert_eq!(channels[1]["target"]["path"], "scale");
    }
}
