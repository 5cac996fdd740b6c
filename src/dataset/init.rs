//! A manifest written from a folder of frames and a few facts (`ffdic dataset init`): one
//! reference, optional static repeats of it, and the other frames in name order as a step
//! series — frame k (from 1) moved by k steps. What a lab has after capturing a series by hand.

use super::manifest::{is_plain_file_name, DatasetError, Manifest, PatternInfo, Run, StageMove};
use crate::image::{frame_files, FRAME_EXTENSIONS};
use serde_json::Map;
use std::path::Path;

/// The step between consecutive frames, in the stage's mm or in the images' px.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    Mm(f64, f64),
    Px(f64, f64),
}

/// What `init_folder` is told about a folder (`ffdic dataset init`'s flags, Python's
/// `ffdic.dataset_init` keywords).
#[derive(Clone, Debug, PartialEq)]
pub struct FolderInit {
    pub scale_px_per_mm: f64,
    pub step: Step,
    /// Default: `guess_reference`.
    pub reference: Option<String>,
    pub repeats: Vec<String>,
    /// Default: the folder's name.
    pub name: Option<String>,
    pub pattern: Option<String>,
    pub stage_repeatability_um: Option<f64>,
    /// Replace an existing `dataset.json`.
    pub force: bool,
}

/// Writes `dir/dataset.json` for a folder of frames as `init` describes it, reads it back as
/// every command will, and returns it. Nothing is written on an error; every problem of the
/// description is named at once.
pub fn init_folder(dir: &Path, init: &FolderInit) -> Result<Manifest, DatasetError> {
    let target = dir.join("dataset.json");
    let invalid = |message: String| DatasetError::Invalid {
        path: target.clone(),
        message,
    };
    let scale = init.scale_px_per_mm;
    if !(scale.is_finite() && scale > 0.0) {
        return Err(invalid(format!(
            "scale {scale}: px per mm, a positive number"
        )));
    }
    if target.exists() && !init.force {
        return Err(invalid(
            "exists (`--force` on the command line, `force=True` in Python, replaces it)".into(),
        ));
    }
    let frames = frames_in(dir)?;
    let Some(reference) = init.reference.clone().or_else(|| guess_reference(&frames)) else {
        return Err(invalid(format!(
            "the folder holds no frame ({})",
            FRAME_EXTENSIONS.map(|e| format!(".{e}")).join(", ")
        )));
    };
    let step_mm = match init.step {
        Step::Mm(dx, dy) => (dx, dy),
        Step::Px(u, v) => (u / scale, v / scale),
    };
    let name = init.name.clone().unwrap_or_else(|| {
        std::fs::canonicalize(dir)
            .ok()
            .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .unwrap_or_else(|| "dataset".into())
    });
    let series = StepSeries {
        name,
        scale_px_per_mm: scale,
        frames,
        reference,
        repeats: init.repeats.clone(),
        step_mm,
        pattern: init.pattern.clone(),
        stage_repeatability_um: init.stage_repeatability_um,
    };
    let manifest = series.manifest().map_err(invalid)?;
    manifest.write(dir)?;
    Manifest::read(dir)
}

/// The folder's frame files, by name.
fn frames_in(dir: &Path) -> Result<Vec<String>, DatasetError> {
    let files = frame_files(dir).map_err(|source| DatasetError::Read {
        path: dir.to_path_buf(),
        source,
    })?;
    Ok(files
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect())
}

/// What a folder's frames are, as the user states it.
#[derive(Clone, Debug, PartialEq)]
pub struct StepSeries {
    pub name: String,
    pub scale_px_per_mm: f64,
    /// Every frame of the folder (plain file names); the order does not matter.
    pub frames: Vec<String>,
    pub reference: String,
    pub repeats: Vec<String>,
    /// The stage's move from one frame to the next, mm.
    pub step_mm: (f64, f64),
    pub pattern: Option<String>,
    pub stage_repeatability_um: Option<f64>,
}

/// The reference a folder's frames suggest when none is named: the frame whose stem is
/// `reference` or `ref` (any case), else the one that starts with `ref`, else the first by name.
pub fn guess_reference(frames: &[String]) -> Option<String> {
    let stem = |f: &String| {
        std::path::Path::new(f)
            .file_stem()
            .map(|s| s.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default()
    };
    let mut sorted = frames.to_vec();
    sorted.sort();
    sorted
        .iter()
        .find(|f| matches!(stem(f).as_str(), "reference" | "ref"))
        .or_else(|| sorted.iter().find(|f| stem(f).starts_with("ref")))
        .or_else(|| sorted.first())
        .cloned()
}

impl StepSeries {
    /// The manifest: one run per frame that is neither the reference nor a repeat, in name
    /// order, frame k moved by k steps; its run id is the frame's stem. Errs listing every
    /// problem at once (a reference or repeat not among the frames, no frame left to be moved).
    pub fn manifest(&self) -> Result<Manifest, String> {
        let mut problems = Vec::new();
        for f in std::iter::once(&self.reference).chain(&self.repeats) {
            if !self.frames.contains(f) {
                problems.push(format!("{f} is not one of the folder's frames"));
            }
        }
        for f in &self.frames {
            if !is_plain_file_name(f) {
                problems.push(format!("{f:?} is not a plain file name"));
            }
        }
        let mut moved: Vec<&String> = self
            .frames
            .iter()
            .filter(|f| **f != self.reference && !self.repeats.contains(f))
            .collect();
        moved.sort();
        if moved.is_empty() {
            problems.push(
                "no frame is left to be a moved one (all are the reference or repeats)".into(),
            );
        }
        let (dx, dy) = self.step_mm;
        if !(dx.is_finite() && dy.is_finite()) || (dx == 0.0 && dy == 0.0) {
            problems.push(format!(
                "the step ({dx}, {dy}) mm must be finite and not zero"
            ));
        }
        if !problems.is_empty() {
            return Err(problems.join("; "));
        }
        let mut manifest = Manifest::new(&self.name, self.scale_px_per_mm);
        manifest.stage_repeatability_um = self.stage_repeatability_um;
        manifest.runs = moved
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let k = (i + 1) as f64;
                Run {
                    id: std::path::Path::new(f.as_str())
                        .file_stem()
                        .map_or_else(|| f.to_string(), |s| s.to_string_lossy().into_owned()),
                    pattern: self.pattern.as_ref().map(|label| PatternInfo {
                        label: label.clone(),
                        ..PatternInfo::default()
                    }),
                    reference: self.reference.clone(),
                    deformed: f.to_string(),
                    stage: StageMove {
                        dx_mm: k * dx,
                        dy_mm: k * dy,
                    },
                    repeat: self.repeats.clone(),
                    exposure_us: None,
                    repeat_of: None,
                    capture: None,
                    twin_of: None,
                    extra: Map::new(),
                }
            })
            .collect();
        manifest.validate()?;
        Ok(manifest)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample3() -> StepSeries {
        let mut frames: Vec<String> = (0..=10).map(|k| format!("shift_{k:02}.tif")).collect();
        frames.push("reference.tif".into());
        StepSeries {
            name: "sample3".into(),
            scale_px_per_mm: 10.0,
            frames,
            reference: "reference.tif".into(),
            repeats: vec!["shift_00.tif".into()],
            step_mm: (0.01, 0.01),
            pattern: None,
            stage_repeatability_um: None,
        }
    }

    #[test]
    fn frame_k_is_moved_by_k_steps_in_name_order() {
        let m = sample3().manifest().unwrap();
        assert_eq!(m.runs.len(), 10);
        assert_eq!(m.runs[0].id, "shift_01");
        assert_eq!(m.runs[9].deformed, "shift_10.tif");
        assert!((m.runs[4].stage.dx_mm - 0.05).abs() < 1e-15);
        assert_eq!(m.runs[2].repeat, ["shift_00.tif"]);
        assert_eq!(
            guess_reference(&sample3().frames).as_deref(),
            Some("reference.tif")
        );
    }

    #[test]
    fn every_problem_is_listed_at_once() {
        let mut s = sample3();
        s.reference = "ref.tif".into();
        s.repeats = vec!["nope.tif".into()];
        s.step_mm = (0.0, 0.0);
        let err = s.manifest().unwrap_err();
        assert!(
            err.contains("ref.tif") && err.contains("nope.tif") && err.contains("step"),
            "{err}"
        );
    }
}
