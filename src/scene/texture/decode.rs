//! PNG and JPEG decoded to 8-bit RGBA, as image viewers bring them: grey is spread over R, G
//! and B, a missing alpha is opaque, palettes and bit depths under 8 are expanded, and 16-bit
//! samples are rounded to 8 bits (`(v + 128) / 257`). PNG and JPEG are the two formats glTF 2.0
//! allows, and the two an MTL `map_Kd` meets in practice; the format is told by the file's
//! first bytes, not its name or MIME type.

use std::io::Cursor;

/// Decoded images may take at most this many bytes; a header asking for more is refused before
/// anything is allocated.
const MAX_DECODED_BYTES: usize = 512 << 20;

/// An image of 8-bit RGBA texels, row 0 at the top (as stored in the file).
#[derive(Debug, Clone, PartialEq)]
pub struct Rgba8 {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<[u8; 4]>,
}

/// Decode an encoded PNG or JPEG image to RGBA8; an error names what could not be read.
pub fn decode(encoded: &[u8]) -> Result<Rgba8, String> {
    if encoded.starts_with(b"\x89PNG\r\n\x1a\n") {
        png_rgba(encoded)
    } else if encoded.starts_with(&[0xff, 0xd8, 0xff]) {
        jpeg_rgba(encoded)
    } else {
        Err("the image is neither PNG nor JPEG".to_string())
    }
}

fn png_rgba(encoded: &[u8]) -> Result<Rgba8, String> {
    let limits = png::Limits {
        bytes: MAX_DECODED_BYTES,
    };
    let mut decoder = png::Decoder::new_with_limits(Cursor::new(encoded), limits);
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder.read_info().map_err(|e| format!("PNG: {e}"))?;
    let size = reader
        .output_buffer_size()
        .filter(|&n| n <= MAX_DECODED_BYTES)
        .ok_or("PNG: the image is too large to decode")?;
    let mut buf = vec![0u8; size];
    let frame = reader
        .next_frame(&mut buf)
        .map_err(|e| format!("PNG: {e}"))?;
    let (color, depth) = reader.output_color_type();
    let channels = match color {
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        png::ColorType::Indexed => return Err("PNG: a palette that was not expanded".into()),
    };
    let texels = frame.width as usize * frame.height as usize;
    let bytes_per_sample = if depth == png::BitDepth::Sixteen {
        2
    } else {
        1
    };
    let samples = buf
        .get(..texels * channels * bytes_per_sample)
        .ok_or("PNG: fewer samples than texels")?;
    let texels = match depth {
        png::BitDepth::Eight => rgba_of(samples.iter().copied(), channels, texels),
        png::BitDepth::Sixteen => {
            let eight = samples.chunks_exact(2).map(|b| {
                let v = u32::from(u16::from_be_bytes([b[0], b[1]]));
                ((v + 128) / 257) as u8
            });
            rgba_of(eight, channels, texels)
        }
        other => return Err(format!("PNG: {other:?} bits per sample after expansion")),
    };
    Ok(Rgba8 {
        width: frame.width,
        height: frame.height,
        texels,
    })
}

fn jpeg_rgba(encoded: &[u8]) -> Result<Rgba8, String> {
    use zune_core::colorspace::ColorSpace;
    let options = zune_core::options::DecoderOptions::default()
        .set_strict_mode(false)
        .set_max_width(usize::MAX)
        .set_max_height(usize::MAX);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(
        zune_core::bytestream::ZCursor::new(encoded),
        options,
    );
    decoder.decode_headers().map_err(|e| format!("JPEG: {e}"))?;
    let (width, height) = decoder.dimensions().ok_or("JPEG: no frame header")?;
    let input = decoder.input_colorspace().ok_or("JPEG: no frame header")?;
    // Grey stays grey (one sample per texel); every other colour space is converted to RGB.
    let (out, channels) = match input {
        ColorSpace::Luma => (ColorSpace::Luma, 1),
        ColorSpace::LumaA => (ColorSpace::LumaA, 2),
        ColorSpace::RGBA => (ColorSpace::RGBA, 4),
        _ => (ColorSpace::RGB, 3),
    };
    let texels = width.saturating_mul(height);
    if texels.saturating_mul(channels) > MAX_DECODED_BYTES {
        return Err("JPEG: the image is too large to decode".into());
    }
    decoder.set_options(decoder.options().jpeg_set_out_colorspace(out));
    let samples = decoder.decode().map_err(|e| format!("JPEG: {e}"))?;
    if samples.len() < texels * channels {
        return Err("JPEG: fewer samples than texels".into());
    }
    Ok(Rgba8 {
        width: width as u32,
        height: height as u32,
        texels: rgba_of(
            samples[..texels * channels].iter().copied(),
            channels,
            texels,
        ),
    })
}

/// Interleaved 8-bit samples of `channels` per texel (grey, grey+alpha, RGB, RGBA) as RGBA.
fn rgba_of(samples: impl Iterator<Item = u8>, channels: usize, texels: usize) -> Vec<[u8; 4]> {
    let mut out = Vec::with_capacity(texels);
    let mut texel = [0u8; 4];
    let mut k = 0;
    for s in samples {
        texel[k] = s;
        k += 1;
        if k < channels {
            continue;
        }
        k = 0;
        out.push(match channels {
            1 => [texel[0], texel[0], texel[0], 255],
            2 => [texel[0], texel[0], texel[0], texel[1]],
            3 => [texel[0], texel[1], texel[2], 255],
            _ => texel,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png(color: png::ColorType, depth: png::BitDepth, w: u32, h: u32, data: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut enc = png::Encoder::new(&mut out, w, h);
        enc.set_color(color);
        enc.set_depth(depth);
        let mut writer = enc.write_header().unwrap();
        writer.write_image_data(data).unwrap();
        writer.finish().unwrap();
        out
    }

    #[test]
    fn grey_rgb_and_alpha_pngs_decode_to_rgba() {
        let rgba = png(
            png::ColorType::Rgba,
            png::BitDepth::Eight,
            2,
            1,
            &[255, 0, 0, 255, 0, 0, 255, 0],
        );
        let m = decode(&rgba).unwrap();
        assert_eq!((m.width, m.height), (2, 1));
        assert_eq!(m.texels, [[255, 0, 0, 255], [0, 0, 255, 0]]);
        let grey = png(
            png::ColorType::Grayscale,
            png::BitDepth::Eight,
            1,
            2,
            &[128, 128],
        );
        assert_eq!(decode(&grey).unwrap().texels, [[128, 128, 128, 255]; 2]);
        // 16 bits round to the nearest 8-bit value: 0x8080 / 257 = 128, 0x807f rounds to 128 too.
        let deep = png(
            png::ColorType::Grayscale,
            png::BitDepth::Sixteen,
            2,
            1,
            &[0x80, 0x80, 0x80, 0x7f],
        );
        assert_eq!(decode(&deep).unwrap().texels, [[128, 128, 128, 255]; 2]);
    }

    #[test]
    fn other_bytes_are_refused_with_a_reason() {
        assert!(decode(b"GIF89a").unwrap_err().contains("neither"));
        let mut cut = png(png::ColorType::Rgb, png::BitDepth::Eight, 4, 4, &[7; 48]);
        cut.truncate(cut.len() - 20);
        assert!(decode(&cut).unwrap_err().starts_with("PNG"));
        let jpeg = [0xff, 0xd8, 0xff, 0xe0, 0, 16];
        assert!(decode(&jpeg).unwrap_err().starts_with("JPEG"));
    }
}
