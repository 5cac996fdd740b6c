//! `AravisCamera`: one GenICam camera behind `ffdic_hw::Camera`.
//!
//! Acquisition runs only inside `acquire`: it starts, collects the frames, and stops, so a frame
//! never predates the call (the bench moves the stage between calls). The stream and its buffer
//! pool live across calls and are rebuilt only when the payload size changes.

use crate::config::AravisConfig;
use crate::error::ctl;
use crate::features::Features;
use crate::frame::frame_from_buffer;
use aravis::glib::object::Cast;
use aravis::prelude::*;
use aravis::{Buffer, GvStream, Stream};
use ffdic_hw::{schemes_for, HardwareScheme};
use ffdic_hw::{
    Camera, CameraCounters, CameraInfo, CameraSettings, Frame, HwError, HwResult, TriggerMode,
};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How long the stream must stay quiet after `AcquisitionStop` before the buffers are taken to
/// hold nothing of that acquisition (`AravisCamera::drain_after_stop`).
const QUIET_AFTER_STOP: Duration = Duration::from_millis(50);

/// The stream and the size of the buffers pushed into it.
struct Pool {
    stream: Stream,
    payload_bytes: usize,
}

impl Pool {
    fn missing_packets(&self) -> u64 {
        self.stream
            .downcast_ref::<GvStream>()
            .map_or(0, |gv| gv.statistics().1)
    }
}

pub struct AravisCamera {
    config: AravisConfig,
    /// `None` only between dropping a lost connection and a successful `reopen`.
    camera: Option<aravis::Camera>,
    features: Features,
    pool: Option<Pool>,
    info: CameraInfo,
    settings: CameraSettings,
    counters: CameraCounters,
    /// Missing packets counted by streams already replaced.
    missing_packets_before: u64,
    /// Set by Aravis' `control-lost` signal (heartbeat thread) or by a failed liveness probe.
    lost: Arc<AtomicBool>,
}

impl AravisCamera {
    /// Opens the camera `id_or_address` (Aravis device id or IP address) with default pool
    /// size and timeouts.
    pub fn open(id_or_address: &str) -> HwResult<Self> {
        Self::open_with(&AravisConfig::new(id_or_address))
    }

    /// Opens the camera `config.device` with the pool size and packet size of `config`.
    pub fn open_with(config: &AravisConfig) -> HwResult<Self> {
        let config = config.clone();
        if config.device.trim().is_empty() {
            // An empty name would make Aravis open the first camera discovery finds.
            return Err(HwError::Protocol(
                "camera device id or address is empty".into(),
            ));
        }
        if config.buffers == 0 {
            return Err(HwError::OutOfRange {
                what: "buffers".into(),
                value: 0.0,
                min: 1.0,
                max: f64::INFINITY,
            });
        }
        let started = Instant::now();
        let camera =
            aravis::Camera::new(Some(&config.device)).map_err(
                |e| match crate::error::map_error(&format!("open {}", config.device), started, &e) {
                    HwError::Protocol(m) | HwError::Unsupported(m) => HwError::Disconnected(m),
                    other => other,
                },
            )?;
        let lost = Arc::new(AtomicBool::new(false));
        if let Some(device) = camera.device() {
            let flag = lost.clone();
            device.connect_control_lost(move |_| flag.store(true, Ordering::SeqCst));
        }
        if let Some(size) = config.packet_size {
            if camera.is_gv_device() {
                ctl("set packet size", || camera.gv_set_packet_size(size as i32))?;
            }
        }
        let features = Features::discover(&camera)?;
        let (sensor_width, sensor_height) = ctl("read sensor size", || camera.sensor_size())?;
        let caps = features.reduction_caps();
        let info = CameraInfo {
            vendor: camera
                .vendor_name()
                .map(|s| s.to_string())
                .unwrap_or_default(),
            model: camera
                .model_name()
                .map(|s| s.to_string())
                .unwrap_or_default(),
            serial: camera
                .device_serial_number()
                .map(|s| s.to_string())
                .unwrap_or_default(),
            sensor_width: sensor_width.max(0) as u32,
            sensor_height: sensor_height.max(0) as u32,
            pixel_formats: features.pixel_formats.clone(),
            hardware_binning: caps.binning_max != (1, 1) && caps.binning_mode.is_some(),
            hardware_decimation: caps.decimation_max != (1, 1),
            hardware_schemes: schemes_for(&caps),
            exposure_range_us: camera.float_bounds(features.exposure).ok(),
        };
        let mut cam = Self {
            config,
            camera: Some(camera),
            features,
            pool: None,
            info,
            settings: CameraSettings::default(),
            counters: CameraCounters::default(),
            missing_packets_before: 0,
            lost,
        };
        cam.settings = cam.read_settings(TriggerMode::FreeRun)?;
        // Free-running until told otherwise: a camera left in trigger mode by another program
        // would otherwise never deliver.
        cam.features.set_trigger(cam.cam()?, TriggerMode::FreeRun)?;
        Ok(cam)
    }

    pub fn config(&self) -> &AravisConfig {
        &self.config
    }

    /// Hardware binning/decimation this camera offers, as fill-factor schemes.
    pub fn hardware_schemes(&self) -> Vec<HardwareScheme> {
        self.info.hardware_schemes.clone()
    }

    /// Whether the camera has been lost (heartbeat failed, or it stopped answering).
    pub fn is_disconnected(&self) -> bool {
        self.lost.load(Ordering::SeqCst)
    }

    /// Opens the same camera again (after a disconnect) and applies the last settings.
    /// Counters carry on.
    pub fn reopen(&mut self) -> HwResult<CameraSettings> {
        self.missing_packets_before += self.pool.take().map_or(0, |p| p.missing_packets());
        // The old connection goes first: Aravis leaves control when it drops a device, and that
        // write should reach a camera that has come back before anyone controls it again.
        self.camera = None;
        self.lost.store(true, Ordering::SeqCst);
        let fresh = Self::open_with(&self.config)?;
        let settings = self.settings.clone();
        let counters = self.counters;
        let missing_before = self.missing_packets_before;
        *self = fresh;
        self.counters = counters;
        self.missing_packets_before = missing_before;
        self.apply(&settings)
    }

    /// The Aravis camera, or Disconnected after a lost connection was dropped.
    fn cam(&self) -> HwResult<&aravis::Camera> {
        self.camera.as_ref().ok_or_else(|| {
            HwError::Disconnected(format!(
                "camera {} is not connected; reopen it",
                self.config.device
            ))
        })
    }

    fn check_connected(&self) -> HwResult<()> {
        if self.is_disconnected() {
            return Err(HwError::Disconnected(format!(
                "camera {} lost its control channel; reopen it",
                self.config.device
            )));
        }
        Ok(())
    }

    fn read_settings(&self, trigger: TriggerMode) -> HwResult<CameraSettings> {
        let (binning, decimation) = self.features.reduction(self.cam()?)?;
        let factor = (binning.0 * decimation.0, binning.1 * decimation.1);
        let roi = self.features.roi(self.cam()?, factor)?;
        // The whole sensor (to within one output pixel) reads back as `None`, as it was asked.
        let full = roi.x == 0
            && roi.y == 0
            && roi.width + factor.0 > self.info.sensor_width
            && roi.height + factor.1 > self.info.sensor_height;
        Ok(CameraSettings {
            exposure_us: self.features.exposure_us(self.cam()?)?,
            gain_db: self.features.gain_db(self.cam()?)?,
            pixel_format: self.features.pixel_format(self.cam()?)?,
            roi: (!full).then_some(roi),
            binning,
            decimation,
            trigger,
        })
    }

    /// The stream, rebuilt with a fresh pool when the payload size changed.
    fn ensure_pool(&mut self) -> HwResult<()> {
        let payload_bytes = {
            let cam = self.cam()?;
            ctl("read payload size", || cam.payload())? as usize
        };
        if self
            .pool
            .as_ref()
            .is_some_and(|p| p.payload_bytes == payload_bytes)
        {
            return Ok(());
        }
        if let Some(old) = self.pool.take() {
            self.missing_packets_before += old.missing_packets();
        }
        let stream = {
            let cam = self.cam()?;
            ctl("create stream", || cam.create_stream())?
        };
        for _ in 0..self.config.buffers {
            stream.push_buffer(Buffer::new_allocate(payload_bytes));
        }
        self.pool = Some(Pool {
            stream,
            payload_bytes,
        });
        Ok(())
    }

    /// Whether the camera still answers its control channel: a register read Aravis retries on
    /// its own. Used when frames stop coming, to tell a slow camera from a vanished one before
    /// the heartbeat notices (≈ 5 s).
    fn probe_alive(&self) -> bool {
        self.camera
            .as_ref()
            .and_then(|c| c.device())
            .is_some_and(|d| d.read_register(0).is_ok())
    }

    /// Collects `count` good frames, each within `timeout`, with acquisition running.
    fn collect(&mut self, count: usize, timeout: Duration) -> HwResult<Vec<Frame>> {
        let software = self.settings.trigger == TriggerMode::Software;
        let mut frames = Vec::with_capacity(count);
        let mut deadline = Instant::now() + timeout;
        while frames.len() < count {
            self.check_connected()?;
            if software {
                // One trigger per buffer wanted, including a retry after a failed one.
                let cam = self.cam()?;
                ctl("software trigger", || cam.software_trigger())?;
            }
            let now = Instant::now();
            let buffer = match deadline.checked_duration_since(now) {
                Some(left) if !left.is_zero() => self
                    .pool
                    .as_ref()
                    .expect("pool exists while acquiring")
                    .stream
                    .timeout_pop_buffer(left.as_micros() as u64),
                _ => None,
            };
            let Some(buffer) = buffer else {
                self.check_connected()?;
                if !self.probe_alive() {
                    self.lost.store(true, Ordering::SeqCst);
                    return Err(HwError::Disconnected(format!(
                        "camera {} sent no frame for {} ms and stopped answering",
                        self.config.device,
                        timeout.as_millis()
                    )));
                }
                return Err(HwError::Timeout {
                    what: format!("frame {} of {count}", frames.len() + 1),
                    after_ms: timeout.as_millis() as u64,
                });
            };
            let result = frame_from_buffer(&buffer);
            // Back to the pool whatever it held: the frame (if any) is already copied out.
            self.pool
                .as_ref()
                .expect("pool exists while acquiring")
                .stream
                .push_buffer(buffer);
            match result {
                Ok(frame) => {
                    self.counters.completed += 1;
                    frames.push(frame);
                    deadline = Instant::now() + timeout;
                }
                Err(_) => self.counters.failed += 1,
            }
        }
        Ok(frames)
    }

    /// Returns to the pool every buffer that arrives until the stream has been quiet for
    /// [`QUIET_AFTER_STOP`]: a frame the camera began before `AcquisitionStop` still arrives after
    /// it, and the next acquisition — perhaps in another read-out mode of the same size (2x2
    /// binning and 2x2 decimation) — would take it as its first frame. The drain before each
    /// start cannot see a frame that lands after it.
    fn drain_after_stop(&self) {
        let Some(pool) = self.pool.as_ref() else {
            return;
        };
        while let Some(late) = pool
            .stream
            .timeout_pop_buffer(QUIET_AFTER_STOP.as_micros() as u64)
        {
            pool.stream.push_buffer(late);
        }
    }

    fn update_missing_packets(&mut self) {
        self.counters.missing_packets =
            self.missing_packets_before + self.pool.as_ref().map_or(0, |p| p.missing_packets());
    }
}

impl Camera for AravisCamera {
    fn info(&self) -> &CameraInfo {
        &self.info
    }

    fn settings(&self) -> CameraSettings {
        self.settings.clone()
    }

    fn apply(&mut self, s: &CameraSettings) -> HwResult<CameraSettings> {
        self.check_connected()?;
        let cam = self.cam()?;
        let f = &self.features;
        f.set_pixel_format(cam, s.pixel_format)?;
        let (binning, decimation) = f.set_reduction(cam, s.binning, s.decimation)?;
        let factor = (binning.0 * decimation.0, binning.1 * decimation.1);
        f.set_roi(cam, s.roi, factor)?;
        f.set_exposure_us(cam, s.exposure_us)?;
        f.set_gain_db(cam, s.gain_db)?;
        f.set_trigger(cam, s.trigger)?;
        self.settings = self.read_settings(s.trigger)?;
        Ok(self.settings.clone())
    }

    fn acquire(&mut self, count: usize, timeout: Duration) -> HwResult<Vec<Frame>> {
        self.check_connected()?;
        if count == 0 {
            return Ok(Vec::new());
        }
        self.ensure_pool()?;
        let pool = self.pool.as_ref().expect("pool just ensured");
        // Frames left from an earlier call predate this one (the stage may have moved since).
        while let Some(stale) = pool.stream.try_pop_buffer() {
            pool.stream.push_buffer(stale);
        }
        let cam = self.cam()?;
        ctl("start acquisition", || cam.start_acquisition())?;
        let result = self.collect(count, timeout);
        let stopped = if self.is_disconnected() {
            // Stopping a vanished camera only waits for control-channel timeouts.
            Ok(())
        } else {
            self.cam()
                .and_then(|cam| ctl("stop acquisition", || cam.stop_acquisition()))
        };
        if stopped.is_ok() {
            self.drain_after_stop();
        }
        self.update_missing_packets();
        let frames = result?;
        stopped?;
        Ok(frames)
    }

    fn software_trigger(&mut self) -> HwResult<()> {
        self.check_connected()?;
        if self.settings.trigger != TriggerMode::Software {
            return Err(HwError::Busy(
                "camera is free-running; set trigger to software first".into(),
            ));
        }
        let cam = self.cam()?;
        ctl("software trigger", || cam.software_trigger())
    }

    fn counters(&self) -> CameraCounters {
        self.counters
    }
}
