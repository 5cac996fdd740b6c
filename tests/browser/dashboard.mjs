// End-to-end test of the ffdic dashboard in headless Chromium (Debian's /usr/bin/chromium),
// driven over the DevTools protocol by playwright-core.
//
//   node tests/browser/dashboard.mjs <base-url> <dataset-dir> <artefact-dir> [expected-verdict]
//
// Against a running daemon at <base-url> (loopback, no token): starts an experiment from the form,
// sees its progress reach 100 % and both bar charts with patterns × schemes bars; uploads the
// dataset in <dataset-dir> (dataset.json + TIFFs, with a hidden effect) through the upload form,
// compares it with the baseline, diagnoses it and sees the verdict (default lens_distortion),
// adds the winner as a new model version and sees the history chart gain a lower point.
// Screenshots of every page go to <artefact-dir>. Exit 0 when everything held.
//
// Chromium is started by this script with exactly these flags (and a fresh user data dir):
//   --headless --no-sandbox --disable-gpu --no-first-run --disable-background-networking
//   --disable-component-update --disable-sync
// plus --remote-debugging-port=0 for the driver; playwright-core connects over CDP.

import { chromium } from "playwright-core";
import { spawn } from "node:child_process";
import fs from "node:fs";
import os from "node:os";
import path from "node:path";

const [base, datasetDir, artefacts, expectedVerdict = "lens_distortion"] = process.argv.slice(2);
if (!base || !datasetDir || !artefacts) {
  console.error("usage: node dashboard.mjs <base-url> <dataset-dir> <artefact-dir> [expected-verdict]");
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
// The experiment the form starts: patterns × schemes bars in each figure.
const PATTERNS = ["a", "b"];
const SCHEMES = ["ff100", "ff50", "ff25"];
const SECOND = 1000;

fs.mkdirSync(artefacts, { recursive: true });
const t0 = Date.now();
const log = (msg) => console.log(`[${((Date.now() - t0) / 1000).toFixed(1).padStart(6)} s] ${msg}`);

function fail(msg) {
  throw new Error(msg);
}

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

async function shot(page, name) {
  const file = path.join(artefacts, `${name}.png`);
  await page.screenshot({ path: file, fullPage: true });
  log(`screenshot ${file}`);
}

async function main() {
  const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), "ffdic-chromium-"));
  const { child, ws } = await startChromium(userDataDir);
  let browser;
  const problems = [];
  try {
    browser = await chromium.connectOverCDP(ws, { timeout: 30 * SECOND });
    const context = browser.contexts()[0] || (await browser.newContext());
    const page = await context.newPage();
    await page.setViewportSize({ width: 1400, height: 1000 });
    page.setDefaultTimeout(30 * SECOND);
    page.on("pageerror", (e) => problems.push(`page error: ${e.message}`));
    page.on("console", (m) => {
      if (m.type() === "error") problems.push(`console error: ${m.text()}`);
    });
    page.on("response", (r) => {
      if (r.status() >= 400 && new URL(r.url()).pathname.startsWith("/assets/")) {
        problems.push(`${r.status()} for ${r.url()}`);
      }
    });

    // ---- home: the bench, the experiment form ----
    await page.goto(`${base}/`);
    await page.waitForSelector("#snapshot[data-loaded=true]", { timeout: 60 * SECOND });
    const bins = await page.locator("#histogram rect.hist-bin").count();
    if (bins < 5) fail(`the snapshot histogram has ${bins} bins`);
    await page.waitForSelector("#camera-state dd");
    const cameraText = await page.locator("#camera-state").innerText();
    if (!/exposure/.test(cameraText) || !/µs/.test(cameraText)) fail(`camera state: ${cameraText}`);
    log(`home: snapshot with a ${bins}-bin histogram; camera ${cameraText.split("\n")[1] || ""}`);
    await shot(page, "1-home");

    const form = page.locator("#experiment-form");
    await form.locator("input[name=run_name]").fill("browser");
    for (const p of ["a", "b", "c"]) {
      await form.locator(`input[name=pattern][value=${p}]`).setChecked(PATTERNS.includes(p));
    }
    for (const s of ["ff100", "ff50", "ff25"]) {
      await form.locator(`input[name=scheme][value=${s}]`).setChecked(SCHEMES.includes(s));
    }
    await form.locator("textarea[name=moves]").fill("x1 1.0 0.0");
    await form.locator("input[name=settle_ms]").fill("0");
    await form.locator("input[name=subset_px]").fill("21");
    await form.locator("input[name=step_px]").fill("10");
    await form.locator("input[name=strain_window]").fill("5");
    await Promise.all([
      page.waitForURL(/\/experiments\/[^/]+$/, { timeout: 30 * SECOND }),
      page.locator("#start-experiment").click(),
    ]);
    const experimentUrl = page.url();
    log(`experiment started: ${experimentUrl}`);

    // ---- experiment: progress to 100 %, Figures 5 and 6 ----
    await page.waitForSelector("#progress-text", { timeout: 30 * SECOND });
    const seen = new Set();
    const deadline = Date.now() + 180 * SECOND;
    for (;;) {
      const text = (await page.locator("#progress-text").innerText()).trim();
      seen.add(text);
      if (text === "100 %") break;
      const status = await page.locator("#run-status .badge").getAttribute("data-status").catch(() => null);
      if (status === "failed" || status === "cancelled") {
        fail(`experiment ${status}: ${await page.locator("#run-message").innerText()} ${await page.locator("#run-error").innerText()}`);
      }
      if (Date.now() > deadline) fail(`progress stuck at ${text}`);
      await page.waitForTimeout(100);
    }
    log(`progress reached 100 % (seen: ${[...seen].join(", ")})`);
    await page.waitForSelector("#run-status .badge[data-status=succeeded]", { timeout: 30 * SECOND });
    const valueNow = await page.locator("#progress").getAttribute("aria-valuenow");
    if (valueNow !== "100") fail(`progress bar aria-valuenow ${valueNow}`);
    await page.waitForSelector("#results[data-loaded=true]", { timeout: 60 * SECOND });
    const want = PATTERNS.length * SCHEMES.length;
    for (const fig of ["figure5_u", "figure5_exx", "figure6_v", "figure6_eyy"]) {
      const bars = await page.locator(`#${fig} svg rect.bar`).count();
      const labels = await page.locator(`#${fig} svg text.bar-label`).evaluateAll((ts) => ts.map((t) => t.textContent));
      if (bars !== want) fail(`${fig}: ${bars} bars, want ${want} (patterns × schemes)`);
      // The % increase over the 100 % bar, as in the paper, on every reduced scheme's bar.
      const pctLabels = labels.filter((l) => /[+-−]?\d+(\.\d+)? %/.test(l));
      if (pctLabels.length !== PATTERNS.length * (SCHEMES.length - 1)) {
        fail(`${fig}: ${pctLabels.length} % labels (${labels.join(" | ")})`);
      }
      log(`${fig}: ${bars} bars, labels ${pctLabels.join(" ")}`);
    }
    const maps = await page.locator("#maps .figure.map svg").count();
    if (maps !== 3) fail(`${maps} of the u, v, εxx maps shown`);
    const legends = await page.locator("#maps svg rect.legend").count();
    if (legends !== 3) fail(`maps without colour scales (${legends} legends)`);
    const csv = await page.locator("#downloads a", { hasText: "study.csv" }).count();
    const tifs = await page.locator("#downloads a", { hasText: ".tif" }).count();
    if (csv !== 1 || tifs < 2) fail(`downloads: ${csv} CSV, ${tifs} TIFF links`);
    log(`maps: ${maps} with colour scales; downloads: CSV and ${tifs} TIFF frames`);
    await shot(page, "2-experiment");

    // ---- upload the hidden-effect dataset through the form ----
    await page.goto(`${base}/`);
    const files = fs.readdirSync(datasetDir).filter((f) => f === "dataset.json" || /\.tiff?$/i.test(f)).map((f) => path.join(datasetDir, f));
    await page.locator("#upload-files").setInputFiles(files);
    await Promise.all([
      page.waitForURL(/\/datasets\/[^/]+$/, { timeout: 60 * SECOND }),
      page.locator("#upload-btn").click(),
    ]);
    log(`uploaded ${files.length} files: ${page.url()}`);

    // ---- dataset: compare with the baseline, diagnose, add the winner ----
    await page.waitForSelector("#model option[value=baseline]", { state: "attached" });
    await page.locator("#model").selectOption("baseline");
    await page.locator("#model-form summary").click();
    const mf = page.locator("#model-form");
    // 2x2 binning (ff100) only, small subsets: the diagnosis takes seconds, not minutes.
    for (const s of ["ff50", "ff25", "native"]) await mf.locator(`input[name=scheme][value=${s}]`).setChecked(false);
    await mf.locator("input[name=scheme][value=ff100]").setChecked(true);
    await mf.locator("input[name=subset_px]").fill("21");
    await mf.locator("input[name=step_px]").fill("10");
    await mf.locator("input[name=strain_window]").fill("5");
    await mf.locator("input[name=prefilter_sigma_px]").fill("0.7");

    const historyPoints = async () => {
      const values = await page.locator("#history circle.history-point").evaluateAll((cs) => cs.map((c) => Number(c.dataset.discrepancy)));
      return values;
    };
    const before = (await historyPoints()).length;
    await page.locator("#compare-btn").click();
    await page.waitForFunction((n) => document.querySelectorAll("#history circle.history-point").length > n, before, { timeout: 300 * SECOND });
    await page.waitForSelector("#comparison-discrepancy", { timeout: 30 * SECOND });
    const baselinePx = Number(await page.locator("#comparison-discrepancy").getAttribute("data-discrepancy"));
    const residualPlots = await page.locator("#comparison-plots .figure svg").count();
    log(`compared with the baseline: ${baselinePx} px; ${residualPlots} residual / statistics plots`);
    if (residualPlots < 1) fail("the comparison shows no residual plot");
    await shot(page, "3-dataset-compared");

    await page.locator("#diagnose-btn").click();
    await page.waitForSelector("#diagnosis-verdict[data-verdict]", { timeout: 400 * SECOND });
    const verdict = await page.locator("#diagnosis-verdict").getAttribute("data-verdict");
    const candidates = await page.locator("#candidate-table tbody tr").count();
    log(`diagnosis: verdict ${verdict}, ${candidates} candidates`);
    if (verdict !== expectedVerdict) {
      fail(`verdict ${verdict}, want ${expectedVerdict}; ${await page.locator("#candidates").innerText()}`);
    }
    const winnerRow = await page.locator(`#candidate-table tr.winner[data-effect=${expectedVerdict}]`).innerText();
    if (!/±/.test(winnerRow)) fail(`the winner's row has no parameter ± stderr: ${winnerRow}`);
    log(`winner: ${winnerRow.replace(/\s+/g, " ")}`);
    await shot(page, "4-dataset-diagnosed");

    const pointsBefore = await historyPoints();
    const add = page.locator("#add-winner");
    await add.waitFor({ state: "visible" });
    const addText = await add.innerText();
    if (!addText.includes(expectedVerdict)) fail(`the add button says "${addText}"`);
    await add.click();
    await page.waitForFunction((n) => document.querySelectorAll("#history circle.history-point").length > n, pointsBefore.length, { timeout: 300 * SECOND });
    const pointsAfter = await historyPoints();
    const last = pointsAfter[pointsAfter.length - 1];
    const previous = pointsAfter[pointsAfter.length - 2];
    log(`history: ${pointsBefore.length} → ${pointsAfter.length} points: ${pointsAfter.map((v) => v.toPrecision(4)).join(" → ")} px`);
    if (pointsAfter.length !== pointsBefore.length + 1) fail("the history did not gain exactly one point");
    if (!(last < previous) || !(last < baselinePx)) fail(`the new point (${last} px) is not lower than before (${previous} px, baseline ${baselinePx} px)`);
    await page.waitForFunction(() => /added/.test(document.querySelector("#add-notice").textContent));
    await shot(page, "5-dataset-winner-added");

    if (problems.length) fail(`the pages reported problems:\n  ${problems.join("\n  ")}`);
    log("all checks passed");
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
  console.error("dashboard test: no result within 15 minutes");
  process.exit(1);
}, 15 * 60 * SECOND);

main().then(
  () => { clearTimeout(hardLimit); process.exit(0); },
  (e) => { clearTimeout(hardLimit); console.error(`dashboard test FAILED: ${e.stack || e.message}`); process.exit(1); },
);
