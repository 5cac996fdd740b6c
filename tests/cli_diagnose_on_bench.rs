//! `ffdic diagnose --on-bench` through the binary (issue 33, "resolve confounds on the bench"):
//! a dataset of the paper's design (one move, no static frames) captured on the small mock
//! bench leaves distortion and scale confounded and the sensor's noise unrevealed; the bench
//! captures designed moves (another size) and static frames, the merged dataset is diagnosed
//! again, and what the design left open is resolved. The dataset states its print nominally (a
//! preset's label), so the blur and the aperture are not fitted against the calibrated print, and
//! the bench captures no phase scan for them: it could not separate either from the print.

use crate::common::{daemon, ffdic_ok};
use ffdic::experiment::ExperimentRequest;
use ffdic::service::job::ExperimentJob;
use ffdic::service::{DaemonConfig, Service};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// One 2 mm move of target a (26 px of the 400 px frame), no static frames, on `config`'s mock
/// bench, its print stated nominally or `characterised`: the dataset's folder in the store.
fn one_move_dataset(config: &DaemonConfig, characterised: bool) -> PathBuf {
    let (service, _) = Service::start(config.clone(), daemon::small_bench(config)).unwrap();
    let request: ExperimentRequest = serde_json::from_value(json!({
        "name": "one move", "patterns": ["a"], "settle_ms": 0,
        "print_characterised": characterised,
        "moves": [{"id": "x2mm", "dx_mm": 2.0, "dy_mm": 0.0}],
        "dic": {"subset_px": 21, "step_px": 10, "strain_window": 5}
    }))
    .unwrap();
    let (record, _) = service
        .submit(ExperimentJob::plan(&service, request).unwrap(), None)
        .unwrap();
    let record = daemon::succeeded(&service, &record.id);
    let dir = service.store.dataset_dir(&record.dataset_id.unwrap());
    service.stop(Duration::from_secs(5));
    dir
}

fn effects_of(list: &Value, key: &str) -> Vec<String> {
    list.as_array()
        .unwrap()
        .iter()
        .map(|x| x[key].to_string())
        .collect()
}

/// The plan's target and designed moves (diagnose/move_design.rs): a second size for the rule,
/// the fewest that make the confounded fields differ, each within the dataset's own move.
fn check_the_designed_moves(bench: &Value) -> Vec<Value> {
    assert_eq!(bench["plan"]["patterns"], json!(["a"]));
    let moves = bench["plan"]["moves"].as_array().unwrap().clone();
    assert!(!moves.is_empty() && moves.len() <= 8, "{moves:?}");
    for m in &moves {
        let size = m["dx_mm"]
            .as_f64()
            .unwrap()
            .hypot(m["dy_mm"].as_f64().unwrap());
        assert!(size > 0.0 && size <= 2.0 + 1e-9, "{m}");
    }
    assert!(
        moves.iter().any(|m| {
            let size = m["dx_mm"]
                .as_f64()
                .unwrap()
                .hypot(m["dy_mm"].as_f64().unwrap());
            size * 1.5 <= 2.0
        }),
        "a move of another size: {moves:?}"
    );
    let pairs = bench["design"]["pairs"].to_string();
    assert!(
        pairs.contains("lens_distortion") && pairs.contains("scale"),
        "{pairs}"
    );
    moves
}

/// The small mock bench's daemon config in a folder of its own: the folder (kept while it
/// lives), the config's path, its data folder and the config.
fn small_bench_config() -> (tempfile::TempDir, PathBuf, PathBuf, DaemonConfig) {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let config_path = tmp.path().join("ffdic.toml");
    std::fs::write(&config_path, daemon::small_config_toml(&data)).unwrap();
    let config = DaemonConfig::load(&config_path).unwrap();
    (tmp, config_path, data, config)
}

#[test]
fn what_one_move_leaves_open_is_captured_on_the_bench_and_resolved() {
    let (_tmp, config_path, data, config) = small_bench_config();
    let dataset = one_move_dataset(&config, false);
    let path = |p: &Path| p.to_str().unwrap().to_string();
    let out = ffdic_ok(&[
        "diagnose",
        &path(&dataset),
        "--on-bench",
        "--config",
        &path(&config_path),
        "--data",
        &path(&data),
        "--schemes",
        "native",
        "--subset",
        "21",
        "--step",
        "10",
        "--json",
    ]);
    let doc: Value = serde_json::from_slice(&out.stdout).expect("one JSON document");
    let (before, bench, after) = (&doc["before"], &doc["on_bench"], &doc["after"]);
    let design_pairs = |d: &Value| -> Vec<String> {
        d["confounded"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|c| c["evidence"] == "design")
            .map(|c| format!("{}+{}", c["effects"][0], c["effects"][1]))
            .collect()
    };
    let distortion_scale = "\"lens_distortion\"+\"scale\"".to_string();
    assert!(
        design_pairs(before).contains(&distortion_scale),
        "one move size confounds distortion and scale: {:?}",
        design_pairs(before)
    );
    let noise = "\"sensor_noise\"".to_string();
    assert!(effects_of(&before["not_identifiable"], "effect").contains(&noise));
    // The bench was asked for moves of several sizes and static frames, at the dataset's move.
    let runs = bench["runs"].to_string();
    assert!(
        runs.contains("several_move_sizes") && runs.contains("static_repeats"),
        "{runs}"
    );
    assert!(!runs.contains("step_series"), "{runs}");
    for effect in ["\"psf_blur\"", "\"fill_factor\""] {
        assert!(
            effects_of(&before["not_identifiable"], "effect").contains(&effect.to_string()),
            "{effect} against a calibrated print"
        );
    }
    let moves = check_the_designed_moves(bench);
    // The merged dataset: the original run first, then the bench's, under their prefix, in the
    // data folder; the original folder is left as it was.
    let merged = PathBuf::from(bench["folder"].as_str().unwrap());
    let manifest: Value =
        serde_json::from_slice(&std::fs::read(merged.join("dataset.json")).unwrap()).unwrap();
    let ids: Vec<&str> = manifest["runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["id"].as_str().unwrap())
        .collect();
    assert_eq!(ids[0], "a-x2mm", "{ids:?}");
    // The original run and the designed moves.
    assert_eq!(ids.len(), 1 + moves.len(), "{ids:?}");
    assert!(
        ids[1..].iter().all(|id| id.starts_with("bench-")),
        "{ids:?}"
    );
    let original: Value =
        serde_json::from_slice(&std::fs::read(dataset.join("dataset.json")).unwrap()).unwrap();
    assert_eq!(original["runs"].as_array().unwrap().len(), 1);
    // Resolved: no design confound of distortion and scale, the noise revealed and fitted.
    assert!(
        !design_pairs(after).contains(&distortion_scale),
        "{:?}",
        design_pairs(after)
    );
    assert!(!effects_of(&after["not_identifiable"], "effect").contains(&noise));
    assert!(
        effects_of(&after["candidates"], "effect").contains(&noise),
        "the noise is fitted with the bench's static frames"
    );
    println!(
        "on the bench: {runs}; before {:?} confounded, after {:?}; verdicts {} -> {}",
        design_pairs(before),
        design_pairs(after),
        before["verdicts"],
        after["verdicts"]
    );
}

/// A request that says its print is characterised gets a dataset stating the print whole (its
/// profile beside its size, spacing, contrast and softness), which a diagnosis takes as stated;
/// without it the dataset states the print nominally (no profile), to be calibrated to the frames.
#[test]
fn an_experiment_states_a_characterised_print_whole() {
    let (_tmp, _, _, config) = small_bench_config();
    let preset = ffdic::model::SpecklePattern::preset("a").unwrap();
    for characterised in [false, true] {
        let dir = one_move_dataset(&config, characterised);
        let manifest = ffdic::dataset::Manifest::read(&dir).unwrap();
        let p = manifest.runs[0]
            .pattern
            .as_ref()
            .expect("the print is stated");
        assert_eq!(p.dot_diameter_mm, Some(preset.dot_diameter_mm));
        assert_eq!(p.contrast, Some(preset.contrast));
        assert_eq!(
            p.profile,
            characterised.then_some(preset.profile),
            "characterised: {characterised}"
        );
    }
}
