//! `DepthImages` as OpenEXR: one multi-part file, one part per image, named `view0`, `view1`, …
//! Channels: `Z` (depth, f32), `triangle` (u32 holding the i32 id's bits, so −1 is 0xFFFFFFFF),
//! `N.X N.Y N.Z` (normal), `S.X S.Y S.Z` (shading normal), `P.X P.Y P.Z` (position), `R G B`
//! (base colour), all f32 but the id (a file without `S.*`, written before shading normals,
//! reads with its geometric normals as its shading normals);
//! each part's camera is a JSON text attribute `scenesample.camera`. ZIP compression is
//! lossless and byte-preserving, so reading returns the arrays bit for bit (NaNs included).

use std::path::Path;

use exr::prelude::*;
use glam::DMat4;
use serde_json::{json, Value};
use smallvec::SmallVec;

use crate::camera::{Camera, Projection};
use crate::error::{Error, Result as CoreResult};
use crate::types::DepthImages;

const CAMERA_ATTR: &str = "scenesample.camera";
/// How the images were made (`DepthImages::method`), on every part.
const METHOD_ATTR: &str = "scenesample.method";

fn exr_err(path: &Path, message: impl std::fmt::Display) -> Error {
    Error::Exr {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// Write every image of `img` to one EXR file at `path`.
pub fn write_depth_images(path: &Path, img: &DepthImages) -> CoreResult<()> {
    let (w, h) = (img.width as usize, img.height as usize);
    let npx = w * h;
    let mut layers = Vec::with_capacity(img.n);
    for i in 0..img.n {
        let px = i * npx..(i + 1) * npx;
        let f32s = |name: &str, v: Vec<f32>| AnyChannel::new(name, FlatSamples::F32(v));
        let comp =
            |v: &[[f32; 3]], k: usize| v[px.clone()].iter().map(|p| p[k]).collect::<Vec<f32>>();
        let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
        channels.push(f32s("Z", img.depth[px.clone()].to_vec()));
        channels.push(AnyChannel::new(
            "triangle",
            FlatSamples::U32(img.triangle[px.clone()].iter().map(|&t| t as u32).collect()),
        ));
        for (k, axis) in ["X", "Y", "Z"].iter().enumerate() {
            channels.push(f32s(&format!("N.{axis}"), comp(&img.normal, k)));
            channels.push(f32s(&format!("S.{axis}"), comp(&img.shading_normal, k)));
            channels.push(f32s(&format!("P.{axis}"), comp(&img.position, k)));
        }
        for (k, c) in ["R", "G", "B"].iter().enumerate() {
            channels.push(f32s(c, comp(&img.color, k)));
        }
        let mut attrs = LayerAttributes::named(format!("view{i}").as_str());
        let cam = ascii_json(&camera_json(&img.cameras[i]));
        let text = Text::new_or_none(&cam)
            .ok_or_else(|| exr_err(path, "camera metadata is not representable as EXR text"))?;
        attrs
            .other
            .insert(Text::from(CAMERA_ATTR), AttributeValue::Text(text));
        let method = Text::new_or_none(img.method.as_str())
            .ok_or_else(|| exr_err(path, "the method name is not representable as EXR text"))?;
        attrs
            .other
            .insert(Text::from(METHOD_ATTR), AttributeValue::Text(method));
        layers.push(Layer::new(
            (w, h),
            attrs,
            Encoding::SMALL_LOSSLESS,
            AnyChannels::sort(channels),
        ));
    }
    let image = Image::from_layers(
        ImageAttributes::new(IntegerBounds::from_dimensions((w, h))),
        layers,
    );
    image
        .write()
        .to_file(path)
        .map_err(|e| exr_err(path, format!("cannot write EXR: {e}")))
}

/// Read a file written by `write_depth_images`.
pub fn read_depth_images(path: &Path) -> CoreResult<DepthImages> {
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_file(path)
        .map_err(|e| exr_err(path, format!("cannot read EXR: {e}")))?;
    let layers = &image.layer_data;
    let Some(first) = layers.first() else {
        return Err(exr_err(path, "the file has no images"));
    };
    let (w, h) = (first.size.width(), first.size.height());
    let npx = w * h;
    let mut out = DepthImages {
        n: layers.len(),
        width: w as u32,
        height: h as u32,
        ..Default::default()
    };
    for (i, layer) in layers.iter().enumerate() {
        if (layer.size.width(), layer.size.height()) != (w, h) {
            return Err(exr_err(
                path,
                format!(
                    "part {i} is {}x{}, part 0 is {w}x{h}",
                    layer.size.width(),
                    layer.size.height()
                ),
            ));
        }
        let chan = |name: &str| -> CoreResult<&FlatSamples> {
            layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name == *name)
                .map(|c| &c.sample_data)
                .ok_or_else(|| {
                    exr_err(
                        path,
                        format!("part {i} has no channel '{name}' (not written by scenesample?)"),
                    )
                })
        };
        let f = |name: &str| -> CoreResult<Vec<f32>> {
            match chan(name)? {
                FlatSamples::F32(v) if v.len() == npx => Ok(v.clone()),
                _ => Err(exr_err(
                    path,
                    format!("part {i} channel '{name}' is not {npx} f32 samples"),
                )),
            }
        };
        out.depth.extend(f("Z")?);
        match chan("triangle")? {
            FlatSamples::U32(v) if v.len() == npx => {
                out.triangle.extend(v.iter().map(|&t| t as i32))
            }
            _ => {
                return Err(exr_err(
                    path,
                    format!("part {i} channel 'triangle' is not {npx} u32 samples"),
                ))
            }
        }
        let vec3 = |names: [&str; 3]| -> CoreResult<Vec<[f32; 3]>> {
            let [a, b, c] = [f(names[0])?, f(names[1])?, f(names[2])?];
            Ok((0..npx).map(|k| [a[k], b[k], c[k]]).collect())
        };
        let normal = vec3(["N.X", "N.Y", "N.Z"])?;
        let shading = match chan("S.X") {
            Ok(_) => vec3(["S.X", "S.Y", "S.Z"])?,
            Err(_) => normal.clone(),
        };
        out.normal.extend(normal);
        out.shading_normal.extend(shading);
        out.position.extend(vec3(["P.X", "P.Y", "P.Z"])?);
        out.color.extend(vec3(["R", "G", "B"])?);
        let cam = match layer.attributes.other.get(&Text::from(CAMERA_ATTR)) {
            Some(AttributeValue::Text(t)) => camera_from_json(&t.to_string())
                .map_err(|m| exr_err(path, format!("part {i}: {m}")))?,
            _ => {
                return Err(exr_err(
                    path,
                    format!("part {i} has no '{CAMERA_ATTR}' attribute"),
                ))
            }
        };
        out.cameras.push(cam);
        // Files from before the attribute existed hold conventional images.
        out.method = match layer.attributes.other.get(&Text::from(METHOD_ATTR)) {
            Some(AttributeValue::Text(t)) => t.to_string(),
            _ => "conventional".into(),
        };
    }
    Ok(out)
}

fn f64_json(x: Option<f64>) -> Value {
    match x {
        Some(v) if v.is_infinite() => json!("inf"),
        Some(v) => json!(v),
        None => Value::Null,
    }
}

pub fn camera_json(c: &Camera) -> Value {
    // Row-major, like the numpy `pose` property.
    let pose: Vec<f64> = c.pose.transpose().to_cols_array().to_vec();
    let mut v = json!({
        "pose": pose, "width": c.width, "height": c.height,
        "znear": f64_json(c.znear), "zfar": f64_json(c.zfar), "name": c.name,
    });
    match c.projection {
        Projection::Perspective { yfov } => {
            v["projection"] = json!("perspective");
            v["yfov"] = json!(yfov);
        }
        Projection::Orthographic { xmag, ymag } => {
            v["projection"] = json!("orthographic");
            v["xmag"] = json!(xmag);
            v["ymag"] = json!(ymag);
        }
    }
    v
}

pub fn camera_from_json(s: &str) -> std::result::Result<Camera, String> {
    let v: Value = serde_json::from_str(s).map_err(|e| format!("bad camera metadata: {e}"))?;
    let num = |k: &str| {
        v[k].as_f64()
            .ok_or_else(|| format!("camera metadata lacks '{k}'"))
    };
    let opt = |k: &str| match &v[k] {
        Value::Null => Ok(None),
        Value::String(s) if s == "inf" => Ok(Some(f64::INFINITY)),
        x => x
            .as_f64()
            .map(Some)
            .ok_or_else(|| format!("camera metadata '{k}' is not a number")),
    };
    let pose: Vec<f64> = v["pose"]
        .as_array()
        .ok_or("camera metadata lacks 'pose'")?
        .iter()
        .filter_map(Value::as_f64)
        .collect();
    let pose: [f64; 16] = pose
        .try_into()
        .map_err(|_| "camera pose must have 16 numbers".to_string())?;
    let projection = match v["projection"].as_str() {
        Some("perspective") => Projection::Perspective { yfov: num("yfov")? },
        Some("orthographic") => Projection::Orthographic {
            xmag: num("xmag")?,
            ymag: num("ymag")?,
        },
        other => return Err(format!("unknown projection {other:?}")),
    };
    let mut c = Camera::new(
        DMat4::from_cols_array(&pose).transpose(),
        projection,
        num("width")? as u32,
        num("height")? as u32,
        opt("znear")?,
        opt("zfar")?,
    )
    .map_err(|e| e.to_string())?;
    c.name = v["name"].as_str().map(str::to_string);
    Ok(c)
}

/// JSON text with every non-ASCII character escaped (EXR text attributes are byte strings).
fn ascii_json(v: &Value) -> String {
    let mut out = String::new();
    for c in v.to_string().chars() {
        if c.is_ascii() {
            out.push(c);
        } else {
            let mut buf = [0u16; 2];
            for u in c.encode_utf16(&mut buf) {
                out.push_str(&format!("\\u{u:04x}"));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn round_trip_is_bit_exact() {
        let cam = Camera::look_at(
            DVec3::new(1e5, 2.0, 3.0),
            DVec3::ZERO,
            DVec3::Y,
            0.7,
            3,
            2,
            None,
            Some(f64::INFINITY),
        )
        .unwrap();
        let mut cam2 = cam.clone();
        cam2.name = Some("naïve ☃".into());
        let img = DepthImages {
            n: 2,
            width: 3,
            height: 2,
            depth: (0..12)
                .map(|i| {
                    if i % 5 == 0 {
                        f32::INFINITY
                    } else {
                        i as f32 * 0.1
                    }
                })
                .collect(),
            triangle: (0..12).map(|i| if i % 5 == 0 { -1 } else { i }).collect(),
            normal: (0..12).map(|i| [i as f32, -1.0, 0.5]).collect(),
            shading_normal: (0..12).map(|i| [0.5, i as f32, -1.0]).collect(),
            position: (0..12)
                .map(|i| {
                    if i % 5 == 0 {
                        [f32::NAN; 3]
                    } else {
                        [1e5 + i as f32, 0.25, 3.0]
                    }
                })
                .collect(),
            color: (0..12).map(|i| [0.1 * i as f32, 0.2, 0.3]).collect(),
            cameras: vec![cam, cam2],
            method: "peeling".into(),
            timings: crate::types::Timings::new(),
        };
        let path = std::env::temp_dir().join(format!("scenesample-exr-{}.exr", std::process::id()));
        write_depth_images(&path, &img).unwrap();
        let back = read_depth_images(&path).unwrap();
        std::fs::remove_file(&path).ok();
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.depth), bits(&img.depth));
        assert_eq!(back.triangle, img.triangle);
        assert_eq!(
            bits(back.position.as_flattened()),
            bits(img.position.as_flattened())
        );
        assert_eq!(
            bits(back.normal.as_flattened()),
            bits(img.normal.as_flattened())
        );
        assert_eq!(
            bits(back.shading_normal.as_flattened()),
            bits(img.shading_normal.as_flattened())
        );
        assert_eq!(
            bits(back.color.as_flattened()),
            bits(img.color.as_flattened())
        );
        assert_eq!(back.cameras, img.cameras);
        assert_eq!(back.method, "peeling");
    }
}
