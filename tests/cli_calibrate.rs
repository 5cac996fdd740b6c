//! `ffdic calibrate` through the binary, as a lab runs it (issue 33): a plan on the config's
//! bench (the small mock bench), the card printed as JSON and its model stored in the data
//! folder; then the card of the runs it captured (`--dataset`), and plans refused before the
//! bench moves. The service path under it is tested over HTTP (`api_experiments`) and with the
//! independent generator behind the exec camera (`exec_camera_bench`).

use crate::common::{daemon, ffdic, ffdic_ok};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Two move sizes along ±x and ±y (the stage's map needs both axes), no phase scan (the default
/// with a nominal print), one round, small subsets: seconds on the small mock bench.
const PLAN: &str = r#"
name = "cli-card"
pattern = "a"
move_sizes_mm = [0.5, 2.5]
static_frames = 1
rounds = 1
seed = 5

[dic]
subset_px = 21
step_px = 10
strain_window = 5
"#;

fn write(path: &Path, text: &str) -> String {
    std::fs::write(path, text).unwrap();
    path.to_str().unwrap().to_string()
}

/// The small mock bench's config in `dir`, its data folder beside it: (data folder, config path).
fn small_bench(dir: &Path) -> (PathBuf, String) {
    let data = dir.join("data");
    let config = write(&dir.join("ffdic.toml"), &daemon::small_config_toml(&data));
    (data, config)
}

#[test]
fn calibrate_on_the_bench_prints_the_card_and_stores_its_model() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, config) = small_bench(tmp.path());
    let plan = write(&tmp.path().join("plan.toml"), PLAN);
    let out = ffdic_ok(&["calibrate", "--config", &config, "--plan", &plan, "--json"]);
    let doc: Value = serde_json::from_slice(&out.stdout).expect("one JSON document on stdout");
    let model = doc["model"].as_str().expect("the card's model");
    assert!(
        model.starts_with("card-cli-card-"),
        "card-NAME-HASH: {model}"
    );
    assert!(
        data.join("models").join(format!("{model}.toml")).is_file(),
        "the card's model is stored in the config's data folder"
    );
    let card = &doc["card"];
    assert_eq!(
        card["stage"]["runs"], 8,
        "±x and ±y at two sizes: {}",
        card["stage"]
    );
    for key in [
        "scale_x_px_per_mm",
        "scale_y_px_per_mm",
        "angle_rad",
        "angle_se_rad",
    ] {
        assert!(card["stage"][key].is_number(), "stage.{key}");
    }
    assert!(card["baseline_px"].is_number() && card["card_px"].is_number());
    assert!(
        card["card_se_px"].as_f64().unwrap() > 0.0,
        "the card's discrepancy has an SE"
    );
    assert_eq!(doc["plan"]["move_sizes_mm"], serde_json::json!([0.5, 2.5]));
    // The plan as run: the phase scan's count stated, none with a nominal print.
    assert_eq!(doc["plan"]["phase_scan_count"], serde_json::json!(0));
    assert!(doc["rounds"]["rounds"].is_array());

    // The runs it captured are a dataset in the data folder: their card again, with --dataset.
    let datasets: Vec<_> = std::fs::read_dir(data.join("datasets"))
        .expect("the calibration's frames became a dataset")
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("dataset.json").is_file())
        .collect();
    assert_eq!(datasets.len(), 1, "{datasets:?}");
    let again = ffdic_ok(&[
        "calibrate",
        "--dataset",
        datasets[0].to_str().unwrap(),
        "--plan",
        &plan,
        "--data",
        data.to_str().unwrap(),
        "--json",
    ]);
    let again: Value = serde_json::from_slice(&again.stdout).unwrap();
    assert_eq!(
        again["card"]["stage"]["runs"], 8,
        "the same runs, the same map"
    );

    // The card's model as the bench of a study (`reproduce --bench-model NAME`): the mock bench
    // renders that camera, whose stage angle the study's v shows.
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/small.toml");
    let study = ffdic_ok(&[
        "reproduce",
        "--experiment",
        fixture.to_str().unwrap(),
        "--bench-model",
        model,
        "--data",
        data.to_str().unwrap(),
        "--no-model",
        "--json",
    ]);
    let study: Value = serde_json::from_slice(&study.stdout).unwrap();
    let angle = card["stage"]["angle_rad"].as_f64().unwrap();
    let row = &study["rows"][0];
    let (u, v) = (
        row["u"]["mean"].as_f64().unwrap(),
        row["v"]["mean"].as_f64().unwrap(),
    );
    println!("the card's bench: u {u:.4} v {v:.4} px, card angle {angle:.5} rad");
    assert!(
        (v.atan2(u) - angle).abs() < 0.001,
        "the study's move at {:.5} rad, the card's stage angle {angle:.5} rad",
        v.atan2(u)
    );
    check_a_design_map_takes_the_card(tmp.path(), &data, model, angle);
}

/// A design map on the card's camera (`model = "card-…"` in the sweep's spec): its plan starts
/// from the card's effects, the stage's angle among them.
fn check_a_design_map_takes_the_card(dir: &Path, data: &Path, model: &str, angle: f64) {
    let smoke = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sweeps/smoke.toml"),
    )
    .unwrap();
    let spec = write(
        &dir.join("sweep.toml"),
        &smoke.replacen("seeds = 3", &format!("seeds = 1\nmodel = \"{model}\""), 1),
    );
    let out = dir.join("sweep");
    ffdic_ok(&[
        "sweep",
        "plan",
        &spec,
        "--out",
        out.to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
    ]);
    let plan: Value =
        serde_json::from_slice(&std::fs::read(out.join("plan.json")).unwrap()).unwrap();
    let stated = plan["base_effects"]["stage_misalignment"]["angle_rad"]
        .as_f64()
        .expect("the card's stage angle in the map's base effects");
    assert!(
        (stated - angle).abs() <= 1e-12 * angle.abs(),
        "{stated} against the card's {angle}: {}",
        plan["base_effects"]
    );
}

#[test]
fn plans_the_bench_cannot_run_are_refused_before_it_moves() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, config) = small_bench(tmp.path());
    let unknown = write(
        &tmp.path().join("unknown.toml"),
        &PLAN.replacen("[dic]", "move_size_mm = 3.0\n\n[dic]", 1),
    );
    let out = ffdic(&["calibrate", "--config", &config, "--plan", &unknown]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("move_size_mm"),
        "{err}"
    );

    let far = write(
        &tmp.path().join("far.toml"),
        &PLAN.replace("[0.5, 2.5]", "[0.5, 20.0]"),
    );
    let out = ffdic(&["calibrate", "--config", &config, "--plan", &far]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("max_motion_px"),
        "a 20 mm move is beyond what the DIC tracks: {err}"
    );
    assert!(
        !data.join("datasets").exists()
            || std::fs::read_dir(data.join("datasets"))
                .unwrap()
                .next()
                .is_none(),
        "nothing was captured"
    );
}
