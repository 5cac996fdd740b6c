// A page on another origin must not be able to drive the bench (issue 12, item 2), checked in
// headless Chromium (Debian's /usr/bin/chromium) driven over the DevTools protocol by
// playwright-core.
//
//   node tests/browser/cross_origin.mjs <attacker-page-url> <daemon-base>
//
// The attacker page (served by tests/browser_cross_origin.rs on another loopback origin) defines
// `window.attacks`: each one sends the daemon a request a hostile page can send without the user
// doing anything — no-cors fetches, forms, beacons, a CORS fetch that needs a preflight. This
// script opens the page, runs the attacks one at a time and, between two attacks, asks the daemon
// itself (from Node, not from the page) where the stage is and which experiments exist, so every
// move or experiment is pinned on the attack that caused it. An attack succeeded when:
//   - the stage moved, or an experiment appeared;
//   - the daemon answered a mutating request from the page with 2xx;
//   - the page could read a response (a preflight or a cross-origin read was granted).
// Prints one line per attack and, last, `RESULT {json}` for the Rust side.
// Exit 0: every attack held; 1: at least one succeeded; 2: the test could not run.
//
// Chromium is started with exactly the flags tests/browser/dashboard.mjs uses (and a fresh user
// data dir):
//   --headless --no-sandbox --disable-gpu --no-first-run --disable-background-networking
//   --disable-component-update --disable-sync
// plus --remote-debugging-port=0 for the driver; playwright-core connects over CDP.

import { chromium } from "playwright-core";
import { spawn } from "node:child_process";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";

const [attackerUrl, daemon] = process.argv.slice(2);
if (!attackerUrl || !daemon) {
  console.error("usage: node cross_origin.mjs <attacker-page-url> <daemon-base>");
  process.exit(2);
}
const CHROMIUM = process.env.CHROMIUM || "/usr/bin/chromium";
const CHROMIUM_FLAGS = [
  "--headless",
  "--no-sandbox",
  "--disable-gpu",
  "--no-first-run",
  "--disable-background-networking",
  "--disable-component-update",
  "--disable-sync",
];
const SECOND = 1000;
const daemonOrigin = new URL(daemon).origin;
if (new URL(attackerUrl).origin === daemonOrigin) {
  console.error(`the attacker page ${attackerUrl} must be on another origin than ${daemonOrigin}`);
  process.exit(2);
}

const t0 = Date.now();
const log = (msg) => console.log(`[${((Date.now() - t0) / 1000).toFixed(1).padStart(5)} s] ${msg}`);
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

/** Starts Chromium with the flags above and a fresh profile; resolves with its CDP URL. */
function startChromium(userDataDir) {
  return new Promise((resolve, reject) => {
    const args = [...CHROMIUM_FLAGS, `--user-data-dir=${userDataDir}`, "--remote-debugging-port=0", "about:blank"];
    const child = spawn(CHROMIUM, args, { stdio: ["ignore", "ignore", "pipe"] });
    let err = "";
    const timer = setTimeout(() => reject(new Error(`chromium did not start within 30 s:\n${err}`)), 30 * SECOND);
    child.on("error", (e) => { clearTimeout(timer); reject(new Error(`cannot run ${CHROMIUM}: ${e.message}`)); });
    child.on("exit", (code) => { clearTimeout(timer); reject(new Error(`chromium exited (${code}):\n${err}`)); });
    child.stderr.on("data", (d) => {
      err += d.toString();
      const m = /DevTools listening on (ws:\/\/\S+)/.exec(err);
      if (m) {
        clearTimeout(timer);
        resolve({ child, ws: m[1] });
      }
    });
  });
}

/** The daemon's own view, asked from Node (same machine, no browser, no Origin). */
async function daemonGet(p) {
  const r = await fetch(`${daemon}/api/v1${p}`);
  if (!r.ok) throw new Error(`GET ${p}: HTTP ${r.status} ${await r.text()}`);
  return r.json();
}
async function bench() {
  const stage = await daemonGet("/stage");
  const experiments = await daemonGet("/experiments");
  return { position: stage.position, experiments: experiments.map((e) => e.id) };
}
const distance = (a, b) => Math.hypot(b.x_mm - a.x_mm, b.y_mm - a.y_mm);

async function main() {
  const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), "ffdic-chromium-"));
  const { child, ws } = await startChromium(userDataDir);
  let browser;
  try {
    browser = await chromium.connectOverCDP(ws, { timeout: 30 * SECOND });
    const context = browser.contexts()[0] || (await browser.newContext());
    const page = await context.newPage();
    page.setDefaultTimeout(10 * SECOND);
    page.on("pageerror", (e) => log(`page error: ${e.message}`));

    // Every request the page sends the daemon, with what the daemon answered (the DevTools
    // protocol sees the real status even where the page only gets an opaque response).
    const requests = [];
    const entries = new Map(); // playwright Request → its entry in `requests`
    const inFlight = new Set();
    let lastEvent = Date.now();
    const toDaemon = (r) => {
      try {
        return new URL(r.url()).origin === daemonOrigin;
      } catch {
        return false;
      }
    };
    page.on("request", (r) => {
      if (!toDaemon(r)) return;
      const entry = { method: r.method(), path: new URL(r.url()).pathname, type: r.resourceType(), status: null, failure: null, contentType: null };
      r.allHeaders().then((h) => { entry.contentType = h["content-type"] ?? null; }).catch(() => {});
      requests.push(entry);
      entries.set(r, entry);
      inFlight.add(r);
      lastEvent = Date.now();
    });
    // The status as the headers arrive: Chromium's opaque-response blocking may still fail the
    // load of a no-cors answer afterwards (net::ERR_ABORTED), though the daemon did answer.
    page.on("response", (resp) => {
      const entry = entries.get(resp.request());
      if (entry) entry.status = resp.status();
    });
    const finished = (r) => {
      const entry = entries.get(r);
      if (!entry) return;
      entry.failure = r.failure()?.errorText ?? null;
      inFlight.delete(r);
      lastEvent = Date.now();
    };
    page.on("requestfinished", finished);
    page.on("requestfailed", finished);

    /** Until the page's requests to the daemon have ended and nothing new came for a while. */
    async function settle() {
      const deadline = Date.now() + 5 * SECOND;
      while (Date.now() < deadline) {
        if (inFlight.size === 0 && Date.now() - lastEvent > 300) return;
        await sleep(50);
      }
    }

    await page.goto(attackerUrl);
    await page.waitForFunction(() => Array.isArray(window.attacks));
    const attacks = await page.evaluate(() => window.attacks.map((a) => a.name));
    log(`attacker page ${attackerUrl} (origin ${new URL(attackerUrl).origin}) against ${daemonOrigin}: ${attacks.length} attacks`);

    const start = await bench();
    log(`stage at (${start.position.x_mm}, ${start.position.y_mm}) mm, ${start.experiments.length} experiments`);
    const results = [];
    let before = start;
    for (let i = 0; i < attacks.length; i++) {
      const name = attacks[i];
      const seenFrom = requests.length;
      const outcome = await page.evaluate((k) => window.attacks[k].run(), i).catch((e) => ({ note: `threw: ${e.message}`, readable: false }));
      await settle();
      // A beacon leaves without the page waiting; if the driver did not see it, give the daemon
      // time to have moved the stage (8 mm at the mock's 25 mm/s is 0.3 s) before looking.
      if (requests.length === seenFrom) await sleep(1 * SECOND);
      const after = await bench();
      const sent = requests.slice(seenFrom);
      const moved = distance(before.position, after.position);
      const created = after.experiments.filter((e) => !before.experiments.includes(e));
      const accepted = sent.filter((r) => r.method !== "GET" && r.status !== null && r.status >= 200 && r.status < 300);
      const why = [];
      if (moved > 1e-6) why.push(`the stage moved ${moved.toFixed(3)} mm to (${after.position.x_mm}, ${after.position.y_mm})`);
      if (created.length) why.push(`experiment ${created.join(", ")} created`);
      if (accepted.length) why.push(`the daemon answered ${accepted.map((r) => `${r.method} ${r.path} ${r.status}`).join(", ")}`);
      if (outcome.readable) why.push(`the page read the response (${outcome.note})`);
      const wire = sent.map((r) => {
        const answer = [r.status === null ? "no answer" : `HTTP ${r.status}`, r.failure].filter(Boolean).join(", ");
        return `${r.method} ${r.path} [${r.type}, Content-Type ${r.contentType ?? "none"}] → ${answer}`;
      });
      results.push({ attack: name, succeeded: why.length > 0, why, page: outcome.note, requests: wire, moved_mm: moved, experiments_created: created });
      log(`${why.length ? "SUCCEEDED" : "held     "} ${name}: ${why.length ? why.join("; ") : "no effect"}`);
      log(`          page saw: ${outcome.note}; on the wire: ${wire.length ? wire.join("; ") : "no request observed"}`);
      before = after;
    }

    const end = await bench();
    const summary = {
      attacks: results.length,
      succeeded: results.filter((r) => r.succeeded).map((r) => r.attack),
      stage_start: start.position,
      stage_end: end.position,
      experiments_created: end.experiments.filter((e) => !start.experiments.includes(e)),
      results,
    };
    console.log(`RESULT ${JSON.stringify(summary)}`);
    return summary.succeeded.length === 0 ? 0 : 1;
  } finally {
    if (browser) await browser.close().catch(() => {});
    // Let Chromium go before removing its profile (it writes until it has exited).
    const exited = child.exitCode !== null ? Promise.resolve() : new Promise((r) => child.once("exit", r));
    child.kill("SIGKILL");
    await Promise.race([exited, new Promise((r) => setTimeout(r, 5 * SECOND))]);
    try {
      fs.rmSync(userDataDir, { recursive: true, force: true, maxRetries: 5, retryDelay: 200 });
    } catch (e) {
      console.warn(`left the profile ${userDataDir}: ${e.message}`);
    }
  }
}

const hardLimit = setTimeout(() => {
  console.error("cross-origin test: no result within 90 s");
  process.exit(2);
}, 90 * SECOND);

main().then(
  (code) => { clearTimeout(hardLimit); process.exit(code); },
  (e) => { clearTimeout(hardLimit); console.error(`cross-origin test could not run: ${e.stack || e.message}`); process.exit(2); },
);
