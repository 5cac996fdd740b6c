//! The hardware boundary of ffdic: `Camera` and `Stage` traits, their types and typed errors.
//! Drivers (Aravis, V4L2, serial stages) and mocks depend on this crate only. Calls block: the
//! daemon runs each device on a thread of its own (the bench actor), never on the async runtime.

mod camera;
mod error;
mod frame;
mod schemes;
mod stage;

pub use camera::{
    Camera, CameraCounters, CameraInfo, CameraSettings, PixelFormat, SensorRoi, TriggerMode,
};
pub use error::HwError;
pub use frame::Frame;
pub use schemes::{
    schemes_for, AxisReduction, BinningDomain, BinningMode, HardwareScheme, ReductionCaps,
    HARDWARE_SCHEME_PREFIX,
};
pub use stage::{on_grid, Stage, StageInfo, StagePosition};

pub type HwResult<T> = Result<T, HwError>;
