//! The daemon over real HTTP on a loopback port: a whole experiment on the mock bench, events in
//! order over SSE with resume, downloads, the run folder against the index, cancellation,
//! queueing, idempotency, and the bench refusing direct control while an experiment holds it.

#[path = "common/daemon.rs"]
mod daemon;

use daemon::{
    client, read_events, small_config, small_request, wait_terminal, wait_until, TestServer,
};
use serde_json::{json, Value};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_whole_experiment_over_http() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let c = client();

    assert_eq!(
        c.get(server.url("/health")).send().await.unwrap().status(),
        200
    );
    let r = c
        .post(server.url("/experiments"))
        .json(&small_request(2))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let location = r.headers()["location"].to_str().unwrap().to_string();
    let run: Value = r.json().await.unwrap();
    let id = run["id"].as_str().unwrap().to_string();
    assert_eq!(location, format!("/api/v1/experiments/{id}"));

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

    let record = wait_terminal(&server.url(&format!("/experiments/{id}"))).await;
    assert_eq!(record["status"], "succeeded");
    assert_eq!(record["progress"], 1.0);
    // The frames are a dataset of their own, linked from the run.
    let dataset = record["dataset_id"]
        .as_str()
        .expect("the run names its dataset");
    let ds: Value = c
        .get(server.url(&format!("/datasets/{dataset}")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(ds["source"], format!("experiment:{id}"));

    // Results: a row per run and scheme, the commanded move recovered (0.5 mm at 6.5 px/mm
    // reduced = 3.25 px per step, turned by the bench's 6.15 mrad stage misalignment).
    let results: Value = c
        .get(server.url(&format!("/experiments/{id}/results")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let rows = results["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2 * 3);
    for r in rows {
        let k: f64 = if r["run"] == "a-x1" { 1.0 } else { 2.0 };
        let u = r["u"]["mean"].as_f64().unwrap();
        assert!((u - 3.25 * k * 0.00615f64.cos()).abs() < 0.02, "{r}");
    }
    let csv = c
        .get(server.url(&format!("/experiments/{id}/results.csv")))
        .send()
        .await
        .unwrap();
    assert!(csv.headers()["content-type"]
        .to_str()
        .unwrap()
        .starts_with("text/csv"));
    assert_eq!(csv.text().await.unwrap().lines().count(), 1 + 6);
    let tiff = c
        .get(server.url(&format!("/experiments/{id}/frames/a_ref.tif")))
        .send()
        .await
        .unwrap();
    assert_eq!(tiff.headers()["content-type"], "image/tiff");
    let bytes = tiff.bytes().await.unwrap();
    let path = tmp.path().join("downloaded.tif");
    std::fs::write(&path, &bytes).unwrap();
    let (img, info) = ffdic::image::read_tiff(&path).unwrap();
    assert_eq!(
        (img.width(), img.height(), info.bit_depth),
        (daemon::WIDTH_PX, daemon::HEIGHT_PX, 16)
    );
    let svg = c
        .get(server.url(&format!("/experiments/{id}/plots/figure5_u.svg")))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(
        svg.starts_with("<svg") || svg.starts_with("<?xml"),
        "{}",
        &svg[..40]
    );

    // The run folder and the index agree; the frames are a dataset of their own.
    let folder = tmp.path().join("runs").join(&id);
    let on_disk: Value =
        serde_json::from_slice(&std::fs::read(folder.join("run.json")).unwrap()).unwrap();
    assert_eq!(on_disk, record);
    let listed: Vec<Value> = c
        .get(server.url("/experiments?status=succeeded"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(listed, vec![record.clone()]);
    let log = std::fs::read_to_string(folder.join("events.jsonl")).unwrap();
    assert_eq!(log.lines().count(), events.len());
    let manifest = ffdic::dataset::Manifest::read(&folder.join("frames")).unwrap();
    assert_eq!(manifest.runs.len(), 2);
    let datasets: Vec<Value> = c
        .get(server.url("/datasets"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(datasets.len(), 1);
    assert_eq!(datasets[0]["source"], format!("experiment:{id}"));
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancel_queue_idempotency_and_a_held_bench() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let c = client();

    // Two at once: the second queues behind the first; both finish.
    let post = |body: Value, key: Option<&str>| {
        let mut r = c.post(server.url("/experiments")).json(&body);
        if let Some(k) = key {
            r = r.header("Idempotency-Key", k);
        }
        r.send()
    };
    let first: Value = post(small_request(6), Some("k-1"))
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let second: Value = post(small_request(1), None)
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let first_url = server.url(&format!("/experiments/{}", first["id"].as_str().unwrap()));
    let second_url = server.url(&format!("/experiments/{}", second["id"].as_str().unwrap()));
    wait_until(&first_url, |r| r["status"] == "running").await;
    let s: Value = c
        .get(&second_url)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(s["status"], "queued", "one experiment at a time");

    // The same Idempotency-Key gives the same experiment, and queues nothing new.
    let again = post(small_request(6), Some("k-1")).await.unwrap();
    assert_eq!(again.status(), 200);
    let again: Value = again.json().await.unwrap();
    assert_eq!(again["id"], first["id"]);

    // Direct control while the experiment holds the bench: 409.
    let patch = c
        .patch(server.url("/camera"))
        .json(&json!({"exposure_us": 5000.0}))
        .send()
        .await
        .unwrap();
    assert_eq!(patch.status(), 409);
    assert_eq!(patch.headers()["content-type"], "application/problem+json");
    let mv = c
        .post(server.url("/stage/moves"))
        .json(&json!({"dx_mm": 1.0}))
        .send()
        .await
        .unwrap();
    assert_eq!(mv.status(), 409);

    // Cancel the first mid-run: it ends cancelled, the stage stands still, the second runs.
    wait_until(&first_url, |r| r["progress"].as_f64().unwrap_or(0.0) > 0.0).await;
    let cancel = c.post(format!("{first_url}/cancel")).send().await.unwrap();
    assert_eq!(cancel.status(), 200);
    let done = wait_terminal(&first_url).await;
    assert_eq!(done["status"], "cancelled", "{done}");
    let again = c.post(format!("{first_url}/cancel")).send().await.unwrap();
    assert_eq!(again.status(), 409, "an ended run cannot be cancelled");
    let second_done = wait_terminal(&second_url).await;
    assert_eq!(second_done["status"], "succeeded", "{second_done}");
    let s1: Value = c
        .get(server.url("/stage"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    tokio::time::sleep(std::time::Duration::from_millis(200)).await;
    let s2: Value = c
        .get(server.url("/stage"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(s1["position"], s2["position"], "the stage stands still");

    // With the bench free again, direct control works and answers with what was set.
    let patch = c
        .patch(server.url("/camera"))
        .json(&json!({"exposure_us": 5000.0}))
        .send()
        .await
        .unwrap();
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
        let c = c.clone();
        let url = server.url("/experiments");
        async move {
            let mut request = small_request(1);
            request["seed"] = json!(seed);
            let r = c.post(&url).json(&request).send().await.unwrap();
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
            results["rows"].clone()
        }
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
