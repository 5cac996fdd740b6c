//! Inverse-compositional Gauss-Newton (IC-GN) sub-pixel registration with the first-order shape
//! function and the zero-normalised SSD criterion, after Pan, Li & Tong, "Fast, robust and
//! accurate digital image correlation calculation without redundant computations", Exp. Mech. 53
//! (2013), and Baker & Matthews, "Lucas-Kanade 20 years on", IJCV 56 (2004).
//!
//! Everything that depends only on the reference — the zero-mean subset, its norm, the steepest-
//! descent images and the Gauss-Newton Hessian with its Cholesky factor — is computed once per
//! subset ([`SubsetReference::prepare`]); an iteration is one pass over the warped deformed
//! subset that interpolates and accumulates at once (`icgn_sums`).

use super::bspline::BSplineImage;
use super::icgn_sums::{warped_sums, SubsetArrays};
use super::reference_sums::{reference_sums, ReferenceSums};
use super::{PoiStatus, Warp};
use crate::image::Image;

/// Smallest ratio of the weaker to the stronger principal gradient energy of a subset: below
/// it the subset is textured in one direction only (the `no_contrast` status). A speckle
/// subset has a ratio of 0.3 to 1; 10⁻³ means a position 30 times less certain across the
/// texture than along it.
pub const MIN_GRADIENT_ISOTROPY: f64 = 1e-3;

/// Per-thread buffers for one subset, reused from point to point.
pub struct Scratch {
    pub f0: Vec<f32>,
    pub(super) gx: Vec<f32>,
    pub(super) gy: Vec<f32>,
    pub(super) g: Vec<f32>,
    dxs: Vec<f32>,
}

impl Scratch {
    pub fn new(half: usize) -> Self {
        let side = 2 * half + 1;
        let n = side * side;
        Self {
            f0: vec![0.0; n],
            gx: vec![0.0; n],
            gy: vec![0.0; n],
            g: vec![0.0; n],
            dxs: (0..side).map(|k| k as f32 - half as f32).collect(),
        }
    }
}

/// Reference-side data of one subset, held in a [`Scratch`].
pub struct SubsetReference {
    pub x0: usize,
    pub y0: usize,
    pub half: usize,
    /// sqrt(Σ (f - f_mean)²).
    pub df: f64,
    /// The reference subset's mean grey value.
    mean: f32,
    /// Σ J·f over the subset (f zero-mean), J the steepest-descent images.
    jf: [f64; 6],
    /// Σ J over the subset.
    jsum: [f64; 6],
    /// Lower Cholesky factor of the Gauss-Newton Hessian Σ JᵀJ.
    chol: [[f64; 6]; 6],
}

/// The outcome of IC-GN at one point.
#[derive(Clone, Copy, Debug)]
pub struct IcgnOutcome {
    pub warp: Warp,
    pub zncc: f64,
    /// Σ r² of the last iteration's ZNSSD residual, on the reference's grey scale (NaN when
    /// never evaluated).
    pub residual_ss: f64,
    pub iterations: u32,
    pub status: PoiStatus,
}

impl SubsetReference {
    /// Loads the reference subset centred at (x0, y0) into `scratch` and factors its Hessian.
    /// None when the subset has no usable contrast (flat, or a singular Hessian).
    pub fn prepare(
        reference: &Image,
        grad_x: &[f32],
        grad_y: &[f32],
        (x0, y0): (usize, usize),
        half: usize,
        scratch: &mut Scratch,
    ) -> Option<Self> {
        let side = 2 * half + 1;
        let w = reference.width();
        for r in 0..side {
            let start = (y0 - half + r) * w + x0 - half;
            let dst = r * side..(r + 1) * side;
            scratch.f0[dst.clone()].copy_from_slice(&reference.data()[start..start + side]);
            scratch.gx[dst.clone()].copy_from_slice(&grad_x[start..start + side]);
            scratch.gy[dst].copy_from_slice(&grad_y[start..start + side]);
        }
        let n = (side * side) as f64;
        // Hessian of the steepest-descent images J = [gx, gx·dx, gx·dy, gy, gy·dx, gy·dy],
        // accumulated as moments {1, dx, dy, dx², dx·dy, dy²} of gx², gx·gy, gy².
        let ReferenceSums {
            mean,
            ss,
            moments: mom,
            jf,
            jsum,
        } = reference_sums(&mut scratch.f0, &scratch.gx, &scratch.gy, &scratch.dxs);
        let df = ss.sqrt();
        // A subset whose grey levels vary by less than 1e-5 of their mean (or not at all) holds
        // no information; ZNCC would divide by ~0.
        if !(df > 1e-5 * (mean.abs() as f64).max(1e-3) * n.sqrt()) {
            return None;
        }
        // Monomial index of m_i·m_j for multipliers {1, dx, dy}.
        const MONO: [[usize; 3]; 3] = [[0, 1, 2], [1, 3, 4], [2, 4, 5]];
        let mut hess = [[0.0f64; 6]; 6];
        for (i, row) in hess.iter_mut().enumerate() {
            for (j, hij) in row.iter_mut().enumerate() {
                let prod = match (i / 3, j / 3) {
                    (0, 0) => 0,
                    (1, 1) => 2,
                    _ => 1,
                };
                *hij = mom[prod][MONO[i % 3][j % 3]];
            }
        }
        // Gradients in essentially one direction (a 1-D texture, an edge, fringes) leave the
        // position along the other undetermined whatever the noise: the weaker eigenvalue of
        // the translation block [Σgx², Σgxgy; Σgxgy, Σgy²] must hold a share of the stronger.
        let (a, b, c) = (mom[0][0], mom[1][0], mom[2][0]);
        let centre = 0.5 * (a + c);
        let spread = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        if !(centre - spread >= MIN_GRADIENT_ISOTROPY * (centre + spread)) {
            return None;
        }
        let chol = cholesky(&hess)?;
        Some(Self {
            x0,
            y0,
            half,
            df,
            mean,
            jf,
            jsum,
            chol,
        })
    }

    /// Standard deviations of u and v, px, that a fit residual Σ r² implies: the Gauss-Newton
    /// covariance σ̂²·H⁻¹ with σ̂² = Σ r² / (n − 6) (the residual holds the noise of both images,
    /// and any misfit). Pan et al., "Study on subset size selection in digital image
    /// correlation for speckle patterns", Opt. Express 16 (2008), derive the same scaling
    /// (σ_u ∝ σ/√SSSIG) for the translation alone.
    pub fn displacement_std(&self, residual_ss: f64) -> (f64, f64) {
        let side = 2 * self.half + 1;
        let dof = (side * side).saturating_sub(6).max(1) as f64;
        let sigma2 = residual_ss / dof;
        let diag = |k: usize| {
            let mut e = [0.0f64; 6];
            e[k] = 1.0;
            cholesky_solve(&self.chol, &e)[k]
        };
        ((sigma2 * diag(0)).sqrt(), (sigma2 * diag(3)).sqrt())
    }

    /// Runs IC-GN from `start` until the update is below `convergence_px` or `max_iterations`.
    pub fn solve(
        &self,
        deformed: &BSplineImage,
        start: Warp,
        convergence_px: f64,
        max_iterations: u32,
        scratch: &mut Scratch,
    ) -> IcgnOutcome {
        let side = 2 * self.half + 1;
        let n = (side * side) as f64;
        let half_f = self.half as f64;
        let mut warp = start;
        let mut zncc = f64::NAN;
        let mut residual_ss = f64::NAN;
        for iteration in 1..=max_iterations {
            let arrays = SubsetArrays {
                f0: &scratch.f0,
                gx: &scratch.gx,
                gy: &scratch.gy,
                half: self.half,
                centre: (self.x0, self.y0),
                shift: self.mean,
            };
            let Some(sums) = warped_sums(deformed, &arrays, &warp) else {
                return IcgnOutcome {
                    warp,
                    zncc,
                    residual_ss,
                    iterations: iteration,
                    status: PoiStatus::LeftImage,
                };
            };
            // h = g − mean_f: Δg² = Σh² − (Σh)²/n.
            let h_mean = sums.h / n;
            let dg = (sums.hh - sums.h * h_mean).max(0.0).sqrt();
            if !(dg > 1e-6 * sums.hh.sqrt()) {
                return IcgnOutcome {
                    warp,
                    zncc,
                    residual_ss,
                    iterations: iteration,
                    status: PoiStatus::LowCorrelation,
                };
            }
            // r = f − k(g − ḡ), k = Δf/Δg: b = Σ Jᵀr = Σ Jf − k(Σ Jh − h̄ Σ J),
            // Σ r² = 2Δf² − 2k Σ f·h (f zero-mean); ZNSSD = Σ r² / Δf².
            let k = self.df / dg;
            let mut b = [0.0f64; 6];
            for (i, bi) in b.iter_mut().enumerate() {
                *bi = self.jf[i] - k * (sums.jh[i] - h_mean * self.jsum[i]);
            }
            let rr = (2.0 * self.df * self.df - 2.0 * k * sums.fh).max(0.0);
            zncc = 1.0 - 0.5 * rr / (self.df * self.df);
            residual_ss = rr;
            let x = cholesky_solve(&self.chol, &b);
            let dp = Warp::from_array([-x[0], -x[1], -x[2], -x[3], -x[4], -x[5]]);
            match warp.compose_inverse(&dp) {
                Some(next) => warp = next,
                None => {
                    return IcgnOutcome {
                        warp,
                        zncc,
                        residual_ss,
                        iterations: iteration,
                        status: PoiStatus::NotConverged,
                    }
                }
            }
            if dp.update_norm(half_f) < convergence_px {
                return IcgnOutcome {
                    warp,
                    zncc,
                    residual_ss,
                    iterations: iteration,
                    status: PoiStatus::Converged,
                };
            }
        }
        IcgnOutcome {
            warp,
            zncc,
            residual_ss,
            iterations: max_iterations,
            status: PoiStatus::NotConverged,
        }
    }
}

/// Cholesky factor L (lower) of a symmetric positive-definite 6x6 matrix; None if not SPD.
#[allow(clippy::needless_range_loop)] // index form mirrors the textbook recurrences
pub(super) fn cholesky<const N: usize>(a: &[[f64; N]; N]) -> Option<[[f64; N]; N]> {
    let mut l = [[0.0f64; N]; N];
    for i in 0..N {
        for j in 0..=i {
            let mut s = a[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            if i == j {
                // Relative pivot test: a pivot this small means gradients in one direction only.
                if !(s > 1e-10 * a[i][i].abs()) {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    Some(l)
}

#[allow(clippy::needless_range_loop)]
pub(super) fn cholesky_solve<const N: usize>(l: &[[f64; N]; N], b: &[f64; N]) -> [f64; N] {
    let mut y = [0.0f64; N];
    for i in 0..N {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i][k] * y[k];
        }
        y[i] = s / l[i][i];
    }
    let mut x = [0.0f64; N];
    for i in (0..N).rev() {
        let mut s = y[i];
        for k in i + 1..N {
            s -= l[k][i] * x[k];
        }
        x[i] = s / l[i][i];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn cholesky_solves_spd_system() {
        let mut a = [[0.0f64; 6]; 6];
        for i in 0..6 {
            for j in 0..6 {
                a[i][j] = 1.0 / (1.0 + (i as f64 - j as f64).abs());
            }
            a[i][i] += 2.0;
        }
        let l = cholesky(&a).unwrap();
        let b = [1.0, -2.0, 3.0, 0.5, -1.0, 2.0];
        let x = cholesky_solve(&l, &b);
        for i in 0..6 {
            let ax: f64 = (0..6).map(|j| a[i][j] * x[j]).sum();
            assert!((ax - b[i]).abs() < 1e-12);
        }
    }
}
