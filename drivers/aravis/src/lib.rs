//! GenICam cameras for ffdic through Aravis 0.8 (GigE Vision and USB3 Vision).
//!
//! - `AravisCamera` implements `ffdic_hw::Camera`; open it by device id or IP address, never by
//!   discovery. Blocking, and Send but not Sync: one thread (the bench actor) owns it.
//! - SFNC features with fallbacks (`features.rs`), Mono8/10/12/16 decoding with line padding
//!   (`unpack.rs`), hardware binning/decimation described by `ReductionCaps` (`ffdic_hw::schemes_for` names them).
//! - `FakeGvCamera` serves caller-rendered frames over the real GigE Vision stack, for tests.

mod camera;
mod config;
mod error;
mod fake;
mod features;
mod frame;
pub mod roi;
pub mod unpack;

pub use camera::AravisCamera;
pub use config::AravisConfig;
pub use fake::{
    FakeCameraError, FakeGvCamera, FillFn, FillRequest, FAKE_ADDRESS, FAKE_DECIMATION_MAX,
};
pub use ffdic_hw::{AxisReduction, BinningMode, HardwareScheme};
