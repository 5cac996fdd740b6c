//! `ffdic._ffdic`: the DIC engine, the reductions, the imaging model and the diagnosis of the
//! ffdic library on numpy arrays. The Python package `ffdic` (python/ffdic) wraps this module
//! and adds the HTTP client. Heavy calls release the GIL.

mod analysis;
mod dataset;
mod errors;
mod frames;
mod input;
mod study;

use pyo3::prelude::*;

#[pymodule]
fn _ffdic(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", ffdic::VERSION)?;
    m.add(
        "STATUSES",
        ffdic::dic::PoiStatus::ALL
            .iter()
            .map(|s| s.as_str())
            .collect::<Vec<_>>(),
    )?;
    m.add_class::<analysis::AnalysisResult>()?;
    m.add_function(wrap_pyfunction!(analysis::analyze, m)?)?;
    m.add_function(wrap_pyfunction!(frames::reduce, m)?)?;
    m.add_function(wrap_pyfunction!(frames::decode_tiff, m)?)?;
    m.add_function(wrap_pyfunction!(frames::read_image, m)?)?;
    m.add_function(wrap_pyfunction!(frames::render, m)?)?;
    m.add_function(wrap_pyfunction!(dataset::dataset_init, m)?)?;
    m.add_function(wrap_pyfunction!(study::compare, m)?)?;
    m.add_function(wrap_pyfunction!(study::diagnose, m)?)?;
    Ok(())
}
