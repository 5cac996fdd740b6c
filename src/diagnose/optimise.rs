//! The optimisers of the fits: Brent's method (after a coarse grid), Nelder–Mead in a box, and
//! standard errors from the curvature of χ² at the minimum (σ² = 2/∂²χ²).
//!
//! Brent's method: Brent, *Algorithms for Minimization without Derivatives* (1973), ch. 5:
//! golden-section steps (Kiefer, Proc. AMS 4 (1953), the bracket shrinking by 1/φ per
//! evaluation) where a parabola through the best three points would not help, the parabola's
//! minimum where it would; each evaluation of the print's and the image fits' objectives renders
//! crops, so the evaluations it saves are the fits' time. Its precision is stated as the golden
//! section's after a number of steps ([`golden_tolerance`]).
//! Nelder & Mead, Computer J. 7 (1965), with their standard coefficients (reflection 1,
//! expansion 2, inside contraction and shrink ½) and only the inside contraction; a point
//! outside the box is clamped onto it, as Box's complex method does (Computer J. 8, 1965). The curvature's σ² = 2/∂²χ² is the 1σ interval
//! of one parameter where Δχ² = 1 (Press et al., Numerical Recipes, 3rd ed., §15.6).

/// `objective`, or +∞ without evaluating it once `stop` says so: an optimisation whose job was
/// cancelled runs its remaining steps for nothing (each one a rendering otherwise), and its
/// caller discards the result.
pub fn unless_stopped<'a>(
    objective: &'a dyn Fn(&[f64]) -> f64,
    stop: &'a dyn Fn() -> bool,
) -> impl Fn(&[f64]) -> f64 + 'a {
    move |x| {
        if stop() {
            f64::INFINITY
        } else {
            objective(x)
        }
    }
}

/// A golden-section step's fraction of the larger part of a bracket: (3 − √5)/2. Where a
/// golden section starts, and Brent's method's step where no parabola is taken.
pub const GOLDEN_STEP: f64 = 0.381_966_011_250_105;

/// The golden section's precision after `iters` steps on a bracket `width` wide, as an absolute
/// tolerance for [`brent`]. Of a unimodal function, the golden section's end lies within 0.618 of
/// its final bracket (width · 0.618^iters) from the minimum, and [`brent`]'s end within twice its
/// tolerance — half that bracket with this one: the cheaper search is no coarser.
pub fn golden_tolerance(width: f64, iters: usize) -> f64 {
    0.25 * width * 0.618_033_988_749_895f64.powi(iters as i32)
}

/// Brent's minimum of `f` on [a, b] from `start` — a point of the bracket and its value,
/// already known to the caller — to the absolute tolerance `tol` in x, with at most
/// `max_evaluations` new evaluations; returns the best point seen and its value.
///
/// Brent, *Algorithms for Minimization without Derivatives* (1973), ch. 5, `localmin`: a
/// parabola through the three best points where it falls inside the bracket and shrinks it
/// fast enough, a golden-section step otherwise. On a smooth objective it takes some half the
/// golden section's evaluations for the same precision (`tests`). An infinite or NaN value (a
/// cancelled job) fails every parabola's test and makes golden-section steps, so the search
/// still ends.
pub fn brent(
    f: &dyn Fn(f64) -> f64,
    (a, b): (f64, f64),
    start: (f64, f64),
    tol: f64,
    max_evaluations: usize,
) -> (f64, f64) {
    // √ε: below it a relative step is lost in rounding.
    let eps = f64::EPSILON.sqrt();
    let (mut a, mut b) = (a.min(b), a.max(b));
    let (mut x, mut fx) = (start.0.clamp(a, b), start.1);
    let (mut w, mut fw, mut v, mut fv) = (x, fx, x, fx);
    // The step before last (e) and the last one (d).
    let (mut d, mut e) = (0.0f64, 0.0f64);
    for _ in 0..max_evaluations {
        let m = 0.5 * (a + b);
        let tol1 = eps * x.abs() + tol;
        let tol2 = 2.0 * tol1;
        if (x - m).abs() <= tol2 - 0.5 * (b - a) {
            break;
        }
        let mut parabolic = false;
        if e.abs() > tol1 {
            let r = (x - w) * (fx - fv);
            let q = (x - v) * (fx - fw);
            let mut p = (x - v) * q - (x - w) * r;
            let mut q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            } else {
                q = -q;
            }
            // Accepted only inside the bracket and under half the step before last (else the
            // parabola is not converging).
            if p.abs() < (0.5 * q * e).abs() && p > q * (a - x) && p < q * (b - x) {
                e = d;
                d = p / q;
                let u = x + d;
                if u - a < tol2 || b - u < tol2 {
                    d = if x < m { tol1 } else { -tol1 };
                }
                parabolic = true;
            }
        }
        if !parabolic {
            e = if x < m { b - x } else { a - x };
            d = GOLDEN_STEP * e;
        }
        let u = if d.abs() >= tol1 {
            x + d
        } else {
            x + tol1.copysign(d)
        };
        let fu = f(u);
        if fu <= fx {
            if u < x {
                b = x;
            } else {
                a = x;
            }
            (v, fv, w, fw, x, fx) = (w, fw, x, fx, u, fu);
        } else {
            if u < x {
                a = u;
            } else {
                b = u;
            }
            if fu <= fw || w == x {
                (v, fv, w, fw) = (w, fw, u, fu);
            } else if fu <= fv || v == x || v == w {
                (v, fv) = (u, fu);
            }
        }
    }
    (x, fx)
}

/// The minimum of `f` on [a, b]: a coarse grid of `n` points, then [`brent`] in the best
/// point's cells from it, as precise as fourteen golden-section steps there.
pub fn minimise_1d(f: &dyn Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    let grid: Vec<(f64, f64)> = (0..n)
        .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
        .map(|x| (x, f(x)))
        .collect();
    let best = grid
        .iter()
        .enumerate()
        .min_by(|x, y| x.1 .1.total_cmp(&y.1 .1))
        .map(|(i, _)| i)
        .unwrap_or(0);
    let h = (b - a) / (n - 1) as f64;
    let (lo, hi) = ((grid[best].0 - h).max(a), (grid[best].0 + h).min(b));
    let steps = 14;
    brent(
        f,
        (lo, hi),
        grid[best],
        golden_tolerance(hi - lo, steps),
        steps + 2,
    )
    .0
}

/// Nelder–Mead in a box (points clamped), from `start` with initial steps `step`.
pub fn nelder_mead(
    f: &dyn Fn(&[f64]) -> f64,
    start: &[f64],
    step: &[f64],
    lo: &[f64],
    hi: &[f64],
    iters: usize,
) -> Vec<f64> {
    let n = start.len();
    let clamp = |x: Vec<f64>| -> Vec<f64> {
        x.iter()
            .enumerate()
            .map(|(i, v)| v.clamp(lo[i], hi[i]))
            .collect()
    };
    let mut simplex: Vec<(Vec<f64>, f64)> = Vec::new();
    let s0 = clamp(start.to_vec());
    simplex.push((s0.clone(), f(&s0)));
    for i in 0..n {
        let mut p = s0.clone();
        p[i] += step[i];
        if p[i] > hi[i] {
            p[i] = s0[i] - step[i];
        }
        let p = clamp(p);
        let v = f(&p);
        simplex.push((p, v));
    }
    for _ in 0..iters {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let centroid: Vec<f64> = (0..n)
            .map(|j| simplex[..n].iter().map(|p| p.0[j]).sum::<f64>() / n as f64)
            .collect();
        let worst = simplex[n].clone();
        let along = |t: f64| {
            clamp(
                (0..n)
                    .map(|j| centroid[j] + t * (worst.0[j] - centroid[j]))
                    .collect(),
            )
        };
        let r = along(-1.0);
        let fr = f(&r);
        if fr < simplex[0].1 {
            let e = along(-2.0);
            let fe = f(&e);
            simplex[n] = if fe < fr { (e, fe) } else { (r, fr) };
        } else if fr < simplex[n - 1].1 {
            simplex[n] = (r, fr);
        } else {
            let c = along(0.5);
            let fc = f(&c);
            if fc < worst.1 {
                simplex[n] = (c, fc);
            } else {
                let best = simplex[0].0.clone();
                for p in simplex.iter_mut().skip(1) {
                    p.0 = clamp(
                        p.0.iter()
                            .zip(&best)
                            .map(|(a, b)| b + 0.5 * (a - b))
                            .collect(),
                    );
                    p.1 = f(&p.0);
                }
            }
        }
        let spread = simplex
            .iter()
            .map(|p| (p.1 - simplex[0].1).abs())
            .fold(0.0, f64::max);
        if spread < 1e-3 {
            break;
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    simplex[0].0.clone()
}

/// Standard errors from the diagonal curvature of χ² (σ² = 2/∂²χ²), steps `h`, kept in bounds;
/// `f0` is χ² at `x`, already evaluated.
pub fn curvature_stderr(
    f: &dyn Fn(&[f64]) -> f64,
    x: &[f64],
    f0: f64,
    h: &[f64],
    lo: &[f64],
    hi: &[f64],
) -> Vec<f64> {
    (0..x.len())
        .map(|i| {
            let mut a = x.to_vec();
            let mut b = x.to_vec();
            // A one-sided stencil at a bound.
            let (da, db) = if x[i] - h[i] < lo[i] {
                (h[i], 2.0 * h[i])
            } else if x[i] + h[i] > hi[i] {
                (-h[i], -2.0 * h[i])
            } else {
                (-h[i], h[i])
            };
            a[i] += da;
            b[i] += db;
            let (fa, fb) = (f(&a), f(&b));
            let curv = if da < 0.0 && db > 0.0 {
                (fa - 2.0 * f0 + fb) / (h[i] * h[i])
            } else {
                (fb - 2.0 * fa + f0) / (h[i] * h[i])
            };
            if curv > 0.0 {
                (2.0 / curv).sqrt()
            } else {
                f64::INFINITY
            }
        })
        .collect()
}

/// Standard errors no smaller than χ² at each parameter's null allows. For each parameter farther
/// than its step `h` from `null`, χ² is evaluated with that parameter at its null and the others
/// at the fit: were χ² quadratic, its rise Δ there would be (distance/σ)², so σ is at least
/// distance/√Δ (the likelihood-ratio test's reading of the same χ²; Wilks, *Ann. Math. Stat.* 9,
/// 1938). Where Δ ≤ 0 the data cannot tell the fit from the null, and σ is the parameter's whole
/// range. The curvature alone fails on an objective that is flat but rough — a model frame's
/// noise drawn again at every trial — where its three points can read any curvature: a pixel
/// aperture fitted to a print with no power where the aperture's transfer differs from 1 read
/// fill factor 0.23 ± 0.07 against full pixels (χ² 10.7–11.5 over the whole range).
pub fn stderr_within_null_reach(
    f: &dyn Fn(&[f64]) -> f64,
    x: &[f64],
    f0: f64,
    null: &[f64],
    curvature_se: &[f64],
    h: &[f64],
    (lo, hi): (&[f64], &[f64]),
) -> Vec<f64> {
    (0..x.len())
        .map(|i| {
            let distance = (x[i] - null[i]).abs();
            if !(distance > h[i]) {
                return curvature_se[i];
            }
            let mut at_null = x.to_vec();
            at_null[i] = null[i];
            let rise = f(&at_null) - f0;
            let range = hi[i] - lo[i];
            let reach = if rise > 0.0 {
                (distance / rise.sqrt()).min(range)
            } else {
                range
            };
            curvature_se[i].max(reach)
        })
        .collect()
}

/// The factor on a fit's standard errors from χ²'s curvature when the terms scatter about the
/// fitted model more than their own errors say: √ĉ, ĉ = max(1, χ²_min/ν) with ν the degrees of
/// freedom left (quasi-likelihood: McCullagh & Nelder, *Generalized Linear Models*, 2nd ed.
/// 1989, §9.2; Birge's ratio). The same ĉ scales the verdict's image χ² ([`super::bic::image_change`]):
/// a model that cannot draw the measured spectrum, or spectra whose bins' errors are estimated
/// from eight groups of lines, would otherwise make a fit's errors smaller than the scatter of
/// its value from one print to the next. Never below 1: a χ² below its degrees of freedom is
/// chance as often as it is errors stated too large.
pub fn dispersion_factor(chi2_min: f64, dof: usize) -> f64 {
    if dof == 0 || !chi2_min.is_finite() {
        return 1.0;
    }
    (chi2_min / dof as f64).max(1.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    #[test]
    fn a_flat_rough_chi2_leaves_the_parameter_its_whole_range() {
        // Quadratic about 0.6 with σ 0.1 (null 1): the rise at the null, (0.4/0.1)² = 16, gives
        // back σ, and the curvature's σ stands.
        let quadratic = |x: &[f64]| 10.0 + ((x[0] - 0.6) / 0.1).powi(2);
        let x = [0.6];
        let f0 = quadratic(&x);
        let curv = curvature_stderr(&quadratic, &x, f0, &[0.04], &[0.05], &[1.0]);
        assert!((curv[0] - 0.1).abs() < 1e-9, "{curv:?}");
        let se = stderr_within_null_reach(
            &quadratic,
            &x,
            f0,
            &[1.0],
            &curv,
            &[0.04],
            (&[0.05], &[1.0]),
        );
        assert!((se[0] - 0.1).abs() < 1e-9, "{se:?}");
        // Flat within ±0.4 but rough: the three points of the curvature read a sharp minimum
        // (σ 0.04), yet χ² at the null is no higher than at the fit.
        let rough = |x: &[f64]| {
            10.7 + if (x[0] - 0.23).abs() < 1e-12 {
                0.0
            } else if x[0] < 0.9 {
                0.4
            } else {
                0.3
            }
        };
        let x = [0.23];
        let f0 = rough(&x);
        let curv = curvature_stderr(&rough, &x, f0, &[0.04], &[0.05], &[1.0]);
        assert!(curv[0] < 0.1, "{curv:?}");
        let se =
            stderr_within_null_reach(&rough, &x, f0, &[1.0], &curv, &[0.04], (&[0.05], &[1.0]));
        // Δ 0.3 at a distance of 0.77: σ ≥ 0.77/√0.3 = 1.41, capped at the range 0.95.
        assert!((se[0] - 0.95).abs() < 1e-12, "{se:?}");
        // A fit within its step of the null keeps the curvature's σ.
        let se = stderr_within_null_reach(
            &rough,
            &[0.98],
            f0,
            &[1.0],
            &[0.2],
            &[0.04],
            (&[0.05], &[1.0]),
        );
        assert_eq!(se, [0.2]);
    }

    /// Counts the evaluations of `f`.
    fn counted(f: impl Fn(f64) -> f64) -> (impl Fn(f64) -> f64, std::rc::Rc<Cell<usize>>) {
        let calls = std::rc::Rc::new(Cell::new(0));
        let c = calls.clone();
        (
            move |x| {
                c.set(c.get() + 1);
                f(x)
            },
            calls,
        )
    }

    #[test]
    fn brent_finds_a_parabola_in_a_few_evaluations_and_returns_its_value() {
        let (f, calls) = counted(|x: f64| (x - 0.3).powi(2) + 2.0);
        let tol = golden_tolerance(3.0, 30);
        let (x, fx) = brent(&f, (-1.0, 2.0), (-1.0, f(-1.0)), tol, 32);
        assert!((x - 0.3).abs() <= 2.0 * tol, "{x}");
        assert_eq!(fx, (x - 0.3).powi(2) + 2.0);
        // Thirty golden-section steps would take 32 evaluations; a parabola is found by
        // interpolation, then bracketed within the tolerance (the start's evaluation counted).
        assert!(calls.get() <= 12, "{} evaluations", calls.get());
    }

    #[test]
    fn brent_takes_fewer_evaluations_than_the_golden_section() {
        // Bowls with quartic flanks over the print's bracket (ln 0.25 to ln 4): 500 of them,
        // their minima, curvatures, flanks and starts spread over the bracket and four decades.
        // Twelve golden-section steps take 14 evaluations for this precision.
        let (lo, hi) = (-1.386, 1.386);
        let tol = golden_tolerance(hi - lo, 12);
        let mut total = 0;
        let mut cases = 0;
        for i in 0..5 {
            for j in 0..5 {
                for k in 0..4 {
                    for l in 0..5 {
                        let x0 = -1.3 + 2.6 * i as f64 / 4.0 + 0.01 * l as f64;
                        let curvature = 10f64.powi(j - 2);
                        let quartic = [0.0, 0.5, 3.0, 10.0][k as usize];
                        let start = lo + (hi - lo) * (0.1 + 0.2 * l as f64);
                        let bowl =
                            |x: f64| curvature * ((x - x0).powi(2) + quartic * (x - x0).powi(4));
                        let (f, calls) = counted(bowl);
                        let (x, _) = brent(&f, (lo, hi), (start, bowl(start)), tol, 14);
                        assert!((x - x0).abs() <= 2.0 * tol + 1e-9, "{x} against {x0}");
                        total += calls.get();
                        cases += 1;
                    }
                }
            }
        }
        let mean = total as f64 / cases as f64;
        assert!(mean < 10.0, "{mean} evaluations on average");
    }

    #[test]
    fn brent_stops_at_a_bound_when_the_minimum_is_beyond_it() {
        let tol = golden_tolerance(1.0, 12);
        let (x, fx) = brent(&|x: f64| x, (0.0, 1.0), (0.7, 0.7), tol, 14);
        assert!(x <= 2.0 * tol, "{x}");
        assert_eq!(fx, x);
    }

    #[test]
    fn brent_ends_on_a_cancelled_objective_at_its_start() {
        let (f, calls) = counted(|_: f64| f64::INFINITY);
        let (x, _) = brent(&f, (0.0, 1.0), (0.5, 1.0), 1e-6, 10);
        assert_eq!(x, 0.5);
        assert!(calls.get() <= 10);
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(64))]

        /// Any bowl with a quartic flank, its minimum anywhere in the bracket, from any start: found
        /// within twice the tolerance of twelve golden-section steps, in at most as many
        /// evaluations as those steps take (14).
        #[test]
        fn brent_finds_any_bowls_minimum(
            x0 in -1.3f64..1.3,
            curvature in 0.01f64..100.0,
            quartic in 0.0f64..10.0,
            start in -1.386f64..1.386,
        ) {
            let bowl = |x: f64| curvature * ((x - x0).powi(2) + quartic * (x - x0).powi(4));
            let (f, calls) = counted(bowl);
            let (lo, hi) = (-1.386, 1.386);
            let tol = golden_tolerance(hi - lo, 12);
            let (x, _) = brent(&f, (lo, hi), (start, bowl(start)), tol, 14);
            proptest::prop_assert!((x - x0).abs() <= 2.0 * tol + 1e-9, "{} against {}", x, x0);
            proptest::prop_assert!(calls.get() <= 14, "{} evaluations", calls.get());
        }

    }

    /// A χ² bowl in two dimensions (σ 1 along x, 1/√k along y), centres anywhere in the box
    /// and anisotropies up to 20, 40,000 of them drawn from a fixed seed. The simplex stops once
    /// its values agree to 1e-3 (a thousandth of a χ²'s 1σ rise), and a simplex flattened along
    /// the narrow axis can agree that well before it reaches the floor. Over 400,000 cases 37
    /// ended beyond a quarter of a standard error (χ² ≥ 1/16; 9 in 100,000) and the worst at
    /// χ² = 0.28 (0.53 σ). A property test of 64 random cases that asserted χ² < 1/16 for every
    /// one failed on a fresh clone's CI at χ² = 0.080 (a = 1.85, b = −0.30, k = 12.9): it
    /// claimed more than the stop gives. Held here: at most one case in a thousand beyond a
    /// quarter σ (ten times the measured rate) and none beyond one σ. A restart from the end
    /// would tighten it (not done: it would move the fill factor's fits).
    #[test]
    fn nelder_mead_ends_near_a_bowls_centre() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let cases = 40_000;
        let (mut beyond_quarter, mut worst) = (0usize, 0.0f64);
        for _ in 0..cases {
            let (a, b): (f64, f64) = (rng.gen_range(-2.0..2.0), rng.gen_range(-2.0..2.0));
            let k: f64 = rng.gen_range(1.0..20.0);
            let f = |x: &[f64]| (x[0] - a).powi(2) + k * (x[1] - b).powi(2);
            let x = nelder_mead(
                &f,
                &[0.0, 0.0],
                &[0.5, 0.5],
                &[-3.0, -3.0],
                &[3.0, 3.0],
                500,
            );
            let chi2 = f(&x);
            beyond_quarter += usize::from(chi2 >= 1.0 / 16.0);
            worst = worst.max(chi2);
        }
        assert!(
            beyond_quarter * 1000 <= cases,
            "{beyond_quarter} of {cases} ended beyond a quarter σ"
        );
        assert!(worst < 1.0, "the worst end: χ² = {worst}");
    }

    #[test]
    fn minimise_1d_takes_the_deeper_of_two_minima() {
        // Two minima: the grid finds the deeper one, Brent's method refines inside its bracket.
        let f = |x: f64| ((x - 0.2).powi(2)).min((x - 0.8).powi(2) - 0.01);
        let x = minimise_1d(&f, 0.0, 1.0, 11);
        assert!((x - 0.8).abs() < 1e-3, "{x}");
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(64))]

        /// χ² = Σ ((x − a)/σ)² has σ as the curvature's standard error, in the interior and, by
        /// the one-sided stencil, at either bound.
        #[test]
        fn curvature_gives_back_sigma(a in -1.0f64..1.0, sigma in 0.01f64..10.0) {
            let chi2 = |x: &[f64]| ((x[0] - a) / sigma).powi(2);
            let h = [0.1 * sigma];
            for (lo, hi) in [(-2.0, 2.0), (a, 2.0), (-2.0, a)] {
                let se = curvature_stderr(&chi2, &[a], chi2(&[a]), &h, &[lo], &[hi]);
                proptest::prop_assert!((se[0] / sigma - 1.0).abs() < 1e-6, "{} against {}", se[0], sigma);
            }
        }
    }

    /// A mean of 50 terms whose stated errors are right (×1) or half the truth (×2): over 400
    /// realisations the fitted value scatters by what the curvature's error scaled by
    /// [`dispersion_factor`] says, within 10 %; unscaled, the halved errors say half of it.
    #[test]
    fn the_dispersion_factor_makes_a_fits_error_its_scatter() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let (n, stated) = (50, 1.0);
        for truth_over_stated in [1.0, 2.0] {
            let noise = Normal::new(0.0, stated * truth_over_stated).unwrap();
            let (mut fits, mut errors, mut unscaled) = (Vec::new(), Vec::new(), Vec::new());
            for _ in 0..400 {
                let y: Vec<f64> = (0..n).map(|_| 3.0 + noise.sample(&mut rng)).collect();
                let chi2 = |x: &[f64]| y.iter().map(|v| ((v - x[0]) / stated).powi(2)).sum::<f64>();
                let a = y.iter().sum::<f64>() / n as f64;
                let f0 = chi2(&[a]);
                let se = curvature_stderr(&chi2, &[a], f0, &[0.1], &[-10.0], &[10.0])[0];
                fits.push(a);
                errors.push(se * dispersion_factor(f0, n - 1));
                unscaled.push(se);
            }
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            let m = mean(&fits);
            let scatter = (fits.iter().map(|a| (a - m).powi(2)).sum::<f64>() / 399.0).sqrt();
            let ratio = scatter / mean(&errors);
            assert!(
                (ratio - 1.0).abs() < 0.1,
                "×{truth_over_stated}: scatter/error {ratio}"
            );
            let plain = scatter / mean(&unscaled);
            assert!(
                (plain / truth_over_stated - 1.0).abs() < 0.1,
                "×{truth_over_stated}: scatter/unscaled {plain}"
            );
        }
        assert_eq!(dispersion_factor(10.0, 0), 1.0);
        assert_eq!(dispersion_factor(f64::NAN, 5), 1.0);
    }

    #[test]
    fn nelder_mead_follows_rosenbrocks_valley() {
        // The banana valley from the classic start (−1.2, 1): f(−1.2, 1) = 24.2, minimum 0 at (1, 1).
        let f = |x: &[f64]| 100.0 * (x[1] - x[0] * x[0]).powi(2) + (1.0 - x[0]).powi(2);
        let x = nelder_mead(
            &f,
            &[-1.2, 1.0],
            &[0.1, 0.1],
            &[-3.0, -3.0],
            &[3.0, 3.0],
            2000,
        );
        // The simplex stops once its values agree to 1e-3, somewhere on the valley's floor near
        // the minimum: f below that spread, not the exact point.
        assert!(f(&x) < 1e-2, "f = {} at {x:?}", f(&x));
        assert!(
            (x[0] - 1.0).abs() < 0.1 && (x[1] - 1.0).abs() < 0.2,
            "{x:?}"
        );
    }

    #[test]
    fn nelder_mead_stops_at_a_bound_when_the_minimum_is_beyond_it() {
        // The unconstrained minimum (2, 0.5) lies beyond x ≤ 1: the box's answer is (1, 0.5).
        let f = |x: &[f64]| (x[0] - 2.0).powi(2) + (x[1] - 0.5).powi(2);
        let x = nelder_mead(
            &f,
            &[0.0, 0.0],
            &[0.3, 0.3],
            &[-1.0, -1.0],
            &[1.0, 1.0],
            500,
        );
        assert!(x.iter().zip([-1.0, -1.0]).all(|(v, lo)| *v >= lo));
        assert!(x.iter().zip([1.0, 1.0]).all(|(v, hi)| *v <= hi));
        assert!(
            (x[0] - 1.0).abs() < 0.03 && (x[1] - 0.5).abs() < 0.05,
            "{x:?}"
        );
    }

    #[test]
    fn a_stopped_objective_is_not_evaluated() {
        let calls = Cell::new(0);
        let f = |_: &[f64]| {
            calls.set(calls.get() + 1);
            1.0
        };
        let stopped = Cell::new(false);
        let stop = || stopped.get();
        let g = unless_stopped(&f, &stop);
        assert_eq!(g(&[0.0]), 1.0);
        stopped.set(true);
        assert_eq!(g(&[0.0]), f64::INFINITY);
        assert_eq!(calls.get(), 1);
    }
}
