//! Issue 36 (6): deletion through the API (refused while in use), the run folders' quota,
//! retention, and lists in pages.

use crate::common::daemon;

use daemon::{client, get, post, small_config, small_request, wait_terminal, TestServer};
use serde_json::{json, Value};

async fn delete(url: &str) -> reqwest::Response {
    client().delete(url).send().await.unwrap()
}

/// Runs a one-move experiment to its end; returns its record.
async fn experiment(server: &TestServer) -> Value {
    let r = post(&server.url("/experiments"), &small_request(1)).await;
    assert_eq!(r.status(), 202);
    let v: Value = r.json().await.unwrap();
    let run = wait_terminal(&server.url(&format!("/jobs/{}", v["id"].as_str().unwrap()))).await;
    assert_eq!(run["status"], "succeeded", "{run}");
    run
}

/// Models: an embedded one is part of the binary (409); a stored one goes (204, then 404), and
/// its name stays its text's: another text under it is a conflict, the same text comes back.
async fn check_only_stored_models_are_deleted(server: &TestServer) {
    assert_eq!(delete(&server.url("/models/baseline")).await.status(), 409);
    let toml = "name = \"mine\"\ndescription = \"a model to delete\"\n";
    assert_eq!(
        post(&server.url("/models"), &json!({ "toml": toml }))
            .await
            .status(),
        201
    );
    assert_eq!(delete(&server.url("/models/mine")).await.status(), 204);
    assert_eq!(get(&server.url("/models/mine")).await.status(), 404);
    assert_eq!(delete(&server.url("/models/mine")).await.status(), 404);
    let other = format!("{toml}# changed\n");
    assert_eq!(
        post(&server.url("/models"), &json!({ "toml": other }))
            .await
            .status(),
        409
    );
    assert_eq!(
        post(&server.url("/models"), &json!({ "toml": toml }))
            .await
            .status(),
        201
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn runs_datasets_and_models_are_deleted_only_when_nothing_uses_them() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let run = experiment(&server).await;
    let (run_id, dataset) = (
        run["id"].as_str().unwrap(),
        run["dataset_id"].as_str().unwrap(),
    );

    // A dataset a running analysis reads: 409, and it stays.
    let slow =
        json!({"schemes": ["ff100", "ff50", "ff25"], "dic": {"subset_px": 41, "step_px": 1}});
    let r = post(&server.url(&format!("/datasets/{dataset}/analyses")), &slow).await;
    assert_eq!(r.status(), 202);
    let analysis: Value = r.json().await.unwrap();
    let analysis_url = server.url(&format!("/jobs/{}", analysis["id"].as_str().unwrap()));
    let r = delete(&server.url(&format!("/datasets/{dataset}"))).await;
    assert_eq!(r.status(), 409);
    let p: Value = r.json().await.unwrap();
    assert!(
        p["detail"]
            .as_str()
            .unwrap()
            .contains(analysis["id"].as_str().unwrap()),
        "{p}"
    );
    // So is the analysis itself while it is queued or running.
    assert_eq!(delete(&analysis_url).await.status(), 409);
    assert_eq!(
        get(&server.url(&format!("/datasets/{dataset}")))
            .await
            .status(),
        200
    );
    let r = client()
        .post(format!("{analysis_url}/cancel"))
        .send()
        .await
        .unwrap();
    assert!(r.status() == 200 || r.status() == 409, "{}", r.status());
    wait_terminal(&analysis_url).await;

    // Once nothing uses them: 204, then 404.
    assert_eq!(delete(&analysis_url).await.status(), 204);
    assert_eq!(get(&analysis_url).await.status(), 404);
    assert_eq!(
        delete(&server.url(&format!("/datasets/{dataset}")))
            .await
            .status(),
        204
    );
    assert_eq!(
        get(&server.url(&format!("/datasets/{dataset}")))
            .await
            .status(),
        404
    );
    let listed: Vec<Value> = daemon::get_json(&server.url("/datasets")).await;
    assert!(listed.is_empty(), "{listed:?}");
    assert_eq!(
        delete(&server.url(&format!("/experiments/{run_id}")))
            .await
            .status(),
        405
    );
    assert_eq!(
        delete(&server.url(&format!("/jobs/{run_id}")))
            .await
            .status(),
        204
    );
    assert_eq!(
        delete(&server.url(&format!("/jobs/{run_id}")))
            .await
            .status(),
        404
    );
    assert_eq!(
        std::fs::read_dir(tmp.path().join("runs")).unwrap().count(),
        0,
        "the run folders are gone"
    );

    check_only_stored_models_are_deleted(&server).await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_experiment_that_would_pass_the_run_folders_quota_is_refused_before_it_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let mut config = small_config(tmp.path());
    // One 400x320 16-bit frame is 256 KB: two fit, the three of a one-move experiment with
    // its static frame do not.
    config.runs_quota_bytes = 600_000;
    let server = TestServer::start(config).await;
    let mut request = small_request(1);
    request["static_frames"] = json!(1);
    let r = post(&server.url("/experiments"), &request).await;
    assert_eq!(r.status(), 507);
    let p: Value = r.json().await.unwrap();
    assert!(
        p["detail"].as_str().unwrap().contains("runs_quota_bytes"),
        "{p}"
    );
    let listed: Vec<Value> = daemon::get_json(&server.url("/experiments")).await;
    assert!(listed.is_empty(), "nothing queued: {listed:?}");
    assert!(!tmp.path().join("runs").read_dir().unwrap().any(|_| true));
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn retention_keeps_the_newest_ended_runs_and_lists_come_in_pages() {
    let tmp = tempfile::tempdir().unwrap();
    let mut config = small_config(tmp.path());
    config.retention.max_ended_runs = 2;
    let server = TestServer::start(config).await;
    let mut ids = Vec::new();
    for _ in 0..3 {
        ids.push(
            experiment(&server).await["id"]
                .as_str()
                .unwrap()
                .to_string(),
        );
    }
    // The worker applies the retention once the third has ended.
    daemon::wait_until(&server.url(&format!("/jobs/{}", ids[0])), |r| {
        r["status"] == 404
    })
    .await;
    for id in &ids[1..] {
        assert_eq!(get(&server.url(&format!("/jobs/{id}"))).await.status(), 200);
    }
    // The datasets the experiments registered stay: three, read one page at a time.
    let mut url = server.url("/datasets?limit=1");
    let mut seen = Vec::new();
    loop {
        let r = get(&url).await;
        assert_eq!(r.status(), 200);
        let next = r
            .headers()
            .get("link")
            .map(|l| l.to_str().unwrap().to_string());
        let page: Vec<Value> = r.json().await.unwrap();
        seen.extend(page.iter().map(|d| d["id"].as_str().unwrap().to_string()));
        let Some(link) = next else { break };
        let path = link.trim_start_matches('<').split('>').next().unwrap();
        assert!(link.ends_with("rel=\"next\""), "{link}");
        url = format!("{}{path}", server.base);
        assert!(seen.len() <= 3, "pages never end: {seen:?}");
    }
    assert_eq!(seen.len(), 3, "{seen:?}");
    let all: Vec<Value> = daemon::get_json(&server.url("/datasets")).await;
    let newest_first: Vec<String> = all
        .iter()
        .map(|d| d["id"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(seen, newest_first);
    // A cursor that is none is refused, naming the field.
    let r = get(&server.url("/experiments?after=yesterday")).await;
    assert_eq!(r.status(), 422);
    let p: Value = r.json().await.unwrap();
    assert_eq!(p["field"], "after");
    server.stop().await;
}
