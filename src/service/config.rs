//! The daemon's configuration (`config/ffdic.toml`, embedded as the default): which camera and
//! stage, where the data lives, where to listen, and the safety settings. Unknown keys are
//! refused with the key named, so a typo never silently falls back to a default.

use crate::experiment::BenchTimeouts;
use crate::model::{Camera as ModelCamera, ModelConfig};
use serde::{Deserialize, Serialize};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

/// The embedded default: mock camera and mock stage, data under `./data`, loopback.
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../config/ffdic.toml");
/// The embedded mock bench's truth (the paper's bench).
pub const PAPER_BENCH_TOML: &str = include_str!("../../config/models/paper-bench.toml");

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaemonConfig {
    /// Run folders, uploaded datasets and the SQLite index.
    pub data_dir: PathBuf,
    pub listen: SocketAddr,
    /// Bearer token for mutating requests; `FFDIC_TOKEN` in the environment overrides it. Required
    /// whenever `listen` is not a loopback address.
    #[serde(default)]
    pub auth_token: Option<String>,
    /// Origins allowed by CORS; empty (the default) sends no CORS headers at all.
    #[serde(default)]
    pub cors_origins: Vec<String>,
    /// Largest JSON request body, bytes.
    #[serde(default = "default_max_json_bytes")]
    pub max_json_bytes: usize,
    /// Largest dataset upload, bytes.
    #[serde(default = "default_max_upload_bytes")]
    pub max_upload_bytes: usize,
    /// Most bytes all stored datasets may take together; an upload that would pass it is
    /// refused (507) before anything is kept.
    #[serde(default = "default_datasets_quota_bytes")]
    pub datasets_quota_bytes: u64,
    /// Most bytes all run folders may take together (experiments' frames, sweeps' results,
    /// every run's files): an experiment whose frames would pass it is refused (507) when
    /// submitted, and a run's write that would pass it fails the run.
    #[serde(default = "default_runs_quota_bytes")]
    pub runs_quota_bytes: u64,
    /// Which ended runs are kept: deleted by age and count at start and after every job.
    #[serde(default)]
    pub retention: crate::store::Retention,
    /// Host names (besides loopback names and IP literals) this daemon answers to; any other
    /// `Host` header is refused, so a DNS-rebinding page cannot reach it.
    #[serde(default)]
    pub allowed_hosts: Vec<String>,
    /// Whether reads (GET) need the token too. Unset: yes when `listen` is not loopback.
    #[serde(default)]
    pub read_requires_token: Option<bool>,
    #[serde(default)]
    pub http: HttpLimits,
    #[serde(default)]
    pub uploads: UploadLimits,
    #[serde(default)]
    pub jobs: JobLimits,
    #[serde(default)]
    pub sweeps: SweepLimits,
    pub bench: BenchConfig,
    pub camera: CameraConfig,
    pub stage: StageConfig,
}

fn default_max_json_bytes() -> usize {
    64 * 1024
}

fn default_max_upload_bytes() -> usize {
    2 * 1024 * 1024 * 1024
}

fn default_datasets_quota_bytes() -> u64 {
    50 * 1024 * 1024 * 1024
}

fn default_runs_quota_bytes() -> u64 {
    100 * 1024 * 1024 * 1024
}

/// Timeouts and limits of the HTTP server, so neither a slow nor a silent client can hold the
/// daemon: a connection must send its request head within `header_read_timeout_ms` (also the
/// keep-alive idle time), each piece of a body within `body_read_timeout_ms`, and a request
/// (other than an SSE stream or an upload) must be answered within `request_timeout_ms`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HttpLimits {
    pub header_read_timeout_ms: u64,
    pub body_read_timeout_ms: u64,
    /// Longer than the slowest bench command (homing, 120 s by default).
    pub request_timeout_ms: u64,
    /// Open connections at most; more are closed as soon as they are accepted.
    pub max_connections: usize,
    /// Open connections at most from one client address, so one client cannot take every slot.
    pub max_connections_per_client: usize,
    /// A response the client does not read: how long a write may wait for the client before the
    /// connection is closed (files are streamed, so a stalled reader holds one chunk, not a file).
    pub write_stall_timeout_ms: u64,
    /// On shutdown, how long open requests get to finish before the daemon exits anyway.
    pub drain_ms: u64,
}

impl Default for HttpLimits {
    fn default() -> Self {
        Self {
            header_read_timeout_ms: 10_000,
            body_read_timeout_ms: 30_000,
            request_timeout_ms: 300_000,
            max_connections: 4_096,
            max_connections_per_client: 256,
            write_stall_timeout_ms: 20_000,
            drain_ms: 3_000,
        }
    }
}

/// What a dataset upload (`POST /datasets`) may take: its pace, and the work its check may cost.
/// The check decodes every frame, so its memory is bounded by `max_frame_pixels` (two frames
/// are held at a time, one upload is checked at a time), not by what the manifest claims.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct UploadLimits {
    /// Most pixels per frame (width × height, read from the TIFF header before decoding).
    pub max_frame_pixels: usize,
    /// Most runs per manifest.
    pub max_runs: usize,
    /// The slowest pace an upload may keep once its first `grace_ms` have passed, bytes/s (the
    /// average since its start).
    pub min_bytes_per_s: u64,
    pub grace_ms: u64,
    /// The whole upload, first byte to the last, at most.
    pub deadline_ms: u64,
}

impl Default for UploadLimits {
    fn default() -> Self {
        Self {
            // A 6144 x 6144 sensor is 37.7 M px.
            max_frame_pixels: 40_000_000,
            max_runs: 1_000,
            min_bytes_per_s: 32 * 1024,
            grace_ms: 10_000,
            deadline_ms: 3_600_000,
        }
    }
}

impl UploadLimits {
    pub fn frames(&self) -> crate::dataset::FrameLimits {
        crate::dataset::FrameLimits {
            max_pixels: self.max_frame_pixels,
            max_runs: self.max_runs,
        }
    }
}

/// How much work the job lanes take: a bound on one analysis, checked when it is submitted (a
/// 422 naming the field to change), and on the jobs waiting per lane (429 with `Retry-After`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct JobLimits {
    /// Most subset pixels one IC-GN iteration of an analysis visits, summed over its runs and
    /// schemes (points × subset²); an analysis usually takes 3–6 iterations a point.
    pub max_analysis_subset_pixels: u64,
    /// Most jobs waiting (queued, not yet running) per lane.
    pub max_queued_per_lane: usize,
}

impl Default for JobLimits {
    fn default() -> Self {
        Self {
            // ≈ 20 min of two cores; the paper's study is ≈ 10⁸.
            max_analysis_subset_pixels: 100_000_000_000,
            max_queued_per_lane: 256,
        }
    }
}

/// How large a sweep (`POST /sweeps`) this daemon takes: it shares its cores with the bench and
/// every other job. At most the compiled ceilings ([`super::job::MAX_DAEMON_SWEEP_TASKS`],
/// [`super::job::MAX_DAEMON_SENSOR_SIDE_PX`]); larger sweeps belong to `ffdic sweep` on a cluster.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SweepLimits {
    pub max_tasks: usize,
    pub max_sensor_side_px: usize,
}

impl Default for SweepLimits {
    fn default() -> Self {
        Self {
            max_tasks: super::job::MAX_DAEMON_SWEEP_TASKS,
            max_sensor_side_px: super::job::MAX_DAEMON_SENSOR_SIDE_PX,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BenchConfig {
    /// Magnification of the bench: image px per mm on the target.
    pub scale_px_per_mm: f64,
    /// Entrance pupil to target along the optical axis, mm, when known: written into every
    /// dataset the bench exports, so a tilted target is reported as angles (without it, as
    /// angles at an assumed distance: one translation identifies the angle over the distance).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub working_distance_mm: Option<f64>,
    #[serde(default = "default_frame_timeout_ms")]
    pub frame_timeout_ms: u64,
    #[serde(default = "default_settle_timeout_ms")]
    pub settle_timeout_ms: u64,
    #[serde(default = "default_home_timeout_ms")]
    pub home_timeout_ms: u64,
}

// The runner's defaults (`BenchTimeouts::default`) are the config's.
fn default_frame_timeout_ms() -> u64 {
    millis(BenchTimeouts::default().frame)
}
fn default_settle_timeout_ms() -> u64 {
    millis(BenchTimeouts::default().settle)
}
fn default_home_timeout_ms() -> u64 {
    millis(BenchTimeouts::default().home)
}
fn millis(d: std::time::Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum CameraConfig {
    /// Renders, through the model, what the sensor sees at the mock stage's position.
    Mock {
        width: usize,
        height: usize,
        #[serde(default = "default_exposure_level")]
        exposure_level: f64,
        /// The bench's truth: `paper-bench` (embedded) or a model file.
        #[serde(default = "default_bench_model")]
        bench_model: String,
        /// The sensor's own 2x2 averaging binning: `digital` (every pixel read, then averaged,
        /// as most sCMOS), `charge` (electrons summed, read once) or `none`.
        #[serde(default)]
        hardware_binning: MockBinning,
        /// The sensor's own decimation up to this factor per axis (1: none).
        #[serde(default = "default_mock_decimation")]
        hardware_decimation_max: u32,
    },
    /// A GenICam camera through Aravis (opened with `--features aravis`): the driver's own
    /// config (`device`, `buffers`, `timeout_ms`, `packet_size`), so a field the driver gains
    /// reaches the daemon by construction.
    Aravis(ffdic_aravis::AravisConfig),
    /// A V4L2 camera (opened with `--features v4l2`): the driver's own config (`device`,
    /// `buffers`, `timeout_ms`, `preferred_fourcc`, `discard_frames`, `gain`).
    V4l2(ffdic_v4l2::V4l2Config),
    /// Frames a command renders or replays, one run per frame with the bench state in its
    /// environment (`ffdic_exec`: a lab's simulator, a recording, the independent generator).
    Exec(ffdic_exec::ExecCameraConfig),
}

fn default_exposure_level() -> f64 {
    0.5
}
fn default_mock_decimation() -> u32 {
    MockReduction::default().decimation_max
}

/// Where the mock sensor bins, if it does.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MockBinning {
    None,
    #[default]
    Digital,
    Charge,
}

/// The mock camera's own binning and decimation (offered as hardware fill-factor schemes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MockReduction {
    pub binning: MockBinning,
    pub decimation_max: u32,
}

impl Default for MockReduction {
    /// 2x2 digital averaging and decimation by 2: the paper's three geometries in hardware.
    fn default() -> Self {
        Self {
            binning: MockBinning::Digital,
            decimation_max: 2,
        }
    }
}

impl MockReduction {
    /// What the mock sensor tells the drivers' scheme naming.
    pub fn caps(self) -> ffdic_hw::ReductionCaps {
        use ffdic_hw::{BinningDomain, BinningMode, ReductionCaps};
        let domain = match self.binning {
            MockBinning::None => None,
            MockBinning::Digital => Some(BinningDomain::Digital),
            MockBinning::Charge => Some(BinningDomain::Charge),
        };
        ReductionCaps {
            binning_max: if domain.is_some() { (2, 2) } else { (1, 1) },
            binning_mode: domain.map(|_| BinningMode::Average),
            binning_domain: domain.unwrap_or(BinningDomain::Unknown),
            decimation_max: (self.decimation_max, self.decimation_max),
        }
    }
}
fn default_bench_model() -> String {
    "paper-bench".into()
}
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum StageConfig {
    /// A simulated stage with travel time and settling.
    Mock {
        #[serde(default = "default_speed")]
        speed_mm_s: f64,
        #[serde(default = "default_settle_ms")]
        settle_ms: u64,
    },
    /// Newport SMC100 / CONEX-CC on a serial port (ASCII protocol).
    Smc100(ffdic_stage::Smc100Config),
    /// Zaber ASCII on a serial port.
    Zaber(ffdic_stage::ZaberConfig),
    /// Thorlabs APT (binary protocol) on a serial port.
    Apt(ffdic_stage::AptConfig),
    /// No stage: snapshots only; experiments need a stage.
    None,
}

fn default_speed() -> f64 {
    25.0
}
fn default_settle_ms() -> u64 {
    20
}

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("bench model {name}: {message}")]
    BenchModel { name: String, message: String },
}

impl DaemonConfig {
    pub fn from_toml(text: &str, origin: &Path) -> Result<Self, ConfigError> {
        let parse = |message: String| ConfigError::Parse {
            path: origin.to_owned(),
            message,
        };
        let config: DaemonConfig =
            toml::from_str(text).map_err(|e| parse(e.message().to_string()))?;
        if !(config.bench.scale_px_per_mm > 0.0) {
            return Err(parse("bench.scale_px_per_mm must be positive".into()));
        }
        if !(config.bench.scale_px_per_mm <= 1e4) {
            return Err(parse("bench.scale_px_per_mm must be at most 10000".into()));
        }
        if let CameraConfig::Mock {
            width,
            height,
            hardware_decimation_max,
            ..
        } = config.camera
        {
            if !(64..=16_384).contains(&width) || !(64..=16_384).contains(&height) {
                return Err(parse(
                    "camera: the mock sensor is 64x64 to 16384x16384 px".into(),
                ));
            }
            if !(1..=4).contains(&hardware_decimation_max) {
                return Err(parse(
                    "camera.hardware_decimation_max: 1 (none) to 4".into(),
                ));
            }
        }
        if let Some(z) = config.bench.working_distance_mm {
            if !(z.is_finite() && z >= 1.0) {
                return Err(parse(format!(
                    "bench.working_distance_mm must be at least 1 mm (got {z})"
                )));
            }
        }
        if let CameraConfig::Exec(exec) = &config.camera {
            exec.validate().map_err(parse)?;
        }
        if config.http.max_connections == 0 {
            return Err(parse("http.max_connections must be at least 1".into()));
        }
        let sweeps = &config.sweeps;
        if !(1..=super::job::MAX_DAEMON_SWEEP_TASKS).contains(&sweeps.max_tasks)
            || !(crate::sweep::MIN_SENSOR_SIDE_PX..=super::job::MAX_DAEMON_SENSOR_SIDE_PX)
                .contains(&sweeps.max_sensor_side_px)
        {
            return Err(parse(format!(
                "sweeps: max_tasks 1 to {}, max_sensor_side_px {} to {}",
                super::job::MAX_DAEMON_SWEEP_TASKS,
                crate::sweep::MIN_SENSOR_SIDE_PX,
                super::job::MAX_DAEMON_SENSOR_SIDE_PX
            )));
        }
        Ok(config)
    }

    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::from_toml(&text, path)
    }

    /// The embedded default.
    pub fn embedded() -> Self {
        Self::from_toml(DEFAULT_CONFIG_TOML, Path::new("config/ffdic.toml"))
            .expect("the embedded config is valid")
    }

    /// The token in force: the environment's `FFDIC_TOKEN`, else the file's.
    pub fn token(&self) -> Option<String> {
        std::env::var("FFDIC_TOKEN")
            .ok()
            .filter(|t| !t.is_empty())
            .or_else(|| self.auth_token.clone().filter(|t| !t.is_empty()))
    }

    /// Whether GET requests need the token (set, or implied by a non-loopback address).
    pub fn reads_need_token(&self) -> bool {
        self.read_requires_token
            .unwrap_or(!self.listen.ip().is_loopback())
            && self.token().is_some()
    }

    /// The mock camera's own binning and decimation; `None` for a real camera.
    pub fn mock_reduction(&self) -> Option<MockReduction> {
        match &self.camera {
            CameraConfig::Mock {
                hardware_binning,
                hardware_decimation_max,
                ..
            } => Some(MockReduction {
                binning: *hardware_binning,
                decimation_max: *hardware_decimation_max,
            }),
            CameraConfig::Aravis(_) | CameraConfig::V4l2(_) | CameraConfig::Exec(_) => None,
        }
    }

    /// The mock camera's geometry as the model sees it.
    pub fn mock_geometry(&self) -> Option<ModelCamera> {
        match &self.camera {
            CameraConfig::Mock {
                width,
                height,
                exposure_level,
                ..
            } => Some(ModelCamera {
                width: *width,
                height: *height,
                scale_px_per_mm: self.bench.scale_px_per_mm,
                exposure_level: *exposure_level,
                principal_dx_px: 0.0,
                principal_dy_px: 0.0,
            }),
            CameraConfig::Aravis(_) | CameraConfig::V4l2(_) | CameraConfig::Exec(_) => None,
        }
    }
}

/// A bench model by embedded name or file path.
pub fn load_bench_model(name: &str) -> Result<ModelConfig, ConfigError> {
    let fail = |message: String| ConfigError::BenchModel {
        name: name.to_string(),
        message,
    };
    if let Some(m) = super::models::embedded_model(name) {
        return Ok(m);
    }
    ModelConfig::load(Path::new(name)).map_err(|e| fail(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_default_is_the_mock_bench_on_loopback() {
        let c = DaemonConfig::embedded();
        assert!(c.listen.ip().is_loopback());
        assert_eq!(c.listen.port(), 8080);
        assert!(matches!(c.camera, CameraConfig::Mock { .. }));
        assert!(matches!(c.stage, StageConfig::Mock { .. }));
        assert_eq!(c.data_dir, PathBuf::from("data"));
    }

    #[test]
    fn unknown_keys_are_named() {
        let text = DEFAULT_CONFIG_TOML.replace("data_dir", "data_dri");
        let err = DaemonConfig::from_toml(&text, Path::new("x.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("data_dri"), "{err}");
    }

    #[test]
    fn lab_examples_parse_into_their_drivers() {
        let aravis = include_str!("../../config/lab-aravis.toml");
        let c = DaemonConfig::from_toml(aravis, Path::new("lab-aravis.toml")).unwrap();
        assert!(matches!(c.camera, CameraConfig::Aravis(_)));
        match &c.stage {
            StageConfig::Smc100(s) => {
                assert_eq!(s.port, "/dev/ttyUSB0");
                assert_eq!(s.baud, 57_600);
            }
            other => panic!("expected smc100, got {other:?}"),
        }
        let v4l2 = include_str!("../../config/lab-v4l2.toml");
        let c = DaemonConfig::from_toml(v4l2, Path::new("lab-v4l2.toml")).unwrap();
        assert!(matches!(c.camera, CameraConfig::V4l2(_)));
        match &c.stage {
            StageConfig::Zaber(z) => assert_eq!(z.microsteps_per_mm, 20_997.375),
            other => panic!("expected zaber, got {other:?}"),
        }
    }

    /// The V4L2 table is the driver's own config: a gain calibration written in `ffdic.toml`
    /// reaches the driver, which maps dB onto a device's control range with it (a synthetic
    /// range: this kernel has no V4L2 device), and a field the driver does not know is an error.
    #[test]
    fn a_v4l2_gain_in_the_config_reaches_the_driver() {
        let text = include_str!("../../config/lab-v4l2.toml").replace(
            "buffers = 4\n",
            "buffers = 4\ngain = { db_per_unit = 0.1, unit_at_0_db = 16 }\ndiscard_frames = 2\n",
        );
        let c = DaemonConfig::from_toml(&text, Path::new("lab-v4l2.toml")).unwrap();
        let CameraConfig::V4l2(v4l2) = &c.camera else {
            panic!("a v4l2 camera: {:?}", c.camera);
        };
        assert_eq!(v4l2.discard_frames, 2);
        let range = ffdic_v4l2::controls::ControlRange {
            min: 0,
            max: 480,
            step: 1,
            default: 16,
        };
        let (units, db) =
            ffdic_v4l2::controls::gain_to_device(6.0, &range, v4l2.gain.as_ref()).unwrap();
        assert_eq!((units, db), (76, 6.0));
        // Without the calibration the driver accepts only 0 dB.
        let plain = DaemonConfig::from_toml(
            include_str!("../../config/lab-v4l2.toml"),
            Path::new("lab-v4l2.toml"),
        )
        .unwrap();
        let CameraConfig::V4l2(plain) = &plain.camera else {
            panic!("a v4l2 camera");
        };
        assert_eq!(plain.buffers, 4);
        assert!(ffdic_v4l2::controls::gain_to_device(6.0, &range, plain.gain.as_ref()).is_err());
        let typo = include_str!("../../config/lab-v4l2.toml")
            .replace("buffers = 4\n", "buffers = 4\ndiscard_frame = 2\n");
        let e = DaemonConfig::from_toml(&typo, Path::new("lab-v4l2.toml")).unwrap_err();
        assert!(e.to_string().contains("discard_frame"), "{e}");
    }

    #[test]
    fn an_exec_camera_is_read_and_its_mistakes_named() {
        let camera = "[camera]\nkind = \"exec\"\ncommand = [\"render\", \"--frame\"]\nwidth = 640\nheight = 540\n";
        let text = DEFAULT_CONFIG_TOML.replace("[camera]\n", "[old_camera]\n");
        let table = |extra: &str| {
            let (head, tail) = text.split_once("[old_camera]").unwrap();
            // The embedded camera table is replaced by the exec one (its keys dropped with it).
            let rest = tail
                .split_once("\n[")
                .map_or(String::new(), |(_, r)| format!("\n[{r}"));
            format!("{head}{camera}{extra}{rest}")
        };
        let c = DaemonConfig::from_toml(&table(""), Path::new("exec.toml")).unwrap();
        match &c.camera {
            CameraConfig::Exec(e) => {
                assert_eq!((e.width, e.bit_depth, e.timeout_ms), (640, 16, 60_000))
            }
            other => panic!("expected exec, got {other:?}"),
        }
        let err = DaemonConfig::from_toml(&table("bit_depth = 12\n"), Path::new("exec.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("bit_depth"), "{err}");
        let err = DaemonConfig::from_toml(&table("shell = true\n"), Path::new("exec.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("shell"), "{err}");
        let near = DEFAULT_CONFIG_TOML.replace("[bench]\n", "[bench]\nworking_distance_mm = 0.5\n");
        let err = DaemonConfig::from_toml(&near, Path::new("x.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("working_distance_mm"), "{err}");
    }

    #[test]
    fn unknown_stage_keys_are_named() {
        let text = include_str!("../../config/lab-v4l2.toml")
            .replace("microsteps_per_mm", "microsteps_mm");
        let err = DaemonConfig::from_toml(&text, Path::new("x.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("microsteps_mm"), "{err}");
    }
}
