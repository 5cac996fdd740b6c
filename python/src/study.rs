//! A dataset against the imaging model: `compare` and `diagnose`, the same documents as
//! `ffdic compare --json` and `ffdic diagnose --json`.

use crate::errors::{json_to_python, value_error};
use crate::frames::model_config;
use ffdic::diagnose::{
    append_history, compare as compare_dataset, diagnose_rounds, history_dir_for, CompareOptions,
    CompareOptionsError, DiagnoseError, HistoryEntry, MAX_ROUNDS,
};
use ffdic::dic::DicSettings;
use pyo3::exceptions::{PyOSError, PyRuntimeError};
use pyo3::prelude::*;
use std::path::{Path, PathBuf};

/// The analysis of both sides, from the CLI's options (schemes as `Scheme::parse` reads them).
fn options(
    schemes: Vec<String>,
    subset: Option<usize>,
    step: Option<usize>,
    prefilter_sigma: Option<f64>,
    seed: Option<u64>,
) -> PyResult<CompareOptions> {
    let d = DicSettings::default();
    let dic = DicSettings {
        subset_px: subset.unwrap_or(d.subset_px),
        step_px: step.unwrap_or(d.step_px),
        prefilter_sigma_px: prefilter_sigma.unwrap_or(d.prefilter_sigma_px),
        ..d
    };
    let seed = seed.unwrap_or(CompareOptions::default().seed);
    CompareOptions::from_scheme_specs(&schemes, dic, seed).map_err(|e| match e {
        CompareOptionsError::Dic(e) => value_error(e),
        other => value_error(format!("schemes: {other}")),
    })
}

fn diagnose_error(e: DiagnoseError) -> PyErr {
    match e {
        DiagnoseError::Dataset(_) | DiagnoseError::Image(_) => PyOSError::new_err(e.to_string()),
        other => PyRuntimeError::new_err(other.to_string()),
    }
}

fn dataset_dir(dataset: &Path) -> PyResult<PathBuf> {
    if !dataset.join("dataset.json").is_file() {
        return Err(value_error(format!(
            "{}: not a dataset folder (no dataset.json)",
            dataset.display()
        )));
    }
    Ok(dataset.to_owned())
}

/// DIC on the dataset's frames against the same DIC on the frames `model` renders for the same
/// nominal experiment; recorded in the dataset's history under `data_dir` unless `history=False`.
#[pyfunction]
#[pyo3(signature = (dataset, model=None, *, schemes=vec!["ff100".into(), "ff50".into(), "ff25".into()],
    subset=None, step=None, prefilter_sigma=None, seed=None, history=true, data_dir="data"))]
#[allow(clippy::too_many_arguments)]
pub fn compare(
    py: Python<'_>,
    dataset: PathBuf,
    model: Option<&str>,
    schemes: Vec<String>,
    subset: Option<usize>,
    step: Option<usize>,
    prefilter_sigma: Option<f64>,
    seed: Option<u64>,
    history: bool,
    data_dir: &str,
) -> PyResult<PyObject> {
    let dir = dataset_dir(&dataset)?;
    let model = model_config(model, "baseline", Path::new(data_dir))?;
    let options = options(schemes, subset, step, prefilter_sigma, seed)?;
    let cmp = py
        .allow_threads(|| compare_dataset(&dir, &model, &options, &|_, _| true))
        .map_err(diagnose_error)?;
    if history {
        let into = history_dir_for(Path::new(data_dir), &dir);
        append_history(&into, &HistoryEntry::of(&cmp)).map_err(diagnose_error)?;
    }
    json_to_python(py, &cmp)
}

/// Which physical effect the model misses: fits every candidate effect, ranks them, and with
/// `rounds` > 1 adds the winner and diagnoses again. The document of `ffdic diagnose --json`,
/// plus `final_model_toml` (the model with every winner added) when a round found one.
#[pyfunction]
#[pyo3(signature = (dataset, model=None, *, rounds=1, schemes=vec!["ff100".into(), "ff50".into(), "ff25".into()],
    subset=None, step=None, prefilter_sigma=None, seed=None, data_dir="data"))]
#[allow(clippy::too_many_arguments)]
pub fn diagnose(
    py: Python<'_>,
    dataset: PathBuf,
    model: Option<&str>,
    rounds: usize,
    schemes: Vec<String>,
    subset: Option<usize>,
    step: Option<usize>,
    prefilter_sigma: Option<f64>,
    seed: Option<u64>,
    data_dir: &str,
) -> PyResult<PyObject> {
    if !(1..=MAX_ROUNDS).contains(&rounds) {
        return Err(value_error(format!("rounds: 1 to {MAX_ROUNDS}")));
    }
    let dir = dataset_dir(&dataset)?;
    let model = model_config(model, "baseline", Path::new(data_dir))?;
    let options = options(schemes, subset, step, prefilter_sigma, seed)?;
    let r = py
        .allow_threads(|| diagnose_rounds(&dir, &model, &options, rounds, &|_, _| true))
        .map_err(diagnose_error)?;
    let mut doc = r.to_json();
    if !r.verdicts.is_empty() {
        doc["final_model_toml"] = serde_json::Value::String(r.final_model.to_toml());
    }
    json_to_python(py, &doc)
}
