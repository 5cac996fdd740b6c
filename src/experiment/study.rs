//! The fill-factor study on a dataset (Hijazi, Rawashdeh & Kähler): for every run, reduce the
//! reference and the moved frame with every scheme, run the same DIC on each reduced pair, and
//! report the statistics with the increase of each standard deviation over the 100 % scheme —
//! the paper's Figures 5 (x: u, exx) and 6 (y: v, eyy).

use crate::dataset::{DatasetError, Manifest, Run};
use crate::dic::{
    CorrelationLengths, DicError, DicResult, DicSettings, PreparedReference, Stats, Summary,
};
use crate::image::{read_tiff, Image, ImageError};
use crate::reduce::{reduce, AxisScheme, Scheme};
pub use crate::report::{Increase, IncreaseInterval, StudyRow};
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
///
/// A run the camera read out in its own binning or decimation (`capture`) is correlated as it is,
/// under the hardware scheme's name, and compared with the first scheme of its full-resolution
/// twin (`twin_of`: same pattern, same move), so the table sets the sensor's scheme beside the
/// synthesised ones.
pub fn analyze_dataset_with(
    dir: &Path,
    manifest: &Manifest,
    schemes: &[Scheme],
    dic: &DicSettings,
    progress: &(dyn Fn(usize, usize) -> bool + Sync),
    on_result: &ResultHook<'_>,
) -> Result<Vec<StudyRow>, StudyError> {
    let total: usize = manifest
        .runs
        .iter()
        .map(|r| {
            if r.capture.is_some() {
                1
            } else {
                schemes.len()
            }
        })
        .sum();
    let mut rows: Vec<StudyRow> = Vec::with_capacity(total);
    let mut frames = RunFrames::default();
    // The baseline (first scheme) of every full-resolution run a hardware run is the twin of,
    // kept until its last hardware run has used it.
    let mut pending: Vec<(&str, usize)> = Vec::new();
    for twin in manifest.runs.iter().filter_map(|r| r.twin_of.as_deref()) {
        match pending.iter_mut().find(|(id, _)| *id == twin) {
            Some((_, n)) => *n += 1,
            None => pending.push((twin, 1)),
        }
    }
    let mut twins: Vec<(String, usize, DicResult)> = Vec::new();
    for run in &manifest.runs {
        let (reference, deformed) = frames.read(dir, run)?;
        let pattern = run
            .pattern
            .as_ref()
            .map_or_else(|| run.id.clone(), |p| p.label.clone());
        // Appends the row of `scheme`; its index, or Cancelled when progress says stop.
        let mut row = |scheme: &Scheme, result: &DicResult, base: Option<(usize, &DicResult)>| {
            on_result(run, scheme, result);
            let index = rows.len();
            rows.push(StudyRow {
                run: run.id.clone(),
                pattern: pattern.clone(),
                scheme: scheme.name.clone(),
                fill_factor: scheme.linear_fill_factor(),
                summary: result.summary,
                increase_pct: base.map(|(i, _)| increase(&rows[i].summary, &result.summary)),
                increase_ci95: base.and_then(|(_, b)| increase_interval(b, result)),
                repeats: 1,
            });
            if progress(rows.len(), total) {
                Ok(index)
            } else {
                Err(StudyError::Cancelled)
            }
        };
        let dic_error = |scheme: &Scheme| {
            let (run, scheme) = (run.id.clone(), scheme.name.clone());
            move |source| StudyError::Dic {
                run,
                scheme,
                source,
            }
        };
        if let Some(hardware) = &run.capture {
            let scheme = hardware_geometry(hardware);
            let result = PreparedReference::new(&reference, dic)
                .and_then(|p| p.correlate(&deformed, None))
                .map_err(dic_error(&scheme))?;
            let twin = run
                .twin_of
                .as_ref()
                .and_then(|twin| twins.iter().position(|(id, _, _)| id == twin));
            let base = twin.map(|k| (twins[k].1, &twins[k].2));
            row(&scheme, &result, base)?;
            if let Some(k) = twin {
                let left = pending.iter_mut().find(|(id, _)| *id == twins[k].0);
                if let Some((_, n)) = left {
                    *n -= 1;
                    if *n == 0 {
                        twins.swap_remove(k);
                    }
                }
            }
            continue;
        }
        let is_twin = pending.iter().any(|(id, n)| *id == run.id && *n > 0);
        let mut baseline: Option<(usize, DicResult)> = None;
        for scheme in schemes {
            let result =
                study_pair_result(&reference, &deformed, scheme, dic).map_err(dic_error(scheme))?;
            let base = baseline.as_ref().map(|(i, r)| (*i, r));
            let index = row(scheme, &result, base)?;
            if baseline.is_none() {
                baseline = Some((index, result));
            }
        }
        if let (true, Some((index, result))) = (is_twin, baseline) {
            twins.push((run.id.clone(), index, result));
        }
    }
    Ok(rows)
}

/// A hardware scheme as the study's reduction vocabulary: the same block per axis, the whole
/// block active when binned, its first pixel when decimated; the name keeps the `hw:` prefix.
fn hardware_geometry(scheme: &ffdic_hw::HardwareScheme) -> Scheme {
    let axis = |a: ffdic_hw::AxisReduction| AxisScheme {
        block: a.factor() as usize,
        first: 0,
        active: a.active_px() as usize,
    };
    Scheme {
        name: scheme.name.clone(),
        x: axis(scheme.x),
        y: axis(scheme.y),
    }
}

/// The frames of one run after another: runs of one pattern share the reference, read once
/// (a few are kept: an experiment with hardware schemes alternates between the full-resolution
/// reference and each scheme's).
#[derive(Default)]
struct RunFrames {
    references: Vec<(String, Image)>,
}

/// References kept by [`RunFrames`]: the full-resolution one and three hardware schemes'.
const REFERENCES_KEPT: usize = 4;

impl RunFrames {
    fn read(&mut self, dir: &Path, run: &Run) -> Result<(Image, Image), StudyError> {
        let cached = self.references.iter().find(|(n, _)| *n == run.reference);
        let reference = match cached {
            Some((_, img)) => img.clone(),
            None => {
                let (img, _) = read_tiff(&dir.join(&run.reference))?;
                if self.references.len() == REFERENCES_KEPT {
                    self.references.remove(0);
                }
                self.references.push((run.reference.clone(), img.clone()));
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
        Ok((reference, deformed))
    }
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
/// of the same grid drawn in both (their errors are correlated: one pair of frames reduced
/// twice, or a hardware scheme's frames of the same print and move as the twin's). None when the grids differ in shape or hold too few blocks.
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
