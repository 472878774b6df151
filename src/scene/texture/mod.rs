//! Base-colour textures as viewers sample them (glTF 2.0 §3.8 and §5.26, OpenGL 4.6 §8.14): the
//! decoded sRGB texels and a mip chain, looked up at a texture coordinate with the sampler's
//! wrap modes and filters. Texels are decoded from sRGB to linear before they are filtered, as
//! a GPU does for an sRGB texture; a magnified texture is filtered bilinearly, a minified one
//! trilinearly between the two mip levels that bracket the footprint's level of detail
//! λ = log2 ρ, ρ the footprint's longer side in texels (the isotropic rule of OpenGL §8.14.1).
//! The mip levels halve each side (rounded down, at least 1) and average their parent's 2×2
//! texels in linear space (3 texels across an odd side).
//!
//! Every level is stored decoded, as linear 16-bit RGBA (the sRGB decode done once, when the
//! texture is made): a lookup then converts and blends four texels as four-lane vectors, with
//! no table per channel. 16 bits hold every 8-bit sRGB value apart (the closest two, 0 and 1,
//! are 20 steps apart) and give it back exactly ([`Texture::texels`]); a texel reads within
//! 8e-6 of its exact decode.
//!
//! A material also keeps its texture's mean texel, for the methods that need one colour per
//! material (`Material::base_color`).

mod decode;

use std::sync::LazyLock;

use glam::Vec4;

pub use decode::{decode, Rgba8};

/// 8-bit sRGB to linear, per value.
static SRGB_TO_LINEAR: LazyLock<[f32; 256]> =
    LazyLock::new(|| std::array::from_fn(|i| srgb8_to_linear_f64(i as u8) as f32));

/// 8-bit sRGB to linear 16-bit (0..65535), rounded to the nearest value.
static SRGB_TO_LINEAR16: LazyLock<[u16; 256]> = LazyLock::new(|| {
    std::array::from_fn(|i| (srgb8_to_linear_f64(i as u8) * 65535.0).round() as u16)
});

/// 8-bit sRGB to linear, in f64 (IEC 61966-2-1).
fn srgb8_to_linear_f64(v: u8) -> f64 {
    let c = f64::from(v) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear [0, 1] to 8-bit sRGB, rounded to the nearest value.
fn linear_to_srgb8(v: f64) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let s = if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// The sRGB decode of one 8-bit value.
pub fn srgb_to_linear(v: u8) -> f32 {
    SRGB_TO_LINEAR[v as usize]
}

/// How a texture coordinate outside [0, 1] reaches the texture (glTF's sampler `wrapS` /
/// `wrapT`; REPEAT when the file gives none).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum Wrap {
    #[default]
    Repeat,
    ClampToEdge,
    MirroredRepeat,
}

impl Wrap {
    /// From glTF's enum value (10497, 33071, 33648); `None` for any other.
    pub fn from_gl(v: u32) -> Option<Wrap> {
        match v {
            10497 => Some(Wrap::Repeat),
            33071 => Some(Wrap::ClampToEdge),
            33648 => Some(Wrap::MirroredRepeat),
            _ => None,
        }
    }

    /// Texel index `i` of a side of `n` texels, wrapped into `0..n`.
    #[inline(always)]
    fn index(self, i: i64, n: i64) -> usize {
        (match self {
            Wrap::Repeat => period(i, n),
            Wrap::ClampToEdge => i.clamp(0, n - 1),
            Wrap::MirroredRepeat => {
                let m = period(i, 2 * n);
                if m < n {
                    m
                } else {
                    2 * n - 1 - m
                }
            }
        }) as usize
    }
}

/// `i` modulo `p` in `0..p`: a step of one period where the lookups keep `i` (their coordinate
/// wrapped to within two periods first, `reduce`), a division only beyond.
#[inline(always)]
fn period(i: i64, p: i64) -> i64 {
    if (0..p).contains(&i) {
        i
    } else if (-p..0).contains(&i) {
        i + p
    } else if (p..2 * p).contains(&i) {
        i - p
    } else {
        i.rem_euclid(p)
    }
}

/// A sampler: wrap modes and filters (glTF 2.0 §5.26; a file without one samples as viewers
/// do by default: REPEAT, LINEAR magnification, LINEAR_MIPMAP_LINEAR minification).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sampler {
    pub wrap: [Wrap; 2],
    /// Magnification by the nearest texel rather than bilinearly (magFilter NEAREST).
    pub mag_nearest: bool,
    /// Minification within a level by the nearest texel (minFilter NEAREST*).
    pub min_nearest: bool,
    /// How minification uses the mip levels: none (level 0 only: NEAREST, LINEAR), the nearest
    /// level (`*_MIPMAP_NEAREST`) or the two around it (`*_MIPMAP_LINEAR`).
    pub mipmap: Mipmap,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Mipmap {
    None,
    Nearest,
    Linear,
}

impl Default for Sampler {
    fn default() -> Self {
        Sampler {
            wrap: [Wrap::Repeat; 2],
            mag_nearest: false,
            min_nearest: false,
            mipmap: Mipmap::Linear,
        }
    }
}

impl Sampler {
    /// From glTF's `magFilter` and `minFilter` enum values (absent: the defaults); unknown
    /// values keep the default.
    pub fn with_filters(mut self, mag: Option<u32>, min: Option<u32>) -> Self {
        if let Some(m) = mag {
            self.mag_nearest = m == 9728;
        }
        if let Some(m) = min {
            (self.min_nearest, self.mipmap) = match m {
                9728 => (true, Mipmap::None),
                9729 => (false, Mipmap::None),
                9984 => (true, Mipmap::Nearest),
                9985 => (false, Mipmap::Nearest),
                9986 => (true, Mipmap::Linear),
                _ => (false, Mipmap::Linear),
            };
        }
        self
    }
}

/// How a material reads its base-colour texture: which of the scene's textures, with what
/// sampler, and the `KHR_texture_transform` of the coordinates (an affine map, row-major 2×3:
/// `u' = m[0]·u + m[1]·v + m[2]`, `v' = m[3]·u + m[4]·v + m[5]`; the identity without one).
/// The texture coordinate set it names is read at load, into the scene's texture coordinates.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TextureRef {
    pub texture: usize,
    pub sampler: Sampler,
    pub transform: [f64; 6],
}

/// The identity texture transform.
pub const IDENTITY_TRANSFORM: [f64; 6] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// `KHR_texture_transform`'s offset, rotation and scale as one map, `T · R · S` with the
/// rotation `[[cos, sin], [−sin, cos]]` as Khronos' sample renderer applies it (counter-clockwise
/// in texture space, whose v axis points down the image).
pub fn texture_transform(offset: [f64; 2], rotation: f64, scale: [f64; 2]) -> [f64; 6] {
    let (s, c) = rotation.sin_cos();
    [
        c * scale[0],
        s * scale[1],
        offset[0],
        -s * scale[0],
        c * scale[1],
        offset[1],
    ]
}

impl TextureRef {
    /// Texture coordinate `uv` through the transform.
    #[inline]
    pub fn apply(&self, uv: [f64; 2]) -> [f64; 2] {
        let m = &self.transform;
        [
            m[0] * uv[0] + m[1] * uv[1] + m[2],
            m[3] * uv[0] + m[4] * uv[1] + m[5],
        ]
    }

    /// A change `d` of the coordinate through the transform's linear part.
    #[inline]
    pub fn apply_linear(&self, d: [f64; 2]) -> [f64; 2] {
        let m = &self.transform;
        [m[0] * d[0] + m[1] * d[1], m[3] * d[0] + m[4] * d[1]]
    }
}

/// One mip level: `width`×`height` texels, linear RGB and alpha in 16 bits (0..65535 for
/// [0, 1]), row-major from the top.
#[derive(Debug, Clone, PartialEq)]
struct Level {
    width: usize,
    height: usize,
    texels: Vec<[u16; 4]>,
    /// The sides as floats, and less one: the lookups' constants (a float from an integer
    /// costs several instructions on x86-64's baseline).
    size: [f64; 2],
    last: [f64; 2],
    /// The level's number in the chain, as a float.
    depth: f64,
}

/// A decoded texture and its mip chain, and its mean texel (linear RGB, alpha as stored).
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    levels: Vec<Level>,
    mean: [f32; 4],
}

impl Texture {
    /// The texture of image `image` (at least one texel), its mip chain built.
    pub fn new(image: Rgba8) -> Result<Texture, String> {
        let (w, h) = (image.width as usize, image.height as usize);
        if w == 0 || h == 0 || image.texels.len() != w * h {
            return Err(format!(
                "an image of {w}x{h} texels needs {} texels, got {}",
                w * h,
                image.texels.len()
            ));
        }
        let mean = mean_linear(&image.texels);
        let lut = &*SRGB_TO_LINEAR16;
        let texels = image
            .texels
            .iter()
            .map(|t| {
                let a = u16::from(t[3]) * 257;
                [
                    lut[t[0] as usize],
                    lut[t[1] as usize],
                    lut[t[2] as usize],
                    a,
                ]
            })
            .collect();
        let mut levels = vec![Level::new(w, h, texels, 0)];
        while let Some(next) = levels.last().and_then(Level::half) {
            levels.push(next);
        }
        Ok(Texture { levels, mean })
    }

    pub fn width(&self) -> usize {
        self.levels[0].width
    }
    pub fn height(&self) -> usize {
        self.levels[0].height
    }
    /// Level 0's texels, sRGB-encoded RGBA8, row-major from the top: the image the texture
    /// was made from, exactly.
    pub fn texels(&self) -> Vec<[u8; 4]> {
        self.levels[0]
            .texels
            .iter()
            .map(|t| {
                let c = |k: usize| linear_to_srgb8(f64::from(t[k]) / 65535.0);
                [c(0), c(1), c(2), (t[3] / 257) as u8]
            })
            .collect()
    }
    /// The mean texel: linear RGB (sRGB decoded) and alpha as stored, each in [0, 1].
    pub fn mean(&self) -> [f32; 4] {
        self.mean
    }
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// The filtered texel at texture coordinate `uv` (0..1 spans the image, v down) for a
    /// footprint whose longer side is `rho` level-0 texels (1 or less: magnified): linear RGB.
    pub fn sample(&self, uv: [f64; 2], rho: f64, s: &Sampler) -> [f32; 3] {
        // λ = log2 ρ ≤ 0: magnified (no logarithm needed to tell).
        if rho <= 1.0 || rho.is_nan() || s.mipmap == Mipmap::None || self.levels.len() == 1 {
            let nearest = if rho > 1.0 {
                s.min_nearest
            } else {
                s.mag_nearest
            };
            return rgb(self.levels[0].filter(uv, nearest, s.wrap));
        }
        let lambda = log2(rho);
        let top = self.levels[self.levels.len() - 1].depth;
        if s.mipmap == Mipmap::Nearest {
            // OpenGL's nearest level: ceil(λ + ½) − 1, within the chain.
            let d = ((lambda + 0.5).ceil() - 1.0).clamp(0.0, top) as i64 as usize;
            return rgb(self.levels[d].filter(uv, s.min_nearest, s.wrap));
        }
        // λ > 0 here, so truncation is its floor.
        let lambda = lambda.min(top);
        let d = lambda as i64;
        let f = (lambda - d as f64) as f32;
        let d = d as usize;
        let a = self.levels[d].filter(uv, s.min_nearest, s.wrap);
        // The next level adds nothing that an 8-bit texel could show.
        if d + 1 >= self.levels.len() || f < 1.0 / 1024.0 {
            return rgb(a);
        }
        let b = self.levels[d + 1].filter(uv, s.min_nearest, s.wrap);
        rgb(a + (b - a) * f)
    }
}

impl Level {
    fn new(width: usize, height: usize, texels: Vec<[u16; 4]>, depth: usize) -> Level {
        let (fw, fh) = (width as f64, height as f64);
        Level {
            width,
            height,
            texels,
            size: [fw, fh],
            last: [fw - 1.0, fh - 1.0],
            depth: depth as f64,
        }
    }

    /// The next level: sides halved (rounded down, at least 1), each texel the linear mean of
    /// the 2×2 (3 across an odd side) it covers; `None` past a 1×1 level.
    fn half(&self) -> Option<Level> {
        if self.width == 1 && self.height == 1 {
            return None;
        }
        let (w, h) = ((self.width / 2).max(1), (self.height / 2).max(1));
        // The source texels a destination index covers along a side of `n` (from `m`).
        let span = |i: usize, n: usize, m: usize| -> std::ops::Range<usize> {
            if m == n {
                i..i + 1
            } else if n % 2 == 1 && i == m - 1 {
                2 * i..2 * i + 3
            } else {
                2 * i..2 * i + 2
            }
        };
        let texels = (0..w * h)
            .map(|k| {
                let (x, y) = (k % w, k / w);
                let mut sum = [0u32; 4];
                let mut count = 0;
                for sy in span(y, self.height, h) {
                    for sx in span(x, self.width, w) {
                        let t = self.texels[sy * self.width + sx];
                        for c in 0..4 {
                            sum[c] += u32::from(t[c]);
                        }
                        count += 1;
                    }
                }
                // The mean, rounded to the nearest (integers: the same on every machine).
                sum.map(|v| ((v + count / 2) / count) as u16)
            })
            .collect();
        Some(Level::new(w, h, texels, self.depth as usize + 1))
    }

    /// Texel `(x, y)` (already wrapped into the level): linear RGBA in units of 1/65535.
    #[inline(always)]
    fn texel(&self, x: usize, y: usize) -> Vec4 {
        self.decoded(y * self.width + x)
    }

    /// Texel `k` (row-major): linear RGBA in units of 1/65535.
    #[inline(always)]
    fn decoded(&self, k: usize) -> Vec4 {
        widen(self.texels[k])
    }

    /// The level filtered at `uv`: the nearest texel, or the bilinear blend of the four around
    /// it (texel centres at half-integers of `uv · size`).
    #[inline(always)]
    fn filter(&self, uv: [f64; 2], nearest: bool, wrap: [Wrap; 2]) -> Vec4 {
        let (x, y) = (uv[0] * self.size[0] - 0.5, uv[1] * self.size[1] - 0.5);
        // Most lookups fall between four texels inside the level: no wrap, one index. The
        // same texels and weights as the general path below, which wraps each corner.
        if !nearest && x >= 0.0 && y >= 0.0 && x < self.last[0] && y < self.last[1] {
            // Both within [0, 2^53): truncation is the floor, through i64 (one instruction).
            let (x0, y0) = (x as i64, y as i64);
            let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
            let k = y0 as usize * self.width + x0 as usize;
            let a = self.decoded(k);
            let b = self.decoded(k + 1);
            let c = self.decoded(k + self.width);
            let d = self.decoded(k + self.width + 1);
            return blend(a, b, c, d, fx, fy);
        }
        self.filter_wrapped(uv, nearest, wrap)
    }

    /// [`Level::filter`] of any coordinate: each texel's index wrapped on its own.
    #[inline(never)]
    fn filter_wrapped(&self, uv: [f64; 2], nearest: bool, wrap: [Wrap; 2]) -> Vec4 {
        let (w, h) = (self.width as i64, self.height as i64);
        // Far outside the image, wrap first so that the texel arithmetic stays in range.
        let (x, y) = (
            reduce(uv[0] * self.size[0], self.width, wrap[0]),
            reduce(uv[1] * self.size[1], self.height, wrap[1]),
        );
        // What no wrap brings near the image (not a number, or beyond f64's integers).
        if !(x.abs() < 1e15 && y.abs() < 1e15) {
            return self.texel(0, 0);
        }
        if nearest {
            let (x, y) = (floor(x), floor(y));
            return self.texel(wrap[0].index(x, w), wrap[1].index(y, h));
        }
        let (x, y) = (x - 0.5, y - 0.5);
        let (x0, y0) = (floor(x), floor(y));
        let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
        let (xa, xb) = (wrap[0].index(x0, w), wrap[0].index(x0 + 1, w));
        let (ya, yb) = (wrap[1].index(y0, h), wrap[1].index(y0 + 1, h));
        let at = |x: usize, y: usize| self.texel(x, y);
        blend(at(xa, ya), at(xb, ya), at(xa, yb), at(xb, yb), fx, fy)
    }
}

/// The bilinear blend of texels `a b` (top row) and `c d` (bottom row) at fractions `fx, fy`.
#[inline(always)]
fn blend(a: Vec4, b: Vec4, c: Vec4, d: Vec4, fx: f32, fy: f32) -> Vec4 {
    let top = a + (b - a) * fx;
    let bottom = c + (d - c) * fx;
    top + (bottom - top) * fy
}

/// A 16-bit texel as four floats (exact: every u16 is an f32).
#[inline(always)]
fn widen(t: [u16; 4]) -> Vec4 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        // SSE2, part of every x86-64: zero-extend the four lanes to 32 bits, convert.
        // SAFETY: the load reads the texel's 8 bytes and nothing else; SSE2 is always present.
        unsafe {
            let v = _mm_loadl_epi64(t.as_ptr().cast());
            Vec4::from(_mm_cvtepi32_ps(_mm_unpacklo_epi16(v, _mm_setzero_si128())))
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        Vec4::new(t[0] as f32, t[1] as f32, t[2] as f32, t[3] as f32)
    }
}

/// 1/65535: a blend of 16-bit texels to [0, 1].
const UNIT16: f32 = 1.0 / 65535.0;

/// The RGB of a blend of 16-bit texels, in [0, 1].
#[inline(always)]
fn rgb(v: Vec4) -> [f32; 3] {
    let v = v * UNIT16;
    [v.x, v.y, v.z]
}

/// log2 of a positive, normal `x` (> 1 here), to 2e-5: the exponent from the bits, the
/// mantissa's from a quintic in `m − 1` fitted on [1, 2) (near-minimax, exact at m = 1).
/// Enough for a level of detail, whose fraction weighs two mip levels of 8-bit texels; no libm
/// call, no division, the same bits on every machine.
#[inline(always)]
fn log2(x: f64) -> f64 {
    let bits = x.to_bits();
    let exponent = ((bits >> 52) & 0x7ff) as i64 - 1023;
    let t = f64::from_bits((bits & 0x000f_ffff_ffff_ffff) | 0x3ff0_0000_0000_0000) - 1.0;
    let p = 0.046_380_86;
    let p = p * t - 0.196_253_19;
    let p = p * t + 0.417_576_65;
    let p = p * t - 0.709_654_42;
    let p = p * t + 1.441_964_5;
    exponent as f64 + p * t
}

/// ⌊x⌋ of `x` within ±2^62, without a call into libm (the x86-64 baseline has no rounding
/// instruction for `f64::floor`); saturated beyond, 0 for NaN.
#[inline(always)]
fn floor(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x {
        i.saturating_sub(1)
    } else {
        i
    }
}

/// A texel coordinate `x` along a side of `n` moved by whole periods of the wrap (a repeat's
/// `n`, a mirror's `2n`) into [−2n, 2n), where its integer part fits any index; clamping needs
/// no move but a bound.
#[inline]
fn reduce(x: f64, n: usize, wrap: Wrap) -> f64 {
    let n = n as f64;
    match wrap {
        Wrap::Repeat if x.abs() >= n => x - floor(x / n) as f64 * n,
        Wrap::MirroredRepeat if x.abs() >= 2.0 * n => x - floor(x / (2.0 * n)) as f64 * 2.0 * n,
        Wrap::ClampToEdge => x.clamp(-1.0, n + 1.0),
        _ => x,
    }
}

/// The mean of RGBA8 sRGB texels: linear RGB and alpha in [0, 1]. The sums run in texel order
/// in f64, so the result is the same on every machine.
fn mean_linear(texels: &[[u8; 4]]) -> [f32; 4] {
    let lut = &*SRGB_TO_LINEAR;
    let mut sum = [0.0f64; 4];
    for t in texels {
        for c in 0..3 {
            sum[c] += f64::from(lut[t[c] as usize]);
        }
        sum[3] += f64::from(t[3]) / 255.0;
    }
    let n = (texels.len() as f64).max(1.0);
    sum.map(|s| (s / n) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker(n: u32) -> Rgba8 {
        let texels = (0..n * n)
            .map(|k| {
                if (k % n + k / n).is_multiple_of(2) {
                    [255, 255, 255, 255]
                } else {
                    [0, 0, 0, 255]
                }
            })
            .collect();
        Rgba8 {
            width: n,
            height: n,
            texels,
        }
    }

    #[test]
    fn the_mean_and_the_mip_chain_of_a_checkerboard() {
        let t = Texture::new(checker(8)).unwrap();
        assert_eq!(t.levels(), 4);
        assert_eq!(t.mean(), [0.5, 0.5, 0.5, 1.0]);
        // Level 1 averages black and white in linear space: 0.5 linear, stored as 32768/65535.
        assert!(t.levels[1]
            .texels
            .iter()
            .all(|x| *x == [32768, 32768, 32768, 65535]));
        let odd = Texture::new(Rgba8 {
            width: 3,
            height: 1,
            texels: vec![[0, 0, 0, 255]; 3],
        })
        .unwrap();
        assert_eq!(odd.levels(), 2);
        assert_eq!((odd.levels[1].width, odd.levels[1].height), (1, 1));
    }

    #[test]
    fn every_srgb_value_is_stored_apart_and_read_back_exactly() {
        let texels: Vec<[u8; 4]> = (0..=255u8).map(|v| [v, 255 - v, v, v]).collect();
        let t = Texture::new(Rgba8 {
            width: 256,
            height: 1,
            texels: texels.clone(),
        })
        .unwrap();
        assert_eq!(t.texels(), texels);
        // Each stored value within one step of its exact decode, and strictly increasing.
        let stored: Vec<u16> = t.levels[0].texels.iter().map(|x| x[0]).collect();
        for (v, s) in stored.iter().enumerate() {
            let exact = srgb8_to_linear_f64(v as u8) * 65535.0;
            assert!((f64::from(*s) - exact).abs() <= 0.5, "{v}: {s} vs {exact}");
        }
        assert!(stored.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn bilinear_between_texel_centres_and_each_wrap() {
        let t = Texture::new(Rgba8 {
            width: 2,
            height: 1,
            texels: vec![[0, 0, 0, 0], [255, 255, 255, 255]],
        })
        .unwrap();
        let s = Sampler::default();
        // Texel centres at u = 0.25 and 0.75; halfway between them, the mean.
        assert_eq!(t.sample([0.25, 0.5], 0.0, &s)[0], 0.0);
        assert_eq!(t.sample([0.75, 0.5], 0.0, &s)[0], 1.0);
        assert_eq!(t.sample([0.5, 0.5], 0.0, &s)[0], 0.5);
        // At u = 0 a repeat blends the two edges, a clamp holds the first texel.
        assert_eq!(t.sample([0.0, 0.5], 0.0, &s)[0], 0.5);
        let clamp = Sampler {
            wrap: [Wrap::ClampToEdge; 2],
            ..s
        };
        assert_eq!(t.sample([0.0, 0.5], 0.0, &clamp)[0], 0.0);
        assert_eq!(t.sample([-7.3, 0.5], 0.0, &clamp)[0], 0.0);
        // A repeat one period on reads the same, far out too.
        assert_eq!(t.sample([1.6, 0.5], 0.0, &s), t.sample([0.6, 0.5], 0.0, &s));
        assert_eq!(t.sample([1e6 + 0.75, 0.5], 0.0, &s)[0], 1.0);
        // Nothing wraps a coordinate that is not a number or past f64's integers: texel 0.
        for u in [f64::NAN, f64::INFINITY, 1e300, -1e300] {
            assert_eq!(t.sample([u, 0.5], 0.0, &s)[0], 0.0);
        }
        assert_eq!(t.sample([f64::NAN, 0.5], 0.0, &clamp)[0], 0.0);
        assert_eq!(t.sample([f64::INFINITY, 0.5], 0.0, &clamp)[0], 1.0);
        let mirror = Sampler {
            wrap: [Wrap::MirroredRepeat; 2],
            ..s
        };
        assert_eq!(t.sample([1.25, 0.5], 0.0, &mirror)[0], 1.0);
        assert_eq!(t.sample([-0.25, 0.5], 0.0, &mirror)[0], 0.0);
    }

    #[test]
    fn minified_lookups_blend_the_levels_around_the_footprint() {
        let t = Texture::new(checker(8)).unwrap();
        let s = Sampler::default();
        // A footprint of 8 texels is level 3 (one texel): the mean, whatever the position.
        let far = t.sample([0.1, 0.3], 8.0, &s);
        assert!((far[0] - 0.5).abs() < 0.003, "{far:?}");
        // Between levels 0 and 1 (ρ = √2): half the way from the texel to the mean.
        let near = t.sample([1.0 / 16.0, 1.0 / 16.0], 2f64.sqrt(), &s);
        assert!((near[0] - 0.75).abs() < 0.003, "{near:?}");
        // Without mip maps a minified lookup reads level 0.
        let flat = Sampler::default().with_filters(None, Some(9729));
        assert_eq!(t.sample([1.0 / 16.0, 1.0 / 16.0], 8.0, &flat)[0], 1.0);
    }

    #[test]
    fn log2_agrees_with_libm() {
        for x in [1.0000001, 1.5, 2.0, 3.0, 7.9, 1024.0, 1e6 + 0.3, 3.3e9] {
            assert!(
                (log2(x) - x.log2()).abs() < 2e-5,
                "{x}: {} {}",
                log2(x),
                x.log2()
            );
        }
    }

    #[test]
    fn the_transform_follows_the_sample_renderer() {
        let r = TextureRef {
            texture: 0,
            sampler: Sampler::default(),
            transform: texture_transform([0.5, 0.0], std::f64::consts::FRAC_PI_2, [2.0, 1.0]),
        };
        let [u, v] = r.apply([1.0, 0.0]);
        assert!(
            (u - 0.5).abs() < 1e-12 && (v + 2.0).abs() < 1e-12,
            "{u} {v}"
        );
    }
}
