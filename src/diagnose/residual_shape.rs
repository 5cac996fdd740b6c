//! The shape of what a comparison leaves: per run the affine part of the field difference in
//! full-resolution px (εxx, εyy, shear, rotation with their standard errors), the RMS of the
//! quadratic part beyond it, whether the strains grow with the move, and the image statistics
//! whose χ² is far above its count.

use super::discrepancy::{quadratic_fit, QuadraticFit};
use super::results::{Comparison, RunComparison, IMAGE_KINDS};
use crate::reduce::Scheme;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Shape {
    pub runs: Vec<RunShape>,
    /// The strains grow with the move (a fit through the origin against the move size beats a
    /// constant), absent with fewer than two move sizes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub grows_with_move: Option<bool>,
    /// Image statistics whose χ² per observation exceeds 3 (kinds: `spectrum`, `noise`,
    /// `mean_map`, `contrast`).
    pub image: Vec<ImageMismatch>,
}

/// The affine and quadratic parts of one run's field difference (its schemes pooled).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunShape {
    pub run: String,
    pub pattern: String,
    pub move_px: [f64; 2],
    pub exx: f64,
    pub eyy: f64,
    /// (∂u/∂y + ∂v/∂x)/2.
    pub shear: f64,
    /// (∂v/∂x − ∂u/∂y)/2, rad.
    pub rotation: f64,
    /// Standard errors of the four, in the same order.
    pub se: [f64; 4],
    /// RMS of the quadratic part beyond the affine one, full-resolution px.
    pub quadratic_px: f64,
    /// RMS of the affine part (less its constant) over the same points, full-resolution px.
    #[serde(default)]
    pub affine_px: f64,
    /// The discrepancy's rigid part, the largest over the run's schemes, px of the analysed
    /// images.
    #[serde(default)]
    pub rigid_px: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageMismatch {
    pub kind: String,
    pub chi2_per_observation: f64,
}

const IMAGE_KIND_NAMES: [&str; IMAGE_KINDS] = ["spectrum", "noise", "mean_map", "contrast"];

/// The full quadratic surface of `values` at `xy` (`discrepancy::quadratic_fit`), and the drop
/// of the residual sum of squares from the mean to it; None with fewer than 12 points or a
/// degenerate layout (its ten low-order terms are what the field test counts).
pub fn surface(xy: &[(f64, f64)], values: &[f64]) -> Option<(QuadraticFit, f64)> {
    if xy.len() < 12 {
        return None;
    }
    let fit = quadratic_fit(xy, values).filter(|f| f.full)?;
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let rss0: f64 = values.iter().map(|v| (v - mean).powi(2)).sum();
    let rss: f64 = values
        .iter()
        .zip(&fit.fitted)
        .map(|(v, f)| (v - f).powi(2))
        .sum();
    Some((fit, (rss0 - rss).max(0.0)))
}

/// One run and scheme's field difference split by order.
struct Orders {
    /// [∂u/∂x, ∂u/∂y, ∂v/∂x, ∂v/∂y], full-resolution px per px.
    grad: [f64; 4],
    var: [f64; 4],
    /// RMS over the points of the quadratic and of the (non-constant) affine part, px.
    quadratic_px: f64,
    affine_px: f64,
}

/// Affine part of one run and scheme in full-resolution px, its variances, and the RMS of the
/// quadratic and the affine parts.
fn affine_of(r: &RunComparison, scheme: &Scheme, infl: f64) -> Option<Orders> {
    let (bx, by) = (scheme.x.block as f64, scheme.y.block as f64);
    let pts: Vec<(f64, f64)> = r
        .detail
        .common
        .iter()
        .map(|p| scheme.to_full(p.x, p.y))
        .collect();
    let n = pts.len() as f64;
    let du: Vec<f64> = r.detail.common.iter().map(|p| p.du * bx).collect();
    let dv: Vec<f64> = r.detail.common.iter().map(|p| p.dv * by).collect();
    let (fu, _) = surface(&pts, &du)?;
    let (fv, _) = surface(&pts, &dv)?;
    // The same points, so the same normalisation for both components.
    let (cx, cy, s) = fu.norm;
    let c = (cx, cy);
    let (cu, cv) = (fu.coefficients, fv.coefficients);
    // Gradients at the points' centre, per full-resolution px.
    let grad = [cu[1] / s, cu[2] / s, cv[1] / s, cv[2] / s];
    // Variances of a slope over the points' spread: σ²c/Σ(x−x̄)².
    let sxx: f64 = pts.iter().map(|p| (p.0 - c.0).powi(2)).sum();
    let syy: f64 = pts.iter().map(|p| (p.1 - c.1).powi(2)).sum();
    let (vu, vv) = (
        r.detail.residual_var_px2.0 * bx * bx * infl,
        r.detail.residual_var_px2.1 * by * by * infl,
    );
    let var = [vu / sxx, vu / syy, vv / sxx, vv / syy];
    let rms = |co: &[f64; 6], terms: &dyn Fn(&[f64; 6], f64, f64) -> f64| {
        pts.iter()
            .map(|p| terms(co, (p.0 - c.0) / s, (p.1 - c.1) / s).powi(2))
            .sum::<f64>()
            / n
    };
    let quadratic = |co: &[f64; 6], a: f64, b: f64| co[3] * a * a + co[4] * a * b + co[5] * b * b;
    let affine = |co: &[f64; 6], a: f64, b: f64| co[1] * a + co[2] * b;
    Some(Orders {
        grad,
        var,
        quadratic_px: (rms(&cu, &quadratic) + rms(&cv, &quadratic)).sqrt(),
        affine_px: (rms(&cu, &affine) + rms(&cv, &affine)).sqrt(),
    })
}

pub fn shape_of(cmp: &Comparison, schemes: &[Scheme], infl: f64) -> Shape {
    let mut runs: Vec<RunShape> = Vec::new();
    let mut ids: Vec<&str> = Vec::new();
    for r in &cmp.runs {
        if !ids.contains(&r.id.as_str()) {
            ids.push(r.id.as_str());
        }
    }
    for id in ids {
        // Pool the run's schemes, weighted by their inverse variances.
        let (mut num, mut den, mut quad, mut lin, mut count) = ([0.0; 4], [0.0; 4], 0.0, 0.0, 0.0);
        let mut rigid_px = 0.0f64;
        let mut first: Option<&RunComparison> = None;
        for r in cmp.runs.iter().filter(|r| r.id == id) {
            rigid_px = rigid_px.max(r.rigid_px);
            let Some(scheme) = schemes.iter().find(|s| s.name == r.scheme) else {
                continue;
            };
            let Some(Orders {
                grad: g,
                var: v,
                quadratic_px,
                affine_px,
            }) = affine_of(r, scheme, infl)
            else {
                continue;
            };
            first.get_or_insert(r);
            for i in 0..4 {
                if v[i] > 0.0 {
                    num[i] += g[i] / v[i];
                    den[i] += 1.0 / v[i];
                }
            }
            quad += quadratic_px;
            lin += affine_px;
            count += 1.0;
        }
        let Some(r) = first else { continue };
        if den.iter().any(|d| !(*d > 0.0)) {
            // A component without a noise level has no standard error: no shape to report.
            continue;
        }
        let g: Vec<f64> = (0..4).map(|i| num[i] / den[i]).collect();
        let v: Vec<f64> = den.iter().map(|d| 1.0 / d).collect();
        // exx = ux, eyy = vy, shear = (uy + vx)/2, rotation = (vx − uy)/2.
        runs.push(RunShape {
            run: r.id.clone(),
            pattern: r.pattern.clone(),
            move_px: r.move_px,
            exx: g[0],
            eyy: g[3],
            shear: 0.5 * (g[1] + g[2]),
            rotation: 0.5 * (g[2] - g[1]),
            se: [
                v[0].sqrt(),
                v[3].sqrt(),
                0.5 * (v[1] + v[2]).sqrt(),
                0.5 * (v[1] + v[2]).sqrt(),
            ],
            quadratic_px: quad / count,
            affine_px: lin / count,
            rigid_px,
        });
    }
    let grows_with_move = grows_with_move(&runs);
    let image = cmp
        .chi2
        .image_parts
        .iter()
        .zip(IMAGE_KIND_NAMES)
        .filter(|((c, n), _)| *n > 0 && *c / *n as f64 > 3.0)
        .map(|((c, n), kind)| ImageMismatch {
            kind: kind.to_string(),
            chi2_per_observation: c / *n as f64,
        })
        .collect();
    Shape {
        runs,
        grows_with_move,
        image,
    }
}

/// Whether the strains' size follows the move's (through the origin) better than a constant,
/// among the runs moved along the same axis as the largest move (a field that grows with the
/// move may differ in kind between axes).
fn grows_with_move(runs: &[RunShape]) -> Option<bool> {
    let largest = runs
        .iter()
        .max_by(|a, b| {
            let size = |r: &RunShape| r.move_px[0].hypot(r.move_px[1]);
            size(a).total_cmp(&size(b))
        })?
        .move_px;
    let along_x = largest[0].abs() >= largest[1].abs();
    let moved: Vec<(f64, f64)> = runs
        .iter()
        .filter(|r| {
            let (along, across) = if along_x {
                (r.move_px[0], r.move_px[1])
            } else {
                (r.move_px[1], r.move_px[0])
            };
            along.abs() > 2.0 && across.abs() < 0.2 * along.abs()
        })
        .map(|r| {
            let size = r.move_px[0].hypot(r.move_px[1]);
            let strain = (r.exx.powi(2) + r.eyy.powi(2) + 2.0 * r.shear.powi(2)).sqrt();
            (size, strain)
        })
        .collect();
    let (lo, hi) = moved.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), m| {
        (lo.min(m.0), hi.max(m.0))
    });
    if moved.len() < 2 || hi < 1.5 * lo {
        return None;
    }
    let mean = moved.iter().map(|m| m.1).sum::<f64>() / moved.len() as f64;
    let rss_const: f64 = moved.iter().map(|m| (m.1 - mean).powi(2)).sum();
    let slope =
        moved.iter().map(|m| m.0 * m.1).sum::<f64>() / moved.iter().map(|m| m.0 * m.0).sum::<f64>();
    let rss_prop: f64 = moved.iter().map(|m| (m.1 - slope * m.0).powi(2)).sum();
    Some(rss_prop < rss_const)
}
