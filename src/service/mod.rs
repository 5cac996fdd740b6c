//! The service behind `ffdic serve` and `ffdic reproduce`: the configuration, the run store, the
//! bench actor and the job lanes, wired together. The HTTP layer (`api/`) and the CLI call this;
//! neither runs an experiment any other way.

mod config;
mod hardware;
pub mod job;
mod jobs;
mod models;
mod scaled_sink;

pub use config::{
    load_bench_model, BenchConfig, CameraConfig, ConfigError, DaemonConfig, HttpLimits, JobLimits,
    MockBinning, MockReduction, StageConfig, SweepLimits, UploadLimits, DEFAULT_CONFIG_TOML,
    PAPER_BENCH_TOML,
};
pub use hardware::{mock_bench, open_bench, HardwareError, SwappableScene};
pub use jobs::{JobContext, JobError, JobOutput, JobResult, Jobs, Lane, QueueError, Work};
pub use models::{
    embedded_model, find_analysis_model, ModelDetail, ModelLookupError, ModelSource,
    ModelStoreError, ModelSummary, NewModel, EMBEDDED_MODELS, PAPER_BENCH_DISTORTION_TOML,
};

use crate::bench::{BenchHandle, BenchHardware, BenchLimits, EXPOSURE_US};

use crate::experiment::BenchTimeouts;
use crate::store::{RecoveryReport, Retention, RunStore, StoreError};
use std::sync::Arc;
use std::time::Duration;

#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error(transparent)]
    Hardware(#[from] HardwareError),
}

/// Everything a request handler needs; cheap to clone.
#[derive(Clone)]
pub struct Service {
    pub config: Arc<DaemonConfig>,
    pub store: Arc<RunStore>,
    pub jobs: Arc<Jobs>,
    pub bench: BenchHandle,
    /// What the bench can do (scale, target, travel, exposure), read at start: every request
    /// is checked against it at the door.
    pub limits: Arc<BenchLimits>,
    /// Cancelled when the server shuts down: live streams end with it.
    pub shutdown: tokio_util::sync::CancellationToken,
    /// Upload checks (which decode every frame) run one at a time: their memory is two frames
    /// of at most `uploads.max_frame_pixels`, however many clients upload at once.
    pub frame_checks: Arc<tokio::sync::Semaphore>,
    /// Bytes staged by the uploads in progress, all together: each upload holds the quota
    /// against the stored datasets and every upload's bytes so far, not its own alone (eight
    /// concurrent uploads once stored 2.5x the quota).
    pub uploads_in_flight: Arc<std::sync::atomic::AtomicU64>,
    /// Bytes of one full-resolution 16-bit frame of the camera as written (TIFF): what an
    /// experiment's frames are estimated from when it is submitted.
    pub frame_bytes: u64,
    /// The camera's sensor, px (width, height): what a calibration's default moves and its DIC's
    /// region are sized from.
    pub sensor_px: (u32, u32),
}

/// A 16-bit TIFF's bytes beyond its pixels (header, one strip's tags), at most.
const TIFF_OVERHEAD_BYTES: u64 = 4096;

impl Service {
    /// Opens the store (recovering runs a crash left unfinished), starts the bench actor on
    /// `hardware` and the job lanes.
    pub fn start(
        config: DaemonConfig,
        hardware: BenchHardware,
    ) -> Result<(Self, RecoveryReport), ServiceError> {
        let (store, recovery) = RunStore::open(&config.data_dir)?;
        store.set_runs_quota(config.runs_quota_bytes);
        let store = Arc::new(store);
        apply_retention(&store, &config.retention);
        let limits = Arc::new(BenchLimits {
            scale_px_per_mm: config.bench.scale_px_per_mm,
            target_field_mm: hardware.targets.as_ref().map(|t| t.field_mm()),
            travel_x_mm: hardware.stage.as_ref().map(|s| s.info().travel_x_mm),
            travel_y_mm: hardware.stage.as_ref().map(|s| s.info().travel_y_mm),
            stage_resolution_mm: hardware.stage.as_ref().map(|s| s.info().resolution_mm),
            exposure_us: hardware
                .camera
                .info()
                .exposure_range_us
                .unwrap_or(EXPOSURE_US),
            hardware_schemes: hardware.camera.info().hardware_schemes.clone(),
        });
        let info = hardware.camera.info();
        let sensor_px = (info.sensor_width, info.sensor_height);
        let frame_bytes =
            2 * u64::from(info.sensor_width) * u64::from(info.sensor_height) + TIFF_OVERHEAD_BYTES;
        let bench = BenchHandle::spawn(hardware, Duration::from_secs(30));
        let jobs = Jobs::with_queue_limit(store.clone(), config.jobs.max_queued_per_lane);
        if !config.retention.keeps_everything() {
            let (store, retention) = (store.clone(), config.retention.clone());
            jobs.after_each_job(Box::new(move || apply_retention(&store, &retention)));
        }
        Ok((
            Self {
                config: Arc::new(config),
                store,
                jobs,
                bench,
                limits,
                shutdown: tokio_util::sync::CancellationToken::new(),
                frame_checks: Arc::new(tokio::sync::Semaphore::new(1)),
                uploads_in_flight: Arc::default(),
                frame_bytes,
                sensor_px,
            },
            recovery,
        ))
    }

    pub fn timeouts(&self) -> BenchTimeouts {
        let b = &self.config.bench;
        BenchTimeouts {
            frame: Duration::from_millis(b.frame_timeout_ms),
            settle: Duration::from_millis(b.settle_timeout_ms),
            home: Duration::from_millis(b.home_timeout_ms),
        }
    }

    /// `QuotaFull` when the files under `folder` would take the stored datasets, with the
    /// uploads in progress, past `datasets_quota_bytes`: an experiment's frames are registered
    /// as a dataset only within the quota uploads are held to.
    pub fn check_datasets_room(&self, folder: &std::path::Path) -> Result<(), StoreError> {
        let needed_bytes = crate::store::folder_bytes(folder).map_err(|source| StoreError::Io {
            path: folder.into(),
            source,
        })?;
        let used_bytes = self.store.datasets_bytes()?
            + self
                .uploads_in_flight
                .load(std::sync::atomic::Ordering::SeqCst);
        let quota_bytes = self.config.datasets_quota_bytes;
        if used_bytes.saturating_add(needed_bytes) > quota_bytes {
            return Err(StoreError::QuotaFull {
                what: "the stored datasets",
                setting: "datasets_quota_bytes",
                used_bytes,
                quota_bytes,
                needed_bytes,
            });
        }
        Ok(())
    }

    /// The model a request names (embedded or stored); an unknown or broken one blames the
    /// request's `model` field.
    fn requested_model(&self, name: &str) -> Result<crate::model::ModelConfig, SubmitError> {
        self.model_named_by(name, "model")
    }

    /// The model a request's `field` names (embedded or stored); an unknown or broken one
    /// blames that field.
    fn model_named_by(
        &self,
        name: &str,
        field: &str,
    ) -> Result<crate::model::ModelConfig, SubmitError> {
        self.model_config(name).map_err(|e| match e {
            ModelStoreError::Store(s) => SubmitError::Store(s),
            other => SubmitError::Field(crate::experiment::FieldError {
                field: field.into(),
                reason: other.to_string(),
            }),
        })
    }

    /// The first step of stopping: no new work, every run cancelled, the stage stopped, then
    /// the server told to drain (live streams end with their run's terminal event).
    pub fn begin_stop(&self) {
        self.jobs.cancel_all();
        let _ = self.bench.stop_stage(crate::bench::Owner::Direct);
        self.shutdown.cancel();
    }

    /// Stops taking work, cancels what runs (cooperatively), waits up to `grace` for the runs to
    /// write their ends, stops the stage.
    pub fn stop(&self, grace: Duration) {
        self.begin_stop();
        self.jobs.join_workers(grace);
        let _ = self.bench.stop_stage(crate::bench::Owner::Direct);
    }
}

/// Deletes the ended runs `retention` does not keep (at start and after every job), logging
/// what went.
fn apply_retention(store: &RunStore, retention: &Retention) {
    match store.prune(retention, std::time::SystemTime::now()) {
        Ok(p) if p.runs.is_empty() => {}
        Ok(p) => tracing::info!(
            runs = p.runs.len(),
            bytes = p.bytes,
            "retention deleted ended runs ({retention:?})"
        ),
        Err(e) => tracing::warn!("retention not applied: {e}"),
    }
}

#[derive(Debug, thiserror::Error)]
pub enum SubmitError {
    #[error(transparent)]
    Field(#[from] crate::experiment::FieldError),
    #[error("no stage is configured: experiments need one")]
    NoStage,
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The lane's queue is full: nothing was queued.
    #[error("{queued} jobs are waiting on the {lane:?} lane, its limit (jobs.max_queued_per_lane): try again later")]
    QueueFull { lane: Lane, queued: usize },
}

impl From<jobs::QueueError> for SubmitError {
    fn from(e: jobs::QueueError) -> Self {
        match e {
            jobs::QueueError::Full { lane, queued } => SubmitError::QueueFull { lane, queued },
            jobs::QueueError::Store(s) => SubmitError::Store(s),
        }
    }
}
