//! Serial translation-stage drivers: Newport SMC100 / CONEX-CC (ASCII), Zaber ASCII and Thorlabs
//! APT (binary). Each implements [`ffdic_hw::Stage`] with an x axis and an optional y axis; the
//! daemon picks one from its TOML config through [`StageConfig`] and [`open_stage`].
//!
//! Layout: `config.rs` (serde configs, units in names), `open.rs` (port settings, entry point),
//! `reopen.rs` (a lost port opened again at the next call), `transport.rs` (reads with deadlines, I/O errors mapped to [`ffdic_hw::HwError`]), `travel.rs`
//! (limits and unit conversion) and one folder per protocol: `protocol.rs` holds the pure
//! encoding and parsing (unit tested), `mod.rs` the driver.

mod apt;
mod config;
mod open;
mod reopen;
mod smc100;
mod transport;
mod travel;
mod zaber;

pub use apt::protocol as apt_protocol;
pub use apt::AptStage;
pub use config::{AptConfig, Smc100Config, StageConfig, ZaberConfig};
pub use open::{open_port, open_stage};
pub use reopen::ReopeningStage;
pub use smc100::protocol as smc100_protocol;
pub use smc100::Smc100Stage;
pub use zaber::protocol as zaber_protocol;
pub use zaber::ZaberStage;
