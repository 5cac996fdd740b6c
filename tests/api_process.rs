//! `ffdic serve` as a process: killed mid-run and restarted (the run is failed with the reason,
//! earlier runs intact), SIGTERM mid-run (cancelled, stage stopped, exit within 10 s), and a
//! non-loopback address without a token refused.

use crate::common::daemon;

use daemon::{client, small_config_toml, small_request, wait_terminal, wait_until, ServeProcess};
use serde_json::Value;
use std::time::{Duration, Instant};

/// `127.0.0.1:PORT` of a base URL `http://127.0.0.1:PORT`.
fn host_port(base: &str) -> String {
    base.trim_start_matches("http://")
        .split('/')
        .next()
        .unwrap()
        .to_string()
}

fn config_file(dir: &std::path::Path) -> String {
    let data = dir.join("data");
    let path = dir.join("ffdic.toml");
    std::fs::write(&path, small_config_toml(&data)).unwrap();
    path.display().to_string()
}

async fn start_experiment(server: &ServeProcess, moves: usize) -> String {
    let r: Value = client()
        .post(server.url("/experiments"))
        .json(&small_request(moves))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    server.url(&format!("/experiments/{}", r["id"].as_str().unwrap()))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn killed_mid_run_the_run_is_failed_after_restart_and_earlier_runs_are_intact() {
    let tmp = tempfile::tempdir().unwrap();
    let config = config_file(tmp.path());
    let mut server = ServeProcess::spawn(&["--config", &config]);
    let done_url = start_experiment(&server, 1).await;
    let done = wait_terminal(&done_url).await;
    assert_eq!(done["status"], "succeeded");
    let done_id = done["id"].as_str().unwrap().to_string();
    let run_json = tmp.path().join("data/runs").join(&done_id).join("run.json");
    let before = std::fs::read(&run_json).unwrap();

    let url = start_experiment(&server, 8).await;
    wait_until(&url, |r| r["status"] == "running").await;
    server.child.kill().unwrap(); // SIGKILL: no chance to clean up
    server.child.wait().unwrap();

    let restarted = ServeProcess::spawn(&["--config", &config]);
    let url = url.replace(&server.base, &restarted.base);
    let r: Value = client()
        .get(&url)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(r["status"], "failed", "{r}");
    assert!(
        r["message"].as_str().unwrap().contains("stopped"),
        "the reason is given: {r}"
    );
    assert_eq!(
        std::fs::read(&run_json).unwrap(),
        before,
        "a finished run is never rewritten"
    );
    let old: Value = client()
        .get(done_url.replace(&server.base, &restarted.base))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(old["status"], "succeeded");
    let mut restarted = restarted;
    restarted.child.kill().unwrap();
    restarted.child.wait().unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_cancels_the_running_experiment_and_exits_within_ten_seconds() {
    let tmp = tempfile::tempdir().unwrap();
    let config = config_file(tmp.path());
    let mut server = ServeProcess::spawn(&["--config", &config]);
    let url = start_experiment(&server, 20).await;
    wait_until(&url, |r| r["progress"].as_f64().unwrap_or(0.0) > 0.0).await;
    let id = url.rsplit('/').next().unwrap().to_string();
    // A stalled client: a request head begun and never finished (it once held shutdown 39 s).
    let mut stalled = std::net::TcpStream::connect(host_port(&server.base)).unwrap();
    std::io::Write::write_all(
        &mut stalled,
        b"GET /api/v1/health HTTP/1.1\r\nHost: 127.0.0.1\r\n",
    )
    .unwrap();
    let (exit, _) = server.terminate_within(Duration::from_secs(10));
    assert!(exit.success(), "{exit:?}");
    let record: Value = serde_json::from_slice(
        &std::fs::read(tmp.path().join("data/runs").join(&id).join("run.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(record["status"], "cancelled", "{record}");
}

#[test]
fn a_non_loopback_address_without_a_token_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let config = config_file(tmp.path());
    // Refused before anything binds: no traffic leaves loopback.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_ffdic"))
        .args(["serve", "--config", &config, "--listen", "0.0.0.0:0"])
        .env_remove("FFDIC_TOKEN")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("token"), "{err}");
    assert!(out.stdout.is_empty(), "nothing was served");
}

/// At the default level a log file gets one line per request (method, path, status, latency)
/// and no terminal colour codes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn requests_are_logged_one_line_each_without_colour_in_a_file() {
    let tmp = tempfile::tempdir().unwrap();
    let config = config_file(tmp.path());
    let log = tmp.path().join("serve.log");
    let mut server = ServeProcess::spawn_logging_to(&["--config", &config], &log);
    let base = server.base.clone();
    for _ in 0..3 {
        let r = client()
            .get(format!("{base}/api/v1/health"))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
    }
    let r = client()
        .get(format!("{base}/api/v1/experiments/nope"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 404);
    // The log is written as responses finish; give the last line a moment.
    let t0 = Instant::now();
    let text = loop {
        let text = std::fs::read_to_string(&log).unwrap();
        if text.contains("404") || t0.elapsed() > Duration::from_secs(5) {
            break text;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    server.child.kill().unwrap();
    server.child.wait().unwrap();
    assert!(
        !text.contains('\u{1b}'),
        "colour codes in a log file:\n{text}"
    );
    let health: Vec<&str> = text
        .lines()
        .filter(|l| l.contains("/api/v1/health") && l.contains("200"))
        .collect();
    assert_eq!(health.len(), 3, "one line per request:\n{text}");
    assert!(
        text.lines()
            .any(|l| l.contains("/api/v1/experiments/nope") && l.contains("404")),
        "{text}"
    );
}

/// Issue 12: 2,000 half-open connections (each a request head begun and never finished; 1,100
/// once took the daemon offline at a 1024 open-files limit) leave `/health` answering. They come
/// from other addresses than the probe: one address holds at most
/// `http.max_connections_per_client` (tests/api_bounded.rs).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_thousand_half_open_connections_leave_health_answering() {
    const CONNECTIONS: usize = 2000;
    // This test process needs the descriptors too.
    // SAFETY: getrlimit/setrlimit only read and write the struct passed.
    unsafe {
        let mut l = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        assert_eq!(libc::getrlimit(libc::RLIMIT_NOFILE, &mut l), 0);
        let want = (CONNECTIONS as libc::rlim_t + 512).min(l.rlim_max);
        if l.rlim_cur < want {
            l.rlim_cur = want;
            assert_eq!(libc::setrlimit(libc::RLIMIT_NOFILE, &l), 0);
        }
        assert!(
            l.rlim_cur >= CONNECTIONS as libc::rlim_t + 256,
            "the hard open-files limit ({}) is below the test's need",
            l.rlim_max
        );
    }
    let tmp = tempfile::tempdir().unwrap();
    let config = config_file(tmp.path());
    let server = ServeProcess::spawn(&["--config", &config]);
    let addr: std::net::SocketAddr = host_port(&server.base).parse().unwrap();
    // From ten other loopback addresses, 200 each: within the per-client cap (256), so all 2000
    // are held and it is the descriptors and the connection slots that are tested.
    let mut open = Vec::with_capacity(CONNECTIONS);
    for k in 0..CONNECTIONS {
        let socket = tokio::net::TcpSocket::new_v4().unwrap();
        let source = format!("127.0.1.{}:0", 1 + k % 10);
        socket.bind(source.parse().unwrap()).unwrap();
        let mut c = socket.connect(addr).await.unwrap();
        tokio::io::AsyncWriteExt::write_all(&mut c, b"GET /api/v1/health HTTP/1.1\r\n")
            .await
            .unwrap();
        open.push(c);
    }
    let t = Instant::now();
    let health = reqwest::Client::builder()
        .timeout(Duration::from_secs(5))
        .build()
        .unwrap()
        .get(server.url("/health"))
        .send()
        .await
        .expect("/health answers beside 2000 half-open connections");
    println!(
        "/health beside {CONNECTIONS} half-open connections: {} in {:.1} ms",
        health.status(),
        t.elapsed().as_secs_f64() * 1e3
    );
    assert_eq!(health.status(), 200);
    drop(open);
}
