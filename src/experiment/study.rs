//! The fill-factor study on a dataset (Hijazi, Rawashdeh & Kähler): for every run, reduce the
//! reference and the moved frame with every scheme, run the same DIC on each reduced pair, and
//! report the statistics with the increase of each standard deviation over the 100 % scheme —
//! the paper's Figures 5 (x: u, exx) and 6 (y: v, eyy).

use crate::dataset::{DatasetError, Manifest, Run};
use crate::dic::{f64_or_nan, interval_or_nan};
use crate::dic::{
    CorrelationLengths, DicError, DicResult, DicSettings, PreparedReference, Stats, Summary,
};
use crate::image::{read_tiff, Image, ImageError};
use crate::reduce::{reduce, Scheme};
use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    #[error("run {run}, scheme {scheme}: {source}")]
    Dic {
        run: String,
        scheme: String,
        source: DicError,
    },
    #[error("cancelled")]
    Cancelled,
    #[error("run {run}: reference is {ref_w}x{ref_h}, deformed {def_w}x{def_h}")]
    SizeMismatch {
        run: String,
        ref_w: usize,
        ref_h: usize,
        def_w: usize,
        def_h: usize,
    },
}

/// Percent increase of each standard deviation over the same run's first (100 %) scheme.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Increase {
    #[serde(deserialize_with = "f64_or_nan")]
    pub u: f64,
    #[serde(deserialize_with = "f64_or_nan")]
    pub v: f64,
    #[serde(deserialize_with = "f64_or_nan")]
    pub exx: f64,
    #[serde(deserialize_with = "f64_or_nan")]
    pub eyy: f64,
    #[serde(deserialize_with = "f64_or_nan")]
    pub exy: f64,
}

/// 95 % intervals of the [`Increase`] percentages: a block bootstrap resampling the same
/// grid blocks in the baseline and this scheme (`dic::bootstrap`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct IncreaseInterval {
    #[serde(deserialize_with = "interval_or_nan")]
    pub u: [f64; 2],
    #[serde(deserialize_with = "interval_or_nan")]
    pub v: [f64; 2],
    #[serde(deserialize_with = "interval_or_nan")]
    pub exx: [f64; 2],
    #[serde(deserialize_with = "interval_or_nan")]
    pub eyy: [f64; 2],
    #[serde(deserialize_with = "interval_or_nan")]
    pub exy: [f64; 2],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StudyRow {
    pub run: String,
    pub pattern: String,
    pub scheme: String,
    /// Linear fill factors (x, y) of the scheme.
    pub fill_factor: (f64, f64),
    pub summary: Summary,
    /// None for the baseline scheme itself.
    pub increase_pct: Option<Increase>,
    /// None for the baseline, and where the two grids differ in shape or hold too few blocks.
    #[serde(default)]
    pub increase_ci95: Option<IncreaseInterval>,
    /// Independent captures pooled into this row (`pool::pool_captures`); 1 for a single capture,
    /// whose intervals are the block bootstrap's.
    #[serde(default = "one_capture")]
    pub repeats: usize,
}

fn one_capture() -> usize {
    1
}

/// Runs the study over every run of a dataset in `dir`. `progress(done, total)` after each pair;
/// it returns whether to go on (false stops with [`StudyError::Cancelled`]).
pub fn analyze_dataset(
    dir: &Path,
    manifest: &Manifest,
    schemes: &[Scheme],
    dic: &DicSettings,
    progress: &(dyn Fn(usize, usize) -> bool + Sync),
) -> Result<Vec<StudyRow>, StudyError> {
    analyze_dataset_with(dir, manifest, schemes, dic, progress, &|_, _, _| {})
}

/// What [`analyze_dataset_with`] shows each full DIC result to (the run, the scheme, the fields),
/// before it keeps only the summary: the experiment runner draws its u, v and strain maps from it.
pub type ResultHook<'a> = dyn Fn(&Run, &Scheme, &DicResult) + Sync + 'a;

/// [`analyze_dataset`], handing every pair's full result to `on_result`.
pub fn analyze_dataset_with(
    dir: &Path,
    manifest: &Manifest,
    schemes: &[Scheme],
    dic: &DicSettings,
    progress: &(dyn Fn(usize, usize) -> bool + Sync),
    on_result: &ResultHook<'_>,
) -> Result<Vec<StudyRow>, StudyError> {
    let total = manifest.runs.len() * schemes.len();
    let mut rows = Vec::with_capacity(total);
    let mut cached: Option<(String, Image)> = None;
    for run in &manifest.runs {
        // Runs of one pattern share the reference: read it once.
        let reference = match &cached {
            Some((name, img)) if *name == run.reference => img.clone(),
            _ => {
                let (img, _) = read_tiff(&dir.join(&run.reference))?;
                cached = Some((run.reference.clone(), img.clone()));
                img
            }
        };
        let (deformed, _) = read_tiff(&dir.join(&run.deformed))?;
        if (reference.width(), reference.height()) != (deformed.width(), deformed.height()) {
            return Err(StudyError::SizeMismatch {
                run: run.id.clone(),
                ref_w: reference.width(),
                ref_h: reference.height(),
                def_w: deformed.width(),
                def_h: deformed.height(),
            });
        }
        let pattern = run
            .pattern
            .as_ref()
            .map_or_else(|| run.id.clone(), |p| p.label.clone());
        let first_row = rows.len();
        let mut baseline: Option<DicResult> = None;
        for scheme in schemes {
            let result =
                study_pair_result(&reference, &deformed, scheme, dic).map_err(|source| {
                    StudyError::Dic {
                        run: run.id.clone(),
                        scheme: scheme.name.clone(),
                        source,
                    }
                })?;
            on_result(run, scheme, &result);
            let summary = result.summary;
            let increase_pct = (rows.len() > first_row).then(|| {
                let base: &StudyRow = &rows[first_row];
                increase(&base.summary, &summary)
            });
            let increase_ci95 = baseline
                .as_ref()
                .and_then(|base| increase_interval(base, &result));
            if baseline.is_none() {
                baseline = Some(result);
            }
            rows.push(StudyRow {
                run: run.id.clone(),
                pattern: pattern.clone(),
                scheme: scheme.name.clone(),
                fill_factor: scheme.linear_fill_factor(),
                summary,
                increase_pct,
                increase_ci95,
                repeats: 1,
            });
            if !progress(rows.len(), total) {
                return Err(StudyError::Cancelled);
            }
        }
    }
    Ok(rows)
}

/// DIC of one full-resolution pair after reduction with `scheme`: every point's displacement
/// and strain, and their summary.
pub fn study_pair_result(
    reference: &Image,
    deformed: &Image,
    scheme: &Scheme,
    dic: &DicSettings,
) -> Result<DicResult, DicError> {
    let r = reduce(reference, scheme).map_err(|e| DicError::Setting {
        field: "scheme",
        reason: e.to_string(),
    })?;
    let d = reduce(deformed, scheme).map_err(|e| DicError::Setting {
        field: "scheme",
        reason: e.to_string(),
    })?;
    PreparedReference::new(&r, dic)?.correlate(&d, None)
}

fn increase(base: &Summary, s: &Summary) -> Increase {
    let pct = |b: &Stats, x: &Stats| 100.0 * (x.std / b.std - 1.0);
    Increase {
        u: pct(&base.u, &s.u),
        v: pct(&base.v, &s.v),
        exx: pct(&base.exx, &s.exx),
        eyy: pct(&base.eyy, &s.eyy),
        exy: pct(&base.exy, &s.exy),
    }
}

/// The paired bootstrap interval of every % increase of `result` over `base`: the same blocks
/// of the same grid drawn in both (their errors are correlated: one pair of frames, reduced
/// twice). None when the grids differ in shape or hold too few blocks.
fn increase_interval(base: &DicResult, result: &DicResult) -> Option<IncreaseInterval> {
    let (nx, ny) = (result.grid.nx(), result.grid.ny());
    if (base.grid.nx(), base.grid.ny()) != (nx, ny) || base.points.len() != result.points.len() {
        return None;
    }
    let (b, f) = (
        crate::dic::valid_fields(&base.points),
        crate::dic::valid_fields(&result.points),
    );
    let (disp, strain) = CorrelationLengths::of(&result.settings).plans(nx, ny);
    let disp = disp?.increase_intervals(&[&b[0], &b[1]], &[&f[0], &f[1]]);
    let strain = strain
        .map(|plan| plan.increase_intervals(&[&b[2], &b[3], &b[4]], &[&f[2], &f[3], &f[4]]))
        .unwrap_or_else(|| vec![[f64::NAN; 2]; 3]);
    Some(IncreaseInterval {
        u: disp[0],
        v: disp[1],
        exx: strain[0],
        eyy: strain[1],
        exy: strain[2],
    })
}
