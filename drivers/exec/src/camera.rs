use crate::run::run_frame;
use crate::ExecCameraConfig;
use ffdic_hw::{
    Camera, CameraCounters, CameraInfo, CameraSettings, Frame, HwError, HwResult, PixelFormat,
    StagePosition,
};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime};

/// The target in front of the camera: its label, and how many times a target was mounted (a
/// remount of the same label starts its frame count again).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Mount {
    pub label: String,
    pub generation: u64,
}

/// The mount, shared with the bench's target changer.
pub type SharedMount = Arc<Mutex<Mount>>;

/// What the camera tells the command about the bench: where the stage is, and what is mounted.
pub struct ExecBench {
    pub position: Box<dyn Fn() -> StagePosition + Send>,
    pub mount: SharedMount,
}

/// Distinguishes the working folders of cameras in one process.
static CAMERAS: AtomicU64 = AtomicU64::new(0);

/// The `exec` camera (crate doc).
pub struct ExecCamera {
    config: ExecCameraConfig,
    bench: ExecBench,
    info: CameraInfo,
    settings: CameraSettings,
    counters: CameraCounters,
    frame_id: u64,
    /// The mount generation the frame count below belongs to, and that count.
    seen_generation: u64,
    since_mount: u64,
    /// Where the command writes its frames (removed with the camera).
    dir: PathBuf,
}

impl ExecCamera {
    pub fn open(config: ExecCameraConfig, bench: ExecBench) -> HwResult<Self> {
        config
            .validate()
            .map_err(|m| HwError::Protocol(format!("exec camera: {m}")))?;
        let dir = std::env::temp_dir().join(format!(
            "ffdic-exec-{}-{}",
            std::process::id(),
            CAMERAS.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir).map_err(|e| {
            HwError::Disconnected(format!("exec camera: cannot create {}: {e}", dir.display()))
        })?;
        let format = pixel_format(config.bit_depth);
        let info = CameraInfo {
            vendor: "ffdic".into(),
            model: format!("exec: {}", config.command.join(" ")),
            serial: String::new(),
            sensor_width: config.width,
            sensor_height: config.height,
            pixel_formats: vec![format],
            hardware_binning: false,
            hardware_decimation: false,
            hardware_schemes: Vec::new(),
            exposure_range_us: None,
        };
        let settings = CameraSettings {
            pixel_format: format,
            ..CameraSettings::default()
        };
        Ok(Self {
            config,
            bench,
            info,
            settings,
            counters: CameraCounters::default(),
            frame_id: 0,
            seen_generation: 0,
            since_mount: 0,
            dir,
        })
    }

    /// The environment of the next frame's command.
    fn environment(&mut self, out: &std::path::Path) -> Vec<(&'static str, String)> {
        let at = (self.bench.position)();
        let mount = self.bench.mount.lock().expect("mount lock").clone();
        if mount.generation != self.seen_generation {
            self.seen_generation = mount.generation;
            self.since_mount = 0;
        }
        vec![
            ("FFDIC_X_MM", format!("{:?}", at.x_mm)),
            ("FFDIC_Y_MM", format!("{:?}", at.y_mm)),
            (
                "FFDIC_EXPOSURE_US",
                format!("{:?}", self.settings.exposure_us),
            ),
            ("FFDIC_TARGET", mount.label),
            ("FFDIC_FRAME", self.since_mount.to_string()),
            ("FFDIC_OUT", out.display().to_string()),
            ("FFDIC_WIDTH", self.config.width.to_string()),
            ("FFDIC_HEIGHT", self.config.height.to_string()),
            ("FFDIC_BIT_DEPTH", self.config.bit_depth.to_string()),
        ]
    }
}

fn pixel_format(bit_depth: u8) -> PixelFormat {
    if bit_depth == 8 {
        PixelFormat::Mono8
    } else {
        PixelFormat::Mono16
    }
}

impl Drop for ExecCamera {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

impl Camera for ExecCamera {
    fn info(&self) -> &CameraInfo {
        &self.info
    }

    fn settings(&self) -> CameraSettings {
        self.settings.clone()
    }

    /// Any positive exposure and gain (the command reads the exposure); the frame's size and
    /// format are the configuration's: no ROI, binning or decimation.
    fn apply(&mut self, settings: &CameraSettings) -> HwResult<CameraSettings> {
        if !(settings.exposure_us.is_finite() && settings.exposure_us > 0.0) {
            return Err(HwError::OutOfRange {
                what: "exposure_us".into(),
                value: settings.exposure_us,
                min: f64::MIN_POSITIVE,
                max: f64::MAX,
            });
        }
        if settings.pixel_format != pixel_format(self.config.bit_depth) {
            return Err(HwError::Unsupported(format!(
                "pixel format {:?}: this exec camera delivers {:?}",
                settings.pixel_format,
                pixel_format(self.config.bit_depth)
            )));
        }
        if settings.roi.is_some() || settings.binning != (1, 1) || settings.decimation != (1, 1) {
            return Err(HwError::Unsupported(
                "an ROI, binning or decimation: an exec camera delivers the configured frame"
                    .into(),
            ));
        }
        self.settings = settings.clone();
        Ok(self.settings.clone())
    }

    /// Runs the command once per frame; each within the configured `timeout_ms` and `timeout`,
    /// the shorter.
    fn acquire(&mut self, count: usize, timeout: Duration) -> HwResult<Vec<Frame>> {
        let limit = timeout.min(Duration::from_millis(self.config.timeout_ms));
        let mut frames = Vec::with_capacity(count);
        for _ in 0..count {
            let out = self.dir.join(format!("frame-{}.tif", self.frame_id));
            let env = self.environment(&out);
            match run_frame(&self.config, &env, &out, limit) {
                Ok(data) => {
                    self.counters.completed += 1;
                    self.since_mount += 1;
                    frames.push(Frame {
                        width: self.config.width as usize,
                        height: self.config.height as usize,
                        bit_depth: self.config.bit_depth,
                        data,
                        frame_id: self.frame_id,
                        device_timestamp_ns: None,
                        host_timestamp: SystemTime::now(),
                    });
                    self.frame_id += 1;
                }
                Err(e) => {
                    self.counters.failed += 1;
                    self.frame_id += 1;
                    return Err(e);
                }
            }
        }
        Ok(frames)
    }

    /// Every frame is triggered by its command: a software trigger has nothing to fire.
    fn software_trigger(&mut self) -> HwResult<()> {
        Ok(())
    }

    fn counters(&self) -> CameraCounters {
        self.counters
    }
}
