//! Which frames an experiment captures and how they are named: one plan shared by the bench
//! runner and `ffdic simulate`, so a captured and a simulated dataset of the same spec hold the
//! same files and runs.
//!
//! With `repeats` = N > 1 every pattern is captured N times, each capture a full reference, its
//! static frames and every move (new noise each time; optionally a new speckle layout), so the
//! study can state the spread of its statistics over independent captures — what the block
//! bootstrap within one capture cannot see (`dic::bootstrap`). With N = 1 the names are those of
//! earlier versions.

use super::spec::MoveSpec;
use crate::dataset::{PatternInfo, Run, StageMove};

/// One mounting of one target: a reference, its static frames, and one deformed frame per move.
#[derive(Clone, Debug, PartialEq)]
pub struct TargetCapture {
    /// Index into the experiment's patterns.
    pub pattern_index: usize,
    /// 1-based capture number, 1..=repeats.
    pub capture: usize,
    pub reference: String,
    /// Static frames at the reference position (noise floor).
    pub static_frames: Vec<String>,
    pub runs: Vec<CaptureRun>,
}

/// One reference/deformed pair of a capture.
#[derive(Clone, Debug, PartialEq)]
pub struct CaptureRun {
    /// The run's id in the manifest.
    pub id: String,
    /// With repeats: the id the study pools this capture's rows under (`{label}-{move}`).
    pub repeat_of: Option<String>,
    /// Index into the experiment's moves.
    pub move_index: usize,
    pub deformed: String,
}

/// The captures of `labels` × `repeats`, pattern by pattern (every capture of a pattern before
/// the next pattern, so a bench mounts each target once unless the layout changes).
pub fn capture_plan(
    labels: &[&str],
    moves: &[MoveSpec],
    static_frames: usize,
    repeats: usize,
) -> Vec<TargetCapture> {
    let mut plan = Vec::with_capacity(labels.len() * repeats);
    for (pattern_index, label) in labels.iter().enumerate() {
        for capture in 1..=repeats.max(1) {
            let (prefix, suffix) = if repeats > 1 {
                (format!("{label}_rep{capture}"), format!("-rep{capture}"))
            } else {
                (label.to_string(), String::new())
            };
            plan.push(TargetCapture {
                pattern_index,
                capture,
                reference: format!("{prefix}_ref.tif"),
                static_frames: (1..=static_frames)
                    .map(|k| format!("{prefix}_ref_r{k}.tif"))
                    .collect(),
                runs: moves
                    .iter()
                    .enumerate()
                    .map(|(move_index, m)| {
                        let pooled = format!("{label}-{}", m.id);
                        CaptureRun {
                            id: format!("{pooled}{suffix}"),
                            repeat_of: (repeats > 1).then_some(pooled),
                            move_index,
                            deformed: format!("{prefix}_{}.tif", m.id),
                        }
                    })
                    .collect(),
            });
        }
    }
    plan
}

/// The layout seed of capture `capture` of a target whose first layout has seed `first`: the
/// first capture keeps it (results of single-capture experiments do not change); later ones,
/// when a new layout is asked for, derive their own.
pub fn layout_seed(first: u64, capture: usize) -> u64 {
    if capture <= 1 {
        first
    } else {
        crate::model::derive_seed(first, 0x1A70, capture as u64)
    }
}

/// One frame of a capture, in the order taken: its file, where the stage stands (mm from
/// home), and the run whose deformed frame it is (None for the reference and static frames).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shot<'a> {
    pub file: &'a str,
    pub dx_mm: f64,
    pub dy_mm: f64,
    pub run: Option<&'a CaptureRun>,
}

impl TargetCapture {
    /// Frames this capture takes.
    pub fn frame_count(&self) -> usize {
        1 + self.static_frames.len() + self.runs.len()
    }

    /// The frames of this capture in the order a bench takes them and a simulation renders
    /// them: the reference and its static frames at home, then each move's deformed frame.
    pub fn shots<'a>(&'a self, moves: &'a [MoveSpec]) -> impl Iterator<Item = Shot<'a>> + 'a {
        let home = |file: &'a String| Shot {
            file,
            dx_mm: 0.0,
            dy_mm: 0.0,
            run: None,
        };
        std::iter::once(home(&self.reference))
            .chain(self.static_frames.iter().map(home))
            .chain(self.runs.iter().map(move |run| {
                let m = &moves[run.move_index];
                Shot {
                    file: &run.deformed,
                    dx_mm: m.dx_mm,
                    dy_mm: m.dy_mm,
                    run: Some(run),
                }
            }))
    }

    /// The manifest entry of `run` (one of this capture's), moved by `m`.
    pub fn manifest_run(
        &self,
        run: &CaptureRun,
        m: &MoveSpec,
        pattern: PatternInfo,
        exposure_us: Option<f64>,
    ) -> Run {
        Run {
            id: run.id.clone(),
            pattern: Some(pattern),
            reference: self.reference.clone(),
            deformed: run.deformed.clone(),
            stage: StageMove {
                dx_mm: m.dx_mm,
                dy_mm: m.dy_mm,
            },
            repeat: self.static_frames.clone(),
            exposure_us,
            repeat_of: run.repeat_of.clone(),
            capture: None,
            twin_of: None,
            extra: Default::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn moves() -> Vec<MoveSpec> {
        ["x", "y"]
            .iter()
            .map(|id| MoveSpec {
                id: id.to_string(),
                dx_mm: 1.0,
                dy_mm: 0.0,
            })
            .collect()
    }

    #[test]
    fn one_capture_keeps_the_names_of_earlier_versions() {
        let plan = capture_plan(&["a"], &moves(), 1, 1);
        assert_eq!(plan.len(), 1);
        assert_eq!(plan[0].reference, "a_ref.tif");
        assert_eq!(plan[0].static_frames, vec!["a_ref_r1.tif"]);
        assert_eq!(plan[0].runs[1].id, "a-y");
        assert_eq!(plan[0].runs[1].deformed, "a_y.tif");
        assert_eq!(plan[0].runs[1].repeat_of, None);
        let moves = moves();
        let shots: Vec<Shot> = plan[0].shots(&moves).collect();
        assert_eq!(shots.len(), plan[0].frame_count());
        assert_eq!(
            shots.iter().map(|s| s.file).collect::<Vec<_>>(),
            ["a_ref.tif", "a_ref_r1.tif", "a_x.tif", "a_y.tif"]
        );
        assert_eq!((shots[1].dx_mm, shots[1].run), (0.0, None));
        assert_eq!(shots[3].run.map(|r| r.id.as_str()), Some("a-y"));
        assert_eq!(shots[3].dx_mm, 1.0);
    }

    #[test]
    fn repeats_name_every_capture_and_pool_under_the_run() {
        let plan = capture_plan(&["a", "b"], &moves(), 0, 3);
        assert_eq!(plan.len(), 6);
        assert_eq!(
            (
                plan[2].pattern_index,
                plan[2].capture,
                plan[3].pattern_index
            ),
            (0, 3, 1)
        );
        assert_eq!(plan[2].reference, "a_rep3_ref.tif");
        assert_eq!(plan[2].runs[0].id, "a-x-rep3");
        assert_eq!(plan[2].runs[0].repeat_of.as_deref(), Some("a-x"));
        assert_eq!(plan[2].runs[0].deformed, "a_rep3_x.tif");
        let mut files: Vec<&str> = plan
            .iter()
            .flat_map(|c| {
                std::iter::once(c.reference.as_str())
                    .chain(c.runs.iter().map(|r| r.deformed.as_str()))
            })
            .collect();
        let n = files.len();
        files.sort();
        files.dedup();
        assert_eq!(files.len(), n, "every frame has its own file");
    }
}
