//! Bad requests get problem documents and change nothing; uploads land whole or not at all; the
//! OpenAPI document matches its checked-in snapshot and lists every route; the token guards every
//! mutating request.

use crate::common::daemon;

use daemon::{client, get_json, small_config, wait_terminal, TestServer};
use serde_json::{json, Value};
use std::path::Path;

fn tree(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let p = e.path();
            out.push(p.display().to_string());
            if p.is_dir() {
                out.extend(tree(&p));
            }
        }
    }
    out.sort();
    out
}

async fn problem(resp: reqwest::Response, status: u16) -> Value {
    assert_eq!(resp.status().as_u16(), status);
    assert_eq!(
        resp.headers()["content-type"],
        "application/problem+json",
        "status {status}"
    );
    let p: Value = resp.json().await.unwrap();
    assert_eq!(p["status"], status);
    assert!(p["title"].is_string() && p["detail"].is_string(), "{p}");
    p
}

/// A started daemon on a fresh data folder, and what its runs and datasets folders hold.
struct Fixture {
    tmp: tempfile::TempDir,
    server: TestServer,
    c: reqwest::Client,
    runs: std::path::PathBuf,
    datasets: std::path::PathBuf,
}

impl Fixture {
    async fn start() -> Fixture {
        let tmp = tempfile::tempdir().unwrap();
        let server = TestServer::start(small_config(tmp.path())).await;
        let (runs, datasets) = (tmp.path().join("runs"), tmp.path().join("datasets"));
        Fixture {
            tmp,
            server,
            c: client(),
            runs,
            datasets,
        }
    }

    fn written(&self) -> (Vec<String>, Vec<String>) {
        (tree(&self.runs), tree(&self.datasets))
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_bodies_are_problems_naming_the_field_and_write_nothing() {
    let f = Fixture::start().await;
    let (server, c) = (&f.server, &f.c);
    let before = f.written();
    let post = |body: &'static str| {
        c.post(server.url("/experiments"))
            .header("content-type", "application/json")
            .body(body)
            .send()
    };

    problem(post("{\"patterns\": [").await.unwrap(), 400).await;
    let p = problem(post(r#"{"frames_averaged": "two"}"#).await.unwrap(), 422).await;
    assert_eq!(p["field"], "frames_averaged");
    let p = problem(post(r#"{"framez": 1}"#).await.unwrap(), 422).await;
    assert!(p["detail"].as_str().unwrap().contains("framez"), "{p}");
    let p = problem(post(r#"{"dic": {"subset_px": 40}}"#).await.unwrap(), 422).await;
    assert_eq!(p["field"], "dic.subset");
    let p = problem(post(r#"{"patterns": ["q"]}"#).await.unwrap(), 422).await;
    assert_eq!(p["field"], "patterns[0]");
    // The constraints the OpenAPI document states are the daemon's own (issue 12).
    for roi in [
        r#"{"x": 0, "y": 0, "width": 0, "height": 10}"#,
        r#"{"x": 2000000, "y": 0, "width": 10, "height": 10}"#,
    ] {
        let body = format!(r#"{{"dic": {{"roi": {roi}}}}}"#);
        let resp = c
            .post(server.url("/experiments"))
            .header("content-type", "application/json")
            .body(body)
            .send()
            .await
            .unwrap();
        assert_eq!(problem(resp, 422).await["field"], "dic.roi", "{roi}");
    }
    for (body, field) in [
        (r#"{"binning": [0, 1]}"#, "binning"),
        (r#"{"binning": [1, 65]}"#, "binning"),
        (r#"{"decimation": [0, 2]}"#, "decimation"),
        (
            r#"{"roi": {"x": 0, "y": 0, "width": 16, "height": 0}}"#,
            "roi",
        ),
    ] {
        let p = problem(
            c.patch(server.url("/camera"))
                .header("content-type", "application/json")
                .body(body)
                .send()
                .await
                .unwrap(),
            422,
        )
        .await;
        assert_eq!(p["field"], field, "{body}");
    }
    let huge = format!("{{\"name\": \"{}\"}}", "x".repeat(200_000));
    problem(
        c.post(server.url("/experiments"))
            .header("content-type", "application/json")
            .body(huge)
            .send()
            .await
            .unwrap(),
        413,
    )
    .await;
    problem(
        c.post(server.url("/experiments"))
            .header("content-type", "text/plain")
            .body("{}")
            .send()
            .await
            .unwrap(),
        415,
    )
    .await;

    assert_eq!(f.written(), before, "nothing written");
    f.server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_ids_and_paths_reach_nothing() {
    let f = Fixture::start().await;
    let (server, c) = (&f.server, &f.c);
    for path in [
        "/experiments/..%2F..%2Fetc",
        "/experiments/NOT-AN-ID",
        "/experiments/exp-20260101T000000-aaaaaa",
        "/jobs/%2Fetc%2Fpasswd",
        "/datasets/..",
    ] {
        problem(c.get(server.url(path)).send().await.unwrap(), 404).await;
    }
    problem(
        c.get(server.url("/experiments?status=bogus"))
            .send()
            .await
            .unwrap(),
        422,
    )
    .await;

    f.server.stop().await;
}

/// A 2-D random texture (a hash of the pixel position), shifted by `dx` px, as a 16-bit TIFF: a
/// sawtooth in one direction would leave any motion along its ridges undetermined.
fn texture_tiff(dx: i64) -> Vec<u8> {
    let img = ffdic::image::Image::from_fn(96, 80, |c, r| {
        let c = (c as i64 - dx) as u64;
        let mut s = c.wrapping_mul(73_856_093) ^ (r as u64).wrapping_mul(19_349_663);
        s ^= s >> 13;
        s = s.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        (s >> 56) as f32
    });
    let data: Vec<u16> = img.data().iter().map(|&v| v as u16).collect();
    ffdic::image::tiff_u16_bytes(96, 80, &data).unwrap()
}

/// A one-run manifest whose stage moved `dx_mm` in x.
fn upload_manifest(dx_mm: f64) -> String {
    json!({"format": "ffdic-dataset/1", "name": "up", "scale_px_per_mm": 13.0,
        "runs": [{"id": "r1", "reference": "ref.tif", "deformed": "def.tif",
                  "stage": {"dx_mm": dx_mm, "dy_mm": 0.0}}]})
    .to_string()
}

fn part(name: &str, bytes: Vec<u8>) -> reqwest::multipart::Part {
    reqwest::multipart::Part::bytes(bytes).file_name(name.to_string())
}

/// Posts `form` to `/datasets` with the fixture's client.
async fn post_dataset(f: &Fixture, form: reqwest::multipart::Form) -> reqwest::Response {
    f.c.post(f.server.url("/datasets"))
        .multipart(form)
        .send()
        .await
        .unwrap()
}

/// A path-traversal file name, a corrupt TIFF, a manifest naming a missing frame, a manifest whose
/// move contradicts its frames and a file the manifest does not name: each refused (422), built
/// from the good upload's `manifest` and frame `good_tiff`.
async fn check_bad_uploads_are_refused(f: &Fixture, manifest: &str, good_tiff: &[u8]) {
    let traversal = reqwest::multipart::Form::new()
        .part(
            "dataset.json",
            part("dataset.json", manifest.to_owned().into_bytes()),
        )
        .part("x", part("../../evil.tif", good_tiff.to_vec()));
    let p = problem(post_dataset(f, traversal).await, 422).await;
    assert_eq!(p["field"], "file");
    let corrupt = reqwest::multipart::Form::new()
        .part(
            "dataset.json",
            part("dataset.json", manifest.to_owned().into_bytes()),
        )
        .part("ref.tif", part("ref.tif", good_tiff.to_vec()))
        .part(
            "def.tif",
            part("def.tif", good_tiff[..good_tiff.len() / 2].to_vec()),
        );
    let p = problem(post_dataset(f, corrupt).await, 422).await;
    assert!(p["detail"].as_str().unwrap().contains("def.tif"), "{p}");
    let missing = reqwest::multipart::Form::new()
        .part(
            "dataset.json",
            part("dataset.json", manifest.to_owned().into_bytes()),
        )
        .part("ref.tif", part("ref.tif", good_tiff.to_vec()));
    problem(post_dataset(f, missing).await, 422).await;
    // Issue 12: a manifest whose move contradicts its frames (they moved 20 px = 1.5 mm, it says
    // 0.001 mm) is refused with the measured figure; so is a file the manifest does not name.
    let mislabelled = upload_manifest(0.001);
    let form = reqwest::multipart::Form::new()
        .part(
            "dataset.json",
            part("dataset.json", mislabelled.into_bytes()),
        )
        .part("ref.tif", part("ref.tif", good_tiff.to_vec()))
        .part("def.tif", part("def.tif", texture_tiff(20)));
    let p = problem(post_dataset(f, form).await, 422).await;
    assert_eq!(p["field"], "runs[r1].stage", "{p}");
    assert!(p["detail"].as_str().unwrap().contains("20.0 px"), "{p}");
    let form = reqwest::multipart::Form::new()
        .part(
            "dataset.json",
            part("dataset.json", manifest.to_owned().into_bytes()),
        )
        .part("ref.tif", part("ref.tif", good_tiff.to_vec()))
        .part("def.tif", part("def.tif", good_tiff.to_vec()))
        .part("notes.txt", part("notes.txt", b"hello".to_vec()));
    let p = problem(post_dataset(f, form).await, 422).await;
    assert!(p["detail"].as_str().unwrap().contains("notes.txt"), "{p}");
}

/// A good upload (`manifest` and `good_tiff` as both frames) lands, and its analysis runs as a
/// job: no motion between identical frames, its files out of reach of a traversal, and the
/// daemon healthy.
async fn check_a_good_upload_is_analysed(f: &Fixture, manifest: String, good_tiff: Vec<u8>) {
    let (server, c) = (&f.server, &f.c);
    let good = reqwest::multipart::Form::new()
        .part("dataset.json", part("dataset.json", manifest.into_bytes()))
        .part("ref.tif", part("ref.tif", good_tiff.clone()))
        .part("def.tif", part("def.tif", good_tiff));
    let r = post_dataset(f, good).await;
    assert_eq!(r.status(), 201);
    let ds: Value = r.json().await.unwrap();
    let ds_id = ds["id"].as_str().unwrap();
    let r = c
        .post(server.url(&format!("/datasets/{ds_id}/analyses")))
        .json(&json!({"schemes": ["ff100"], "dic": {"subset_px": 15, "step_px": 8, "strain_window": 3}}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let job_url = format!(
        "{}{}",
        server.base,
        r.headers()["location"].to_str().unwrap()
    );
    let job = wait_terminal(&job_url).await;
    assert_eq!(job["status"], "succeeded", "{job}");
    let rows: Value = c
        .get(format!("{job_url}/files/results/study.json"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    // The two frames are identical: no motion.
    let u = rows["rows"][0]["u"]["mean"].as_f64().unwrap();
    assert!(u.abs() < 1e-3, "{rows}");
    problem(
        c.get(format!("{job_url}/files/..%2Frun.json/x"))
            .send()
            .await
            .unwrap(),
        404,
    )
    .await;
    assert_eq!(
        c.get(server.url("/health")).send().await.unwrap().status(),
        200
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_uploads_land_nothing_and_a_good_one_is_analysed() {
    let f = Fixture::start().await;
    let before = f.written();
    let manifest = upload_manifest(0.5);
    let good_tiff = texture_tiff(0);
    check_bad_uploads_are_refused(&f, &manifest, &good_tiff).await;
    assert!(!f.tmp.path().join("evil.tif").exists());
    assert_eq!(f.written(), before, "nothing written");

    // …and the server keeps serving: a good upload lands, and its analysis runs as a job.
    check_a_good_upload_is_analysed(&f, manifest, good_tiff).await;
    f.server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn openapi_matches_its_snapshot_and_lists_every_route() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let doc: Value = client()
        .get(server.url("/openapi.json"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let paths = doc["paths"].as_object().unwrap();
    for (path, methods) in [
        ("/api/v1/health", &["get"][..]),
        ("/api/v1/status", &["get"]),
        ("/api/v1/camera", &["get", "patch"]),
        ("/api/v1/camera/snapshot", &["post"]),
        ("/api/v1/stage", &["get"]),
        ("/api/v1/stage/moves", &["post"]),
        ("/api/v1/experiments", &["get", "post"]),
        ("/api/v1/experiments/{id}", &["get"]),
        ("/api/v1/experiments/{id}/cancel", &["post"]),
        ("/api/v1/experiments/{id}/events", &["get"]),
        ("/api/v1/experiments/{id}/results", &["get"]),
        ("/api/v1/experiments/{id}/results.csv", &["get"]),
        ("/api/v1/experiments/{id}/frames/{name}", &["get"]),
        ("/api/v1/experiments/{id}/plots/{name}", &["get"]),
        ("/api/v1/datasets", &["get", "post"]),
        ("/api/v1/datasets/{id}", &["get"]),
        ("/api/v1/datasets/{id}/analyses", &["post"]),
        ("/api/v1/jobs/{id}", &["get"]),
        ("/api/v1/jobs/{id}/cancel", &["post"]),
        ("/api/v1/jobs/{id}/events", &["get"]),
        ("/api/v1/jobs/{id}/files/{folder}/{name}", &["get"]),
    ] {
        let entry = paths
            .get(path)
            .unwrap_or_else(|| panic!("{path} missing from the OpenAPI document"));
        for m in methods {
            assert!(entry.get(*m).is_some(), "{m} {path} missing");
        }
    }
    // Issue 12: operation ids are unique; every error is documented as problem+json; every
    // operation lists the statuses the middleware can answer with.
    let mut ids = std::collections::HashSet::new();
    for (path, item) in paths {
        for (method, op) in item.as_object().unwrap() {
            let id = op["operationId"].as_str().unwrap_or_default();
            assert!(
                ids.insert(id.to_string()),
                "{method} {path}: operationId {id:?} twice"
            );
            for (status, response) in op["responses"].as_object().unwrap() {
                let content = response["content"].as_object();
                let problem_as_json = content
                    .and_then(|c| c.get("application/json"))
                    .is_some_and(|j| j["schema"]["$ref"] == "#/components/schemas/Problem");
                assert!(
                    !problem_as_json,
                    "{method} {path} {status}: problem documented as application/json"
                );
            }
            for status in ["400", "401", "403", "421", "500", "503"] {
                assert!(
                    op["responses"].get(status).is_some(),
                    "{method} {path}: no {status}"
                );
            }
        }
    }
    // Issue 12: request bodies carry their constraints — no object without its properties, no
    // integer without its bounds, anywhere a JSON body reaches through `$ref`s.
    let mut loose = Vec::new();
    for (path, item) in paths {
        for (method, op) in item.as_object().unwrap() {
            if let Some(schema) = op.pointer("/requestBody/content/application~1json/schema") {
                unconstrained(&doc, schema, &format!("{method} {path}"), &mut loose, 0);
            }
        }
    }
    assert!(
        loose.is_empty(),
        "request bodies without constraints: {loose:#?}"
    );
    let snapshot = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/snapshots/openapi.json");
    let text = serde_json::to_string_pretty(&doc).unwrap() + "\n";
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        std::fs::write(&snapshot, &text).unwrap();
    }
    let expected = std::fs::read_to_string(&snapshot)
        .expect("tests/snapshots/openapi.json (UPDATE_SNAPSHOTS=1 writes it)");
    assert!(
        expected == text,
        "the OpenAPI document changed: review it and run with UPDATE_SNAPSHOTS=1"
    );
    server.stop().await;
}

/// Collects the places in `schema` (resolving `#/components/schemas/…`) where an object has no
/// properties or an integer no bounds.
fn unconstrained(doc: &Value, schema: &Value, at: &str, out: &mut Vec<String>, depth: usize) {
    assert!(depth < 16, "{at}: schema nested too deep (a cycle?)");
    if let Some(r) = schema["$ref"].as_str() {
        let name = r.trim_start_matches("#/components/schemas/");
        let target = &doc["components"]["schemas"][name];
        assert!(!target.is_null(), "{at}: dangling $ref {r}");
        return unconstrained(doc, target, &format!("{at} > {name}"), out, depth + 1);
    }
    let types: Vec<&str> = match &schema["type"] {
        Value::String(t) => vec![t.as_str()],
        Value::Array(ts) => ts.iter().filter_map(Value::as_str).collect(),
        _ => vec![],
    };
    if types.contains(&"object")
        && schema.get("properties").is_none()
        && schema.get("additionalProperties").is_none()
    {
        out.push(format!("{at}: object without properties"));
    }
    if types.contains(&"integer")
        && (schema.get("minimum").is_none() || schema.get("maximum").is_none())
    {
        out.push(format!("{at}: integer without minimum and maximum"));
    }
    for key in ["oneOf", "anyOf", "allOf"] {
        for (i, s) in schema[key].as_array().into_iter().flatten().enumerate() {
            unconstrained(doc, s, &format!("{at}/{key}[{i}]"), out, depth + 1);
        }
    }
    for (name, s) in schema["properties"].as_object().into_iter().flatten() {
        unconstrained(doc, s, &format!("{at}.{name}"), out, depth + 1);
    }
    for key in ["items", "additionalProperties"] {
        if schema[key].is_object() {
            unconstrained(doc, &schema[key], &format!("{at}[]"), out, depth + 1);
        }
    }
    for (i, s) in schema["prefixItems"]
        .as_array()
        .into_iter()
        .flatten()
        .enumerate()
    {
        unconstrained(doc, s, &format!("{at}[{i}]"), out, depth + 1);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_token_guards_every_mutating_request() {
    let tmp = tempfile::tempdir().unwrap();
    let mut config = small_config(tmp.path());
    config.auth_token = Some("s3cret-token".into());
    let server = TestServer::start(config).await;
    let c = client();
    let p = problem(
        c.post(server.url("/experiments"))
            .json(&json!({}))
            .send()
            .await
            .unwrap(),
        401,
    )
    .await;
    assert!(
        !p["detail"].as_str().unwrap().contains("s3cret"),
        "never leak the token"
    );
    problem(
        c.patch(server.url("/camera"))
            .bearer_auth("wrong")
            .json(&json!({"exposure_us": 1000.0}))
            .send()
            .await
            .unwrap(),
        401,
    )
    .await;
    problem(
        c.post(server.url("/stage/moves"))
            .json(&json!({"dx_mm": 1.0}))
            .send()
            .await
            .unwrap(),
        401,
    )
    .await;
    assert!(tree(&tmp.path().join("runs")).is_empty());
    // Reads stay open; the right token passes.
    assert_eq!(
        c.get(server.url("/experiments"))
            .send()
            .await
            .unwrap()
            .status(),
        200
    );
    let ok = c
        .patch(server.url("/camera"))
        .bearer_auth("s3cret-token")
        .json(&json!({"exposure_us": 1000.0}))
        .send()
        .await
        .unwrap();
    assert_eq!(ok.status(), 200);
    server.stop().await;
}

/// Issue 12's reproducers: each of these killed the daemon or its bench thread, drove the bench
/// from a body no JSON client sends, or answered 500. Now each is a problem naming its cause,
/// and the daemon answers afterwards.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn requests_that_killed_the_daemon_are_refused_at_the_door() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let c = client();
    let post = |body: String| {
        c.post(server.url("/experiments"))
            .header("content-type", "application/json")
            .body(body)
            .send()
    };
    let custom = |d: f64, s: f64| {
        format!(
            r#"{{"patterns":[{{"label":"x","dot_diameter_mm":{d},"dot_spacing_mm":{s},"contrast":0.8}}]}}"#
        )
    };
    // A 288 GB layout (aborted the process) and a capacity overflow (killed the bench thread).
    for (d, s) in [(0.0005, 0.001), (0.5, 1e-9)] {
        let p = problem(post(custom(d, s)).await.unwrap(), 422).await;
        assert_eq!(p["field"], "patterns[0]", "{p}");
    }
    let p = problem(
        post(r#"{"moves":[{"id":"far","dx_mm":1e7}]}"#.into())
            .await
            .unwrap(),
        422,
    )
    .await;
    assert_eq!(p["field"], "moves[0]", "{p}");
    let p = problem(
        post(r#"{"dic":{"max_motion_px":100000}}"#.into())
            .await
            .unwrap(),
        422,
    )
    .await;
    assert_eq!(p["field"], "dic.max_motion_px", "{p}");
    problem(post("[]".into()).await.unwrap(), 422).await;
    // A direct absolute move beyond the travel names its axis.
    let p = problem(
        c.post(server.url("/stage/moves"))
            .json(&json!({"x_mm": 0.0, "y_mm": 1e7}))
            .send()
            .await
            .unwrap(),
        422,
    )
    .await;
    assert_eq!(p["field"], "y_mm", "{p}");
    // A body with no content type is what a cross-site no-cors fetch sends.
    problem(
        c.post(server.url("/experiments"))
            .body("{}")
            .send()
            .await
            .unwrap(),
        415,
    )
    .await;
    // Upload part names that `Path::components` shortened to a plain name: 500 before.
    for name in ["x/", "x/."] {
        let form = reqwest::multipart::Form::new().text(name, "1");
        let resp = c
            .post(server.url("/datasets"))
            .multipart(form)
            .send()
            .await
            .unwrap();
        assert!(
            resp.status().is_client_error(),
            "part {name:?}: {}",
            resp.status()
        );
    }
    // The framework's own rejections are problems too.
    problem(
        c.delete(server.url("/experiments")).send().await.unwrap(),
        405,
    )
    .await;
    check_the_daemon_answers_with_nothing_queued(&server).await;
    server.stop().await;
}

/// After the refusals the daemon answers, healthy, and no experiment was queued.
async fn check_the_daemon_answers_with_nothing_queued(server: &TestServer) {
    let health: Value = get_json(&server.url("/health")).await;
    assert_eq!(health["status"], "ok", "{health}");
    let runs: Value = get_json(&server.url("/experiments")).await;
    assert_eq!(
        runs.as_array().map(Vec::len),
        Some(0),
        "nothing queued: {runs}"
    );
}

/// Issue 12: `datasets_quota_bytes` holds: an upload that would pass it is refused (507) with the
/// figures, and nothing of it is kept.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_upload_past_the_datasets_quota_is_refused_and_nothing_kept() {
    let tmp = tempfile::tempdir().unwrap();
    let mut config = small_config(tmp.path());
    let tiff = {
        let data: Vec<u16> = (0..96 * 80u32)
            .map(|k| (k.wrapping_mul(2_654_435_761) >> 20) as u16)
            .collect();
        ffdic::image::tiff_u16_bytes(96, 80, &data).unwrap()
    };
    // Room for one dataset of two frames, not for two.
    config.datasets_quota_bytes = 3 * tiff.len() as u64;
    let server = TestServer::start(config).await;
    let manifest = json!({"format": "ffdic-dataset/1", "name": "q", "scale_px_per_mm": 13.0,
        "runs": [{"id": "r1", "reference": "ref.tif", "deformed": "def.tif",
                  "stage": {"dx_mm": 0.0, "dy_mm": 0.0}}]})
    .to_string();
    let upload = || {
        let part = |name: &str, bytes: Vec<u8>| {
            reqwest::multipart::Part::bytes(bytes).file_name(name.to_string())
        };
        let form = reqwest::multipart::Form::new()
            .part(
                "dataset.json",
                part("dataset.json", manifest.clone().into_bytes()),
            )
            .part("ref.tif", part("ref.tif", tiff.clone()))
            .part("def.tif", part("def.tif", tiff.clone()));
        client()
            .post(server.url("/datasets"))
            .multipart(form)
            .send()
    };
    assert_eq!(upload().await.unwrap().status(), 201);
    let datasets = tmp.path().join("datasets");
    let before = tree(&datasets);
    let p = problem(upload().await.unwrap(), 507).await;
    assert!(
        p["detail"]
            .as_str()
            .unwrap()
            .contains("datasets_quota_bytes"),
        "{p}"
    );
    assert_eq!(tree(&datasets), before, "nothing kept");
    server.stop().await;
}

/// Issue 12 (schemathesis findings): a malformed Last-Event-ID is refused instead of replaying
/// from the start; a name no model can have is simply absent (404, not a 422 about TOML).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_malformed_last_event_id_is_refused_and_an_impossible_model_name_is_absent() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let c = client();
    let r = c
        .post(server.url("/experiments"))
        .json(&daemon::small_request(1))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let events = server.url(&format!("/experiments/{id}/events"));
    let p = problem(
        c.get(&events)
            .header("last-event-id", "null")
            .send()
            .await
            .unwrap(),
        400,
    )
    .await;
    assert!(
        p["detail"].as_str().unwrap().contains("Last-Event-ID"),
        "{p}"
    );
    wait_terminal(&server.url(&format!("/experiments/{id}"))).await;
    let ok = c
        .get(&events)
        .header("last-event-id", "3")
        .send()
        .await
        .unwrap();
    assert_eq!(ok.status(), 200);
    problem(
        c.get(server.url("/models/%C3%91%07")).send().await.unwrap(),
        404,
    )
    .await;
    server.stop().await;
}

/// Sends `request` as raw bytes and reads the whole answer (the server closes after it).
async fn raw(base: &str, request: &[u8]) -> String {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let addr = base.trim_start_matches("http://");
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    stream.write_all(request).await.unwrap();
    let mut answer = Vec::new();
    let read = stream.read_to_end(&mut answer);
    tokio::time::timeout(std::time::Duration::from_secs(10), read)
        .await
        .expect("the server answers and closes")
        .unwrap();
    String::from_utf8_lossy(&answer).into_owned()
}

/// Issue 36 (7): hyper's own 400/414/431 went out with empty bodies, and a 100 KB header was
/// taken.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn requests_hyper_cannot_parse_get_problem_documents_and_large_headers_are_refused() {
    let f = Fixture::start().await;
    let head = "GET /api/v1/health HTTP/1.1\r\nHost: localhost\r\n";
    let many: String = (0..200).map(|i| format!("X-{i}: 1\r\n")).collect();
    let cases = [
        (
            format!(
                "{head}X-Big: {}\r\nConnection: close\r\n\r\n",
                "a".repeat(100_000)
            ),
            431,
        ),
        (
            format!(
                "{head}X-Mid: {}\r\nConnection: close\r\n\r\n",
                "a".repeat(9_000)
            ),
            431,
        ),
        (format!("{head}{many}Connection: close\r\n\r\n"), 431),
        (
            format!(
                "GET /api/v1/{} HTTP/1.1\r\nHost: localhost\r\n\r\n",
                "a".repeat(70_000)
            ),
            414,
        ),
        (format!("{head}Bad Header\r\n\r\n"), 400),
        ("GARBAGE\r\n\r\n".to_string(), 400),
    ];
    for (request, status) in cases {
        let answer = raw(&f.server.base, request.as_bytes()).await;
        let (head, body) = answer.split_once("\r\n\r\n").expect("a whole answer");
        assert!(head.starts_with(&format!("HTTP/1.1 {status} ")), "{head}");
        assert!(
            head.contains("content-type: application/problem+json"),
            "{head}"
        );
        let problem: Value = serde_json::from_str(body).unwrap_or_else(|e| panic!("{e}: {body}"));
        assert_eq!(problem["status"], status, "{problem}");
    }
    // A browser's head (a few KB of cookies) still passes.
    let cookies = format!(
        "{head}Cookie: {}\r\nConnection: close\r\n\r\n",
        "c".repeat(4_000)
    );
    assert!(raw(&f.server.base, cookies.as_bytes())
        .await
        .starts_with("HTTP/1.1 200 "));
    f.server.stop().await;
}
