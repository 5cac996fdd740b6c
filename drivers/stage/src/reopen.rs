//! A stage whose port comes back: a USB-serial adapter pulled and plugged in again (or a
//! controller power-cycled) closes the port, and the driver that held it answers
//! `Disconnected` for ever. This wrapper drops a driver that answered `Disconnected` and opens
//! the port again at the next call, so the daemon needs no restart. A reopened controller has
//! lost its reference: the bench marks the stage unhomed on `Disconnected`.

use crate::config::StageConfig;
use crate::open::open_driver;
use ffdic_hw::{HwError, HwResult, Stage, StageInfo, StagePosition};
use std::time::Duration;

pub struct ReopeningStage {
    config: StageConfig,
    /// The info of the first open (travel, axes): what the daemon checked requests against.
    info: StageInfo,
    driver: Option<Box<dyn Stage>>,
}

impl ReopeningStage {
    /// Opens the stage `config` describes now (an absent controller is an error here, as it
    /// is at start), and again whenever it was lost.
    pub fn open(config: &StageConfig) -> HwResult<Self> {
        let driver = open_driver(config)?;
        Ok(Self {
            config: config.clone(),
            info: driver.info().clone(),
            driver: Some(driver),
        })
    }

    /// Runs `call` on the driver, opening the port first if it was lost; a `Disconnected`
    /// answer drops the driver.
    fn with<T>(&mut self, call: impl FnOnce(&mut dyn Stage) -> HwResult<T>) -> HwResult<T> {
        let driver = match self.driver.as_mut() {
            Some(d) => d,
            None => self.driver.insert(open_driver(&self.config)?),
        };
        let result = call(driver.as_mut());
        if matches!(result, Err(HwError::Disconnected(_))) {
            self.driver = None;
        }
        result
    }
}

impl Stage for ReopeningStage {
    fn info(&self) -> &StageInfo {
        &self.info
    }

    fn home(&mut self, timeout: Duration) -> HwResult<()> {
        self.with(|s| s.home(timeout))
    }

    fn move_absolute(&mut self, target: StagePosition) -> HwResult<()> {
        self.with(|s| s.move_absolute(target))
    }

    fn move_relative(&mut self, dx_mm: f64, dy_mm: f64) -> HwResult<()> {
        self.with(|s| s.move_relative(dx_mm, dy_mm))
    }

    fn position(&mut self) -> HwResult<StagePosition> {
        self.with(|s| s.position())
    }

    fn wait_settled(&mut self, timeout: Duration) -> HwResult<StagePosition> {
        self.with(|s| s.wait_settled(timeout))
    }

    fn stop(&mut self) -> HwResult<()> {
        self.with(|s| s.stop())
    }
}
