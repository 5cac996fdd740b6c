//! The sums over a reference subset that IC-GN precomputes once per point (Pan, Li & Tong,
//! Exp. Mech. 53 (2013)): the subset's mean and norm, the moments of the gradient products
//! that make up the Gauss-Newton Hessian, and Σ J·f and Σ J that the fused iteration pass
//! (`icgn_sums`) needs.
//!
//! The sums run in eight f32 lanes per subset row (flushed to f64 at each row's end) so that
//! the compiler vectorises them; the same code is compiled a second time for AVX2 + FMA and
//! chosen once per process from the CPU.

/// Lanes of the per-row accumulators.
const LANES: usize = 8;

/// Sums over one subset, f64.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct ReferenceSums {
    /// The subset's mean grey value.
    pub mean: f32,
    /// Σ (f − mean)².
    pub ss: f64,
    /// Moments {1, dx, dy, dx², dx·dy, dy²} of gx², gx·gy and gy².
    pub moments: [[f64; 6]; 3],
    /// Σ J·(f − mean), J = [gx, gx·dx, gx·dy, gy, gy·dx, gy·dy].
    pub jf: [f64; 6],
    /// Σ J.
    pub jsum: [f64; 6],
}

/// Makes `f0` zero-mean in place and returns its sums with the gradients `gx`, `gy` (all
/// `side` x `side`, row-major; `dxs[c]` = c − half).
pub(super) fn reference_sums(f0: &mut [f32], gx: &[f32], gy: &[f32], dxs: &[f32]) -> ReferenceSums {
    #[cfg(target_arch = "x86_64")]
    if super::icgn_sums::simd_available() {
        // SAFETY: the CPU has AVX2 and FMA (checked above).
        return unsafe { reference_sums_avx2(f0, gx, gy, dxs) };
    }
    reference_sums_lanes(f0, gx, gy, dxs)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn reference_sums_avx2(
    f0: &mut [f32],
    gx: &[f32],
    gy: &[f32],
    dxs: &[f32],
) -> ReferenceSums {
    use std::arch::x86_64::*;
    let side = dxs.len();
    if side < LANES {
        return reference_sums_lanes(f0, gx, gy, dxs);
    }
    // The mean and Σ (f − mean)² as in the portable code (they are cheap); then the 17 row
    // sums of the moments in 17 registers, the last chunk of a row overlapping the one before
    // with its repeated lanes zeroed.
    let mut out = mean_and_ss(f0, side);
    let half = (side / 2) as f64;
    let lane_ids = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    for r in 0..side {
        let dy = r as f64 - half;
        let at_row = r * side;
        let mut acc = [_mm256_setzero_ps(); 17];
        let mut done = 0usize;
        while done < side {
            let c0 = done.min(side - LANES);
            let live = _mm256_castsi256_ps(_mm256_cmpgt_epi32(
                lane_ids,
                _mm256_set1_epi32(done as i32 - c0 as i32 - 1),
            ));
            let at = at_row + c0;
            let a = _mm256_and_ps(_mm256_loadu_ps(gx.as_ptr().add(at)), live);
            let b = _mm256_loadu_ps(gy.as_ptr().add(at));
            let f = _mm256_loadu_ps(f0.as_ptr().add(at));
            let dx = _mm256_loadu_ps(dxs.as_ptr().add(c0));
            let b = _mm256_and_ps(b, live);
            let (aa, ab, bb) = (
                _mm256_mul_ps(a, a),
                _mm256_mul_ps(a, b),
                _mm256_mul_ps(b, b),
            );
            let (af, bf) = (_mm256_mul_ps(a, f), _mm256_mul_ps(b, f));
            for (k, p) in [aa, ab, bb].into_iter().enumerate() {
                let pdx = _mm256_mul_ps(p, dx);
                acc[3 * k] = _mm256_add_ps(acc[3 * k], p);
                acc[3 * k + 1] = _mm256_add_ps(acc[3 * k + 1], pdx);
                acc[3 * k + 2] = _mm256_fmadd_ps(pdx, dx, acc[3 * k + 2]);
            }
            acc[9] = _mm256_add_ps(acc[9], af);
            acc[10] = _mm256_fmadd_ps(af, dx, acc[10]);
            acc[11] = _mm256_add_ps(acc[11], bf);
            acc[12] = _mm256_fmadd_ps(bf, dx, acc[12]);
            acc[13] = _mm256_add_ps(acc[13], a);
            acc[14] = _mm256_fmadd_ps(a, dx, acc[14]);
            acc[15] = _mm256_add_ps(acc[15], b);
            acc[16] = _mm256_fmadd_ps(b, dx, acc[16]);
            done = c0 + LANES;
        }
        let mut row = [0.0f64; 17];
        for (s, v) in row.iter_mut().zip(acc) {
            let mut lanes = [0.0f32; LANES];
            _mm256_storeu_ps(lanes.as_mut_ptr(), v);
            *s = lanes.iter().map(|&x| x as f64).sum();
        }
        add_row(&mut out, &row, dy);
    }
    out
}

/// Makes `f0` zero-mean; its mean and Σ (f − mean)².
#[inline(always)]
fn mean_and_ss(f0: &mut [f32], side: usize) -> ReferenceSums {
    let n = (side * side) as f64;
    let chunks = side / LANES;
    // The mean, then Σ (f − mean)² on the zero-mean values.
    let mut sum = 0.0f64;
    for row in f0.chunks_exact(side) {
        let mut acc = [[0.0f32; LANES]; 1];
        for chunk in row.chunks_exact(LANES) {
            for l in 0..LANES {
                acc[0][l] += chunk[l];
            }
        }
        sum += lane_total(&acc)[0] + row[chunks * LANES..].iter().map(|&v| v as f64).sum::<f64>();
    }
    let mean = (sum / n) as f32;
    let mut ss = 0.0f64;
    for row in f0.chunks_exact_mut(side) {
        let mut acc = [[0.0f32; LANES]; 1];
        for chunk in row.chunks_exact_mut(LANES) {
            for l in 0..LANES {
                chunk[l] -= mean;
                acc[0][l] += chunk[l] * chunk[l];
            }
        }
        let mut tail = 0.0f64;
        for v in &mut row[chunks * LANES..] {
            *v -= mean;
            tail += (*v as f64) * (*v as f64);
        }
        ss += lane_total(&acc)[0] + tail;
    }
    ReferenceSums {
        mean,
        ss,
        ..Default::default()
    }
}

/// Adds one row's 17 sums (see `reference_sums_lanes`) at row offset `dy`.
#[inline(always)]
fn add_row(out: &mut ReferenceSums, row: &[f64; 17], dy: f64) {
    for (m, p) in out.moments.iter_mut().zip(row.chunks_exact(3)) {
        m[0] += p[0];
        m[1] += p[1];
        m[2] += dy * p[0];
        m[3] += p[2];
        m[4] += dy * p[1];
        m[5] += dy * dy * p[0];
    }
    for (sums, o) in [(&mut out.jf, 9), (&mut out.jsum, 13)] {
        sums[0] += row[o];
        sums[1] += row[o + 1];
        sums[2] += dy * row[o];
        sums[3] += row[o + 2];
        sums[4] += row[o + 3];
        sums[5] += dy * row[o + 2];
    }
}

/// Σ of a row in lanes, then in a fixed order.
#[inline(always)]
fn lane_total<const K: usize>(acc: &[[f32; LANES]; K]) -> [f64; K] {
    acc.map(|lanes| lanes.iter().map(|&v| v as f64).sum())
}

#[inline(always)]
fn reference_sums_lanes(f0: &mut [f32], gx: &[f32], gy: &[f32], dxs: &[f32]) -> ReferenceSums {
    let side = dxs.len();
    let half = (side / 2) as f64;
    let chunks = side / LANES;
    let mut out = mean_and_ss(f0, side);
    // Per row: Σ p, Σ p·dx, Σ p·dx² for p = gx², gx·gy, gy² (0..9), then Σ gx·f, Σ gx·f·dx,
    // Σ gy·f, Σ gy·f·dx, Σ gx, Σ gx·dx, Σ gy, Σ gy·dx (9..17).
    #[inline(always)]
    fn terms(a: f32, b: f32, f: f32, dx: f32) -> [f32; 17] {
        let (aa, ab, bb, af, bf) = (a * a, a * b, b * b, a * f, b * f);
        [
            aa,
            aa * dx,
            aa * dx * dx,
            ab,
            ab * dx,
            ab * dx * dx,
            bb,
            bb * dx,
            bb * dx * dx,
            af,
            af * dx,
            bf,
            bf * dx,
            a,
            a * dx,
            b,
            b * dx,
        ]
    }
    for r in 0..side {
        let dy = r as f64 - half;
        let range = r * side..(r + 1) * side;
        let (a_row, b_row, f_row) = (&gx[range.clone()], &gy[range.clone()], &f0[range]);
        let mut acc = [[0.0f32; LANES]; 17];
        for k in 0..chunks {
            let at = k * LANES;
            for l in 0..LANES {
                let t = terms(a_row[at + l], b_row[at + l], f_row[at + l], dxs[at + l]);
                for (a, v) in acc.iter_mut().zip(t) {
                    a[l] += v;
                }
            }
        }
        let mut row = lane_total(&acc);
        for c in chunks * LANES..side {
            let t = terms(a_row[c], b_row[c], f_row[c], dxs[c]);
            for (s, v) in row.iter_mut().zip(t) {
                *s += v as f64;
            }
        }
        add_row(&mut out, &row, dy);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_match_their_definition() {
        for half in [20usize, 2] {
            let side = 2 * half + 1;
            let n = side * side;
            let f: Vec<f32> = (0..n).map(|i| 500.0 + ((i * 37 % 101) as f32)).collect();
            let gx: Vec<f32> = (0..n).map(|i| ((i * 53 % 97) as f32) * 0.1 - 4.0).collect();
            let gy: Vec<f32> = (0..n).map(|i| ((i * 29 % 89) as f32) * 0.1 - 4.5).collect();
            let dxs: Vec<f32> = (0..side).map(|c| c as f32 - half as f32).collect();
            let mut f0_portable = f.clone();
            let portable = reference_sums_lanes(&mut f0_portable, &gx, &gy, &dxs);
            let mut f0 = f.clone();
            let got = reference_sums(&mut f0, &gx, &gy, &dxs);
            assert_eq!(f0, f0_portable, "the zero-mean subset");

            let mean = f.iter().map(|&v| v as f64).sum::<f64>() / n as f64;
            let mut want = ReferenceSums::default();
            let mut scale = ReferenceSums::default();
            for i in 0..n {
                let (dx, dy) = (
                    (i % side) as f64 - half as f64,
                    (i / side) as f64 - half as f64,
                );
                let (a, b, fz) = (gx[i] as f64, gy[i] as f64, f[i] as f64 - mean);
                assert!((f0[i] as f64 - fz).abs() < 1e-3, "zero-mean value {i}");
                want.ss += fz * fz;
                let mono = [1.0, dx, dy, dx * dx, dx * dy, dy * dy];
                for (k, p) in [a * a, a * b, b * b].into_iter().enumerate() {
                    for (m, mo) in mono.iter().enumerate() {
                        want.moments[k][m] += p * mo;
                        scale.moments[k][m] += (p * mo).abs();
                    }
                }
                let j = [a, a * dx, a * dy, b, b * dx, b * dy];
                for (k, jk) in j.into_iter().enumerate() {
                    want.jf[k] += jk * fz;
                    scale.jf[k] += (jk * fz).abs();
                    want.jsum[k] += jk;
                    scale.jsum[k] += jk.abs();
                }
            }
            for (got, what) in [(portable, "portable"), (got, "dispatched")] {
                assert!((got.mean as f64 - mean).abs() < 1e-4 * mean, "{what}");
                assert!((got.ss - want.ss).abs() < 1e-5 * want.ss);
                for k in 0..3 {
                    for m in 0..6 {
                        let (g, w, s) =
                            (got.moments[k][m], want.moments[k][m], scale.moments[k][m]);
                        assert!((g - w).abs() <= 1e-5 * s, "moment {k},{m}: {g} vs {w}");
                    }
                }
                for k in 0..6 {
                    assert!(
                        (got.jf[k] - want.jf[k]).abs() <= 1e-5 * scale.jf[k],
                        "jf {k}"
                    );
                    assert!(
                        (got.jsum[k] - want.jsum[k]).abs() <= 1e-5 * scale.jsum[k],
                        "jsum {k}"
                    );
                }
            }
        }
    }
}
