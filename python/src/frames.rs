//! Frames: fill-factor reductions, TIFF decoding and the imaging model's rendering.

use crate::errors::{image_error, json_to_python, runtime_error, value_error};
use crate::input::InputImage;
use ffdic::experiment::{simulate_dataset, ExperimentSpec};
use ffdic::image::{FrameInfo, Image};
use ffdic::reduce::Scheme;
use numpy::ndarray::Array2;
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::Path;

/// A scheme by preset name (`ff100`, `ff50`, `ff25`, any case) or as the JSON the API takes:
/// `{"name": …, "x": {"block", "first", "active"}, "y": {…}}`.
fn scheme(spec: &str) -> PyResult<Scheme> {
    if spec.trim_start().starts_with('{') {
        let s: Scheme = serde_json::from_str(spec)
            .map_err(|e| value_error(format!("scheme: not a scheme description: {e}")))?;
        Scheme::new(&s.name, s.x, s.y).map_err(|e| value_error(format!("scheme: {e}")))
    } else {
        Scheme::parse(spec).map_err(|e| value_error(format!("scheme: {e}")))
    }
}

fn to_array(py: Python<'_>, image: Image) -> PyObject {
    let (w, h) = (image.width(), image.height());
    Array2::from_shape_vec((h, w), image.into_vec())
        .expect("an image's shape holds")
        .into_pyarray(py)
        .into_any()
        .unbind()
}

/// A frame with the fill factor of `scheme` synthesised from it (float32; see
/// `ffdic::reduce`). `scheme_json` is a preset name or a scheme as JSON.
#[pyfunction]
#[pyo3(signature = (frame, scheme_json="ff50"))]
pub fn reduce(py: Python<'_>, frame: &Bound<'_, PyAny>, scheme_json: &str) -> PyResult<PyObject> {
    let scheme = scheme(scheme_json)?;
    let image = InputImage::from_python(frame, "frame")?.to_image();
    let reduced = py
        .allow_threads(|| ffdic::reduce::reduce(&image, &scheme))
        .map_err(|e| value_error(format!("reduce: {e}")))?;
    Ok(to_array(py, reduced))
}

/// An image as stored: uint8 or uint16 for integer TIFFs, float32 otherwise.
fn stored(py: Python<'_>, image: Image, info: FrameInfo) -> PyObject {
    let (w, h) = (image.width(), image.height());
    let data = image.into_vec();
    // Integer grey values are exact in f32 (at most 16 bits).
    match info.bit_depth {
        8 => Array2::from_shape_vec((h, w), data.iter().map(|&v| v as u8).collect())
            .expect("shape")
            .into_pyarray(py)
            .into_any()
            .unbind(),
        16 => Array2::from_shape_vec((h, w), data.iter().map(|&v| v as u16).collect())
            .expect("shape")
            .into_pyarray(py)
            .into_any()
            .unbind(),
        _ => to_array(py, Image::from_vec(w, h, data).expect("shape")),
    }
}

/// A TIFF file's bytes (a frame fetched from the daemon) as a 2-D array.
#[pyfunction]
pub fn decode_tiff(py: Python<'_>, data: &[u8]) -> PyResult<PyObject> {
    let (image, info) =
        ffdic::image::decode_tiff(data, Path::new("<bytes>")).map_err(image_error)?;
    Ok(stored(py, image, info))
}

/// A TIFF, PNG or BMP file as a 2-D array (what `ffdic analyze` reads).
#[pyfunction]
pub fn read_image(py: Python<'_>, path: std::path::PathBuf) -> PyResult<PyObject> {
    let (image, info) = ffdic::image::read_image(&path).map_err(image_error)?;
    Ok(stored(py, image, info))
}

/// An experiment from a TOML file path or TOML text; the paper's study when `None`.
pub fn experiment_spec(given: Option<&str>) -> PyResult<ExperimentSpec> {
    match given {
        None => Ok(ExperimentSpec::paper()),
        Some(text) if Path::new(text).is_file() => {
            ExperimentSpec::load(Path::new(text)).map_err(value_error)
        }
        Some(text) => {
            ExperimentSpec::from_toml(text, Path::new("<experiment>")).map_err(value_error)
        }
    }
}

/// A model from a file path, an embedded or stored name, or TOML text.
pub fn model_config(
    given: Option<&str>,
    default_name: &str,
    data_dir: &Path,
) -> PyResult<ffdic::model::ModelConfig> {
    let given = given.unwrap_or(default_name);
    if given.contains('\n') || given.contains('=') {
        return ffdic::model::ModelConfig::from_toml(given, Path::new("<model>"))
            .map_err(value_error);
    }
    ffdic::service::find_analysis_model(Some(given), data_dir).map_err(value_error)
}

/// The frames the imaging model renders for an experiment, exactly as `ffdic simulate` writes
/// them: `{"manifest": dict, "frames": {file name: uint16 array}}`.
#[pyfunction]
#[pyo3(signature = (experiment=None, model=None, seed=None, data_dir="data"))]
pub fn render(
    py: Python<'_>,
    experiment: Option<&str>,
    model: Option<&str>,
    seed: Option<u64>,
    data_dir: &str,
) -> PyResult<PyObject> {
    let spec = experiment_spec(experiment)?;
    let model = model_config(model, "paper-bench", Path::new(data_dir))?;
    let seed = seed.unwrap_or(spec.seed);
    let dir = tempfile::tempdir().map_err(runtime_error)?;
    let manifest = py
        .allow_threads(|| simulate_dataset(&spec, &model, seed, dir.path(), &|_, _| {}))
        .map_err(value_error)?;
    let frames = PyDict::new(py);
    for file in manifest.frame_files() {
        let (image, info) =
            ffdic::image::read_tiff(&dir.path().join(&file)).map_err(image_error)?;
        frames.set_item(file, stored(py, image, info))?;
    }
    let out = PyDict::new(py);
    out.set_item("manifest", json_to_python(py, &manifest)?)?;
    out.set_item("frames", frames)?;
    Ok(out.into_any().unbind())
}
