//! The plan caches' transforms against the discrete Fourier transform written out. An integration
//! test, not a unit test: a unit-test harness would compile every rustfft algorithm again (the
//! crate's whole cost), while this file only calls the built library.

use ffdic_fft::{
    plan_f32, plan_f64, plan_real_forward_f32, plan_real_inverse_f32, Complex, Direction,
};

/// Each width's transform against the DFT written out, at a power of two, a prime that
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
        plan_f64(len, Direction::Forward).process(&mut y64);
        let mut y32: Vec<Complex<f32>> = x
            .iter()
            .map(|v| Complex::new(v.re as f32, v.im as f32))
            .collect();
        plan_f32(len, Direction::Forward).process(&mut y32);
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
        plan_f32(len, Direction::Inverse).process(&mut y32);
        for (v, orig) in y32.iter().zip(&x) {
            let back = Complex::new(v.re as f64, v.im as f64) / len as f64;
            assert!(
                (back - orig).norm() < 1e-5 * scale,
                "f32 round trip, len {len}"
            );
        }
    }
}

/// The real transforms against the DFT written out, at even and odd lengths (an even one takes a
/// complex transform of half the length, an odd one does not), and their round trip.
#[test]
fn real_transforms_match_the_dft_written_out() {
    for len in [16usize, 45, 720] {
        let x: Vec<f64> = (0..len)
            .map(|i| (i as f64 * 0.37).sin() + 0.01 * i as f64)
            .collect();
        let half = len / 2 + 1;
        let dft: Vec<Complex<f64>> = (0..half)
            .map(|k| {
                x.iter()
                    .enumerate()
                    .fold(Complex::new(0.0, 0.0), |acc, (n, v)| {
                        let phase =
                            -2.0 * std::f64::consts::PI * ((k * n) % len) as f64 / len as f64;
                        acc + Complex::new(phase.cos(), phase.sin()) * *v
                    })
            })
            .collect();
        let mut input: Vec<f32> = x.iter().map(|v| *v as f32).collect();
        let mut spectrum = vec![Complex::new(0.0f32, 0.0); half];
        plan_real_forward_f32(len)
            .process(&mut input, &mut spectrum)
            .unwrap();
        let scale: f64 = dft.iter().map(|v| v.norm()).fold(0.0, f64::max);
        for k in 0..half {
            let d = Complex::new(spectrum[k].re as f64, spectrum[k].im as f64) - dft[k];
            assert!(d.norm() < 1e-5 * scale, "len {len}, bin {k}");
        }
        let mut back = vec![0.0f32; len];
        plan_real_inverse_f32(len)
            .process(&mut spectrum, &mut back)
            .unwrap();
        for (v, orig) in back.iter().zip(&x) {
            assert!(
                (*v as f64 / len as f64 - orig).abs() < 1e-5 * scale,
                "round trip, len {len}"
            );
        }
    }
}
