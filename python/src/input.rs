//! numpy arrays in: a 2-D array of uint8, uint16, float32 or float64, C- or F-ordered or
//! strided, as the grey image the engine reads. A C-contiguous float32 array is lent to the
//! engine as it is (no copy); every other layout or dtype is converted once, in one pass.

use crate::errors::value_error;
use ffdic::image::{Image, ImageView};
use numpy::{
    Element, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

/// A grey image from Python: borrowed from the array or converted from it.
pub struct InputImage<'py> {
    width: usize,
    height: usize,
    pixels: Pixels<'py>,
}

enum Pixels<'py> {
    Borrowed(PyReadonlyArray2<'py, f32>),
    Converted(Vec<f32>),
}

impl<'py> InputImage<'py> {
    /// Reads `obj` (named `name` in errors).
    pub fn from_python(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Self> {
        let array = obj.downcast::<PyUntypedArray>().map_err(|_| {
            let type_name = obj
                .get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_else(|_| "?".into());
            value_error(format!(
                "{name}: expected a 2-D numpy array, got {type_name}"
            ))
        })?;
        if array.ndim() != 2 {
            return Err(value_error(format!(
                "{name}: expected a 2-D (grey) array, got {} dimensions, shape {:?}{}",
                array.ndim(),
                array.shape(),
                if array.ndim() == 3 {
                    " (convert colour frames to grey first)"
                } else {
                    ""
                }
            )));
        }
        let (height, width) = (array.shape()[0], array.shape()[1]);
        if width == 0 || height == 0 {
            return Err(value_error(format!(
                "{name}: the array is empty, shape ({height}, {width})"
            )));
        }
        let pixels = if let Ok(a) = obj.downcast::<PyArray2<f32>>() {
            let readonly = a.readonly();
            // (`as_slice` also accepts F-contiguous memory, which is the transpose.)
            if a.is_c_contiguous() && readonly.as_slice().is_ok() {
                Pixels::Borrowed(readonly)
            } else {
                Pixels::Converted(readonly.as_array().iter().copied().collect())
            }
        } else if let Some(v) = convert::<f64>(obj, |v| v as f32) {
            Pixels::Converted(v)
        } else if let Some(v) = convert::<u16>(obj, f32::from) {
            Pixels::Converted(v)
        } else if let Some(v) = convert::<u8>(obj, f32::from) {
            Pixels::Converted(v)
        } else {
            return Err(value_error(format!(
                "{name}: dtype {} is not supported (uint8, uint16, float32, float64, native byte order)",
                array.dtype().str().map(|s| s.to_string()).unwrap_or_default()
            )));
        };
        let image = Self {
            width,
            height,
            pixels,
        };
        let bad = image
            .view()
            .data()
            .iter()
            .filter(|v| !v.is_finite())
            .count();
        if bad > 0 {
            return Err(value_error(format!(
                "{name}: {bad} of {} pixels are NaN or infinite{}",
                width * height,
                if bad == width * height {
                    " (all of them)"
                } else {
                    ""
                }
            )));
        }
        Ok(image)
    }

    pub fn view(&self) -> ImageView<'_> {
        let data = match &self.pixels {
            Pixels::Borrowed(a) => a.as_slice().expect("checked contiguous"),
            Pixels::Converted(v) => v.as_slice(),
        };
        ImageView::new(self.width, self.height, data).expect("shape from the array")
    }

    /// Whether the pixels were copied out of the array (any layout but C-contiguous float32).
    pub fn copied(&self) -> bool {
        matches!(self.pixels, Pixels::Converted(_))
    }

    pub fn shape(&self) -> (usize, usize) {
        (self.height, self.width)
    }

    pub fn to_image(&self) -> Image {
        self.view().to_image()
    }
}

/// The array's values as f32 in row-major order, if its dtype is `T`.
fn convert<T: Element + Copy>(obj: &Bound<'_, PyAny>, f: impl Fn(T) -> f32) -> Option<Vec<f32>> {
    let a = obj.downcast::<PyArray2<T>>().ok()?;
    let readonly = a.readonly();
    let values = readonly.as_array().iter().map(|&v| f(v)).collect();
    Some(values)
}
