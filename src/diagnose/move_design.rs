//! The moves a bench adds to a dataset so that the geometric effects it left confounded leave
//! different fields (issue 33: "the experiment design that makes their signatures most different
//! for the fewest moves"). A geometric effect's signature over a set of translations is its basis
//! field ([`super::basis`]) at every point the DIC sees, each run's constant part removed (the
//! comparison fits every run's landing). Two effects are told apart as well as their signatures'
//! largest canonical correlation ρ allows (Hotelling 1936): fitted together, a parameter's
//! variance grows by 1/(1 − ρ²) over its fit alone. The design is greedy, as sequential optimal
//! designs are (Atkinson, Donev & Tobias, "Optimum Experimental Designs", 2007, ch. 11): from a
//! menu of moves (±x and ±y at a quarter, half and all of the dataset's largest move) it adds the
//! move that best meets the identifiability rules still unmet, then lowers ρ the most, smaller
//! moves first among equals, until the rules hold and every pair's variance inflation is at most
//! [`MAX_VARIANCE_INFLATION`], or a move no longer helps.

use super::basis::{geometric_basis, GeometricParam};
use super::geometric::{Geometric, Terms};
use super::identifiability::Confounded;
use super::separating_runs::SeparatingRuns;
use crate::model::EffectId;
use nalgebra::DMatrix;
use serde::Serialize;

/// The variance inflation a designed pair may keep: each parameter's standard error at most
/// √2 of its own fit's.
pub const MAX_VARIANCE_INFLATION: f64 = 2.0;

/// Most moves a design adds.
pub const MAX_DESIGNED_MOVES: usize = 8;

/// Points per side of the grid the signatures are sampled on.
const GRID_POINTS_PER_SIDE: usize = 32;

/// Two geometric effects and how alike their signatures are under the dataset's moves and with
/// the designed ones.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DesignedPair {
    pub effects: [EffectId; 2],
    /// Largest canonical correlation of their signatures: the dataset's moves alone.
    pub correlation_before: f64,
    /// With the designed moves.
    pub correlation_after: f64,
}

/// The designed moves (full-resolution px, in the order chosen) and what they do to each pair.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MoveDesign {
    pub moves_px: Vec<(f64, f64)>,
    pub pairs: Vec<DesignedPair>,
}

/// What the added moves must supply besides lowering the correlations: the identifiability rules'
/// run kinds (`identifiability.rs`).
#[derive(Clone, Copy, Debug, Default)]
pub struct MoveRules {
    /// Translations of two sizes at least 1.5 apart.
    pub several_sizes: bool,
    /// Translations along x and along y.
    pub both_axes: bool,
}

/// The fields an effect's first fit frees ([`Geometric::terms`]: all of a joint effect's, a
/// nested effect's first group).
fn leading_terms(g: Geometric) -> &'static [GeometricParam] {
    match g.terms() {
        Terms::Joint(terms) => terms,
        Terms::Nested(groups) => groups.first().copied().unwrap_or(&[]),
    }
}

/// The signature of `terms` over `moves_px` on a `frame` (width, height px): one column per term,
/// two rows (u, v) per point seen in both frames of a run, each run's mean removed.
fn signature(terms: &[GeometricParam], moves_px: &[(f64, f64)], frame: (f64, f64)) -> DMatrix<f64> {
    let r0 = 0.5 * frame.0.hypot(frame.1);
    let mut rows: Vec<Vec<f64>> = Vec::new();
    for &t in moves_px {
        let inside = |x: f64, y: f64| x.abs() < 0.5 * frame.0 && y.abs() < 0.5 * frame.1;
        let n = GRID_POINTS_PER_SIDE;
        let points: Vec<(f64, f64)> = (0..n * n)
            .map(|k| {
                let (i, j) = ((k % n) as f64 + 0.5, (k / n) as f64 + 0.5);
                (
                    (i / n as f64 - 0.5) * frame.0,
                    (j / n as f64 - 0.5) * frame.1,
                )
            })
            .filter(|&(x, y)| inside(x + t.0, y + t.1))
            .collect();
        let mut run: Vec<Vec<f64>> = vec![Vec::new(); 2 * points.len()];
        for &term in terms {
            let field: Vec<(f64, f64)> = points
                .iter()
                .map(|&p| geometric_basis(term, p, t, r0))
                .collect();
            let m = points.len().max(1) as f64;
            let (mu, mv) = field
                .iter()
                .fold((0.0, 0.0), |(a, b), f| (a + f.0 / m, b + f.1 / m));
            for (k, f) in field.iter().enumerate() {
                run[2 * k].push(f.0 - mu);
                run[2 * k + 1].push(f.1 - mv);
            }
        }
        rows.extend(run);
    }
    DMatrix::from_fn(rows.len(), terms.len(), |i, j| rows[i][j])
}

/// The orthonormal basis of `m`'s columns that carry a field (a column without one, a term the
/// moves cannot see, is left out).
fn column_space(m: DMatrix<f64>) -> Option<DMatrix<f64>> {
    let keep: Vec<usize> = (0..m.ncols())
        .filter(|&j| m.column(j).norm() > 1e-9 * (1.0 + m.norm()))
        .collect();
    if keep.is_empty() || m.nrows() < keep.len() {
        return None;
    }
    Some(m.select_columns(&keep).qr().q())
}

/// The largest canonical correlation between the signatures of `a` and `b` over `moves_px`
/// (0 when either leaves no field).
pub fn signature_correlation(
    a: Geometric,
    b: Geometric,
    moves_px: &[(f64, f64)],
    frame: (f64, f64),
) -> f64 {
    terms_correlation(leading_terms(a), leading_terms(b), moves_px, frame)
}

/// [`signature_correlation`] of two sets of basis fields.
fn terms_correlation(
    a: &[GeometricParam],
    b: &[GeometricParam],
    moves_px: &[(f64, f64)],
    frame: (f64, f64),
) -> f64 {
    let (Some(qa), Some(qb)) = (
        column_space(signature(a, moves_px, frame)),
        column_space(signature(b, moves_px, frame)),
    ) else {
        return 0.0;
    };
    (qa.transpose() * qb)
        .singular_values()
        .iter()
        .copied()
        .fold(0.0, f64::max)
        .min(1.0)
}

/// How many of `rules` the moves leave unmet (`identifiability.rs`'s thresholds: sizes distinct
/// by 5 %, the largest at least 1.5 times the smallest above 2 px).
fn unmet(rules: MoveRules, moves_px: &[(f64, f64)]) -> usize {
    let sizes: Vec<f64> = moves_px
        .iter()
        .map(|m| m.0.hypot(m.1))
        .filter(|s| *s > 2.0)
        .collect();
    let (small, large) = sizes.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), s| {
        (lo.min(*s), hi.max(*s))
    });
    let sizes_ok = large >= 1.5 * small;
    let along = |axis: usize| {
        moves_px.iter().any(|m| {
            let (a, b) = if axis == 0 { (m.0, m.1) } else { (m.1, m.0) };
            a.abs() > 1e-9 && b.abs() <= 1e-9 * a.abs().max(1.0)
        })
    };
    usize::from(rules.several_sizes && !sizes_ok)
        + usize::from(rules.both_axes && !(along(0) && along(1)))
}

/// The largest correlation over `pairs` with `moves_px`.
fn worst(pairs: &[[Geometric; 2]], moves_px: &[(f64, f64)], frame: (f64, f64)) -> f64 {
    pairs
        .iter()
        .map(|[a, b]| signature_correlation(*a, *b, moves_px, frame))
        .fold(0.0, f64::max)
}

/// The moves to add to a dataset whose runs moved by `existing_px` (full-resolution px) on a
/// `frame` (width, height px), chosen from `menu_px`, so that `rules` hold and the signatures of
/// `pairs` differ (see the module's comment).
pub fn design_moves(
    existing_px: &[(f64, f64)],
    menu_px: &[(f64, f64)],
    pairs: &[[Geometric; 2]],
    rules: MoveRules,
    frame: (f64, f64),
) -> MoveDesign {
    let target = (1.0 - 1.0 / MAX_VARIANCE_INFLATION).sqrt();
    let mut moves: Vec<(f64, f64)> = existing_px.to_vec();
    let mut chosen: Vec<(f64, f64)> = Vec::new();
    while chosen.len() < MAX_DESIGNED_MOVES {
        let now = (unmet(rules, &moves), worst(pairs, &moves, frame));
        if now.0 == 0 && now.1 <= target {
            break;
        }
        let score = |m: &(f64, f64)| {
            let mut trial = moves.clone();
            trial.push(*m);
            (
                unmet(rules, &trial),
                worst(pairs, &trial, frame),
                m.0.hypot(m.1),
            )
        };
        let best = menu_px
            .iter()
            .filter(|m| !chosen.contains(m))
            .map(|m| (score(m), *m))
            .min_by(|(a, _), (b, _)| {
                a.0.cmp(&b.0)
                    .then(a.1.total_cmp(&b.1))
                    .then(a.2.total_cmp(&b.2))
            });
        let Some(((rules_left, correlation, _), m)) = best else {
            break;
        };
        if rules_left == now.0 && correlation > now.1 - 1e-3 {
            break;
        }
        moves.push(m);
        chosen.push(m);
    }
    MoveDesign {
        pairs: pairs
            .iter()
            .map(|[a, b]| DesignedPair {
                effects: [a.effect(), b.effect()],
                correlation_before: signature_correlation(*a, *b, existing_px, frame),
                correlation_after: signature_correlation(*a, *b, &moves, frame),
            })
            .collect(),
        moves_px: chosen,
    }
}

/// [`design_moves`] for what a diagnosis left open: its confounded pairs whose two sides are
/// geometric effects (by the design or by the data), and the rules `runs` asks for.
pub fn design_for(
    confounded: &[Confounded],
    runs: &[SeparatingRuns],
    existing_px: &[(f64, f64)],
    menu_px: &[(f64, f64)],
    frame: (f64, f64),
) -> MoveDesign {
    let pairs: Vec<[Geometric; 2]> = confounded.iter().filter_map(Geometric::pair_of).collect();
    let rules = MoveRules {
        several_sizes: runs.contains(&SeparatingRuns::SeveralMoveSizes),
        both_axes: runs.contains(&SeparatingRuns::BothAxes),
    };
    design_moves(existing_px, menu_px, &pairs, rules, frame)
}

#[cfg(test)]
mod tests {
    use super::*;

    const FRAME: (f64, f64) = (640.0, 540.0);

    fn menu(largest: f64) -> Vec<(f64, f64)> {
        [0.25, 0.5, 1.0]
            .iter()
            .flat_map(|s| {
                let d = s * largest;
                [(d, 0.0), (-d, 0.0), (0.0, d), (0.0, -d)]
            })
            .collect()
    }

    /// A field is perfectly like itself and, once the runs' landings are removed, a rotation's
    /// is unlike a scale change's on a centred frame (the one is the other turned by 90°).
    #[test]
    fn correlations_are_those_of_the_fields() {
        let moves = [(65.0, 0.0)];
        let same = signature_correlation(Geometric::Scale, Geometric::Scale, &moves, FRAME);
        assert!((same - 1.0).abs() < 1e-9, "{same}");
        let r = signature_correlation(Geometric::Rotation, Geometric::Scale, &moves, FRAME);
        assert!(r < 0.05, "{r}");
    }

    /// A tilt's field under one x move is close to a scale change's (ρ ≈ 0.95: εxx ≈ 2 εyy
    /// against an isotropic strain); the tilt's strain changes sign with the move and a scale
    /// change's does not, so the one move back the other way separates them.
    #[test]
    fn a_tilt_and_a_scale_change_are_separated_by_the_move_back() {
        let pair = [[Geometric::TargetTilt, Geometric::Scale]];
        let d = design_moves(
            &[(65.0, 0.0)],
            &menu(65.0),
            &pair,
            MoveRules::default(),
            FRAME,
        );
        let p = &d.pairs[0];
        eprintln!("tilt against scale: {p:?}, moves {:?}", d.moves_px);
        assert!(p.correlation_before > 0.9, "{p:?}");
        assert!(p.correlation_after <= (0.5f64).sqrt(), "{p:?}");
        assert_eq!(d.moves_px, vec![(-65.0, 0.0)]);
    }

    /// Decentring distortion (p1, p2) and a tilt (both slopes) leave nearly the same fields
    /// under translations, even ±x and ±y at two sizes (docs/calibration.md): translations
    /// separate them only through the noise's strength.
    #[test]
    fn a_tilt_and_decentring_stay_alike_under_translations() {
        use GeometricParam as P;
        let tilt = [P::TiltSlopeY, P::TiltSlopeX];
        let decentring = [P::DistortionP1, P::DistortionP2];
        let plan: Vec<(f64, f64)> = std::iter::once((65.0, 0.0))
            .chain(menu(65.0).into_iter().filter(|m| m.0.hypot(m.1) != 32.5))
            .collect();
        let x_only = terms_correlation(&tilt, &decentring, &[(65.0, 0.0)], FRAME);
        let both = terms_correlation(&tilt, &decentring, &plan, FRAME);
        eprintln!("tilt against decentring: x only {x_only:.4}, ±x ±y at two sizes {both:.4}");
        assert!(x_only > 0.95 && both > 0.9, "{x_only} {both}");
    }

    /// Distortion and scale already differ under one move (the landing removed, a k1 field is
    /// quadratic over the frame, a scale change linear): only the rule's second size is added,
    /// the smallest move that meets it.
    #[test]
    fn the_rules_are_met_with_the_fewest_moves() {
        let pair = [[Geometric::LensDistortion, Geometric::Scale]];
        let rules = MoveRules {
            several_sizes: true,
            both_axes: false,
        };
        let d = design_moves(&[(65.0, 0.0)], &menu(65.0), &pair, rules, FRAME);
        eprintln!("distortion against scale: {d:?}");
        assert_eq!(d.moves_px.len(), 1, "{d:?}");
        assert_eq!(unmet(rules, &[(65.0, 0.0), d.moves_px[0]]), 0);
        assert!(d.pairs[0].correlation_before < 0.1, "{d:?}");
        // Nothing asked, nothing confounded: no move.
        let none = design_moves(
            &[(65.0, 0.0)],
            &menu(65.0),
            &[],
            MoveRules::default(),
            FRAME,
        );
        assert!(none.moves_px.is_empty());
    }
}
