//! `compare` on a dataset ffdic did not make: 8-bit frames of 256x256 px, no camera block, no
//! pattern fields (the speckle is estimated from the measured reference), no repeats.

use ffdic::diagnose::{compare, CompareOptions, BASELINE_TOML};
use ffdic::experiment::{simulate_dataset, ExperimentSpec, MoveSpec, PatternSpec};
use ffdic::image::{read_tiff, write_tiff_u8, Image};
use ffdic::model::effects::{SensorNoise, StageMisalignment};
use ffdic::model::{Camera, Effects, ModelConfig};
use std::path::Path;

#[test]
fn eight_bit_small_frames_without_optional_fields() {
    let dir = tempfile::tempdir().unwrap();
    foreign_dataset(dir.path());
    let model = ModelConfig::from_toml(BASELINE_TOML, Path::new("baseline.toml")).unwrap();
    let cmp = compare(dir.path(), &model, &CompareOptions::default(), &|_, _| true).unwrap();
    let n = &cmp.model.nominal;
    assert_eq!(n.bit_depth, 8);
    assert_eq!(n.patterns[0].source, "estimated");
    println!(
        "estimated speckle {:?}, white {:.1} DN",
        n.patterns[0].pattern, n.patterns[0].white_level_dn
    );
    // The estimate lands near the printed pattern a (0.5 mm dots at 0.75 mm).
    let p = &n.patterns[0].pattern;
    assert!((p.dot_diameter_mm / 0.5 - 1.0).abs() < 0.35, "{p:?}");
    assert_eq!(cmp.runs.len(), 3);
    for r in &cmp.runs {
        assert!(
            r.discrepancy_px.is_finite() && r.measured.summary.valid > 0,
            "{r:?}"
        );
        println!("{} {}: D {:.5} px", r.id, r.scheme, r.discrepancy_px);
    }
    // The move (13 px at full resolution, 6.5 px reduced) is recovered by the fitted stage.
    assert!(
        (n.misalignment_rad - 0.005).abs() < 0.002,
        "{}",
        n.misalignment_rad
    );
    let json = serde_json::to_value(&cmp).unwrap();
    for key in ["model", "discrepancy_px", "runs"] {
        assert!(json.get(key).is_some(), "{key}");
    }
    for key in ["id", "scheme", "discrepancy_px", "measured", "model"] {
        assert!(json["runs"][0].get(key).is_some(), "{key}");
    }
}

/// A dataset of 8-bit 256x256 frames (one 1 mm x move at 13 px/mm, pattern a) with every
/// optional manifest field stripped, in `dir`.
fn foreign_dataset(dir: &Path) {
    let spec = ExperimentSpec {
        name: "foreign".into(),
        seed: 3,
        camera: Camera {
            width: 256,
            height: 256,
            scale_px_per_mm: 13.0,
            exposure_level: 0.5,
            principal_dx_px: 0.0,
            principal_dy_px: 0.0,
        },
        patterns: vec![PatternSpec::Preset("a".into())],
        moves: vec![MoveSpec {
            id: "x1".into(),
            dx_mm: 1.0,
            dy_mm: 0.0,
        }],
        step_series: vec![],
        static_frames: 0,
        repeats: 1,
        new_layout_per_repeat: false,
        schemes: vec![],
        dic: Default::default(),
    };
    let bench = ModelConfig {
        name: "bench".into(),
        description: String::new(),
        effects: Effects {
            stage_misalignment: Some(StageMisalignment { angle_rad: 0.005 }),
            sensor_noise: Some(SensorNoise {
                full_well_e: 30000.0,
                read_noise_e: 2.0,
                gain: 0.46,
            }),
            ..Effects::default()
        },
    };
    simulate_dataset(&spec, &bench, 3, dir, &|_, _| {}).unwrap();
    // Rewrite as 8-bit frames and strip every optional field.
    for name in ["a_ref.tif", "a_x1.tif"] {
        let path = dir.join(name);
        let (img, _) = read_tiff(&path).unwrap();
        let scaled =
            Image::from_vec(256, 256, img.data().iter().map(|v| v / 257.0).collect()).unwrap();
        write_tiff_u8(&path, &scaled).unwrap();
    }
    let manifest = r#"{ "format": "ffdic-dataset/1", "name": "foreign", "scale_px_per_mm": 13.0, "lab": "elsewhere",
        "runs": [ { "id": "x1", "reference": "a_ref.tif", "deformed": "a_x1.tif", "stage": { "dx_mm": 1.0, "dy_mm": 0.0 } } ] }"#;
    std::fs::write(dir.join("dataset.json"), manifest).unwrap();
}

/// Issue 34 (3): `ffdic compare DIR --schemes native` answered "unknown scheme 'native'" while
/// the dashboard and the API offered it: a lab's own frames could only be judged on the paper's
/// 2x2 reductions. The CLI takes `native` and any BLOCKxBLOCK/APERTURE, as `ffdic reduce` does.
#[test]
fn the_cli_compares_at_native_resolution_and_on_any_block_and_aperture() {
    let dir = tempfile::tempdir().unwrap();
    foreign_dataset(dir.path());
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_ffdic"))
        .arg("compare")
        .arg(dir.path())
        .args(["--schemes", "native,2x2/1x2", "--json", "--data"])
        .arg(dir.path().join("data"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let schemes: Vec<&str> = json["runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["scheme"].as_str().unwrap())
        .collect();
    assert_eq!(schemes.len(), 2, "{schemes:?}");
    assert!(schemes.contains(&"native"), "{schemes:?}");
    assert!(
        schemes.iter().any(|s| s.starts_with("b2x2a1x2")),
        "{schemes:?}"
    );
    // A name that is neither says what is taken.
    let bad = std::process::Command::new(env!("CARGO_BIN_EXE_ffdic"))
        .arg("compare")
        .arg(dir.path())
        .args(["--schemes", "ff75", "--data"])
        .arg(dir.path().join("data"))
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("native") && err.contains("BLOCKxBLOCK/APERTURE"),
        "{err}"
    );
}

/// Issue 34 (7): `ffdic compare DIR/dataset.json` failed on "Not a directory". A dataset is
/// named by its folder or by its manifest, for `compare`, `diagnose` and `history` alike; any
/// other file is refused with what is expected.
#[test]
fn a_dataset_is_named_by_its_folder_or_by_its_manifest() {
    let dir = tempfile::tempdir().unwrap();
    foreign_dataset(dir.path());
    let manifest = dir.path().join("dataset.json");
    let ffdic = |args: &[&std::ffi::OsStr]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_ffdic"))
            .args(args)
            .output()
            .unwrap()
    };
    let data = dir.path().join("data");
    let compared = ffdic(&[
        "compare".as_ref(),
        manifest.as_os_str(),
        "--schemes".as_ref(),
        "native".as_ref(),
        "--json".as_ref(),
        "--data".as_ref(),
        data.as_os_str(),
    ]);
    assert!(
        compared.status.success(),
        "{}",
        String::from_utf8_lossy(&compared.stderr)
    );
    // Issue 34 (6): the history goes into the data folder, not the measurement folder.
    assert!(!dir.path().join("ffdic-history.jsonl").exists());
    let history = ffdic(&[
        "history".as_ref(),
        manifest.as_os_str(),
        "--json".as_ref(),
        "--data".as_ref(),
        data.as_os_str(),
    ]);
    assert!(
        history.status.success(),
        "{}",
        String::from_utf8_lossy(&history.stderr)
    );
    let entries: serde_json::Value = serde_json::from_slice(&history.stdout).unwrap();
    assert_eq!(entries.as_array().map(Vec::len), Some(1), "{entries}");
    let frame = dir.path().join("a_ref.tif");
    let refused = ffdic(&["diagnose".as_ref(), frame.as_os_str()]);
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        err.contains("a_ref.tif") && err.contains("dataset.json"),
        "{err}"
    );
}
