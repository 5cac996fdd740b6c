//! The `exec` camera with the independent generator behind it (issue 33): the daemon's bench,
//! opened from a config naming `kind = "exec"`, runs an experiment whose every frame is one
//! `generate.py --frame` call told the stage's position, the mounted target and the frame index;
//! each captured frame equals the generator's own dataset frame for that position bit for bit.
//! And a command that fails leaves a clear error while the bench goes on.

#[path = "common/folder_sink.rs"]
mod folder_sink;
#[path = "common/independent.rs"]
mod independent;

use folder_sink::FolderSink;

use ffdic::dic::DicSettings;
use ffdic::experiment::{
    run_experiment, BenchGeometry, BenchHandle, BenchLimits, BenchTimeouts, ExperimentRequest,
    MoveSpec, PatternSpec,
};
use ffdic::service::{open_bench, DaemonConfig};
use serde_json::json;
use std::path::Path;
use std::time::Duration;

const SCALE_PX_PER_MM: f64 = 13.0;

/// A daemon config whose camera is `command`, 640x540 16-bit, on the mock stage.
fn config(data: &Path, command: &[String]) -> DaemonConfig {
    let text = format!(
        r#"
data_dir = {data:?}
listen = "127.0.0.1:0"
[bench]
scale_px_per_mm = {SCALE_PX_PER_MM}
frame_timeout_ms = 60000
[camera]
kind = "exec"
command = {command}
width = 640
height = 540
bit_depth = 16
timeout_ms = 60000
[stage]
kind = "mock"
speed_mm_s = 200.0
settle_ms = 1
"#,
        command = serde_json::to_string(command).unwrap(),
    );
    DaemonConfig::from_toml(&text, Path::new("exec.toml")).unwrap()
}

fn grey(path: &Path) -> Vec<f32> {
    let (image, _) = ffdic::image::read_tiff(path).unwrap();
    image.data().to_vec()
}

#[test]
fn an_experiment_through_the_exec_camera_captures_the_generators_frames_bit_for_bit() {
    let root = tempfile::tempdir().unwrap();
    // The generator's spec: one print 'a', the experiment's moves, one static repeat.
    let spec = json!({
        "name": "exec", "seed": 3301,
        "width": 640, "height": 540, "scale_px_per_mm": SCALE_PX_PER_MM, "bit_depth": 16,
        "white_level_dn": 30000.0, "read_noise_dn": 20.0,
        "patterns": [{"label": "a", "dot_diameter_mm": 0.3, "dot_spacing_mm": 0.45, "contrast": 0.7}],
        "moves": [{"id": "x2", "dx_mm": 2.0, "dy_mm": 0.0}, {"id": "y1", "dx_mm": 0.0, "dy_mm": 1.5}],
        "step_series": [],
        "repeats": 1,
        "stage": {"constant_offset_px": [0.2, -0.1], "repeatability_um": 3.0},
        "effects": {"k1_norm": -0.002}
    });
    let spec_path = root.path().join("spec.json");
    std::fs::write(&spec_path, spec.to_string()).unwrap();
    let expected = root.path().join("dataset");
    independent::generate(&spec, &expected);

    let generator = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/independent/generate.py");
    let command = vec![
        independent::python().display().to_string(),
        generator.display().to_string(),
        spec_path.display().to_string(),
        "--frame".into(),
    ];
    let hardware = open_bench(&config(root.path(), &command)).unwrap();
    let bench = BenchHandle::spawn(hardware, Duration::from_secs(30));
    let status = bench.status().unwrap();
    assert!(status.has_target_mount, "the exec camera's target changer");
    let limits = BenchLimits {
        scale_px_per_mm: SCALE_PX_PER_MM,
        target_field_mm: None,
        travel_x_mm: Some((-25.0, 25.0)),
        travel_y_mm: Some((-25.0, 25.0)),
        exposure_us: (10.0, 1e6),
        hardware_schemes: Vec::new(),
    };
    let request = ExperimentRequest {
        name: "exec".into(),
        patterns: vec![PatternSpec::Preset("a".into())],
        moves: vec![
            MoveSpec {
                id: "x2".into(),
                dx_mm: 2.0,
                dy_mm: 0.0,
            },
            MoveSpec {
                id: "y1".into(),
                dx_mm: 0.0,
                dy_mm: 1.5,
            },
        ],
        step_series: Vec::new(),
        static_frames: 1,
        dic: DicSettings {
            subset_px: 21,
            step_px: 20,
            ..DicSettings::default()
        },
        ..ExperimentRequest::default()
    };
    let plan = request.plan(&limits).expect("a valid plan");
    let out = tempfile::tempdir().unwrap();
    let sink = FolderSink::new(out.path());
    let lease = bench.hold("exec").unwrap();
    let outcome = run_experiment(
        &plan,
        &bench,
        &lease,
        BenchGeometry {
            scale_px_per_mm: SCALE_PX_PER_MM,
            working_distance_mm: Some(300.0),
        },
        BenchTimeouts::default(),
        &sink,
    )
    .unwrap_or_else(|e| panic!("{e}; events {:?}", sink.events.lock().unwrap()));
    drop(lease);

    let generated: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(expected.join("dataset.json")).unwrap())
            .unwrap();
    let file_at = |dx: f64, dy: f64| -> String {
        generated["runs"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["stage"]["dx_mm"] == dx && r["stage"]["dy_mm"] == dy)
            .unwrap_or_else(|| panic!("a generated run at ({dx}, {dy})"))["deformed"]
            .as_str()
            .unwrap()
            .to_string()
    };
    // The bench's stated working distance goes into the dataset it exports.
    assert_eq!(outcome.manifest.working_distance_mm, Some(300.0));
    let runs = &outcome.manifest.runs;
    assert_eq!(runs.len(), 2, "{runs:?}");
    let reference = outcome.frames_dir.join(&runs[0].reference);
    assert_eq!(
        grey(&reference),
        grey(&expected.join("a_ref.tif")),
        "the reference"
    );
    for r in runs {
        let captured = grey(&outcome.frames_dir.join(&r.deformed));
        let want = grey(&expected.join(file_at(r.stage.dx_mm, r.stage.dy_mm)));
        assert!(captured == want, "run {}: not the generator's frame", r.id);
    }
    let repeat = runs[0].repeat.first().expect("the static frame");
    assert_eq!(
        grey(&outcome.frames_dir.join(repeat)),
        grey(&expected.join("a_ref_r1.tif")),
        "the static repeat"
    );
    // The DIC saw the commanded moves (with the generator's stage offsets: within a pixel).
    let ff100 = outcome
        .rows
        .iter()
        .find(|row| row.run.ends_with("x2") && row.scheme == "ff100")
        .unwrap_or_else(|| panic!("an ff100 row of x2 in {:?}", outcome.rows));
    let want = 2.0 * SCALE_PX_PER_MM / 2.0;
    assert!(
        (ff100.summary.u.mean - want).abs() < 1.0,
        "{} vs {want}",
        ff100.summary.u.mean
    );
}

#[test]
fn a_failing_command_fails_the_capture_and_the_bench_goes_on() {
    let root = tempfile::tempdir().unwrap();
    let flag = root.path().join("fail");
    std::fs::write(&flag, "").unwrap();
    let command: Vec<String> = vec![
        "sh".into(),
        "-c".into(),
        format!(
            "if [ -e '{}' ]; then echo 'renderer: no such print' >&2; exit 2; fi; exit 0",
            flag.display()
        ),
    ];
    let bench = BenchHandle::spawn(
        open_bench(&config(root.path(), &command)).unwrap(),
        Duration::from_secs(30),
    );
    let owner = ffdic::experiment::Owner::Direct;
    let err = bench
        .capture(owner.clone(), 1, Duration::from_secs(10))
        .unwrap_err()
        .to_string();
    assert!(err.contains("renderer: no such print"), "{err}");
    std::fs::remove_file(&flag).unwrap();
    // Exits 0 and writes nothing now: a clear error again, and the actor still answers.
    let err = bench
        .capture(owner, 1, Duration::from_secs(10))
        .unwrap_err()
        .to_string();
    assert!(err.contains("wrote no frame"), "{err}");
    assert!(bench.status().is_ok() && bench.is_alive());
}

/// With `frame_travel_mm` in its spec the generator lays one print over the whole travel: the
/// dataset's reference and a single-frame call's are the same frame, and a frame far from every
/// run of the spec is speckle to its corners (what a calibration's moves need).
#[test]
fn the_generators_print_covers_the_stated_travel_in_both_modes() {
    let root = tempfile::tempdir().unwrap();
    let spec = json!({
        "name": "travel", "seed": 3302,
        "width": 320, "height": 270, "scale_px_per_mm": SCALE_PX_PER_MM, "bit_depth": 16,
        "white_level_dn": 30000.0, "read_noise_dn": 20.0,
        "patterns": [{"label": "a", "dot_diameter_mm": 0.3, "dot_spacing_mm": 0.45, "contrast": 0.7}],
        "moves": [{"id": "x1", "dx_mm": 1.0, "dy_mm": 0.0}],
        "step_series": [],
        "repeats": 0,
        "frame_travel_mm": [-6.0, 6.0, -5.0, 5.0]
    });
    let spec_path = root.path().join("spec.json");
    std::fs::write(&spec_path, spec.to_string()).unwrap();
    let dataset = root.path().join("dataset");
    independent::generate(&spec, &dataset);
    let generator = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/independent/generate.py");
    let frame = |x: &str, y: &str, out: &Path| {
        let status = std::process::Command::new(independent::python())
            .arg(&generator)
            .arg(&spec_path)
            .arg("--frame")
            .envs([
                ("FFDIC_X_MM", x),
                ("FFDIC_Y_MM", y),
                ("FFDIC_TARGET", "a"),
                ("FFDIC_FRAME", "0"),
            ])
            .env("FFDIC_OUT", out)
            .status()
            .unwrap();
        assert!(status.success());
        grey(out)
    };
    let reference = frame("0.0", "0.0", &root.path().join("ref.tif"));
    assert_eq!(reference, grey(&dataset.join("a_ref.tif")));
    let far = frame("5.5", "-4.5", &root.path().join("far.tif"));
    // Every 40-px block at the far corner holds speckle: its std well above the read noise.
    let (w, h) = (320usize, 270usize);
    for (bx, by) in [(0, 0), (w - 40, 0), (0, h - 40), (w - 40, h - 40)] {
        let block: Vec<f64> = (by..by + 40)
            .flat_map(|y| (bx..bx + 40).map(move |x| (x, y)))
            .map(|(x, y)| far[y * w + x] as f64)
            .collect();
        let mean = block.iter().sum::<f64>() / block.len() as f64;
        let sd =
            (block.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / block.len() as f64).sqrt();
        assert!(
            sd > 1000.0,
            "block at ({bx}, {by}): std {sd} DN: no speckle"
        );
    }
}
