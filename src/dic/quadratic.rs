//! The second-order shape function (Lu & Cary, "Deformation measurements by digital image
//! correlation: implementation of a second-order displacement gradient", Exp. Mech. 40 (2000)):
//! u(Δx, Δy) = u + uₓΔx + u_yΔy + ½uₓₓΔx² + uₓ_yΔxΔy + ½u_yyΔy², likewise v — for subsets over
//! which the displacement gradient itself changes (a notch, a crack tip, a step). IC-GN with
//! the inverse-compositional update written as a 6x6 matrix acting on (Δx², ΔxΔy, Δy², Δx, Δy,
//! 1), after Gao, Cheng, Su & Chen, "High-efficiency and high-accuracy digital image
//! correlation for three-dimensional measurement", Opt. Lasers Eng. 65 (2015).

use super::bspline::BSplineImage;
use super::icgn::{cholesky, cholesky_solve, Scratch};
use super::{PoiStatus, Warp};
use nalgebra::Matrix6;

/// p = (u, uₓ, u_y, uₓₓ, uₓ_y, u_yy, v, vₓ, v_y, vₓₓ, vₓ_y, v_yy).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuadraticWarp {
    pub p: [f64; 12],
}

impl QuadraticWarp {
    pub fn from_affine(w: &Warp) -> Self {
        Self {
            p: [
                w.u, w.ux, w.uy, 0.0, 0.0, 0.0, w.v, w.vx, w.vy, 0.0, 0.0, 0.0,
            ],
        }
    }

    /// The first-order part.
    pub fn affine(&self) -> Warp {
        let p = &self.p;
        Warp {
            u: p[0],
            ux: p[1],
            uy: p[2],
            v: p[6],
            vx: p[7],
            vy: p[8],
        }
    }

    /// Where the subset offset (dx, dy) lands, relative to the subset centre.
    pub fn apply(&self, dx: f64, dy: f64) -> (f64, f64) {
        let p = &self.p;
        let quad = |o: usize| {
            p[o] + p[o + 1] * dx
                + p[o + 2] * dy
                + 0.5 * p[o + 3] * dx * dx
                + p[o + 4] * dx * dy
                + 0.5 * p[o + 5] * dy * dy
        };
        (dx + quad(0), dy + quad(6))
    }

    /// The warp acting on ξ = (Δx², ΔxΔy, Δy², Δx, Δy, 1), terms above second order dropped.
    fn matrix(&self) -> [[f64; 6]; 6] {
        let p = &self.p;
        // x' = a0Δx² + a1ΔxΔy + a2Δy² + a3Δx + a4Δy + a5, likewise y' with b.
        let a = [0.5 * p[3], p[4], 0.5 * p[5], 1.0 + p[1], p[2], p[0]];
        let b = [0.5 * p[9], p[10], 0.5 * p[11], p[7], 1.0 + p[8], p[6]];
        let product = |a: &[f64; 6], b: &[f64; 6]| {
            [
                a[3] * b[3] + a[5] * b[0] + a[0] * b[5],
                a[3] * b[4] + a[4] * b[3] + a[5] * b[1] + a[1] * b[5],
                a[4] * b[4] + a[5] * b[2] + a[2] * b[5],
                a[5] * b[3] + a[3] * b[5],
                a[5] * b[4] + a[4] * b[5],
                a[5] * b[5],
            ]
        };
        [
            product(&a, &a),
            product(&a, &b),
            product(&b, &b),
            a,
            b,
            [0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        ]
    }

    fn from_matrix(m: &[[f64; 6]; 6]) -> Self {
        let (a, b) = (&m[3], &m[4]);
        Self {
            p: [
                a[5],
                a[3] - 1.0,
                a[4],
                2.0 * a[0],
                a[1],
                2.0 * a[2],
                b[5],
                b[3],
                b[4] - 1.0,
                2.0 * b[0],
                b[1],
                2.0 * b[2],
            ],
        }
    }

    /// W(self) ∘ W(dp)⁻¹; None when W(dp) is singular (nalgebra's LU inverse).
    pub fn compose_inverse(&self, dp: &QuadraticWarp) -> Option<Self> {
        let matrix = |m: [[f64; 6]; 6]| Matrix6::from_fn(|i, j| m[i][j]);
        let product = matrix(self.matrix()) * matrix(dp.matrix()).try_inverse()?;
        Some(Self::from_matrix(&std::array::from_fn(|i| {
            std::array::from_fn(|j| product[(i, j)])
        })))
    }

    /// Largest displacement, px, the update causes in a subset of half-width `half`.
    fn update_norm(&self, half: f64) -> f64 {
        let p = &self.p;
        let h2 = half * half;
        let first = p[1] * p[1] + p[2] * p[2] + p[7] * p[7] + p[8] * p[8];
        let second = 0.25 * (p[3] * p[3] + p[5] * p[5] + p[9] * p[9] + p[11] * p[11])
            + p[4] * p[4]
            + p[10] * p[10];
        (p[0] * p[0] + p[6] * p[6] + h2 * first + h2 * h2 * second).sqrt()
    }
}

/// The outcome of second-order IC-GN at one point.
#[derive(Clone, Copy, Debug)]
pub struct QuadraticOutcome {
    pub warp: QuadraticWarp,
    pub zncc: f64,
    pub iterations: u32,
    pub status: PoiStatus,
    /// Standard deviations of u and v from σ̂²·H⁻¹ (NaN when never evaluated).
    pub std_px: (f64, f64),
}

/// IC-GN with the second-order shape function for the subset centred at (x0, y0) whose
/// zero-mean grey values (norm `df`) and gradients are loaded in `scratch`.
pub struct QuadraticSolve<'a> {
    pub deformed: &'a BSplineImage,
    pub centre: (usize, usize),
    pub half: usize,
    pub df: f64,
}

#[allow(clippy::needless_range_loop)] // index form mirrors the normal equations
impl QuadraticSolve<'_> {
    /// The 12 steepest-descent values of pixel (dx, dy) with gradient (gx, gy).
    fn jacobian(gx: f64, gy: f64, dx: f64, dy: f64) -> [f64; 12] {
        let m = [1.0, dx, dy, 0.5 * dx * dx, dx * dy, 0.5 * dy * dy];
        let mut j = [0.0f64; 12];
        for k in 0..6 {
            j[k] = gx * m[k];
            j[k + 6] = gy * m[k];
        }
        j
    }

    /// The Gauss–Newton Hessian of the reference subset, Σ Jᵀ J over its pixels (constant in
    /// the inverse-compositional scheme).
    fn hessian(&self, scratch: &Scratch) -> [[f64; 12]; 12] {
        let side = 2 * self.half + 1;
        let h = self.half as f64;
        let mut hess = [[0.0f64; 12]; 12];
        for i in 0..side * side {
            let (dx, dy) = ((i % side) as f64 - h, (i / side) as f64 - h);
            let j = Self::jacobian(scratch.gx[i] as f64, scratch.gy[i] as f64, dx, dy);
            for a in 0..12 {
                for b in 0..=a {
                    hess[a][b] += j[a] * j[b];
                }
            }
        }
        for a in 0..12 {
            for b in a + 1..12 {
                hess[a][b] = hess[b][a];
            }
        }
        hess
    }

    pub fn run(
        &self,
        start: QuadraticWarp,
        convergence_px: f64,
        max_iterations: u32,
        scratch: &mut Scratch,
    ) -> QuadraticOutcome {
        let side = 2 * self.half + 1;
        let n = side * side;
        let h = self.half as f64;
        let offsets = |i: usize| ((i % side) as f64 - h, (i / side) as f64 - h);
        let hess = self.hessian(scratch);
        let mut outcome = QuadraticOutcome {
            warp: start,
            zncc: f64::NAN,
            iterations: 0,
            status: PoiStatus::NotConverged,
            std_px: (f64::NAN, f64::NAN),
        };
        let Some(chol) = cholesky(&hess) else {
            outcome.status = PoiStatus::NoContrast;
            return outcome;
        };
        let (w_max, h_max) = (
            self.deformed.width() as f64 - 0.5,
            self.deformed.height() as f64 - 0.5,
        );
        let (x0, y0) = (self.centre.0 as f64, self.centre.1 as f64);
        let mut warp = start;
        for iteration in 1..=max_iterations {
            outcome.iterations = iteration;
            for i in 0..n {
                let (dx, dy) = offsets(i);
                let (lx, ly) = warp.apply(dx, dy);
                let (x, y) = (x0 + lx, y0 + ly);
                if !(x >= -0.5 && y >= -0.5 && x <= w_max && y <= h_max) {
                    outcome.status = PoiStatus::LeftImage;
                    return outcome;
                }
                scratch.g[i] = self.deformed.sample(x, y);
            }
            let gm = scratch.g[..n].iter().map(|&v| v as f64).sum::<f64>() / n as f64;
            let dg = scratch.g[..n]
                .iter()
                .map(|&v| (v as f64 - gm).powi(2))
                .sum::<f64>()
                .sqrt();
            if !(dg > 0.0) {
                outcome.status = PoiStatus::LowCorrelation;
                return outcome;
            }
            let k = self.df / dg;
            let mut b = [0.0f64; 12];
            let mut rr = 0.0f64;
            for i in 0..n {
                let (dx, dy) = offsets(i);
                let r = scratch.f0[i] as f64 - k * (scratch.g[i] as f64 - gm);
                let j = Self::jacobian(scratch.gx[i] as f64, scratch.gy[i] as f64, dx, dy);
                for a in 0..12 {
                    b[a] += j[a] * r;
                }
                rr += r * r;
            }
            outcome.zncc = 1.0 - 0.5 * rr / (self.df * self.df);
            let sigma2 = rr / (n.saturating_sub(12).max(1)) as f64;
            let diag = |idx: usize| {
                let mut e = [0.0f64; 12];
                e[idx] = 1.0;
                cholesky_solve(&chol, &e)[idx]
            };
            outcome.std_px = ((sigma2 * diag(0)).sqrt(), (sigma2 * diag(6)).sqrt());
            let x = cholesky_solve(&chol, &b);
            let dp = QuadraticWarp { p: x.map(|v| -v) };
            match warp.compose_inverse(&dp) {
                Some(next) => warp = next,
                None => {
                    outcome.warp = warp;
                    return outcome;
                }
            }
            outcome.warp = warp;
            if dp.update_norm(h) < convergence_px {
                outcome.status = PoiStatus::Converged;
                return outcome;
            }
        }
        outcome
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn composition_with_own_inverse_is_near_identity_and_matches_affine() {
        let w = QuadraticWarp {
            p: [
                1.5, 0.01, -0.02, 0.0, 0.0, 0.0, -3.0, 0.005, 0.03, 0.0, 0.0, 0.0,
            ],
        };
        let dp = QuadraticWarp {
            p: [
                0.1, 0.001, 0.002, 0.0, 0.0, 0.0, -0.05, -0.001, 0.0005, 0.0, 0.0, 0.0,
            ],
        };
        let affine = w.affine().compose_inverse(&dp.affine()).unwrap();
        let quad = w.compose_inverse(&dp).unwrap();
        let a = quad.affine();
        for (x, y) in [
            (a.u, affine.u),
            (a.ux, affine.ux),
            (a.vy, affine.vy),
            (a.v, affine.v),
        ] {
            assert!((x - y).abs() < 1e-12);
        }
        let q = QuadraticWarp {
            p: [
                0.3, 0.01, 0.0, 1e-4, -2e-4, 5e-5, -0.2, 0.0, 0.02, 3e-4, 0.0, -1e-4,
            ],
        };
        let id = q.compose_inverse(&q).unwrap();
        assert!(id.p.iter().all(|v| v.abs() < 1e-6), "{id:?}");
    }
}
