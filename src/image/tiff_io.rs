//! Grayscale TIFF in and out (the `tiff` crate). 8- and 16-bit integer and 32-bit float grey
//! images are read; 8- and 16-bit are written. Writes go to a temporary file that is renamed into
//! place, so a crash never leaves a half-written frame under the final name.

use super::{Image, ImageError};
use std::fs::File;
use std::io::{BufReader, Cursor};
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult};
use tiff::encoder::{colortype, TiffEncoder};
use tiff::ColorType;

/// What a TIFF file held before conversion to f32.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TiffInfo {
    pub width: usize,
    pub height: usize,
    pub bit_depth: u8,
}

/// Reads the first page of a grayscale TIFF as f32 grey values on the file's own scale.
pub fn read_tiff(path: &Path) -> Result<(Image, TiffInfo), ImageError> {
    let file = File::open(path).map_err(|source| ImageError::Open {
        path: path.to_owned(),
        source,
    })?;
    let decode_err = |e: tiff::TiffError| ImageError::Decode {
        path: path.to_owned(),
        reason: e.to_string(),
    };
    let mut decoder = Decoder::new(BufReader::new(file)).map_err(decode_err)?;
    let (w, h) = decoder.dimensions().map_err(decode_err)?;
    let (width, height) = (w as usize, h as usize);
    let color = decoder.colortype().map_err(decode_err)?;
    let bit_depth = match color {
        ColorType::Gray(bits @ (8 | 16 | 32)) => bits,
        other => {
            return Err(ImageError::Unsupported {
                path: path.to_owned(),
                kind: format!("{other:?}"),
            })
        }
    };
    let data: Vec<f32> = match decoder.read_image().map_err(decode_err)? {
        DecodingResult::U8(v) => v.into_iter().map(f32::from).collect(),
        DecodingResult::U16(v) => v.into_iter().map(f32::from).collect(),
        DecodingResult::F32(v) => v,
        other => {
            return Err(ImageError::Unsupported {
                path: path.to_owned(),
                kind: format!("{:?} samples", std::mem::discriminant(&other)),
            })
        }
    };
    let image = Image::from_vec(width, height, data).map_err(|_| ImageError::Decode {
        path: path.to_owned(),
        reason: "pixel data shorter than the image dimensions".into(),
    })?;
    Ok((
        image,
        TiffInfo {
            width,
            height,
            bit_depth: bit_depth as u8,
        },
    ))
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
    crate::store::write_atomically(path, buffer.get_ref()).map_err(|e| encode_err(e.to_string()))
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
