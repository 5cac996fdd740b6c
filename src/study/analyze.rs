//! The fill-factor study on a dataset (Hijazi, Rawashdeh & Kähler): for every run, reduce the
//! reference and the moved frame with every scheme, run the same DIC on each reduced pair, and
//! report the statistics with the increase of each standard deviation over the 100 % scheme —
//! the paper's Figures 5 (x: u, exx) and 6 (y: v, eyy).

use super::card::CardCorrection;
use super::rows::{Increase, IncreaseInterval, StudyRow};
use crate::dataset::{DatasetError, Manifest, Run};
use crate::dic::{CorrelationLengths, DicResult, DicSettings, Stats, Summary};
use crate::pairs::{correlate_pairs, PairError, PairVisitor, RunPair};
use crate::reduce::Scheme;
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// A frame unreadable, a pair of two sizes, a reduction or correlation that failed.
    #[error(transparent)]
    Pair(PairError),
    #[error("cancelled")]
    Cancelled,
}

impl From<PairError> for StudyError {
    fn from(e: PairError) -> Self {
        match e {
            PairError::Cancelled => StudyError::Cancelled,
            other => StudyError::Pair(other),
        }
    }
}

/// Runs the study over every run of a dataset in `dir`. `progress(done, total)` after each pair;
/// it returns whether to go on (false stops with [`StudyError::Cancelled`]). `cancelled` is asked
/// while a pair is correlated (from its threads, before every point): `true` stops it within a
/// point, with [`StudyError::Cancelled`].
pub fn analyze_dataset(
    dir: &Path,
    manifest: &Manifest,
    schemes: &[Scheme],
    dic: &DicSettings,
    progress: &(dyn Fn(usize, usize) -> bool + Sync),
    cancelled: &(dyn Fn() -> bool + Sync),
) -> Result<Vec<StudyRow>, StudyError> {
    analyze_dataset_with(
        dir,
        manifest,
        (schemes, dic, None),
        progress,
        cancelled,
        &|_, _, _| {},
    )
}

/// What [`analyze_dataset_with`] shows each full DIC result to (the run, the scheme, the fields),
/// before it keeps only the summary: the experiment runner draws its u, v and strain maps from it.
pub type ResultHook<'a> = dyn Fn(&Run, &Scheme, &DicResult) + Sync + 'a;

/// [`analyze_dataset`], handing every pair's full result to `on_result`; with a camera `card`,
/// each row also holds its displacement with the card's geometry taken off.
///
/// A run the camera read out in its own binning or decimation (`capture`) is correlated as it is,
/// under the hardware scheme's name, and compared with the first scheme of its full-resolution
/// twin (`twin_of`: same pattern, same move), so the table sets the sensor's scheme beside the
/// synthesised ones.
pub fn analyze_dataset_with(
    dir: &Path,
    manifest: &Manifest,
    (schemes, dic, card): (&[Scheme], &DicSettings, Option<&CardCorrection>),
    progress: &(dyn Fn(usize, usize) -> bool + Sync),
    cancelled: &(dyn Fn() -> bool + Sync),
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
    // The baseline (first scheme) of every full-resolution run a hardware run is the twin of,
    // kept until its last hardware run has used it.
    let mut pending: Vec<(String, usize)> = Vec::new();
    for twin in manifest.runs.iter().filter_map(|r| r.twin_of.as_deref()) {
        match pending.iter_mut().find(|(id, _)| id == twin) {
            Some((_, n)) => *n += 1,
            None => pending.push((twin.to_string(), 1)),
        }
    }
    let mut study = Study {
        scale_px_per_mm: manifest.scale_px_per_mm,
        rows: Vec::with_capacity(total),
        total,
        progress,
        cancelled,
        on_result,
        card,
        pending,
        twins: Vec::new(),
        baseline: None,
    };
    correlate_pairs(dir, &manifest.runs, schemes, dic, &mut study)?;
    Ok(study.rows)
}

/// The study's side of the pair loop: one row per result, each against its baseline.
struct Study<'a> {
    /// The dataset's scale at full resolution, px/mm.
    scale_px_per_mm: f64,
    rows: Vec<StudyRow>,
    total: usize,
    progress: &'a (dyn Fn(usize, usize) -> bool + Sync),
    cancelled: &'a (dyn Fn() -> bool + Sync),
    on_result: &'a ResultHook<'a>,
    card: Option<&'a CardCorrection>,
    /// Twin ids with the number of hardware runs still to use them.
    pending: Vec<(String, usize)>,
    /// (twin id, its baseline row, its baseline result)
    twins: Vec<(String, usize, DicResult)>,
    /// The current full-resolution run's baseline: (run index, row, result).
    baseline: Option<(usize, usize, DicResult)>,
}

impl Study<'_> {
    /// The baseline a result of `pair` is compared with: its run's first scheme, or for a
    /// hardware run its twin's. (row, result)
    fn base_of(&self, pair: &RunPair<'_>) -> Option<(usize, &DicResult)> {
        match &pair.run.twin_of {
            Some(twin) => self
                .twins
                .iter()
                .find(|(id, _, _)| id == twin)
                .map(|(_, row, result)| (*row, result)),
            None => match &self.baseline {
                Some((run, row, result)) if *run == pair.index => Some((*row, result)),
                _ => None,
            },
        }
    }

    /// A hardware run has used its twin's baseline: released after the twin's last one.
    fn release_twin(&mut self, twin: &str) {
        if let Some((_, n)) = self.pending.iter_mut().find(|(id, _)| id == twin) {
            *n -= 1;
            if *n == 0 {
                self.twins.retain(|(id, _, _)| id != twin);
            }
        }
    }
}

impl PairVisitor for Study<'_> {
    type Error = StudyError;

    fn cancelled(&self) -> bool {
        (self.cancelled)()
    }

    fn result(
        &mut self,
        pair: &RunPair<'_>,
        scheme: &Scheme,
        result: DicResult,
    ) -> Result<(), StudyError> {
        let run = pair.run;
        (self.on_result)(run, scheme, &result);
        let (increase_pct, increase_ci95) = match self.base_of(pair) {
            Some((row, base)) => (
                Some(increase(&self.rows[row].summary, &result.summary)),
                increase_interval(base, &result),
            ),
            None => (None, None),
        };
        if let Some(twin) = &run.twin_of {
            self.release_twin(twin);
        }
        let index = self.rows.len();
        self.rows.push(StudyRow {
            run: run.id.clone(),
            pattern: run
                .pattern
                .as_ref()
                .map_or_else(|| run.id.clone(), |p| p.label.clone()),
            scheme: scheme.name.clone(),
            fill_factor: scheme.linear_fill_factor(),
            summary: result.summary,
            increase_pct,
            increase_ci95,
            repeats: 1,
            expected_px: Some(expected_px(run, scheme, self.scale_px_per_mm)),
            card: self.card.map(|c| c.stats(Some(scheme), &result.points)),
        });
        let first_scheme =
            run.capture.is_none() && self.baseline.as_ref().map(|b| b.0) != Some(pair.index);
        if first_scheme {
            if self.pending.iter().any(|(id, n)| *id == run.id && *n > 0) {
                self.twins.push((run.id.clone(), index, result.clone()));
            }
            self.baseline = Some((pair.index, index, result));
        }
        if (self.progress)(self.rows.len(), self.total) {
            Ok(())
        } else {
            Err(StudyError::Cancelled)
        }
    }
}

/// The commanded move of `run` in the pixels `scheme` measures it in: the stage's move at the
/// dataset's scale, over the camera's own binning or decimation (a `capture` run's frames are
/// read out reduced) and the scheme's block, per axis.
fn expected_px(run: &Run, scheme: &Scheme, scale_px_per_mm: f64) -> [f64; 2] {
    let (capture_x, capture_y) = run
        .capture
        .as_ref()
        .map_or((1, 1), |c| (c.x.factor(), c.y.factor()));
    [
        run.stage.dx_mm * scale_px_per_mm / (capture_x as f64 * scheme.x.block as f64),
        run.stage.dy_mm * scale_px_per_mm / (capture_y as f64 * scheme.y.block as f64),
    ]
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
