//! Frames in any of the formats a lab meets, told apart by their first bytes (not the file
//! name): TIFF through [`super::tiff_io`] (exact 8/16-bit integer and 32-bit float grey,
//! palettes), PNG and BMP through the `image` crate (webcams and V4L2 grabs save these).
//! Grey PNGs keep their values exactly (8 or 16 bit); colour ones and palette BMPs become Rec. 601
//! luma on their channel scale — a grey palette (R = G = B) gives its grey level exactly — as
//! TIFF palettes do.

use super::tiff_io::{decode_tiff, FrameInfo};
use super::{Image, ImageError};
use image::{DynamicImage, ImageFormat};
use std::path::Path;

/// Reads a frame: TIFF, PNG or BMP, by content.
pub fn read_image(path: &Path) -> Result<(Image, FrameInfo), ImageError> {
    let bytes = std::fs::read(path).map_err(|source| ImageError::Open {
        path: path.to_owned(),
        source,
    })?;
    decode_image(&bytes, path)
}

/// As [`read_image`], from the file's bytes; `path` names it in errors.
pub fn decode_image(bytes: &[u8], path: &Path) -> Result<(Image, FrameInfo), ImageError> {
    let format = match bytes {
        [b'I', b'I', 42, 0, ..] | [b'M', b'M', 0, 42, ..] => return decode_tiff(bytes, path),
        [0x89, b'P', b'N', b'G', ..] => ImageFormat::Png,
        [b'B', b'M', ..] => ImageFormat::Bmp,
        _ => {
            return Err(ImageError::Format {
                path: path.to_owned(),
                reason: "its first bytes are none of TIFF, PNG or BMP".into(),
            })
        }
    };
    let decoded =
        image::load_from_memory_with_format(bytes, format).map_err(|e| ImageError::Format {
            path: path.to_owned(),
            reason: e.to_string(),
        })?;
    Ok(to_grey(decoded))
}

/// Rec. 601 luma of an RGB triple; exactly the grey level when R = G = B.
fn luma(r: f32, g: f32, b: f32) -> f32 {
    if r == g && g == b {
        r
    } else {
        (0.299 * r as f64 + 0.587 * g as f64 + 0.114 * b as f64) as f32
    }
}

fn to_grey(decoded: DynamicImage) -> (Image, FrameInfo) {
    let (width, height) = (decoded.width() as usize, decoded.height() as usize);
    let (data, bit_depth): (Vec<f32>, u8) = match decoded {
        DynamicImage::ImageLuma8(g) => (g.into_raw().into_iter().map(f32::from).collect(), 8),
        DynamicImage::ImageLumaA8(g) => (g.pixels().map(|p| f32::from(p.0[0])).collect(), 8),
        DynamicImage::ImageLuma16(g) => (g.into_raw().into_iter().map(f32::from).collect(), 16),
        DynamicImage::ImageLumaA16(g) => (g.pixels().map(|p| f32::from(p.0[0])).collect(), 16),
        DynamicImage::ImageRgb16(_) | DynamicImage::ImageRgba16(_) => {
            let rgb = decoded.to_rgb16();
            let px = rgb.pixels().map(|p| {
                let [r, g, b] = p.0.map(f32::from);
                luma(r, g, b)
            });
            (px.collect(), 16)
        }
        other => {
            let rgb = other.to_rgb8();
            let px = rgb.pixels().map(|p| {
                let [r, g, b] = p.0.map(f32::from);
                luma(r, g, b)
            });
            (px.collect(), 8)
        }
    };
    let image = Image::from_vec(width, height, data).expect("one value per pixel");
    (
        image,
        FrameInfo {
            width,
            height,
            bit_depth,
        },
    )
}
