//! The dashboard end to end in a real browser: headless Debian `chromium`, driven by
//! `tests/browser/dashboard.mjs` (playwright-core from npm, pinned in its package-lock.json),
//! against the daemon on 127.0.0.1 port 0 with the small mock bench. The script starts an
//! experiment from the form and sees its progress reach 100 % and both bar charts with
//! patterns × schemes bars; uploads a dataset whose bench has a lens distortion the baseline model
//! lacks; diagnoses it and sees the verdict; adds the winner and sees the history chart gain a
//! lower point; reloads the page and reopens those jobs; uploads a second dataset of the same bench
//! (another seed) and adds its winner, which must get a name of its own (issue 13); starts the
//! smoke design map from the home page and sees its recommendations, heat maps with the paper's
//! points, bias plots and cells (issue 15); starts a calibration from the home page and sees its
//! camera card: the stored model, the stage's map, the discrepancy with its SEs (issue 33); diagnoses
//! a one-move dataset and resolves its confounds on the bench (issue 33). Screenshots
//! land in `target/browser-artifacts/`.
//!
//! Needs `node`, `/usr/bin/chromium` and `npm ci --prefix tests/browser` (scripts/test-all.sh
//! installs all three). Missing any of them is a failure, not a skip: CI has them.

use crate::common::daemon;

use daemon::{client, small_config, TestServer};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// One pattern, a reference repeat and three moves (x, larger x, y): what makes a lens
/// distortion identifiable and tells it from rotation and scale (see tests/hidden_effect.rs).
/// The seed comes first, from [`simulate`]: two seeds make two datasets of one bench.
const EXPERIMENT_TOML: &str = r#"
name = "hidden-lens"
patterns = ["a"]
static_frames = 1
schemes = ["ff100"]

[camera]
width = 512
height = 512
scale_px_per_mm = 13.0
exposure_level = 0.5

[[moves]]
id = "x2"
dx_mm = 2.0
dy_mm = 0.0

[[moves]]
id = "x4"
dx_mm = 4.0
dy_mm = 0.0

[[moves]]
id = "y3"
dx_mm = 0.0
dy_mm = 3.0
"#;

/// The bench: misaligned stage, a barrel distortion, a flat sensor noise (what the baseline
/// assumes). The baseline model lacks only the distortion.
const BENCH_TOML: &str = r#"
name = "bench-hidden-lens"
description = "a bench whose lens distorts (k1 = -0.003), which the baseline model lacks"

[effects.stage_misalignment]
angle_rad = 0.004

[effects.lens_distortion]
k1 = -0.003

[effects.sensor_noise]
full_well_e = 1e10
read_noise_e = 1.5e6
gain = 1e4
"#;

const CHROMIUM: &str = "/usr/bin/chromium";

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn artefact_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join("target"));
    target.join("browser-artifacts")
}

/// Fails with what to install when the browser tooling is missing.
fn require_tools() {
    let node = Command::new("node").arg("--version").output();
    assert!(
        node.as_ref().is_ok_and(|o| o.status.success()),
        "the dashboard browser test needs Node.js (`node` on PATH; Debian: apt-get install nodejs npm): {:?}",
        node.err()
    );
    assert!(
        Path::new(CHROMIUM).exists(),
        "the dashboard browser test needs {CHROMIUM} (Debian: apt-get install chromium)"
    );
    let driver = repo().join("tests/browser/node_modules/playwright-core/package.json");
    assert!(
        driver.exists(),
        "the dashboard browser test needs playwright-core: run `npm ci --prefix tests/browser` \
         (scripts/test-all.sh does) — {} is missing",
        driver.display()
    );
}

fn simulate(dir: &Path, seed: u64) -> PathBuf {
    let experiment = dir.join(format!("experiment-{seed}.toml"));
    std::fs::write(&experiment, format!("seed = {seed}\n{EXPERIMENT_TOML}")).unwrap();
    std::fs::write(dir.join("bench.toml"), BENCH_TOML).unwrap();
    let out = dir.join(format!("dataset-{seed}"));
    let status = Command::new(env!("CARGO_BIN_EXE_ffdic"))
        .args(["simulate", "--experiment"])
        .arg(&experiment)
        .arg("--model")
        .arg(dir.join("bench.toml"))
        .arg("--out")
        .arg(&out)
        .env("RUST_LOG", "warn")
        .status()
        .unwrap();
    assert!(status.success(), "ffdic simulate failed");
    out
}

/// The pages and assets are served before any browser is involved: the home page as HTML with a
/// content security policy, every page and script, and 404 for an asset that does not exist.
async fn check_the_pages_are_served(server: &TestServer) {
    let home = client()
        .get(format!("{}/", server.base))
        .send()
        .await
        .unwrap();
    assert_eq!(home.status(), 200);
    assert!(home.headers()["content-type"]
        .to_str()
        .unwrap()
        .starts_with("text/html"));
    assert!(home.headers().contains_key("content-security-policy"));
    for path in [
        "/experiments/x",
        "/datasets/x",
        "/sweeps/x",
        "/assets/home.js",
        "/assets/sweep.js",
    ] {
        let r = client()
            .get(format!("{}{path}", server.base))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200, "{path}");
    }
    let missing = client()
        .get(format!("{}/assets/nope.js", server.base))
        .send()
        .await
        .unwrap();
    assert_eq!(missing.status(), 404);
}

/// What the browser saw, checked once more through the API: the uploaded dataset's history fell.
async fn check_the_history_fell(server: &TestServer) {
    let datasets: Vec<Value> = client()
        .get(server.url("/datasets"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let uploaded = datasets
        .iter()
        .rev()
        .find(|d| d["source"] == "upload")
        .expect("the upload made a dataset");
    let history: Value = client()
        .get(server.url(&format!(
            "/datasets/{}/history",
            uploaded["id"].as_str().unwrap()
        )))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let d: Vec<f64> = history["entries"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["discrepancy_px"].as_f64().unwrap())
        .collect();
    assert!(d.len() >= 2, "{history}");
    assert!(d[d.len() - 1] < d[0], "{history}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dashboard_in_headless_chromium() {
    require_tools();
    let work = tempfile::tempdir().unwrap();
    let dataset = simulate(work.path(), 11);
    // The same bench again, another speckle layout and noise: the diagnosis finds the same effect
    // with other fitted parameters, so its winner is another model under the same name.
    let second = simulate(work.path(), 12);
    let data = work.path().join("data");
    let server = TestServer::start(small_config(&data)).await;
    check_the_pages_are_served(&server).await;

    let artefacts = artefact_dir();
    let script = repo().join("tests/browser/dashboard.mjs");
    let base = server.base.clone();
    let t = Instant::now();
    let status = tokio::task::spawn_blocking(move || {
        Command::new("node")
            .arg(&script)
            .arg(&base)
            .arg(&dataset)
            .arg(&artefacts)
            .arg("lens_distortion")
            .arg(&second)
            .status()
            .unwrap()
    })
    .await
    .unwrap();
    println!("browser script: {:.1} s", t.elapsed().as_secs_f64());
    assert!(
        status.success(),
        "the dashboard failed in the browser ({status}); screenshots in {}",
        artefact_dir().display()
    );

    check_the_history_fell(&server).await;
    for shot in [
        "1-home",
        "2-experiment",
        "3-dataset-compared",
        "4-dataset-diagnosed",
        "5-dataset-winner-added",
        "6-dataset-reloaded",
        "7-second-dataset-added",
        "8-sweep",
        "9-on-bench",
    ] {
        assert!(
            artefact_dir().join(format!("{shot}.png")).is_file(),
            "{shot}"
        );
    }
    server.stop().await;
}
