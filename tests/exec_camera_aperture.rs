//! Issue 33's "a confound … lens blur against fill factor: `--on-bench` adds at most 6 runs and
//! names the right effect", on frames ffdic does not render: the independent generator behind the
//! `exec` camera hides either a pixel aperture or a lens blur; the dataset's design (moves of
//! several sizes along x and y, a static repeat, no sub-pixel steps) leaves the two confounded by
//! its design and nothing else open. The on-bench job captures the rule's step series, three
//! sub-pixel steps along each axis (six runs, nothing else), and the merged dataset's diagnosis
//! has no such confound and names what the generator hid first, the other not significant beside
//! it.

use crate::common::independent;
use crate::exec_camera_bench::{config_sized, frame_command, on_bench_run};

use ffdic::diagnose::{open_questions, Rounds, SeparatingRuns, STEP_SERIES_MIN_STEPS};
use ffdic::model::EffectId;
use ffdic::service::job::OnBenchCapture;
use serde_json::{json, Value};
use std::time::Duration;

const SCALE_PX_PER_MM: f64 = 13.0;

/// The generator's bench, 640x540 at 13 px/mm, with `effects` hidden. Its print is small dots
/// (0.18 mm, σ ≈ 1 px) stated as characterised (profile, contrast, MTF in the manifest): with a
/// calibrated print the print absorbs any blur and neither effect can be told (`PRINT_SEPARATION`).
/// Its label is a lab's own, not a preset's: the bench mounts the print the dataset states.
fn bench(seed: u64, effects: Value) -> Value {
    json!({
        "name": "aperture-or-blur", "seed": seed,
        "width": 640, "height": 540, "scale_px_per_mm": SCALE_PX_PER_MM, "bit_depth": 16,
        "white_level_dn": 30000.0, "read_noise_dn": 20.0,
        "patterns": [{"label": "lab-7", "dot_diameter_mm": 0.18, "dot_spacing_mm": 0.27, "contrast": 0.7}],
        "state_print": "characterised",
        "moves": [
            {"id": "x1", "dx_mm": 1.25, "dy_mm": 0.0}, {"id": "x2", "dx_mm": 2.5, "dy_mm": 0.0},
            {"id": "x5", "dx_mm": 5.0, "dy_mm": 0.0}, {"id": "y5", "dx_mm": 0.0, "dy_mm": 5.0}
        ],
        "step_series": [],
        "repeats": 1,
        "frame_travel_mm": [-5.0, 5.0, -5.0, 5.0],
        "stage": {"repeatability_um": 1.0},
        "stated_repeatability_um": 1.0,
        "effects": effects
    })
}

/// The design confounds a diagnosis's rounds left.
fn design_pairs(r: &Rounds) -> Vec<[String; 2]> {
    open_questions(&r.diagnoses)
        .0
        .into_iter()
        .filter(|c| c.evidence == "design")
        .map(|c| c.effects)
        .collect()
}

/// The hidden effect as named: its fitted parameters (value, standard error), and whether the
/// other effect was significant beside it.
#[derive(Debug)]
struct Named {
    params: Vec<(String, f64, f64)>,
    other_significant: bool,
}

/// The first round that named `effect`, with `other` beside it.
fn named(r: &Rounds, effect: EffectId, other: EffectId) -> Option<Named> {
    let d = r
        .diagnoses
        .iter()
        .find(|d| d.verdict.as_ref().and_then(|v| v.catalogue()) == Some(effect))?;
    let find = |e: EffectId| {
        d.candidates
            .iter()
            .find(|c| c.effect.catalogue() == Some(e))
    };
    let winner = find(effect)?;
    let params = winner
        .params
        .iter()
        .map(|(k, v)| {
            (
                k.clone(),
                *v,
                winner.stderr.get(k).copied().unwrap_or(f64::NAN),
            )
        })
        .collect();
    Some(Named {
        params,
        other_significant: find(other).is_some_and(|c| c.significant),
    })
}

/// The on-bench job on the generator's bench hiding `effects`: the first diagnosis, what the
/// bench asked for and the ids of the runs it captured, the merged dataset's diagnosis.
fn on_bench(seed: u64, effects: Value) -> (Rounds, OnBenchCapture, Vec<String>, Rounds) {
    let root = tempfile::tempdir().unwrap();
    let spec = bench(seed, effects);
    let dir = root.path().join("dataset");
    independent::generate(&spec, &dir);
    let command = frame_command(&spec, root.path());
    let config = config_sized(
        &root.path().join("data"),
        &command,
        (640, 540),
        SCALE_PX_PER_MM,
    );
    // Three rounds: the baseline has no sensor noise, which the first names.
    let run = on_bench_run(&config, &dir, 3);
    let captured = run
        .bench
        .captured
        .as_ref()
        .expect("the bench's frames stored");
    let captured = ffdic::dataset::Manifest::read(&run.service.store.dataset_dir(captured))
        .unwrap()
        .runs
        .into_iter()
        .map(|r| r.id)
        .collect();
    run.service.stop(Duration::from_secs(5));
    (run.before, run.bench, captured, run.after)
}

/// Each round's verdict with its parameters and the discrepancy it diagnosed, px.
fn rounds_in_words(r: &Rounds) -> Vec<String> {
    r.rounds
        .iter()
        .map(|round| {
            let params: Vec<String> = round
                .params
                .iter()
                .map(|(k, v)| {
                    format!(
                        "{k} {v:.4} ± {:.4}",
                        round.stderr.get(k).unwrap_or(&f64::NAN)
                    )
                })
                .collect();
            format!(
                "{} ({}) at {:.5} ± {:.5}",
                round
                    .verdict
                    .as_ref()
                    .map_or("none".into(), |v| v.to_string()),
                params.join(", "),
                round.discrepancy_px,
                round.discrepancy_se_px
            )
        })
        .collect()
}

/// Before: the aperture and the blur confounded by the design and nothing else open. The bench:
/// a step series only, at most six runs. After: the confound gone and `hidden` named, each of its
/// parameters within 10 % or two standard errors of `truth`, `other` not significant beside it
/// and named in no round.
fn check_resolved(
    seed: u64,
    effects: Value,
    hidden: EffectId,
    truth: &[(&str, f64)],
    other: EffectId,
) {
    let (before, bench, captured, after) = on_bench(seed, effects);
    let pair = [
        EffectId::FillFactor.as_str().to_string(),
        EffectId::PsfBlur.as_str().to_string(),
    ];
    eprintln!(
        "{hidden}: verdicts {:?} -> {:?}; design confounds {:?} -> {:?}; bench {:?}, runs {:?}; \
         named before {:?}, after {:?}\n  rounds before {:?}\n  rounds after {:?}",
        before.verdicts,
        after.verdicts,
        design_pairs(&before),
        design_pairs(&after),
        bench.runs,
        captured,
        named(&before, hidden, other),
        named(&after, hidden, other),
        rounds_in_words(&before),
        rounds_in_words(&after),
    );
    assert_eq!(design_pairs(&before), vec![pair.clone()]);
    assert_eq!(bench.runs, vec![SeparatingRuns::StepSeries]);
    assert!(captured.len() <= 6, "at most six runs: {captured:?}");
    assert_eq!(captured.len(), 2 * STEP_SERIES_MIN_STEPS, "{captured:?}");
    assert!(
        !design_pairs(&after).contains(&pair),
        "{:?}",
        design_pairs(&after)
    );
    let named = named(&after, hidden, other)
        .unwrap_or_else(|| panic!("{hidden} named: {:?}", after.verdicts));
    assert!(
        !named.other_significant,
        "{other} significant beside {hidden}"
    );
    assert_eq!(named.params.len(), truth.len(), "{:?}", named.params);
    for (name, value, se) in &named.params {
        let (_, t) = truth
            .iter()
            .find(|(k, _)| k == name)
            .expect("a hidden parameter");
        assert!(
            (value - t).abs() <= (0.1 * t).max(2.0 * se),
            "{name} {value} ± {se}, truth {t}"
        );
    }
    // Neither before nor after: a blur fitted on its spectra's shape alone came out 1.4–3.4 SE
    // high and a later round named an aperture for the rest (docs/calibration.md).
    for rounds in [&before, &after] {
        assert!(
            !rounds.verdicts.iter().any(|v| v.catalogue() == Some(other)),
            "{other} named: {:?}",
            rounds.verdicts
        );
    }
}

/// The pixel aperture hidden (40 % of the pitch in x, 70 % in y).
#[test]
fn a_hidden_aperture_is_named_after_the_benchs_step_series() {
    check_resolved(
        3341,
        json!({"fill_factor": [0.4, 0.7]}),
        EffectId::FillFactor,
        &[("fx", 0.4), ("fy", 0.7)],
        EffectId::PsfBlur,
    );
}

/// A Gaussian lens blur hidden (σ 0.6 px).
#[test]
fn a_hidden_blur_is_named_after_the_benchs_step_series() {
    check_resolved(
        3342,
        json!({"psf_sigma_px": 0.6}),
        EffectId::PsfBlur,
        &[("sigma_px", 0.6)],
        EffectId::FillFactor,
    );
}
