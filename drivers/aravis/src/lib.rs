//! GenICam cameras for ffdic through Aravis 0.8 (GigE Vision and USB3 Vision).
//!
//! - `AravisCamera` implements `ffdic_hw::Camera`; open it by device id or IP address, never by
//!   discovery. Blocking, and Send but not Sync: one thread (the bench actor) owns it.
//! - SFNC features with fallbacks (`features.rs`), Mono8/10/12/16 decoding with line padding
//!   (`unpack.rs`), hardware binning/decimation described by `ReductionCaps` (`ffdic_hw::schemes_for` names them).
//! - `FakeGvCamera` serves caller-rendered frames over the real GigE Vision stack, for tests.
//!
//! Without the default feature `camera` the crate is its config and the pure parts (ROI,
//! unpacking): what the daemon's config embeds, built without libaravis.

#[cfg(feature = "camera")]
mod camera;
mod config;
#[cfg(feature = "camera")]
mod error;
#[cfg(feature = "camera")]
mod fake;
#[cfg(feature = "camera")]
mod features;
#[cfg(feature = "camera")]
mod frame;
pub mod roi;
pub mod unpack;

#[cfg(feature = "camera")]
pub use camera::AravisCamera;
pub use config::AravisConfig;
#[cfg(feature = "camera")]
pub use fake::{
    FakeCameraError, FakeGvCamera, FillFn, FillRequest, FAKE_ADDRESS, FAKE_DECIMATION_MAX,
};
pub use ffdic_hw::{AxisReduction, BinningMode, HardwareScheme};
