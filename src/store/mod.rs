//! Run folders are the source of truth: every file lands whole or not at all.

mod atomic;

pub use atomic::write_atomically;
