use super::{ImageError, Roi};

/// A single-channel image of f32 grey values, row-major, no padding.
///
/// Grey values keep the camera's scale (0..255 for 8-bit, 0..65535 for 16-bit data); nothing in
/// the DIC engine depends on the scale because its criterion is zero-normalised.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

impl Image {
    /// An image filled with `value`.
    pub fn filled(width: usize, height: usize, value: f32) -> Self {
        Self {
            width,
            height,
            data: vec![value; width * height],
        }
    }

    /// Wraps a row-major buffer; its length must be `width * height`.
    pub fn from_vec(width: usize, height: usize, data: Vec<f32>) -> Result<Self, ImageError> {
        super::ImageView::new(width, height, &data)?;
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// Builds an image by evaluating `f(col, row)` at every pixel.
    pub fn from_fn(width: usize, height: usize, mut f: impl FnMut(usize, usize) -> f32) -> Self {
        let mut data = Vec::with_capacity(width * height);
        for row in 0..height {
            for col in 0..width {
                data.push(f(col, row));
            }
        }
        Self {
            width,
            height,
            data,
        }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn data(&self) -> &[f32] {
        &self.data
    }

    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }

    pub fn into_vec(self) -> Vec<f32> {
        self.data
    }

    /// The grey value at (col, row). Panics when out of bounds, like slice indexing.
    #[inline]
    pub fn get(&self, col: usize, row: usize) -> f32 {
        self.data[row * self.width + col]
    }

    #[inline]
    pub fn set(&mut self, col: usize, row: usize, value: f32) {
        self.data[row * self.width + col] = value;
    }

    pub fn row(&self, row: usize) -> &[f32] {
        &self.data[row * self.width..(row + 1) * self.width]
    }

    /// The rectangle covering the whole image.
    pub fn bounds(&self) -> Roi {
        Roi::new(0, 0, self.width, self.height)
    }

    /// A copy of the pixels inside `roi`, which must lie inside the image.
    pub fn crop(&self, roi: Roi) -> Image {
        assert!(
            roi.x + roi.width <= self.width && roi.y + roi.height <= self.height,
            "crop {roi:?} outside {}x{}",
            self.width,
            self.height
        );
        Image::from_fn(roi.width, roi.height, |c, r| self.get(roi.x + c, roi.y + r))
    }

    /// The mean pixel value (0 for an empty image; accumulated in f64), as
    /// [`Image::mean_std`] gives it.
    pub fn mean(&self) -> f64 {
        let n = self.data.len().max(1) as f64;
        self.data.iter().map(|&v| v as f64).sum::<f64>() / n
    }

    /// Mean and population standard deviation of all pixels (accumulated in f64).
    pub fn mean_std(&self) -> (f64, f64) {
        let n = self.data.len().max(1) as f64;
        let mean = self.mean();
        let var = self
            .data
            .iter()
            .map(|&v| (v as f64 - mean).powi(2))
            .sum::<f64>()
            / n;
        (mean, var.sqrt())
    }
}
