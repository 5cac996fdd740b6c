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

/// Cases where the model's random error is known to miss the measured one, with the ratio
/// (model / measured) recorded: open findings, not tolerances. Print b's ff25 v on the 5 mm move
/// is 0.813 ± 0.041 with the disks' exact coverage (0.816 ± 0.043 with the strips it replaced,
/// when the bound 0.90 − 2 SE was 0.814 and it passed by 0.002): 4.5 SE below 1, while its u is
/// 1.22 ± 0.08 above. The cause is not the rendering (the exact coverage moved it 0.003); the
/// model's print differs from this one in its dots' depth (±15 % against none) and their least
/// distance (one diameter against 1.05). Each entry fails the test if the case comes back within
/// the bounds (remove it) or moves by more than 2 SE from the ratio recorded.
const KNOWN_MISSES: [(&str, f64); 1] = [("b-x5mm ff25 v", 0.813)];

/// The relative standard error of a std from its 95 % interval.
fn relative_se(std: f64, ci95: [f64; 2]) -> f64 {
    (ci95[1] - ci95[0]) / (2.0 * 1.96 * std)
}

#[test]
fn the_model_random_error_matches_the_measured_for_every_print_and_scheme() {
    let mut draw = Draw::new(3701);
    let spec = paper_like("print-random-error", &mut draw, json!({}));
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("dataset");
    generate(&spec, &dir);
    let meas = load_measurement(&dir, &paper_schemes(), &|_, _| true).unwrap();
    let cmp: Comparison = compare_prepared(&meas, &baseline(), &|_, _| true).unwrap();
    for p in &cmp.model.nominal.patterns {
        println!(
            "print {}: {:?} {:?}, d {:.4} mm, softness {:.4} mm, contrast {:.3} (profile χ² {:?}, placement χ² {:?})",
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
    let (mut strict, mut total, mut misses) = (0, 0, Vec::new());
    for r in &cmp.runs {
        let (m, o) = (&r.measured, &r.model);
        let stats = [
            (
                &m.summary.u,
                &o.summary.u,
                m.random_px[0],
                o.random_px[0],
                "u",
            ),
            (
                &m.summary.v,
                &o.summary.v,
                m.random_px[1],
                o.random_px[1],
                "v",
            ),
        ];
        for (ms, os, measured, model, axis) in stats {
            let ratio = model / measured;
            let se =
                ratio * relative_se(ms.std, ms.std_ci95).hypot(relative_se(os.std, os.std_ci95));
            println!(
                "{} {} {axis}: measured {measured:.5} px, model {model:.5} px, ratio {ratio:.3} ± {se:.3}",
                r.id, r.scheme
            );
            total += 1;
            strict += usize::from((ratio - 1.0).abs() <= 0.10);
            // Within 10 %, or beyond it by less than two standard errors of the ratio (the two
            // stds are each known to ±5–6 % at 95 % over ~700 points: a ratio of 1.12 ± 0.05
            // is not shown to be off by more than 10 %). The note counts the strict ones.
            let case = format!("{} {} {axis}", r.id, r.scheme);
            let missed = (ratio - 1.0).abs() > 0.10 + 2.0 * se;
            let known = KNOWN_MISSES.iter().find(|(known, _)| *known == case);
            match known {
                // A known miss must still be one, and no further off than it was.
                Some((_, recorded)) if !missed || (ratio - recorded).abs() > 2.0 * se => misses
                    .push(format!(
                        "{case}: {ratio:.3} ± {se:.3}, listed as a known miss at {recorded}: \
                         update KNOWN_MISSES"
                    )),
                Some(_) => {}
                None if missed => misses.push(format!("{case}: {ratio:.3} ± {se:.3}")),
                None => {}
            }
        }
    }
    println!("{strict} of {total} within 10 %; beyond 10 % by more than 2 SE: {misses:?}");
    assert!(misses.is_empty(), "random error off: {misses:?}");
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
