//! Issue 36: the daemon bounded. Each test is a reproducer of what a valid-looking request once
//! did — an upload of 0.5 MB that allocated gigabytes, clients that never read and held every
//! connection slot, an upload trickling a byte at a time, a check that outlived its client —
//! and asserts the bound that now holds. The bomb frames are generated here, not committed.

use crate::common::daemon;

use daemon::{
    client, get_json, small_config, small_request, wait_terminal, ServeProcess, TestServer,
};
use serde_json::{json, Value};
use std::net::SocketAddr;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// The tests that keep both cores busy or time a cancel run one at a time: a cancel's latency
/// timed while the file's other tests render and correlate on the same two cores measures them
/// (a diagnosis's cancel took 1.1 s in CI beside them, at most 304 ms alone).
static HEAVY: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// A deflate-compressed 16-bit grey TIFF of `side`² zeros (`side` a multiple of 256), written
/// by hand: every strip of 256 rows is the same zlib stream, compressed once, so the test never
/// holds the decoded frame. 16384² is 512 MB decoded and about 0.5 MB on the wire.
fn deflate_bomb(side: u32) -> Vec<u8> {
    use std::io::Write;
    const ROWS: u32 = 256;
    let strips = side / ROWS;
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    z.write_all(&vec![0u8; (side * ROWS * 2) as usize]).unwrap();
    let strip = z.finish().unwrap();
    // Little-endian header, then the strips, the two offset tables and the IFD.
    let mut out = b"II*\0".to_vec();
    out.extend_from_slice(&0u32.to_le_bytes()); // the IFD's offset, set below
    let first = out.len() as u32;
    for _ in 0..strips {
        out.extend_from_slice(&strip);
    }
    let offsets_at = out.len() as u32;
    for k in 0..strips {
        out.extend_from_slice(&(first + k * strip.len() as u32).to_le_bytes());
    }
    let counts_at = out.len() as u32;
    for _ in 0..strips {
        out.extend_from_slice(&(strip.len() as u32).to_le_bytes());
    }
    let ifd_at = out.len() as u32;
    out[4..8].copy_from_slice(&ifd_at.to_le_bytes());
    // (tag, type: 3 SHORT / 4 LONG, count, value or offset), in ascending tag order.
    let entries: [(u16, u16, u32, u32); 9] = [
        (256, 4, 1, side),            // ImageWidth
        (257, 4, 1, side),            // ImageLength
        (258, 3, 1, 16),              // BitsPerSample
        (259, 3, 1, 8),               // Compression: Deflate
        (262, 3, 1, 1),               // PhotometricInterpretation: BlackIsZero
        (273, 4, strips, offsets_at), // StripOffsets
        (277, 3, 1, 1),               // SamplesPerPixel
        (278, 4, 1, ROWS),            // RowsPerStrip
        (279, 4, strips, counts_at),  // StripByteCounts
    ];
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    for (tag, kind, count, value) in entries {
        out.extend_from_slice(&tag.to_le_bytes());
        out.extend_from_slice(&kind.to_le_bytes());
        out.extend_from_slice(&count.to_le_bytes());
        out.extend_from_slice(&value.to_le_bytes());
    }
    out.extend_from_slice(&0u32.to_le_bytes());
    out
}

#[test]
fn the_hand_written_bomb_is_a_valid_tiff() {
    let bytes = deflate_bomb(512);
    let (image, info) =
        ffdic::image::decode_tiff(&bytes, std::path::Path::new("bomb.tif")).unwrap();
    assert_eq!((info.width, info.height, info.bit_depth), (512, 512, 16));
    assert!(image.data().iter().all(|&v| v == 0.0));
}

/// A hashed 16-bit texture (no renderer of ours) shifted by `dx` px, uncompressed.
fn texture_tiff(w: usize, h: usize, dx: i64) -> Vec<u8> {
    let data: Vec<u16> = (0..w * h)
        .map(|k| {
            let (c, r) = ((k % w) as i64 - dx, (k / w) as u64);
            let mut s = (c as u64).wrapping_mul(73_856_093) ^ r.wrapping_mul(19_349_663);
            s ^= s >> 13;
            (s.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 52) as u16
        })
        .collect();
    ffdic::image::tiff_u16_bytes(w, h, &data).unwrap()
}

fn manifest(runs: &[(&str, &str, &str, f64)], scale_px_per_mm: f64) -> Vec<u8> {
    let runs: Vec<Value> = runs
        .iter()
        .map(|(id, reference, deformed, dx_mm)| {
            json!({"id": id, "reference": reference, "deformed": deformed,
                   "stage": {"dx_mm": dx_mm, "dy_mm": 0.0}})
        })
        .collect();
    json!({"format": "ffdic-dataset/1", "name": "bounded", "scale_px_per_mm": scale_px_per_mm,
           "runs": runs})
    .to_string()
    .into_bytes()
}

/// `runs` runs over one pair of frames (`ref.tif`, `def.tif`), each stating a move of `dx_mm`
/// at 13 px/mm.
fn pair_form(
    reference: &[u8],
    deformed: &[u8],
    runs: usize,
    dx_mm: f64,
) -> reqwest::multipart::Form {
    let ids: Vec<String> = (0..runs).map(|k| format!("r{k}")).collect();
    let rows: Vec<(&str, &str, &str, f64)> = ids
        .iter()
        .map(|id| (id.as_str(), "ref.tif", "def.tif", dx_mm))
        .collect();
    form(vec![
        ("dataset.json".into(), manifest(&rows, 13.0)),
        ("ref.tif".into(), reference.to_vec()),
        ("def.tif".into(), deformed.to_vec()),
    ])
}

fn form(parts: Vec<(String, Vec<u8>)>) -> reqwest::multipart::Form {
    parts
        .into_iter()
        .fold(reqwest::multipart::Form::new(), |f, (name, bytes)| {
            f.part(
                name.clone(),
                reqwest::multipart::Part::bytes(bytes).file_name(name),
            )
        })
}

/// The upload bomb of issue 36: two 16384² frames of 0.5 MB each, a stated move of 3,000 px.
fn bomb_form() -> reqwest::multipart::Form {
    let bomb = deflate_bomb(16_384);
    assert!(bomb.len() < 2 << 20, "{} bytes", bomb.len());
    form(vec![
        (
            "dataset.json".into(),
            manifest(&[("r1", "ref.tif", "def.tif", 3000.0 / 13.0)], 13.0),
        ),
        ("ref.tif".into(), bomb.clone()),
        ("def.tif".into(), bomb),
    ])
}

async fn assert_health_within(base_api: &str, limit: Duration) {
    let c = reqwest::Client::builder().timeout(limit).build().unwrap();
    let t0 = Instant::now();
    let r = c.get(format!("{base_api}/health")).send().await;
    let took = t0.elapsed();
    let status = r.map(|r| r.status().as_u16());
    assert_eq!(status.ok(), Some(200), "/health after {took:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_upload_bomb_is_refused_from_its_header_and_a_large_stated_move_costs_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let r = client()
        .post(server.url("/datasets"))
        .multipart(bomb_form())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 422);
    let p: Value = r.json().await.unwrap();
    let detail = p["detail"].as_str().unwrap();
    assert!(
        detail.contains("ref.tif") && detail.contains("16384x16384"),
        "{p}"
    );
    assert!(
        !detail.contains(&tmp.path().display().to_string()),
        "no server path: {p}"
    );
    assert_eq!(p["field"], "file");
    // Nothing left behind.
    let staged: Vec<_> = std::fs::read_dir(tmp.path().join("datasets"))
        .unwrap()
        .flatten()
        .collect();
    assert!(staged.is_empty(), "{staged:?}");
    assert_health_within(&server.url(""), Duration::from_secs(1)).await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_manifest_past_the_run_cap_is_refused_naming_runs_and_many_runs_over_one_pair_pass() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    let (reference, deformed) = (texture_tiff(96, 80, 0), texture_tiff(96, 80, 13));
    let upload = |runs: usize| pair_form(&reference, &deformed, runs, 1.0);
    // Issue 36's 2,000 runs over one pair.
    let r = client()
        .post(server.url("/datasets"))
        .multipart(upload(2_000))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 422);
    let p: Value = r.json().await.unwrap();
    assert_eq!(p["field"], "runs", "{p}");
    assert!(p["detail"].as_str().unwrap().contains("1000"), "{p}");
    // Within the cap, runs that share a pair are checked once: it lands.
    let r = client()
        .post(server.url("/datasets"))
        .multipart(upload(1_000))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let record: Value = r.json().await.unwrap();
    assert_eq!(record["runs"], 1000);
    assert_eq!(record["bit_depth"], 16, "recorded at upload: {record}");
    let id = record["id"].as_str().unwrap();
    let details: Value = get_json(&server.url(&format!("/datasets/{id}/details"))).await;
    assert_eq!(details["bit_depth"], 16);
    server.stop().await;
}

/// Runs a one-move experiment on the daemon at `base`; the path of one of its frames.
async fn experiment_frame(base: &str) -> String {
    let r: Value = client()
        .post(format!("{base}/api/v1/experiments"))
        .json(&small_request(1))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let id = r["id"].as_str().unwrap().to_string();
    let run = wait_terminal(&format!("{base}/api/v1/experiments/{id}")).await;
    assert_eq!(run["status"], "succeeded", "{run}");
    let frame = run["result_files"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|f| f.as_str())
        .find(|f| f.starts_with("frames/") && f.ends_with(".tif"))
        .unwrap()
        .to_string();
    format!("/api/v1/jobs/{id}/files/{frame}")
}

/// A socket from `source` (another loopback address: the per-client limit counts addresses)
/// with a tiny receive buffer, so the server's writes stall as soon as the client stops reading.
async fn slow_reader(
    source: &str,
    server: SocketAddr,
    path: &str,
) -> Option<tokio::net::TcpStream> {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    socket.bind(format!("{source}:0").parse().unwrap()).unwrap();
    let mut stream = socket.connect(server).await.ok()?;
    let head = format!("GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n");
    stream.write_all(head.as_bytes()).await.ok()?;
    Some(stream)
}

/// Reads what is left of a stalled response; the number of bytes the client got in all.
async fn drain(mut stream: tokio::net::TcpStream) -> usize {
    let mut total = 0;
    let mut buf = vec![0u8; 64 * 1024];
    while let Ok(Ok(n)) = tokio::time::timeout(Duration::from_secs(5), stream.read(&mut buf)).await
    {
        if n == 0 {
            break;
        }
        total += n;
    }
    total
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_that_never_read_hold_neither_every_slot_nor_their_own_for_long() {
    let tmp = tempfile::tempdir().unwrap();
    let mut config = small_config(tmp.path());
    config.http.max_connections = 80;
    config.http.max_connections_per_client = 32;
    config.http.write_stall_timeout_ms = 2_000;
    // 8 MB frames, as a lab camera's (the were 11 MB): more than the socket buffers on
    // both sides hold, so a client that does not read stalls the server's writes.
    config.camera = ffdic::service::CameraConfig::Mock {
        width: 2048,
        height: 2048,
        exposure_level: 0.5,
        bench_model: "paper-bench".into(),
        hardware_binning: ffdic::service::MockBinning::Digital,
        hardware_decimation_max: 2,
    };
    let server = TestServer::start(config).await;
    let path = experiment_frame(&server.base).await;
    let frame_bytes = client()
        .get(format!("{}{path}", server.base))
        .send()
        .await
        .unwrap()
        .bytes()
        .await
        .unwrap()
        .len();
    let addr: SocketAddr = server.base.trim_start_matches("http://").parse().unwrap();

    // Issue 36: 80 such clients held all 80 slots; every /health probe was refused.
    let mut held = Vec::new();
    for _ in 0..100 {
        if let Some(s) = slow_reader("127.0.0.2", addr, &path).await {
            held.push(s);
        }
    }
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(1_500) {
        assert_health_within(&server.url(""), Duration::from_secs(1)).await;
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    // Past the write stall timeout every stalled response has been cut short.
    tokio::time::sleep(Duration::from_millis(2_500)).await;
    let mut got = Vec::new();
    for stream in held {
        got.push(drain(stream).await);
    }
    let cut = got.iter().filter(|&&n| n < frame_bytes).count();
    assert_eq!(
        cut,
        got.len(),
        "frame {frame_bytes} bytes; received {got:?}"
    );
    assert_health_within(&server.url(""), Duration::from_secs(1)).await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_upload_that_trickles_is_ended_by_its_pace() {
    let tmp = tempfile::tempdir().unwrap();
    let mut config = small_config(tmp.path());
    config.uploads.grace_ms = 1_000;
    config.uploads.min_bytes_per_s = 1_000;
    let server = TestServer::start(config).await;
    let addr: SocketAddr = server.base.trim_start_matches("http://").parse().unwrap();
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    let head = "POST /api/v1/datasets HTTP/1.1\r\nHost: 127.0.0.1\r\n\
                Content-Type: multipart/form-data; boundary=XyZ\r\nContent-Length: 100000\r\n\r\n\
                --XyZ\r\nContent-Disposition: form-data; name=\"ref.tif\"; filename=\"ref.tif\"\r\n\r\n";
    stream.write_all(head.as_bytes()).await.unwrap();
    // A byte every 300 ms: each piece well within the 30 s body timeout, the pace far below.
    let t0 = Instant::now();
    let mut answer = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "still open after 10 s"
        );
        if stream.write_all(b"x").await.is_err() {
            break;
        }
        match tokio::time::timeout(Duration::from_millis(300), stream.read(&mut buf)).await {
            Ok(Ok(0)) | Ok(Err(_)) => break,
            Ok(Ok(n)) => answer.extend_from_slice(&buf[..n]),
            Err(_) => {}
        }
        if answer.windows(4).any(|w| w == b"\r\n\r\n") && answer.len() > 200 {
            break;
        }
    }
    let text = String::from_utf8_lossy(&answer);
    assert!(text.starts_with("HTTP/1.1 408"), "{text}");
    assert!(text.contains("min_bytes_per_s"), "{text}");
    assert_health_within(&server.url(""), Duration::from_secs(1)).await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_check_whose_client_left_stops_and_keeps_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(tmp.path())).await;
    // 150 runs over 300 distinct flat 4096² frames: about 30 KB each on the wire, 64 MB each
    // decoded; the check decodes them one after another for tens of seconds.
    let flat = deflate_bomb(4096);
    let ids: Vec<(String, String, String)> = (0..150)
        .map(|k| {
            (
                format!("r{k}"),
                format!("ref{k}.tif"),
                format!("def{k}.tif"),
            )
        })
        .collect();
    let rows: Vec<(&str, &str, &str, f64)> = ids
        .iter()
        .map(|(i, r, d)| (i.as_str(), r.as_str(), d.as_str(), 0.0))
        .collect();
    let mut parts = vec![("dataset.json".to_string(), manifest(&rows, 13.0))];
    for (_, r, d) in &ids {
        parts.push((r.clone(), flat.clone()));
        parts.push((d.clone(), flat.clone()));
    }
    let impatient = reqwest::Client::builder()
        .timeout(Duration::from_secs(3))
        .build()
        .unwrap();
    let r = impatient
        .post(server.url("/datasets"))
        .multipart(form(parts))
        .send()
        .await;
    assert!(
        r.is_err(),
        "the check should outlast the client's 3 s: {r:?}"
    );
    let datasets = tmp.path().join("datasets");
    let left_at = Instant::now();
    loop {
        let staged = std::fs::read_dir(&datasets).unwrap().flatten().count();
        if staged == 0 {
            break;
        }
        assert!(
            left_at.elapsed() < Duration::from_secs(5),
            "the staging folder outlived its client by 5 s"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let listed: Vec<Value> = get_json(&server.url("/datasets")).await;
    assert!(listed.is_empty(), "{listed:?}");
    server.stop().await;
}

/// The daemon's address-space budget under `prlimit --as` (issue 36 asks for one, e.g. 1 GB).
const BUDGET_BYTES: u64 = 1 << 30;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn within_an_address_space_budget_bombs_large_uploads_and_slow_readers_leave_it_alive() {
    let _heavy = HEAVY.lock().await;
    if std::process::Command::new("prlimit")
        .arg("--version")
        .output()
        .is_err()
    {
        panic!("prlimit (util-linux) is needed for the memory budget test");
    }
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let config = tmp.path().join("ffdic.toml");
    std::fs::write(
        &config,
        daemon::small_config_toml(&data)
            + "[http]\nwrite_stall_timeout_ms = 2000\nmax_connections_per_client = 64\n",
    )
    .unwrap();
    let server = ServeProcess::spawn_under(
        &["prlimit", &format!("--as={BUDGET_BYTES}"), "--"],
        &["--config", &config.display().to_string()],
    );
    let api = server.url("");
    let health = tokio::spawn({
        let api = api.clone();
        async move {
            // /health within 1 s, every 200 ms, for as long as the load lasts.
            let mut probes = 0;
            loop {
                assert_health_within(&api, Duration::from_secs(1)).await;
                probes += 1;
                tokio::time::sleep(Duration::from_millis(200)).await;
                if probes >= 100 {
                    return probes;
                }
            }
        }
    });
    // The bomb.
    let r = client()
        .post(server.url("/datasets"))
        .multipart(bomb_form())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 422);
    // Three concurrent large uploads: 4096² textured frames, 32 MB each, 64 MB decoded.
    let (a, b) = (texture_tiff(4096, 4096, 0), texture_tiff(4096, 4096, 26));
    let uploads: Vec<_> = (0..3)
        .map(|_| {
            let f = pair_form(&a, &b, 1, 2.0);
            client().post(server.url("/datasets")).multipart(f).send()
        })
        .collect();
    for r in futures_join(uploads).await {
        assert_eq!(r.unwrap().status(), 201);
    }
    // A frame to read slowly (datasets serve no files; an experiment's run does).
    let path = experiment_frame(&server.base).await;
    let addr: SocketAddr = server.base.trim_start_matches("http://").parse().unwrap();
    let mut readers = Vec::new();
    for k in 0..100 {
        let source = format!("127.0.0.{}", 2 + k % 4);
        if let Some(s) = slow_reader(&source, addr, &path).await {
            readers.push(s);
        }
    }
    assert!(health.await.unwrap() >= 100);
    drop(readers);
    assert_health_within(&api, Duration::from_secs(1)).await;
    let status = std::fs::read_to_string(format!("/proc/{}/status", server.child.id())).unwrap();
    for line in status
        .lines()
        .filter(|l| l.starts_with("VmHWM") || l.starts_with("VmPeak"))
    {
        println!("daemon under the budget: {line}");
    }
    let mut server = server;
    assert!(
        server.child.try_wait().unwrap().is_none(),
        "the daemon died under the budget"
    );
    server.child.kill().unwrap();
    server.child.wait().unwrap();
}

async fn futures_join<F>(futures: Vec<F>) -> Vec<F::Output>
where
    F: std::future::Future + Send + 'static,
    F::Output: Send + 'static,
{
    // Spawned, so they run at once (a request future does nothing until polled).
    let handles: Vec<_> = futures.into_iter().map(tokio::spawn).collect();
    let mut out = Vec::new();
    for h in handles {
        out.push(h.await.unwrap());
    }
    out
}

/// Uploads one pair of `w`x`h` textured frames (moved 13 px = 1 mm at 13 px/mm) as a dataset of
/// `runs` runs over it; its id.
async fn upload_pair(api: &str, (w, h): (usize, usize), runs: usize) -> String {
    let f = pair_form(&texture_tiff(w, h, 0), &texture_tiff(w, h, 13), runs, 1.0);
    let r = client()
        .post(format!("{api}/datasets"))
        .multipart(f)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let record: Value = r.json().await.unwrap();
    record["id"].as_str().unwrap().to_string()
}

/// Issue 36's dense analysis: subset 101 px at every pixel of the 1280x1080 reductions, three
/// schemes (1.16 M points a scheme, 3.5e10 subset pixels an iteration).
fn dense_analysis() -> Value {
    json!({"schemes": ["ff100", "ff50", "ff25"],
           "dic": {"subset_px": 101, "step_px": 1,
                   "roi": {"x": 0, "y": 0, "width": 1280, "height": 1080}}})
}

async fn submit(api: &str, dataset: &str, body: &Value) -> reqwest::Response {
    client()
        .post(format!("{api}/datasets/{dataset}/analyses"))
        .json(body)
        .send()
        .await
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dense_analysis_is_cancelled_within_a_second_and_a_full_lane_answers_429() {
    let _heavy = HEAVY.lock().await;
    let tmp = tempfile::tempdir().unwrap();
    let mut config = small_config(tmp.path());
    config.jobs.max_queued_per_lane = 2;
    let server = TestServer::start(config).await;
    let api = server.url("");
    // Work bounded at submission: three runs of it pass jobs.max_analysis_subset_pixels.
    let three = upload_pair(&api, (2560, 2160), 3).await;
    let r = submit(&api, &three, &dense_analysis()).await;
    assert_eq!(r.status(), 422);
    let p: Value = r.json().await.unwrap();
    assert_eq!(p["field"], "dic.step_px", "{p}");

    let one = upload_pair(&api, (2560, 2160), 1).await;
    let r = submit(&api, &one, &dense_analysis()).await;
    assert_eq!(r.status(), 202);
    let dense: Value = r.json().await.unwrap();
    let dense_url = server.url(&format!("/jobs/{}", dense["id"].as_str().unwrap()));
    daemon::wait_until(&dense_url, |r| r["status"] == "running").await;
    // Two wait behind it; a third finds the lane full.
    let light = json!({"schemes": ["ff100"], "dic": {"subset_px": 21, "step_px": 40}});
    let mut queued = Vec::new();
    for _ in 0..2 {
        let r = submit(&api, &one, &light).await;
        assert_eq!(r.status(), 202);
        let v: Value = r.json().await.unwrap();
        queued.push(server.url(&format!("/jobs/{}", v["id"].as_str().unwrap())));
    }
    let r = submit(&api, &one, &light).await;
    assert_eq!(r.status(), 429);
    assert!(r.headers().contains_key("retry-after"), "{:?}", r.headers());
    // A cancelled job gives its place back at once, not when the worker skips it.
    let cancelled = queued.remove(0);
    let r = client()
        .post(format!("{cancelled}/cancel"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let r = submit(&api, &one, &light).await;
    assert_eq!(r.status(), 202);
    let v: Value = r.json().await.unwrap();
    queued.push(server.url(&format!("/jobs/{}", v["id"].as_str().unwrap())));
    // Deep in the correlation of its first scheme (its preparation takes about a second).
    tokio::time::sleep(Duration::from_secs(3)).await;
    let (ended, took) = cancel_and_time(&dense_url).await.expect("still running");
    println!("dense analysis cancelled in {} ms", took.as_millis());
    assert_eq!(ended["status"], "cancelled", "{ended}");
    // Issue 36: it ignored cancel for more than 166 s.
    assert!(took < Duration::from_secs(1), "cancelled after {took:?}");
    for url in queued {
        assert_eq!(wait_terminal(&url).await["status"], "succeeded");
    }
    server.stop().await;
}

/// Cancels the running job at `url`: its record once no longer running and how long that took
/// from the request; `None` when it had already ended.
async fn cancel_and_time(url: &str) -> Option<(Value, Duration)> {
    let t0 = Instant::now();
    let r = client().post(format!("{url}/cancel")).send().await.unwrap();
    if r.status() == 409 {
        return None;
    }
    assert_eq!(r.status(), 200);
    loop {
        let r: Value = get_json(url).await;
        if r["status"] != "running" {
            return Some((r, t0.elapsed()));
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Issue 36 (3): an averaged frame was one capture command, which no cancel could stop (64
/// frames of the 2560x2160 mock bench took tens of seconds). Cancelled during the capture of
/// its first frame (64 averaged, the API's maximum), an experiment ends within a second.
///
/// The cancel comes 1.5 s into the run: inside that capture while a frame takes more than
/// 23 ms. With 32 frames and 2.5 s, a fresh-clone run of 2026-12-07 found the first frame
/// already written (the mock's frames render faster since the noise table of that day).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_experiment_is_cancelled_within_a_second_inside_an_averaged_capture() {
    let _heavy = HEAVY.lock().await;
    let tmp = tempfile::tempdir().unwrap();
    let mut config = small_config(tmp.path());
    config.bench.scale_px_per_mm = 26.0;
    if let ffdic::service::CameraConfig::Mock { width, height, .. } = &mut config.camera {
        (*width, *height) = (2560, 2160);
    }
    let server = TestServer::start(config).await;
    let mut request = daemon::small_request(1);
    request["frames_averaged"] = json!(64);
    let r = client()
        .post(server.url("/experiments"))
        .json(&request)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let run: Value = r.json().await.unwrap();
    let url = server.url(&format!("/jobs/{}", run["id"].as_str().unwrap()));
    daemon::wait_until(&url, |r| r["status"] == "running").await;
    tokio::time::sleep(Duration::from_millis(1_500)).await;
    let (ended, took) = cancel_and_time(&url).await.expect("still capturing");
    println!(
        "experiment cancelled inside its capture after {} ms",
        took.as_millis()
    );
    assert_eq!(ended["status"], "cancelled", "{ended}");
    let frames = ended["result_files"].as_array().unwrap().len();
    assert_eq!(
        frames, 0,
        "cancelled before its first frame was written: {ended}"
    );
    assert!(took < Duration::from_secs(1), "after {took:?}");
    server.stop().await;
}

/// Issue 36 (3): a diagnosis was watched only between its steps (a comparison renders and
/// correlates every run, a candidate fit takes seconds). Cancelled at several moments of its
/// work on a 1280x1080 dataset of the mock bench: each ends `cancelled` within a second.
///
/// The moments are fractions of the time one diagnosis of the dataset takes here, measured
/// first: at fixed delays up to 4.4 s, a diagnosis made faster (2.3–2.5 s on 2026-12-07)
/// left most of them after its end and the test with three cancels mid-work.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_diagnosis_is_cancelled_within_a_second_wherever_it_is() {
    let _heavy = HEAVY.lock().await;
    let tmp = tempfile::tempdir().unwrap();
    let mut config = small_config(tmp.path());
    // The paper's bench at half its sensor: a dataset of two moves made by the mock bench.
    config.bench.scale_px_per_mm = 26.0;
    if let ffdic::service::CameraConfig::Mock { width, height, .. } = &mut config.camera {
        (*width, *height) = (1280, 1080);
    }
    let server = TestServer::start(config).await;
    let api = server.url("");
    let mut request = daemon::small_request(2);
    request["schemes"] = json!(["ff100"]);
    request["dic"] = json!({"subset_px": 31, "step_px": 40, "strain_window": 3});
    let r = client()
        .post(format!("{api}/experiments"))
        .json(&request)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let run: Value = r.json().await.unwrap();
    let run = wait_terminal(&server.url(&format!("/jobs/{}", run["id"].as_str().unwrap()))).await;
    assert_eq!(run["status"], "succeeded", "{run}");
    let big = run["dataset_id"].as_str().unwrap().to_string();
    let start_diagnosis = || async {
        let r = client()
            .post(format!("{api}/datasets/{big}/diagnoses"))
            .json(&json!({"model": "baseline"}))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 202);
        let job: Value = r.json().await.unwrap();
        let url = server.url(&format!("/jobs/{}", job["id"].as_str().unwrap()));
        daemon::wait_until(&url, |r| r["status"] == "running").await;
        url
    };
    // One diagnosis to its end: how long the work lasts on this machine, now, from `running`
    // as the delays below are.
    let url = start_diagnosis().await;
    let t0 = Instant::now();
    let whole = wait_terminal(&url).await;
    let whole_ms = t0.elapsed().as_millis() as f64;
    assert_eq!(whole["status"], "succeeded", "{whole}");
    println!("one diagnosis: {whole_ms:.0} ms");
    let mut latencies_ms = Vec::new();
    for fraction in [0.05, 0.18, 0.31, 0.44, 0.57, 0.70, 0.83] {
        let url = start_diagnosis().await;
        let delay_ms = (fraction * whole_ms) as u64;
        tokio::time::sleep(Duration::from_millis(delay_ms)).await;
        let Some((ended, took)) = cancel_and_time(&url).await else {
            let ended: Value = get_json(&url).await;
            println!("diagnosis had ended before {delay_ms} ms: {ended}");
            continue;
        };
        println!(
            "diagnosis cancelled {delay_ms} ms in: after {} ms ({})",
            took.as_millis(),
            ended["message"]
        );
        assert!(
            took < Duration::from_secs(1),
            "cancelled {delay_ms} ms in, after {took:?}"
        );
        // A cancel that lands after the diagnosis's last step (writing its results) is accepted
        // and the run still ends `succeeded`: its work was done. Within the same second either
        // way; a cancel ignored mid-work would take the seconds the work has left.
        if ended["status"] == "succeeded" {
            continue;
        }
        assert_eq!(ended["status"], "cancelled", "{ended}");
        latencies_ms.push(took.as_millis());
    }
    assert!(
        latencies_ms.len() >= 4,
        "only {} of 7 diagnoses were cancelled mid-work",
        latencies_ms.len()
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_with_three_thousand_queued_jobs_exits_within_ten_seconds_and_cancels_them_all() {
    let _heavy = HEAVY.lock().await;
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let config = tmp.path().join("ffdic.toml");
    std::fs::write(
        &config,
        daemon::small_config_toml(&data) + "[jobs]\nmax_queued_per_lane = 5000\n",
    )
    .unwrap();
    let mut server = ServeProcess::spawn(&["--config", &config.display().to_string()]);
    let api = server.url("");
    let big = upload_pair(&api, (2560, 2160), 1).await;
    let small = upload_pair(&api, (96, 80), 1).await;
    let r = submit(&api, &big, &dense_analysis()).await;
    assert_eq!(r.status(), 202);
    let dense: Value = r.json().await.unwrap();
    let dense_id = dense["id"].as_str().unwrap().to_string();
    daemon::wait_until(&server.url(&format!("/jobs/{dense_id}")), |r| {
        r["status"] == "running"
    })
    .await;
    // 3,000 analyses queued behind it, eight submissions in flight at a time.
    let light = json!({"schemes": ["ff100"], "dic": {"subset_px": 21, "step_px": 20}});
    let mut pending = tokio::task::JoinSet::new();
    for _ in 0..3_000 {
        if pending.len() == 8 {
            let status: u16 = pending.join_next().await.unwrap().unwrap();
            assert_eq!(status, 202);
        }
        let (api, small, light) = (api.clone(), small.clone(), light.clone());
        pending.spawn(async move { submit(&api, &small, &light).await.status().as_u16() });
    }
    while let Some(status) = pending.join_next().await {
        assert_eq!(status.unwrap(), 202);
    }
    let (exit, took) = server.terminate_within(Duration::from_secs(10));
    println!("exit {took:?} after SIGTERM");
    assert!(exit.success(), "{exit:?}");
    // Every run's own record: none started after the signal, none succeeded, all cancelled.
    let mut statuses: std::collections::BTreeMap<String, usize> = Default::default();
    let mut started = Vec::new();
    for entry in std::fs::read_dir(data.join("runs")).unwrap().flatten() {
        let Ok(text) = std::fs::read(entry.path().join("run.json")) else {
            continue;
        };
        let r: Value = serde_json::from_slice(&text).unwrap();
        *statuses
            .entry(r["status"].as_str().unwrap().to_string())
            .or_default() += 1;
        if r["started_at"].is_string() {
            started.push(r["id"].as_str().unwrap().to_string());
        }
    }
    assert_eq!(statuses.get("cancelled"), Some(&3_001), "{statuses:?}");
    assert_eq!(statuses.len(), 1, "{statuses:?}");
    assert_eq!(
        started,
        vec![dense_id],
        "only the dense analysis ever started"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn eight_concurrent_uploads_store_no_more_than_the_quota() {
    let _heavy = HEAVY.lock().await;
    let tmp = tempfile::tempdir().unwrap();
    let mut config = small_config(tmp.path());
    let (reference, deformed) = (texture_tiff(320, 300, 0), texture_tiff(320, 300, 13));
    let one_upload = (reference.len() + deformed.len()) as u64;
    // Room for three uploads and a half.
    config.datasets_quota_bytes = one_upload * 7 / 2;
    let quota = config.datasets_quota_bytes;
    let server = TestServer::start(config).await;
    let uploads: Vec<_> = (0..8)
        .map(|_| {
            let f = pair_form(&reference, &deformed, 1, 1.0);
            client().post(server.url("/datasets")).multipart(f).send()
        })
        .collect();
    let statuses: Vec<u16> = futures_join(uploads)
        .await
        .into_iter()
        .map(|r| r.unwrap().status().as_u16())
        .collect();
    let stored = server.service.store.datasets_bytes().unwrap();
    println!("statuses {statuses:?}; stored {stored} of {quota} bytes");
    // Issue 36: each checked the usage it saw when it began, and 2.5x the quota was stored.
    assert!(stored <= quota, "stored {stored} > quota {quota}");
    assert!(
        statuses.iter().all(|s| [201, 507].contains(s)),
        "{statuses:?}"
    );
    // At most three fit; which ones depends on how the eight interleave.
    let stored_uploads = statuses.iter().filter(|&&s| s == 201).count();
    assert!((1..=3).contains(&stored_uploads), "{statuses:?}");
    let staged = std::fs::read_dir(tmp.path().join("datasets"))
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .count();
    assert_eq!(staged, 0, "no staging folder left");
    server.stop().await;
}
