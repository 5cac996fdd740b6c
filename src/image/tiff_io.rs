//! Grayscale TIFF in and out (the `tiff` crate). 8- and 16-bit integer and 32-bit float grey
//! images are read, and palette and grey+alpha ones through [`super::tiff_layout`]; 8- and
//! 16-bit are written. Writes go to a temporary file that is renamed into
//! place, so a crash never leaves a half-written frame under the final name.

use super::tiff_layout::{rewrite_as_grey, Rewritten};
use super::{Image, ImageError};
use std::io::Cursor;
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult};
use tiff::encoder::{colortype, TiffEncoder};
use tiff::tags::Tag;
use tiff::ColorType;

/// What a frame file held before conversion to f32: its size and bit depth per sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameInfo {
    pub width: usize,
    pub height: usize,
    pub bit_depth: u8,
}

/// Reads the first page of a grayscale TIFF as f32 grey values on the file's own scale. Palette
/// images are read through their colour map (grey palettes exactly, colour ones as Rec. 601
/// luma) on the scale of their index depth; grey+alpha images drop the alpha.
pub fn read_tiff(path: &Path) -> Result<(Image, FrameInfo), ImageError> {
    let bytes = std::fs::read(path).map_err(|source| ImageError::Open {
        path: path.to_owned(),
        source,
    })?;
    decode_tiff(&bytes, path)
}

/// As [`read_tiff`], from the file's bytes (a frame fetched over HTTP); `path` names it in
/// errors.
pub fn decode_tiff(bytes: &[u8], path: &Path) -> Result<(Image, FrameInfo), ImageError> {
    decode_tiff_within(bytes, path, usize::MAX)
}

/// As [`decode_tiff`], but a frame whose header states more than `max_pixels` pixels is refused
/// before any pixel buffer is allocated, and the decoder's own buffers are held to that size: a
/// deflate-compressed 16384² frame is 0.5 MB on the wire and 1 GB decoded.
pub fn decode_tiff_within(
    bytes: &[u8],
    path: &Path,
    max_pixels: usize,
) -> Result<(Image, FrameInfo), ImageError> {
    let decode_err = |e: tiff::TiffError| ImageError::Decode {
        path: path.to_owned(),
        reason: e.to_string(),
    };
    let unsupported = |kind: String| ImageError::Unsupported {
        path: path.to_owned(),
        kind,
    };
    // One look at the header: the size, refused before a pixel is decoded, and the colour type.
    let mut probe = Decoder::new(Cursor::new(bytes));
    if let Some((w, h)) = probe.as_mut().ok().and_then(|d| d.dimensions().ok()) {
        let (width, height) = (w as usize, h as usize);
        if width.saturating_mul(height) > max_pixels {
            return Err(ImageError::TooLarge {
                path: path.to_owned(),
                width,
                height,
                max_pixels,
            });
        }
    }
    let colortype = probe.and_then(|mut d| d.colortype());
    let limits = decoder_limits(max_pixels);
    let open = |b| open_limited(b, &limits);
    match colortype {
        Ok(ColorType::Gray(8 | 16 | 32)) => {
            let mut decoder = open(bytes).map_err(decode_err)?;
            decode_grey(&mut decoder, path)
        }
        other => match rewrite_as_grey(bytes) {
            Some(Rewritten::Palette(copy)) => {
                let mut decoder = open(copy.as_slice()).map_err(decode_err)?;
                let (indices, info) = decode_grey(&mut decoder, path)?;
                let map = decoder.get_tag_u16_vec(Tag::ColorMap).map_err(decode_err)?;
                palette_to_grey(&indices, info, &map).ok_or_else(|| ImageError::Decode {
                    path: path.to_owned(),
                    reason: "the colour map does not cover the palette indices".into(),
                })
            }
            Some(Rewritten::GreyAlpha(copy)) => {
                let mut decoder = open(copy.as_slice()).map_err(decode_err)?;
                let (both, info) = decode_grey(&mut decoder, path)?;
                let width = info.width / 2;
                let grey: Vec<f32> = both.data().iter().step_by(2).copied().collect();
                let image =
                    Image::from_vec(width, info.height, grey).map_err(|_| ImageError::Decode {
                        path: path.to_owned(),
                        reason: "pixel data shorter than the image dimensions".into(),
                    })?;
                Ok((image, FrameInfo { width, ..info }))
            }
            None => match other {
                Ok(color) => Err(unsupported(format!("{color:?}"))),
                Err(e) => Err(decode_err(e)),
            },
        },
    }
}

/// The tiff crate's buffer limits for frames of at most `max_pixels` (two samples per pixel for
/// grey+alpha, eight bytes per sample at most); its defaults (256 MB) when unbounded.
fn decoder_limits(max_pixels: usize) -> tiff::decoder::Limits {
    let mut limits = tiff::decoder::Limits::default();
    if max_pixels != usize::MAX {
        let bytes = max_pixels.saturating_mul(2 * 8);
        limits.decoding_buffer_size = bytes;
        limits.intermediate_buffer_size = bytes;
    }
    limits
}

fn open_limited<'a>(
    bytes: &'a [u8],
    limits: &tiff::decoder::Limits,
) -> Result<Decoder<Cursor<&'a [u8]>>, tiff::TiffError> {
    Ok(Decoder::new(Cursor::new(bytes))?.with_limits(limits.clone()))
}

/// Width, height and bit depth from the header alone (no pixel is decoded): grey, palette and
/// grey+alpha files, as [`read_tiff`] reads them.
pub fn read_tiff_header(path: &Path) -> Result<FrameInfo, ImageError> {
    let file = std::fs::File::open(path).map_err(|source| ImageError::Open {
        path: path.to_owned(),
        source,
    })?;
    let decode_err = |e: tiff::TiffError| ImageError::Decode {
        path: path.to_owned(),
        reason: e.to_string(),
    };
    let mut decoder = Decoder::new(std::io::BufReader::new(file)).map_err(decode_err)?;
    let (w, h) = decoder.dimensions().map_err(decode_err)?;
    let bit_depth = match decoder.colortype().map_err(decode_err)? {
        ColorType::Gray(b) | ColorType::Palette(b) | ColorType::GrayA(b) => b,
        other => {
            return Err(ImageError::Unsupported {
                path: path.to_owned(),
                kind: format!("{other:?}"),
            })
        }
    };
    Ok(FrameInfo {
        width: w as usize,
        height: h as usize,
        bit_depth,
    })
}

/// Decodes a grey first page (8/16-bit integer or 32-bit float).
fn decode_grey(
    decoder: &mut Decoder<Cursor<&[u8]>>,
    path: &Path,
) -> Result<(Image, FrameInfo), ImageError> {
    let decode_err = |e: tiff::TiffError| ImageError::Decode {
        path: path.to_owned(),
        reason: e.to_string(),
    };
    let (w, h) = decoder.dimensions().map_err(decode_err)?;
    let (width, height) = (w as usize, h as usize);
    let bit_depth = match decoder.colortype().map_err(decode_err)? {
        ColorType::Gray(bits @ (8 | 16 | 32)) => bits,
        other => {
            return Err(ImageError::Unsupported {
                path: path.to_owned(),
                kind: format!("{other:?}"),
            })
        }
    };
    // The f32 copy is sized from the header: asked for, not assumed (a refusal, not an abort).
    let widen = |n: usize| -> Result<Vec<f32>, ImageError> {
        let mut v = Vec::new();
        v.try_reserve_exact(n)
            .map_err(|_| ImageError::OutOfMemory {
                path: path.to_owned(),
                bytes: n.saturating_mul(4),
            })?;
        Ok(v)
    };
    let data: Vec<f32> = match decoder.read_image().map_err(decode_err)? {
        DecodingResult::U8(v) => {
            let mut out = widen(v.len())?;
            out.extend(v.into_iter().map(f32::from));
            out
        }
        DecodingResult::U16(v) => {
            let mut out = widen(v.len())?;
            out.extend(v.into_iter().map(f32::from));
            out
        }
        DecodingResult::F32(v) => v,
        other => {
            let kind = match other {
                DecodingResult::U32(_) => "32-bit integer samples",
                DecodingResult::U64(_) => "64-bit integer samples",
                DecodingResult::F64(_) => "64-bit float samples",
                _ => "signed integer samples",
            };
            return Err(ImageError::Unsupported {
                path: path.to_owned(),
                kind: kind.into(),
            });
        }
    };
    let image = Image::from_vec(width, height, data).map_err(|_| ImageError::Decode {
        path: path.to_owned(),
        reason: "pixel data shorter than the image dimensions".into(),
    })?;
    Ok((
        image,
        FrameInfo {
            width,
            height,
            bit_depth: bit_depth as u8,
        },
    ))
}

/// Grey values of palette indices: the colour map holds 2^bits red, then green, then blue
/// entries on a 16-bit scale; the grey is scaled back to the index depth (a grey palette of an
/// 8-bit image gives its 0..255 values exactly).
fn palette_to_grey(indices: &Image, info: FrameInfo, map: &[u16]) -> Option<(Image, FrameInfo)> {
    let entries = 1usize << info.bit_depth.min(16);
    if map.len() < 3 * entries {
        return None;
    }
    let (r, g, b) = (
        &map[..entries],
        &map[entries..2 * entries],
        &map[2 * entries..3 * entries],
    );
    let scale = ((1u32 << info.bit_depth.min(16)) - 1) as f64 / 65535.0;
    let grey: Vec<f32> = indices
        .data()
        .iter()
        .map(|&i| {
            let i = (i as usize).min(entries - 1);
            let y = if r[i] == g[i] && g[i] == b[i] {
                r[i] as f64
            } else {
                0.299 * r[i] as f64 + 0.587 * g[i] as f64 + 0.114 * b[i] as f64
            };
            (y * scale) as f32
        })
        .collect();
    let image = Image::from_vec(info.width, info.height, grey).ok()?;
    Some((image, info))
}

/// Writes 16-bit grey values, rounding and clamping to 0..=65535.
pub fn write_tiff_u16(path: &Path, image: &Image) -> Result<(), ImageError> {
    let data: Vec<u16> = image
        .data()
        .iter()
        .map(|&v| v.round().clamp(0.0, 65535.0) as u16)
        .collect();
    write_atomically(path, |w| {
        TiffEncoder::new(w)?.write_image::<colortype::Gray16>(
            image.width() as u32,
            image.height() as u32,
            &data,
        )
    })
}

/// A 16-bit grayscale TIFF in memory (camera frames for HTTP responses and run folders).
pub fn tiff_u16_bytes(width: usize, height: usize, data: &[u16]) -> Result<Vec<u8>, ImageError> {
    let mut buffer = Cursor::new(Vec::new());
    TiffEncoder::new(&mut buffer)
        .and_then(|mut e| e.write_image::<colortype::Gray16>(width as u32, height as u32, data))
        .map_err(|e| ImageError::Encode {
            path: "<memory>".into(),
            reason: e.to_string(),
        })?;
    Ok(buffer.into_inner())
}

/// Writes 8-bit grey values, rounding and clamping to 0..=255.
pub fn write_tiff_u8(path: &Path, image: &Image) -> Result<(), ImageError> {
    let data: Vec<u8> = image
        .data()
        .iter()
        .map(|&v| v.round().clamp(0.0, 255.0) as u8)
        .collect();
    write_atomically(path, |w| {
        TiffEncoder::new(w)?.write_image::<colortype::Gray8>(
            image.width() as u32,
            image.height() as u32,
            &data,
        )
    })
}

/// Encodes in memory (the encoder needs Seek), then writes the file atomically.
fn write_atomically(
    path: &Path,
    encode: impl FnOnce(&mut Cursor<Vec<u8>>) -> Result<(), tiff::TiffError>,
) -> Result<(), ImageError> {
    let encode_err = |reason: String| ImageError::Encode {
        path: path.to_owned(),
        reason,
    };
    let mut buffer = Cursor::new(Vec::new());
    encode(&mut buffer).map_err(|e| encode_err(e.to_string()))?;
    crate::atomic_write::write_atomically(path, buffer.get_ref())
        .map_err(|e| encode_err(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sixteen_bit_round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.tif");
        let img = Image::from_fn(7, 5, |c, r| (c * 1000 + r * 7) as f32);
        write_tiff_u16(&path, &img).unwrap();
        let (back, info) = read_tiff(&path).unwrap();
        assert_eq!(info.bit_depth, 16);
        assert_eq!(back, img);
    }

    #[test]
    fn eight_bit_round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.tif");
        let img = Image::from_fn(4, 3, |c, r| (c * 50 + r) as f32);
        write_tiff_u8(&path, &img).unwrap();
        let (back, info) = read_tiff(&path).unwrap();
        assert_eq!(info.bit_depth, 8);
        assert_eq!(back, img);
    }

    fn fixture(name: &str) -> std::path::PathBuf {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/tiff")
            .join(name)
    }

    /// The fixtures were written by tifffile (Python), not by this crate: a 64x48 ramp
    /// (i·7 mod 251, 8-bit) and (i·97 mod 65521, 16-bit).
    fn ramp8(c: usize, r: usize) -> f32 {
        ((r * 64 + c) * 7 % 251) as f32
    }

    #[test]
    fn palette_and_grey_alpha_files_are_read() {
        let (img, info) = read_tiff(&fixture("palette8.tif")).unwrap();
        assert_eq!((info.width, info.height, info.bit_depth), (64, 48, 8));
        assert_eq!(img, Image::from_fn(64, 48, ramp8));
        let (img, _) = read_tiff(&fixture("greyalpha8.tif")).unwrap();
        assert_eq!(img, Image::from_fn(64, 48, ramp8));
        let (img, info) = read_tiff(&fixture("greyalpha16.tif")).unwrap();
        assert_eq!(info.bit_depth, 16);
        assert_eq!(
            img,
            Image::from_fn(64, 48, |c, r| ((r * 64 + c) * 97 % 65521) as f32)
        );
        // A colour palette k -> (k, 255 - k, k / 2) becomes its Rec. 601 luma.
        let (img, _) = read_tiff(&fixture("palette8_colour.tif")).unwrap();
        let k = ramp8(5, 3) as f64;
        let luma = 0.299 * k + 0.587 * (255.0 - k) + 0.114 * (k / 2.0).floor();
        assert!(
            (img.get(5, 3) as f64 - luma).abs() < 1e-3,
            "{} vs {luma}",
            img.get(5, 3)
        );
    }

    #[test]
    fn truncated_file_is_a_decode_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.tif");
        let img = Image::from_fn(64, 64, |c, r| (c + r) as f32);
        write_tiff_u16(&path, &img).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
        assert!(matches!(read_tiff(&path), Err(ImageError::Decode { .. })));
        std::fs::write(&path, b"not a tiff at all").unwrap();
        assert!(matches!(read_tiff(&path), Err(ImageError::Decode { .. })));
    }
}
