//! One experiment on the bench, start to finish: for every pattern, mount it, capture the
//! reference at the home position, move the stage through every commanded translation, wait for
//! it to settle, capture; write the frames as an `ffdic-dataset/1` export; then reduce every pair
//! with every scheme and run DIC (the paper's study), and write the results and figures.
//!
//! The runner knows nothing of HTTP or SQLite: it reports through a [`RunSink`], which the
//! service implements over the run store and the event stream, and `ffdic reproduce` over the same.

use super::captures::{capture_plan, layout_seed, TargetCapture};
use super::request::ExperimentPlan;
use crate::bench::{BenchError, BenchHandle, BenchLease, BenchStatus, Owner};
use crate::dataset::{CameraInfo, Manifest, Run};
use crate::image::{tiff_u16_bytes, ImageError};
use crate::report::field_map_svgs;
use crate::report::study_files;
use crate::run_event::EventKind;
use crate::study::{analyze_dataset_with, StudyError, StudyRow};
use ffdic_hw::{CameraSettings, Frame, HardwareScheme, StagePosition};
use serde_json::{json, Value};
use std::path::PathBuf;
use std::time::Duration;

/// How long one capture command of an averaged frame may take, about: a cancel is seen between
/// commands.
const CAPTURE_SLICE: Duration = Duration::from_millis(500);

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
    #[error("hardware scheme {scheme}: {reason}")]
    CaptureMode { scheme: String, reason: String },
}

/// What a finished experiment produced.
#[derive(Clone, Debug)]
pub struct ExperimentOutcome {
    pub manifest: Manifest,
    /// The dataset export: `frames/` of the run folder.
    pub frames_dir: PathBuf,
    pub rows: Vec<StudyRow>,
    /// Every capture's own rows when the plan repeats captures (empty for one capture).
    pub captures: Vec<StudyRow>,
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
    geometry: BenchGeometry,
    timeouts: BenchTimeouts,
    sink: &dyn RunSink,
) -> Result<ExperimentOutcome, RunnerError> {
    still_on_error(
        bench,
        capture_and_analyse(plan, bench, lease, geometry, timeouts, sink),
    )
}

/// `result`, the stage told to stand still first when it is an error: whatever happened (not
/// waited for: a cancel inside a half-second mock exposure would otherwise wait for it).
fn still_on_error<T>(
    bench: &BenchHandle,
    result: Result<T, RunnerError>,
) -> Result<T, RunnerError> {
    if result.is_err() {
        let _ = bench.stop_stage_soon();
    }
    result
}

/// What the bench's configuration states of its optics, written into every dataset it exports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BenchGeometry {
    pub scale_px_per_mm: f64,
    /// Entrance pupil to target, mm, when the lab stated it (`[bench] working_distance_mm`): a
    /// tilted target is then reported as angles.
    pub working_distance_mm: Option<f64>,
}

impl BenchGeometry {
    /// A bench that states its scale alone.
    pub fn scale(scale_px_per_mm: f64) -> Self {
        Self {
            scale_px_per_mm,
            working_distance_mm: None,
        }
    }
}

/// Captures `plan`'s frames on the bench and exports them (`frames/`, `ffdic-dataset/1`), without
/// the study: for a reading of the frames' own (a perpendicularity check), which ends at half
/// the progress an experiment's capture reports. The stage is left standing still on an error.
pub fn capture_experiment(
    plan: &ExperimentPlan,
    bench: &BenchHandle,
    lease: &BenchLease,
    geometry: BenchGeometry,
    timeouts: BenchTimeouts,
    sink: &dyn RunSink,
) -> Result<(Manifest, PathBuf), RunnerError> {
    let mut files = Files::new(sink);
    still_on_error(
        bench,
        capture_on_bench(plan, bench, lease, geometry, timeouts, &mut files),
    )
    .map(|c| (c.manifest, c.frames_dir))
}

/// The bench prepared, the frames captured and exported, the camera's read-out restored.
fn capture_on_bench(
    plan: &ExperimentPlan,
    bench: &BenchHandle,
    lease: &BenchLease,
    geometry: BenchGeometry,
    timeouts: BenchTimeouts,
    files: &mut Files<'_>,
) -> Result<Captured, RunnerError> {
    let session = Session::prepare(plan, bench, lease, timeouts, files.sink)?;
    let captured = session.capture(files, geometry);
    // The camera's own binning and decimation go back to what they were, whatever happened.
    let restored = session.restore_readout();
    let captured = captured?;
    restored?;
    session.check()?;
    Ok(captured)
}

/// The experiment's steps: prepare the bench, capture and export, analyse, write the results.
fn capture_and_analyse(
    plan: &ExperimentPlan,
    bench: &BenchHandle,
    lease: &BenchLease,
    geometry: BenchGeometry,
    timeouts: BenchTimeouts,
    sink: &dyn RunSink,
) -> Result<ExperimentOutcome, RunnerError> {
    let mut files = Files::new(sink);
    let captured = capture_on_bench(plan, bench, lease, geometry, timeouts, &mut files)?;
    let (captures, map_files) = analyse(plan, &captured, sink)?;
    let rows = write_results(plan, &captured.manifest, &captures, &mut files)?;
    files.written.extend(map_files);
    Ok(ExperimentOutcome {
        manifest: captured.manifest,
        frames_dir: captured.frames_dir,
        rows,
        captures: if plan.repeats > 1 {
            captures
        } else {
            Vec::new()
        },
        files: files.written,
    })
}

/// The run's files in the order written (`ExperimentOutcome::files`).
struct Files<'a> {
    sink: &'a dyn RunSink,
    written: Vec<String>,
}

impl<'a> Files<'a> {
    fn new(sink: &'a dyn RunSink) -> Self {
        Self {
            sink,
            written: Vec::new(),
        }
    }

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

/// Where a capture stands: frames taken of all, the common size of each read-out mode's frames
/// (full resolution under `None`), their folder.
struct CaptureState {
    captured: usize,
    total: usize,
    sizes: Vec<(Option<String>, (usize, usize, u8))>,
    frames_dir: PathBuf,
}

impl CaptureState {
    /// Checks that `mode`'s frames keep one size.
    fn check_size(
        &mut self,
        mode: Option<&HardwareScheme>,
        size: (usize, usize, u8),
    ) -> Result<(), RunnerError> {
        let key = mode.map(|h| h.name.clone());
        match self.sizes.iter().find(|(k, _)| *k == key) {
            None => self.sizes.push((key, size)),
            Some((_, (sw, sh, _))) if (*sw, *sh) != (size.0, size.1) => {
                return Err(RunnerError::FrameSize(format!(
                    "{sw}x{sh} then {}x{}",
                    size.0, size.1
                )))
            }
            _ => {}
        }
        Ok(())
    }

    fn full_resolution(&self) -> (usize, usize, u8) {
        self.sizes
            .iter()
            .find(|(k, _)| k.is_none())
            .map(|(_, s)| *s)
            .unwrap_or_default()
    }
}

/// The file of frame `name` read out in the hardware scheme `mode`.
fn frame_file(mode: Option<&HardwareScheme>, name: &str) -> String {
    match mode {
        Some(h) => format!("{}_{name}", h.file_stem()),
        None => name.to_string(),
    }
}

/// One run's hold on the bench: the plan, the bench as it was found, who commands it and how long
/// each step may take.
struct Session<'a> {
    plan: &'a ExperimentPlan,
    bench: &'a BenchHandle,
    lease: &'a BenchLease,
    owner: Owner,
    status: BenchStatus,
    /// The camera's settings for full-resolution frames (the plan's exposure applied); the
    /// hardware schemes change only binning and decimation.
    full_resolution: CameraSettings,
    timeouts: BenchTimeouts,
    sink: &'a dyn RunSink,
}

impl<'a> Session<'a> {
    /// Reads the bench, sets the exposure the plan asks for and full resolution (no binning or
    /// decimation, checked on read-back), and homes the stage.
    fn prepare(
        plan: &'a ExperimentPlan,
        bench: &'a BenchHandle,
        lease: &'a BenchLease,
        timeouts: BenchTimeouts,
        sink: &'a dyn RunSink,
    ) -> Result<Session<'a>, RunnerError> {
        let status = bench.status()?;
        let mut session = Session {
            plan,
            bench,
            lease,
            owner: Owner::Run(lease.run_id.clone()),
            full_resolution: status.camera.settings.clone(),
            status,
            timeouts,
            sink,
        };
        session.check()?;
        let mut settings = session.full_resolution.clone();
        if let Some(exposure_us) = plan.exposure_us {
            settings.exposure_us = exposure_us;
        }
        // Every frame the study synthesises from is a full-resolution frame, whatever binning
        // someone left set (`PATCH /camera`): the sensor's own reduction only as `hw:` schemes.
        (settings.binning, settings.decimation) = ((1, 1), (1, 1));
        if plan.exposure_us.is_some() || settings != session.full_resolution {
            let applied = bench.apply_camera(session.owner.clone(), settings)?;
            sink.event(
                EventKind::CameraSet,
                0.0,
                &format!(
                    "exposure {} µs, binning {:?}, decimation {:?}",
                    applied.exposure_us, applied.binning, applied.decimation
                ),
                json!({ "settings": applied }),
            );
            session.full_resolution = applied;
            session.select(None)?;
        }
        if session.status.stage.is_some() {
            sink.event(EventKind::Homing, 0.0, "homing the stage", Value::Null);
            if let Err(e) = bench.home(session.owner.clone(), timeouts.home) {
                let _ = session.restore_readout();
                return Err(e.into());
            }
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
        geometry: BenchGeometry,
    ) -> Result<Captured, RunnerError> {
        let plan = self.plan;
        let labels: Vec<&str> = plan.patterns.iter().map(|p| p.label.as_str()).collect();
        let captures = capture_plan(&labels, &plan.moves, plan.static_frames, plan.repeats);
        let modes = 1 + plan.hardware_schemes.len();
        let mut state = CaptureState {
            captured: 0,
            total: modes
                * captures
                    .iter()
                    .map(TargetCapture::frame_count)
                    .sum::<usize>(),
            sizes: Vec::new(),
            frames_dir: PathBuf::new(),
        };
        let mut manifest = Manifest::new(&plan.name, geometry.scale_px_per_mm);
        manifest.working_distance_mm = geometry.working_distance_mm;
        for target in &captures {
            self.check()?;
            self.mount(target, &state)?;
            let pattern = &plan.patterns[target.pattern_index];
            let home = StagePosition::default();
            for shot in target.shots(&plan.moves) {
                let at = StagePosition {
                    x_mm: shot.dx_mm,
                    y_mm: shot.dy_mm,
                };
                self.shoot(&mut state, files, shot.file, at)?;
                let Some(run) = shot.run else {
                    continue;
                };
                let full = target.manifest_run(
                    run,
                    &plan.moves[run.move_index],
                    super::simulate::pattern_info(
                        &pattern.label,
                        pattern,
                        plan.print_characterised,
                    ),
                    Some(self.full_resolution.exposure_us),
                );
                let hardware: Vec<Run> = plan
                    .hardware_schemes
                    .iter()
                    .map(|h| hardware_run(&full, h))
                    .collect();
                manifest.runs.push(full);
                manifest.runs.extend(hardware);
            }
            if self.status.stage.is_some() {
                self.bench
                    .move_to(self.owner.clone(), home, self.timeouts.settle)?;
            }
        }
        self.describe(&mut manifest, state.full_resolution());
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
    /// it as `frames/{name}`; then the same in every hardware scheme of the plan (same position,
    /// same settle), back to full resolution at the end.
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
        self.grab(state, files, name, None)?;
        for scheme in &self.plan.hardware_schemes {
            self.select(Some(scheme))?;
            self.grab(state, files, name, Some(scheme))?;
        }
        if !self.plan.hardware_schemes.is_empty() {
            self.select(None)?;
        }
        Ok(())
    }

    /// Sets the camera's read-out to `mode` (a hardware scheme, or full resolution) and checks
    /// what it read back.
    fn select(&self, mode: Option<&HardwareScheme>) -> Result<(), RunnerError> {
        let wanted = match mode {
            Some(h) => h.applied_to(&self.full_resolution),
            None => self.full_resolution.clone(),
        };
        let applied = self
            .bench
            .apply_camera(self.owner.clone(), wanted.clone())?;
        if (applied.binning, applied.decimation) != (wanted.binning, wanted.decimation) {
            return Err(RunnerError::CaptureMode {
                scheme: mode.map_or_else(|| "full resolution".into(), |h| h.name.clone()),
                reason: format!(
                    "asked for binning {:?} and decimation {:?}, the camera read back {:?} and {:?}",
                    wanted.binning, wanted.decimation, applied.binning, applied.decimation
                ),
            });
        }
        Ok(())
    }

    /// Puts the camera's binning and decimation back as the run found them (after a capture
    /// that changed them: hardware schemes, or a camera found binned).
    fn restore_readout(&self) -> Result<(), RunnerError> {
        let found = &self.status.camera.settings;
        let full = (1, 1);
        if self.plan.hardware_schemes.is_empty()
            && (found.binning, found.decimation) == (full, full)
        {
            return Ok(());
        }
        let settings = CameraSettings {
            binning: found.binning,
            decimation: found.decimation,
            ..self.full_resolution.clone()
        };
        self.bench.apply_camera(self.owner.clone(), settings)?;
        Ok(())
    }

    /// `count` frames, in capture commands of about [`CAPTURE_SLICE`] each (the first frame
    /// alone, to time one), the cancel asked before each and while each is waited for: 64
    /// averaged frames were one command that no cancel could stop.
    fn capture_watched(&self, count: usize) -> Result<Vec<Frame>, RunnerError> {
        let mut frames = Vec::with_capacity(count);
        let mut batch = 1;
        while frames.len() < count {
            self.check()?;
            let n = batch.min(count - frames.len());
            let started = std::time::Instant::now();
            let stop = || self.sink.cancelled();
            let batch_frames =
                self.bench
                    .capture_until(self.owner.clone(), n, self.timeouts.frame, &stop)?;
            frames.extend(batch_frames.ok_or(RunnerError::Cancelled)?);
            let per_frame_s = started.elapsed().as_secs_f64() / n as f64;
            batch = ((CAPTURE_SLICE.as_secs_f64() / per_frame_s.max(1e-6)) as usize).max(1);
        }
        Ok(frames)
    }

    /// Captures the averaged frame in the current read-out `mode` and writes it.
    fn grab(
        &self,
        state: &mut CaptureState,
        files: &mut Files<'_>,
        name: &str,
        mode: Option<&HardwareScheme>,
    ) -> Result<(), RunnerError> {
        let frames = self.capture_watched(self.plan.frames_averaged)?;
        let (w, h, depth, data) = average(&frames)?;
        state.check_size(mode, (w, h, depth))?;
        let file = frame_file(mode, name);
        let path = files.write(format!("frames/{file}"), &tiff_u16_bytes(w, h, &data)?)?;
        state.frames_dir = path.parent().map(PathBuf::from).unwrap_or_default();
        state.captured += 1;
        self.sink.event(
            EventKind::FrameCaptured,
            progress(state.captured, state.total, CAPTURE_SHARE),
            &format!("{file} ({w}x{h}, {} frame(s) averaged)", frames.len()),
            json!({ "file": file, "frame_ids": frames.iter().map(|f| f.frame_id).collect::<Vec<_>>() }),
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
/// of each pattern's first run with every synthesised scheme and of its hardware twins in their
/// schemes: the rows (one per capture, run and scheme) and the maps' files.
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
        let mapped = first_runs.contains(&run.id.as_str())
            || run
                .twin_of
                .as_deref()
                .is_some_and(|twin| first_runs.contains(&twin));
        if !mapped {
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
        (&plan.schemes, &plan.dic, None),
        &|done, total| {
            sink.event(
                EventKind::PairAnalyzed,
                CAPTURE_SHARE + (1.0 - CAPTURE_SHARE) * done as f64 / total.max(1) as f64,
                &format!("{done} of {total} reduced pairs correlated"),
                json!({ "done": done, "total": total }),
            );
            !sink.cancelled()
        },
        &|| sink.cancelled(),
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

/// The study's tables and figures; the rows as the library serialises them (`rows.json`, every
/// field of `StudyRow`), and with repeats every capture's own rows beside them. Returns the rows
/// pooled over the captures (an in-process caller takes them from the job's result, not from
/// these files).
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

/// The manifest entry of `full`'s frames read out in the hardware scheme `scheme`.
fn hardware_run(full: &Run, scheme: &HardwareScheme) -> Run {
    let stem = scheme.file_stem();
    let file = |name: &String| frame_file(Some(scheme), name);
    Run {
        id: format!("{}_{stem}", full.id),
        reference: file(&full.reference),
        deformed: file(&full.deformed),
        repeat: full.repeat.iter().map(file).collect(),
        repeat_of: full.repeat_of.as_ref().map(|r| format!("{r}_{stem}")),
        capture: Some(scheme.clone()),
        twin_of: Some(full.id.clone()),
        ..full.clone()
    }
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
