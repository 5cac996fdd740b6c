//! Stage configuration as the daemon reads it from TOML: `[stage] protocol = "smc100", port = ...`.
//! Every field has an explicit default; unknown fields are errors so a typo is not silently ignored.

use serde::{Deserialize, Serialize};

/// Which controller drives the stage, and its settings. Tagged by `protocol`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "protocol", rename_all = "lowercase")]
pub enum StageConfig {
    Smc100(Smc100Config),
    Zaber(ZaberConfig),
    Apt(AptConfig),
}

impl StageConfig {
    pub fn port(&self) -> &str {
        match self {
            StageConfig::Smc100(c) => &c.port,
            StageConfig::Zaber(c) => &c.port,
            StageConfig::Apt(c) => &c.port,
        }
    }
}

/// Newport SMC100 / CONEX-CC. Positions are in the controller's units, set up as mm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Smc100Config {
    pub port: String,
    /// SMC100: 57600; CONEX-CC: 921600.
    pub baud: u32,
    /// Longest wait for one reply.
    pub timeout_ms: u64,
    /// Controller address of the x axis (1–31).
    pub x_address: u8,
    /// Controller address of the y axis on the same RS-485 chain, if there is one.
    pub y_address: Option<u8>,
    /// Travel allowed, mm; narrowed to the controller's software limits (`SL?`, `SR?`) at open.
    pub x_travel_mm: (f64, f64),
    pub y_travel_mm: (f64, f64),
}

impl Default for Smc100Config {
    fn default() -> Self {
        Self {
            port: "/dev/ttyUSB0".into(),
            baud: 57_600,
            timeout_ms: 500,
            x_address: 1,
            y_address: None,
            x_travel_mm: (-12.5, 12.5),
            y_travel_mm: (-12.5, 12.5),
        }
    }
}

/// Zaber ASCII protocol devices. Positions travel as microsteps on the wire.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ZaberConfig {
    pub port: String,
    pub baud: u32,
    pub timeout_ms: u64,
    /// Device address (1–99) and axis number (1–9) of the x axis.
    pub x_address: u8,
    pub x_axis: u8,
    /// Device address of the y axis, if there is one (may equal `x_address` with `y_axis` = 2).
    pub y_address: Option<u8>,
    pub y_axis: u8,
    /// Microsteps per mm: 1 / (microstep size in mm). X-LSM: 0.047625 µm → 20997.375.
    pub microsteps_per_mm: f64,
    pub x_travel_mm: (f64, f64),
    pub y_travel_mm: (f64, f64),
}

impl Default for ZaberConfig {
    fn default() -> Self {
        Self {
            port: "/dev/ttyUSB0".into(),
            baud: 115_200,
            timeout_ms: 500,
            x_address: 1,
            x_axis: 1,
            y_address: None,
            y_axis: 1,
            microsteps_per_mm: 20_997.375,
            x_travel_mm: (0.0, 25.0),
            y_travel_mm: (0.0, 25.0),
        }
    }
}

/// Thorlabs APT / Kinesis motor controllers. Positions travel as encoder counts on the wire.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AptConfig {
    pub port: String,
    pub baud: u32,
    pub timeout_ms: u64,
    /// Destination byte of the x axis: 0x50 (80) for a single-channel USB controller, 0x21.. for
    /// the bays of a benchtop controller.
    pub x_address: u8,
    pub y_address: Option<u8>,
    /// Channel identifier inside the addressed module (1 for single-channel modules).
    pub channel: u16,
    /// Encoder counts per mm. Z8 actuators on a KDC101/TDC001: 34304.
    pub counts_per_mm: f64,
    pub x_travel_mm: (f64, f64),
    pub y_travel_mm: (f64, f64),
}

impl Default for AptConfig {
    fn default() -> Self {
        Self {
            port: "/dev/ttyUSB0".into(),
            baud: 115_200,
            timeout_ms: 500,
            x_address: 0x50,
            y_address: None,
            channel: 1,
            counts_per_mm: 34_304.0,
            x_travel_mm: (0.0, 25.0),
            y_travel_mm: (0.0, 25.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_picks_the_protocol_and_fills_defaults() {
        let c: StageConfig = toml::from_str(
            r#"protocol = "zaber"
               port = "/dev/ttyUSB3"
               y_address = 2
               x_travel_mm = [0.0, 50.0]"#,
        )
        .unwrap();
        let StageConfig::Zaber(z) = c else {
            panic!("expected a zaber config, got {c:?}")
        };
        assert_eq!(z.port, "/dev/ttyUSB3");
        assert_eq!(z.y_address, Some(2));
        assert_eq!(z.x_travel_mm, (0.0, 50.0));
        assert_eq!(z.baud, 115_200);
    }

    #[test]
    fn unknown_fields_and_protocols_are_refused() {
        let typo = toml::from_str::<StageConfig>("protocol = \"apt\"\ncount_per_mm = 2.0");
        assert!(typo.unwrap_err().to_string().contains("count_per_mm"));
        assert!(toml::from_str::<StageConfig>("protocol = \"esp300\"").is_err());
    }
}
