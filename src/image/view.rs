//! A borrowed grey image: what the DIC engine reads its two inputs through, so a caller holding
//! f32 pixels elsewhere (a numpy array from Python, a camera buffer) lends them without a copy.
//! The engine's first step (the pre-filter) writes its own working copy anyway.

use super::{Image, ImageError};

/// Row-major f32 grey values, no padding, borrowed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageView<'a> {
    width: usize,
    height: usize,
    data: &'a [f32],
}

impl<'a> ImageView<'a> {
    /// Wraps a row-major buffer; its length must be `width * height`.
    pub fn new(width: usize, height: usize, data: &'a [f32]) -> Result<Self, ImageError> {
        if width.checked_mul(height) != Some(data.len()) {
            return Err(ImageError::Shape {
                width,
                height,
                len: data.len(),
            });
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn data(&self) -> &'a [f32] {
        self.data
    }

    /// An owned copy.
    pub fn to_image(&self) -> Image {
        Image::from_vec(self.width, self.height, self.data.to_vec()).expect("a view's shape holds")
    }
}

impl<'a> From<&'a Image> for ImageView<'a> {
    fn from(image: &'a Image) -> Self {
        Self {
            width: image.width(),
            height: image.height(),
            data: image.data(),
        }
    }
}
