//! FFT plans for ffdic: rustfft's planner, one plan cache per float width and thread.
//!
//! Why a crate of its own: rustfft's planner is generic over the float, and every algorithm it
//! may pick (scalar, SSE and AVX butterflies of many prime sizes, mixed radix, Bluestein) is
//! compiled in the crate that names the concrete float. Named in ffdic's library they were a
//! quarter of its LLVM IR (826,985 of 3,198,356 lines, `cargo llvm-lines --lib --profile test`),
//! compiled twice in every test build (the library and its unit-test harness) and again in the
//! Python wheel. Named here they are compiled once, and with the dependencies' profile (see the
//! workspace's `Cargo.toml`) the test build and the wheel share that one build. A plan is a trait
//! object either way, so the transforms run the same code as before.
//!
//! Why one cache per thread: a diagnosis transforms frames of a few sizes thousands of times,
//! and planning (choosing an algorithm, computing its twiddles) costs more than a small
//! transform. The cache is borrowed only while a plan is looked up, never while it runs, so a
//! transform whose rows run on rayon may plan again from any thread without a conflict.

use std::cell::RefCell;
use std::sync::Arc;

use realfft::RealFftPlanner;
pub use realfft::{ComplexToReal, RealToComplex};
pub use rustfft::num_complex::Complex;
pub use rustfft::Fft;
use rustfft::FftPlanner;

/// Which way a plan transforms. Both are unnormalised: a forward and an inverse transform of
/// `len` points scale the input by `len`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    Forward,
    Inverse,
}

thread_local! {
    static PLANS_F32: RefCell<FftPlanner<f32>> = RefCell::new(FftPlanner::new());
    static PLANS_F64: RefCell<FftPlanner<f64>> = RefCell::new(FftPlanner::new());
    static REAL_PLANS_F32: RefCell<RealFftPlanner<f32>> = RefCell::new(RealFftPlanner::new());
}

/// The single-precision transform of `len` points from this thread's plan cache.
pub fn plan_f32(len: usize, direction: Direction) -> Arc<dyn Fft<f32>> {
    PLANS_F32.with_borrow_mut(|planner| match direction {
        Direction::Forward => planner.plan_fft_forward(len),
        Direction::Inverse => planner.plan_fft_inverse(len),
    })
}

/// The double-precision transform of `len` points from this thread's plan cache.
pub fn plan_f64(len: usize, direction: Direction) -> Arc<dyn Fft<f64>> {
    PLANS_F64.with_borrow_mut(|planner| match direction {
        Direction::Forward => planner.plan_fft_forward(len),
        Direction::Inverse => planner.plan_fft_inverse(len),
    })
}

/// The single-precision transform of `len` real samples to their `len / 2 + 1` non-negative
/// frequencies (realfft: a complex transform of half the length), from this thread's cache. Half
/// the work of [`plan_f32`] on a real signal, whose other half of the spectrum is the conjugate.
pub fn plan_real_forward_f32(len: usize) -> Arc<dyn RealToComplex<f32>> {
    REAL_PLANS_F32.with_borrow_mut(|planner| planner.plan_fft_forward(len))
}

/// The inverse of [`plan_real_forward_f32`], unnormalised: `len / 2 + 1` frequencies to `len` real
/// samples, `len` times the signal. The zero frequency's imaginary part (and, for even `len`, the
/// Nyquist frequency's) must be zero.
pub fn plan_real_inverse_f32(len: usize) -> Arc<dyn ComplexToReal<f32>> {
    REAL_PLANS_F32.with_borrow_mut(|planner| planner.plan_fft_inverse(len))
}
