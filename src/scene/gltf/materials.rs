//! glTF materials (glTF 2.0 §3.9) reduced to what the methods use: the base colour (its factor,
//! and its texture decoded with its sampler and `KHR_texture_transform`), metallic, roughness,
//! emission (with `KHR_materials_emissive_strength`) and sidedness. A material's one colour,
//! `Material::base_color`, is its factor times its texture's mean texel.

use std::sync::Arc;

use super::{percent_decode, read_uri, Loader};
use crate::scene::texture::{self, Sampler, Texture, TextureRef, Wrap};
use crate::scene::Material;

impl Loader<'_> {
    /// Every material, with its base-colour texture decoded where it can be read (once per
    /// image), and the texture coordinate set each texture reads.
    pub(super) fn materials(&mut self) {
        let doc = self.doc;
        // Every missing external image is reported, also those no method reads (normal maps...).
        for img in doc.images() {
            if let gltf::image::Source::Uri { uri, .. } = img.source() {
                if !uri.starts_with("data:") && !self.base.join(percent_decode(uri)).is_file() {
                    self.warn(format!("image {} ('{uri}') is missing", img.index()));
                    self.images.insert(img.index(), None);
                }
            }
        }
        for m in doc.materials() {
            let pbr = m.pbr_metallic_roughness();
            let factor = pbr.base_color_factor();
            let index = m.index().unwrap_or(0);
            let (texture, set) = match pbr.base_color_texture() {
                Some(info) => self.texture_ref(&info, index),
                None => (None, 0),
            };
            let mean = texture.map(|r| self.parts.textures[r.texture].mean());
            let base_color = match mean {
                Some(t) => [0, 1, 2, 3].map(|k| factor[k] * t[k]),
                None => factor,
            };
            let strength = m
                .extension_value("KHR_materials_emissive_strength")
                .and_then(|v| v.get("emissiveStrength"))
                .and_then(|v| v.as_f64())
                .unwrap_or(1.0) as f32;
            self.texcoord_sets.push(set);
            self.parts.materials.push(Material {
                name: m.name().unwrap_or("").to_string(),
                base_color,
                base_color_factor: factor,
                base_color_textured: mean.is_some(),
                base_color_texture: texture,
                metallic: pbr.metallic_factor(),
                roughness: pbr.roughness_factor(),
                emissive: m.emissive_factor().map(|e| e * strength),
                double_sided: m.double_sided(),
            });
        }
    }

    /// How material `material` reads the texture of `info`: its decoded image, its sampler and
    /// its `KHR_texture_transform`, and the texture coordinate set it names (the transform's
    /// `texCoord` overrides the texture info's). `None` when the image cannot be read.
    fn texture_ref(
        &mut self,
        info: &gltf::texture::Info,
        material: usize,
    ) -> (Option<TextureRef>, u32) {
        let tex = info.texture();
        let transform = info.extension_value("KHR_texture_transform");
        let number = |v: Option<&serde_json::Value>, default: f64| {
            v.and_then(serde_json::Value::as_f64)
                .filter(|x| x.is_finite())
                .unwrap_or(default)
        };
        let pair = |key: &str, default: f64| {
            let v = transform.and_then(|t| t.get(key));
            [0, 1].map(|k| number(v.and_then(|v| v.get(k)), default))
        };
        let set = transform
            .and_then(|t| t.get("texCoord"))
            .and_then(serde_json::Value::as_u64)
            .map_or(info.tex_coord(), |s| s as u32);
        let Some(image) = self.image(tex.source(), material) else {
            return (None, set);
        };
        let s = tex.sampler();
        let wrap =
            |w: gltf::texture::WrappingMode| Wrap::from_gl(w.as_gl_enum()).unwrap_or(Wrap::Repeat);
        let sampler = Sampler {
            wrap: [wrap(s.wrap_s()), wrap(s.wrap_t())],
            ..Sampler::default()
        }
        .with_filters(
            s.mag_filter().map(|f| f.as_gl_enum()),
            s.min_filter().map(|f| f.as_gl_enum()),
        );
        let rotation = number(transform.and_then(|t| t.get("rotation")), 0.0);
        let r = TextureRef {
            texture: image,
            sampler,
            transform: texture::texture_transform(
                pair("offset", 0.0),
                rotation,
                pair("scale", 1.0),
            ),
        };
        (Some(r), set)
    }

    /// The scene's texture of glTF image `image`, decoded on its first use; `None` (with a
    /// warning naming the material) when it cannot be read.
    fn image(&mut self, image: gltf::Image, material: usize) -> Option<usize> {
        if let Some(m) = self.images.get(&image.index()) {
            return *m;
        }
        let bytes = match image.source() {
            gltf::image::Source::View { view, .. } => {
                let buf = &self.buffers[view.buffer().index()];
                buf.get(view.offset()..view.offset() + view.length())
                    .map(<[u8]>::to_vec)
                    .ok_or_else(|| "its buffer view is out of bounds".to_string())
            }
            gltf::image::Source::Uri { uri, .. } => read_uri(uri, self.base),
        };
        let decoded = bytes
            .and_then(|b| texture::decode(&b))
            .and_then(Texture::new);
        let index = match decoded {
            Ok(t) => {
                self.parts.textures.push(Arc::new(t));
                Some(self.parts.textures.len() - 1)
            }
            Err(e) => {
                self.warn(format!(
                    "image {} of material {material} could not be read ({e}); its base colour uses the factor alone",
                    image.index()
                ));
                None
            }
        };
        self.images.insert(image.index(), index);
        index
    }
}
