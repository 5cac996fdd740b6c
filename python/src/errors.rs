//! Library errors as Python exceptions: what the caller gave wrong is a `ValueError`, a file
//! that cannot be read an `OSError`, anything else a `RuntimeError`.

use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;

pub fn value_error(message: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(message.to_string())
}

pub fn dic_error(e: ffdic::dic::DicError) -> PyErr {
    // Every DIC error is about the inputs: settings, sizes, ROI, mask.
    value_error(e)
}

pub fn image_error(e: ffdic::image::ImageError) -> PyErr {
    use ffdic::image::ImageError;
    match e {
        ImageError::Open { .. } => PyOSError::new_err(e.to_string()),
        other => value_error(other),
    }
}

pub fn runtime_error(message: impl std::fmt::Display) -> PyErr {
    PyRuntimeError::new_err(message.to_string())
}

/// A JSON document as Python objects (dicts, lists, floats…), through the standard `json`
/// module so NaN and big integers come out as Python has them.
pub fn json_to_python(py: Python<'_>, value: &impl serde::Serialize) -> PyResult<PyObject> {
    let text = serde_json::to_string(value).map_err(runtime_error)?;
    Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
}
