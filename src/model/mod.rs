//! The forward model of the imaging chain: scene -> geometry -> optics -> sensor.
//!
//! Rendering integrates the scene exactly over each pixel's light-sensitive area; it never
//! interpolates a raster, which would put interpolation bias into the truth the DIC engine is
//! measured against.

mod speckle;

pub use speckle::{render_dots, GaussianDot, SpeckleLayout};
