//! `ffdic analyze` as a user runs it: JSON on stdout, files in --out, one-line errors.

use crate::common;

use common::{ffdic, ffdic_ok};
use ffdic::image::{write_tiff_u16, Image};
use std::path::{Path, PathBuf};
use std::process::Output;

fn sample3(name: &str) -> String {
    common::shared_data()
        .join("dic-challenge-1/sample3")
        .join(name)
        .to_string_lossy()
        .into_owned()
}

fn stderr_line(out: &Output) -> String {
    let s = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        s.trim_end().lines().count(),
        1,
        "one-line error expected, got: {s}"
    );
    assert!(!s.contains("panicked"), "{s}");
    s
}

#[test]
fn json_document_has_the_documented_shape() {
    let out = ffdic_ok(&[
        "analyze",
        &sample3("reference.tif"),
        &sample3("shift_05.tif"),
        "--json",
    ]);
    assert!(out.stderr.is_empty(), "nothing but JSON when --json");
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON document");
    assert_eq!(doc["points"], 576);
    assert_eq!(doc["valid"], 576);
    for field in ["u", "v", "exx", "eyy", "exy"] {
        for stat in ["mean", "std", "min", "max"] {
            assert!(doc[field][stat].is_f64(), "{field}.{stat}");
        }
    }
    assert!((doc["u"]["mean"].as_f64().unwrap() - 0.5).abs() < 0.002);
    assert!(doc["elapsed_s"].as_f64().unwrap() > 0.0);
    assert_eq!(doc["settings"]["dic"]["subset_px"], 41);
    assert_eq!(doc["settings"]["strain_gauge_px"], 161);
}

/// Issue 34 (4): the core question — how far is the measured move from the commanded one? —
/// had no answer: `analyze` had no `--expected`. Sample 3's truth is (0.5, 0.5) px for shift_05.
#[test]
fn the_bias_against_the_commanded_move_comes_with_its_interval() {
    let run = |expected: &str, json: bool| {
        let mut args = vec![
            "analyze".to_string(),
            sample3("reference.tif"),
            sample3("shift_05.tif"),
            "--expected".into(),
            expected.into(),
        ];
        if json {
            args.push("--json".into());
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = ffdic(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        out
    };
    let doc: serde_json::Value = serde_json::from_slice(&run("0.5,0.5", true).stdout).unwrap();
    for axis in ["u", "v"] {
        let b = &doc["bias"][axis];
        let (mean, bias) = (
            b["mean_px"].as_f64().unwrap(),
            b["bias_px"].as_f64().unwrap(),
        );
        assert_eq!(mean, doc[axis]["mean"].as_f64().unwrap());
        assert_eq!(bias, mean - 0.5);
        // The engine's accuracy on Sample 3 (tests/dic_sample3.rs).
        assert!(bias.abs() < 0.002, "{axis}: {b}");
        let (lo, hi) = (
            b["bias_ci95_px"][0].as_f64().unwrap(),
            b["bias_ci95_px"][1].as_f64().unwrap(),
        );
        assert!(lo < bias && bias < hi && hi - lo < 0.01, "{axis}: {b}");
        assert_eq!(b["valid_points"], 576);
    }
    // A move commanded 0.1 px shorter than made: a bias of +0.1 px, far outside its interval.
    let doc: serde_json::Value = serde_json::from_slice(&run("0.4,0.5", true).stdout).unwrap();
    let b = &doc["bias"]["u"];
    assert!((b["bias_px"].as_f64().unwrap() - 0.1).abs() < 0.002, "{b}");
    assert!(b["bias_ci95_px"][0].as_f64().unwrap() > 0.09, "{b}");
    let text = String::from_utf8(run("-0.5,0.5", false).stdout).unwrap();
    assert!(text.contains("against the commanded move"), "{text}");
    assert!(text.contains("expected   -0.50000"), "{text}");
    let bad = ffdic(&[
        "analyze",
        &sample3("reference.tif"),
        &sample3("shift_05.tif"),
        "--expected",
        "0.5",
    ]);
    assert!(stderr_line(&bad).contains("expected U,V"));
}

#[test]
fn out_folder_gets_points_and_settings() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("res");
    ffdic_ok(&[
        "analyze",
        &sample3("reference.tif"),
        &sample3("shift_02.tif"),
        "--subset",
        "31",
        "--step",
        "25",
        "--roi",
        "50,60,400,380",
        "--strain-window",
        "5",
        "--interp",
        "bspline5",
        "--threads",
        "1",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    let csv = std::fs::read_to_string(out_dir.join("points.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        "x,y,u,v,exx,eyy,exy,zncc,u_std_px,v_std_px,iterations,status"
    );
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), 17 * 16);
    assert!(rows.iter().all(|r| r.ends_with(",converged")));
    let settings: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("settings.json")).unwrap())
            .unwrap();
    assert_eq!(settings["dic"]["subset_px"], 31);
    assert_eq!(settings["dic"]["interpolation"], "bspline5");
    assert_eq!(settings["strain_gauge_px"], 4 * 25 + 31);
    assert_eq!(settings["ffdic_version"], ffdic::VERSION);
}

fn write_image(dir: &Path, name: &str, w: usize, h: usize) -> PathBuf {
    let p = dir.join(name);
    let layout = common::layout(w, h, 5);
    write_tiff_u16(&p, &common::render(&layout, w, h)).unwrap();
    p
}

#[test]
fn bad_inputs_give_one_line_errors_and_a_failure_exit() {
    let dir = tempfile::tempdir().unwrap();
    let a = write_image(dir.path(), "a.tif", 200, 160);
    let b = write_image(dir.path(), "b.tif", 180, 160);
    let corrupt = dir.path().join("corrupt.tif");
    let bytes = std::fs::read(&a).unwrap();
    std::fs::write(&corrupt, &bytes[..bytes.len() / 3]).unwrap();
    let (a, b, corrupt) = (
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        corrupt.to_str().unwrap(),
    );
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["analyze", "/nonexistent.tif", a], "cannot open"),
        (vec!["analyze", a, corrupt], "not a readable TIFF"),
        (vec!["analyze", a, b], "same size"),
        (vec!["analyze", a, a, "--roi", "500,10,50,50"], "outside"),
        (
            vec!["analyze", a, a, "--roi", "60,60,30,30"],
            "larger than the ROI",
        ),
        (vec!["analyze", a, a, "--subset", "40"], "odd"),
        (vec!["analyze", a, a, "--strain-window", "4"], "odd"),
        (vec!["analyze", a, a, "--interp", "linear"], "bspline3"),
    ];
    for (args, needle) in cases {
        let out = ffdic(&args);
        assert!(!out.status.success(), "{args:?} should fail");
        let line = stderr_line(&out);
        assert!(line.contains(needle), "{args:?}: '{line}' lacks '{needle}'");
        assert!(out.stdout.is_empty());
    }
}

/// A flat region is a point status, not an error; but a run that keeps no point at all exits
/// non-zero with one line naming the likely cause — after writing everything it computed.
#[test]
fn no_valid_point_exits_non_zero_naming_the_cause_with_everything_written() {
    let dir = tempfile::tempdir().unwrap();
    let img = Image::filled(200, 160, 1000.0);
    let p = dir.path().join("flat.tif");
    write_tiff_u16(&p, &img).unwrap();
    let out = ffdic(&[
        "analyze",
        p.to_str().unwrap(),
        p.to_str().unwrap(),
        "--json",
        "--out",
        dir.path().join("r").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let line = stderr_line(&out);
    assert!(
        line.contains("no valid point") && line.contains("no_contrast") && line.contains("texture"),
        "{line}"
    );
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["valid"], 0);
    let csv = std::fs::read_to_string(dir.path().join("r/points.csv")).unwrap();
    assert!(csv.lines().skip(1).all(|l| l.ends_with(",no_contrast")));

    // Two unrelated speckle images: nothing correlates.
    let a = write_image(dir.path(), "a.tif", 200, 160);
    let other = dir.path().join("other.tif");
    write_tiff_u16(
        &other,
        &common::render(&common::layout(200, 160, 99), 200, 160),
    )
    .unwrap();
    let out = ffdic(&[
        "analyze",
        a.to_str().unwrap(),
        other.to_str().unwrap(),
        "--json",
    ]);
    assert!(!out.status.success());
    let line = stderr_line(&out);
    assert!(
        line.contains("no valid point") && line.contains("same speckle"),
        "{line}"
    );
}

#[test]
fn a_sequence_accumulates_frame_by_frame() {
    // Sample 3's frames shifted by 0.1 px steps in x and y, given as a list and as a folder.
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    std::fs::create_dir(&frames).unwrap();
    for k in 1..=3 {
        let name = format!("shift_0{k}.tif");
        std::fs::copy(sample3(&name), frames.join(&name)).unwrap();
    }
    let out_dir = dir.path().join("res");
    for deformed in [
        vec![
            frames.join("shift_01.tif"),
            frames.join("shift_02.tif"),
            frames.join("shift_03.tif"),
        ],
        vec![frames.clone()],
    ] {
        let mut args = vec!["analyze".to_string(), sample3("reference.tif")];
        args.extend(deformed.iter().map(|p| p.to_string_lossy().into_owned()));
        args.extend(["--json", "--out"].map(String::from));
        args.push(out_dir.to_string_lossy().into_owned());
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = ffdic(&refs);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let frames_doc = doc["frames"].as_array().unwrap();
        assert_eq!(frames_doc.len(), 3);
        for (k, f) in frames_doc.iter().enumerate() {
            let shift = 0.1 * (k + 1) as f64;
            assert_eq!(f["index"], k + 1);
            assert_eq!(f["valid"], f["points"], "{f}");
            assert!(
                (f["u"]["mean"].as_f64().unwrap() - shift).abs() < 0.003,
                "{f}"
            );
            assert!(
                (f["v"]["mean"].as_f64().unwrap() - shift).abs() < 0.003,
                "{f}"
            );
        }
        for k in 1..=3 {
            assert!(out_dir.join(format!("points_{k:04}.csv")).is_file());
        }
    }
}

#[test]
fn thresholds_and_polygon_masks_are_settable() {
    let dir = tempfile::tempdir().unwrap();
    let polygons = dir.path().join("mask.json");
    // Sample 3 is 512x512 with points 25..=485 at the defaults: exclude the left half.
    std::fs::write(
        &polygons,
        r#"{"exclude": [[[0, 0], [255, 0], [255, 511], [0, 511]]]}"#,
    )
    .unwrap();
    let out = ffdic(&[
        "analyze",
        &sample3("reference.tif"),
        &sample3("shift_05.tif"),
        "--mask-polygons",
        polygons.to_str().unwrap(),
        "--min-zncc",
        "0.99999",
        "--json",
    ]);
    // No point survives: the run fails, names why, and still prints its document.
    assert!(!out.status.success());
    let line = stderr_line(&out);
    assert!(
        line.contains("288 of 288 analysed points low_correlation; 288 masked")
            && line.contains("--min-zncc 0.99999"),
        "{line}"
    );
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let masked = doc["statuses"]["masked"].as_u64().unwrap();
    assert_eq!(masked, 24 * 12, "{doc}");
    // Noisy images never correlate to 0.99999: every analysed point is refused.
    assert_eq!(doc["valid"], 0, "{doc}");
    assert_eq!(doc["settings"]["dic"]["min_zncc"], 0.99999);
    let out = ffdic(&[
        "analyze",
        &sample3("reference.tif"),
        &sample3("shift_05.tif"),
        "--min-zncc",
        "2",
    ]);
    assert!(!out.status.success());
    assert!(stderr_line(&out).contains("min_zncc"));
}

#[test]
fn the_second_order_shape_function_is_selectable() {
    let out = ffdic_ok(&[
        "analyze",
        &sample3("reference.tif"),
        &sample3("shift_05.tif"),
        "--shape",
        "quadratic",
        "--json",
    ]);
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["settings"]["shape_function"], "quadratic");
    assert_eq!(doc["valid"], doc["points"], "{doc}");
    assert!(
        (doc["u"]["mean"].as_f64().unwrap() - 0.5).abs() < 0.003,
        "{doc}"
    );
    let out = ffdic(&[
        "analyze",
        &sample3("reference.tif"),
        &sample3("shift_05.tif"),
        "--shape",
        "cubic",
    ]);
    assert!(!out.status.success());
    assert!(stderr_line(&out).contains("cubic"));
}

/// An ROI that reaches beyond the image is analysed inside it, and the output says so.
#[test]
fn an_roi_partly_outside_the_image_is_reported_not_clipped_in_silence() {
    let dir = tempfile::tempdir().unwrap();
    let a = write_image(dir.path(), "a.tif", 200, 160);
    let a = a.to_str().unwrap();
    let out = ffdic_ok(&[
        "analyze",
        a,
        a,
        "--roi",
        "100,100,200,200",
        "--subset",
        "21",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--roi 100,100,200,200 reaches beyond the 200x160 image")
            && stderr.contains("analysed inside 100,100,100,60")
            && stderr.contains("points)"),
        "{stderr}"
    );
}

/// With the images' scale, points.csv carries positions and displacements in mm beside px, and
/// settings.json says what the strain columns are.
#[test]
fn a_scale_adds_mm_columns_and_the_strain_is_defined() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("res");
    ffdic_ok(&[
        "analyze",
        &sample3("reference.tif"),
        &sample3("shift_02.tif"),
        "--roi",
        "100,100,200,200",
        "--step",
        "50",
        "--scale",
        "20",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    let csv = std::fs::read_to_string(out_dir.join("points.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(&header[12..], ["x_mm", "y_mm", "u_mm", "v_mm"]);
    for row in lines {
        let f: Vec<&str> = row.split(',').collect();
        let num = |i: usize| f[i].parse::<f64>().unwrap();
        assert!((num(12) - num(0) / 20.0).abs() < 1e-12 && (num(14) - num(2) / 20.0).abs() < 1e-12);
    }
    let settings: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("settings.json")).unwrap())
            .unwrap();
    assert_eq!(settings["scale_px_per_mm"], 20.0);
    assert!(settings["strain"].as_str().unwrap().contains("du/dx"));
    let bad = ffdic(&[
        "analyze",
        &sample3("reference.tif"),
        &sample3("shift_02.tif"),
        "--scale",
        "0",
    ]);
    assert!(!bad.status.success() && stderr_line(&bad).contains("px per mm"));
}
