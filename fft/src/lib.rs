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

#[cfg(test)]
mod tests {
    use super::*;

    /// Each planner's transform against the DFT written out, at a power of two, a prime that
    /// rustfft serves with a SIMD butterfly (31) and one it serves with Bluestein's algorithm (67).
    #[test]
    fn transforms_match_the_dft_written_out() {
        for len in [16usize, 31, 67] {
            let x: Vec<Complex<f64>> = (0..len)
                .map(|i| Complex::new((i as f64 * 0.37).sin() + 0.1 * i as f64, (i as f64).cos()))
                .collect();
            let dft: Vec<Complex<f64>> = (0..len)
                .map(|k| {
                    x.iter()
                        .enumerate()
                        .fold(Complex::new(0.0, 0.0), |acc, (n, v)| {
                            let phase = -2.0 * std::f64::consts::PI * (k * n) as f64 / len as f64;
                            acc + v * Complex::new(phase.cos(), phase.sin())
                        })
                })
                .collect();
            let mut y64 = x.clone();
            Planner64::new().plan_fft_forward(len).process(&mut y64);
            let mut y32: Vec<Complex<f32>> = x
                .iter()
                .map(|v| Complex::new(v.re as f32, v.im as f32))
                .collect();
            let mut p32 = Planner32::new();
            p32.plan_fft_forward(len).process(&mut y32);
            let scale: f64 = dft.iter().map(|v| v.norm()).fold(0.0, f64::max);
            for k in 0..len {
                assert!(
                    (y64[k] - dft[k]).norm() < 1e-12 * scale,
                    "f64, len {len}, bin {k}"
                );
                let d32 = Complex::new(y32[k].re as f64, y32[k].im as f64) - dft[k];
                assert!(d32.norm() < 1e-5 * scale, "f32, len {len}, bin {k}");
            }
            // The inverse undoes the forward up to the factor len.
            p32.plan_fft_inverse(len).process(&mut y32);
            for (v, orig) in y32.iter().zip(&x) {
                let back = Complex::new(v.re as f64, v.im as f64) / len as f64;
                assert!(
                    (back - orig).norm() < 1e-5 * scale,
                    "f32 round trip, len {len}"
                );
            }
        }
    }
}
