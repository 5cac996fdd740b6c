//! Issue 34: a lab's own step series made a dataset in one command (`ffdic dataset init`), then
//! compared at the camera's resolution, with the accuracy of every step against its commanded
//! move — on DIC Challenge 1.0 Sample 3 (shift_k moved by 0.1·k px in x and y).

use crate::common;

use common::{ffdic, ffdic_ok};
use std::path::Path;

fn copy_sample3(to: &Path) {
    let from = common::shared_data().join("dic-challenge-1/sample3");
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(&from).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}

/// `ffdic compare --json` of the dataset in `d` at native resolution, with no history kept.
fn compare_native_json(d: &str) -> serde_json::Value {
    let out = ffdic_ok(&[
        "compare",
        d,
        "--schemes",
        "native",
        "--json",
        "--no-history",
    ]);
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `ffdic dataset init` makes the step series in `d` a dataset (ten runs of 0.1 px steps, the
/// first frame a static repeat); once is enough: a second init does not replace the manifest
/// unless asked.
fn init_the_step_series(d: &str) {
    let init = ffdic_ok(&[
        "dataset",
        "init",
        d,
        "--scale",
        "10",
        "--repeat",
        "shift_00.tif",
        "--step-px",
        "0.1,0.1",
        "--stage-repeatability-um",
        "2",
    ]);
    let said = String::from_utf8_lossy(&init.stdout);
    assert!(
        said.contains("10 runs against reference.tif (repeats shift_00.tif)"),
        "{said}"
    );
    // Once is enough: a second init does not replace the manifest unless asked.
    let again = ffdic(&[
        "dataset",
        "init",
        d,
        "--scale",
        "10",
        "--step-px",
        "0.1,0.1",
    ]);
    assert!(!again.status.success());
    assert!(String::from_utf8_lossy(&again.stderr).contains("--force"));
}

/// Each run of the comparison (`compare --json`'s `runs`) has the commanded step k·0.1 px and
/// Sample 3's small bias and std against it, on both axes.
fn check_the_accuracy_of_every_step(runs: &[serde_json::Value]) {
    for (k, r) in runs.iter().enumerate() {
        let a = &r["accuracy"];
        let step = 0.1 * (k + 1) as f64;
        for axis in 0..2 {
            let commanded = a["commanded_px"][axis].as_f64().unwrap();
            let bias = a["bias_px"][axis].as_f64().unwrap();
            let se = a["bias_se_px"][axis].as_f64().unwrap();
            let std = a["std_px"][axis].as_f64().unwrap();
            println!(
                "{} axis {axis}: commanded {commanded:.4} bias {bias:+.5} ± {se:.5} std {std:.5}",
                r["id"]
            );
            assert!(
                (commanded - step).abs() < 1e-9,
                "{}: commanded {commanded}",
                r["id"]
            );
            // A step assigned to the wrong frame would be off by 0.1 px; Sample 3's DIC bias is
            // a few thousandths of a pixel at most.
            assert!(
                bias.abs() < 0.005 && se > 0.0 && se < 0.001,
                "{}: bias {bias} ± {se}",
                r["id"]
            );
            assert!(std > 0.0 && std < 0.01, "{}: std {std}", r["id"]);
        }
    }
}

/// The plots in `plots` of a comparison of `runs` runs: the accuracy against the commanded move
/// (a bias with its ±2 SE bar and a std per run and axis: the S-curve of a step series), the
/// summary's small multiples of the discrepancy and its three parts (a bar per run and scheme,
/// one scheme here, in each), and the residual profiles as one plot per scheme.
fn check_the_plots(plots: &Path, runs: usize) {
    let svg = std::fs::read_to_string(plots.join("accuracy_vs_commanded.svg")).unwrap();
    assert_eq!(svg.matches(r#"class="error-bar""#).count(), 2 * runs);
    assert_eq!(svg.matches(r#"class="point""#).count(), 4 * runs);
    assert!(svg.contains("bias of u") && svg.contains("std of v"));
    let summary = std::fs::read_to_string(plots.join("summary.svg")).unwrap();
    assert_eq!(summary.matches(r#"<g class="panel""#).count(), 4);
    assert_eq!(
        summary.matches(r#"class="bar""#).count(),
        4 * runs,
        "{summary}"
    );
    assert!(plots.join("residual_vs_x_native.svg").is_file());
}

/// The text output of a comparison of `runs` runs carries the accuracy table; each discrepancy
/// and part carries its standard error, or is a bound where the debiasing left zero: never a bare
/// "0.00000" that reads as perfect agreement.
fn check_the_text_table(text: &str, runs: usize) {
    let table: Vec<&str> = text
        .lines()
        .skip_while(|l| !l.starts_with("run "))
        .skip(2)
        .take(runs)
        .collect();
    assert_eq!(table.len(), runs, "{text}");
    for line in &table {
        let bare_zero = line
            .match_indices("0.00000")
            .any(|(at, _)| !line[at..].trim_start_matches(['0', '.']).starts_with(" ±"));
        assert!(!bare_zero, "{line}");
        assert!(
            line.matches(" ± ").count() + line.matches("< ").count() >= 6,
            "{line}"
        );
    }
    assert!(
        text.contains("accuracy against the commanded move")
            && text.contains("bias u [px]")
            && text.contains("the stage's repeatability 2.00 µm"),
        "{text}"
    );
}

#[test]
fn a_sample3_step_series_is_a_dataset_in_one_command_with_the_bias_of_every_step() {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("sample3");
    copy_sample3(&dir);
    let d = dir.to_str().unwrap();
    init_the_step_series(d);

    // One comparison (ten runs, each rendered and correlated: a minute of the suite) gives all
    // three: the text table, the plots and comparison.json (what `--json` prints) beside them.
    let plots = root.path().join("plots");
    let text = ffdic_ok(&[
        "compare",
        d,
        "--schemes",
        "native",
        "--no-history",
        "--out",
        plots.to_str().unwrap(),
    ]);
    let cmp: serde_json::Value =
        serde_json::from_slice(&std::fs::read(plots.join("comparison.json")).unwrap()).unwrap();
    let runs = cmp["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 10);
    check_the_accuracy_of_every_step(runs);
    check_the_plots(&plots, runs.len());
    check_the_text_table(&String::from_utf8_lossy(&text.stdout), runs.len());
}

/// The same frames as 8-bit grey PNG (re-encoded by the `png` crate from the values the `tiff`
/// crate decodes: lossless, and neither is ffdic's reader) make the same dataset: every run's
/// accuracy and the discrepancy are equal to the digit.
#[test]
fn a_step_series_in_png_frames_gives_the_numbers_of_its_tiffs() {
    let root = tempfile::tempdir().unwrap();
    let from = common::shared_data().join("dic-challenge-1/sample3");
    let (tiffs, pngs) = (root.path().join("tiff"), root.path().join("png"));
    std::fs::create_dir_all(&tiffs).unwrap();
    std::fs::create_dir_all(&pngs).unwrap();
    for stem in ["reference", "shift_00", "shift_01", "shift_03", "shift_06"] {
        let tif = from.join(format!("{stem}.tif"));
        std::fs::copy(&tif, tiffs.join(format!("{stem}.tif"))).unwrap();
        let mut decoder = tiff::decoder::Decoder::new(std::fs::File::open(&tif).unwrap()).unwrap();
        let (w, h) = decoder.dimensions().unwrap();
        let tiff::decoder::DecodingResult::U8(values) = decoder.read_image().unwrap() else {
            panic!("Sample 3 is 8-bit grey");
        };
        let file = std::fs::File::create(pngs.join(format!("{stem}.png"))).unwrap();
        let mut e = png::Encoder::new(std::io::BufWriter::new(file), w, h);
        e.set_color(png::ColorType::Grayscale);
        e.set_depth(png::BitDepth::Eight);
        e.write_header().unwrap().write_image_data(&values).unwrap();
    }
    let compare = |dir: &Path, ext: &str| -> serde_json::Value {
        let d = dir.to_str().unwrap();
        let repeat = format!("shift_00.{ext}");
        ffdic_ok(&[
            "dataset",
            "init",
            d,
            "--scale",
            "10",
            "--repeat",
            &repeat,
            "--step-px",
            "0.1,0.1",
        ]);
        compare_native_json(d)
    };
    let (t, p) = (compare(&tiffs, "tif"), compare(&pngs, "png"));
    assert_eq!(p["runs"].as_array().unwrap().len(), 3);
    assert_eq!(t["discrepancy_px"], p["discrepancy_px"]);
    for (a, b) in t["runs"]
        .as_array()
        .unwrap()
        .iter()
        .zip(p["runs"].as_array().unwrap())
    {
        assert_eq!(a["accuracy"], b["accuracy"], "{}", a["id"]);
    }
}
