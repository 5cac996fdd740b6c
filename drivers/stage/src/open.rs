//! Opening a port with a protocol's line settings, and the one entry point the daemon calls.

use crate::config::StageConfig;
use crate::{AptStage, Smc100Stage, ZaberStage};
use ffdic_hw::{HwError, HwResult, Stage};
use serialport::{DataBits, FlowControl, Parity, SerialPort, StopBits};
use std::time::Duration;

/// Opens `path` 8N1 at `baud` with the given flow control. A missing or busy device is
/// `Disconnected`: nothing is there to talk to.
pub fn open_port(
    path: &str,
    baud: u32,
    flow_control: FlowControl,
    timeout_ms: u64,
) -> HwResult<Box<dyn SerialPort>> {
    serialport::new(path, baud)
        .data_bits(DataBits::Eight)
        .parity(Parity::None)
        .stop_bits(StopBits::One)
        .flow_control(flow_control)
        .timeout(Duration::from_millis(timeout_ms))
        .open()
        .map_err(|e| HwError::Disconnected(format!("cannot open {path}: {e}")))
}

/// Opens the stage the config describes and checks that its controller answers; a port lost
/// later is opened again at the next call ([`crate::ReopeningStage`]).
pub fn open_stage(config: &StageConfig) -> HwResult<Box<dyn Stage>> {
    Ok(Box::new(crate::ReopeningStage::open(config)?))
}

/// The protocol's driver on a freshly opened port.
pub(crate) fn open_driver(config: &StageConfig) -> HwResult<Box<dyn Stage>> {
    Ok(match config {
        StageConfig::Smc100(c) => Box::new(Smc100Stage::open(c)?),
        StageConfig::Zaber(c) => Box::new(ZaberStage::open(c)?),
        StageConfig::Apt(c) => Box::new(AptStage::open(c)?),
    })
}
