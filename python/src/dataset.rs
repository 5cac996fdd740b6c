//! `dataset_init`: a folder of frames captured by hand made a dataset, as `ffdic dataset init`
//! makes it (the library's `init_folder`: the same manifest, the same errors).

use crate::errors::{json_to_python, value_error};
use ffdic::dataset::{init_folder, DatasetError, FolderInit, Step};
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use std::path::PathBuf;

/// Writes `folder/dataset.json` for a step series: a reference, its static repeats, and the
/// other frames in name order, frame k moved by k steps. Returns the manifest as a dict.
#[pyfunction]
#[pyo3(signature = (folder, *, scale_px_per_mm, step_mm=None, step_px=None, reference=None,
    repeats=Vec::new(), name=None, pattern=None, stage_repeatability_um=None, force=false))]
#[allow(clippy::too_many_arguments)]
pub fn dataset_init(
    py: Python<'_>,
    folder: PathBuf,
    scale_px_per_mm: f64,
    step_mm: Option<(f64, f64)>,
    step_px: Option<(f64, f64)>,
    reference: Option<String>,
    repeats: Vec<String>,
    name: Option<String>,
    pattern: Option<String>,
    stage_repeatability_um: Option<f64>,
    force: bool,
) -> PyResult<PyObject> {
    let step = match (step_mm, step_px) {
        (Some((dx, dy)), None) => Step::Mm(dx, dy),
        (None, Some((u, v))) => Step::Px(u, v),
        (Some(_), Some(_)) => return Err(value_error("give step_mm or step_px, not both")),
        (None, None) => return Err(value_error("the step: step_mm=(dx, dy) or step_px=(u, v)")),
    };
    let init = FolderInit {
        scale_px_per_mm,
        step,
        reference,
        repeats,
        name,
        pattern,
        stage_repeatability_um,
        force,
    };
    let manifest = py
        .allow_threads(|| init_folder(&folder, &init))
        .map_err(|e| match e {
            DatasetError::Invalid { .. } => value_error(e),
            DatasetError::Read { .. } | DatasetError::Write { .. } => {
                PyOSError::new_err(e.to_string())
            }
        })?;
    json_to_python(py, &manifest)
}
