//! The model against a measurement over HTTP (issue 6's API): upload a dataset whose bench has a
//! lens distortion the baseline lacks, compare, diagnose, add the winner as a model, compare again
//! — and the dataset's history shows the discrepancy fall.

use crate::common::daemon;

use daemon::{client, get, get_json, post, small_config, wait_terminal, TestServer};
use ffdic::dic::DicSettings;
use ffdic::experiment::{simulate_dataset, ExperimentSpec, MoveSpec, PatternSpec};
use ffdic::model::effects::{LensDistortion, SensorNoise, StageMisalignment};
use ffdic::model::{Camera, Effects, ModelConfig};
use ffdic::reduce::{AxisScheme, Scheme};
use serde_json::{json, Value};
use std::path::Path;

const K1: f64 = -0.003;

/// 512x512 frames at 13 px/mm of pattern a, moved 2 and 4 mm in x and 3 mm in y (translations of
/// several sizes: distortion is told from scale), on a bench with a radial distortion.
fn simulate(dir: &Path) {
    let mv = |id: &str, dx_mm: f64, dy_mm: f64| MoveSpec {
        id: id.into(),
        dx_mm,
        dy_mm,
    };
    let spec = ExperimentSpec {
        name: "distorted".into(),
        seed: 11,
        camera: Camera {
            width: 512,
            height: 512,
            scale_px_per_mm: 13.0,
            exposure_level: 0.5,
            principal_dx_px: 0.0,
            principal_dy_px: 0.0,
        },
        patterns: vec![PatternSpec::Preset("a".into())],
        moves: vec![mv("x2", 2.0, 0.0), mv("x4", 4.0, 0.0), mv("y3", 0.0, 3.0)],
        step_series: vec![],
        static_frames: 1,
        repeats: 1,
        new_layout_per_repeat: false,
        schemes: vec![],
        dic: DicSettings::default(),
    };
    let bench = ModelConfig {
        name: "bench-distorted".into(),
        description: String::new(),
        effects: Effects {
            stage_misalignment: Some(StageMisalignment { angle_rad: 0.004 }),
            lens_distortion: Some(LensDistortion::radial(K1)),
            // Signal-independent noise, as the baseline assumes: distortion is the one hidden effect.
            sensor_noise: Some(SensorNoise {
                full_well_e: 1e10,
                read_noise_e: 150.0 * 1e4,
                gain: 1e4,
            }),
            ..Effects::default()
        },
    };
    simulate_dataset(&spec, &bench, spec.seed, dir, &|_, _| {}).unwrap();
}

async fn upload(server: &TestServer, dir: &Path) -> Value {
    let mut form = reqwest::multipart::Form::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let part =
            reqwest::multipart::Part::bytes(std::fs::read(&path).unwrap()).file_name(name.clone());
        form = form.part(name, part);
    }
    let resp = client()
        .post(server.url("/datasets"))
        .multipart(form)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 201);
    resp.json().await.unwrap()
}

/// The analysis both sides get: native resolution, small subsets.
fn analysis(model: &str) -> Value {
    let one = AxisScheme {
        block: 1,
        first: 0,
        active: 1,
    };
    json!({
        "model": model,
        "schemes": [Scheme::new("native", one, one).unwrap()],
        "dic": {"subset_px": 21, "step_px": 10, "strain_window": 5}
    })
}

/// Posts a job, checks 202 + Location, waits for it and returns its record.
async fn run_job(server: &TestServer, path: &str, body: &Value) -> Value {
    let resp = client()
        .post(server.url(path))
        .json(body)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 202, "{}", resp.text().await.unwrap());
    let location = resp.headers()["location"].to_str().unwrap().to_string();
    assert!(location.starts_with("/api/v1/jobs/"), "{location}");
    let record = wait_terminal(&format!("{}{location}", server.base)).await;
    assert_eq!(record["status"], "succeeded", "{record}");
    record
}

async fn job_file(server: &TestServer, job: &Value, rel: &str) -> reqwest::Response {
    let resp = client()
        .get(server.url(&format!(
            "/jobs/{}/files/{rel}",
            job["id"].as_str().unwrap()
        )))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 200, "{rel}");
    resp
}

/// Adds `toml` as a model (`POST /models`), whatever the answer.
async fn add_model(server: &TestServer, toml: &str) -> reqwest::Response {
    post(&server.url("/models"), &json!({ "toml": toml })).await
}

/// Compares dataset `id` with `model`: the job's record and its `results/comparison.json`.
async fn compare(server: &TestServer, id: &str, model: &str) -> (Value, Value) {
    let record = run_job(
        server,
        &format!("/datasets/{id}/comparisons"),
        &analysis(model),
    )
    .await;
    let comparison = job_file(server, &record, "results/comparison.json")
        .await
        .json()
        .await
        .unwrap();
    (record, comparison)
}

/// The comparison job `record` lists plots, and the first one served is an SVG.
async fn check_first_plot_is_svg(server: &TestServer, record: &Value) {
    let svgs: Vec<&str> = record["result_files"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|f| f.as_str().filter(|f| f.starts_with("plots/")))
        .collect();
    assert!(!svgs.is_empty(), "{record}");
    let svg = job_file(server, record, svgs[0])
        .await
        .text()
        .await
        .unwrap();
    assert!(
        svg.starts_with("<svg") || svg.starts_with("<?xml"),
        "{svgs:?}"
    );
}

/// Diagnoses dataset `id` against the baseline, checks the verdict names the bench's lens
/// distortion and returns the winner's model (TOML).
async fn diagnose_lens_distortion(server: &TestServer, id: &str) -> String {
    let diag = run_job(
        server,
        &format!("/datasets/{id}/diagnoses"),
        &analysis("baseline"),
    )
    .await;
    let d: Value = job_file(server, &diag, "results/diagnosis.json")
        .await
        .json()
        .await
        .unwrap();
    assert_eq!(d["verdict"], "lens_distortion", "{d}");
    job_file(server, &diag, "results/winner-model.toml")
        .await
        .text()
        .await
        .unwrap()
}

/// One click: the winner becomes a model version; the same model twice is harmless, another
/// model under its name is a conflict, an embedded name is reserved, and a misspelt effect is
/// refused by name. Returns the stored model's name.
async fn add_the_winner(server: &TestServer, winner: &str) -> String {
    let resp = add_model(server, winner).await;
    assert_eq!(resp.status(), 201);
    let added: Value = resp.json().await.unwrap();
    let name = added["name"].as_str().unwrap().to_string();
    assert!(
        added["effects"]
            .as_array()
            .unwrap()
            .contains(&json!("lens_distortion")),
        "{added}"
    );
    assert_eq!(add_model(server, winner).await.status(), 200);
    assert_eq!(
        add_model(
            server,
            &format!("{winner}\n[effects.psf_blur]\nsigma_px = 0.5\n")
        )
        .await
        .status(),
        409
    );
    assert_eq!(
        add_model(server, &winner.replace(&name, "baseline"))
            .await
            .status(),
        409
    );
    let bad = add_model(server, "name = \"x\"\n[effects.psf_blurr]\nsigma_px = 1\n").await;
    assert_eq!(bad.status(), 422);
    assert!(bad.text().await.unwrap().contains("psf_blurr"));
    let detail: Value = get_json(&server.url(&format!("/models/{name}"))).await;
    assert_eq!(detail["source"], "stored");
    assert_eq!(detail["toml"], winner);
    name
}

/// Dataset `id`'s history: the baseline's comparison, then model `name`'s with a smaller
/// discrepancy, both of the same manifest; and its chart is served as SVG.
async fn check_history(server: &TestServer, id: &str, name: &str) {
    let history: Value = get_json(&server.url(&format!("/datasets/{id}/history"))).await;
    let entries = history["entries"].as_array().unwrap();
    assert_eq!(entries.len(), 2, "{history}");
    assert_eq!(entries[0]["model"], "baseline");
    assert_eq!(entries[1]["model"], name);
    assert!(entries[1]["discrepancy_px"].as_f64() < entries[0]["discrepancy_px"].as_f64());
    // Both compared the same manifest: one content key, its run count.
    let manifest = entries[0]["manifest_version"].as_str().unwrap();
    assert_eq!(manifest.len(), 12, "{history}");
    assert_eq!(entries[1]["manifest_version"], manifest);
    assert_eq!(entries[0]["manifest_runs"], 3, "{history}");
    let chart = get(&server.url(&format!("/datasets/{id}/history.svg"))).await;
    assert_eq!(chart.headers()["content-type"], "image/svg+xml");
}

/// A model that does not exist, and a dataset that does not: named problems, nothing queued.
async fn check_unknown_model_and_dataset_refused(server: &TestServer, id: &str) {
    let resp = post(
        &server.url(&format!("/datasets/{id}/comparisons")),
        &json!({"model": "nope"}),
    )
    .await;
    assert_eq!(resp.status(), 422);
    let problem: Value = resp.json().await.unwrap();
    assert_eq!(problem["field"], "model", "{problem}");
    let resp = post(&server.url("/datasets/ds-nope/diagnoses"), &json!({})).await;
    assert_eq!(resp.status(), 404);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn compare_diagnose_add_the_winner_and_the_history_falls() {
    let data = tempfile::tempdir().unwrap();
    let frames = tempfile::tempdir().unwrap();
    simulate(frames.path());
    let server = TestServer::start(small_config(data.path())).await;
    let dataset = upload(&server, frames.path()).await;
    let id = dataset["id"].as_str().unwrap();

    // The models a comparison can name: the embedded ones, baseline first.
    let models: Value = get_json(&server.url("/models")).await;
    assert_eq!(models[0]["name"], "baseline");
    assert_eq!(models[0]["source"], "embedded");

    let (before, cmp) = compare(&server, id, "baseline").await;
    let before_px = cmp["discrepancy_px"].as_f64().unwrap();
    assert_eq!(cmp["runs"].as_array().unwrap().len(), 3);
    check_first_plot_is_svg(&server, &before).await;

    let winner = diagnose_lens_distortion(&server, id).await;
    let name = add_the_winner(&server, &winner).await;

    let (_, cmp) = compare(&server, id, &name).await;
    let after_px = cmp["discrepancy_px"].as_f64().unwrap();
    println!("discrepancy {before_px:.5} px with baseline, {after_px:.5} px with {name}");
    assert!(after_px <= before_px / 3.0, "{before_px} → {after_px}");

    check_history(&server, id, &name).await;
    check_unknown_model_and_dataset_refused(&server, id).await;
    server.stop().await;
}

/// A model with an effect the user wrote down goes in through the API like any other, listed as
/// `user.NAME (proposed)` while its parameter has no value; an expression that reads a variable
/// it does not declare is refused with 422 naming the variable and what it may read. The same
/// for an intensity effect.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_model_with_a_user_effect_is_added_and_a_wrong_one_refused_naming_the_variable() {
    let data = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(data.path())).await;
    let bow = "name = \"bowed\"\n[effects.user.bow]\nu = \"c * (x^2 + y^2) * tx\"\nv = \"c * (x^2 + y^2) * ty\"\n[effects.user.bow.params.c]\nunit = \"1/px^2\"\nmin = -1e-7\nmax = 1e-7\n";
    let resp = add_model(&server, bow).await;
    assert_eq!(resp.status(), 201);
    let added: Value = resp.json().await.unwrap();
    assert_eq!(added["effects"], json!(["user.bow (proposed)"]), "{added}");
    let wrong = add_model(
        &server,
        &bow.replace("c * (x^2 + y^2) * ty", "k * y * ty")
            .replace("bowed", "other"),
    )
    .await;
    assert_eq!(wrong.status(), 422);
    let text = wrong.text().await.unwrap();
    assert!(
        text.contains("'k'") && text.contains("x, y, tx, ty"),
        "{text}"
    );
    // An intensity effect goes in the same way; one that is both a displacement and an
    // intensity is refused, saying to write two effects.
    let lamp = "name = \"lamp\"\n[effects.user.lamp]\nintensity = \"ax * x\"\n[effects.user.lamp.params.ax]\nunit = \"1/px\"\nmin = -1e-3\nmax = 1e-3\n";
    let resp = add_model(&server, lamp).await;
    assert_eq!(resp.status(), 201);
    let added: Value = resp.json().await.unwrap();
    assert_eq!(added["effects"], json!(["user.lamp (proposed)"]), "{added}");
    let both = add_model(
        &server,
        &lamp
            .replace("intensity = ", "u = \"ax * tx\"\nintensity = ")
            .replace("name = \"lamp\"", "name = \"both\""),
    )
    .await;
    assert_eq!(both.status(), 422);
    let text = both.text().await.unwrap();
    assert!(text.contains("write two effects"), "{text}");
}
