//! Design maps through the daemon (`POST /sweeps`, issue 15): a sweep runs as a job with
//! progress, its map equals the one `ffdic sweep plan/run/merge` makes of the same spec, a bad
//! spec is refused naming the field with nothing queued, and a cancelled sweep stops.

use crate::common::daemon;

use daemon::{
    client, get, get_json, post, read_events, small_config, wait_terminal, wait_until, TestServer,
};
use serde_json::{json, Value};
use std::path::Path;
use std::process::Command;

/// The tests that keep both cores busy or time a cancel run one at a time: a cancel's latency
/// timed while the file's other tests render and correlate on the same two cores measures them
/// (a diagnosis's cancel took 1.1 s in CI beside them, at most 304 ms alone).
static HEAVY: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// `config/sweeps/smoke.toml` as the JSON body of `POST /sweeps`.
fn smoke_spec() -> Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sweeps/smoke.toml");
    let spec: toml::Value = toml::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    serde_json::to_value(spec).unwrap()
}

/// The CLI's `map.csv` of `spec` (written as TOML into `dir`).
fn cli_map_csv(spec: &Value, dir: &Path) -> String {
    let spec_path = dir.join("spec.toml");
    let toml_spec: toml::Value = serde_json::from_value(spec.clone()).unwrap();
    std::fs::write(&spec_path, toml::to_string(&toml_spec).unwrap()).unwrap();
    let sweep = dir.join("sweep");
    for args in [
        vec![
            "sweep".into(),
            "plan".into(),
            spec_path.display().to_string(),
            "--out".into(),
            sweep.display().to_string(),
        ],
        vec!["sweep".into(), "run".into(), sweep.display().to_string()],
        vec!["sweep".into(), "merge".into(), sweep.display().to_string()],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_ffdic"))
            .args(&args)
            .env("RUST_LOG", "warn")
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    std::fs::read_to_string(sweep.join("map.csv")).unwrap()
}

/// Every figure sweep `id`'s `map` names is served as SVG; the bias plots exist (two sub-pixel
/// positions), and the heat map marks the paper's prints.
async fn check_every_figure_is_served(server: &TestServer, id: &str, map: &Value) {
    let figures: Vec<&str> = map["figures"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap())
        .collect();
    assert!(figures.contains(&"map_u_std_px_0.svg"), "{figures:?}");
    assert!(
        figures.iter().any(|f| f.starts_with("bias_u_ff25_")),
        "{figures:?}"
    );
    for name in &figures {
        let r = get(&server.url(&format!("/sweeps/{id}/plots/{name}"))).await;
        assert_eq!(r.status(), 200, "{name}");
        assert_eq!(r.headers()["content-type"], "image/svg+xml");
        assert!(r.text().await.unwrap().starts_with("<svg"));
    }
    // The paper's b (3.1 px) lies between the smoke map's 2 and 4 px prints, a (6.5 px) between
    // 4 and 7: both marked at the three paper schemes.
    let heat = get(&server.url(&format!("/sweeps/{id}/plots/map_u_std_px_0.svg")))
        .await
        .text()
        .await
        .unwrap();
    assert_eq!(heat.matches(r#"class="marker""#).count(), 6);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sweep_through_the_daemon_maps_as_the_cli_does() {
    let _heavy = HEAVY.lock().await;
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(&tmp.path().join("data"))).await;
    let spec = smoke_spec();

    let r = post(&server.url("/sweeps"), &spec).await;
    assert_eq!(r.status(), 202);
    let location = r.headers()["location"].to_str().unwrap().to_string();
    let run: Value = r.json().await.unwrap();
    let id = run["id"].as_str().unwrap().to_string();
    assert!(id.starts_with("swp-"), "{id}");
    assert_eq!(location, format!("/api/v1/sweeps/{id}"));
    assert_eq!(run["kind"], "sweep");

    let done = wait_terminal(&server.url(&format!("/sweeps/{id}"))).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    let events = read_events(&server.url(&format!("/jobs/{id}/events")), None, 1000).await;
    let kinds: Vec<&str> = events.iter().map(|e| e.kind.as_str()).collect();
    for kind in ["planned", "shards_run", "merged", "succeeded"] {
        assert!(kinds.contains(&kind), "no {kind} event in {kinds:?}");
    }
    let last_progress = events.iter().rfind(|e| e.kind == "shards_run").unwrap();
    assert_eq!(last_progress.data["done"], last_progress.data["total"]);

    // The map: 3 prints x 3 schemes x 2 sub-pixel positions, 3 realisations each.
    let map: Value = get_json(&server.url(&format!("/sweeps/{id}/map"))).await;
    assert_eq!(map["name"], "smoke");
    assert_eq!(map["tasks"], 54);
    assert_eq!(map["missing_tasks"], 0);
    let cells = map["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 18);
    for c in cells {
        assert_eq!(c["n"], 3, "{c}");
        let u = &c["stats"]["u_std_px"];
        let (mean, lo, hi) = (
            u["mean"].as_f64().unwrap(),
            u["lo"].as_f64().unwrap(),
            u["hi"].as_f64().unwrap(),
        );
        assert!(lo <= mean && mean <= hi && mean > 0.0, "{c}");
    }
    assert_eq!(map["recommendations"].as_array().unwrap().len(), 6);

    // The same spec through the CLI gives the same table, byte for byte.
    let csv = get(&server.url(&format!("/sweeps/{id}/map.csv"))).await;
    assert!(csv.headers()["content-type"]
        .to_str()
        .unwrap()
        .starts_with("text/csv"));
    let csv = csv.text().await.unwrap();
    let cli_dir = tmp.path().join("cli");
    std::fs::create_dir_all(&cli_dir).unwrap();
    let cli_spec = spec.clone();
    let cli_csv = tokio::task::spawn_blocking(move || cli_map_csv(&cli_spec, &cli_dir))
        .await
        .unwrap();
    assert_eq!(csv, cli_csv);

    // The Arrow IPC file (the default feature `arrow`): the file format's magic at both ends.
    let arrow = get(&server.url(&format!("/sweeps/{id}/map.arrow"))).await;
    assert_eq!(
        arrow.headers()["content-type"],
        "application/vnd.apache.arrow.file"
    );
    let arrow = arrow.bytes().await.unwrap();
    assert!(arrow.starts_with(b"ARROW1") && arrow.ends_with(b"ARROW1"));

    check_every_figure_is_served(&server, &id, &map).await;

    let listed: Vec<Value> = get_json(&server.url("/sweeps")).await;
    assert_eq!(listed.len(), 1);
    assert_eq!(listed[0]["id"], id.as_str());
    // A sweep is no experiment, and an experiment id is no sweep.
    let r = get(&server.url(&format!("/experiments/{id}"))).await;
    assert_eq!(r.status(), 404);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_sweeps_are_refused_naming_the_field_and_queue_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let mut config = small_config(&tmp.path().join("data"));
    config.sweeps.max_tasks = 50;
    let server = TestServer::start(config).await;
    let with = |pointer: &str, value: Value| {
        let mut spec = smoke_spec();
        *spec.pointer_mut(pointer).unwrap() = value;
        spec
    };
    let mut unknown_field = smoke_spec();
    unknown_field["axes"]["dot_size"] = json!([3.0]);
    let cases = [
        // 54 tasks over this daemon's 50.
        (smoke_spec(), "axes"),
        (with("/camera/width", json!(5000)), "camera"),
        (with("/seeds", json!(0)), "seeds"),
        (
            with("/axes/dot_diameter_px", json!([0.1])),
            "dot_diameter_px",
        ),
        // Issue 36: sub-pixel dots were accepted and every task failed at once.
        (
            with("/axes/dot_diameter_px", json!([0.5])),
            "dot_diameter_px",
        ),
        (
            {
                let mut s = smoke_spec();
                s["axes"]["patterns"] = json!(["a"]);
                s["camera"]["scale_px_per_mm"] = json!(0.5);
                s
            },
            "patterns",
        ),
        (with("/axes/subpixel_x", json!([2.0])), "subpixel_x"),
        (with("/axes/schemes", json!(["ff12"])), "schemes"),
        (with("/dic/subset_px", json!(30)), "dic"),
        (with("/name", json!("")), "name"),
        (
            {
                let mut s = smoke_spec();
                s["model"] = json!("no-such-model");
                s
            },
            "model",
        ),
        (unknown_field, "dot_size"),
        (
            {
                let mut s = smoke_spec();
                s["axes"]["pixel_aperture"] = json!([[0.0, 1.0]]);
                s
            },
            "pixel_aperture",
        ),
    ];
    for (body, field) in cases {
        let r = post(&server.url("/sweeps"), &body).await;
        let status = r.status();
        let problem: Value = r.json().await.unwrap();
        assert_eq!(status, 422, "{field}: {problem}");
        assert!(
            problem.to_string().contains(field),
            "{field} not named: {problem}"
        );
    }
    let listed: Vec<Value> = get_json(&server.url("/sweeps")).await;
    assert!(listed.is_empty(), "{listed:?}");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cancelled_sweep_stops_and_keeps_what_it_finished() {
    let _heavy = HEAVY.lock().await;
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let server = TestServer::start(small_config(&data)).await;
    // 64 shards of 512x512 renderings: long enough to cancel in the middle.
    let mut spec = smoke_spec();
    spec["camera"]["width"] = json!(512);
    spec["camera"]["height"] = json!(512);
    spec["seeds"] = json!(32);
    spec["axes"]["dot_diameter_px"] = json!([3.0]);
    let r = post(&server.url("/sweeps"), &spec).await;
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    wait_until(&server.url(&format!("/sweeps/{id}")), |r| {
        r["progress"].as_f64().unwrap_or(0.0) > 0.0
    })
    .await;
    let r = client()
        .post(server.url(&format!("/jobs/{id}/cancel")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let done = wait_terminal(&server.url(&format!("/sweeps/{id}"))).await;
    assert_eq!(done["status"], "cancelled", "{done}");
    let results = std::fs::read_dir(data.join("runs").join(&id).join("sweep/results"))
        .unwrap()
        .count();
    assert!(
        results > 0 && results < 192,
        "{results} of 192 task results kept"
    );
    // No map of a sweep that did not finish.
    let r = get(&server.url(&format!("/sweeps/{id}/map"))).await;
    assert_eq!(r.status(), 404);
    server.stop().await;
}

/// Issue 36 (3): a sweep was watched between its shards only, and a shard of a large sensor
/// (two renderings and three correlations) takes seconds. Cancelled during its rendering and
/// during its correlations, a one-shard sweep of a 4096x4096 sensor ends within a second.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sweep_is_cancelled_within_a_second_inside_its_shard() {
    let _heavy = HEAVY.lock().await;
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(&tmp.path().join("data"))).await;
    let mut spec = smoke_spec();
    spec["camera"]["width"] = json!(4096);
    spec["camera"]["height"] = json!(4096);
    spec["seeds"] = json!(1);
    spec["axes"]["dot_diameter_px"] = json!([3.0]);
    spec["axes"]["subpixel_x"] = json!([0.0]);
    for delay_ms in [300u64, 1_500, 3_000, 4_000] {
        spec["name"] = json!(format!("big-{delay_ms}"));
        let r = post(&server.url("/sweeps"), &spec).await;
        assert_eq!(r.status(), 202);
        let id = r.json::<Value>().await.unwrap()["id"]
            .as_str()
            .unwrap()
            .to_string();
        let url = server.url(&format!("/jobs/{id}"));
        wait_until(&url, |r| r["status"] == "running").await;
        tokio::time::sleep(std::time::Duration::from_millis(delay_ms)).await;
        let t0 = std::time::Instant::now();
        let r = client().post(format!("{url}/cancel")).send().await.unwrap();
        if r.status() == 409 {
            let ended: Value = client()
                .get(&url)
                .send()
                .await
                .unwrap()
                .json()
                .await
                .unwrap();
            println!(
                "the sweep had ended before {delay_ms} ms: {}",
                ended["message"]
            );
            continue;
        }
        let done = wait_until(&url, |r| r["status"] != "running").await;
        let took = t0.elapsed();
        println!(
            "sweep cancelled {delay_ms} ms in: after {} ms",
            took.as_millis()
        );
        assert_eq!(done["status"], "cancelled", "{done}");
        assert!(took < std::time::Duration::from_secs(1), "after {took:?}");
    }
    server.stop().await;
}
