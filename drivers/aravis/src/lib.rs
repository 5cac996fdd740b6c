//! GenICam cameras for ffdic through Aravis 0.8 (GigE Vision and USB3 Vision).
//!
//! - `AravisCamera` implements `ffdic_hw::Camera`; open it by device id or IP address, never by
//!   discovery. Blocking, and Send but not Sync: one thread (the bench actor) owns it.
//! - SFNC features with fallbacks (`features.rs`), Mono8/10/12/16 decoding with line padding
//!   (`unpack.rs`), hardware binning/decimation as fill-factor schemes (`schemes.rs`).
//! - `FakeGvCamera` serves caller-rendered frames over the real GigE Vision stack, for tests.

mod camera;
mod config;
mod error;
mod fake;
mod features;
mod frame;
pub mod roi;
pub mod schemes;
pub mod unpack;

pub use camera::AravisCamera;
pub use config::AravisConfig;
pub use fake::{FakeCameraError, FakeGvCamera, FillFn, FAKE_ADDRESS};
pub use schemes::{AxisReduction, BinningMode, HardwareScheme};
