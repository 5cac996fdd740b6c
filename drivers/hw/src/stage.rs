use crate::HwResult;
use serde::{Deserialize, Serialize};
use std::time::Duration;

/// A position of the translation stage, mm.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StagePosition {
    pub x_mm: f64,
    pub y_mm: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageInfo {
    pub model: String,
    /// Axes the stage has: 1 (x only) or 2 (x and y).
    pub axes: u8,
    /// Travel limits per axis, mm.
    pub travel_x_mm: (f64, f64),
    pub travel_y_mm: (f64, f64),
    /// The smallest step a move is commanded in, mm: one device unit (a microstep, an encoder
    /// count, the last decimal the controller is sent). Every move the stage makes is a whole
    /// number of them, so a move is stated to this resolution and no finer; it says nothing of
    /// the stage's accuracy or repeatability.
    #[serde(default)]
    pub resolution_mm: f64,
}

impl StageInfo {
    /// `mm` on the stage's grid of commanded positions (unchanged without a resolution).
    pub fn on_grid(&self, mm: f64) -> f64 {
        on_grid(mm, self.resolution_mm)
    }
}

/// `mm` on a grid of `resolution_mm` steps: the nearest whole number of steps (unchanged
/// without a positive step, or for a value that is not finite). The one rounding of a move to
/// what a stage can be commanded: the stages' own and the bench's check of a request.
pub fn on_grid(mm: f64, resolution_mm: f64) -> f64 {
    if resolution_mm > 0.0 && mm.is_finite() {
        (mm / resolution_mm).round() * resolution_mm
    } else {
        mm
    }
}

/// A motorised translation stage. Blocking; one thread owns it. Moves return once commanded;
/// `wait_settled` blocks until the stage stands still at its target.
pub trait Stage: Send {
    fn info(&self) -> &StageInfo;
    /// Finds the reference position (required after power-up by most controllers).
    fn home(&mut self, timeout: Duration) -> HwResult<()>;
    fn move_absolute(&mut self, target: StagePosition) -> HwResult<()>;
    fn move_relative(&mut self, dx_mm: f64, dy_mm: f64) -> HwResult<()> {
        let p = self.position()?;
        self.move_absolute(StagePosition {
            x_mm: p.x_mm + dx_mm,
            y_mm: p.y_mm + dy_mm,
        })
    }
    fn position(&mut self) -> HwResult<StagePosition>;
    /// Waits until the stage has stopped, then returns where it is.
    fn wait_settled(&mut self, timeout: Duration) -> HwResult<StagePosition>;
    fn stop(&mut self) -> HwResult<()>;
}
