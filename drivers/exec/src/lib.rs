//! A camera driven by any renderer or recording (`[camera] kind = "exec"`): for every frame the
//! daemon runs the configured command with the bench state in its environment and reads the grey
//! TIFF the command wrote. A lab plugs in its own simulator or a replay of recorded frames; the
//! tests plug in ffdic's independent generator. It implements the same `Camera` trait as the
//! Aravis and V4L2 drivers and goes through the same bench actor.
//!
//! The command's environment (one frame):
//!
//! | variable | value |
//! |---|---|
//! | `FFDIC_X_MM`, `FFDIC_Y_MM` | the stage's position, mm |
//! | `FFDIC_EXPOSURE_US` | the exposure the camera is set to, µs |
//! | `FFDIC_TARGET` | the mounted target's label (empty before a mount) |
//! | `FFDIC_FRAME` | the frame's index since the target was mounted, from 0 |
//! | `FFDIC_OUT` | the path of the TIFF to write |
//! | `FFDIC_WIDTH`, `FFDIC_HEIGHT`, `FFDIC_BIT_DEPTH` | what the frame must be |
//!
//! A non-zero exit, no file, a file of another size or bit depth, or no exit within
//! `timeout_ms` fails the capture with a [`ffdic_hw::HwError`] that says which (the command's
//! last stderr lines included); the camera stays usable.

mod camera;
mod config;
mod run;

pub use camera::{ExecBench, ExecCamera, Mount, SharedMount};
pub use config::ExecCameraConfig;
