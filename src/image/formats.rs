//! Frames in any of the formats a lab meets, told apart by their first bytes (not the file
//! name): TIFF through [`super::tiff_io`] (exact 8/16-bit integer and 32-bit float grey,
//! palettes), PNG and BMP through the `image` crate (webcams and V4L2 grabs save these).
//! Grey PNGs keep their values exactly (8 or 16 bit); colour ones and palette BMPs become Rec. 601
//! luma on their channel scale — a grey palette (R = G = B) gives its grey level exactly — as
//! TIFF palettes do.

use super::tiff_io::{decode_tiff, decode_tiff_within, read_tiff_header, FrameInfo};
use super::{Image, ImageError};
use image::{DynamicImage, ImageFormat};
use std::path::{Path, PathBuf};

/// The file extensions (any case) of the frame formats [`read_image`] reads: what a folder of
/// frames is listed by.
pub const FRAME_EXTENSIONS: [&str; 4] = ["tif", "tiff", "png", "bmp"];

/// The frame files of folder `dir` (by [`FRAME_EXTENSIONS`]), sorted by name.
pub fn frame_files(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| FRAME_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        })
        .collect();
    files.sort();
    Ok(files)
}

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
    let Some(format) = format_of(bytes, path)? else {
        return decode_tiff(bytes, path);
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

/// The format of a frame's bytes, from its first bytes.
fn format_of(bytes: &[u8], path: &Path) -> Result<Option<ImageFormat>, ImageError> {
    match bytes {
        [b'I', b'I', 42, 0, ..] | [b'M', b'M', 0, 42, ..] => Ok(None),
        [0x89, b'P', b'N', b'G', ..] => Ok(Some(ImageFormat::Png)),
        [b'B', b'M', ..] => Ok(Some(ImageFormat::Bmp)),
        _ => Err(ImageError::Format {
            path: path.to_owned(),
            reason: "its first bytes are none of TIFF, PNG or BMP".into(),
        }),
    }
}

/// As [`decode_image`], refused from the header before a pixel is decoded when the frame has
/// more than `max_pixels` pixels (what a dataset's frames are checked with).
pub fn decode_image_within(
    bytes: &[u8],
    path: &Path,
    max_pixels: usize,
) -> Result<(Image, FrameInfo), ImageError> {
    let Some(format) = format_of(bytes, path)? else {
        return decode_tiff_within(bytes, path, max_pixels);
    };
    let info = header_of(std::io::Cursor::new(bytes), format, path)?;
    if info.width.saturating_mul(info.height) > max_pixels {
        return Err(ImageError::TooLarge {
            path: path.to_owned(),
            width: info.width,
            height: info.height,
            max_pixels,
        });
    }
    decode_image(bytes, path)
}

/// A frame's size and bit depth (per channel) from its header, TIFF, PNG or BMP.
pub fn read_image_header(path: &Path) -> Result<FrameInfo, ImageError> {
    let open = |source| ImageError::Open {
        path: path.to_owned(),
        source,
    };
    let mut file = std::io::BufReader::new(std::fs::File::open(path).map_err(open)?);
    // Enough to tell the three formats apart; the decoder then reads the header alone.
    let mut head = Vec::with_capacity(8);
    std::io::Read::read_to_end(&mut std::io::Read::take(&mut file, 8), &mut head).map_err(open)?;
    match format_of(&head, path)? {
        None => read_tiff_header(path),
        Some(format) => {
            std::io::Seek::rewind(&mut file).map_err(open)?;
            header_of(file, format, path)
        }
    }
}

/// Size and bit depth of a PNG or BMP from its header (nothing past it is read).
fn header_of(
    reader: impl std::io::BufRead + std::io::Seek,
    format: ImageFormat,
    path: &Path,
) -> Result<FrameInfo, ImageError> {
    use image::ImageDecoder;
    let bad = |e: image::ImageError| ImageError::Format {
        path: path.to_owned(),
        reason: e.to_string(),
    };
    let decoder = image::ImageReader::with_format(reader, format)
        .into_decoder()
        .map_err(bad)?;
    let (w, h) = decoder.dimensions();
    let colour = decoder.color_type();
    Ok(FrameInfo {
        width: w as usize,
        height: h as usize,
        bit_depth: (colour.bits_per_pixel() / u16::from(colour.channel_count())) as u8,
    })
}
