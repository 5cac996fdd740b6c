//! `analyze`: one reference/deformed pair through the DIC engine, the same settings and the
//! same numbers as `ffdic analyze` on the same images.

use crate::errors::{dic_error, json_to_python, runtime_error, value_error};
use crate::input::InputImage;
use ffdic::dic::{
    analyze_sequence, DicResult, DicSettings, PoiResult, PoiStatus, PreparedReference, RasterMask,
};
use ffdic::image::{Image, Roi};
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyList;
use std::time::Instant;

/// The result of one analysis: per-point arrays (row-major over the grid of `grid_shape`),
/// the settings that made them and the summary `ffdic analyze --json` prints.
#[pyclass(frozen, module = "ffdic._ffdic")]
pub struct AnalysisResult {
    #[pyo3(get)]
    x: PyObject,
    #[pyo3(get)]
    y: PyObject,
    #[pyo3(get)]
    u: PyObject,
    #[pyo3(get)]
    v: PyObject,
    #[pyo3(get)]
    exx: PyObject,
    #[pyo3(get)]
    eyy: PyObject,
    #[pyo3(get)]
    exy: PyObject,
    #[pyo3(get)]
    zncc: PyObject,
    #[pyo3(get)]
    u_std_px: PyObject,
    #[pyo3(get)]
    v_std_px: PyObject,
    #[pyo3(get)]
    iterations: PyObject,
    /// Status codes, indices into `STATUSES` (0 = converged).
    #[pyo3(get)]
    status: PyObject,
    /// (rows, columns) of the point grid.
    #[pyo3(get)]
    grid_shape: (usize, usize),
    /// The ROI holding the point centres: (x, y, width, height), px.
    #[pyo3(get)]
    roi: (usize, usize, usize, usize),
    /// Size of the virtual strain gauge, px.
    #[pyo3(get)]
    strain_gauge_px: usize,
    /// Integer rigid offset of the global FFT cross-correlation, px.
    #[pyo3(get)]
    global_offset_px: (i64, i64),
    /// Every DIC setting, as `ffdic analyze` writes them to settings.json.
    #[pyo3(get)]
    settings: PyObject,
    /// Points, valid points, counts per status, mean/std/95 % interval/min/max of u, v and
    /// the strains: the document `ffdic analyze --json` prints.
    #[pyo3(get)]
    summary: PyObject,
    /// Wall time of the analysis (preparing the reference and correlating), s.
    #[pyo3(get)]
    elapsed_s: f64,
    /// Whether the reference and the deformed image were copied out of their arrays (False
    /// for C-contiguous float32: the engine read them where they lay).
    #[pyo3(get)]
    reference_copied: bool,
    #[pyo3(get)]
    deformed_copied: bool,
    /// In a sequence, the frame this one was correlated against (0: the reference given;
    /// k: the k-th deformed frame, after the reference moved). Always 0 for a pair.
    #[pyo3(get)]
    reference_index: usize,
    // For __repr__ and _repr_html_.
    summary_rows: Vec<(&'static str, [f64; 3], &'static str)>,
    counts: (usize, usize),
}

#[pymethods]
impl AnalysisResult {
    /// Status names per point (`converged`, `low_correlation`…).
    #[getter]
    fn status_names(&self, py: Python<'_>) -> PyResult<Vec<&'static str>> {
        let codes: Vec<u8> = self.status.extract(py)?;
        Ok(codes
            .into_iter()
            .map(|c| PoiStatus::ALL[c as usize].as_str())
            .collect())
    }

    fn __repr__(&self) -> String {
        let (points, valid) = self.counts;
        let mut s = format!(
            "AnalysisResult({points} points, {valid} valid, grid {}x{}, strain gauge {} px",
            self.grid_shape.0, self.grid_shape.1, self.strain_gauge_px
        );
        for (name, [mean, std, _], unit) in &self.summary_rows {
            s += &format!(", {name} mean {mean:.5} std {std:.5} {unit}");
        }
        s + ")"
    }

    fn _repr_html_(&self) -> String {
        let (points, valid) = self.counts;
        let mut s = format!(
            "<table><caption>ffdic analysis: {points} points, {valid} valid, strain gauge {} px, {:.3} s</caption>\
             <tr><th></th><th>mean</th><th>std</th><th>max |·|</th><th></th></tr>",
            self.strain_gauge_px, self.elapsed_s
        );
        for (name, [mean, std, max_abs], unit) in &self.summary_rows {
            s += &format!(
                "<tr><th>{name}</th><td>{mean:.5}</td><td>{std:.5}</td><td>{max_abs:.5}</td><td>{unit}</td></tr>"
            );
        }
        s + "</table>"
    }
}

/// DIC of `deformed` against `reference` (2-D arrays of one shape), or of each frame of a
/// sequence (`deformed` a list of arrays: displacements accumulated since the reference, the
/// reference moving on when the correlation drops, as `ffdic analyze REF F1 F2 …`). Every
/// keyword defaults to `ffdic analyze`'s value; `mask` (pairs only) is a 2-D array of the
/// reference's shape, non-zero where points are analysed. Releases the GIL while it runs;
/// `threads` bounds its worker threads (default: every core).
#[pyfunction]
#[pyo3(signature = (reference, deformed, *, subset=None, step=None, roi=None, strain_window=None,
    interp=None, shape=None, prefilter_sigma=None, min_zncc=None, max_motion=None,
    max_displacement_std=None, outlier_threshold=None, outlier_test=true, mask=None, threads=None))]
#[allow(clippy::too_many_arguments)]
pub fn analyze(
    py: Python<'_>,
    reference: &Bound<'_, PyAny>,
    deformed: &Bound<'_, PyAny>,
    subset: Option<usize>,
    step: Option<usize>,
    roi: Option<(usize, usize, usize, usize)>,
    strain_window: Option<usize>,
    interp: Option<&str>,
    shape: Option<&str>,
    prefilter_sigma: Option<f64>,
    min_zncc: Option<f64>,
    max_motion: Option<usize>,
    max_displacement_std: Option<f64>,
    outlier_threshold: Option<f64>,
    outlier_test: bool,
    mask: Option<&Bound<'_, PyAny>>,
    threads: Option<usize>,
) -> PyResult<PyObject> {
    let settings = dic_settings(
        subset,
        step,
        roi,
        strain_window,
        interp,
        shape,
        prefilter_sigma,
        min_zncc,
        max_motion,
        max_displacement_std,
        outlier_threshold,
        outlier_test,
    )?;
    if threads == Some(0) {
        return Err(value_error("threads: at least 1 (None: every core)"));
    }
    let pool = match threads {
        Some(n) => Some(
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(runtime_error)?,
        ),
        None => None,
    };
    let reference = InputImage::from_python(reference, "reference")?;
    if let Ok(frames) = deformed.downcast::<PyList>() {
        if mask.is_some() {
            return Err(value_error(
                "mask applies to one image pair (a sequence's points move from frame to frame)",
            ));
        }
        return analyze_frames(py, &reference, frames, &settings, pool.as_ref());
    }
    let deformed = same_shape(
        &reference,
        InputImage::from_python(deformed, "deformed")?,
        "deformed",
    )?;
    let mask = match mask {
        Some(m) => {
            let m = same_shape(&reference, InputImage::from_python(m, "mask")?, "mask")?;
            Some(RasterMask::from_image(&m.to_image()))
        }
        None => None,
    };
    let (ref_view, def_view) = (reference.view(), deformed.view());
    let started = Instant::now();
    let result = py
        .allow_threads(|| {
            in_pool(pool.as_ref(), || {
                PreparedReference::with_mask(ref_view, &settings, mask.as_ref())?
                    .correlate(def_view, None)
            })
        })
        .map_err(dic_error)?;
    let elapsed_s = started.elapsed().as_secs_f64();
    let r = build(
        py,
        &result,
        elapsed_s,
        reference.copied(),
        deformed.copied(),
    )?;
    Ok(Py::new(py, r)?.into_any())
}

/// DIC settings: the library's defaults, overridden by what the caller gave, validated.
#[allow(clippy::too_many_arguments)]
fn dic_settings(
    subset: Option<usize>,
    step: Option<usize>,
    roi: Option<(usize, usize, usize, usize)>,
    strain_window: Option<usize>,
    interp: Option<&str>,
    shape: Option<&str>,
    prefilter_sigma: Option<f64>,
    min_zncc: Option<f64>,
    max_motion: Option<usize>,
    max_displacement_std: Option<f64>,
    outlier_threshold: Option<f64>,
    outlier_test: bool,
) -> PyResult<DicSettings> {
    let d = DicSettings::default();
    let interpolation = match interp {
        None => d.interpolation,
        Some(s) => serde_json::from_value(serde_json::Value::String(s.into()))
            .map_err(|_| value_error(format!("interp: '{s}' is not bspline3 or bspline5")))?,
    };
    let shape = match shape {
        None => d.shape,
        Some(s) => s
            .parse()
            .map_err(|e: String| value_error(format!("shape: {e}")))?,
    };
    let settings = DicSettings {
        subset_px: subset.unwrap_or(d.subset_px),
        step_px: step.unwrap_or(d.step_px),
        roi: roi.map(|(x, y, w, h)| Roi::new(x, y, w, h)),
        strain_window: strain_window.unwrap_or(d.strain_window),
        interpolation,
        shape,
        prefilter_sigma_px: prefilter_sigma.unwrap_or(d.prefilter_sigma_px),
        min_zncc: min_zncc.unwrap_or(d.min_zncc),
        max_motion_px: max_motion.unwrap_or(d.max_motion_px),
        max_displacement_std_px: max_displacement_std.unwrap_or(d.max_displacement_std_px),
        outlier_threshold: if outlier_test {
            outlier_threshold.or(d.outlier_threshold)
        } else {
            None
        },
        ..d
    };
    settings.validate().map_err(dic_error)?;
    Ok(settings)
}

/// A sequence: every frame of `frames` against `reference`, accumulated (`analyze_sequence`).
fn analyze_frames(
    py: Python<'_>,
    reference: &InputImage<'_>,
    frames: &Bound<'_, PyList>,
    settings: &DicSettings,
    pool: Option<&rayon::ThreadPool>,
) -> PyResult<PyObject> {
    let frames = frames
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let name = format!("deformed[{k}]");
            same_shape(reference, InputImage::from_python(&f, &name)?, &name)
        })
        .collect::<PyResult<Vec<_>>>()?;
    let reference_image = reference.to_image();
    let images: Vec<Image> = frames.iter().map(InputImage::to_image).collect();
    let started = Instant::now();
    let sequence = py
        .allow_threads(|| {
            in_pool(pool, || {
                analyze_sequence(&reference_image, images, settings, |_| {})
            })
        })
        .map_err(dic_error)?;
    let elapsed_s = started.elapsed().as_secs_f64() / sequence.len().max(1) as f64;
    let results = sequence
        .iter()
        .zip(&frames)
        .map(|(frame, input)| {
            let mut r = build(
                py,
                &frame.result,
                elapsed_s,
                reference.copied(),
                input.copied(),
            )?;
            r.reference_index = frame.reference_index;
            Ok(Py::new(py, r)?.into_any())
        })
        .collect::<PyResult<Vec<PyObject>>>()?;
    Ok(PyList::new(py, results)?.into_any().unbind())
}

/// `image` (named `name`) when it has the reference's shape, else a `ValueError` naming both.
fn same_shape<'a>(
    reference: &InputImage<'_>,
    image: InputImage<'a>,
    name: &str,
) -> PyResult<InputImage<'a>> {
    if reference.shape() != image.shape() {
        return Err(value_error(format!(
            "reference and {name} differ in shape: {:?} and {:?}",
            reference.shape(),
            image.shape()
        )));
    }
    Ok(image)
}

/// `run` on `pool`'s threads, or on the global pool (every core) without one.
fn in_pool<T: Send>(pool: Option<&rayon::ThreadPool>, run: impl FnOnce() -> T + Send) -> T {
    match pool {
        Some(pool) => pool.install(run),
        None => run(),
    }
}

fn column(py: Python<'_>, points: &[PoiResult], f: impl Fn(&PoiResult) -> f64) -> PyObject {
    points
        .iter()
        .map(f)
        .collect::<Vec<f64>>()
        .into_pyarray(py)
        .into_any()
        .unbind()
}

fn build(
    py: Python<'_>,
    result: &DicResult,
    elapsed_s: f64,
    reference_copied: bool,
    deformed_copied: bool,
) -> PyResult<AnalysisResult> {
    let p = &result.points;
    let status: Vec<u8> = p
        .iter()
        .map(|q| {
            PoiStatus::ALL
                .iter()
                .position(|s| *s == q.status)
                .expect("every status is listed") as u8
        })
        .collect();
    let iterations: Vec<u32> = p.iter().map(|q| q.iterations).collect();
    let roi = result.grid.roi;
    let s = result.summary;
    let row = |st: ffdic::dic::Stats| [st.mean, st.std, st.min.abs().max(st.max.abs())];
    let scaled = |st: ffdic::dic::Stats| {
        let [m, sd, mx] = row(st);
        [m * 1e6, sd * 1e6, mx * 1e6]
    };
    Ok(AnalysisResult {
        x: column(py, p, |q| q.x),
        y: column(py, p, |q| q.y),
        u: column(py, p, |q| q.u),
        v: column(py, p, |q| q.v),
        exx: column(py, p, |q| q.exx),
        eyy: column(py, p, |q| q.eyy),
        exy: column(py, p, |q| q.exy),
        zncc: column(py, p, |q| q.zncc),
        u_std_px: column(py, p, |q| q.u_std_px),
        v_std_px: column(py, p, |q| q.v_std_px),
        iterations: iterations.into_pyarray(py).into_any().unbind(),
        status: status.into_pyarray(py).into_any().unbind(),
        grid_shape: (result.grid.ny(), result.grid.nx()),
        roi: (roi.x, roi.y, roi.width, roi.height),
        strain_gauge_px: result.strain_gauge_px,
        global_offset_px: result.global_offset_px,
        settings: json_to_python(py, &ffdic::report::dic_settings_json(result))?,
        summary: json_to_python(py, &ffdic::report::dic_summary_json(result))?,
        elapsed_s,
        reference_copied,
        deformed_copied,
        reference_index: 0,
        summary_rows: vec![
            ("u", row(s.u), "px"),
            ("v", row(s.v), "px"),
            ("exx", scaled(s.exx), "µε"),
            ("eyy", scaled(s.eyy), "µε"),
            ("exy", scaled(s.exy), "µε"),
        ],
        counts: (s.points, s.valid),
    })
}
