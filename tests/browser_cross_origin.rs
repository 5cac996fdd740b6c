//! A web page on another origin must not drive the bench (issue 12, item 2: a page on another
//! loopback origin moved the stage 8 mm). The daemon runs in-process on 127.0.0.1 port 0 with the
//! small mock bench; a second, tiny HTTP server on 127.0.0.2 plays the hostile site. Its page
//! (`ATTACK_PAGE`) holds the requests a page can send without a click: "simple" ones that need no
//! preflight (no-cors fetches with no Content-Type and with text/plain, auto-submitted text/plain
//! forms whose body reads as JSON, to the stage and to the experiments, and beacons), a CORS fetch
//! with application/json (needs a preflight, which must not be granted) and a cross-origin read. `tests/browser/cross_origin.mjs` opens the page in headless Debian `chromium`
//! (playwright-core, pinned in tests/browser/package-lock.json, the same flags as the dashboard
//! test) and runs them one at a time, pinning any effect on the attack that caused it.
//!
//! Then, through the API: the stage stands where it stood and no experiment exists. And, with no
//! browser: a DNS-rebinding request (`Host: evil.example:PORT`, what a page on a name rebound to
//! 127.0.0.1 sends) is refused with 421 or 403 as problem+json, reading or moving. Last, the
//! protection must not lock out the daemon's own clients: `Host: localhost` reads, and a
//! same-origin JSON move (what the dashboard sends) moves the stage — which also shows the mock
//! stage does move, so "it did not move" above means something.
//!
//! Needs `node`, `/usr/bin/chromium` and `npm ci --prefix tests/browser` (scripts/test-all.sh
//! installs all three). Missing any of them is a failure, not a skip: CI has them.

use crate::common::daemon;

use daemon::{client, small_config, TestServer};
use reqwest::header::{CONTENT_TYPE, HOST, ORIGIN};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;

const CHROMIUM: &str = "/usr/bin/chromium";

/// The hostile site's address. Another loopback address, not just another port of 127.0.0.1:
/// ports do not make sites, so only another host makes the browser send `Sec-Fetch-Site:
/// cross-site` — what the issue's attacker page was. Linux routes all of 127.0.0.0/8 to `lo`.
const ATTACKER_IP: &str = "127.0.0.2";

/// Where the test parks the stage before the attacks, (x, y) mm: off the homed origin, so that
/// an experiment a page managed to start (it homes the stage first) cannot put the stage back
/// where it stood and hide. The page's moves go 8 mm along x from here.
const START_MM: (f64, f64) = (-4.0, -5.0);

/// The hostile page. `__DAEMON__` becomes the daemon's base URL, `__START_X__` and `__START_Y__`
/// the coordinates of `START_MM`. Each attack returns what the
/// page itself could observe (`readable`: it could read the daemon's answer). Stage attacks come
/// first: an experiment, once created, would hold the bench and turn later moves into 409s.
const ATTACK_PAGE: &str = r#"<!doctype html>
<html lang="en">
<meta charset="utf-8">
<title>Nothing to see here</title>
<body>
<script>
"use strict";
const DAEMON = "__DAEMON__";
const MOVES = `${DAEMON}/api/v1/stage/moves`;
const EXPERIMENTS = `${DAEMON}/api/v1/experiments`;
const START = { x_mm: __START_X__, y_mm: __START_Y__ };

// A real StageMoveRequest (src/api/routes/stage.rs): absolute, 8 mm along x from where the stage
// stands. Attack k also asks for y + k mm, so every move that succeeds changes the position,
// even after an earlier one did.
const moveTo = (k) => JSON.stringify({ x_mm: START.x_mm + 8.0, y_mm: START.y_mm + k });
// A real ExperimentRequest, small enough to run on the mock bench in a second or two.
const EXPERIMENT = {
  name: "cross-origin",
  patterns: ["a"],
  moves: [{ id: "x1", dx_mm: 0.5, dy_mm: 0.0 }],
  settle_ms: 0,
  dic: { subset_px: 21, step_px: 10, strain_window: 5 },
};
// A Blob with no type: fetch and sendBeacon then send no Content-Type header at all (a string
// body would get text/plain). This is the hole of issue 12: no Content-Type was taken as JSON.
const untyped = (text) => new Blob([text]);

async function noCors(url, init) {
  try {
    const r = await fetch(url, { method: "POST", mode: "no-cors", ...init });
    return { note: `no-cors fetch resolved (${r.type} response)`, readable: r.type !== "opaque" };
  } catch (e) {
    return { note: `no-cors fetch rejected: ${e}`, readable: false };
  }
}

async function corsFetch(url, init) {
  try {
    const r = await fetch(url, { mode: "cors", ...init });
    return { note: `CORS fetch resolved: HTTP ${r.status} ${(await r.text()).slice(0, 200)}`, readable: true };
  } catch (e) {
    return { note: `CORS fetch rejected: ${e}`, readable: false };
  }
}

// An auto-submitted form: a "simple" request, never preflighted. enctype=text/plain writes the
// body as `name=value\r\n` unescaped, so a field name and value can spell JSON around the `=`.
function submitForm(url, name, value) {
  return new Promise((resolve) => {
    const sink = document.createElement("iframe");
    sink.name = `sink-${Math.random().toString(36).slice(2)}`;
    document.body.append(sink);
    const form = document.createElement("form");
    form.method = "post";
    form.enctype = "text/plain";
    form.action = url;
    form.target = sink.name;
    const field = document.createElement("input");
    field.type = "hidden";
    field.name = name;
    field.value = value;
    form.append(field);
    document.body.append(form);
    // After the iframe's own about:blank load: the next load is the daemon's answer.
    setTimeout(() => {
      const timer = setTimeout(() => resolve({ note: "form posted; no answer loaded within 5 s", readable: false }), 5000);
      sink.addEventListener("load", () => {
        clearTimeout(timer);
        resolve({ note: "form posted; the answer loaded in a hidden iframe", readable: false });
      }, { once: true });
      form.submit();
    }, 0);
  });
}

function beacon(url, body) {
  return { note: `sendBeacon queued: ${navigator.sendBeacon(url, body)}`, readable: false };
}

window.attacks = [
  { name: "no-cors fetch, no Content-Type -> stage/moves",
    run: () => noCors(MOVES, { body: untyped(moveTo(0)) }) },
  { name: "no-cors fetch, text/plain -> stage/moves",
    run: () => noCors(MOVES, { headers: { "Content-Type": "text/plain" }, body: moveTo(1) }) },
  // A move request has no string field to hide the `=` in: the closest a form gets is
  // `{...}=`, which only a lenient parser would take. Sent anyway, for that parser.
  { name: "form text/plain -> stage/moves",
    run: () => submitForm(MOVES, moveTo(2), "") },
  { name: "sendBeacon, no Content-Type -> stage/moves",
    run: () => beacon(MOVES, untyped(moveTo(3))) },
  { name: "sendBeacon, text/plain -> stage/moves",
    run: () => beacon(MOVES, moveTo(4)) },
  { name: "CORS fetch, application/json (preflighted) -> stage/moves",
    run: () => corsFetch(MOVES, { method: "POST", headers: { "Content-Type": "application/json" }, body: moveTo(5) }) },
  { name: "CORS read of GET /api/v1/stage",
    run: () => corsFetch(`${DAEMON}/api/v1/stage`, {}) },
  // `{"name":"cross-origin` + `=` + `","patterns":…}` is a valid ExperimentRequest whose name
  // ends in "=".
  { name: "form text/plain -> experiments",
    run: () => {
      const { name, ...rest } = EXPERIMENT;
      return submitForm(EXPERIMENTS, `{"name":"${name}`, `",${JSON.stringify(rest).slice(1)}`);
    } },
  { name: "no-cors fetch, no Content-Type -> experiments",
    run: () => noCors(EXPERIMENTS, { body: untyped(JSON.stringify(EXPERIMENT)) }) },
];
</script>
</body>
</html>
"#;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Fails with what to install when the browser tooling is missing.
fn require_tools() {
    let node = Command::new("node").arg("--version").output();
    assert!(
        node.as_ref().is_ok_and(|o| o.status.success()),
        "the cross-origin browser test needs Node.js (`node` on PATH; Debian: apt-get install nodejs npm): {:?}",
        node.err()
    );
    assert!(
        Path::new(CHROMIUM).exists(),
        "the cross-origin browser test needs {CHROMIUM} (Debian: apt-get install chromium)"
    );
    let driver = repo().join("tests/browser/node_modules/playwright-core/package.json");
    assert!(
        driver.exists(),
        "the cross-origin browser test needs playwright-core: run `npm ci --prefix tests/browser` \
         (scripts/test-all.sh does) — {} is missing",
        driver.display()
    );
}

/// The hostile site: `ATTACK_PAGE` at `/` (404 for anything else) on `ATTACKER_IP`, port 0.
/// Returns the page's URL and the accept loop (abort it when done).
async fn serve_attacker(daemon_base: &str) -> (String, tokio::task::JoinHandle<()>) {
    let listener = TcpListener::bind((ATTACKER_IP, 0))
        .await
        .unwrap_or_else(|e| panic!("cannot listen on {ATTACKER_IP}, the attacker's origin: {e}"));
    let url = format!("http://{}/", listener.local_addr().unwrap());
    let page = ATTACK_PAGE
        .replace("__DAEMON__", daemon_base)
        .replace("__START_X__", &format!("{:.1}", START_MM.0))
        .replace("__START_Y__", &format!("{:.1}", START_MM.1));
    let task = tokio::spawn(async move {
        while let Ok((mut stream, _)) = listener.accept().await {
            let page = page.clone();
            tokio::spawn(async move {
                // The request head is all we need (the browser sends no body on GET).
                let mut head = Vec::new();
                let mut buf = [0u8; 4096];
                while !head.windows(4).any(|w| w == b"\r\n\r\n") && head.len() < 65536 {
                    match tokio::time::timeout(Duration::from_secs(5), stream.read(&mut buf)).await
                    {
                        Ok(Ok(n)) if n > 0 => head.extend_from_slice(&buf[..n]),
                        _ => return,
                    }
                }
                let (status, body) = if head.starts_with(b"GET / ") {
                    ("200 OK", page.as_str())
                } else {
                    ("404 Not Found", "")
                };
                let response = format!(
                    "HTTP/1.1 {status}\r\nContent-Type: text/html; charset=utf-8\r\n\
                     Content-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n{body}",
                    body.len()
                );
                let _ = stream.write_all(response.as_bytes()).await;
                let _ = stream.shutdown().await;
            });
        }
    });
    (url, task)
}

/// Where the stage is, (x, y) in mm, as `GET /api/v1/stage` says.
async fn stage_position(server: &TestServer) -> (f64, f64) {
    let stage: Value = client()
        .get(server.url("/stage"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let p = &stage["position"];
    match (p["x_mm"].as_f64(), p["y_mm"].as_f64()) {
        (Some(x), Some(y)) => (x, y),
        _ => panic!("the stage reports no position: {stage}"),
    }
}

fn moved_mm(a: (f64, f64), b: (f64, f64)) -> f64 {
    (b.0 - a.0).hypot(b.1 - a.1)
}

/// Every experiment the daemon knows (queued, running or ended).
async fn experiments(server: &TestServer) -> Vec<Value> {
    client()
        .get(server.url("/experiments"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap()
}

/// A request as a page on a DNS-rebound name sends it: to the daemon's address, but with that
/// name in `Host` (and, mutating, as the same-origin `Origin` the browser believes it is).
/// Returns status, content type and body.
async fn rebound(
    server: &TestServer,
    method: reqwest::Method,
    path: &str,
    body: Option<Value>,
) -> (u16, String, String) {
    let port = server.base.rsplit(':').next().unwrap();
    let evil = format!("evil.example:{port}");
    // reqwest (hyper-util) keeps a Host header that is set explicitly.
    let mut req = client()
        .request(method, server.url(path))
        .header(HOST, &evil);
    if let Some(body) = body {
        req = req
            .header(ORIGIN, format!("http://{evil}"))
            .header("Sec-Fetch-Site", "same-origin")
            .json(&body);
    }
    let r = req.send().await.unwrap();
    let status = r.status().as_u16();
    let content_type = r
        .headers()
        .get(CONTENT_TYPE)
        .map(|v| v.to_str().unwrap_or("").to_string())
        .unwrap_or_default();
    (status, content_type, r.text().await.unwrap())
}

/// Homes the stage and parks it at `START_MM` as a local client (no Origin, JSON) would: the mock
/// stage refuses to move before it is homed, and the attacks must find a bench that would obey
/// them. Returns where the stage stands.
async fn park_the_stage(server: &TestServer) -> (f64, f64) {
    let park = client()
        .post(server.url("/stage/moves"))
        .json(&json!({"home": true, "x_mm": START_MM.0, "y_mm": START_MM.1}))
        .send()
        .await
        .unwrap();
    assert_eq!(
        park.status(),
        200,
        "parking the stage: {}",
        park.text().await.unwrap()
    );
    let start = stage_position(server).await;
    assert!(
        moved_mm(start, START_MM) < 1e-6,
        "the stage is at {start:?}"
    );
    start
}

/// Serves the hostile page and has `tests/browser/cross_origin.mjs` run its attacks in the
/// browser. Returns the script's outcome and one line per attack that got through, with what it
/// did, for the failure messages.
async fn run_the_attacks_in_the_browser(server: &TestServer) -> (std::process::Output, String) {
    let (attacker_url, attacker) = serve_attacker(&server.base).await;
    let script = repo().join("tests/browser/cross_origin.mjs");
    let base = server.base.clone();
    let t = Instant::now();
    let browser = tokio::task::spawn_blocking(move || {
        Command::new("node")
            .arg(&script)
            .arg(&attacker_url)
            .arg(&base)
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    attacker.abort();
    let out = String::from_utf8_lossy(&browser.stdout);
    print!("{out}");
    eprint!("{}", String::from_utf8_lossy(&browser.stderr));
    println!(
        "browser script: {:.1} s, {}",
        t.elapsed().as_secs_f64(),
        browser.status
    );
    // 0: every attack held, 1: some succeeded; anything else: the attacks did not all run, and
    // an unmoved stage would prove nothing.
    assert!(
        matches!(browser.status.code(), Some(0 | 1)),
        "the browser script could not run ({}): see its output above",
        browser.status
    );
    let report: Value = out
        .lines()
        .find_map(|l| l.strip_prefix("RESULT "))
        .map(|l| serde_json::from_str(l).unwrap())
        .expect("the browser script prints a RESULT line");
    let succeeded: String = report["results"]
        .as_array()
        .expect("the RESULT line lists the attacks")
        .iter()
        .filter(|r| r["succeeded"] == true)
        .map(|r| {
            let why: Vec<&str> = r["why"]
                .as_array()
                .unwrap()
                .iter()
                .filter_map(Value::as_str)
                .collect();
            format!(
                "\n  - {}: {}",
                r["attack"].as_str().unwrap(),
                why.join("; ")
            )
        })
        .collect();
    (browser, succeeded)
}

/// The protection must not lock out the daemon's own clients: `Host: localhost` reads, and a
/// same-origin JSON move (what the dashboard sends) moves the stage.
async fn check_the_daemons_own_clients_get_in(server: &TestServer) {
    let port = server.base.rsplit(':').next().unwrap();
    let local = client()
        .get(server.url("/stage"))
        .header(HOST, format!("localhost:{port}"))
        .send()
        .await
        .unwrap();
    assert_eq!(local.status(), 200, "Host: localhost must be served");
    // What the dashboard sends: same origin, JSON.
    let own = client()
        .post(server.url("/stage/moves"))
        .header(ORIGIN, &server.base)
        .header("Sec-Fetch-Site", "same-origin")
        .json(&json!({"x_mm": -3.0, "y_mm": 2.0}))
        .send()
        .await
        .unwrap();
    assert_eq!(
        own.status(),
        200,
        "a same-origin JSON move: {}",
        own.text().await.unwrap()
    );
    let end = stage_position(server).await;
    assert!(moved_mm(end, (-3.0, 2.0)) < 1e-6, "the stage is at {end:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_on_another_origin_cannot_drive_the_bench() {
    require_tools();
    let work = tempfile::tempdir().unwrap();
    let server = TestServer::start(small_config(&work.path().join("data"))).await;
    let start = park_the_stage(&server).await;

    // ---- the hostile page in the browser ----
    let (browser, succeeded) = run_the_attacks_in_the_browser(&server).await;
    let after_browser = stage_position(&server).await;
    let runs = experiments(&server).await;

    // ---- DNS rebinding: the daemon's address under someone else's name ----
    let rebound_read = rebound(&server, reqwest::Method::GET, "/stage", None).await;
    let rebound_move = rebound(
        &server,
        reqwest::Method::POST,
        "/stage/moves",
        Some(json!({"x_mm": -8.0, "y_mm": -8.0})),
    )
    .await;
    let after_rebinding = stage_position(&server).await;
    println!(
        "Host evil.example: GET /stage → {} {:?}; POST /stage/moves → {} {:?}",
        rebound_read.0, rebound_read.1, rebound_move.0, rebound_move.1
    );

    // ---- what must hold ----
    let moved = moved_mm(start, after_browser);
    assert!(
        moved < 1e-6,
        "a page on {ATTACKER_IP} moved the stage {moved:.3} mm, from {start:?} to {after_browser:?}; \
         the attacks that succeeded:{succeeded}"
    );
    assert!(
        runs.is_empty(),
        "a page on {ATTACKER_IP} created {} experiment(s) ({}); the attacks that succeeded:{succeeded}",
        runs.len(),
        runs.iter().map(|r| r["id"].to_string()).collect::<Vec<_>>().join(", ")
    );
    assert!(
        browser.status.success(),
        "attacks that succeeded in the browser (the script's output is above):{succeeded}"
    );
    let moved = moved_mm(after_browser, after_rebinding);
    assert!(
        moved < 1e-6,
        "a request for Host evil.example moved the stage {moved:.3} mm (answer: {rebound_move:?})"
    );
    for (what, (status, content_type, body)) in [("read", &rebound_read), ("move", &rebound_move)] {
        assert!(
            matches!(status, 421 | 403),
            "a {what} for Host evil.example (DNS rebinding) got {status}, want 421 or 403: {body}"
        );
        assert!(
            content_type.starts_with("application/problem+json"),
            "the refused {what} is {content_type:?}, not problem+json: {body}"
        );
        let problem: Value = serde_json::from_str(body).unwrap();
        assert_eq!(problem["status"], *status, "{body}");
    }

    // ---- and the daemon's own clients still get in ----
    check_the_daemons_own_clients_get_in(&server).await;
    server.stop().await;
}
