//! The bench: the actor thread that alone owns the camera and the stage (`actor.rs`), what the
//! bench can physically do as every request is checked against it (`limits.rs`), and the imaging
//! model as the mock camera's scene (`model_scene.rs`).

mod actor;
mod limits;
mod model_scene;

pub use actor::{
    BenchError, BenchHandle, BenchHardware, BenchLease, BenchStatus, CameraStatus, Owner,
    StageStatus, TargetMount,
};
pub use limits::{
    BenchLimits, OutOfTravel, StageAxis, DOT_DIAMETER_PX, EXPOSURE_US, MIN_DOT_SPACING_PX,
};
pub use model_scene::ModelScene;
