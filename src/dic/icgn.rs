//! Inverse-compositional Gauss-Newton (IC-GN) sub-pixel registration with the first-order shape
//! function and the zero-normalised SSD criterion, after Pan, Li & Tong, "Fast, robust and
//! accurate digital image correlation calculation without redundant computations", Exp. Mech. 53
//! (2013), and Baker & Matthews, "Lucas-Kanade 20 years on", IJCV 56 (2004).
//!
//! Everything that depends only on the reference — the zero-mean subset, its norm, the steepest-
//! descent images and the Gauss-Newton Hessian with its Cholesky factor — is computed once per
//! subset ([`SubsetReference::prepare`]); an iteration only interpolates the deformed subset and
//! accumulates one 6-vector.

use super::bspline::{cubic_weights, quintic_weights, BSplineImage};
use super::{Interpolation, PoiStatus, Warp};
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
        let mut sum = 0.0f64;
        for r in 0..side {
            let start = (y0 - half + r) * w + x0 - half;
            let dst = r * side..(r + 1) * side;
            scratch.f0[dst.clone()].copy_from_slice(&reference.data()[start..start + side]);
            scratch.gx[dst.clone()].copy_from_slice(&grad_x[start..start + side]);
            scratch.gy[dst.clone()].copy_from_slice(&grad_y[start..start + side]);
            sum += scratch.f0[dst].iter().map(|&v| v as f64).sum::<f64>();
        }
        let n = (side * side) as f64;
        let mean = (sum / n) as f32;
        let mut ss = 0.0f64;
        for v in scratch.f0.iter_mut() {
            *v -= mean;
            ss += (*v as f64) * (*v as f64);
        }
        let df = ss.sqrt();
        // A subset whose grey levels vary by less than 1e-5 of their mean (or not at all) holds
        // no information; ZNCC would divide by ~0.
        if !(df > 1e-5 * (mean.abs() as f64).max(1e-3) * n.sqrt()) {
            return None;
        }

        // Hessian of the steepest-descent images J = [gx, gx·dx, gx·dy, gy, gy·dx, gy·dy],
        // accumulated as moments {1, dx, dy, dx², dx·dy, dy²} of gx², gx·gy, gy² (row by row).
        let mut mom = [[0.0f64; 6]; 3];
        for r in 0..side {
            let dy = r as f64 - half as f64;
            let gxr = &scratch.gx[r * side..(r + 1) * side];
            let gyr = &scratch.gy[r * side..(r + 1) * side];
            let mut s = [[0.0f32; 3]; 3];
            for ((&a, &b), &dx) in gxr.iter().zip(gyr).zip(&scratch.dxs) {
                let prods = [a * a, a * b, b * b];
                for (sp, p) in s.iter_mut().zip(prods) {
                    sp[0] += p;
                    sp[1] += p * dx;
                    sp[2] += p * dx * dx;
                }
            }
            for (m, sp) in mom.iter_mut().zip(&s) {
                let (s0, s1, s2) = (sp[0] as f64, sp[1] as f64, sp[2] as f64);
                m[0] += s0;
                m[1] += s1;
                m[2] += dy * s0;
                m[3] += s2;
                m[4] += dy * s1;
                m[5] += dy * dy * s0;
            }
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
        let mean = 0.5 * (a + c);
        let spread = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        if !(mean - spread >= MIN_GRADIENT_ISOTROPY * (mean + spread)) {
            return None;
        }
        let chol = cholesky(&hess)?;
        Some(Self {
            x0,
            y0,
            half,
            df,
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
            let inside = match deformed.kind() {
                Interpolation::Bspline3 => warp_subset::<4>(deformed, self, &warp, &mut scratch.g),
                Interpolation::Bspline5 => warp_subset::<6>(deformed, self, &warp, &mut scratch.g),
            };
            if !inside {
                return IcgnOutcome {
                    warp,
                    zncc,
                    residual_ss,
                    iterations: iteration,
                    status: PoiStatus::LeftImage,
                };
            }
            let gm = (scratch.g.iter().map(|&v| v as f64).sum::<f64>() / n) as f32;
            let dg = scratch
                .g
                .iter()
                .map(|&v| {
                    let d = (v - gm) as f64;
                    d * d
                })
                .sum::<f64>()
                .sqrt();
            if !(dg > 0.0) {
                return IcgnOutcome {
                    warp,
                    zncc,
                    residual_ss,
                    iterations: iteration,
                    status: PoiStatus::LowCorrelation,
                };
            }
            // r = (f - fm) - (Δf/Δg)(g - gm); b = Σ Jᵀr; ZNSSD = Σ r² / Δf².
            let k = (self.df / dg) as f32;
            let offset = k * gm;
            let mut b = [0.0f64; 6];
            let mut rr = 0.0f64;
            for r in 0..side {
                let dy = r as f64 - half_f;
                let range = r * side..(r + 1) * side;
                let (f0, g) = (&scratch.f0[range.clone()], &scratch.g[range.clone()]);
                let (gx, gy) = (&scratch.gx[range.clone()], &scratch.gy[range]);
                let (mut a0, mut a1, mut b0, mut b1, mut s) =
                    (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
                for i in 0..side {
                    let res = f0[i] - k * g[i] + offset;
                    let dx = scratch.dxs[i];
                    let ax = gx[i] * res;
                    let ay = gy[i] * res;
                    a0 += ax;
                    a1 += ax * dx;
                    b0 += ay;
                    b1 += ay * dx;
                    s += res * res;
                }
                b[0] += a0 as f64;
                b[1] += a1 as f64;
                b[2] += dy * a0 as f64;
                b[3] += b0 as f64;
                b[4] += b1 as f64;
                b[5] += dy * b0 as f64;
                rr += s as f64;
            }
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

/// Interpolates the deformed subset under `warp` into `out`; false when any corner of the warped
/// subset falls outside the image (an affine map of a square is a parallelogram, so the corners
/// bound it).
#[inline(always)]
fn warp_subset<const N: usize>(
    def: &BSplineImage,
    sref: &SubsetReference,
    warp: &Warp,
    out: &mut [f32],
) -> bool {
    let h = sref.half as f64;
    // Pixel (c, r) covers [c-0.5, c+0.5]: the image spans [-0.5, w-0.5], where the mirror-
    // boundary interpolant is still defined by the edge pixels themselves.
    let (w_max, h_max) = (def.width() as f64 - 0.5, def.height() as f64 - 0.5);
    for (dx, dy) in [(-h, -h), (h, -h), (-h, h), (h, h)] {
        let (lx, ly) = warp.apply(dx, dy);
        let (x, y) = (sref.x0 as f64 + lx, sref.y0 as f64 + ly);
        if !(x >= -0.5 && y >= -0.5 && x <= w_max && y <= h_max) {
            return false;
        }
    }
    let side = 2 * sref.half + 1;
    let coeffs = def.coeffs();
    let stride = def.stride();
    let kind = def.kind();
    let (sx, sy) = ((1.0 + warp.ux) as f32, warp.vx as f32);
    for r in 0..side {
        let dy = r as f64 - h;
        // Positions relative to the subset centre keep f32 precision (~1e-5 px) on any image.
        let (lx0, ly0) = warp.apply(-h, dy);
        let (lx0, ly0) = (lx0 as f32, ly0 as f32);
        let out_row = &mut out[r * side..(r + 1) * side];
        for (c, o) in out_row.iter_mut().enumerate() {
            let lx = lx0 + c as f32 * sx;
            let ly = ly0 + c as f32 * sy;
            let (fx, fy) = (floor_i32(lx), floor_i32(ly));
            let (tx, ty) = (lx - fx as f32, ly - fy as f32);
            let ix = sref.x0 as isize + fx as isize;
            let iy = sref.y0 as isize + fy as isize;
            let base = def.tap_base(ix, iy, kind);
            *o = if N == 4 {
                taps4(coeffs, base, stride, &cubic_weights(tx), &cubic_weights(ty))
            } else {
                taps6(
                    coeffs,
                    base,
                    stride,
                    &quintic_weights(tx),
                    &quintic_weights(ty),
                )
            };
        }
    }
    true
}

/// floor() as an integer without a libm call (x86-64's baseline has no rounding instruction).
#[inline(always)]
fn floor_i32(x: f32) -> i32 {
    let t = x as i32;
    t - ((x < t as f32) as i32)
}

/// Σ_j wy_j Σ_i wx_i c[j][i] over a 4x4 tap block. Each tap row is 4 contiguous floats, summed
/// column-wise first so the compiler keeps the four rows in one vector register.
#[inline(always)]
fn taps4(c: &[f32], base: usize, stride: usize, wx: &[f32; 4], wy: &[f32; 4]) -> f32 {
    let row = |k: usize| -> [f32; 4] {
        c[base + k * stride..base + k * stride + 4]
            .try_into()
            .expect("4 taps")
    };
    let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
    let mut col = [0.0f32; 4];
    for i in 0..4 {
        col[i] = wy[0] * r0[i] + wy[1] * r1[i] + wy[2] * r2[i] + wy[3] * r3[i];
    }
    (col[0] * wx[0] + col[1] * wx[1]) + (col[2] * wx[2] + col[3] * wx[3])
}

#[inline(always)]
fn taps6(c: &[f32], base: usize, stride: usize, wx: &[f32; 6], wy: &[f32; 6]) -> f32 {
    let mut col = [0.0f32; 6];
    for (j, &wyj) in wy.iter().enumerate() {
        let row = &c[base + j * stride..base + j * stride + 6];
        for i in 0..6 {
            col[i] += wyj * row[i];
        }
    }
    col.iter().zip(wx).map(|(a, b)| a * b).sum()
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

    #[test]
    fn floor_matches_std() {
        for x in [-2.5f32, -1.0, -0.3, 0.0, 0.7, 3.0, 12.9999] {
            assert_eq!(floor_i32(x), x.floor() as i32, "{x}");
        }
    }
}
