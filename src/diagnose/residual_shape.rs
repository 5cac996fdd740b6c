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

const IMAGE_KIND_NAMES: [&str; IMAGE_KINDS] =
    ["spectrum", "noise", "mean_map", "contrast", "light_change"];

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::discrepancy::CommonPoint;
    use crate::diagnose::test_fields::{
        comparison, field_points, run_comparison, run_shape, CENTRE,
    };

    /// ∂u/∂x, ∂u/∂y, ∂v/∂x, ∂v/∂y of a strain εxx, εyy, a shear γ and a rotation ω:
    /// εxx, γ − ω, γ + ω, εyy.
    const STRAIN: (f64, f64, f64, f64) = (2e-4, -1e-4, 5e-5, 3e-5);
    /// Noise of the field difference, px per component.
    const SIGMA: f64 = 0.01;

    /// The affine field of [`STRAIN`] at p (px from the centre), and `a`·x² in u.
    fn affine_field(a: f64) -> impl Fn((f64, f64), (f64, f64)) -> (f64, f64) {
        let (exx, eyy, shear, rot) = STRAIN;
        move |p, _| {
            (
                exx * p.0 + (shear - rot) * p.1 + a * p.0 * p.0,
                (shear + rot) * p.0 + eyy * p.1,
            )
        }
    }

    /// Σ(v − v̄)² of one coordinate of the points.
    fn spread(points: &[CommonPoint], coordinate: fn(&CommonPoint) -> f64) -> f64 {
        let n = points.len() as f64;
        let mean = points.iter().map(coordinate).sum::<f64>() / n;
        points.iter().map(|p| (coordinate(p) - mean).powi(2)).sum()
    }

    #[test]
    fn an_affine_field_is_read_back_as_its_strains_and_its_rotation() {
        // A quadratic 0.05 px at x = ±1280 px rides on u; the grid of `field_points` is centred
        // in x (its x̄ is the frame's centre), so it changes no slope there.
        let a = 0.05 / 1280f64.powi(2);
        let common = field_points((130.0, 0.0), affine_field(a), SIGMA, 1);
        let (sxx, syy) = (spread(&common, |p| p.x), spread(&common, |p| p.y));
        let n = common.len() as f64;
        let ybar = common.iter().map(|p| p.y).sum::<f64>() / n;
        // The affine part's RMS less its constant, and the quadratic part's, over the points.
        let (exx, eyy, shear, rot) = STRAIN;
        let affine: f64 = common
            .iter()
            .map(|p| {
                let (x, y) = (p.x - CENTRE.0, p.y - ybar);
                (exx * x + (shear - rot) * y).powi(2) + ((shear + rot) * x + eyy * y).powi(2)
            })
            .sum::<f64>();
        let quadratic: f64 = common
            .iter()
            .map(|p| (a * (p.x - CENTRE.0).powi(2)).powi(2))
            .sum();
        let run = run_comparison(("r0", "a", "native"), [130.0, 0.0], common, SIGMA * SIGMA);
        let native = Scheme::parse("native").unwrap();
        let shape = shape_of(&comparison(vec![run]), &[native], 1.0);
        let s = &shape.runs[0];
        assert_eq!((s.run.as_str(), s.pattern.as_str()), ("r0", "a"));
        // A slope's standard error is σ/√Σ(x − x̄)²; shear and rotation average two slopes.
        let (se_x, se_y) = (SIGMA / sxx.sqrt(), SIGMA / syy.sqrt());
        let se_mixed = 0.5 * (se_x.powi(2) + se_y.powi(2)).sqrt();
        for (got, truth) in s.se.iter().zip([se_x, se_y, se_mixed, se_mixed]) {
            assert!((got / truth - 1.0).abs() < 1e-9, "{got} against {truth}");
        }
        for (name, got, truth, se) in [
            ("exx", s.exx, exx, s.se[0]),
            ("eyy", s.eyy, eyy, s.se[1]),
            ("shear", s.shear, shear, s.se[2]),
            ("rotation", s.rotation, rot, s.se[3]),
        ] {
            assert!(
                (got - truth).abs() < 3.0 * se,
                "{name}: {got} ± {se} against {truth}"
            );
        }
        let (affine, quadratic) = ((affine / n).sqrt(), (quadratic / n).sqrt());
        assert!(
            (s.affine_px / affine - 1.0).abs() < 0.01,
            "{} against {affine}",
            s.affine_px
        );
        assert!(
            (s.quadratic_px - quadratic).abs() < 1e-3,
            "{} against {quadratic}",
            s.quadratic_px
        );
        assert_eq!(
            shape.grows_with_move, None,
            "one move: nothing to grow with"
        );
    }

    #[test]
    fn schemes_of_a_run_pool_in_full_resolution_px() {
        // The same field analysed in 2x2 blocks: positions and displacements in half-size px,
        // (x − 0.5)/2 and u/2 (the block's two pixels centred at 0.5). Its strains are the same
        // numbers; with the same noise in full-resolution px, two schemes halve each variance.
        let native_points = field_points((130.0, 0.0), affine_field(0.0), SIGMA, 2);
        let blocks: Vec<CommonPoint> = field_points((130.0, 0.0), affine_field(0.0), SIGMA, 3)
            .into_iter()
            .map(|p| CommonPoint {
                x: (p.x - 0.5) / 2.0,
                y: (p.y - 0.5) / 2.0,
                du: p.du / 2.0,
                dv: p.dv / 2.0,
                ..p
            })
            .collect();
        let schemes = [
            Scheme::parse("native").unwrap(),
            Scheme::parse("2x2/2x2").unwrap(),
        ];
        let alone = |points: Vec<CommonPoint>, scheme: &Scheme, var: f64| {
            let run = run_comparison(("r0", "a", &scheme.name), [130.0, 0.0], points, var);
            shape_of(&comparison(vec![run]), &schemes, 1.0).runs[0].clone()
        };
        let one = alone(native_points.clone(), &schemes[0], SIGMA * SIGMA);
        let two = alone(blocks.clone(), &schemes[1], SIGMA * SIGMA / 4.0);
        let (exx, eyy, shear, rot) = STRAIN;
        for s in [&one, &two] {
            for (got, truth, se) in [
                (s.exx, exx, s.se[0]),
                (s.eyy, eyy, s.se[1]),
                (s.shear, shear, s.se[2]),
                (s.rotation, rot, s.se[3]),
            ] {
                assert!(
                    (got - truth).abs() < 3.0 * se,
                    "{got} ± {se} against {truth}"
                );
            }
        }
        let mut first = run_comparison(("r0", "a", "native"), [130.0, 0.0], native_points, 1e-4);
        let mut second =
            run_comparison(("r0", "a", &schemes[1].name), [130.0, 0.0], blocks, 2.5e-5);
        (first.rigid_px, second.rigid_px) = (0.01, 0.03);
        let both = shape_of(&comparison(vec![first, second]), &schemes, 1.0);
        assert_eq!(both.runs.len(), 1, "one run, two schemes");
        let pooled = &both.runs[0];
        for (k, (a, b)) in one.se.iter().zip(&two.se).enumerate() {
            let truth = 1.0 / (1.0 / (a * a) + 1.0 / (b * b)).sqrt();
            assert!((pooled.se[k] / truth - 1.0).abs() < 1e-9);
            assert!(
                (pooled.se[k] / a - 0.5f64.sqrt()).abs() < 0.02,
                "{}",
                pooled.se[k] / a
            );
        }
        assert!((pooled.exx - exx).abs() < 3.0 * pooled.se[0]);
        assert_eq!(
            pooled.rigid_px, 0.03,
            "the larger rigid part of the run's schemes"
        );
    }

    #[test]
    fn strains_proportional_to_the_move_grow_with_it_and_constant_ones_do_not() {
        // A tilt's strain along x is 2a·tx: 1e-6 per px of move. A y move of another kind
        // is left out (the largest move is along x).
        let sizes = [32.5, 65.0, 130.0];
        let tilt: Vec<RunShape> = sizes
            .iter()
            .map(|&t| run_shape([t, 0.0], 2e-6 * t, 1e-6 * t, 0.0))
            .chain([run_shape([0.0, 100.0], 5e-4, 0.0, 0.0)])
            .collect();
        assert_eq!(grows_with_move(&tilt), Some(true));
        // A scale change: the same strain at every move.
        let scale: Vec<RunShape> = sizes
            .iter()
            .map(|&t| run_shape([t, 0.0], 1e-4, 1e-4, 0.0))
            .collect();
        assert_eq!(grows_with_move(&scale), Some(false));
        // Moves within a factor 1.5 of one another, or one moved run: no test.
        let close: Vec<RunShape> = [100.0, 130.0]
            .iter()
            .map(|&t| run_shape([t, 0.0], 1e-6 * t, 0.0, 0.0))
            .collect();
        assert_eq!(grows_with_move(&close), None);
        assert_eq!(grows_with_move(&tilt[2..3]), None);
        assert_eq!(grows_with_move(&[]), None);
    }

    proptest::proptest! {
        /// Strains k·|t| for any k > 0 and moves spanning a factor of two or more grow with the
        /// move, along either axis.
        #[test]
        fn any_strain_proportional_to_the_move_grows(
            k in 1e-8f64..1e-4,
            small in 3.0f64..100.0,
            ratio in 2.0f64..20.0,
            along_y in proptest::bool::ANY,
        ) {
            let runs: Vec<RunShape> = [small, small * ratio.sqrt(), small * ratio]
                .iter()
                .map(|&t| {
                    let m = if along_y { [0.0, t] } else { [t, 0.0] };
                    run_shape(m, k * t, 0.5 * k * t, 0.1 * k * t)
                })
                .collect();
            proptest::prop_assert_eq!(grows_with_move(&runs), Some(true));
        }
    }

    #[test]
    fn image_statistics_beyond_three_per_observation_are_named() {
        // spectrum 31/10 = 3.1 (named), noise 30/10 = 3.0 (not: the bound is strict), no mean map
        // observed, contrast 100/10 = 10 (named).
        let mut cmp = comparison(Vec::new());
        cmp.chi2.image_parts = [(31.0, 10), (30.0, 10), (0.0, 0), (100.0, 10), (0.0, 0)];
        let shape = shape_of(&cmp, &[], 1.0);
        let named: Vec<(&str, f64)> = shape
            .image
            .iter()
            .map(|m| (m.kind.as_str(), m.chi2_per_observation))
            .collect();
        assert_eq!(named, vec![("spectrum", 3.1), ("contrast", 10.0)]);
        assert!(shape.runs.is_empty());
    }

    #[test]
    fn the_surface_takes_the_sum_of_squares_its_terms_explain() {
        // An exact quadratic on a 5x4 grid: the surface explains all of its variance about the
        // mean, Σ(v − v̄)².
        let xy: Vec<(f64, f64)> = (0..20)
            .map(|k| ((k % 5) as f64 * 10.0, (k / 5) as f64 * 7.0))
            .collect();
        let values: Vec<f64> = xy
            .iter()
            .map(|(x, y)| 1.0 + 0.02 * x - 0.01 * y + 3e-4 * x * y + 2e-4 * x * x)
            .collect();
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        let rss0: f64 = values.iter().map(|v| (v - mean).powi(2)).sum();
        let (fit, drop) = surface(&xy, &values).unwrap();
        assert!(fit.full);
        assert!((drop / rss0 - 1.0).abs() < 1e-9, "{drop} against {rss0}");
        // Eleven points, or one row of points, hold no full quadratic surface.
        assert!(surface(&xy[..11], &values[..11]).is_none());
        let row: Vec<(f64, f64)> = (0..20).map(|k| (k as f64, 3.0)).collect();
        assert!(surface(&row, &values).is_none());
    }
}
