//! One experiment on the bench, start to finish: for every pattern, mount it, capture the
//! reference at the home position, move the stage through every commanded translation, wait for
//! it to settle, capture; write the frames as an `ffdic-dataset/1` export; then reduce every pair
//! with every scheme and run DIC (the paper's study), and write the results and figures.
//!
//! The runner knows nothing of HTTP or SQLite: it reports through a [`RunSink`], which the
//! service implements over the run store and the event stream, and `ffdic reproduce` over the same.

use super::bench::{BenchError, BenchHandle, BenchLease, Owner};
use super::captures::{capture_plan, layout_seed, TargetCapture};
use super::figures::study_files;
use super::maps::field_map_svgs;
use super::request::ExperimentPlan;
use super::study::{analyze_dataset_with, StudyError, StudyRow};
use crate::dataset::{CameraInfo, Manifest, Run};
use crate::image::{tiff_u16_bytes, ImageError};
use ffdic_hw::{CameraSettings, Frame, StagePosition};
use serde_json::{json, Value};
use std::path::PathBuf;
use std::time::Duration;

/// Where a run reports to and writes into.
pub trait RunSink: Sync {
    /// A typed event for the run's log and live subscribers; `progress` in 0..=1.
    fn event(&self, kind: &str, progress: f64, message: &str, data: Value);
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

/// Writes one captured frame's bytes under a file name and says where it went.
type FrameWriter<'a> = dyn FnMut(String, &[u8]) -> Result<PathBuf, RunnerError> + 'a;

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

fn capture_and_analyse(
    plan: &ExperimentPlan,
    bench: &BenchHandle,
    lease: &BenchLease,
    scale_px_per_mm: f64,
    timeouts: BenchTimeouts,
    sink: &dyn RunSink,
) -> Result<ExperimentOutcome, RunnerError> {
    let owner = Owner::Run(lease.run_id.clone());
    let check = || {
        if sink.cancelled() {
            Err(RunnerError::Cancelled)
        } else {
            Ok(())
        }
    };
    let mut files = Vec::new();
    let mut write = |rel: String, bytes: &[u8]| -> Result<PathBuf, RunnerError> {
        let p = sink.write(&rel, bytes).map_err(RunnerError::Write)?;
        files.push(rel);
        Ok(p)
    };

    check()?;
    let status = bench.status()?;
    if let Some(exposure_us) = plan.exposure_us {
        let settings = CameraSettings {
            exposure_us,
            ..status.camera.settings.clone()
        };
        let applied = bench.apply_camera(owner.clone(), settings)?;
        sink.event(
            "camera_set",
            0.0,
            &format!("exposure {} µs", applied.exposure_us),
            json!({ "settings": applied }),
        );
    }
    if status.stage.is_some() {
        sink.event("homing", 0.0, "homing the stage", Value::Null);
        bench.home(owner.clone(), timeouts.home)?;
    }

    let labels: Vec<&str> = plan.patterns.iter().map(|p| p.label.as_str()).collect();
    let captures = capture_plan(&labels, &plan.moves, plan.static_frames, plan.repeats);
    let total_frames: usize = captures.iter().map(TargetCapture::frame_count).sum();
    let mut captured = 0usize;
    let mut manifest = Manifest::new(&plan.name, scale_px_per_mm);
    let mut size: Option<(usize, usize, u8)> = None;
    let mut frames_dir = PathBuf::new();

    for target in &captures {
        check()?;
        let pi = target.pattern_index;
        let pattern = &plan.patterns[pi];
        let label = &pattern.label;
        let new_layout = target.capture == 1 || plan.new_layout_per_repeat;
        if status.has_target_mount && new_layout {
            bench.mount(
                owner.clone(),
                label,
                pattern,
                layout_seed(plan.seed.wrapping_add(pi as u64), target.capture),
            )?;
            sink.event(
                "target_mounted",
                progress(captured, total_frames, CAPTURE_SHARE),
                &format!(
                    "pattern {label} in front of the camera (capture {} of {})",
                    target.capture, plan.repeats
                ),
                json!({ "pattern": label, "capture": target.capture }),
            );
        }
        let mut shoot = |name: &str,
                         at: StagePosition,
                         write: &mut FrameWriter<'_>|
         -> Result<(), RunnerError> {
            check()?;
            if status.stage.is_some() {
                let reached = bench.move_to(owner.clone(), at, timeouts.settle)?;
                sink.event(
                    "stage_moved",
                    progress(captured, total_frames, CAPTURE_SHARE),
                    &format!(
                        "stage at x {:.4} mm, y {:.4} mm",
                        reached.x_mm, reached.y_mm
                    ),
                    json!({ "commanded": at, "reached": reached }),
                );
                std::thread::sleep(Duration::from_millis(plan.settle_ms));
            }
            check()?;
            let frames = bench.capture(owner.clone(), plan.frames_averaged, timeouts.frame)?;
            let (w, h, depth, data) = average(&frames)?;
            match size {
                None => size = Some((w, h, depth)),
                Some((sw, sh, _)) if (sw, sh) != (w, h) => {
                    return Err(RunnerError::FrameSize(format!("{sw}x{sh} then {w}x{h}")))
                }
                _ => {}
            }
            let path = write(format!("frames/{name}"), &tiff_u16_bytes(w, h, &data)?)?;
            frames_dir = path.parent().map(PathBuf::from).unwrap_or_default();
            captured += 1;
            sink.event(
                "frame_captured",
                progress(captured, total_frames, CAPTURE_SHARE),
                &format!("{name} ({w}x{h}, {} frame(s) averaged)", frames.len()),
                json!({ "file": name, "frame_ids": frames.iter().map(|f| f.frame_id).collect::<Vec<_>>() }),
            );
            Ok(())
        };
        let home = StagePosition::default();
        shoot(&target.reference, home, &mut write)?;
        for name in &target.static_frames {
            shoot(name, home, &mut write)?;
        }
        for run in &target.runs {
            let m = &plan.moves[run.move_index];
            let at = StagePosition {
                x_mm: m.dx_mm,
                y_mm: m.dy_mm,
            };
            shoot(&run.deformed, at, &mut write)?;
            manifest.runs.push(
                target.manifest_run(
                    run,
                    m,
                    super::simulate::pattern_info(label, pattern, false),
                    plan.exposure_us
                        .or(Some(status.camera.settings.exposure_us)),
                ),
            );
        }
        if status.stage.is_some() {
            bench.move_to(owner.clone(), home, timeouts.settle)?;
        }
    }
    let (width, height, bit_depth) = size.unwrap_or_default();
    manifest.camera = Some(CameraInfo {
        width,
        height,
        bit_depth,
        extra: [
            ("vendor".to_string(), json!(status.camera.info.vendor)),
            ("model".to_string(), json!(status.camera.info.model)),
            ("serial".to_string(), json!(status.camera.info.serial)),
        ]
        .into_iter()
        .collect(),
    });
    manifest.extra.insert(
        "captured_by".into(),
        json!({ "run": lease.run_id, "ffdic": crate::VERSION }),
    );
    let manifest_text = serde_json::to_string_pretty(&manifest).expect("manifest serialises");
    write("frames/dataset.json".into(), manifest_text.as_bytes())?;
    sink.event(
        "dataset_written",
        CAPTURE_SHARE,
        &format!("{} runs exported as ffdic-dataset/1", manifest.runs.len()),
        json!({ "runs": manifest.runs.len() }),
    );

    check()?;
    // u, v and strain maps of each pattern's first run, with every scheme.
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
    let rows = analyze_dataset_with(
        &frames_dir,
        &manifest,
        &plan.schemes,
        &plan.dic,
        &|done, total| {
            sink.event(
                "pair_analyzed",
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

    let captures = rows;
    let (rows, study) = study_files(&manifest, &captures);
    for (rel, bytes) in study {
        write(rel, &bytes)?;
    }
    // The rows as the library holds them, for clients that read them back (`ffdic reproduce`);
    // with repeats, every capture's own rows beside them.
    let rows_text = serde_json::to_string(&rows).expect("rows serialise");
    write("results/rows.json".into(), rows_text.as_bytes())?;
    if plan.repeats > 1 {
        let text = serde_json::to_string(&captures).expect("rows serialise");
        write("results/captures.json".into(), text.as_bytes())?;
    }
    files.extend(map_files);
    Ok(ExperimentOutcome {
        manifest,
        frames_dir,
        rows,
        files,
    })
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
