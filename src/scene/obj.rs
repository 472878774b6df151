//! Wavefront OBJ with MTL materials, read natively so the effect planner sees the materials of
//! the most common research format.
//!
//! Geometry: `v` (with the optional per-vertex colour `v x y z r g b`), `vt` and `vn`, `f` (any
//! polygon, fan triangulated; `v`, `v/vt`, `v//vn`, `v/vt/vn`; negative indices count back from
//! the last one), `o` and `g` (object ids), `usemtl`, `mtllib`. A corner's `vn` is its shading
//! normal (a corner without one gets the area-weighted normal of its faces, as for glTF) and
//! its `vt` its texture coordinate (v up, as OBJ has it). Lines, points, smoothing groups and
//! free-form geometry are not used.
//!
//! Materials (MTL), mapped onto the metallic-roughness model the package uses:
//! - `Kd` (default 0.8 grey) times `map_Kd` sampled at each point (sRGB decoded, filtered as
//!   for glTF, `surface`), with its `-o` offset, `-s` scale and `-clamp on`; the material's one
//!   colour (`Material::base_color`) is `Kd` times the texture's mean texel;
//! - `Ke` is the emissive colour;
//! - roughness: `Pr` when given, else from the specular exponent `Ns` as
//!   `1 - sqrt(clamp(Ns, 0, 1000) / 1000)` (the inverse of Blender's exporter), else 1;
//! - metallic: `Pm` when given, else 0 (an OBJ material is a dielectric unless it says so);
//! - alpha: `d`, else `1 - Tr`, else 1;
//! - OBJ has no back faces: every material is double sided.
//!
//! A missing MTL file, texture or material name is a warning (`Scene::warnings`), never an
//! error: the faces keep the material's factors, or no material. File names may contain
//! spaces, and Windows separators (`textures\wood.png`) are accepted.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::texture::{self, Sampler, Texture, TextureRef, Wrap};
use super::{Material, Scene, SceneParts};
use crate::error::{Error, Result};

/// Load an OBJ file and the MTL files it names.
pub fn load(path: &Path) -> Result<Scene> {
    let bytes = std::fs::read(path).map_err(|e| Error::SceneFile {
        path: path.to_path_buf(),
        message: format!("cannot read the file: {e}"),
    })?;
    let text = String::from_utf8_lossy(&bytes);
    let parts = parse(&text, path.parent().unwrap_or(Path::new(".")), path)?;
    Scene::new(parts).map_err(|e| match e {
        Error::Scene(m) => Error::Scene(format!("{}: {m}", path.display())),
        other => other,
    })
}

/// What the OBJ text defines, before faces are split by material.
struct Reader<'a> {
    base: &'a Path,
    path: &'a Path,
    positions: Vec<[f32; 3]>,
    /// Per position, its colour when the file gives one.
    vertex_colors: Vec<Option<[f32; 3]>>,
    /// `vt` and `vn` statements, in order.
    texcoords: Vec<[f32; 2]>,
    normals: Vec<[f32; 3]>,
    materials: Vec<Material>,
    by_name: HashMap<String, usize>,
    objects: Vec<String>,
    object_of: HashMap<String, usize>,
    /// A corner (position, `vt`, `vn`; `u32::MAX` for none) of a face of a material -> output
    /// vertex: a position used with several texture coordinates, normals or materials becomes
    /// one vertex per combination.
    vertex_of: HashMap<(Corner, i32), u32>,
    parts: SceneParts,
    /// Warnings already given, so a repeated problem is reported once.
    said: std::collections::HashSet<String>,
}

fn parse(text: &str, base: &Path, path: &Path) -> Result<SceneParts> {
    let mut r = Reader {
        base,
        path,
        positions: Vec::new(),
        vertex_colors: Vec::new(),
        texcoords: Vec::new(),
        normals: Vec::new(),
        materials: Vec::new(),
        by_name: HashMap::new(),
        objects: Vec::new(),
        object_of: HashMap::new(),
        vertex_of: HashMap::new(),
        parts: SceneParts::default(),
        said: Default::default(),
    };
    let stem = path
        .file_stem()
        .map_or("mesh".to_string(), |s| s.to_string_lossy().into_owned());
    // Faces before any `o`/`g` belong to an object named after the file.
    let mut object: Option<i32> = None;
    let mut material = -1i32;
    // A line ending in a backslash continues on the next.
    let mut joined = String::new();
    for (number, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim_end();
        if let Some(head) = line.strip_suffix('\\') {
            joined.push_str(head);
            joined.push(' ');
            continue;
        }
        joined.push_str(line);
        let line = std::mem::take(&mut joined);
        let line = line.trim();
        let (key, rest) = line.split_once(char::is_whitespace).unwrap_or((line, ""));
        let rest = rest.trim();
        let at = || format!("{}:{}", path.display(), number + 1);
        match key {
            "v" | "vt" | "vn" => r.vertex_data(key, rest, &at)?,
            "f" => {
                let o = match object {
                    Some(o) => o,
                    None => *object.insert(r.object(&stem)),
                };
                r.face(rest, o, material, &at)?
            }
            "o" | "g" => {
                let name = if rest.is_empty() { stem.as_str() } else { rest };
                object = Some(r.object(name));
            }
            "usemtl" => {
                material = match r.by_name.get(rest) {
                    Some(&m) => m as i32,
                    None => {
                        r.warn(format!(
                            "{}: material {rest:?} is not defined in any MTL file; its faces \
                             have no material",
                            path.display()
                        ));
                        -1
                    }
                };
            }
            "mtllib" => r.mtllib(rest),
            "l" | "p" | "curv" | "curv2" | "surf" => r.warn(format!(
                "{}: {key} elements (lines, points, free-form geometry) are not triangles and \
                 were skipped",
                path.display()
            )),
            _ => {}
        }
    }
    let Reader {
        mut parts,
        materials,
        objects,
        ..
    } = r;
    // A texture whose faces give no `vt` is read at (0, 0).
    if parts.texcoords.is_none() && materials.iter().any(|m| m.base_color_texture.is_some()) {
        parts.texcoords = Some(vec![[0.0; 2]; parts.vertices.len()]);
    }
    parts.materials = materials;
    parts.objects = objects;
    Ok(parts)
}

impl Reader<'_> {
    fn err(&self, at: &str, message: impl std::fmt::Display) -> Error {
        Error::Scene(format!("{at}: {message}"))
    }

    /// `v x y z [r g b]`, `vt u [v]` or `vn x y z`.
    fn vertex_data(&mut self, key: &str, rest: &str, at: &dyn Fn() -> String) -> Result<()> {
        let x: Vec<f32> = numbers(rest).map_err(|m| self.err(&at(), m))?;
        let get = |k: usize| x.get(k).copied().unwrap_or(0.0);
        let what = if key == "v" { "vertex" } else { "normal" };
        if key != "vt" && x.len() < 3 {
            return Err(self.err(&at(), format!("a {what} needs 3 coordinates: {key} {rest}")));
        }
        match key {
            "v" => {
                self.positions.push([x[0], x[1], x[2]]);
                self.vertex_colors
                    .push((x.len() >= 6).then(|| [x[3], x[4], x[5]]));
            }
            "vt" => self.texcoords.push([get(0), get(1)]),
            _ => self.normals.push([x[0], x[1], x[2]]),
        }
        Ok(())
    }

    fn warn(&mut self, message: String) {
        if self.said.insert(message.clone()) {
            self.parts.warnings.push(message);
        }
    }

    fn object(&mut self, name: &str) -> i32 {
        if let Some(&i) = self.object_of.get(name) {
            return i as i32;
        }
        self.objects.push(name.to_string());
        self.object_of
            .insert(name.to_string(), self.objects.len() - 1);
        (self.objects.len() - 1) as i32
    }

    /// `f a b c ...`: a fan of triangles around the first corner.
    fn face(
        &mut self,
        rest: &str,
        object: i32,
        material: i32,
        at: &dyn Fn() -> String,
    ) -> Result<()> {
        let mut corners = Vec::with_capacity(4);
        for token in rest.split_whitespace() {
            let mut refs = token.split('/');
            let counts = [
                ("vertex", self.positions.len()),
                ("texture coordinate", self.texcoords.len()),
                ("normal", self.normals.len()),
            ];
            let mut corner = [u32::MAX; 3];
            for (k, (what, n)) in counts.into_iter().enumerate() {
                let Some(text) = refs.next().filter(|t| !t.is_empty() || k == 0) else {
                    continue;
                };
                let i: i64 = text
                    .parse()
                    .map_err(|_| self.err(&at(), format!("bad {what} reference {token:?}")))?;
                let n = n as i64;
                let index = if i < 0 { n + i } else { i - 1 };
                if i == 0 || !(0..n).contains(&index) {
                    let message = format!("{what} {i} does not exist ({n} defined so far)");
                    if k == 0 {
                        return Err(self.err(&at(), message));
                    }
                    // A corner's missing texture coordinate or normal is left out, as
                    // viewers do.
                    self.warn(format!("{}: {message}; the corner has none", at()));
                    continue;
                }
                corner[k] = index as u32;
            }
            corners.push(self.vertex(corner, material));
        }
        if corners.len() < 3 {
            self.warn(format!(
                "{}: faces with fewer than 3 corners were skipped",
                self.path.display()
            ));
            return Ok(());
        }
        for k in 1..corners.len() - 1 {
            self.parts
                .faces
                .push([corners[0], corners[k], corners[k + 1]]);
            self.parts.material_ids.push(material);
            self.parts.object_ids.push(object);
        }
        Ok(())
    }

    /// The output vertex of `corner` for faces of `material`: its position, colour (`Kd` times
    /// the vertex colour), texture coordinate and normal. Normals and texture coordinates start
    /// (zero-filled for the vertices before) with the first corner that has one.
    fn vertex(&mut self, corner: Corner, material: i32) -> u32 {
        if let Some(&v) = self.vertex_of.get(&(corner, material)) {
            return v;
        }
        let [position, vt, vn] = corner.map(|i| (i != u32::MAX).then_some(i as usize));
        let position = position.unwrap_or(0);
        let parts = &mut self.parts;
        let before = parts.vertices.len();
        let v = before as u32;
        parts.vertices.push(self.positions[position]);
        let base = usize::try_from(material)
            .ok()
            .map_or([1.0; 4], |m| self.materials[m].base_color_factor);
        let c = self.vertex_colors[position].unwrap_or([1.0; 3]);
        parts.colors.get_or_insert_with(Vec::new).push([
            base[0] * c[0],
            base[1] * c[1],
            base[2] * c[2],
        ]);
        if let Some(k) = vt {
            let uv = parts
                .texcoords
                .get_or_insert_with(|| vec![[0.0; 2]; before]);
            uv.push(self.texcoords[k]);
        } else if let Some(uv) = parts.texcoords.as_mut() {
            uv.push([0.0; 2]);
        }
        if let Some(k) = vn {
            let ns = parts.normals.get_or_insert_with(|| vec![[0.0; 3]; before]);
            ns.push(self.normals[k]);
        } else if let Some(ns) = parts.normals.as_mut() {
            ns.push([0.0; 3]);
        }
        self.vertex_of.insert((corner, material), v);
        v
    }

    /// `mtllib a.mtl [b.mtl ...]`: the whole argument as one file name if it exists (names may
    /// contain spaces), else each word.
    fn mtllib(&mut self, rest: &str) {
        let names: Vec<String> = if self.find(rest).is_some() {
            vec![rest.to_string()]
        } else {
            rest.split_whitespace().map(str::to_string).collect()
        };
        for name in names {
            match self.find(&name) {
                Some(file) => match std::fs::read(&file) {
                    Ok(bytes) => self.mtl(&String::from_utf8_lossy(&bytes), &file),
                    Err(e) => self.warn(format!(
                        "{}: cannot read the MTL file {}: {e}; its materials are missing",
                        self.path.display(),
                        file.display()
                    )),
                },
                None => self.warn(format!(
                    "{}: the MTL file {name:?} is missing; faces using its materials have no \
                     material",
                    self.path.display()
                )),
            }
        }
    }

    /// The file `name` refers to, relative to the OBJ's folder, with Windows separators too.
    fn find(&self, name: &str) -> Option<PathBuf> {
        let name = name.trim().trim_matches('"');
        if name.is_empty() {
            return None;
        }
        let unix = name.replace('\\', "/");
        [name.to_string(), unix]
            .iter()
            .map(|n| self.base.join(n))
            .find(|p| p.is_file())
    }

    fn mtl(&mut self, text: &str, file: &Path) {
        let mut current: Option<(Material, Mtl)> = None;
        for line in text.lines() {
            let line = line.split('#').next().unwrap_or("").trim();
            let (key, rest) = line.split_once(char::is_whitespace).unwrap_or((line, ""));
            let rest = rest.trim();
            if key == "newmtl" {
                if let Some(done) = current.take() {
                    self.add_material(done, file);
                }
                let m = Material {
                    name: rest.to_string(),
                    base_color: [0.8, 0.8, 0.8, 1.0],
                    base_color_factor: [0.8, 0.8, 0.8, 1.0],
                    metallic: 0.0,
                    roughness: 1.0,
                    double_sided: true,
                    ..Material::default()
                };
                current = Some((m, Mtl::default()));
                continue;
            }
            let Some((m, extra)) = current.as_mut() else {
                continue;
            };
            let vals = || numbers(rest).unwrap_or_default();
            let rgb = |v: Vec<f32>| match v.len() {
                0 => None,
                1 | 2 => Some([v[0]; 3]),
                _ => Some([v[0], v[1], v[2]]),
            };
            match key {
                "Kd" => {
                    if let Some(c) = rgb(vals()) {
                        m.base_color_factor[..3].copy_from_slice(&c);
                    }
                }
                "Ke" => {
                    if let Some(c) = rgb(vals()) {
                        m.emissive = c;
                    }
                }
                "Ns" => extra.ns = vals().first().copied(),
                "Pr" => extra.pr = vals().first().copied(),
                "Pm" => extra.pm = vals().first().copied(),
                "d" => extra.d = vals().last().copied(),
                "Tr" => extra.tr = vals().last().copied(),
                "map_Kd" => extra.map_kd = Some(rest.to_string()),
                _ => {}
            }
        }
        if let Some(done) = current.take() {
            self.add_material(done, file);
        }
    }

    fn add_material(&mut self, (mut m, x): (Material, Mtl), file: &Path) {
        m.roughness = match (x.pr, x.ns) {
            (Some(pr), _) => pr.clamp(0.0, 1.0),
            (None, Some(ns)) => 1.0 - (ns.clamp(0.0, 1000.0) / 1000.0).sqrt(),
            (None, None) => 1.0,
        };
        m.metallic = x.pm.map_or(0.0, |p| p.clamp(0.0, 1.0));
        m.base_color_factor[3] = match (x.d, x.tr) {
            (Some(d), _) => d.clamp(0.0, 1.0),
            (None, Some(tr)) => 1.0 - tr.clamp(0.0, 1.0),
            (None, None) => 1.0,
        };
        m.base_color = m.base_color_factor;
        if let Some(statement) = x.map_kd {
            let map = MapKd::parse(&statement);
            match self.texture(&map.file, file) {
                Ok(t) => {
                    let mean = t.mean();
                    for (c, t) in m.base_color.iter_mut().zip(mean) {
                        *c *= t;
                    }
                    m.base_color_textured = true;
                    self.parts.textures.push(Arc::new(t));
                    m.base_color_texture = Some(map.binding(self.parts.textures.len() - 1));
                }
                Err(e) => self.warn(format!(
                    "{}: material {:?}: {e}; its colour is Kd alone",
                    file.display(),
                    m.name
                )),
            }
        }
        // A later definition of the same name wins, as in most OBJ readers.
        match self.by_name.get(&m.name) {
            Some(&i) => self.materials[i] = m,
            None => {
                self.by_name.insert(m.name.clone(), self.materials.len());
                self.materials.push(m);
            }
        }
    }
}

impl Reader<'_> {
    /// The texture of the image `name` (relative to the MTL file `file`), decoded.
    fn texture(&self, name: &str, file: &Path) -> std::result::Result<Texture, String> {
        if name.is_empty() {
            return Err("map_Kd names no file".into());
        }
        let base = file.parent().unwrap_or(Path::new("."));
        let found = [name.to_string(), name.replace('\\', "/")]
            .iter()
            .map(|n| base.join(n))
            .find(|p| p.is_file())
            .ok_or_else(|| format!("the texture {name:?} is missing"))?;
        std::fs::read(&found)
            .map_err(|e| e.to_string())
            .and_then(|b| texture::decode(&b))
            .and_then(Texture::new)
            .map_err(|e| format!("cannot decode {}: {e}", found.display()))
    }
}

/// A corner of a face: its position, `vt` and `vn` (0-based; `u32::MAX` for none).
type Corner = [u32; 3];

/// The MTL statements that need the whole material before they can be applied.
#[derive(Default)]
struct Mtl {
    ns: Option<f32>,
    pr: Option<f32>,
    pm: Option<f32>,
    d: Option<f32>,
    tr: Option<f32>,
    map_kd: Option<String>,
}

/// Whitespace-separated floats.
fn numbers(s: &str) -> std::result::Result<Vec<f32>, String> {
    s.split_whitespace()
        .map(|t| {
            t.parse::<f32>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("{t:?} is not a finite number"))
        })
        .collect()
}

/// A `map_Kd` statement: its file name (what follows its options, spaces included) and the
/// options that change where the texture is read: `-o` (offset), `-s` (scale) and `-clamp`.
#[derive(Debug, PartialEq)]
struct MapKd {
    file: String,
    offset: [f64; 2],
    scale: [f64; 2],
    clamp: bool,
}

impl MapKd {
    fn parse(rest: &str) -> MapKd {
        let args = |opt: &str| match opt {
            "-o" | "-s" | "-t" => 3,
            "-mm" => 2,
            "-bm" | "-boost" | "-texres" | "-blendu" | "-blendv" | "-clamp" | "-cc"
            | "-imfchan" | "-type" => 1,
            _ => 0,
        };
        let mut map = MapKd {
            file: String::new(),
            offset: [0.0; 2],
            scale: [1.0; 2],
            clamp: false,
        };
        let words: Vec<&str> = rest.split_whitespace().collect();
        let mut i = 0;
        while i < words.len() && words[i].starts_with('-') && words[i].len() > 1 {
            let n = args(words[i]);
            // Options with up to three numbers: take only the numbers.
            let mut taken = Vec::new();
            while taken.len() < n && i + 1 + taken.len() < words.len() {
                let w = words[i + 1 + taken.len()];
                if n == 1 || w.parse::<f64>().is_ok() {
                    taken.push(w);
                } else {
                    break;
                }
            }
            let num = |k: usize, default: f64| {
                taken
                    .get(k)
                    .and_then(|w| w.parse::<f64>().ok())
                    .filter(|x| x.is_finite())
                    .unwrap_or(default)
            };
            match words[i] {
                "-o" => map.offset = [num(0, 0.0), num(1, 0.0)],
                "-s" => map.scale = [num(0, 1.0), num(1, 1.0)],
                "-clamp" => map.clamp = taken.first() == Some(&"on"),
                _ => {}
            }
            i += 1 + taken.len();
        }
        map.file = words[i.min(words.len())..].join(" ");
        map
    }

    /// How a material reads texture `texture`: OBJ's `vt` has v up, so the lookup is at
    /// `(s_u·u + o_u, 1 − (s_v·v + o_v))` in the image (row 0 at the top); repeat or clamp.
    fn binding(&self, texture: usize) -> TextureRef {
        let wrap = if self.clamp {
            Wrap::ClampToEdge
        } else {
            Wrap::Repeat
        };
        TextureRef {
            texture,
            sampler: Sampler {
                wrap: [wrap; 2],
                ..Sampler::default()
            },
            transform: [
                self.scale[0],
                0.0,
                self.offset[0],
                0.0,
                -self.scale[1],
                1.0 - self.offset[1],
            ],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_options_are_read_and_spaces_kept() {
        let m = MapKd::parse("-s 2 3 1 -bm 0.5 my tex.png");
        assert_eq!(
            (m.file.as_str(), m.scale, m.clamp),
            ("my tex.png", [2.0, 3.0], false)
        );
        let m = MapKd::parse("-clamp on .\\textures\\a.jpg");
        assert_eq!((m.file.as_str(), m.clamp), (".\\textures\\a.jpg", true));
        let m = MapKd::parse("-o 0.5 wood.png");
        assert_eq!((m.file.as_str(), m.offset), ("wood.png", [0.5, 0.0]));
        assert_eq!(MapKd::parse("plain.png").file, "plain.png");
        // v up in OBJ, down in the image: (0.25, 0.75) is read at (0.25, 0.25).
        let r = MapKd::parse("plain.png").binding(0);
        assert_eq!(r.apply([0.25, 0.75]), [0.25, 0.25]);
    }

    #[test]
    fn polygons_fan_and_negative_indices_count_back() {
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\nf -4/1 -3//2 -1/3/4\n";
        let p = parse(text, Path::new("."), Path::new("t.obj")).unwrap();
        assert_eq!(p.faces.len(), 3);
        assert_eq!(p.faces[0], [0, 1, 2]);
        assert_eq!(p.faces[1], [0, 2, 3]);
        assert_eq!(p.faces[2], [0, 1, 3]);
        assert_eq!(p.objects, vec!["t".to_string()]);
        assert!(p.material_ids.iter().all(|&m| m == -1));
    }

    #[test]
    fn bad_references_are_scene_errors_with_the_line() {
        for text in [
            "v 0 0 0\nf 1 2 3\n",
            "v 0 0 0\nf 1 x 1\n",
            "v 0 nan 0\n",
            "v 0 0\n",
        ] {
            match parse(text, Path::new("."), Path::new("t.obj")) {
                Err(Error::Scene(m)) => assert!(m.contains("t.obj:"), "{m}"),
                other => panic!("{text:?}: {other:?}"),
            }
        }
    }
}
