//! How to reach and stream from one V4L2 camera (the `[camera.v4l2]` table of a lab config).

use crate::controls::GainCalibration;
use crate::format::V4l2Format;
use ffdic_hw::{HwError, HwResult};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Duration;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct V4l2Config {
    /// The video node, e.g. `/dev/video0` or a stable `/dev/v4l/by-id/...` link. The camera is
    /// opened by this path alone, never by picking the first node that exists.
    pub device: PathBuf,
    /// mmap buffers requested with VIDIOC_REQBUFS (the driver may grant fewer or more): enough
    /// to ride out a slow consumer for a few frames without the driver dropping any.
    #[serde(default = "default_buffers")]
    pub buffers: usize,
    /// Longest wait for one good frame, ms, when the caller gives no timeout of its own.
    #[serde(default = "default_timeout_ms")]
    pub timeout_ms: u64,
    /// The format to use when it gives the requested depth, e.g. "Y10P" to move a fifth fewer
    /// bytes than "Y10". Without it the unpacked format wins when the device offers both.
    #[serde(default)]
    pub preferred_fourcc: Option<V4l2Format>,
    /// Frames dropped after every VIDIOC_STREAMON before frames are kept: many sensors apply a
    /// new exposure one or two frames late. Dropped frames count as neither completed nor failed.
    #[serde(default)]
    pub discard_frames: u32,
    /// How the device's gain units relate to dB. Without it only `gain_db = 0` is accepted (the
    /// gain control is then set to its minimum): V4L2 gain has device-specific units.
    #[serde(default)]
    pub gain: Option<GainCalibration>,
}

fn default_buffers() -> usize {
    4
}

fn default_timeout_ms() -> u64 {
    2_000
}

/// Every default, and an empty device path that `validate` rejects: fill in `device`.
impl Default for V4l2Config {
    fn default() -> Self {
        Self::new(PathBuf::new())
    }
}

/// What `V4l2Camera::open` takes: a node path (every other field defaulted) or a whole config.
impl From<&V4l2Config> for V4l2Config {
    fn from(config: &V4l2Config) -> Self {
        config.clone()
    }
}

impl From<&Path> for V4l2Config {
    fn from(path: &Path) -> Self {
        Self::new(path)
    }
}

impl From<PathBuf> for V4l2Config {
    fn from(path: PathBuf) -> Self {
        Self::new(path)
    }
}

impl From<&str> for V4l2Config {
    fn from(path: &str) -> Self {
        Self::new(path)
    }
}

impl V4l2Config {
    /// Defaults for everything but the device.
    pub fn new(device: impl Into<PathBuf>) -> Self {
        Self {
            device: device.into(),
            buffers: default_buffers(),
            timeout_ms: default_timeout_ms(),
            preferred_fourcc: None,
            discard_frames: 0,
            gain: None,
        }
    }

    pub fn timeout(&self) -> Duration {
        Duration::from_millis(self.timeout_ms)
    }

    /// Rejects what would fail later in a less obvious way.
    pub fn validate(&self) -> HwResult<()> {
        if self.device.as_os_str().is_empty() {
            return Err(HwError::Protocol("V4L2 device path is empty".into()));
        }
        if !(1..=32).contains(&self.buffers) {
            // VIDEO_MAX_FRAME (videodev2.h) is 32 buffers.
            return Err(HwError::OutOfRange {
                what: "buffers".into(),
                value: self.buffers as f64,
                min: 1.0,
                max: 32.0,
            });
        }
        if let Some(g) = &self.gain {
            g.validate()?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_fill_everything_but_the_device() {
        let c: V4l2Config = toml::from_str("device = \"/dev/video0\"").unwrap();
        assert_eq!(c, V4l2Config::new("/dev/video0"));
        assert_eq!(c.buffers, 4);
        assert_eq!(c.timeout(), Duration::from_secs(2));
        assert_eq!(c.preferred_fourcc, None);
        assert!(c.validate().is_ok());
    }

    #[test]
    fn every_field_and_no_unknown_ones() {
        let c: V4l2Config = toml::from_str(
            "device = \"/dev/v4l/by-id/usb-cam-video-index0\"\nbuffers = 8\ntimeout_ms = 500\n\
             preferred_fourcc = \"Y10P\"\ndiscard_frames = 2\n\
             gain = { db_per_unit = 0.1, unit_at_0_db = 0 }",
        )
        .unwrap();
        assert_eq!((c.buffers, c.timeout_ms, c.discard_frames), (8, 500, 2));
        assert_eq!(c.preferred_fourcc, Some(V4l2Format::Y10P));
        assert_eq!(c.gain.unwrap().db_per_unit, 0.1);
        let e = toml::from_str::<V4l2Config>("device = \"x\"\nbufers = 4").unwrap_err();
        assert!(e.to_string().contains("bufers"), "{e}");
        assert!(toml::from_str::<V4l2Config>("buffers = 4").is_err());
        assert!(
            toml::from_str::<V4l2Config>("device = \"x\"\npreferred_fourcc = \"YUYV\"").is_err()
        );
    }

    #[test]
    fn validation_names_the_bad_field() {
        let mut c = V4l2Config::new("/dev/video0");
        c.buffers = 0;
        assert!(matches!(c.validate(), Err(HwError::OutOfRange { what, .. }) if what == "buffers"));
        assert!(V4l2Config::new("").validate().is_err());
        assert!(V4l2Config::default().validate().is_err());
        c.buffers = 33;
        assert!(c.validate().is_err());
    }
}
