//! The diagnosis held against datasets ffdic did not render (issue 18): every dataset here comes
//! from the independent generator (`tests/independent/`, Python with numpy, its own speckle,
//! geometry, optics, sensor and stage; see its README), with hidden values, seeds and prints drawn
//! per test (`FFDIC_INDEPENDENT_SEED` redraws them all), or from the DIC Challenge's Sample 3
//! images. The baseline model is diagnosed against each; the tests assert the verdicts, the
//! fitted parameters against the generator's `truth.json`, and the fall of the discrepancy.
//!
//! The analysis is the default DIC (subset 41, step 20) on the native frames (one scheme, to keep
//! the suite's time), `diagnose --rounds` as the library runs it.

use crate::common::independent;

use ffdic::diagnose::{
    compare_prepared, diagnose_rounds_prepared, load_measurement, CompareOptions, Diagnosis,
};
use ffdic::dic::DicSettings;
use ffdic::reduce::Scheme;
use independent::{baseline, bench, candidate, diagnose, generate, measure, options, report, Draw};
use serde_json::{json, Value};

/// `value` is within 5 % of `truth` or within two of its standard errors.
fn close(effect: &str, value: f64, se: f64, truth: f64) {
    let ok = (value - truth).abs() <= 0.05 * truth.abs() || (value - truth).abs() <= 2.0 * se;
    assert!(
        ok,
        "{effect}: fitted {value} ± {se}, truth {truth} ({:+.1} %)",
        100.0 * (value / truth - 1.0)
    );
}

fn param(d: &Diagnosis, effect: &str, name: &str) -> (f64, f64) {
    let c = candidate(d, effect);
    (c.params[name], c.stderr.get(name).copied().unwrap_or(0.0))
}

/// One hidden effect: named in the first round, its parameter against the truth, and the
/// discrepancy at least 3x lower with it added.
fn single(spec: Value, effect: &str, name: &str, truth: f64) {
    let (r, _) = diagnose(&spec, 1);
    let d = &r.diagnoses[0];
    assert_eq!(
        ffdic::model::effects::verdict_name(&d.verdict),
        effect,
        "verdict"
    );
    let (v, se) = param(d, effect, name);
    close(effect, v, se, truth);
    independent::winner_falls_3x(d, effect);
}

#[test]
fn the_generator_passes_its_own_checks() {
    // Shifts measured by its own FFT phase correlation, mean, contrast, noise and vignetting
    // against their predictions, disk areas against Monte Carlo (tests/independent/selfcheck.py).
    let out = std::process::Command::new(independent::python())
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/independent/selfcheck.py"
        ))
        .output()
        .expect("selfcheck.py runs");
    println!("{}", String::from_utf8_lossy(&out.stdout));
    assert!(
        out.status.success(),
        "selfcheck failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn controls_with_nothing_hidden_give_at_most_one_verdict() {
    // Ten datasets: different seeds, smooth and sharp prints, stage offsets up to 0.5 px. Nothing
    // to find, and (issue 32) nothing left unexplained on at least nine.
    let mut verdicts = Vec::new();
    let mut unexplained = Vec::new();
    for k in 0..10u64 {
        let mut draw = Draw::new(100 + k);
        let spec = bench(&format!("control-{k}"), &mut draw, k % 2 == 1);
        let (r, _) = diagnose(&spec, 1);
        verdicts.push(r.diagnoses[0].verdict.clone());
        unexplained.push(r.diagnoses[0].unexplained.significant);
    }
    println!("control verdicts: {verdicts:?}; unexplained: {unexplained:?}");
    let found = verdicts.iter().filter(|v| v.is_some()).count();
    assert!(
        found <= 1,
        "{found} of 10 controls got a verdict: {verdicts:?}"
    );
    let left = unexplained.iter().filter(|u| **u).count();
    assert!(
        left <= 1,
        "{left} of 10 controls left something significant unexplained"
    );
}

/// Gaussian dots placed independently (the generator's `gaussian` profile, Poisson positions) are
/// calibrated as Gaussian dots of the generator's σ. The placement is chosen below half the
/// spacing frequency, where a hard core can read a χ² within the scatter of Poisson's: on the
/// first print here it read 10.5 against 12.7 over some 12 bins, and chosen on that, the
/// Gaussian dots' whole band was rejected (χ² 5,024) and the print ended as soft disks of a σ 7 %
/// short. Poisson is now kept unless another placement is better by more than the χ²'s own
/// scatter (`calibrate_scene::choose_placement`). The second print is a drawn one whose
/// placement was never in doubt (hard core 50.9, Poisson 11.7). The calibrated σ of the test
/// bench's Gaussian prints was within 1.1 % of the truth on five prints (2026-12-07).
#[test]
fn gaussian_dots_placed_independently_are_calibrated_as_such() {
    use ffdic::model::DotProfile;
    // (seed, white level, dot diameter, spacing, contrast, stage offset): the bench's print.
    let prints = [
        (1_234_567u64, 30000.0, 0.3, 0.51, 0.65, [0.2, -0.3]),
        (
            673_701_294,
            30830.0,
            0.33269,
            0.54053,
            0.56697,
            [-0.438, 0.086],
        ),
    ];
    for (k, (seed, white, d, spacing, contrast, offset)) in prints.into_iter().enumerate() {
        let mut spec = bench(
            &format!("gaussian-{k}"),
            &mut Draw::new(40 + k as u64),
            false,
        );
        spec["seed"] = json!(seed);
        spec["white_level_dn"] = json!(white);
        spec["patterns"] = json!([{"label": "a", "profile": "gaussian", "dot_diameter_mm": d,
                                    "dot_spacing_mm": spacing, "contrast": contrast}]);
        spec["stage"]["constant_offset_px"] = json!(offset);
        let measured = measure(&spec);
        let cmp = compare_prepared(&measured.measurement, &baseline(), &|_, _| true).unwrap();
        let p = &cmp.model.nominal.patterns[0];
        let cal = p
            .calibration
            .as_ref()
            .expect("a nominal print is calibrated");
        // The generator's own σ of its dots (truth.json), not one derived here from the FWHM.
        let truth_sigma_mm = measured.truth["patterns"][0]["sigma_mm"].as_f64().unwrap();
        println!(
            "print {k}: placement {:?} (χ² {:?}), profile {:?} (χ² {:?}), σ {:.5} mm against {:.5}",
            p.pattern.placement,
            p.placement_chi2,
            cal.profile,
            p.profile_chi2,
            cal.sigma_mm,
            truth_sigma_mm
        );
        assert_eq!(cal.profile, DotProfile::Gaussian, "print {k}");
        assert!(
            (cal.sigma_mm / truth_sigma_mm - 1.0).abs() < 0.03,
            "print {k}: σ {} mm against {truth_sigma_mm}",
            cal.sigma_mm
        );
    }
}

#[test]
fn hidden_lens_distortion() {
    let mut draw = Draw::new(1);
    let mut spec = bench("distortion", &mut draw, false);
    // −2e-10 to −6e-10 px⁻² at the paper's 2560x2160 is −1.2e-3 to −3.7e-3 in ffdic's normalised
    // k1 (r0 the half diagonal): the same range here, where r0 is 4x smaller.
    let k1_norm = -draw.range(2.0e-3, 5.0e-3);
    spec["effects"] = json!({"k1_norm": k1_norm});
    single(spec, "lens_distortion", "k1", k1_norm);
}

#[test]
fn hidden_rotation() {
    let mut draw = Draw::new(2);
    let mut spec = bench("rotation", &mut draw, false);
    let angle = draw.range(1.0e-4, 3.0e-4) * draw.sign();
    spec["effects"] = json!({"rotation_rad": angle});
    single(spec, "rotation", "angle_rad", angle);
}

#[test]
fn hidden_scale() {
    let mut draw = Draw::new(3);
    let mut spec = bench("scale", &mut draw, true);
    let ds = draw.range(1.0e-4, 3.0e-4) * draw.sign();
    spec["effects"] = json!({"scale_ds": ds});
    single(spec, "scale", "ds", ds);
}

#[test]
fn hidden_stage_error() {
    // The stage states 1 µm but lands with 10–20 µm of scatter.
    let mut draw = Draw::new(4);
    let mut spec = bench("stage", &mut draw, false);
    let sigma_um = draw.range(10.0, 20.0);
    spec["stated_repeatability_um"] = json!(1.0);
    spec["stage"] = json!({"constant_offset_px": [0.0, 0.0], "repeatability_um": sigma_um});
    let (r, truth) = diagnose(&spec, 1);
    let d = &r.diagnoses[0];
    assert_eq!(
        ffdic::model::effects::verdict_name(&d.verdict),
        "stage_error"
    );
    // The truth: the RMS per axis of the offsets the generator drew.
    let offsets: Vec<f64> = truth["runs"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|run| {
            let o = &run["offset_px"]["total"];
            [o[0].as_f64().unwrap(), o[1].as_f64().unwrap()]
        })
        .collect();
    let rms_px = (offsets.iter().map(|x| x * x).sum::<f64>() / offsets.len() as f64).sqrt();
    let (v, se) = param(d, "stage_error", "repeatability_um");
    close("stage_error", v, se, rms_px * 1000.0 / 13.0);
    let after = d.after.as_ref().unwrap();
    assert!(after.discrepancy_px * 3.0 <= d.discrepancy_px);
}

#[test]
fn hidden_vignetting() {
    // DIC's zero-normalised criterion barely sees vignetting: its evidence is the mean-intensity
    // map, so the fall asked of it is that map's χ² (the test prints the displacement
    // discrepancy beside it).
    let mut draw = Draw::new(5);
    let mut spec = bench("vignetting", &mut draw, false);
    let v = draw.range(0.2, 0.4);
    spec["effects"] = json!({"vignetting_v": v});
    let (r, _) = diagnose(&spec, 1);
    let d = &r.diagnoses[0];
    assert_eq!(
        ffdic::model::effects::verdict_name(&d.verdict),
        "vignetting"
    );
    let (fit, se) = param(d, "vignetting", "v");
    close("vignetting", fit, se, v);
    let before = d.before.as_ref().unwrap();
    let after = d.after.as_ref().unwrap();
    // The mean-intensity map's χ² (the statistic vignetting acts on).
    let (map_before, map_after) = (before.chi2.image_parts[2].0, after.chi2.image_parts[2].0);
    println!(
        "vignetting: mean-map χ² {map_before} -> {map_after}, image χ² {} -> {}, discrepancy {} -> {} px",
        before.chi2.image, after.chi2.image, before.discrepancy_px, after.discrepancy_px
    );
    assert!(map_after * 3.0 <= map_before);
}

#[test]
fn hidden_shot_noise_with_a_repeat_of_one_print_only() {
    // Two prints, a photon-transfer (shot) noise the baseline lacks, and a static repeat of print
    // a only (print b's is struck from the manifest, as a lab that took one repeat would have
    // it). The photon transfer curve is fitted from the repeat's noise alone: print b's curve
    // from its single frame is the speckle's curvature: fitted beside it, on a dataset like this
    // one (2 e/DN, 40 e of read noise, two moves), the read noise came out 38 ± 41 e, against
    // 42.4 ± 3.0 e from the repeat alone (2026-11-29).
    let mut draw = Draw::new(7);
    let mut spec = bench("shot", &mut draw, false);
    let gain_e_per_dn = draw.range(1.5, 3.0);
    let read_noise_dn = spec["read_noise_dn"].as_f64().unwrap();
    spec["gain_e_per_dn"] = json!(gain_e_per_dn);
    spec["patterns"] = json!([
        independent::print(&mut draw, "a", false),
        independent::print(&mut draw, "b", false)
    ]);
    spec["moves"] = json!([{"id": "x5mm", "dx_mm": 5.0, "dy_mm": 0.0}]);
    spec["step_series"] = json!([]);
    // The spec, to generate the dataset again outside the test.
    println!("spec: {spec}");
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("dataset");
    generate(&spec, &dir);
    let manifest_path = dir.join("dataset.json");
    let mut manifest: Value =
        serde_json::from_slice(&std::fs::read(&manifest_path).unwrap()).unwrap();
    for run in manifest["runs"].as_array_mut().unwrap() {
        if run["reference"].as_str().unwrap().starts_with("b_") {
            run.as_object_mut().unwrap().remove("repeat");
        }
    }
    std::fs::write(&manifest_path, serde_json::to_vec(&manifest).unwrap()).unwrap();
    let meas = load_measurement(&dir, &options(), &|_, _| true).unwrap();
    let r = diagnose_rounds_prepared(&meas, &baseline(), 1, &|_, _| true).unwrap();
    report("shot", &r);
    let d = &r.diagnoses[0];
    assert_eq!(
        ffdic::model::effects::verdict_name(&d.verdict),
        "sensor_noise"
    );
    let (gain, gain_se) = param(d, "sensor_noise", "gain");
    close("sensor_noise gain", gain, gain_se, gain_e_per_dn);
    let (read_e, read_se) = param(d, "sensor_noise", "read_noise_e");
    let truth_e = read_noise_dn * gain_e_per_dn;
    println!("gain {gain} ± {gain_se} (truth {gain_e_per_dn}), read noise {read_e} ± {read_se} e (truth {truth_e})");
    // Within 15 % or two standard errors of the truth, and known to better than 20 %.
    assert!(
        (read_e - truth_e).abs() <= (0.15 * truth_e).max(2.0 * read_se),
        "read noise {read_e} ± {read_se} e, truth {truth_e}"
    );
    assert!(read_se < 0.2 * truth_e, "read noise {read_e} ± {read_se} e");
}

/// The psf_blur dataset of the tests: Gaussian dots, a lens blur drawn in 0.8–1.4 px.
fn psf_spec(state_print: &str) -> (Value, f64) {
    let mut draw = Draw::new(6);
    let sigma = draw.range(0.8, 1.4);
    let mut spec = bench(&format!("psf-{state_print}"), &mut draw, false);
    spec["effects"] = json!({"psf_sigma_px": sigma});
    spec["state_print"] = json!(state_print);
    (spec, sigma)
}

#[test]
fn hidden_psf_blur_with_a_nominal_print_is_not_fitted_against_it() {
    let (spec, _) = psf_spec("nominal");
    let (r, _) = diagnose(&spec, 1);
    let d = &r.diagnoses[0];
    // Never another effect; with a print known only nominally, the blur is the print's or the
    // lens's: the print's calibration absorbs it, so neither the blur nor the aperture is
    // fitted, and the diagnosis says so with what would separate them.
    assert_eq!(
        ffdic::model::effects::verdict_name(&d.verdict),
        "none",
        "verdict"
    );
    for effect in [
        ffdic::model::EffectId::PsfBlur,
        ffdic::model::EffectId::FillFactor,
    ] {
        assert!(d.candidates.iter().all(|c| c.effect != effect), "{effect}");
        let n = d
            .not_identifiable
            .iter()
            .find(|n| n.effect == effect)
            .unwrap_or_else(|| panic!("{effect} reported as not identifiable"));
        assert!(n.runs_to_add.contains("characterised print"), "{n:?}");
    }
}

/// With a characterised print the blur is the lens's: named, its σ within 20 % (the issue's
/// figure). Met since the model's lens blur spreads each dot's darkening instead of adding to it
/// (`model::render`: the depth falls as σ² grows); before, adding the blur darkened the model's
/// frames, the white level rose 27 % to match the mean and the image statistics grew worse
/// (ΔBIC +26.7, verdict `none`). The σ had needed the print's placement chosen from the
/// spectrum (`compare::choose_placement`; a jittered grid left it 28 % low) and the fit on the
/// spectrum's shape above half the spacing frequency.
#[test]
fn hidden_psf_blur_with_a_characterised_print_is_named_within_20_percent() {
    let (spec, sigma) = psf_spec("characterised");
    let (r, _) = diagnose(&spec, 1);
    let d = &r.diagnoses[0];
    let criteria = d
        .candidates
        .iter()
        .find(|c| c.effect == ffdic::model::EffectId::PsfBlur)
        .map(|c| format!("ΔBIC {:.1}, {:?}", c.delta_bic, c.criteria));
    assert_eq!(
        ffdic::model::effects::verdict_name(&d.verdict),
        "psf_blur",
        "psf_blur candidate: {criteria:?}"
    );
    let (fit, se) = param(d, "psf_blur", "sigma_px");
    println!(
        "psf_blur σ {fit} ± {se} px, truth {sigma} px; discrepancy {} -> {:?} px",
        d.discrepancy_px,
        d.after.as_ref().map(|a| a.discrepancy_px)
    );
    assert!(
        (fit / sigma - 1.0).abs() <= 0.2,
        "psf_blur σ {fit} px, truth {sigma} px"
    );
}

#[test]
fn hidden_fill_factor_is_never_a_fit_at_its_bound() {
    let mut draw = Draw::new(7);
    let mut spec = bench("fill-factor", &mut draw, true);
    spec["effects"] = json!({"fill_factor": [0.5, 1.0]});
    let (r, _) = diagnose(&spec, 1);
    let d = &r.diagnoses[0];
    assert!(
        ffdic::model::effects::verdict_name(&d.verdict) == "fill_factor"
            || ffdic::model::effects::verdict_name(&d.verdict) == "none",
        "verdict {}",
        ffdic::model::effects::verdict_name(&d.verdict)
    );
    // Not named: the diagnosis says why, as a confound or, against a print calibrated from the
    // frames, as what would reveal the aperture.
    if ffdic::model::effects::verdict_name(&d.verdict) == "none" {
        assert!(
            d.confounded
                .iter()
                .any(|c| c.effects.contains(&"fill_factor".to_string()))
                || d.not_identifiable
                    .iter()
                    .any(|n| n.effect == ffdic::model::EffectId::FillFactor),
            "{:?} {:?}",
            d.confounded,
            d.not_identifiable
        );
    }
    for c in d.candidates.iter().filter(|c| c.significant) {
        assert!(
            c.criteria.within_range,
            "{} significant at a bound",
            c.effect
        );
    }
}

/// Several hidden at once: every one found by the rounds, each within 10 %, the discrepancy
/// falling at every round.
fn several(spec: Value, expected: &[(&str, &str, f64)]) {
    let (r, _) = diagnose(&spec, expected.len() + 1);
    for (effect, name, truth) in expected {
        assert!(
            r.verdicts.iter().any(|v| v.to_string() == *effect),
            "{effect} not found: {:?}",
            r.verdicts
        );
        let k = r
            .verdicts
            .iter()
            .position(|v| v.to_string() == *effect)
            .unwrap();
        let value = r.rounds[k].params[*name];
        assert!(
            (value / truth - 1.0).abs() <= 0.10,
            "{effect}: {value} against {truth}"
        );
    }
    for round in r
        .rounds
        .iter()
        .filter(|x| ffdic::model::effects::verdict_name(&x.verdict) != "none")
    {
        let after = round.after_px.unwrap();
        assert!(
            after < round.discrepancy_px,
            "round {}: {} -> {after}",
            ffdic::model::effects::verdict_name(&round.verdict),
            round.discrepancy_px
        );
    }
}

#[test]
fn distortion_rotation_and_stage_offsets_at_once() {
    let mut draw = Draw::new(8);
    let mut spec = bench("distortion+rotation", &mut draw, false);
    let k1 = -draw.range(2.0e-3, 5.0e-3);
    let angle = draw.range(1.0e-4, 3.0e-4);
    spec["effects"] = json!({"k1_norm": k1, "rotation_rad": angle});
    several(
        spec,
        &[
            ("lens_distortion", "k1", k1),
            ("rotation", "angle_rad", angle),
        ],
    );
}

#[test]
fn vignetting_and_scale_at_once() {
    let mut draw = Draw::new(9);
    let mut spec = bench("vignetting+scale", &mut draw, false);
    let v = draw.range(0.2, 0.4);
    let ds = draw.range(1.0e-4, 3.0e-4);
    spec["effects"] = json!({"vignetting_v": v, "scale_ds": ds});
    let (r, _) = diagnose(&spec, 3);
    for (effect, name, truth) in [("vignetting", "v", v), ("scale", "ds", ds)] {
        let k = r
            .verdicts
            .iter()
            .position(|x| x.to_string() == effect)
            .unwrap_or_else(|| panic!("{effect} not found: {:?}", r.verdicts));
        let value = r.rounds[k].params[name];
        assert!(
            (value / truth - 1.0).abs() <= 0.10,
            "{effect}: {value} against {truth}"
        );
    }
    // Vignetting falls in the image statistics, scale in the displacements: every round lowers
    // the total χ² (the displacement discrepancy cannot fall with vignetting, see above).
    for (k, round) in r
        .rounds
        .iter()
        .enumerate()
        .filter(|(_, x)| ffdic::model::effects::verdict_name(&x.verdict) != "none")
    {
        let d = &r.diagnoses[k];
        let before = d.before.as_ref().unwrap().chi2.total;
        let after = d.after.as_ref().unwrap();
        let after_chi2 = after.chi2.total;
        assert!(
            after_chi2 < before,
            "round {}: χ² {before} -> {after_chi2}",
            ffdic::model::effects::verdict_name(&round.verdict)
        );
    }
}

#[test]
fn sample3_has_nothing_to_find() {
    // Fourier-shifted frames of one real speckle image: no lens, print or sensor effect between
    // reference and shifts.
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("sample3");
    independent::sample3(&dir, 10.0);
    let meas = load_measurement(&dir, &options(), &|_, _| true).unwrap();
    let r = diagnose_rounds_prepared(&meas, &baseline(), 1, &|_, _| true).unwrap();
    report("sample3", &r);
    assert_eq!(
        ffdic::model::effects::verdict_name(&r.diagnoses[0].verdict),
        "none"
    );
}

/// The false-alarm rate over 30 control seeds (slow: run with `--ignored`; the figure is in
/// docs/model-and-diagnosis.md).
#[test]
#[ignore = "slow: 30 diagnoses; the measured rate is in docs/model-and-diagnosis.md"]
fn false_alarm_rate_over_30_controls() {
    let mut verdicts = Vec::new();
    let mut unexplained = 0;
    for k in 0..30u64 {
        let mut draw = Draw::new(1000 + k);
        let spec = bench(&format!("control-{k}"), &mut draw, k % 2 == 1);
        let (r, _) = diagnose(&spec, 1);
        verdicts.push(r.diagnoses[0].verdict.clone());
        unexplained += usize::from(r.diagnoses[0].unexplained.significant);
    }
    let found = verdicts.iter().filter(|v| v.is_some()).count();
    println!(
        "false alarms: {found} of 30: {verdicts:?}; unexplained significant: {unexplained} of 30"
    );
    assert!(found <= 3, "{found} of 30 controls got a verdict");
    assert!(
        unexplained <= 3,
        "{unexplained} of 30 controls left something significant unexplained"
    );
}

/// Issue 17 on data ffdic did not render: the generator reads every position out again in the
/// camera's own modes (its own convention: the first pixels of each block binned or kept, digital
/// binning digitising every pixel, charge binning reading the summed electrons once). `compare`
/// renders the model in each run's mode: a hardware run's discrepancy is its synthesised twin's
/// (the same irradiance, the same pixel apertures, in px of frames of the same size) within 3
/// standard errors of their difference, and so is the model's random error over the measured
/// one — which is what tells the modes apart (the model rendering hw:dec2x2 as a 2x2 binning
/// gives 0.17 against the twin's 0.31, 5 standard errors; a constant sampling phase, by
/// contrast, moves reference and moved frame alike and no displacement).
#[test]
fn hardware_read_outs_compare_as_their_synthesised_twins() {
    use ffdic::diagnose::compare_prepared;
    let mut draw = Draw::new(17);
    let mut spec = bench("hardware-read-outs", &mut draw, false);
    spec["moves"] = json!([{"id": "x5mm", "dx_mm": 5.0, "dy_mm": 0.0},
                           {"id": "y5mm", "dx_mm": 0.0, "dy_mm": 5.0}]);
    spec["step_series"] = json!([]);
    spec["hardware_readouts"] = json!([
        {"name": "hw:bin2x2-average", "binning": [2, 2], "value": "average", "domain": "digital"},
        {"name": "hw:dec2x2", "decimation": [2, 2]}
    ]);
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("dataset");
    generate(&spec, &dir);
    let options = CompareOptions {
        schemes: ["ff100", "ff25"]
            .iter()
            .map(|p| Scheme::preset(p).unwrap())
            .collect(),
        dic: DicSettings {
            subset_px: 21,
            step_px: 10,
            ..DicSettings::default()
        },
        seed: 0x5EED,
    };
    let meas = load_measurement(&dir, &options, &|_, _| true).unwrap();
    let cmp = compare_prepared(&meas, &baseline(), &|_, _| true).unwrap();
    let hw = cmp.hardware.as_ref().expect("the hardware runs compared");
    assert_eq!(hw.runs.len(), 4);
    for r in &hw.runs {
        let twin_scheme = if r.scheme == "hw:dec2x2" {
            "ff25"
        } else {
            "ff100"
        };
        let twin = cmp
            .runs
            .iter()
            .find(|t| t.id == r.twin && t.scheme == twin_scheme)
            .unwrap();
        let se =
            r.se.discrepancy_se_px
                .hypot(twin.detail.discrepancy_se_px());
        println!(
            "{} ({}): D {:.5} ± {:.5} px; twin {} {}: D {:.5} px (rigid {:.5} / {:.5}, field {:.5} / {:.5})",
            r.id, r.scheme, r.discrepancy_px, r.se.discrepancy_se_px, twin.id, twin_scheme,
            twin.discrepancy_px, r.parts.rigid_px, twin.rigid_px, r.parts.field_px, twin.field_px
        );
        assert!(
            (r.discrepancy_px - twin.discrepancy_px).abs() < 3.0 * se,
            "{}: {} against the twin's {} (se {se})",
            r.id,
            r.discrepancy_px,
            twin.discrepancy_px
        );
        // The model's random error over the measured one, as for the twin: the read-out's pixel
        // aperture and noise rendered right. Each std estimate has a relative standard error
        // 1/√(2 n_eff), n_eff = points/(subset/step)² for overlapping subsets; the difference of
        // two log ratios holds four of them.
        let n_eff = r.points as f64 / (21.0f64 / 10.0).powi(2);
        let se_log = (2.0 / n_eff).sqrt();
        for axis in 0..2 {
            let hw_ratio = r.model_random_px[axis] / r.measured_random_px[axis];
            let twin_ratio = twin.model.random_px[axis] / twin.measured.random_px[axis];
            println!("   axis {axis}: model/measured random {hw_ratio:.3}, twin {twin_ratio:.3} (se of log {se_log:.3})");
            assert!(
                (hw_ratio.ln() - twin_ratio.ln()).abs() < 3.0 * se_log,
                "{} axis {axis}: random ratio {hw_ratio} against the twin's {twin_ratio}",
                r.id
            );
        }
    }
}
