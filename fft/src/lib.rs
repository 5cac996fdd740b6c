//! FFT plans for ffdic: rustfft's planner behind one type per float width.
//!
//! Why a crate of its own: rustfft's planner is generic over the float, and every algorithm it
//! may pick (scalar, SSE and AVX butterflies of many prime sizes, mixed radix, Bluestein) is
//! compiled in the crate that names the concrete float. Named in ffdic's library they were a
//! quarter of its LLVM IR (826,985 of 3,198,356 lines, `cargo llvm-lines --lib --profile test`),
//! compiled twice in every test build (the library and its unit-test harness) and again in the
//! Python wheel. Named here they are compiled once, and with the dependencies' profile (see the
//! workspace's `Cargo.toml`) the test build and the wheel share that one build. A plan is a trait
//! object either way, so the transforms run the same code as before.

use std::sync::Arc;

pub use rustfft::num_complex::Complex;
pub use rustfft::Fft;

/// Plans of single-precision transforms, cached by length (rustfft's `FftPlanner<f32>`).
pub struct Planner32(rustfft::FftPlanner<f32>);

/// Plans of double-precision transforms, cached by length (rustfft's `FftPlanner<f64>`).
pub struct Planner64(rustfft::FftPlanner<f64>);

impl Default for Planner32 {
    fn default() -> Self {
        Self::new()
    }
}

impl Planner32 {
    pub fn new() -> Self {
        Self(rustfft::FftPlanner::new())
    }

    /// The forward transform of `len` points (unnormalised).
    pub fn plan_fft_forward(&mut self, len: usize) -> Arc<dyn Fft<f32>> {
        self.0.plan_fft_forward(len)
    }

    /// The inverse transform of `len` points (unnormalised: a round trip scales by `len`).
    pub fn plan_fft_inverse(&mut self, len: usize) -> Arc<dyn Fft<f32>> {
        self.0.plan_fft_inverse(len)
    }
}

impl Default for Planner64 {
    fn default() -> Self {
        Self::new()
    }
}

impl Planner64 {
    pub fn new() -> Self {
        Self(rustfft::FftPlanner::new())
    }

    /// The forward transform of `len` points (unnormalised).
    pub fn plan_fft_forward(&mut self, len: usize) -> Arc<dyn Fft<f64>> {
        self.0.plan_fft_forward(len)
    }
}
