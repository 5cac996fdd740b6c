//! V4L2 cameras for ffdic, through the `v4l` crate (mmap streaming I/O).
//!
//! - `V4l2Camera` implements `ffdic_hw::Camera`; open it by node path (`/dev/video0`, better a
//!   `/dev/v4l/by-id/...` link). Blocking, and Send but not Sync: one thread (the bench actor)
//!   owns it.
//! - Luma formats GREY, Y10, Y12, Y16 and the MIPI-packed Y10P, Y12P, decoded with line padding
//!   by pure functions (`unpack`).
//! - Manual exposure in 100 µs units; gain in device units, mapped to dB only through a
//!   calibration from the config (`controls`).
//! - Buffers flagged V4L2_BUF_FLAG_ERROR, short buffers and gaps in the sequence numbers count as
//!   failed frames (`intake`, `sequence`).
//!
//! Caveat: `v4l` 0.14 panics in `Drop` when VIDIOC_STREAMOFF or the buffer release fails with an
//! errno other than ENODEV; a healthy or unplugged device never does that.
//!
//! Without the default feature `camera` the crate is its config and the pure parts (formats,
//! unpacking, control mapping, buffer intake): what the daemon's config embeds, built without
//! the `v4l` crate.

#[cfg(feature = "camera")]
mod camera;
mod config;
pub mod controls;
#[cfg(feature = "camera")]
mod device_controls;
#[cfg(feature = "camera")]
mod error;
pub mod format;
pub mod intake;
pub mod sequence;
pub mod unpack;

#[cfg(feature = "camera")]
pub use camera::V4l2Camera;
pub use config::V4l2Config;
pub use controls::GainCalibration;
pub use format::V4l2Format;
pub use intake::{ActiveFormat, BadBuffer, BufferMeta, Intake, Taken};
pub use sequence::{Observation, SequenceTracker};
pub use unpack::{unpack, UnpackError};
