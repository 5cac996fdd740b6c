//! How to reach and stream from one GenICam camera (the `[camera.aravis]` table of a lab config).

use serde::{Deserialize, Serialize};
use std::time::Duration;

#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AravisConfig {
    /// Aravis device id (`Vendor-Model-Serial`, as `arv-tool-0.8` lists it) or IP address. The
    /// camera is opened by this alone, never by picking the first one discovery finds.
    pub device: String,
    /// Buffers in the stream's pool: enough to ride out a slow consumer for a few frames.
    #[serde(default = "default_buffers")]
    pub buffers: usize,
    /// Longest wait for one frame, ms, when the caller gives no timeout of its own.
    #[serde(default = "default_timeout_ms")]
    pub timeout_ms: u64,
    /// GigE Vision packet size, bytes; `None` keeps Aravis' own negotiation.
    #[serde(default)]
    pub packet_size: Option<u32>,
}

fn default_buffers() -> usize {
    8
}

fn default_timeout_ms() -> u64 {
    2_000
}

/// No device: fill `device` in (opening an empty device name is refused, not discovered).
impl Default for AravisConfig {
    fn default() -> Self {
        Self::new("")
    }
}

impl AravisConfig {
    /// Defaults for everything but the device.
    pub fn new(device: impl Into<String>) -> Self {
        Self {
            device: device.into(),
            buffers: default_buffers(),
            timeout_ms: default_timeout_ms(),
            packet_size: None,
        }
    }

    pub fn timeout(&self) -> Duration {
        Duration::from_millis(self.timeout_ms)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_fill_everything_but_the_device() {
        let c: AravisConfig = toml::from_str("device = \"192.168.1.20\"").unwrap();
        assert_eq!(c, AravisConfig::new("192.168.1.20"));
        assert_eq!(c.buffers, 8);
        assert_eq!(c.timeout(), Duration::from_secs(2));
    }

    #[test]
    fn every_field_and_no_unknown_ones() {
        let c: AravisConfig = toml::from_str(
            "device = \"Basler-acA2040-21654321\"\nbuffers = 4\ntimeout_ms = 500\npacket_size = 8192",
        )
        .unwrap();
        assert_eq!(
            (c.buffers, c.timeout_ms, c.packet_size),
            (4, 500, Some(8192))
        );
        let e = toml::from_str::<AravisConfig>("device = \"x\"\nbufers = 4").unwrap_err();
        assert!(e.to_string().contains("bufers"), "{e}");
        assert!(toml::from_str::<AravisConfig>("buffers = 4").is_err());
    }
}
