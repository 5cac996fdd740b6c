#![allow(dead_code)] // each test file uses a part of it
//! A daemon for tests: the real service and router on a loopback port 0, on a small mock bench
//! (400x320 px at 13 px/mm) so an experiment takes a second, and an SSE reader.

use ffdic::service::{mock_bench, CameraConfig, DaemonConfig, MockBinning, Service};
use serde_json::{json, Value};
use std::path::Path;
use std::time::{Duration, Instant};

pub const WIDTH_PX: usize = 400;
pub const HEIGHT_PX: usize = 320;
pub const SCALE_PX_PER_MM: f64 = 13.0;

pub fn small_config(data_dir: &Path) -> DaemonConfig {
    let mut c = DaemonConfig::embedded();
    c.data_dir = data_dir.to_owned();
    c.listen = "127.0.0.1:0".parse().unwrap();
    c.bench.scale_px_per_mm = SCALE_PX_PER_MM;
    c.camera = CameraConfig::Mock {
        width: WIDTH_PX,
        height: HEIGHT_PX,
        exposure_level: 0.5,
        bench_model: "paper-bench".into(),
        hardware_binning: MockBinning::Digital,
        hardware_decimation_max: 2,
    };
    c
}

/// The same bench as a config file, for the `ffdic serve` binary.
pub fn small_config_toml(data_dir: &Path) -> String {
    format!(
        r#"data_dir = "{}"
listen = "127.0.0.1:0"
[bench]
scale_px_per_mm = {SCALE_PX_PER_MM}
[camera]
kind = "mock"
width = {WIDTH_PX}
height = {HEIGHT_PX}
[stage]
kind = "mock"
speed_mm_s = 25.0
settle_ms = 10
"#,
        data_dir.display()
    )
}

/// One pattern, `moves` moves of 0.5 mm steps along x, small DIC settings.
pub fn small_request(moves: usize) -> Value {
    let moves: Vec<Value> = (1..=moves)
        .map(|k| json!({"id": format!("x{k}"), "dx_mm": 0.5 * k as f64, "dy_mm": 0.0}))
        .collect();
    json!({
        "name": "small",
        "patterns": ["a"],
        "moves": moves,
        "settle_ms": 0,
        "dic": {"subset_px": 21, "step_px": 10, "strain_window": 5}
    })
}

/// The mock bench `config` describes (its camera on the paper's bench model).
pub fn small_bench(config: &DaemonConfig) -> ffdic::bench::BenchHardware {
    let geometry = config.mock_geometry().unwrap();
    let truth = ffdic::service::load_bench_model("paper-bench").unwrap();
    mock_bench(
        geometry,
        truth,
        config.mock_reduction().unwrap_or_default(),
        25.0,
        Duration::from_millis(10),
    )
    .unwrap()
}

pub struct TestServer {
    pub base: String,
    pub service: Service,
    pub task: tokio::task::JoinHandle<()>,
}

impl TestServer {
    /// Starts the service and the router on 127.0.0.1:0 (call inside a multi-thread runtime).
    pub async fn start(config: DaemonConfig) -> Self {
        let hardware = small_bench(&config);
        Self::start_on(config, hardware).await
    }

    /// Starts the service on `hardware` (the small mock bench, altered by the test).
    pub async fn start_on(config: DaemonConfig, hardware: ffdic::bench::BenchHardware) -> Self {
        let (service, _) = Service::start(config, hardware).unwrap();
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let base = format!("http://{}", listener.local_addr().unwrap());
        let app = ffdic::api::app(service.clone(), ffdic::dashboard::router());
        let shutdown = service.shutdown.clone();
        let limits = service.config.http.clone();
        let task = tokio::spawn(async move {
            ffdic::api::run(listener, app, shutdown, &limits)
                .await
                .unwrap();
        });
        Self {
            base,
            service,
            task,
        }
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}/api/v1{path}", self.base)
    }

    pub async fn stop(self) {
        let s = self.service.clone();
        tokio::task::spawn_blocking(move || s.stop(Duration::from_secs(8)))
            .await
            .unwrap();
        let _ = tokio::time::timeout(Duration::from_secs(10), self.task).await;
    }
}

pub fn client() -> reqwest::Client {
    reqwest::Client::builder()
        .timeout(Duration::from_secs(120))
        .build()
        .unwrap()
}

/// POSTs `body` as JSON to `url`.
pub async fn post(url: &str, body: &Value) -> reqwest::Response {
    client().post(url).json(body).send().await.unwrap()
}

pub async fn get(url: &str) -> reqwest::Response {
    client().get(url).send().await.unwrap()
}

/// GETs `url` and reads its body as JSON into `T` (whatever the status).
pub async fn get_json<T: serde::de::DeserializeOwned>(url: &str) -> T {
    get(url).await.json().await.unwrap()
}

/// One server-sent event.
#[derive(Debug, Clone)]
pub struct Sse {
    pub id: u64,
    pub kind: String,
    pub data: Value,
}

/// Reads events from `url` until a terminal one (or `limit`), resuming after `last_id`.
pub async fn read_events(url: &str, last_id: Option<u64>, limit: usize) -> Vec<Sse> {
    let mut req = client().get(url);
    if let Some(id) = last_id {
        req = req.header("Last-Event-ID", id.to_string());
    }
    let mut resp = req.send().await.unwrap();
    assert_eq!(resp.status(), 200);
    assert!(resp.headers()["content-type"]
        .to_str()
        .unwrap()
        .starts_with("text/event-stream"));
    let mut out = Vec::new();
    let mut buffer = String::new();
    let deadline = Instant::now() + Duration::from_secs(120);
    while Instant::now() < deadline {
        let chunk = match tokio::time::timeout(Duration::from_secs(60), resp.chunk()).await {
            Ok(Ok(Some(c))) => c,
            _ => break,
        };
        buffer.push_str(&String::from_utf8_lossy(&chunk));
        while let Some(end) = buffer.find("\n\n") {
            let block: String = buffer.drain(..end + 2).collect();
            let (mut id, mut kind, mut data) = (None, String::new(), String::new());
            for line in block.lines() {
                if let Some(v) = line.strip_prefix("id:") {
                    id = v.trim().parse().ok();
                } else if let Some(v) = line.strip_prefix("event:") {
                    kind = v.trim().to_string();
                } else if let Some(v) = line.strip_prefix("data:") {
                    data.push_str(v.trim());
                }
            }
            if let Some(id) = id {
                let terminal = ["succeeded", "failed", "cancelled"].contains(&kind.as_str());
                out.push(Sse {
                    id,
                    kind,
                    data: serde_json::from_str(&data).unwrap_or(Value::Null),
                });
                if terminal || out.len() >= limit {
                    return out;
                }
            }
        }
    }
    out
}

/// Polls `url` (a run) until its status is terminal.
pub async fn wait_terminal(url: &str) -> Value {
    let deadline = Instant::now() + Duration::from_secs(180);
    loop {
        let r: Value = client()
            .get(url)
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        if ["succeeded", "failed", "cancelled"].contains(&r["status"].as_str().unwrap_or("")) {
            return r;
        }
        assert!(Instant::now() < deadline, "run never ended: {r}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// Polls `url` until `pred` holds for the run record.
pub async fn wait_until(url: &str, pred: impl Fn(&Value) -> bool) -> Value {
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let r: Value = client()
            .get(url)
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        if pred(&r) {
            return r;
        }
        assert!(Instant::now() < deadline, "condition never held: {r}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// `ffdic serve` as a child process; the first stdout line names the address.
pub struct ServeProcess {
    pub child: std::process::Child,
    pub base: String,
}

/// A daemon a test leaves (by returning or by panicking) is killed: left running it would keep
/// the test runner's output pipe open, and CI waiting.
impl Drop for ServeProcess {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

impl ServeProcess {
    pub fn spawn(args: &[&str]) -> Self {
        let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_ffdic"));
        command
            .env("RUST_LOG", "warn")
            .stderr(std::process::Stdio::inherit());
        Self::start(command, args)
    }

    /// [`ServeProcess::spawn`] behind a wrapper command (`prlimit --as=… --`).
    pub fn spawn_under(wrapper: &[&str], args: &[&str]) -> Self {
        let mut command = std::process::Command::new(wrapper[0]);
        command
            .args(&wrapper[1..])
            .arg(env!("CARGO_BIN_EXE_ffdic"))
            .env("RUST_LOG", "warn")
            .stderr(std::process::Stdio::inherit());
        Self::start(command, args)
    }

    /// [`ServeProcess::spawn`] at the default log level, stderr into the file `log`.
    pub fn spawn_logging_to(args: &[&str], log: &std::path::Path) -> Self {
        let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_ffdic"));
        command
            .env_remove("RUST_LOG")
            .stderr(std::fs::File::create(log).unwrap());
        Self::start(command, args)
    }

    fn start(mut command: std::process::Command, args: &[&str]) -> Self {
        use std::io::BufRead;
        let mut child = command
            .arg("serve")
            .args(args)
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        std::io::BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let base = line
            .trim()
            .strip_prefix("listening on ")
            .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
            .to_string();
        Self { child, base }
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}/api/v1{path}", self.base)
    }

    /// Sends SIGTERM and waits for the exit, failing the test past `limit`; the exit status
    /// and how long it took.
    pub fn terminate_within(&mut self, limit: Duration) -> (std::process::ExitStatus, Duration) {
        let t0 = Instant::now();
        let signalled = std::process::Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(signalled.success());
        loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                return (s, t0.elapsed());
            }
            assert!(
                t0.elapsed() < limit,
                "still running {limit:?} after SIGTERM"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

/// Waits for job `id` to end, however it ends.
pub fn ended(
    service: &ffdic::service::Service,
    id: &ffdic::store::RunId,
) -> ffdic::store::RunRecord {
    loop {
        let r = service.store.get(id).unwrap();
        if r.status.is_terminal() {
            return r;
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// Waits for job `id` to end; it must have succeeded.
pub fn succeeded(
    service: &ffdic::service::Service,
    id: &ffdic::store::RunId,
) -> ffdic::store::RunRecord {
    let record = ended(service, id);
    assert_eq!(
        record.status,
        ffdic::store::RunStatus::Succeeded,
        "{}",
        record.message
    );
    record
}
