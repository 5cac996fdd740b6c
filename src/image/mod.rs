//! Images for the numerics: one f32 type, a pixel rectangle, 8/16-bit grayscale TIFF I/O, and
//! frames read by content (TIFF, PNG, BMP).
//!
//! Pixel coordinates follow DESIGN.md: the origin is the centre of the top-left pixel, x to the
//! right, y down. Pixel (col, row) therefore covers the square [col-0.5, col+0.5] x [row-0.5, row+0.5].

mod error;
pub mod focus_map;
mod formats;
mod gray;
mod roi;
pub mod speckle_quality;
mod tiff_io;
mod tiff_layout;
mod view;

pub use error::ImageError;
pub use focus_map::{focus_map, FocusMap};
pub use formats::{
    decode_image, decode_image_within, frame_files, read_image, read_image_header, FRAME_EXTENSIONS,
};
pub use gray::Image;
pub use roi::Roi;
pub use speckle_quality::{speckle_quality, SpeckleQuality, SpeckleQualityError};
pub use tiff_io::{
    decode_tiff, decode_tiff_within, read_tiff, read_tiff_header, tiff_u16_bytes, write_tiff_u16,
    write_tiff_u8, FrameInfo,
};
pub use view::ImageView;
