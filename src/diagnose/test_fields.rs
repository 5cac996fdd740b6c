//! Synthetic DIC results for the module's unit tests: a grid of valid points whose displacements a
//! function gives, plus Gaussian noise of a chosen σ — an analysis whose truth is known without
//! rendering or correlating anything, so a step is tested apart from the engine and the model.

use super::discrepancy::{CommonPoint, DiscrepancyErrors, RunDiscrepancy};
use super::fit_geometric::FieldSample;
use super::image_stats::{FrameStats, MeanMap};
use super::measurement::Measurement;
use super::nominal::Nominal;
use super::residual_shape::{RunShape, Shape};
use super::residuals::ResidualMap;
use super::results::{Chi2, Comparison, DiscrepancyParts, ModelInfo, RunComparison, Side};
use super::unexplained::Unexplained;
use super::verdict::{Candidate, Criteria, Diagnosis, Evidence, Method};
use super::CompareOptions;
use crate::dataset::Manifest;
use crate::dic::{DicResult, DicSettings, PoiGrid, PoiResult, PoiStatus, Summary};
use crate::model::{CandidateId, Effects};
use crate::reduce::Scheme;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// An analysis of a `width`×`height` frame at `settings`' grid whose every point moved by
/// `field(x, y)` (px of that frame) plus independent noise of σ `noise_px` per component.
pub(super) fn synthetic_result(
    (width, height): (usize, usize),
    settings: &DicSettings,
    field: impl Fn(f64, f64) -> (f64, f64),
    noise_px: f64,
    seed: u64,
) -> DicResult {
    let grid = PoiGrid::new(settings, width, height).expect("a frame larger than a subset");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, noise_px).expect("a finite σ");
    let mut points = Vec::with_capacity(grid.xs.len() * grid.ys.len());
    for &y in &grid.ys {
        for &x in &grid.xs {
            let (x, y) = (x as f64, y as f64);
            let (u, v) = field(x, y);
            let mut p = PoiResult::invalid(x, y, PoiStatus::Converged, 1.0, 1);
            p.u = u + noise.sample(&mut rng);
            p.v = v + noise.sample(&mut rng);
            points.push(p);
        }
    }
    DicResult {
        settings: settings.clone(),
        summary: Summary::of(&points),
        grid,
        points,
        global_offset_px: (0, 0),
        strain_gauge_px: settings.strain_gauge_px(),
    }
}

/// A manifest at 26 px/mm whose runs move by `moves_mm`, run i of pattern `patterns[i % len]`;
/// `known_dots` states every print's dot size.
/// What a test manifest states of its prints.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum PrintStated {
    /// The label only: the print is estimated from the frames.
    Nothing,
    /// The dots' diameter and spacing: the rest is calibrated from the frames.
    DotSize,
    /// Profile, diameter, spacing and contrast: characterised (`print::characterised`).
    Characterised,
}

pub(super) fn manifest(moves_mm: &[(f64, f64)], patterns: &[&str], print: PrintStated) -> Manifest {
    let runs: Vec<_> = moves_mm
        .iter()
        .enumerate()
        .map(|(i, (dx, dy))| {
            let label = patterns[i % patterns.len()];
            let pattern = match print {
                PrintStated::Nothing => serde_json::json!({"label": label}),
                PrintStated::DotSize => {
                    serde_json::json!({"label": label, "dot_diameter_mm": 0.5, "dot_spacing_mm": 1.0})
                }
                PrintStated::Characterised => serde_json::json!({"label": label,
                    "dot_diameter_mm": 0.5, "dot_spacing_mm": 1.0, "contrast": 0.6,
                    "profile": "gaussian"}),
            };
            serde_json::json!({"id": format!("r{i}"), "pattern": pattern,
                "reference": format!("ref_{label}.tif"), "deformed": format!("def{i}.tif"),
                "stage": {"dx_mm": dx, "dy_mm": dy}})
        })
        .collect();
    serde_json::from_value(serde_json::json!({"format": crate::dataset::FORMAT,
        "name": "synthetic", "scale_px_per_mm": 26.0, "runs": runs}))
    .expect("a valid manifest")
}

/// Field differences (measured − model, px) on a grid of a 2560x2160 frame every 64 px, of a run
/// that moved by `move_px`: `field(p, t)` at p (px from the centre), plus noise of σ `noise_px`.
pub(super) fn field_points(
    move_px: (f64, f64),
    field: impl Fn((f64, f64), (f64, f64)) -> (f64, f64),
    noise_px: f64,
    seed: u64,
) -> Vec<CommonPoint> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, noise_px).expect("a finite σ");
    let mut points = Vec::new();
    for (row, y) in (32..2160).step_by(64).enumerate() {
        for (col, x) in (32..2560).step_by(64).enumerate() {
            let (x, y) = (x as f64, y as f64);
            let (du, dv) = field((x - 1280.0, y - 1080.0), move_px);
            points.push(CommonPoint {
                index: row * 40 + col,
                x,
                y,
                du: du + noise.sample(&mut rng),
                dv: dv + noise.sample(&mut rng),
                fit_du: 0.0,
                fit_dv: 0.0,
            });
        }
    }
    points
}

/// The frame of [`field_points`]: 2560x2160 px, its centre and half diagonal (distortion's r0).
pub(super) const FRAME: (f64, f64) = (2560.0, 2160.0);
pub(super) const CENTRE: (f64, f64) = (1280.0, 1080.0);

/// The distortion's normalising radius of [`FRAME`]: its half diagonal, px.
pub(super) fn half_diagonal() -> f64 {
    CENTRE.0.hypot(CENTRE.1)
}

/// Brown's radial distortion about `c` (px from the image centre; Brown, Photogramm. Eng. 32
/// (1966)): an ideal point q is imaged at q + D(q), D(q) = (q − c)·(k1·r² + k2·r⁴),
/// r = |q − c|/r0 ([`half_diagonal`]).
fn brown(q: (f64, f64), c: (f64, f64), (k1, k2): (f64, f64)) -> (f64, f64) {
    let (x, y) = (q.0 - c.0, q.1 - c.1);
    let r2 = (x * x + y * y) / half_diagonal().powi(2);
    let f = k1 * r2 + k2 * r2 * r2;
    (x * f, y * f)
}

/// The field a move `t` leaves at the image position p (px from the centre) where the lens has
/// [`brown`]'s distortion and the model none: the ideal point imaged there is q, p = q + D(q)
/// (fixed-point steps until they move it by less than 1e-12 px); after the move it is imaged
/// at q + t + D(q + t), so the displacement at p exceeds t by D(q + t) − D(q).
pub(super) fn lens_field(p: (f64, f64), t: (f64, f64), c: (f64, f64), k: (f64, f64)) -> (f64, f64) {
    let mut q = p;
    for _ in 0..200 {
        let d = brown(q, c, k);
        let next = (p.0 - d.0, p.1 - d.1);
        let moved = (next.0 - q.0).hypot(next.1 - q.1);
        q = next;
        if moved < 1e-12 {
            break;
        }
    }
    let (a, b) = (brown((q.0 + t.0, q.1 + t.1), c, k), brown(q, c, k));
    (a.0 - b.0, a.1 - b.1)
}

/// A run's field difference as the geometric fits read it: on [`FRAME`], noise variance
/// `var_px2` per component, uncorrelated points, the run its own pattern.
pub(super) fn field_sample<'a>(
    scheme: &'a Scheme,
    points: &'a [CommonPoint],
    move_px: (f64, f64),
    var_px2: f64,
    run: usize,
) -> FieldSample<'a> {
    FieldSample {
        scheme,
        move_px,
        centre: CENTRE,
        r0: half_diagonal(),
        points,
        var: (var_px2, var_px2),
        inflation: 1.0,
        pattern: run,
        run,
    }
}

/// The field differences of runs moved by `moves` ([`field_points`]), run k's noise drawn from
/// seed `seed + k`.
pub(super) fn field_runs(
    moves: &[(f64, f64)],
    field: impl Fn((f64, f64), (f64, f64)) -> (f64, f64) + Copy,
    noise_px: f64,
    seed: u64,
) -> Vec<Vec<CommonPoint>> {
    moves
        .iter()
        .enumerate()
        .map(|(k, &t)| field_points(t, field, noise_px, seed + k as u64))
        .collect()
}

/// [`field_sample`] of every run: run k moved by `moves[k]`, its field difference `points[k]`.
pub(super) fn run_samples<'a>(
    scheme: &'a Scheme,
    moves: &[(f64, f64)],
    points: &'a [Vec<CommonPoint>],
    var_px2: f64,
) -> Vec<FieldSample<'a>> {
    moves
        .iter()
        .zip(points)
        .enumerate()
        .map(|(k, (&t, p))| field_sample(scheme, p, t, var_px2, k))
        .collect()
}

/// A run's shape with only its move and strains set (no rotation, errors of 1e-6).
pub(super) fn run_shape(move_px: [f64; 2], exx: f64, eyy: f64, shear: f64) -> RunShape {
    RunShape {
        run: format!("{move_px:?}"),
        pattern: "a".into(),
        move_px,
        exx,
        eyy,
        shear,
        rotation: 0.0,
        se: [1e-6; 4],
        quadratic_px: 0.0,
        affine_px: 0.0,
        rigid_px: 0.0,
    }
}

/// The nominal experiment of [`FRAME`] at 12 bits and 26 px/mm (as [`manifest`]): the stage as
/// commanded (no misalignment, travel scale 1, no landing), no pattern.
pub(super) fn nominal() -> Nominal {
    Nominal {
        width: FRAME.0 as usize,
        height: FRAME.1 as usize,
        bit_depth: 12,
        scale_px_per_mm: 26.0,
        noise_floor_dn: 2.0,
        misalignment_rad: 0.0,
        travel_scale: 1.0,
        stage: Default::default(),
        patterns: Vec::new(),
    }
}

/// A measurement of `manifest` on [`FRAME`] analysed in `schemes` (names as `Scheme::parse`
/// takes them), with nothing read: no frames, statistics or analyses.
pub(super) fn measurement(manifest: Manifest, schemes: &[&str]) -> Measurement {
    let mut labels: Vec<String> = Vec::new();
    let pattern_of_run = manifest
        .runs
        .iter()
        .map(|r| {
            let label = r.pattern.as_ref().map_or("", |p| p.label.as_str());
            labels.iter().position(|l| l == label).unwrap_or_else(|| {
                labels.push(label.to_string());
                labels.len() - 1
            })
        })
        .collect();
    let schemes = schemes.iter().map(|s| Scheme::parse(s).unwrap()).collect();
    Measurement {
        dir: Default::default(),
        manifest,
        options: CompareOptions {
            schemes,
            ..CompareOptions::default()
        },
        labels,
        pattern_of_run,
        width: FRAME.0 as usize,
        height: FRAME.1 as usize,
        bit_depth: 12,
        reference_crops: Vec::new(),
        repeat_crops: Vec::new(),
        moved_crops: Vec::new(),
        reference_stats: Vec::new(),
        moved_stats: Vec::new(),
        dic: Vec::new(),
        nominal: nominal(),
        hardware: Vec::new(),
        hardware_runs_set_aside: 0,
    }
}

/// One run and scheme of a comparison whose field difference (measured − model, px of the
/// analysed image) is `common`, of noise variance `var_px2` per component (each side's random
/// error √(var/2)); every part of its discrepancy zero, its residual map empty.
pub(super) fn run_comparison(
    (id, pattern, scheme): (&str, &str, &str),
    move_px: [f64; 2],
    common: Vec<CommonPoint>,
    var_px2: f64,
) -> RunComparison {
    let side = Side {
        summary: Summary::of(&[]),
        random_px: [(var_px2 / 2.0).sqrt(); 2],
    };
    RunComparison {
        id: id.into(),
        pattern: pattern.into(),
        scheme: scheme.into(),
        discrepancy_px: 0.0,
        rigid_px: 0.0,
        field_px: 0.0,
        std_px: 0.0,
        se: DiscrepancyErrors::default(),
        stage_offset_um: [0.0; 2],
        stage_landing_um: [0.0; 2],
        measured: side.clone(),
        model: side,
        mean_diff_px: [0.0; 2],
        subpixel_fraction: [0.0; 2],
        move_px,
        accuracy: Default::default(),
        residual: ResidualMap {
            xs: Vec::new(),
            ys: Vec::new(),
            du: Vec::new(),
            dv: Vec::new(),
            profile_x: Vec::new(),
            profile_y: Vec::new(),
        },
        detail: RunDiscrepancy {
            points: common.len(),
            residual_var_px2: (var_px2, var_px2),
            common,
            ..RunDiscrepancy::default()
        },
    }
}

/// A comparison of the baseline (no effects, [`nominal`]) made of `runs`; its discrepancy their
/// RMS, its χ² counting two observations a common point; no images, no model analyses.
pub(super) fn comparison(runs: Vec<RunComparison>) -> Comparison {
    let n = runs.len().max(1) as f64;
    let discrepancy_px = (runs.iter().map(|r| r.discrepancy_px.powi(2)).sum::<f64>() / n).sqrt();
    Comparison {
        dataset: "synthetic".into(),
        manifest_version: String::new(),
        manifest_runs: runs.len(),
        model: ModelInfo {
            name: "baseline".into(),
            version: "0".into(),
            effects: Effects::default(),
            nominal: nominal(),
        },
        discrepancy_px,
        discrepancy_se_px: 0.0,
        parts: DiscrepancyParts::default(),
        parts_se: DiscrepancyParts::default(),
        chi2: Chi2 {
            observations: runs.iter().map(|r| 2 * r.detail.points).sum(),
            ..Chi2::default()
        },
        runs,
        images: Vec::new(),
        hardware: None,
        hardware_runs_set_aside: 0,
        model_dic: Vec::new(),
    }
}

/// A frame's statistics at mean `mean_dn` with nothing else measured (no spectra, noise curve or
/// mean map).
pub(super) fn frame_stats(mean_dn: f64) -> FrameStats {
    FrameStats {
        mean_dn,
        contrast: 0.3,
        contrast_se: 0.01,
        mean_map: MeanMap {
            nx: 0,
            ny: 0,
            xs: Vec::new(),
            ys: Vec::new(),
            values: Vec::new(),
            se: Vec::new(),
        },
        ptc: Vec::new(),
        ptc_from_repeat: false,
        psd_x: Vec::new(),
        psd_y: Vec::new(),
        light_map: None,
    }
}

/// What a comparison of discrepancy `discrepancy_px` leaves: the field test's F (threshold 1.5)
/// when given, no shape; significant when F exceeds its threshold.
pub(super) fn finding(discrepancy_px: f64, field_f: Option<f64>) -> Unexplained {
    Unexplained {
        significant: field_f.is_some_and(|f| f > 1.5),
        false_alarm_rate: 0.01,
        discrepancy_px,
        systematic_px: 0.0,
        expected_px: 0.0,
        ratio: 0.0,
        random_error_ratio: None,
        field_f,
        field_f_threshold: field_f.map(|_| 1.5),
        light_f: None,
        light_f_threshold: None,
        shape: Shape::default(),
        implausible_stage: Vec::new(),
        summary: String::new(),
    }
}

/// A candidate `effect` fitted to `params` (name, value, standard error) at `delta_bic`, whose
/// discrepancy dropped by `drop_px`: significant when ΔBIC < −10 and the drop is positive (the
/// other criteria met); its discrepancy after is not computed (NaN).
pub(super) fn candidate(
    effect: impl Into<CandidateId>,
    params: &[(&str, f64, f64)],
    delta_bic: f64,
    drop_px: f64,
) -> Candidate {
    let effect = effect.into();
    let significant = delta_bic < -10.0 && drop_px > 0.0;
    Candidate {
        params: params.iter().map(|p| (p.0.to_string(), p.1)).collect(),
        stderr: params.iter().map(|p| (p.0.to_string(), p.2)).collect(),
        discrepancy_px: f64::NAN,
        delta_bic,
        significant,
        drop_px,
        recomputed: true,
        method: Method::Predicted,
        criteria: Criteria {
            delta_bic_ok: delta_bic < -10.0,
            beyond_null: significant,
            evidence: Evidence::of_candidate(&effect, &Effects::default()),
            drop_px,
            drop_se_px: 0.0,
            image_chi2_drop: 0.0,
            image_chi2_se: 0.0,
            drop_ok: drop_px > 0.0,
            within_range: true,
            outside_range: None,
            separable_from_print: true,
            explains_its_signature: true,
        },
        derived: Default::default(),
        notes: Vec::new(),
        effect,
    }
}

/// A diagnosis of `before`'s model with `candidates` (as given) and `verdict`, nothing left
/// unexplained, no comparison after.
pub(super) fn diagnosis(
    before: &Comparison,
    candidates: Vec<Candidate>,
    verdict: Option<CandidateId>,
) -> Diagnosis {
    Diagnosis {
        model: before.model.clone(),
        discrepancy_px: before.discrepancy_px,
        discrepancy_se_px: before.discrepancy_se_px,
        discrepancy_by_seed_px: vec![before.discrepancy_px],
        ranking_by_drop: candidates.iter().map(|c| c.effect.clone()).collect(),
        candidates,
        verdict,
        confounded: Vec::new(),
        not_identifiable: Vec::new(),
        unexplained: finding(before.discrepancy_px, None),
        unexplained_after: None,
        explained_fraction: None,
        partial: false,
        withheld: None,
        winner_model: None,
        before: Some(before.clone()),
        after: None,
    }
}
