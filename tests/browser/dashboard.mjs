// End-to-end test of the ffdic dashboard in headless Chromium (Debian's /usr/bin/chromium),
// driven over the DevTools protocol by playwright-core.
//
//   node tests/browser/dashboard.mjs <base-url> <dataset-dir> <artefact-dir> [expected-verdict] [second-dataset-dir]
//
// Against a running daemon at <base-url> (loopback, no token): starts an experiment from the form,
// sees its progress reach 100 % and both bar charts with patterns × schemes bars; uploads the
// dataset in <dataset-dir> (dataset.json + TIFFs, with a hidden effect) through the upload form,
// compares it with the baseline, diagnoses it and sees the verdict (default lens_distortion),
// adds the winner as a new model version and sees the history chart gain a lower point. Then
// (issue 13) the page, reloaded, lists those jobs and reopens one; a second dataset of the same
// bench (another seed) diagnosed and added must not claim the first dataset's model as its own;
// the home page takes no snapshot until asked; a finished experiment replays its events; the
// study charts carry error bars; moves and errors carry µm beside px; a calibration started from
// the home page shows its camera card (issue 33); a one-move dataset diagnosed offers to resolve
// its confounds on the bench, and the bench's runs resolve them (issue 33).
//
// Defects are collected (each check says what it saw) and reported together at the end, so one
// run shows every one that is still there.
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

const [base, datasetDir, artefacts, expectedVerdict = "lens_distortion", secondDatasetDir] = process.argv.slice(2);
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

/**
 * Clicks the home page's `button` that starts a run of `kind` (sweeps, calibrations), follows it
 * to its page, and waits until the run has succeeded and its results are shown.
 */
async function startAndFinish(page, button, kind) {
  await Promise.all([
    page.waitForURL(new RegExp(`/${kind}/[^/]+$`), { timeout: 30 * SECOND }),
    page.locator(button).click(),
  ]);
  log(`${kind}: started ${page.url()}`);
  await page.waitForSelector("#run-status .badge[data-status=succeeded]", { timeout: 180 * SECOND });
  await page.waitForSelector("#results[data-loaded=true]", { timeout: 60 * SECOND });
}

/** Defects seen so far; the run fails at the end when there is any. */
const defects = [];
function expect(ok, msg) {
  if (ok) log(`ok: ${msg}`);
  else {
    defects.push(msg);
    log(`DEFECT: ${msg}`);
  }
  return ok;
}

/** Waits for `selector` up to `ms`; false (not an exception) when it never appears. */
async function appears(page, selector, ms = 10 * SECOND, state = "attached") {
  return page.waitForSelector(selector, { timeout: ms, state }).then(() => true, () => false);
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
      // The second dataset's add meets a 409 on purpose (the name holds the first's model):
      // the browser logs that response; the page handles it.
      const expected409 = /status of 409/.test(m.text()) && /\/api\/v1\/models$/.test(m.location().url || "");
      if (m.type() === "error" && !expected409) problems.push(`console error: ${m.text()}`);
    });
    page.on("response", (r) => {
      if (r.status() >= 400 && new URL(r.url()).pathname.startsWith("/assets/")) {
        problems.push(`${r.status()} for ${r.url()}`);
      }
    });

    // Every snapshot the pages ask for: on real hardware each one is an acquisition.
    let snapshots = 0;
    page.on("request", (r) => {
      if (new URL(r.url()).pathname.endsWith("/camera/snapshot")) snapshots++;
    });

    // ---- home: the bench, the experiment form ----
    await page.goto(`${base}/`);
    await page.waitForSelector("#camera-state dd");
    await page.waitForTimeout(2 * SECOND);
    expect(snapshots === 0, `the home page takes no snapshot on load (it made ${snapshots} requests to /camera/snapshot)`);
    await page.locator("#snapshot-btn").click();
    await page.waitForSelector("#snapshot[data-loaded=true]", { timeout: 60 * SECOND });
    expect(snapshots === 1, `one click, one snapshot (${snapshots})`);
    const bins = await page.locator("#histogram rect.hist-bin").count();
    if (bins < 5) fail(`the snapshot histogram has ${bins} bins`);
    const stats = await page.locator("#snapshot-stats").innerText();
    expect(/saturated/.test(stats) && /clipped black/.test(stats), `the snapshot reports clipping at both ends: ${stats.replace(/\s+/g, " ")}`);
    if (expect(await appears(page, "#snapshot-zoom[data-loaded=true]", 10 * SECOND), "the snapshot has a 1:1 zoom")) {
      const zoom = await page.locator("#snapshot-zoom").evaluate((c) => ({ w: c.width, h: c.height, cssW: c.getBoundingClientRect().width }));
      expect(zoom.w > 0 && Math.abs(zoom.cssW - zoom.w) < 1.5, `the zoom shows native pixels (${zoom.w} px drawn ${zoom.cssW.toFixed(1)} px wide)`);
    }
    if (expect(await appears(page, "#snapshot-quality [data-figure=mean_gradient]", 10 * SECOND), "the snapshot has speckle-quality figures")) {
      const q = await page.locator("#snapshot-quality").innerText();
      expect(/gradient/i.test(q) && /speckle size/i.test(q) && /SSSIG/.test(q) && /DIC/.test(q), `quality figures with what they mean: ${q.replace(/\s+/g, " ").slice(0, 300)}`);
      const mig = Number(await page.locator("#snapshot-quality [data-figure=mean_gradient]").getAttribute("data-value"));
      expect(mig > 0, `mean intensity gradient ${mig} DN/px`);
    }
    // The focus by region: 4x3 cells of the whole frame, each a % of the sharpest (the mock
    // bench's flat target is in focus everywhere).
    if (expect(await appears(page, "#focus-map td[data-focus-pct]", 10 * SECOND), "the snapshot has a focus map")) {
      const pcts = (await page.locator("#focus-map td").evaluateAll((tds) => tds.map((t) => Number(t.dataset.focusPct))));
      expect(pcts.length === 12 && pcts.every((p) => p > 50 && p <= 100) && pcts.some((p) => p === 100),
        `focus map: 12 regions within a factor two of the sharpest: ${pcts.join(", ")}`);
    }
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
    // Three independent captures: the study pools them (mean and t interval over captures).
    await form.locator("input[name=repeats]").fill("3");
    // A grid of 20 x 16 points on the reduced 200 x 160 px frames: enough bootstrap blocks
    // (dic::bootstrap::MIN_BLOCKS of 2 correlation lengths) for the displacement intervals.
    await form.locator("input[name=subset_px]").fill("17");
    await form.locator("input[name=step_px]").fill("9");
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
    for (const fig of ["figure5_u", "figure6_v"]) {
      const bars = await page.locator(`#${fig} svg path.error-bar`).count();
      expect(bars >= PATTERNS.length * SCHEMES.length, `${fig}: error bars on the bars (${bars})`);
    }
    const studyText = await page.locator("#study-table").innerText();
    expect(/\[[-+−]?\d/.test(studyText), "the study table carries intervals");
    expect(/n = 3 captures/.test(studyText), `the study table says it pools 3 captures: ${studyText.slice(0, 200)}`);
    const maps = await page.locator("#maps .figure.map svg").count();
    expect(maps >= 5, `all five maps shown (u, v, εxx, εyy, εxy): ${maps}`);
    const mapText = await page.locator("#maps").innerText();
    for (const f of ["εyy", "εxy"]) {
      expect(mapText.includes(f) || (await page.locator(`#maps svg:has-text("${f}")`).count()) > 0, `an ${f} map`);
    }
    const legends = await page.locator("#maps svg rect.legend").count();
    if (legends !== maps) fail(`maps without colour scales (${legends} legends for ${maps} maps)`);
    const moves = await page.locator("#run-info").innerText();
    expect(/px/.test(moves.split("\n").find((l) => /x1/.test(l)) || ""), `the moves carry px beside mm: ${moves.replace(/\s+/g, " ").slice(0, 200)}`);
    expect(/µm/.test(await page.locator("#study-table thead").innerText()), "the study table gives µm beside px");
    const csv = await page.locator("#downloads a", { hasText: "study.csv" }).count();
    const tifs = await page.locator("#downloads a", { hasText: ".tif" }).count();
    if (csv !== 1 || tifs < 2) fail(`downloads: ${csv} CSV, ${tifs} TIFF links`);
    log(`maps: ${maps} with colour scales; downloads: CSV and ${tifs} TIFF frames`);
    await shot(page, "2-experiment");

    // A finished experiment, opened afresh: its events are replayed into the Events box.
    await page.goto(experimentUrl);
    await page.waitForSelector("#results[data-loaded=true]", { timeout: 60 * SECOND });
    await page.waitForTimeout(1 * SECOND);
    const events = await page.locator("#events li").count();
    expect(events >= 5 && (await page.locator("#events li[data-kind=succeeded]").count()) === 1,
      `the Events box of a finished run shows its replayed events (${events})`);

    // ---- a design map from the home page's default spec (the smoke sweep) ----
    await page.goto(`${base}/`);
    await page.waitForSelector("#sweep-form textarea[name=spec]");
    const specText = await page.locator("#sweep-form textarea[name=spec]").inputValue();
    expect(JSON.parse(specText).name === "smoke", "the sweep form offers the smoke spec");
    await startAndFinish(page, "#start-sweep", "sweeps");
    const recommendationRows = await page.locator("#recommendations tbody tr").count();
    const cellRows = await page.locator("#cells tbody tr").count();
    expect(recommendationRows === 6, `6 recommendations (3 schemes x 2 sub-pixel positions): ${recommendationRows}`);
    expect(cellRows === 18, `18 cells: ${cellRows}`);
    const heatmaps = await page.locator("#heatmaps .figure svg").count();
    expect(heatmaps === 2, `one std u heat map per sub-pixel position: ${heatmaps}`);
    const markers = await page.locator("#heatmaps svg g.marker").count();
    expect(markers === 12, `the paper's a and b at its three fill factors on both maps: ${markers}`);
    await page.locator("#stat-pickers button[data-stat=v_std_px]").click();
    await page.waitForFunction(() => [...document.querySelectorAll("#heatmaps .figure")].every((f) => f.dataset.figure.startsWith("map_v_std_px_") && f.dataset.loaded === "true"), null, { timeout: 30 * SECOND });
    const biasPlots = await page.locator("#bias .figure svg").count();
    expect(biasPlots === 3, `a bias plot per scheme (sub-pixel x has two values): ${biasPlots}`);
    expect(/\[[-+−]?\d/.test(await page.locator("#cells").innerText()), "the cells carry intervals");
    log(`sweep: ${cellRows} cells, ${recommendationRows} recommendations, ${heatmaps} heat maps with ${markers} paper points, ${biasPlots} bias plots`);
    await shot(page, "8-sweep");

    // ---- a calibration from the home page (issue 33): its camera card as a page ----
    await page.goto(`${base}/`);
    await page.waitForSelector("#calibration-form textarea[name=plan]");
    const planText = await page.locator("#calibration-form textarea[name=plan]").inputValue();
    expect(JSON.parse(planText).name === "camera-card", "the calibration form offers a plan");
    // Two move sizes along both axes (the stage's map needs them), no phase scan, one round, small
    // subsets: seconds on the small mock bench.
    await page.locator("#calibration-form textarea[name=plan]").fill(JSON.stringify({
      name: "browser-card", pattern: "a", move_sizes_mm: [0.5, 2.5], phase_scan_count: 0,
      static_frames: 1, rounds: 1, dic: { subset_px: 21, step_px: 10, strain_window: 5 },
    }));
    await startAndFinish(page, "#start-calibration", "calibrations");
    const cardModel = await page.locator("#card-model").innerText();
    expect(/^card-browser-card-/.test(cardModel), `the card names its stored model: ${cardModel}`);
    const stageRows = await page.locator("#card-stage tbody tr").count();
    expect(stageRows === 4, `the stage's map: scale x, scale y, angle, skew (${stageRows} rows)`);
    const discrepancy = await page.locator("#card-discrepancy").innerText();
    expect(/\d ± \d/.test(discrepancy) && discrepancy.includes("→"), `the discrepancy before and with the card, with SEs: ${discrepancy}`);
    const found = await page.locator("#card-found").innerText();
    expect(found.startsWith("Found: "), `the card says what it found: ${found}`);
    expect((await page.locator("#card-imaging tbody tr").count()) >= 1, "the imaging chain has rows");
    expect((await page.locator("#card-unexplained").innerText()).length > 20, "what the card leaves unexplained is said");
    expect(await page.locator(`#card-use a[href^="/datasets/"]`).count() === 1, "the card links the dataset its frames became");
    expect(await page.locator("#downloads a").count() === 4, "card.json, card.txt, the model and the rounds to download");
    log(`calibration: ${found}; ${discrepancy}`);
    await shot(page, "9-calibration");
    await page.goto(`${base}/`);
    await page.waitForSelector("#calibration-list tr[data-id]", { timeout: 10 * SECOND });
    expect(await page.locator("#calibration-list tr[data-id]").count() === 1, "the home page lists the calibration");

    // ---- the perpendicularity check on the bench page (issue 33's setup aid) ----
    await page.locator("#perp-btn").click();
    if (expect(await appears(page, "#perp-result[data-loaded=true]", 120 * SECOND), "the perpendicularity check reports")) {
      const stage = await page.locator("#perp-result [data-perp=stage_angle_rad]").innerText();
      expect(/±/.test(stage), `the stage's angle with its standard error: ${stage}`);
      const tilts = await page.locator("#perp-result [data-perp^=tilt_about]").allInnerTexts();
      expect(tilts.length === 2 && tilts.every((t) => /±/.test(t)), `two tilt angles with their standard errors: ${tilts.join("; ")}`);
      log(`perpendicularity: stage ${stage}; tilt ${tilts.join(", ")}`);
      const models = await page.evaluate(async () => (await (await fetch("/api/v1/models")).json()).map((m) => m.name));
      expect(!models.some((n) => n.startsWith("card-perpendicularity-")), `a check keeps no model: ${models.join(", ")}`);
      const calibrations = await page.evaluate(async () => (await (await fetch("/api/v1/calibrations")).json()).length);
      expect(calibrations === 1, `a check is no calibration (${calibrations} calibrations)`);
    }
    // Kept checking while the mount is adjusted: the readings follow one another until unticked.
    await page.locator("#perp-live").setChecked(true);
    await page.locator("#perp-btn").click();
    if (expect(await appears(page, "#perp-history li[data-reading='3']", 120 * SECOND), "kept checking, the readings follow one another")) {
      await page.locator("#perp-live").setChecked(false);
      await page.waitForFunction(() => !document.querySelector("#perp-btn").disabled, null, { timeout: 120 * SECOND });
      const readings = await page.locator("#perp-history li").count();
      expect(readings >= 3 && readings <= 4, `unticked, the checks stop (${readings} readings)`);
      log(`perpendicularity kept: ${(await page.locator("#perp-history li").first().innerText()).replace(/\s+/g, " ")}`);
    }

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
    const mf = page.locator("#model-form");
    // 2x2 binning (ff100) only, small subsets: the diagnosis takes seconds, not minutes. A page
    // load resets the form, so this is done again after each.
    const smallAnalysis = async () => {
      await page.locator("#model-form summary").click();
      for (const s of ["ff50", "ff25", "native"]) await mf.locator(`input[name=scheme][value=${s}]`).setChecked(false);
      await mf.locator("input[name=scheme][value=ff100]").setChecked(true);
      await mf.locator("input[name=subset_px]").fill("21");
      await mf.locator("input[name=step_px]").fill("10");
      await mf.locator("input[name=strain_window]").fill("5");
      await mf.locator("input[name=prefilter_sigma_px]").fill("0.7");
    };
    await smallAnalysis();

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
    const firstPlot = await page.locator("#comparison-plots .figure").first().getAttribute("data-plot");
    expect(firstPlot === "summary.svg", `the comparison leads with its summary figure (${firstPlot})`);
    const allFigures = await page.locator("#comparison-plots .figure").count();
    await page.locator("#plot-picker").selectOption({ index: 1 });
    const oneRun = await page.locator("#comparison-plots .figure:not(.hidden)").count();
    expect(oneRun > 1 && oneRun < allFigures, `the picker narrows ${allFigures} figures to one run's ${oneRun}`);
    await page.locator("#plot-picker").selectOption("");
    const accuracyRows = await page.locator("#accuracy-table tbody tr").count();
    const sCurve = await page.locator('#comparison-plots .figure[data-plot="accuracy_vs_commanded.svg"] svg line.error-bar').count();
    log(`accuracy against the commanded move: ${accuracyRows} rows; ${sCurve} error bars on its plot`);
    if (accuracyRows < 1) fail("the comparison shows no accuracy against the commanded move");
    if (sCurve < 1) fail("the plot of bias and std against the commanded move has no error bar");
    // Every length carries its error, and a part below its noise is a bound, never a bare zero.
    const runCells = await page.locator("#comparison-runs tbody td.num").allInnerTexts();
    const bare = runCells.filter((t) => !/±|^< |^—$/.test(t));
    expect(runCells.length > 0 && bare.length === 0, `every discrepancy cell is "x ± se" or "< bound" (${bare.slice(0, 4).join(" | ")})`);
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
    const firstModel = (await page.locator("#comparison-model").innerText()).split(" (")[0];
    const summary = await page.locator("#comparison-summary").innerText();
    expect(/µm/.test(summary), `the discrepancy carries µm beside px: ${summary.replace(/\s+/g, " ").slice(0, 120)}`);
    expect(/how to read/i.test(await page.locator("#comparison").innerText()) && /how to read/i.test(await page.locator("#diagnosis").innerText()),
      "a 'how to read this' beside the discrepancy and the ΔBIC");
    const info = await page.locator("#dataset-info").innerText();
    expect(/px\/mm/.test(info) && /bit/.test(info) && /x2/.test(info) && /mm/.test(info) && /µm|px/.test(info),
      `the dataset card gives the scale, bit depth and runs with moves: ${info.replace(/\s+/g, " ").slice(0, 300)}`);
    await shot(page, "5-dataset-winner-added");

    // ---- reload: the comparisons and diagnoses are still listed and reopen ----
    // The page as first opened (a result shown puts `?job=` in the address).
    const datasetUrl = page.url().split("?")[0];
    await page.goto(datasetUrl);
    if (expect(await appears(page, "#job-list tr[data-kind=diagnosis]", 15 * SECOND), "the dataset page lists its jobs after a reload")) {
      const kinds = await page.locator("#job-list tr[data-kind]").evaluateAll((rs) => rs.map((r) => r.dataset.kind));
      expect(kinds.filter((k) => k === "comparison").length === 2 && kinds.filter((k) => k === "diagnosis").length === 1,
        `two comparisons and one diagnosis listed (${kinds.join(", ")})`);
      await page.locator("#job-list tr[data-kind=diagnosis] a.open").first().click();
      expect(await appears(page, `#diagnosis-verdict[data-verdict=${expectedVerdict}]`, 15 * SECOND, "visible"), "a listed diagnosis reopens");
      const diagnosisUrl = page.url();
      expect(/\?job=dia-/.test(diagnosisUrl), `the address names the diagnosis shown: ${diagnosisUrl}`);
      await page.locator("#job-list tr[data-kind=comparison] a.open").first().click();
      expect(await appears(page, "#comparison-discrepancy", 15 * SECOND, "visible"), "a listed comparison reopens");
      // A result's URL, opened anew (bookmarked, pasted into a lab book), shows that result.
      await page.goto(diagnosisUrl);
      expect(await appears(page, `#diagnosis-verdict[data-verdict=${expectedVerdict}]`, 30 * SECOND, "visible"), "a diagnosis's own URL opens it");
      const link = await page.locator("#diagnosis-link").getAttribute("href");
      expect(diagnosisUrl.endsWith(link), `the diagnosis links to itself (${link})`);
    }
    await shot(page, "6-dataset-reloaded");

    // ---- an effect of the user's own, written beside the unexplained residual ----
    await smallAnalysis();
    await page.locator("#user-effect summary").click();
    await page.locator("#user-effect-btn").click();
    if (expect(await appears(page, '#candidate-table tr[data-effect="user.bow"]', 300 * SECOND), "the user's effect is fitted as a candidate")) {
      const row = await page.locator('#candidate-table tr[data-effect="user.bow"]').innerText();
      expect(/c = .*±/.test(row), `the user's effect has its parameter ± stderr: ${row.replace(/\s+/g, " ")}`);
      await page.waitForFunction(() => /user\.bow: /.test(document.querySelector("#user-effect-notice").textContent), null, { timeout: 30 * SECOND });
      log(`user effect: ${(await page.locator("#user-effect-notice").innerText()).replace(/\s+/g, " ")}`);
      const models = await page.evaluate(async () => (await (await fetch("/api/v1/models")).json()).map((m) => m.name));
      expect(models.includes("baseline+bow"), `the model with the user's effect is stored (${models.join(", ")})`);
    }
    await shot(page, "6b-user-effect");

    // ---- a second dataset of the same bench: its winner must not pass for the first's ----
    if (secondDatasetDir) {
      await page.goto(`${base}/`);
      const files2 = fs.readdirSync(secondDatasetDir).filter((f) => f === "dataset.json" || /\.tiff?$/i.test(f)).map((f) => path.join(secondDatasetDir, f));
      await page.locator("#upload-files").setInputFiles(files2);
      await Promise.all([
        page.waitForURL((u) => /\/datasets\/[^/]+$/.test(u.pathname) && u.href !== datasetUrl, { timeout: 60 * SECOND }),
        page.locator("#upload-btn").click(),
      ]);
      const second = page.url();
      log(`uploaded the second dataset: ${second}`);
      await page.waitForSelector("#model option[value=baseline]", { state: "attached" });
      await page.locator("#model").selectOption("baseline");
      await smallAnalysis();
      await page.locator("#diagnose-btn").click();
      await page.waitForSelector("#diagnosis-verdict[data-verdict]", { timeout: 400 * SECOND });
      const verdict2 = await page.locator("#diagnosis-verdict").getAttribute("data-verdict");
      if (verdict2 !== expectedVerdict) fail(`second dataset: verdict ${verdict2}, want ${expectedVerdict}`);
      await add.waitFor({ state: "visible" });
      await add.click();
      // Done when the button is enabled again (the add and its comparison, or an error).
      await page.waitForFunction(() => !document.querySelector("#add-winner").disabled && !/…$/.test(document.querySelector("#add-notice").textContent), null, { timeout: 300 * SECOND });
      const notice = await page.locator("#add-notice").innerText();
      const error = await page.locator("#job-error").innerText();
      const compared = (await page.locator("#comparison-model").innerText().catch(() => "")).split(" (")[0];
      log(`second add: notice "${notice}", error "${error}", comparison with "${compared}"`);
      expect(!new RegExp(`model ${firstModel.replace(/[+.]/g, "\\$&")} added`).test(notice),
        `the second add does not report the first dataset's model ${firstModel} as added ("${notice}")`);
      const models = await page.evaluate(async () => (await (await fetch("/api/v1/models")).json()).map((m) => m.name));
      const fresh = models.filter((n) => n !== firstModel && n.startsWith(firstModel));
      expect(fresh.length === 1, `the second winner is stored under a fresh name (${models.join(", ")})`);
      if (fresh.length === 1) {
        expect(notice.includes(fresh[0]) && notice.includes(firstModel), `the notice names both models: "${notice}"`);
        expect(compared === fresh[0], `the comparison after the add uses the new model (${compared})`);
      }
      await shot(page, "7-second-dataset-added");
    }

    // ---- the bench resolves what one move leaves open (issue 33) ----
    // One 2 mm move, no static frames, captured through the API: distortion and scale are
    // confounded by the design, the sensor's noise cannot be revealed.
    const oneMove = await page.evaluate(async () => {
      const post = await fetch("/api/v1/experiments", {
        method: "POST", headers: { "content-type": "application/json" },
        body: JSON.stringify({ name: "one move", patterns: ["a"], settle_ms: 0, moves: [{ id: "x2mm", dx_mm: 2.0, dy_mm: 0.0 }], dic: { subset_px: 21, step_px: 10, strain_window: 5 } }),
      });
      const job = await post.json();
      for (;;) {
        const r = await (await fetch(`/api/v1/jobs/${job.id}`)).json();
        if (r.status === "succeeded") return r.dataset_id;
        if (["failed", "cancelled"].includes(r.status)) return null;
        await new Promise((ok) => setTimeout(ok, 200));
      }
    });
    if (expect(!!oneMove, "a one-move experiment through the API gives a dataset")) {
      await page.goto(`${base}/datasets/${oneMove}`);
      await page.waitForSelector("#model option[value=baseline]", { state: "attached" });
      await page.locator("#model").selectOption("baseline");
      await smallAnalysis();
      await mf.locator("input[name=scheme][value=ff100]").setChecked(false);
      await mf.locator("input[name=scheme][value=native]").setChecked(true);
      await page.locator("#diagnose-btn").click();
      await page.waitForSelector("#diagnosis-verdict[data-verdict]", { timeout: 400 * SECOND });
      const benchButton = page.locator("#on-bench-btn");
      const asked = expect(await appears(page, "#on-bench-btn", 15 * SECOND, "visible"), "a diagnosis that left confounds offers to resolve them on the bench");
      const runs = (await benchButton.getAttribute("data-runs")) || "";
      expect(runs.includes("several_move_sizes") && runs.includes("static_repeats"),
        `the bench is asked for moves of several sizes and static frames (${runs}: "${await benchButton.innerText()}")`);
      if (asked) {
        await benchButton.click();
        if (expect(await appears(page, "#on-bench-table", 400 * SECOND, "visible"), "the on-bench job shows what it resolved")) {
          const rows = await page.locator("#on-bench-table tbody tr").evaluateAll((rs) => rs.map((r) => [r.dataset.open, r.lastElementChild.textContent]));
          log(`on the bench: ${rows.map((r) => r.join(": ")).join("; ")}`);
          const pair = rows.find((r) => /lens_distortion and scale confounded \(design\)/.test(r[0] || ""));
          expect(pair && pair[1] === "resolved", `distortion and scale, confounded by one move, are resolved by the bench's runs (${JSON.stringify(rows)})`);
          const noise = rows.find((r) => /sensor_noise not identifiable/.test(r[0] || ""));
          expect(noise && noise[1] === "resolved", "the sensor's noise, unrevealed without static frames, is revealed");
          const merged = await page.locator("#on-bench-dataset").innerText();
          expect(merged && merged !== oneMove, `the bench's runs make a new dataset (${merged}), the original stays`);
          expect(await appears(page, "#job-list tr[data-kind=on_bench]", 15 * SECOND), "the dataset's page lists the on-bench job");
        }
      }
      await shot(page, "9-on-bench");
    }

    if (problems.length) fail(`the pages reported problems:\n  ${problems.join("\n  ")}`);
    if (defects.length) fail(`${defects.length} defects:\n  ${defects.join("\n  ")}`);
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
