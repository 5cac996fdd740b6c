//! The forward model of the imaging chain: scene -> geometry -> optics -> sensor.
//!
//! Rendering integrates the scene exactly over each pixel's light-sensitive area; it never
//! interpolates a raster, which would put interpolation bias into the truth the DIC engine is
//! measured against. Effects and their ids follow DESIGN.md ("The model and its effects").

mod config;
mod correction;
mod disk;
pub mod effects;
mod hard_core;
mod lattice;
mod normal;
pub(crate) mod normal_draws;
mod pattern;
mod readout;
mod remembered;
mod render;
mod seed;
mod shot_noise;
mod speckle;

pub use config::{ModelConfig, ModelError};
pub use correction::GeometryCorrection;
pub use disk::DiskDot;
pub use effects::{CandidateId, EffectId, Effects, Stage};
pub use pattern::{
    DotProfile, DotShape, Placement, SpecklePattern, TargetDot, TooManyDots, MAX_TARGET_DOTS,
};
pub use readout::{BinnedValue, BinningDomain, SensorChain, SensorReadout};
pub(crate) use remembered::Remembered;
pub use render::{
    project, project_prepared, project_with_depth, render_frame, render_frame_read_out,
    render_frame_until, Camera, FrameSpec,
};
pub use seed::derive_seed;
pub use speckle::{render_dots, render_dots_until, Dot, Footprint, GaussianDot, SpeckleLayout};
