//! The daemon over real HTTP on a loopback port: a whole experiment on the mock bench, events in
//! order over SSE with resume, downloads, the run folder against the index, cancellation,
//! queueing, idempotency, and the bench refusing direct control while an experiment holds it.

use crate::common::daemon;

use daemon::{
    client, get, get_json, post, read_events, small_config, small_request, wait_terminal,
    wait_until, TestServer,
};
use serde_json::{json, Value};

/// The daemon is healthy and takes a two-move experiment with 202 and its Location; returns the
/// run's id.
async fn start_a_two_move_experiment(server: &TestServer) -> String {
    assert_eq!(get(&server.url("/health")).await.status(), 200);
    let r = post(&server.url("/experiments"), &small_request(2)).await;
    assert_eq!(r.status(), 202);
    let location = r.headers()["location"].to_str().unwrap().to_string();
    let run: Value = r.json().await.unwrap();
    let id = run["id"].as_str().unwrap().to_string();
    assert_eq!(location, format!("/api/v1/experiments/{id}"));
    id
}

/// Run `id`'s events: in order, ending with the terminal one, progress never falling, one per
/// frame and pair; resuming after an id replays exactly what came after it. Returns them.
async fn check_the_events_and_their_resumption(server: &TestServer, id: &str) -> Vec<daemon::Sse> {
    // Events arrive in order, end with the terminal one, progress never falls.
    let events = read_events(
        &server.url(&format!("/experiments/{id}/events")),
        None,
        10_000,
    )
    .await;
    let kinds: Vec<&str> = events.iter().map(|e| e.kind.as_str()).collect();
    assert_eq!(kinds.first(), Some(&"queued"), "{kinds:?}");
    assert_eq!(kinds.last(), Some(&"succeeded"), "{kinds:?}");
    for k in ["started", "stage_moved", "frame_captured", "pair_analyzed"] {
        assert!(kinds.contains(&k), "{k} missing from {kinds:?}");
    }
    assert!(
        events.windows(2).all(|w| w[1].id == w[0].id + 1),
        "ids consecutive"
    );
    let progress: Vec<f64> = events
        .iter()
        .map(|e| e.data["progress"].as_f64().unwrap())
        .collect();
    assert!(
        progress.windows(2).all(|w| w[1] >= w[0] - 1e-12),
        "{progress:?}"
    );
    assert_eq!(*progress.last().unwrap(), 1.0);
    // 1 pattern x (reference + 2 moves) frames; 2 runs x 3 schemes pairs.
    assert_eq!(kinds.iter().filter(|k| **k == "frame_captured").count(), 3);
    assert_eq!(kinds.iter().filter(|k| **k == "pair_analyzed").count(), 6);

    // Resuming after an id replays exactly what came after it.
    let resumed = read_events(
        &server.url(&format!("/experiments/{id}/events")),
        Some(events[2].id),
        10_000,
    )
    .await;
    assert_eq!(resumed.len(), events.len() - 3);
    assert_eq!(resumed[0].id, events[3].id);
    events
}

/// Run `id`'s downloads: the results (a row per run and scheme, the commanded move recovered:
/// 0.5 mm at 6.5 px/mm reduced = 3.25 px per step, turned by the bench's 6.15 mrad stage
/// misalignment), their CSV, a frame as a 16-bit TIFF (saved in `tmp` to be read) and a plot.
async fn check_the_downloads(server: &TestServer, id: &str, tmp: &std::path::Path) {
    let results: Value = get_json(&server.url(&format!("/experiments/{id}/results"))).await;
    let rows = results["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2 * 3);
    for r in rows {
        let k: f64 = if r["run"] == "a-x1" { 1.0 } else { 2.0 };
        let u = r["u"]["mean"].as_f64().unwrap();
        assert!((u - 3.25 * k * 0.00615f64.cos()).abs() < 0.02, "{r}");
    }
    let csv = get(&server.url(&format!("/experiments/{id}/results.csv"))).await;
    assert!(csv.headers()["content-type"]
        .to_str()
        .unwrap()
        .starts_with("text/csv"));
    assert_eq!(csv.text().await.unwrap().lines().count(), 1 + 6);
    let tiff = get(&server.url(&format!("/experiments/{id}/frames/a_ref.tif"))).await;
    assert_eq!(tiff.headers()["content-type"], "image/tiff");
    let bytes = tiff.bytes().await.unwrap();
    let path = tmp.join("downloaded.tif");
    std::fs::write(&path, &bytes).unwrap();
    let (img, info) = ffdic::image::read_tiff(&path).unwrap();
    assert_eq!(
        (img.width(), img.height(), info.bit_depth),
        (daemon::WIDTH_PX, daemon::HEIGHT_PX, 16)
    );
    let svg = get(&server.url(&format!("/experiments/{id}/plots/figure5_u.svg")))
        .await
        .text()
        .await
        .unwrap();
    assert!(
        svg.starts_with("<svg") || svg.starts_with("<?xml"),
        "{}",
        &svg[..40]
    );
}

/// The run folder under `data` and the index agree on run `id` (its `record`, its `events`
/// logged, its frames); the frames are a dataset of their own.
async fn check_the_run_folder_agrees_with_the_index(
    server: &TestServer,
    data: &std::path::Path,
    id: &str,
    record: &Value,
    events: usize,
) {
    let folder = data.join("runs").join(id);
    let on_disk: Value =
        serde_json::from_slice(&std::fs::read(folder.join("run.json")).unwrap()).unwrap();
    assert_eq!(&on_disk, record);
    let listed: Vec<Value> = get_json(&server.url("/experiments?status=succeeded")).await;
    assert_eq!(listed, vec![record.clone()]);
    let log = std::fs::read_to_string(folder.join("events.jsonl")).unwrap();
    assert_eq!(log.lines().count(), events);
    let manifest = ffdic::dataset::Manifest::read(&folder.join("frames")).unwrap();
    assert_eq!(manifest.runs.len(), 2);
    let datasets: Vec<Value> = get_json(&server.url("/datasets")).await;
    assert_eq!(datasets.len(), 1);
    assert_eq!(datasets[0]["source"], format!("experiment:{id}"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_whole_experiment_over_http() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let id = start_a_two_move_experiment(&server).await;
    let events = check_the_events_and_their_resumption(&server, &id).await;

    let record = wait_terminal(&server.url(&format!("/experiments/{id}"))).await;
    assert_eq!(record["status"], "succeeded");
    assert_eq!(record["progress"], 1.0);
    // The frames are a dataset of their own, linked from the run.
    let dataset = record["dataset_id"]
        .as_str()
        .expect("the run names its dataset");
    let ds: Value = get_json(&server.url(&format!("/datasets/{dataset}"))).await;
    assert_eq!(ds["source"], format!("experiment:{id}"));

    check_the_downloads(&server, &id, tmp.path()).await;
    check_the_run_folder_agrees_with_the_index(&server, tmp.path(), &id, &record, events.len())
        .await;
    server.stop().await;
}

/// Posts `body` as an experiment, with an `Idempotency-Key` when `key` names one.
async fn post_experiment(server: &TestServer, body: Value, key: Option<&str>) -> reqwest::Response {
    let mut r = client().post(server.url("/experiments")).json(&body);
    if let Some(k) = key {
        r = r.header("Idempotency-Key", k);
    }
    r.send().await.unwrap()
}

/// Asks the camera for a 5000 µs exposure directly (`PATCH /camera`), whatever the answer.
async fn set_the_exposure_directly(server: &TestServer) -> reqwest::Response {
    client()
        .patch(server.url("/camera"))
        .json(&json!({"exposure_us": 5000.0}))
        .send()
        .await
        .unwrap()
}

/// Direct control while an experiment holds the bench: 409, as problem+json.
async fn check_a_held_bench_refuses_direct_control(server: &TestServer) {
    let patch = set_the_exposure_directly(server).await;
    assert_eq!(patch.status(), 409);
    assert_eq!(patch.headers()["content-type"], "application/problem+json");
    let mv = post(&server.url("/stage/moves"), &json!({"dx_mm": 1.0})).await;
    assert_eq!(mv.status(), 409);
}

/// With the bench free, direct control works and answers with what was set; snapshots come as
/// PNG when asked, TIFF otherwise.
async fn check_a_free_bench_obeys_direct_control(server: &TestServer) {
    let c = client();
    let patch = set_the_exposure_directly(server).await;
    assert_eq!(patch.status(), 200);
    let applied: Value = patch.json().await.unwrap();
    assert_eq!(applied["exposure_us"], 5000.0);
    let snap = c
        .post(server.url("/camera/snapshot?format=png"))
        .send()
        .await
        .unwrap();
    assert_eq!(snap.headers()["content-type"], "image/png");
    let snap = c.post(server.url("/camera/snapshot")).send().await.unwrap();
    assert_eq!(snap.headers()["content-type"], "image/tiff");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancel_queue_idempotency_and_a_held_bench() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let c = client();

    // Two at once: the second queues behind the first; both finish.
    let first: Value = post_experiment(&server, small_request(6), Some("k-1"))
        .await
        .json()
        .await
        .unwrap();
    let second: Value = post_experiment(&server, small_request(1), None)
        .await
        .json()
        .await
        .unwrap();
    let first_url = server.url(&format!("/experiments/{}", first["id"].as_str().unwrap()));
    let second_url = server.url(&format!("/experiments/{}", second["id"].as_str().unwrap()));
    wait_until(&first_url, |r| r["status"] == "running").await;
    let s: Value = get_json(&second_url).await;
    assert_eq!(s["status"], "queued", "one experiment at a time");

    // The same Idempotency-Key gives the same experiment, and queues nothing new.
    let again = post_experiment(&server, small_request(6), Some("k-1")).await;
    assert_eq!(again.status(), 200);
    let again: Value = again.json().await.unwrap();
    assert_eq!(again["id"], first["id"]);

    // A run is `running` a moment before its work takes the bench; once it reports progress it
    // holds it.
    wait_until(&first_url, |r| r["progress"].as_f64().unwrap_or(0.0) > 0.0).await;
    check_a_held_bench_refuses_direct_control(&server).await;

    // Cancel the first mid-run: it ends cancelled, the stage stands still, the second runs.
    let cancel = c.post(format!("{first_url}/cancel")).send().await.unwrap();
    assert_eq!(cancel.status(), 200);
    let done = wait_terminal(&first_url).await;
    assert_eq!(done["status"], "cancelled", "{done}");
    let again = c.post(format!("{first_url}/cancel")).send().await.unwrap();
    assert_eq!(again.status(), 409, "an ended run cannot be cancelled");
    let second_done = wait_terminal(&second_url).await;
    assert_eq!(second_done["status"], "succeeded", "{second_done}");
    let s1: Value = get_json(&server.url("/stage")).await;
    tokio::time::sleep(std::time::Duration::from_millis(200)).await;
    let s2: Value = get_json(&server.url("/stage")).await;
    assert_eq!(s1["position"], s2["position"], "the stage stands still");

    check_a_free_bench_obeys_direct_control(&server).await;
    server.stop().await;
}

/// The mock bench is deterministic for a request: the same experiment twice, with snapshots
/// before and between, gives the same numbers to the last digit; another seed does not (so the
/// comparison can fail).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_same_request_gives_the_same_results_whatever_was_captured_before() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let c = client();
    let snapshot = || async {
        let r = c.post(server.url("/camera/snapshot")).send().await.unwrap();
        assert_eq!(r.status(), 200);
    };
    let run = |seed: u64| {
        let mut request = small_request(1);
        request["seed"] = json!(seed);
        let server = &server;
        async move { run_to_results(server, &request).await.1["rows"].clone() }
    };
    snapshot().await;
    let first = run(7).await;
    snapshot().await;
    snapshot().await;
    let second = run(7).await;
    assert_eq!(first, second, "same request, same seed, different numbers");
    let other = run(8).await;
    assert_ne!(first, other, "another seed gave the same numbers");
    assert_eq!(first.as_array().unwrap().len(), 3);
}

/// Issue 13: `repeats` captures every pair anew (new noise each) and the study pools them — the
/// mean over captures with a Student-t interval — while every capture's rows stay in
/// `captures`. Checked against the captures themselves: the pooled std is their mean, its
/// interval holds it, and with `new_layout_per_repeat` the references show different prints.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn repeats_pool_independent_captures_with_intervals_over_them() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let run = |repeats: usize, new_layouts: bool| {
        let mut request = small_request(1);
        request["repeats"] = json!(repeats);
        request["new_layout_per_repeat"] = json!(new_layouts);
        let server = &server;
        async move { run_to_results(server, &request).await }
    };
    let (id, results) = run(4, false).await;
    let rows = results["rows"].as_array().unwrap();
    let captures = results["captures"].as_array().unwrap();
    assert_eq!((rows.len(), captures.len()), (3, 12), "{results}");
    for row in rows {
        assert_eq!(row["repeats"], 4);
        assert_eq!(row["run"], "a-x1");
        let own: Vec<&Value> = captures
            .iter()
            .filter(|c| c["scheme"] == row["scheme"])
            .collect();
        assert_eq!(own.len(), 4);
        let stds: Vec<f64> = own
            .iter()
            .map(|c| c["u"]["std"].as_f64().unwrap())
            .collect();
        assert!(
            stds.windows(2).any(|w| w[0] != w[1]),
            "four captures, one noise: {stds:?}"
        );
        let mean = stds.iter().sum::<f64>() / 4.0;
        let std = row["u"]["std"].as_f64().unwrap();
        assert!((std - mean).abs() < 1e-12 * mean, "{std} vs {mean}");
        let ci = &row["u"]["ci95"];
        let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
        assert!(lo < std && std < hi, "{row}");
        // The t interval of four values reaches past their range only by the t factor.
        let spread = stds.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - stds.iter().cloned().fold(f64::INFINITY, f64::min);
        assert!(hi - lo < 4.0 * spread, "{lo}..{hi} for {stds:?}");
        if row["scheme"] != "ff100" {
            let inc = &row["increase_ci95"]["u"];
            assert!(inc[0].as_f64().unwrap() < inc[1].as_f64().unwrap(), "{row}");
        }
    }
    let dir = server.service.store.run_dir(&id.parse().unwrap());
    let manifest: Value =
        serde_json::from_slice(&std::fs::read(dir.join("frames/dataset.json")).unwrap()).unwrap();
    let runs = manifest["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 4);
    assert_eq!(runs[2]["id"], "a-x1-rep3");
    assert_eq!(runs[2]["repeat_of"], "a-x1");
    assert_eq!(runs[2]["reference"], "a_rep3_ref.tif");

    // The same print in every capture unless a new layout is asked for.
    let correlation = |dir: &std::path::Path| {
        let read = |name: &str| {
            ffdic::image::read_tiff(&dir.join("frames").join(name))
                .unwrap()
                .0
        };
        let (a, b) = (read("a_rep1_ref.tif"), read("a_rep2_ref.tif"));
        let (a, b) = (a.data(), b.data());
        let mean = |x: &[f32]| x.iter().map(|&v| v as f64).sum::<f64>() / x.len() as f64;
        let (ma, mb) = (mean(a), mean(b));
        let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
        for (&x, &y) in a.iter().zip(b) {
            let (x, y) = (x as f64 - ma, y as f64 - mb);
            ab += x * y;
            aa += x * x;
            bb += y * y;
        }
        ab / (aa * bb).sqrt()
    };
    let same = correlation(&dir);
    let (new_id, _) = run(2, true).await;
    let new = correlation(&server.service.store.run_dir(&new_id.parse().unwrap()));
    assert!(same > 0.9, "same print, new noise: r = {same}");
    assert!(new.abs() < 0.2, "a new layout: r = {new}");
}

/// `GET /camera` lists the schemes the mock sensor offers, each with the preset it stands for,
/// binning in the digital domain.
async fn check_the_offered_hardware_schemes(server: &TestServer) {
    let camera: Value = daemon::get_json(&server.url("/camera")).await;
    let offered: Vec<(&str, &str)> = camera["info"]["hardware_schemes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            (
                s["name"].as_str().unwrap(),
                s["equivalent_preset"].as_str().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        offered,
        [
            ("hw:bin2x2-average", "ff100"),
            ("hw:dec2-bin2-average", "ff50"),
            ("hw:dec2x2", "ff25")
        ]
    );
    assert_eq!(
        camera["info"]["hardware_schemes"][0]["binning_domain"],
        "digital"
    );
}

/// The camera's own binning and decimation (issue 17): `GET /camera` lists the schemes the mock
/// sensor offers; an experiment naming two of them captures every position in each mode beside
/// the full-resolution frame, records the mode per run in the dataset, puts each scheme in the
/// table beside the synthesised ones with its increase over the twin run's ff100, and leaves the
/// camera at full resolution.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hardware_schemes_are_captured_beside_their_synthesised_twins() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    check_the_offered_hardware_schemes(&server).await;

    let mut request = small_request(2);
    request["schemes"] = json!(["ff100", "ff25", "hw:bin2x2-average", "HW:DEC2X2"]);
    let (id, results) = run_to_results(&server, &request).await;
    let rows = results["rows"].as_array().unwrap();
    let row = |run: &str, scheme: &str| {
        rows.iter()
            .find(|r| r["run"] == run && r["scheme"] == scheme)
            .unwrap_or_else(|| panic!("no row {run} {scheme} in {rows:?}"))
    };
    assert_eq!(rows.len(), 8, "{rows:?}");
    for k in ["a-x1", "a-x2"] {
        let binned = row(&format!("{k}_hw-bin2x2-average"), "hw:bin2x2-average");
        let decimated = row(&format!("{k}_hw-dec2x2"), "hw:dec2x2");
        assert_eq!(binned["fill_factor"], json!([1.0, 1.0]));
        assert_eq!(decimated["fill_factor"], json!([0.5, 0.5]));
        // Increases over the twin's ff100, with a paired interval wherever the synthesised
        // ff25 of the same pair has one (the same grid; too few blocks on this small bench).
        let synthesised = row(k, "ff25");
        for r in [binned, decimated] {
            assert!(r["increase_pct"]["u"].is_number(), "{r}");
            assert_eq!(
                r["increase_ci95"].is_null(),
                synthesised["increase_ci95"].is_null(),
                "{r}"
            );
        }
        // Same pattern, same move, a smaller pixel aperture: decimation raises the error over
        // the twin's ff100 as the synthesised ff25 does (paper, Figure 5).
        assert!(
            decimated["increase_pct"]["u"].as_f64().unwrap() > 0.0,
            "{decimated}"
        );
    }

    let dir = server.service.store.run_dir(&id.parse().unwrap());
    let manifest: Value =
        serde_json::from_slice(&std::fs::read(dir.join("frames/dataset.json")).unwrap()).unwrap();
    let runs = manifest["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 6);
    let hw = &runs[1];
    assert_eq!(hw["id"], "a-x1_hw-bin2x2-average");
    assert_eq!(hw["twin_of"], "a-x1");
    assert_eq!(hw["capture"]["name"], "hw:bin2x2-average");
    assert_eq!(hw["reference"], "hw-bin2x2-average_a_ref.tif");
    assert!(runs[0].get("capture").is_none());
    let (frame, _) = ffdic::image::read_tiff(&dir.join("frames/hw-dec2x2_a_x2.tif")).unwrap();
    assert_eq!(
        (frame.width(), frame.height()),
        (daemon::WIDTH_PX / 2, daemon::HEIGHT_PX / 2)
    );
    let settings: Value = daemon::get_json(&server.url("/camera")).await;
    assert_eq!(settings["settings"]["binning"], json!([1, 1]));
    assert_eq!(settings["settings"]["decimation"], json!([1, 1]));
    // Maps of the first run in every scheme, the hardware ones beside the synthesised.
    for scheme in ["ff100", "ff25", "hw-bin2x2-average", "hw-dec2x2"] {
        let map = dir.join(format!("plots/map_a_{scheme}_u.svg"));
        assert!(map.is_file(), "{map:?}");
    }
    compare_renders_each_capture_mode(&dir.join("frames"));

    // Each read-out mode has its own noise stream: the synthesised rows are those of the same
    // request without hardware schemes, number for number.
    request["schemes"] = json!(["ff100", "ff25"]);
    let (_, alone) = run_to_results(&server, &request).await;
    let alone = alone["rows"].as_array().unwrap();
    assert_eq!(alone.len(), 4);
    for a in alone {
        let r = row(a["run"].as_str().unwrap(), a["scheme"].as_str().unwrap());
        assert_eq!(
            (&a["u"], &a["v"], &a["exx"]),
            (&r["u"], &r["v"], &r["exx"]),
            "{a}"
        );
    }
    server.stop().await;
}

/// `compare` renders the model in each hardware run's capture mode, beside the fit: the model's
/// displacements are in the captured frames' px (rendered at full resolution they would be twice
/// the measured ones: a discrepancy of the move's size) and its random error follows the mode's
/// pixel aperture (decimation's is larger than binning's, as measured), within the sampling
/// error of two random-error estimates (±40 % here: a few hundred overlapping subsets).
fn compare_renders_each_capture_mode(frames: &std::path::Path) {
    use ffdic::diagnose::{compare, CompareOptions, BASELINE_TOML};
    let model =
        ffdic::model::ModelConfig::from_toml(BASELINE_TOML, std::path::Path::new("baseline"))
            .unwrap();
    let dic = serde_json::from_value(small_request(2)["dic"].clone()).unwrap();
    let options =
        CompareOptions::from_scheme_specs(&["ff100".into(), "ff25".into()], dic, 1).unwrap();
    let cmp = compare(frames, &model, &options, &|_, _| true).unwrap();
    assert_eq!(cmp.hardware_runs_set_aside, 0);
    let hw = cmp.hardware.as_ref().expect("the hardware runs compared");
    assert_eq!(hw.runs.len(), 4, "{:?}", hw.runs);
    let twin_d = cmp.discrepancy_px;
    for r in &hw.runs {
        println!(
            "{} ({}): D {:.5} px (the fit's {twin_d:.5}); random u {:.5} meas, {:.5} model",
            r.id, r.scheme, r.discrepancy_px, r.measured_random_px[0], r.model_random_px[0]
        );
        assert!(r.discrepancy_px < 0.02, "{r:?}");
        for axis in 0..2 {
            let ratio = r.model_random_px[axis] / r.measured_random_px[axis];
            assert!(
                (0.6..1.6).contains(&ratio),
                "{}: random ratio {ratio}",
                r.id
            );
        }
        // The model's reference in the capture mode has the measured mean level.
        let (m, o) = (&r.reference[0], &r.reference[1]);
        assert!((o.mean_dn / m.mean_dn - 1.0).abs() < 0.02, "{m:?} {o:?}");
    }
}

/// A camera without binning or decimation answers 422 naming the hardware scheme asked for, and
/// queues nothing (the refusals of `hw:` names elsewhere are unit tests of `experiment::request`).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_camera_without_the_features_refuses_hardware_schemes() {
    let tmp = tempfile::tempdir().unwrap();
    let mut config = small_config(tmp.path());
    config.camera = ffdic::service::CameraConfig::Mock {
        width: daemon::WIDTH_PX,
        height: daemon::HEIGHT_PX,
        exposure_level: 0.5,
        bench_model: "paper-bench".into(),
        hardware_binning: ffdic::service::MockBinning::None,
        hardware_decimation_max: 1,
    };
    let server = TestServer::start(config).await;
    let camera: Value = daemon::get_json(&server.url("/camera")).await;
    assert_eq!(camera["info"]["hardware_schemes"], json!([]));
    let mut request = small_request(1);
    request["schemes"] = json!(["ff100", "hw:bin2x2-average"]);
    let r = client()
        .post(server.url("/experiments"))
        .json(&request)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 422);
    let problem: Value = r.json().await.unwrap();
    let text = problem.to_string();
    assert!(
        text.contains("schemes[1]") && text.contains("hw:bin2x2-average"),
        "{problem}"
    );
    let runs: Value = daemon::get_json(&server.url("/experiments")).await;
    assert_eq!(
        runs.as_array().map_or(0, Vec::len),
        0,
        "nothing queued: {runs}"
    );
    server.stop().await;
}

/// Posts `request`, waits for success, and returns the run's id and its `results` (study.json).
async fn run_to_results(server: &TestServer, request: &Value) -> (String, Value) {
    let c = client();
    let url = server.url("/experiments");
    let r = c.post(&url).json(request).send().await.unwrap();
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let record = wait_terminal(&format!("{url}/{id}")).await;
    assert_eq!(record["status"], "succeeded", "{record}");
    let results: Value = c
        .get(format!("{url}/{id}/results"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    (id, results)
}

/// `POST /calibrations` (issue 33): a plan on the mock bench becomes a run of its own kind whose
/// frames are a dataset, whose card is a file and whose model is stored; a plan the bench cannot
/// move is refused naming the move, and nothing is queued.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_calibration_over_http_writes_a_card_and_stores_its_model() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let plan = json!({
        "name": "small bench",
        "move_sizes_mm": [0.5, 2.5],
        "static_frames": 1,
        "rounds": 1,
        "dic": {"subset_px": 21, "step_px": 10, "strain_window": 5}
    });
    let r = post(&server.url("/calibrations"), &plan).await;
    assert_eq!(r.status(), 202);
    let location = r.headers()["location"].to_str().unwrap().to_string();
    let id = r.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(id.starts_with("cal-"), "{id}");
    assert_eq!(location, format!("/api/v1/calibrations/{id}"));
    let record = wait_terminal(&server.url(&format!("/calibrations/{id}"))).await;
    assert_eq!(record["status"], "succeeded", "{record}");
    assert!(record["dataset_id"].is_string(), "{record}");
    // The record keeps the plan as run: the phase scan's count left unset is stated, none with
    // a nominal print.
    assert_eq!(record["request"]["phase_scan_count"], json!(0), "{record}");
    let card: Value = get_json(&server.url(&format!("/calibrations/{id}/card"))).await;
    let model = card["model"].as_str().unwrap();
    assert!(model.starts_with("card-small-bench-"), "{model}");
    assert_eq!(card["plan"]["move_sizes_mm"], json!([0.5, 2.5]));
    assert_eq!(card["experiment"]["moves"].as_array().unwrap().len(), 8);
    let stage = &card["card"]["stage"];
    assert!(
        (stage["scale_x_px_per_mm"].as_f64().unwrap() - 13.0).abs() < 0.1,
        "{stage}"
    );
    let stored = get(&server.url(&format!("/models/{model}"))).await;
    assert_eq!(stored.status(), 200, "the card's model is stored");
    let listed: Value = get_json(&server.url("/calibrations")).await;
    assert_eq!(listed.as_array().unwrap().len(), 1, "{listed}");

    // 20 mm is 260 px here, beyond what the DIC tracks (160 px): refused before the bench moves.
    let beyond = json!({"move_sizes_mm": [20.0], "rounds": 1});
    let r = post(&server.url("/calibrations"), &beyond).await;
    assert_eq!(r.status(), 422);
    let problem: Value = r.json().await.unwrap();
    assert_eq!(problem["field"], "move_sizes_mm", "{problem}");
    assert!(problem.to_string().contains("max_motion_px"), "{problem}");
    server.stop().await;
}
