//! The print's random error (issue 32): the model's random DIC error against the measured one,
//! print by print and scheme by scheme, on a paper-like dataset the independent generator made
//! (`tests/independent/`): the paper's 26 px/mm, its prints a (Gaussian dots), b (small hard
//! disks, placed without touching) and c (a defocused, low-contrast print of a: disks of 0.5 mm
//! blurred by a further 0.18 mm, contrast 0.45), a 5 mm and a 0.05 mm move, a stage offset of
//! 0.4 px in y, the paper's three schemes. The field is 960x810 (3/8 of the paper's per axis: the
//! same prints in px, a seventh of the pixels).

use crate::common::independent;

use ffdic::diagnose::{compare_prepared, load_measurement, CompareOptions, Comparison, Rounds};
use ffdic::dic::DicSettings;
use ffdic::reduce::Scheme;
use ffdic::stats::mean_and_variance_of_mean;
use independent::{baseline, candidate, generate, report, Draw};
use serde_json::{json, Value};

fn paper_like(name: &str, draw: &mut Draw, effects: Value) -> Value {
    json!({
        "name": name,
        "seed": draw.seed(),
        "width": 960, "height": 810, "scale_px_per_mm": 26.0, "bit_depth": 16,
        "white_level_dn": draw.range(25000.0, 35000.0),
        "gain_e_per_dn": null, "read_noise_dn": 40.0,
        "patterns": [
            {"label": "a", "profile": "gaussian", "dot_diameter_mm": 0.5, "dot_spacing_mm": 0.75,
             "contrast": 0.7},
            {"label": "b", "profile": "disk", "dot_diameter_mm": 0.24, "dot_spacing_mm": 0.36,
             "contrast": 0.8, "placement": "dart"},
            {"label": "c", "profile": "disk", "dot_diameter_mm": 0.5, "dot_spacing_mm": 0.75,
             "contrast": 0.45, "edge_softness_mm": 0.18, "placement": "dart"}
        ],
        "state_print": "nominal",
        "moves": [{"id": "x5mm", "dx_mm": 5.0, "dy_mm": 0.0},
                  {"id": "x005", "dx_mm": 0.05, "dy_mm": 0.0}],
        "repeats": 1,
        "stage": {"constant_offset_px": [0.0, 0.4], "repeatability_um": 2.0},
        "stated_repeatability_um": 20.0,
        "effects": effects
    })
}

fn paper_schemes() -> CompareOptions {
    CompareOptions {
        dic: DicSettings::default(),
        schemes: Scheme::presets(),
        seed: 0x5EED,
    }
}

/// The model's seeds (speckle layout, noise and so the print's calibration): the model's random
/// error is their mean, and their scatter is what one realisation of a random error scatters by.
const MODEL_SEEDS: [u64; 3] = [0x5EED, 0x5EED + 1, 0x5EED + 2];

/// The relative standard error of a std from its 95 % interval (the block bootstrap over the
/// grid: `dic::stats`).
fn relative_se(std: f64, ci95: [f64; 2]) -> f64 {
    (ci95[1] - ci95[0]) / (2.0 * 1.96 * std)
}

/// One run × scheme × axis: the measured random error, the model's by seed, and the bootstrap's
/// relative error of the measured one.
struct Case {
    name: String,
    measured: f64,
    model: Vec<f64>,
    bootstrap_rel_se: f64,
}

impl Case {
    fn model_mean(&self) -> f64 {
        mean_and_variance_of_mean(&self.model).0
    }

    /// The seeds' relative sample variance about their mean.
    fn seed_rel_var(&self) -> f64 {
        let (mean, var_of_mean) = mean_and_variance_of_mean(&self.model);
        var_of_mean * self.model.len() as f64 / (mean * mean)
    }
}

/// The model's random error against the measured, run × scheme × axis. A random error estimated
/// from one realisation (≈ 700 points of one print, one noise draw) scatters from realisation
/// to realisation by more than the block bootstrap of its grid says: over eight model seeds of
/// this test's dataset the model's random error scattered by 2–14 % (SD, relative; median 6 %)
/// against the bootstrap's 3–5 %, and over four more draws of the generator's print b the
/// measured ff25 v of the 5 mm move was 0.0096–0.0101 px where this draw's is 0.0127 (`ffdic
/// analyze` of the reduced pair, its default region). The measured side is one such
/// realisation, the model's side the mean of `MODEL_SEEDS.len()`: a ratio's relative error is
/// that scatter (from the seeds, pooled over the cases: 2 × 36 degrees of freedom; at least the
/// bootstrap's) times √(1 + 1/seeds).
#[test]
fn the_model_random_error_matches_the_measured_for_every_print_and_scheme() {
    let mut draw = Draw::new(3701);
    let spec = paper_like("print-random-error", &mut draw, json!({}));
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("dataset");
    generate(&spec, &dir);
    let mut meas = load_measurement(&dir, &paper_schemes(), &|_, _| true).unwrap();
    let mut cases: Vec<Case> = Vec::new();
    for (k, seed) in MODEL_SEEDS.into_iter().enumerate() {
        meas.options.seed = seed;
        let cmp: Comparison = compare_prepared(&meas, &baseline(), &|_, _| true).unwrap();
        print_calibrated(seed, &cmp);
        let sides = cmp.runs.iter().flat_map(|r| {
            let (m, o) = (&r.measured, &r.model);
            [
                ("u", m.random_px[0], o.random_px[0], &m.summary.u),
                ("v", m.random_px[1], o.random_px[1], &m.summary.v),
            ]
            .map(|(axis, measured, model, stats)| {
                let name = format!("{} {} {axis}", r.id, r.scheme);
                (
                    name,
                    measured,
                    model,
                    relative_se(stats.std, stats.std_ci95),
                )
            })
        });
        for (i, (name, measured, model, bootstrap_rel_se)) in sides.enumerate() {
            if k == 0 {
                cases.push(Case {
                    name,
                    measured,
                    model: vec![model],
                    bootstrap_rel_se,
                });
            } else {
                assert_eq!(
                    cases[i].name, name,
                    "the same runs and schemes for every seed"
                );
                cases[i].model.push(model);
            }
        }
    }
    let seeds = MODEL_SEEDS.len() as f64;
    let realisation_rel_sd =
        (cases.iter().map(Case::seed_rel_var).sum::<f64>() / cases.len() as f64).sqrt();
    println!(
        "one realisation's random error scatters by {:.3} (relative SD, pooled over {} cases of {} seeds)",
        realisation_rel_sd,
        cases.len(),
        MODEL_SEEDS.len()
    );
    let (mut strict, mut misses) = (0, Vec::new());
    for c in &cases {
        let ratio = c.model_mean() / c.measured;
        let one_rel_sd = realisation_rel_sd.max(c.bootstrap_rel_se);
        let se = ratio * one_rel_sd * (1.0 + 1.0 / seeds).sqrt();
        let by_seed: Vec<String> = c.model.iter().map(|o| format!("{o:.5}")).collect();
        println!(
            "{}: measured {:.5} px, model {:.5} px (seeds {}), ratio {ratio:.3} ± {se:.3}",
            c.name,
            c.measured,
            c.model_mean(),
            by_seed.join(", ")
        );
        strict += usize::from((ratio - 1.0).abs() <= 0.10);
        // Within 10 %, or beyond it by less than two standard errors of the ratio.
        if (ratio - 1.0).abs() > 0.10 + 2.0 * se {
            misses.push(format!("{}: {ratio:.3} ± {se:.3}", c.name));
        }
    }
    println!(
        "{strict} of {} within 10 %; beyond 10 % by more than 2 SE: {misses:?}",
        cases.len()
    );
    assert!(misses.is_empty(), "random error off: {misses:?}");
}

/// A random error's mean ratio over independent draws: one draw's 8–9 % scatter hides a
/// systematic miss of that order, eight draws do not. Print b alone (0.24 mm hard disks placed
/// by the generator's dart throwing with its least gap of 5 % of their diameter), the 5 mm and
/// 0.05 mm moves, ff100 and ff50, one model seed per draw; per run × scheme × axis the mean of
/// the eight ratios must lie within 10 % of one, or beyond it by less than two of its standard
/// errors (their scatter over √8). Where the model laid disks out touching (no gap), the small
/// move's ff50 v stood at 1.188 ± 0.018 over such draws and this fails
/// (`docs/model-and-diagnosis.md`, "the hard core's gap").
#[test]
fn print_b_random_error_holds_over_eight_draws() {
    let schemes = CompareOptions {
        dic: DicSettings::default(),
        schemes: ["ff100", "ff50"]
            .map(|s| Scheme::preset(s).unwrap())
            .to_vec(),
        seed: 0x5EED,
    };
    let root = tempfile::tempdir().unwrap();
    let mut ratios: Vec<(String, Vec<f64>)> = Vec::new();
    for k in 0..8u64 {
        let mut draw = Draw::new(3710 + k);
        let mut spec = paper_like(&format!("print-b-draw-{k}"), &mut draw, json!({}));
        spec["patterns"] = json!([{"label": "b", "profile": "disk", "dot_diameter_mm": 0.24,
            "dot_spacing_mm": 0.36, "contrast": 0.8, "placement": "dart"}]);
        let dir = root.path().join(format!("draw-{k}"));
        generate(&spec, &dir);
        let meas = load_measurement(&dir, &schemes, &|_, _| true).unwrap();
        let cmp = compare_prepared(&meas, &baseline(), &|_, _| true).unwrap();
        print_calibrated(k, &cmp);
        for (i, (name, ratio)) in cmp
            .runs
            .iter()
            .flat_map(|r| {
                [("u", 0), ("v", 1)].map(|(axis, a)| {
                    (
                        format!("{} {} {axis}", r.id, r.scheme),
                        r.model.random_px[a] / r.measured.random_px[a],
                    )
                })
            })
            .enumerate()
        {
            if k == 0 {
                ratios.push((name, vec![ratio]));
            } else {
                assert_eq!(
                    ratios[i].0, name,
                    "the same runs and schemes for every draw"
                );
                ratios[i].1.push(ratio);
            }
        }
    }
    let mut misses = Vec::new();
    for (name, r) in &ratios {
        let (mean, var_of_mean) = mean_and_variance_of_mean(r);
        let se = var_of_mean.sqrt();
        println!("{name}: ratio {mean:.3} ± {se:.3} over {} draws", r.len());
        if (mean - 1.0).abs() > 0.10 + 2.0 * se {
            misses.push(format!("{name}: {mean:.3} ± {se:.3}"));
        }
    }
    assert!(
        misses.is_empty(),
        "random error off over the draws: {misses:?}"
    );
}

/// The prints a comparison calibrated, for the log.
fn print_calibrated(seed: u64, cmp: &Comparison) {
    for p in &cmp.model.nominal.patterns {
        println!(
            "seed {seed}: print {}: {:?} {:?}, d {:.4} mm, softness {:.4} mm, contrast {:.3} (profile χ² {:?}, placement χ² {:?})",
            p.pattern.label,
            p.pattern.profile,
            p.pattern.placement,
            p.pattern.dot_diameter_mm,
            p.pattern.edge_softness_mm,
            p.pattern.contrast,
            p.profile_chi2,
            p.placement_chi2
        );
    }
}

/// Diagnoses the paper-like dataset with `effects` hidden for one round; the verdict must be
/// `effect`.
fn diagnosed(test: u64, effects: Value, effect: &str) -> Rounds {
    let mut draw = Draw::new(test);
    let spec = paper_like(&format!("paper-like-{effect}"), &mut draw, effects);
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("dataset");
    generate(&spec, &dir);
    let meas = load_measurement(&dir, &paper_schemes(), &|_, _| true).unwrap();
    let r = ffdic::diagnose::diagnose_rounds_prepared(&meas, &baseline(), 1, &|_, _| true).unwrap();
    report(effect, &r);
    r
}

/// A hidden effect on the paper-like dataset: named, and the total discrepancy falls 3x.
fn hidden(test: u64, effects: Value, effect: &str) {
    let r = diagnosed(test, effects, effect);
    let d = &r.diagnoses[0];
    assert_eq!(
        ffdic::model::effects::verdict_name(&d.verdict),
        effect,
        "verdict"
    );
    let c = candidate(d, effect);
    println!("{effect}: {:?} ± {:?}", c.params, c.stderr);
    let after = d.after.as_ref().expect("the winner's comparison");
    println!(
        "{effect}: discrepancy {:.5} ± {:.5} -> {:.5} ± {:.5} px",
        d.discrepancy_px, d.discrepancy_se_px, after.discrepancy_px, after.discrepancy_se_px
    );
    independent::winner_falls_3x(d, effect);
}

#[test]
fn hidden_lens_distortion_on_paper_prints_falls_3x() {
    // −4e-10 px⁻² at the paper's 2560x2160 (its half-diagonal 1675 px): the same normalised k1
    // (−1.12e-3) at 960x810 (628 px) is −2.84e-9 px⁻².
    hidden(3702, json!({"k1_per_px2": -2.84e-9}), "lens_distortion");
}

#[test]
fn hidden_scale_on_paper_prints_falls_3x() {
    hidden(3703, json!({"scale_ds": 2.0e-4}), "scale");
}

/// Vignetting barely moves a zero-normalised DIC result, so its displacement discrepancy has
/// little to fall (the test prints it); the fall asked is that of the statistic it acts on, the
/// mean-intensity map's χ² (as `independent_diagnosis::hidden_vignetting`).
#[test]
fn hidden_vignetting_on_paper_prints_is_named_and_its_map_falls_3x() {
    let r = diagnosed(3704, json!({"vignetting_v": 0.3}), "vignetting");
    let d = &r.diagnoses[0];
    assert_eq!(
        ffdic::model::effects::verdict_name(&d.verdict),
        "vignetting"
    );
    let c = candidate(d, "vignetting");
    println!("vignetting: {:?} ± {:?}", c.params, c.stderr);
    let (before, after) = (d.before.as_ref().unwrap(), d.after.as_ref().unwrap());
    let (map_before, map_after) = (before.chi2.image_parts[2].0, after.chi2.image_parts[2].0);
    println!(
        "vignetting: mean-map χ² {map_before:.1} -> {map_after:.1}; discrepancy {:.5} ± {:.5} -> {:.5} ± {:.5} px",
        before.discrepancy_px, before.discrepancy_se_px, after.discrepancy_px, after.discrepancy_se_px
    );
    assert!(map_after * 3.0 <= map_before);
}
