//! One experiment on the bench, start to finish: for every pattern, mount it, capture the
//! reference at the home position, move the stage through every commanded translation, wait for
//! it to settle, capture; write the frames as an `ffdic-dataset/1` export; then reduce every pair
//! with every scheme and run DIC (the paper's study), and write the results and figures.
//!
//! The runner knows nothing of HTTP or SQLite: it reports through a [`RunSink`], which the
//! service implements over the run store and the event stream, and `ffdic reproduce` over the same.

use super::bench::{BenchError, BenchHandle, BenchLease, BenchStatus, Owner};
use super::captures::{capture_plan, layout_seed, TargetCapture};
use super::figures::study_files;
use super::maps::field_map_svgs;
use super::request::ExperimentPlan;
use super::study::{analyze_dataset_with, StudyError, StudyRow};
use crate::dataset::{CameraInfo, Manifest, Run};
use crate::image::{tiff_u16_bytes, ImageError};
use crate::run_event::EventKind;
use ffdic_hw::{CameraSettings, Frame, StagePosition};
use serde_json::{json, Value};
use std::path::PathBuf;
use std::time::Duration;

/// Where a run reports to and writes into.
pub trait RunSink: Sync {
    /// A typed event for the run's log and live subscribers; `progress` in 0..=1.
    fn event(&self, kind: EventKind, progress: f64, message: &str, data: Value);
    /// Writes `bytes` atomically at `rel` inside the run folder; returns the full path.
    fn write(&self, rel: &str, bytes: &[u8]) -> Result<PathBuf, String>;
    /// Whether the run was asked to stop.
    fn cancelled(&self) -> bool;
}

#[derive(Debug, thiserror::Error)]
pub enum RunnerError {
    #[error("cancelled")]
    Cancelled,
    #[error(transparent)]
    Bench(#[from] BenchError),
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error(transparent)]
    Study(#[from] StudyError),
    #[error("cannot write {0}")]
    Write(String),
    #[error("the camera delivered frames of different sizes ({0})")]
    FrameSize(String),
}

/// What a finished experiment produced.
#[derive(Clone, Debug)]
pub struct ExperimentOutcome {
    pub manifest: Manifest,
    /// The dataset export: `frames/` of the run folder.
    pub frames_dir: PathBuf,
    pub rows: Vec<StudyRow>,
    pub files: Vec<String>,
}

/// Timeouts of the bench steps.
#[derive(Clone, Copy, Debug)]
pub struct BenchTimeouts {
    pub frame: Duration,
    pub settle: Duration,
    pub home: Duration,
}

impl Default for BenchTimeouts {
    fn default() -> Self {
        Self {
            frame: Duration::from_secs(20),
            settle: Duration::from_secs(60),
            home: Duration::from_secs(120),
        }
    }
}

/// Share of the progress bar the capture takes; the analysis takes the rest.
const CAPTURE_SHARE: f64 = 0.5;

pub fn run_experiment(
    plan: &ExperimentPlan,
    bench: &BenchHandle,
    lease: &BenchLease,
    scale_px_per_mm: f64,
    timeouts: BenchTimeouts,
    sink: &dyn RunSink,
) -> Result<ExperimentOutcome, RunnerError> {
    let result = capture_and_analyse(plan, bench, lease, scale_px_per_mm, timeouts, sink);
    if result.is_err() {
        // Whatever happened, leave the stage standing still.
        let _ = bench.stop_stage(Owner::Run(lease.run_id.clone()));
    }
    result
}

/// The experiment's steps: prepare the bench, capture and export, analyse, write the results.
fn capture_and_analyse(
    plan: &ExperimentPlan,
    bench: &BenchHandle,
    lease: &BenchLease,
    scale_px_per_mm: f64,
    timeouts: BenchTimeouts,
    sink: &dyn RunSink,
) -> Result<ExperimentOutcome, RunnerError> {
    let mut files = Files {
        sink,
        written: Vec::new(),
    };
    let session = Session::prepare(plan, bench, lease, timeouts, sink)?;
    let captured = session.capture(&mut files, scale_px_per_mm)?;
    session.check()?;
    let (captures, map_files) = analyse(plan, &captured, sink)?;
    let rows = write_results(plan, &captured.manifest, &captures, &mut files)?;
    files.written.extend(map_files);
    Ok(ExperimentOutcome {
        manifest: captured.manifest,
        frames_dir: captured.frames_dir,
        rows,
        files: files.written,
    })
}

/// The run's files in the order written (`ExperimentOutcome::files`).
struct Files<'a> {
    sink: &'a dyn RunSink,
    written: Vec<String>,
}

impl Files<'_> {
    fn write(&mut self, rel: String, bytes: &[u8]) -> Result<PathBuf, RunnerError> {
        let path = self.sink.write(&rel, bytes).map_err(RunnerError::Write)?;
        self.written.push(rel);
        Ok(path)
    }
}

/// The frames of a finished capture: their manifest and the folder they are in.
struct Captured {
    manifest: Manifest,
    frames_dir: PathBuf,
}

/// Where a capture stands: frames taken of all, their common size, their folder.
struct CaptureState {
    captured: usize,
    total: usize,
    size: Option<(usize, usize, u8)>,
    frames_dir: PathBuf,
}

/// One run's hold on the bench: the plan, the bench as it was found, who commands it and how long
/// each step may take.
struct Session<'a> {
    plan: &'a ExperimentPlan,
    bench: &'a BenchHandle,
    lease: &'a BenchLease,
    owner: Owner,
    status: BenchStatus,
    timeouts: BenchTimeouts,
    sink: &'a dyn RunSink,
}

impl<'a> Session<'a> {
    /// Reads the bench, sets the exposure the plan asks for and homes the stage.
    fn prepare(
        plan: &'a ExperimentPlan,
        bench: &'a BenchHandle,
        lease: &'a BenchLease,
        timeouts: BenchTimeouts,
        sink: &'a dyn RunSink,
    ) -> Result<Session<'a>, RunnerError> {
        let session = Session {
            plan,
            bench,
            lease,
            owner: Owner::Run(lease.run_id.clone()),
            status: bench.status()?,
            timeouts,
            sink,
        };
        session.check()?;
        if let Some(exposure_us) = plan.exposure_us {
            let settings = CameraSettings {
                exposure_us,
                ..session.status.camera.settings.clone()
            };
            let applied = bench.apply_camera(session.owner.clone(), settings)?;
            sink.event(
                EventKind::CameraSet,
                0.0,
                &format!("exposure {} µs", applied.exposure_us),
                json!({ "settings": applied }),
            );
        }
        if session.status.stage.is_some() {
            sink.event(EventKind::Homing, 0.0, "homing the stage", Value::Null);
            bench.home(session.owner.clone(), timeouts.home)?;
        }
        Ok(session)
    }

    fn check(&self) -> Result<(), RunnerError> {
        if self.sink.cancelled() {
            Err(RunnerError::Cancelled)
        } else {
            Ok(())
        }
    }

    /// Every target of the plan: mount it, the reference and static frames at home, each move;
    /// then the manifest beside the frames (an `ffdic-dataset/1` export).
    fn capture(
        &self,
        files: &mut Files<'_>,
        scale_px_per_mm: f64,
    ) -> Result<Captured, RunnerError> {
        let plan = self.plan;
        let labels: Vec<&str> = plan.patterns.iter().map(|p| p.label.as_str()).collect();
        let captures = capture_plan(&labels, &plan.moves, plan.static_frames, plan.repeats);
        let mut state = CaptureState {
            captured: 0,
            total: captures.iter().map(TargetCapture::frame_count).sum(),
            size: None,
            frames_dir: PathBuf::new(),
        };
        let mut manifest = Manifest::new(&plan.name, scale_px_per_mm);
        for target in &captures {
            self.check()?;
            self.mount(target, &state)?;
            let pattern = &plan.patterns[target.pattern_index];
            let home = StagePosition::default();
            self.shoot(&mut state, files, &target.reference, home)?;
            for name in &target.static_frames {
                self.shoot(&mut state, files, name, home)?;
            }
            for run in &target.runs {
                let m = &plan.moves[run.move_index];
                let at = StagePosition {
                    x_mm: m.dx_mm,
                    y_mm: m.dy_mm,
                };
                self.shoot(&mut state, files, &run.deformed, at)?;
                manifest.runs.push(
                    target.manifest_run(
                        run,
                        m,
                        super::simulate::pattern_info(&pattern.label, pattern, false),
                        plan.exposure_us
                            .or(Some(self.status.camera.settings.exposure_us)),
                    ),
                );
            }
            if self.status.stage.is_some() {
                self.bench
                    .move_to(self.owner.clone(), home, self.timeouts.settle)?;
            }
        }
        self.describe(&mut manifest, state.size.unwrap_or_default());
        let manifest_text = serde_json::to_string_pretty(&manifest).expect("manifest serialises");
        files.write("frames/dataset.json".into(), manifest_text.as_bytes())?;
        self.sink.event(
            EventKind::DatasetWritten,
            CAPTURE_SHARE,
            &format!("{} runs exported as ffdic-dataset/1", manifest.runs.len()),
            json!({ "runs": manifest.runs.len() }),
        );
        Ok(Captured {
            manifest,
            frames_dir: state.frames_dir,
        })
    }

    /// Puts a new layout of the target's pattern in front of the camera, where the bench can.
    fn mount(&self, target: &TargetCapture, state: &CaptureState) -> Result<(), RunnerError> {
        let (plan, pi) = (self.plan, target.pattern_index);
        let pattern = &plan.patterns[pi];
        let new_layout = target.capture == 1 || plan.new_layout_per_repeat;
        if !(self.status.has_target_mount && new_layout) {
            return Ok(());
        }
        let label = &pattern.label;
        let seed = layout_seed(plan.seed.wrapping_add(pi as u64), target.capture);
        self.bench.mount(self.owner.clone(), label, pattern, seed)?;
        self.sink.event(
            EventKind::TargetMounted,
            progress(state.captured, state.total, CAPTURE_SHARE),
            &format!(
                "pattern {label} in front of the camera (capture {} of {})",
                target.capture, plan.repeats
            ),
            json!({ "pattern": label, "capture": target.capture }),
        );
        Ok(())
    }

    /// Moves the stage to `at` (when there is one), waits, captures the averaged frame and writes
    /// it as `frames/{name}`.
    fn shoot(
        &self,
        state: &mut CaptureState,
        files: &mut Files<'_>,
        name: &str,
        at: StagePosition,
    ) -> Result<(), RunnerError> {
        self.check()?;
        if self.status.stage.is_some() {
            let reached = self
                .bench
                .move_to(self.owner.clone(), at, self.timeouts.settle)?;
            self.sink.event(
                EventKind::StageMoved,
                progress(state.captured, state.total, CAPTURE_SHARE),
                &format!(
                    "stage at x {:.4} mm, y {:.4} mm",
                    reached.x_mm, reached.y_mm
                ),
                json!({ "commanded": at, "reached": reached }),
            );
            std::thread::sleep(Duration::from_millis(self.plan.settle_ms));
        }
        self.check()?;
        let frames = self.bench.capture(
            self.owner.clone(),
            self.plan.frames_averaged,
            self.timeouts.frame,
        )?;
        let (w, h, depth, data) = average(&frames)?;
        match state.size {
            None => state.size = Some((w, h, depth)),
            Some((sw, sh, _)) if (sw, sh) != (w, h) => {
                return Err(RunnerError::FrameSize(format!("{sw}x{sh} then {w}x{h}")))
            }
            _ => {}
        }
        let path = files.write(format!("frames/{name}"), &tiff_u16_bytes(w, h, &data)?)?;
        state.frames_dir = path.parent().map(PathBuf::from).unwrap_or_default();
        state.captured += 1;
        self.sink.event(
            EventKind::FrameCaptured,
            progress(state.captured, state.total, CAPTURE_SHARE),
            &format!("{name} ({w}x{h}, {} frame(s) averaged)", frames.len()),
            json!({ "file": name, "frame_ids": frames.iter().map(|f| f.frame_id).collect::<Vec<_>>() }),
        );
        Ok(())
    }

    /// The camera that took the frames and the run that captured them, in the manifest.
    fn describe(&self, manifest: &mut Manifest, (width, height, bit_depth): (usize, usize, u8)) {
        let info = &self.status.camera.info;
        manifest.camera = Some(CameraInfo {
            width,
            height,
            bit_depth,
            extra: [
                ("vendor".to_string(), json!(info.vendor)),
                ("model".to_string(), json!(info.model)),
                ("serial".to_string(), json!(info.serial)),
            ]
            .into_iter()
            .collect(),
        });
        manifest.extra.insert(
            "captured_by".into(),
            json!({ "run": self.lease.run_id, "ffdic": crate::VERSION }),
        );
    }
}

/// The study of the captured frames (every pair with every scheme), and the u, v and strain maps
/// of each pattern's first run with every scheme: the rows (one per capture, run and scheme) and
/// the maps' files.
fn analyse(
    plan: &ExperimentPlan,
    captured: &Captured,
    sink: &dyn RunSink,
) -> Result<(Vec<StudyRow>, Vec<String>), RunnerError> {
    let manifest = &captured.manifest;
    let first_runs: Vec<&str> = plan
        .patterns
        .iter()
        .filter_map(|p| {
            manifest
                .runs
                .iter()
                .find(|r| r.pattern.as_ref().is_some_and(|i| i.label == p.label))
                .map(|r| r.id.as_str())
        })
        .collect();
    let maps: std::sync::Mutex<Result<Vec<String>, String>> = std::sync::Mutex::new(Ok(Vec::new()));
    let draw_maps = |run: &Run, scheme: &crate::reduce::Scheme, result: &crate::dic::DicResult| {
        if !first_runs.contains(&run.id.as_str()) {
            return;
        }
        let pattern = run.pattern.as_ref().map_or("", |p| p.label.as_str());
        let mut written = maps.lock().expect("map list");
        for (file, svg) in field_map_svgs(result, &run.id, pattern, &scheme.name) {
            let rel = format!("plots/{file}");
            match (&mut *written, sink.write(&rel, svg.as_bytes())) {
                (Ok(list), Ok(_)) => list.push(rel),
                (Ok(_), Err(e)) => *written = Err(e),
                (Err(_), _) => {}
            }
        }
    };
    let captures = analyze_dataset_with(
        &captured.frames_dir,
        manifest,
        &plan.schemes,
        &plan.dic,
        &|done, total| {
            sink.event(
                EventKind::PairAnalyzed,
                CAPTURE_SHARE + (1.0 - CAPTURE_SHARE) * done as f64 / total.max(1) as f64,
                &format!("{done} of {total} reduced pairs correlated"),
                json!({ "done": done, "total": total }),
            );
            !sink.cancelled()
        },
        &draw_maps,
    )
    .map_err(|e| match e {
        StudyError::Cancelled => RunnerError::Cancelled,
        other => RunnerError::Study(other),
    })?;
    let map_files = maps
        .into_inner()
        .expect("map list")
        .map_err(RunnerError::Write)?;
    Ok((captures, map_files))
}

/// The study's tables and figures; the rows as the library holds them, for clients that read
/// them back (`ffdic reproduce`), and with repeats every capture's own rows beside them. Returns
/// the rows pooled over the captures.
fn write_results(
    plan: &ExperimentPlan,
    manifest: &Manifest,
    captures: &[StudyRow],
    files: &mut Files<'_>,
) -> Result<Vec<StudyRow>, RunnerError> {
    let (rows, study) = study_files(manifest, captures);
    for (rel, bytes) in study {
        files.write(rel, &bytes)?;
    }
    let rows_text = serde_json::to_string(&rows).expect("rows serialise");
    files.write("results/rows.json".into(), rows_text.as_bytes())?;
    if plan.repeats > 1 {
        let text = serde_json::to_string(captures).expect("rows serialise");
        files.write("results/captures.json".into(), text.as_bytes())?;
    }
    Ok(rows)
}

fn progress(done: usize, total: usize, share: f64) -> f64 {
    share * done as f64 / total.max(1) as f64
}

/// The mean of `frames` as 16-bit samples (rounded): averaging N frames lowers the temporal noise
/// by √N, which is why a lab captures several.
fn average(frames: &[Frame]) -> Result<(usize, usize, u8, Vec<u16>), RunnerError> {
    let first = frames
        .first()
        .ok_or_else(|| RunnerError::FrameSize("no frame delivered".into()))?;
    if frames
        .iter()
        .any(|f| (f.width, f.height) != (first.width, first.height))
    {
        return Err(RunnerError::FrameSize(
            "frames of one capture differ".into(),
        ));
    }
    if frames.len() == 1 {
        return Ok((
            first.width,
            first.height,
            first.bit_depth,
            first.data.clone(),
        ));
    }
    let mut sum = vec![0u64; first.data.len()];
    for f in frames {
        for (s, &v) in sum.iter_mut().zip(&f.data) {
            *s += v as u64;
        }
    }
    let n = frames.len() as u64;
    let data = sum.iter().map(|&s| ((s + n / 2) / n) as u16).collect();
    Ok((first.width, first.height, first.bit_depth, data))
}
