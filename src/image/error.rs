use std::path::PathBuf;

/// Errors of image construction and TIFF input/output.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("cannot open {path}: {source}")]
    Open {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path} is not a readable TIFF: {reason}")]
    Decode { path: PathBuf, reason: String },
    #[error("{path}: unsupported TIFF pixel type {kind} (read: 8- or 16-bit integer or 32-bit float grey, palette, grey+alpha)")]
    Unsupported { path: PathBuf, kind: String },
    /// Refused from the header, before a byte of pixel data is allocated.
    #[error("{path} is {width}x{height} px, over the limit of {max_pixels} px a frame may have")]
    TooLarge {
        path: PathBuf,
        width: usize,
        height: usize,
        max_pixels: usize,
    },
    #[error("{path}: cannot allocate {bytes} bytes to decode it")]
    OutOfMemory { path: PathBuf, bytes: usize },
    #[error("{path} is not a readable TIFF, PNG or BMP frame: {reason}")]
    Format { path: PathBuf, reason: String },
    #[error("cannot write {path}: {reason}")]
    Encode { path: PathBuf, reason: String },
    #[error("image buffer of {len} values does not match {width}x{height}")]
    Shape {
        width: usize,
        height: usize,
        len: usize,
    },
}
