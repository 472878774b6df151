//! `EXT_meshopt_compression` (and `KHR_meshopt_compression`, its ratified successor with the
//! same layout): a buffer view whose bytes are one meshoptimizer stream elsewhere. The
//! extension names the compressed range (`buffer`, `byteOffset`, `byteLength`), how many
//! elements it holds (`count`) of how many bytes (`byteStride`), its `mode` (vertex
//! `ATTRIBUTES`, `TRIANGLES`, or an `INDICES` sequence) and a `filter` applied after decoding
//! (`OCTAHEDRAL` normals, `QUATERNION` rotations, `EXPONENTIAL` floats; `COLOR` in the KHR
//! version). The streams are decoded by `draco-gltf`'s pure-Rust port of meshoptimizer's
//! decoders (bounds-checked; from the same project as the Draco decoder) into the buffer view's
//! own place in its buffer, before anything reads it, so that accessors, skins and clips read
//! them like any other data. A buffer that exists only to hold decoded views (the extension's
//! `fallback: true`, with no data of its own) starts as zeros.

use draco_gltf::meshopt::{decode_buffer_view, MeshoptFilter, MeshoptMode};
use serde_json::Value;

/// The extension's names: the vendor one and the ratified one.
pub(super) const NAMES: [&str; 2] = ["EXT_meshopt_compression", "KHR_meshopt_compression"];

/// The extension object of `view`, and the name it goes by, if the view is compressed.
fn extension<'a>(view: &'a gltf::buffer::View) -> Option<(&'static str, &'a Value)> {
    NAMES
        .iter()
        .find_map(|&n| view.extension_value(n).map(|v| (n, v)))
}

/// Whether buffer `b` is a fallback buffer: one that holds no data of its own, only the
/// decoded contents of compressed views.
pub(super) fn is_fallback(b: &gltf::Buffer) -> bool {
    NAMES.iter().any(|&n| {
        b.extension_value(n)
            .and_then(|e| e.get("fallback"))
            .and_then(Value::as_bool)
            == Some(true)
    })
}

/// Decode every compressed buffer view of `doc` into its place in `buffers`. An error names
/// the view and what is wrong with it.
pub(super) fn decode_views(doc: &gltf::Document, buffers: &mut [Vec<u8>]) -> Result<(), String> {
    for view in doc.views() {
        let Some((name, ext)) = extension(&view) else {
            continue;
        };
        let err = |m: String| format!("buffer view {}: {name} {m}", view.index());
        let int = |key: &str, default: Option<u64>| {
            ext.get(key)
                .map(|v| {
                    v.as_u64()
                        .ok_or_else(|| err(format!("{key} is not a count")))
                })
                .unwrap_or_else(|| default.ok_or_else(|| err(format!("has no {key}"))))
                .and_then(|v| usize::try_from(v).map_err(|_| err(format!("{key} is too large"))))
        };
        let text = |key: &str, default: Option<&'static str>| -> Result<String, String> {
            match ext.get(key) {
                Some(v) => v
                    .as_str()
                    .map(str::to_owned)
                    .ok_or_else(|| err(format!("{key} is not a string"))),
                None => default
                    .map(str::to_owned)
                    .ok_or_else(|| err(format!("has no {key}"))),
            }
        };
        let (source, offset, length) = (
            int("buffer", None)?,
            int("byteOffset", Some(0))?,
            int("byteLength", None)?,
        );
        let (stride, count) = (int("byteStride", None)?, int("count", None)?);
        let mode = text("mode", None)?;
        let filter = text("filter", Some("NONE"))?;
        let mode = MeshoptMode::from_name(&mode).map_err(|_| {
            err(format!(
                "mode {mode} is not one of ATTRIBUTES, TRIANGLES, INDICES"
            ))
        })?;
        let filter = MeshoptFilter::from_name(&filter).map_err(|_| {
            err(format!(
                "filter {filter} is not one of NONE, OCTAHEDRAL, QUATERNION, EXPONENTIAL, COLOR"
            ))
        })?;
        let size = count
            .checked_mul(stride)
            .filter(|&s| s <= view.length())
            .ok_or_else(|| {
                err(format!(
                    "decodes to {count} x {stride} bytes, more than the view's {}",
                    view.length()
                ))
            })?;
        let compressed = buffers
            .get(source)
            .and_then(|b| b.get(offset..offset.checked_add(length)?))
            .ok_or_else(|| {
                err(format!(
                    "names bytes {offset}..+{length} of buffer {source}, which it does not have"
                ))
            })?
            .to_vec();
        let target = view.buffer().index();
        let start = view.offset();
        let place = buffers
            .get_mut(target)
            .and_then(|b| b.get_mut(start..start.checked_add(size)?))
            .ok_or_else(|| err(format!("has no room in buffer {target}")))?;
        decode_buffer_view(place, &compressed, mode, filter, count, stride)
            .map_err(|e| err(format!("stream could not be decoded: {e}")))?;
    }
    Ok(())
}
