//! ffdic: translation experiments, fill-factor synthesis, 2D DIC and a physical model of the
//! imaging chain. See the README (for users) and ARCHITECTURE.md (how the code is built).

// `!(x > limit)` is how this crate says "fails unless certainly above the limit": a NaN must
// fail such checks, which `x <= limit` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod api;
pub mod atomic_write;
pub mod bench;
pub mod dashboard;
pub mod dataset;
pub mod diagnose;
pub mod dic;
pub mod experiment;
pub mod image;
pub mod model;
pub mod pairs;
pub mod reduce;
pub mod report;
pub mod run_event;
pub mod service;
pub mod stats;
pub mod store;
pub mod study;
pub mod sweep;
pub mod text_enum;

/// The crate version, recorded in every result's settings.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
