//! The paper's findings (Hijazi, Rawashdeh & Kähler, § 4) tested on a study with repeated
//! captures: each finding becomes a difference with a 95 % t interval over the captures, and a
//! verdict — it holds, it is contradicted, or this bench cannot resolve it. Differences within
//! one pattern are paired per capture (one pair of frames reduced twice); differences between
//! patterns compare independent captures (Welch's t, Satterthwaite's degrees of freedom, rounded
//! down: conservative).

use super::rows::{Increase, StudyRow};
use crate::stats::{mean_and_variance_of_mean, mean_interval, t_975};
use serde::Serialize;

/// What the interval says about a finding.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    Holds,
    Contradicted,
    NotResolved,
}

/// One tested statement.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Finding {
    /// The paper's statement.
    pub claim: String,
    /// The difference tested, in words.
    pub measure: String,
    pub mean: f64,
    pub ci95: [f64; 2],
    /// Captures behind each side.
    pub captures: usize,
    pub verdict: Verdict,
}

/// The paper's findings on `captures` (every capture's own rows, `results/captures.json`):
/// those whose patterns and schemes the study holds, with at least two captures each.
pub fn paper_findings(captures: &[StudyRow]) -> Vec<Finding> {
    let c = Captures(captures);
    let mut out = Findings(Vec::new());
    fill_factor_effects(&c, &mut out);
    // "speckle (b) shows the largest fill factor dependence" (x: +13.2 % displacement,
    // +19.8 % strain).
    for other in ["a", "c"] {
        for (name, f) in [("u", U), ("exx", EXX)] {
            let x = welch(&c.increase("b", "ff25", f), &c.increase(other, "ff25", f));
            out.push(
                "pattern b shows the largest fill-factor dependence",
                format!("b minus {other}, ff25 increase of std {name} [points]"),
                x,
                above(x.1, 0.0),
            );
        }
    }
    // Figure 6: the sub-pixel y component is affected more than the x translation.
    for p in ["b", "c"] {
        for ((nx, fx), (ny, fy)) in [(("u", U), ("v", V)), (("exx", EXX), ("eyy", EYY))] {
            let x = paired(&c.increase(p, "ff25", fy), &c.increase(p, "ff25", fx));
            out.push(
                "the sub-pixel y component is affected more than the x move",
                format!("{p} ff25: increase of std {ny} minus that of std {nx} [points]"),
                x,
                above(x.1, 0.0),
            );
        }
    }
    // "the most significant increase in error occurs with the 25 % fill factor images".
    for p in ["b", "c"] {
        for (name, f) in [("u", U), ("v", V)] {
            let x = paired(&c.increase(p, "ff25", f), &c.increase(p, "ff50", f));
            out.push(
                "the largest increase is at 25 %",
                format!("{p}: ff25 minus ff50 increase of std {name} [points]"),
                x,
                above(x.1, 0.0),
            );
        }
    }
    // "speckle (a) consistently shows the lowest magnitude of strain error".
    for other in ["b", "c"] {
        for scheme in ["ff100", "ff50", "ff25"] {
            let exx_std: fn(&StudyRow) -> f64 = |r| 1e6 * r.summary.exx.std;
            let x = welch(&c.std(other, scheme, exx_std), &c.std("a", scheme, exx_std));
            out.push(
                "pattern a has the lowest strain error",
                format!("{other} minus a, {scheme} std exx [µε]"),
                x,
                above(x.1, 0.0),
            );
        }
    }
    out.0
}

/// § 4: "for speckle (a) the fill factor has no effect on the error" (read as within ±5 %); "for
/// speckles (b) and (c), the fill factor has some effect".
fn fill_factor_effects(c: &Captures<'_>, out: &mut Findings) {
    for scheme in ["ff50", "ff25"] {
        for (name, f) in [("u", U), ("exx", EXX)] {
            let x = summary(&c.increase("a", scheme, f));
            out.push(
                "pattern a: the fill factor has no effect (within ±5 %)",
                format!("a {scheme} increase of std {name} [%]"),
                x,
                within(x.1, 5.0),
            );
        }
        for p in ["b", "c"] {
            for (name, f) in [("u", U), ("v", V), ("exx", EXX), ("eyy", EYY)] {
                let x = summary(&c.increase(p, scheme, f));
                out.push(
                    "patterns b and c: the error grows at a lower fill factor",
                    format!("{p} {scheme} increase of std {name} [%]"),
                    x,
                    above(x.1, 0.0),
                );
            }
        }
    }
}

/// Which part of a row's increase over ff100 a finding reads.
const U: fn(&Increase) -> f64 = |i| i.u;
const V: fn(&Increase) -> f64 = |i| i.v;
const EXX: fn(&Increase) -> f64 = |i| i.exx;
const EYY: fn(&Increase) -> f64 = |i| i.eyy;

/// Every capture's rows.
struct Captures<'a>(&'a [StudyRow]);

impl Captures<'_> {
    fn rows<'r>(&'r self, pattern: &'r str, scheme: &'r str) -> impl Iterator<Item = &'r StudyRow> {
        self.0
            .iter()
            .filter(move |r| r.pattern == pattern && r.scheme == scheme)
    }

    /// One capture's increase (`f` of it) per capture of `pattern` with `scheme`.
    fn increase(&self, pattern: &str, scheme: &str, f: fn(&Increase) -> f64) -> Vec<f64> {
        self.rows(pattern, scheme)
            .filter_map(|r| r.increase_pct.as_ref().map(f))
            .collect()
    }

    /// `f` of each capture's row of `pattern` with `scheme`.
    fn std(&self, pattern: &str, scheme: &str, f: fn(&StudyRow) -> f64) -> Vec<f64> {
        self.rows(pattern, scheme).map(f).collect()
    }
}

/// The findings made so far: one is kept when at least two captures stand behind it and its
/// interval is finite.
struct Findings(Vec<Finding>);

impl Findings {
    fn push(&mut self, claim: &str, measure: String, xs: (f64, [f64; 2], usize), verdict: Verdict) {
        let (mean, ci95, n) = xs;
        if n >= 2 && ci95.iter().all(|x| x.is_finite()) {
            self.0.push(Finding {
                claim: claim.to_string(),
                measure,
                mean,
                ci95,
                captures: n,
                verdict,
            });
        }
    }
}

fn summary(xs: &[f64]) -> (f64, [f64; 2], usize) {
    let (m, ci) = mean_interval(xs);
    (m, ci, xs.len())
}

/// The mean difference of two paired samples, with its t interval.
fn paired(a: &[f64], b: &[f64]) -> (f64, [f64; 2], usize) {
    if a.len() != b.len() {
        return (f64::NAN, [f64::NAN; 2], 0);
    }
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    summary(&d)
}

/// The difference of the means of two independent samples with Welch's interval.
fn welch(a: &[f64], b: &[f64]) -> (f64, [f64; 2], usize) {
    let n = a.len().min(b.len());
    if n < 2 {
        return (f64::NAN, [f64::NAN; 2], 0);
    }
    let ((ma, sa), (mb, sb)) = (mean_and_variance_of_mean(a), mean_and_variance_of_mean(b));
    let se2 = sa + sb;
    let df = se2 * se2
        / (sa * sa / (a.len() - 1) as f64 + sb * sb / (b.len() - 1) as f64).max(f64::MIN_POSITIVE);
    let half = t_975((df.floor() as usize).max(1)) * se2.sqrt();
    let d = ma - mb;
    (d, [d - half, d + half], n)
}

/// Holds when the whole interval is above `x`, contradicted when it is all below.
fn above([lo, hi]: [f64; 2], x: f64) -> Verdict {
    if lo > x {
        Verdict::Holds
    } else if hi < x {
        Verdict::Contradicted
    } else {
        Verdict::NotResolved
    }
}

/// Holds when the interval lies within ±`tolerance`, contradicted when it lies outside.
fn within([lo, hi]: [f64; 2], tolerance: f64) -> Verdict {
    if lo >= -tolerance && hi <= tolerance {
        Verdict::Holds
    } else if lo > tolerance || hi < -tolerance {
        Verdict::Contradicted
    } else {
        Verdict::NotResolved
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verdicts_follow_the_interval() {
        assert_eq!(above([1.0, 2.0], 0.0), Verdict::Holds);
        assert_eq!(above([-2.0, -1.0], 0.0), Verdict::Contradicted);
        assert_eq!(above([-1.0, 1.0], 0.0), Verdict::NotResolved);
        assert_eq!(within([-4.0, 4.0], 5.0), Verdict::Holds);
        assert_eq!(within([6.0, 9.0], 5.0), Verdict::Contradicted);
        assert_eq!(within([3.0, 9.0], 5.0), Verdict::NotResolved);
    }

    /// Welch's interval against a hand computation: a = (1, 2, 3), b = (2, 4, 6, 8):
    /// means 2 and 5, variances of the means 1/3 and 20/12; se² = 2; df = 4 / (1/18 + 25/27)
    /// = 4.08 → 4, t = 2.7764.
    #[test]
    fn welch_by_hand() {
        let (d, [lo, hi], _) = welch(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.0, 8.0]);
        assert!((d + 3.0).abs() < 1e-12);
        let half = 2.7764 * 2f64.sqrt();
        assert!((lo - (-3.0 - half)).abs() < 1e-9 && (hi - (-3.0 + half)).abs() < 1e-9);
    }
}
