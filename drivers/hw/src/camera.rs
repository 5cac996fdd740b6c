use crate::{Frame, HardwareScheme, HwResult};
use serde::{Deserialize, Serialize};
use std::time::Duration;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PixelFormat {
    Mono8,
    Mono10,
    Mono12,
    Mono16,
}

impl PixelFormat {
    pub fn bit_depth(self) -> u8 {
        match self {
            PixelFormat::Mono8 => 8,
            PixelFormat::Mono10 => 10,
            PixelFormat::Mono12 => 12,
            PixelFormat::Mono16 => 16,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TriggerMode {
    FreeRun,
    Software,
}

/// A sensor region in sensor pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SensorRoi {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

/// Settings a camera applies; `apply` returns what the camera really set (rounded, clamped).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSettings {
    pub exposure_us: f64,
    pub gain_db: f64,
    pub pixel_format: PixelFormat,
    pub roi: Option<SensorRoi>,
    /// Hardware binning (horizontal, vertical); (1, 1) is none.
    pub binning: (u32, u32),
    /// Hardware decimation (horizontal, vertical); (1, 1) is none.
    pub decimation: (u32, u32),
    pub trigger: TriggerMode,
}

impl Default for CameraSettings {
    fn default() -> Self {
        Self {
            exposure_us: 10_000.0,
            gain_db: 0.0,
            pixel_format: PixelFormat::Mono16,
            roi: None,
            binning: (1, 1),
            decimation: (1, 1),
            trigger: TriggerMode::FreeRun,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo {
    pub vendor: String,
    pub model: String,
    pub serial: String,
    pub sensor_width: u32,
    pub sensor_height: u32,
    pub pixel_formats: Vec<PixelFormat>,
    /// Binning and decimation the hardware does itself (offered as hardware fill-factor schemes).
    pub hardware_binning: bool,
    pub hardware_decimation: bool,
    /// The hardware fill-factor schemes the camera offers (`schemes_for` its reduction caps):
    /// an experiment names them in its `schemes` (`hw:bin2x2-average`, …).
    #[serde(default)]
    pub hardware_schemes: Vec<HardwareScheme>,
    /// The exposures the camera accepts, µs, when it says (GenICam feature bounds); requests
    /// are checked against it before anything is captured.
    #[serde(default)]
    pub exposure_range_us: Option<(f64, f64)>,
}

/// Stream health since the camera was opened.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CameraCounters {
    pub completed: u64,
    pub failed: u64,
    pub missing_packets: u64,
}

/// A camera. Blocking; one thread owns it.
pub trait Camera: Send {
    fn info(&self) -> &CameraInfo;
    fn settings(&self) -> CameraSettings;
    /// Applies settings and returns what the camera really uses.
    fn apply(&mut self, settings: &CameraSettings) -> HwResult<CameraSettings>;
    /// Acquires `count` frames, each within `timeout`. A frame with missing data is never
    /// returned: it counts as failed, and the call errs when the camera cannot deliver.
    fn acquire(&mut self, count: usize, timeout: Duration) -> HwResult<Vec<Frame>>;
    /// Fires one software trigger (in `TriggerMode::Software`).
    fn software_trigger(&mut self) -> HwResult<()>;
    fn counters(&self) -> CameraCounters;
}
