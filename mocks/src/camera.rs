use crate::bench::SharedBench;
use ffdic_hw::{
    schemes_for, Camera, CameraCounters, CameraInfo, CameraSettings, Frame, HardwareScheme,
    HwError, HwResult, PixelFormat, ReductionCaps, StagePosition, TriggerMode,
};
use std::time::{Duration, Instant, SystemTime};

/// The mock sensor's exposure range, µs (a PCO Edge 5.5 offers 10 µs to 10 s).
pub const MIN_EXPOSURE_US: f64 = 10.0;
pub const MAX_EXPOSURE_US: f64 = 10_000_000.0;

/// What the sensor sees: the caller's physics (the root crate plugs in the imaging model).
pub trait Scene: Send + Sync {
    /// Sensor size, px.
    fn size(&self) -> (usize, usize);
    /// The frame, in DN of `bit_depth` bits, with the target at `position`, read out in the
    /// hardware scheme `readout` (`None`: every pixel): [`output_size`] samples, row-major.
    /// `frame_index` seeds the noise of this exposure.
    fn render(
        &self,
        position: StagePosition,
        exposure_us: f64,
        bit_depth: u8,
        frame_index: u64,
        readout: Option<&HardwareScheme>,
    ) -> Vec<u16>;
}

/// The frame a `sensor` (width, height) delivers in `readout`: every block of binned or
/// decimated pixels is one output pixel; a partial block at an edge is dropped.
pub fn output_size(sensor: (usize, usize), readout: Option<&HardwareScheme>) -> (usize, usize) {
    match readout {
        Some(s) => (
            sensor.0 / s.x.factor() as usize,
            sensor.1 / s.y.factor() as usize,
        ),
        None => sensor,
    }
}

/// Faults to inject into the mock camera.
#[derive(Clone, Copy, Debug, Default)]
pub struct CameraFaults {
    /// The camera disappears once this many frames have been delivered.
    pub disconnect_after_frames: Option<u64>,
    /// Frames with these indices arrive with missing packets (dropped, counted, retried).
    pub missing_packets_every: Option<u64>,
    /// The stream stalls: every acquisition times out.
    pub stalled: bool,
}

pub struct MockCamera<S: Scene> {
    info: CameraInfo,
    scene: S,
    bench: SharedBench,
    settings: CameraSettings,
    counters: CameraCounters,
    next_frame_id: u64,
    pub faults: CameraFaults,
}

impl<S: Scene> MockCamera<S> {
    pub fn new(scene: S, bench: SharedBench) -> Self {
        let (w, h) = scene.size();
        Self {
            info: CameraInfo {
                vendor: "ffdic".into(),
                model: "mock sCMOS".into(),
                serial: "MOCK-0001".into(),
                sensor_width: w as u32,
                sensor_height: h as u32,
                pixel_formats: vec![PixelFormat::Mono8, PixelFormat::Mono12, PixelFormat::Mono16],
                hardware_binning: false,
                hardware_decimation: false,
                hardware_schemes: Vec::new(),
                exposure_range_us: Some((MIN_EXPOSURE_US, MAX_EXPOSURE_US)),
            },
            scene,
            bench,
            settings: CameraSettings::default(),
            counters: CameraCounters::default(),
            next_frame_id: 0,
            faults: CameraFaults::default(),
        }
    }

    /// The camera with the sensor's own binning and decimation (`caps`), offered as hardware
    /// schemes; the scene renders every frame in the scheme the settings select.
    pub fn with_reduction(mut self, caps: ReductionCaps) -> Self {
        self.info.hardware_schemes = schemes_for(&caps);
        self.info.hardware_binning = caps.binning_max != (1, 1) && caps.binning_mode.is_some();
        self.info.hardware_decimation = caps.decimation_max != (1, 1);
        self
    }

    /// The hardware scheme the current settings select (`None`: full resolution).
    fn readout(&self) -> Option<&HardwareScheme> {
        self.info
            .hardware_schemes
            .iter()
            .find(|h| h.is_selected_by(&self.settings))
    }
}

impl<S: Scene> Camera for MockCamera<S> {
    fn info(&self) -> &CameraInfo {
        &self.info
    }

    fn settings(&self) -> CameraSettings {
        self.settings.clone()
    }

    fn apply(&mut self, s: &CameraSettings) -> HwResult<CameraSettings> {
        if !(s.exposure_us >= MIN_EXPOSURE_US && s.exposure_us <= MAX_EXPOSURE_US) {
            return Err(HwError::OutOfRange {
                what: "exposure_us".into(),
                value: s.exposure_us,
                min: MIN_EXPOSURE_US,
                max: MAX_EXPOSURE_US,
            });
        }
        if !(0.0..=24.0).contains(&s.gain_db) {
            return Err(HwError::OutOfRange {
                what: "gain_db".into(),
                value: s.gain_db,
                min: 0.0,
                max: 24.0,
            });
        }
        if !self.info.pixel_formats.contains(&s.pixel_format) {
            return Err(HwError::Unsupported(format!(
                "pixel format {:?}",
                s.pixel_format
            )));
        }
        if s.roi.is_some() {
            return Err(HwError::Unsupported("ROI on the mock camera".into()));
        }
        let full_resolution = s.binning == (1, 1) && s.decimation == (1, 1);
        if !full_resolution
            && !self
                .info
                .hardware_schemes
                .iter()
                .any(|h| h.is_selected_by(s))
        {
            let offered: Vec<&str> = self
                .info
                .hardware_schemes
                .iter()
                .map(|h| h.name.as_str())
                .collect();
            return Err(HwError::Unsupported(format!(
                "binning {:?} with decimation {:?} on the mock camera (it offers: {})",
                s.binning,
                s.decimation,
                if offered.is_empty() {
                    "none".to_string()
                } else {
                    offered.join(", ")
                }
            )));
        }
        self.settings = s.clone();
        Ok(self.settings.clone())
    }

    fn acquire(&mut self, count: usize, timeout: Duration) -> HwResult<Vec<Frame>> {
        let mut frames = Vec::with_capacity(count);
        while frames.len() < count {
            if self.faults.stalled {
                std::thread::sleep(timeout);
                self.counters.failed += 1;
                return Err(HwError::Timeout {
                    what: "frame".into(),
                    after_ms: timeout.as_millis() as u64,
                });
            }
            if let Some(n) = self.faults.disconnect_after_frames {
                if self.counters.completed >= n {
                    return Err(HwError::Disconnected("mock camera unplugged".into()));
                }
            }
            let id = self.next_frame_id;
            self.next_frame_id += 1;
            // The exposure sees the target where it is at this moment, moving or not.
            let position = self
                .bench
                .lock()
                .expect("bench lock")
                .position_at(Instant::now());
            if self
                .faults
                .missing_packets_every
                .is_some_and(|k| k > 0 && id % k == k - 1)
            {
                self.counters.failed += 1;
                self.counters.missing_packets += 3;
                continue;
            }
            let readout = self.readout();
            let (w, h) = output_size(self.scene.size(), readout);
            let bit_depth = self.settings.pixel_format.bit_depth();
            let data =
                self.scene
                    .render(position, self.settings.exposure_us, bit_depth, id, readout);
            debug_assert_eq!(data.len(), w * h);
            self.counters.completed += 1;
            frames.push(Frame {
                width: w,
                height: h,
                bit_depth,
                data,
                frame_id: id,
                device_timestamp_ns: Some(id * 1_000_000),
                host_timestamp: SystemTime::now(),
            });
        }
        Ok(frames)
    }

    fn software_trigger(&mut self) -> HwResult<()> {
        if self.settings.trigger != TriggerMode::Software {
            return Err(HwError::Busy(
                "camera is free-running; set trigger to software first".into(),
            ));
        }
        Ok(())
    }

    fn counters(&self) -> CameraCounters {
        self.counters
    }
}
