// Home: the bench (state, snapshot with histogram, exposure and gain), experiments, datasets.
import { api, el, $, clear, num, mm, when, showError, setupToken, loadRunList, follow, valuePm } from "./common.js";
import { histogramSvg } from "./charts.js";

setupToken();

// ---------- bench ----------

function kv(node, pairs) {
  clear(node, pairs.flatMap(([k, v]) => [el("dt", {}, k), el("dd", {}, v)]));
}

async function loadBench() {
  try {
    const status = await api("/status");
    const b = status.bench;
    const cam = b.camera;
    kv($("#camera-state"), [
      ["camera", `${cam.info.vendor} ${cam.info.model} (${cam.info.serial})`],
      ["sensor", `${cam.info.sensor_width} × ${cam.info.sensor_height} px`],
      ["exposure", `${num(cam.settings.exposure_us)} µs`],
      ["gain", `${num(cam.settings.gain_db)} dB`],
      ["pixel format", String(cam.settings.pixel_format)],
      ["binning", (cam.settings.binning || []).join(" × ")],
      ["decimation", (cam.settings.decimation || []).join(" × ")],
      ["hardware schemes", (cam.info.hardware_schemes || []).map((h) => h.name).join(", ") || "none"],
      ["frames", cam.counters ? `${cam.counters.completed} completed, ${cam.counters.failed} failed, ${cam.counters.missing_packets} packets missing` : "—"],
    ]);
    offerHardwareSchemes(cam.info.hardware_schemes || []);
    const form = $("#camera-form");
    if (document.activeElement?.form !== form) {
      form.exposure_us.value = cam.settings.exposure_us;
      form.gain_db.value = cam.settings.gain_db;
    }
    const st = b.stage;
    kv($("#stage-state"), st ? [
      ["stage", st.info.model],
      ["position", st.position ? `x ${mm(st.position.x_mm, st.info.resolution_mm)} mm, y ${mm(st.position.y_mm, st.info.resolution_mm)} mm` : "unknown"],
      ["step", st.info.resolution_mm > 0 ? `${num(1000 * st.info.resolution_mm)} µm (moves are commanded in whole steps)` : "—"],
      ["homed", st.homed === undefined ? "—" : (st.homed ? "yes" : "no")],
      ["travel x", `${st.info.travel_x_mm[0]} … ${st.info.travel_x_mm[1]} mm`],
      ["travel y", `${st.info.travel_y_mm[0]} … ${st.info.travel_y_mm[1]} mm`],
    ] : [["stage", "none configured"]]);
    kv($("#queue-state"), [
      ["held by", b.holder ? el("a", { href: `/experiments/${b.holder}` }, b.holder) : "nobody"],
      ["target", b.target || "—"],
      ["queued", String(status.experiments_queued)],
      ["running", String(status.experiments_running)],
      ["data", el("span", { class: "mono" }, status.data_dir)],
    ]);
  } catch (e) {
    kv($("#camera-state"), [["error", e.message]]);
  }
}

/** The camera's own binning/decimation as experiment schemes (unchecked), once per page. */
function offerHardwareSchemes(schemes) {
  const holder = $("#hardware-schemes");
  if (!holder || holder.dataset.filled) return;
  holder.dataset.filled = "1";
  clear(holder, schemes.map((h) => {
    const twin = h.equivalent_preset ? `, beside ${h.equivalent_preset}` : "";
    const domain = h.binning_domain ? `, ${h.binning_domain} binning` : "";
    return el("label", {}, el("input", { type: "checkbox", name: "scheme", value: h.name }), ` ${h.name} (on the sensor${twin}${domain})`);
  }));
}

/** Decodes an uncompressed 8/16-bit grey baseline TIFF (what the daemon writes). */
function decodeTiff(buf) {
  const dv = new DataView(buf);
  const le = dv.getUint16(0) === 0x4949;
  const u16 = (o) => dv.getUint16(o, le);
  const u32 = (o) => dv.getUint32(o, le);
  if (u16(2) !== 42) throw new Error("not a TIFF");
  const ifd = u32(4);
  const n = u16(ifd);
  const tags = {};
  for (let i = 0; i < n; i++) {
    const e = ifd + 2 + 12 * i;
    const [tag, type, count] = [u16(e), u16(e + 2), u32(e + 4)];
    const size = type === 3 ? 2 : 4;
    const at = count * size > 4 ? u32(e + 8) : e + 8;
    const vals = [];
    for (let k = 0; k < count; k++) vals.push(size === 2 ? u16(at + 2 * k) : u32(at + 4 * k));
    tags[tag] = vals;
  }
  const [w, h, bits] = [tags[256][0], tags[257][0], (tags[258] || [8])[0]];
  if ((tags[259] || [1])[0] !== 1) throw new Error("compressed TIFF");
  const out = new Uint16Array(w * h);
  let p = 0;
  tags[273].forEach((off, s) => {
    const bytes = tags[279][s];
    const step = bits === 16 ? 2 : 1;
    for (let b = 0; b + step <= bytes && p < out.length; b += step) {
      out[p++] = bits === 16 ? dv.getUint16(off + b, le) : dv.getUint8(off + b);
    }
  });
  return { width: w, height: h, bits, data: out };
}

/** Side of the 1:1 zoom, px: a crop of the frame's centre drawn at native pixels. */
const ZOOM_PX = 160;

/** Draws the centre of the frame, one frame pixel per canvas pixel, with the same stretch. */
function drawZoom(img, lo, hi) {
  const side = Math.min(ZOOM_PX, img.width, img.height);
  const x0 = Math.floor((img.width - side) / 2);
  const y0 = Math.floor((img.height - side) / 2);
  const canvas = $("#snapshot-zoom");
  canvas.width = side;
  canvas.height = side;
  // CSS size = canvas size: the browser never resamples the pixels.
  canvas.style.width = `${side}px`;
  canvas.style.height = `${side}px`;
  const ctx = canvas.getContext("2d");
  const rgba = ctx.createImageData(side, side);
  for (let r = 0; r < side; r++) {
    for (let c = 0; c < side; c++) {
      const v = img.data[(y0 + r) * img.width + x0 + c];
      const g = Math.max(0, Math.min(255, Math.round((255 * (v - lo)) / (hi - lo))));
      rgba.data.set([g, g, g, 255], 4 * (r * side + c));
    }
  }
  ctx.putImageData(rgba, 0, 0);
  canvas.title = `pixels ${x0}…${x0 + side - 1} × ${y0}…${y0 + side - 1} at 1:1`;
  canvas.dataset.loaded = "true";
}

/** The speckle-quality figures the server computed on this frame, each with what it means. */
function showQuality(q, bits) {
  const box = $("#snapshot-quality");
  if (!q) {
    clear(box, el("p", { class: "muted" }, "no quality figures for this frame"));
    return;
  }
  const full = 2 ** bits - 1;
  const row = (key, name, value, why, raw) => [
    el("dt", {}, name),
    el("dd", { "data-figure": key, "data-value": raw }, value, el("span", { class: "why" }, why)),
  ];
  const size = q.speckle_size_px;
  const perDn = (x) => (Number.isFinite(x) ? `${num(x, 3)} px per DN of noise` : "—");
  clear(box, el("dl", { class: "kv quality" },
    row("mean_gradient", "mean intensity gradient",
      `${num(q.mean_gradient_dn_per_px, 3)} DN/px (${num((100 * q.mean_gradient_dn_per_px) / full, 3)} % of full scale per px)`,
      "Pan et al. 2010: the random error of every subset falls as this rises (σ_u ∝ noise / gradient); a sharp, high-contrast pattern has a large one.",
      q.mean_gradient_dn_per_px),
    row("speckle_size", "mean speckle size",
      size == null ? "— (no speckle: the autocorrelation stays above ½)" : `${num(size, 3)} px (x ${num(q.speckle_size_x_px, 3)}, y ${num(q.speckle_size_y_px, 3)})`,
      "Width of the autocorrelation at half its height. About 3–5 px suits DIC: smaller speckles alias, larger ones need larger subsets.",
      size ?? ""),
    row("sssig", `SSSIG over ${q.subset_px} px subsets`,
      `median ${num(q.sssig_x_median_dn2, 3)} (x) / ${num(q.sssig_y_median_dn2, 3)} (y) DN², worst ${num(q.sssig_x_min_dn2, 3)} / ${num(q.sssig_y_min_dn2, 3)} DN², over ${q.subsets} subsets`,
      "Pan et al. 2008: the sum of squared intensity gradients in one subset. The larger, the better that subset is matched; a small worst value marks a featureless region.",
      q.sssig_x_median_dn2),
    row("predicted_std", "expected DIC error",
      `σ_u ≈ ${perDn(q.std_u_px_per_noise_dn)}, σ_v ≈ ${perDn(q.std_v_px_per_noise_dn)}` +
        (Number.isFinite(q.noise_dn) ? `; at the measured noise (σ ≈ ${num(q.noise_dn, 3)} DN) σ_u ≈ ${num(q.std_u_px, 3)} px, σ_v ≈ ${num(q.std_v_px, 3)} px` : ""),
      "√2 · noise / √SSSIG for a median subset (Pan et al. 2008). The noise is the temporal σ of this frame against a second one the snapshot took for it.",
      q.std_u_px_per_noise_dn)));
}

/** The whole frame's gradient energy region by region, as % of the sharpest region: a target
 * in focus everywhere reads near 100 % in every cell; one side well below the other is a
 * defocus there (the target or the sensor tilted, or the lens's field curvature). */
function showFocus(focus) {
  const box = $("#snapshot-focus");
  if (!focus || !Array.isArray(focus.energy_dn2_per_px2)) {
    clear(box, el("p", { class: "muted" }, "no focus figures for this frame"));
    return;
  }
  const e = focus.energy_dn2_per_px2;
  const max = Math.max(...e);
  const rows = [];
  for (let r = 0; r < focus.rows; r++) {
    const cells = [];
    for (let c = 0; c < focus.columns; c++) {
      const v = e[r * focus.columns + c];
      const pct = max > 0 ? (100 * v) / max : NaN;
      const cell = el("td", { class: "num", "data-focus-pct": Number.isFinite(pct) ? pct.toFixed(1) : "",
        title: `${num(v, 4)} DN²/px²` }, Number.isFinite(pct) ? `${num(pct, 3)} %` : "—");
      // Through the CSSOM: the page's CSP refuses inline style attributes.
      cell.style.background = `rgba(46, 125, 50, ${Number.isFinite(pct) ? (0.6 * pct / 100).toFixed(2) : 0})`;
      cells.push(cell);
    }
    rows.push(el("tr", {}, ...cells));
  }
  const weakest = max > 0 ? (100 * Math.min(...e)) / max : NaN;
  clear(box,
    el("table", { class: "focus-map", id: "focus-map" }, el("tbody", {}, ...rows)),
    el("p", { class: "why" }, `Mean squared intensity gradient per region of the whole frame (Krotkov 1987), as % of the sharpest; the weakest region holds ${num(weakest, 3)} %. On one print this falls where the lens defocuses: adjust the focus or the target's tilt until the regions agree.`));
}

async function snapshot() {
  const btn = $("#snapshot-btn");
  btn.disabled = true;
  showError($("#snapshot-error"), null);
  try {
    const resp = await api("/camera/snapshot?quality=true", { method: "POST", raw: true });
    const qualityHeader = resp.headers.get("X-Speckle-Quality");
    const img = decodeTiff(await resp.arrayBuffer());
    const sorted = Uint16Array.from(img.data).sort();
    const q = (f) => sorted[Math.min(sorted.length - 1, Math.floor(f * sorted.length))];
    const [lo, hi] = [q(0.005), Math.max(q(0.995), q(0.005) + 1)];
    const canvas = $("#snapshot");
    canvas.width = img.width;
    canvas.height = img.height;
    const ctx = canvas.getContext("2d");
    const rgba = ctx.createImageData(img.width, img.height);
    let sum = 0, sat = 0, dark = 0, max = 0;
    const full = img.bits === 16 ? 65535 : 255;
    for (let i = 0; i < img.data.length; i++) {
      const v = img.data[i];
      sum += v;
      if (v >= full) sat++;
      if (v === 0) dark++;
      if (v > max) max = v;
      const g = Math.max(0, Math.min(255, Math.round((255 * (v - lo)) / (hi - lo))));
      // Clipped pixels marked: saturated red, black-clipped blue (DIC loses both).
      if (v >= full) rgba.data.set([230, 30, 30, 255], 4 * i);
      else if (v === 0) rgba.data.set([30, 80, 230, 255], 4 * i);
      else rgba.data.set([g, g, g, 255], 4 * i);
    }
    ctx.putImageData(rgba, 0, 0);
    drawZoom(img, lo, hi);
    let quality = null;
    try { quality = qualityHeader ? JSON.parse(qualityHeader) : null; } catch (_) { /* shown as none */ }
    showQuality(quality, img.bits);
    showFocus(quality && quality.focus);
    // Histogram over the 16-bit range the frame uses (bins of a power of two).
    const top = Math.max(256, 2 ** Math.ceil(Math.log2(max + 1)));
    const bins = 128;
    const width = top / bins;
    const counts = new Array(bins).fill(0);
    for (const v of img.data) counts[Math.min(bins - 1, Math.floor(v / width))]++;
    clear($("#histogram"), histogramSvg(counts, width, top, "DN", "Histogram of the snapshot"));
    const mean = sum / img.data.length;
    kv($("#snapshot-stats"), [
      ["size", `${img.width} × ${img.height} px, ${img.bits} bit`],
      ["mean", `${num(mean)} DN`],
      ["0.5 … 99.5 %", `${lo} … ${hi} DN`],
      ["saturated", `${sat} px (${num((100 * sat) / img.data.length, 2)} %)`],
      // Pixels at 0 DN lost what lay below the black level: noise and dark speckles are cut,
      // which biases DIC as saturation does (raise the exposure or the camera's black level).
      ["clipped black (0 DN)", `${dark} px (${num((100 * dark) / img.data.length, 2)} %)`],
      ["taken", new Date().toLocaleTimeString()],
    ]);
    $("#snapshot").dataset.loaded = "true";
  } catch (e) {
    showError($("#snapshot-error"), e);
  } finally {
    btn.disabled = false;
  }
}

$("#snapshot-btn").addEventListener("click", snapshot);

/** A small move back and forth along x on the bench (`POST /perpendicularity-checks`), then the
 * target's tilt and the stage's angle read from the two fields, each with its standard error. */
async function checkPerpendicularity() {
  const status = $("#perp-status");
  showError($("#perp-error"), null);
  try {
    const run = await api("/perpendicularity-checks", { method: "POST", body: { pattern: $("#perp-pattern").value } });
    const id = encodeURIComponent(run.id);
    const record = await follow(`/perpendicularity-checks/${id}`, `/jobs/${id}/events`, null,
      (r) => { status.textContent = `${r.status}, ${Math.round(100 * (r.progress || 0))} %`; });
    if (record.status !== "succeeded") throw new Error(`the check ${record.status}: ${record.message || ""}`);
    const r = await api(`/perpendicularity-checks/${id}/reading`);
    const rows = [
      ["tilt about y (+x side farther) [rad]", valuePm(r.tilt_about_y_rad, r.tilt_about_y_se_rad), "tilt_about_y_rad"],
      ["tilt about x (+y side farther) [rad]", valuePm(r.tilt_about_x_rad, r.tilt_about_x_se_rad), "tilt_about_x_rad"],
      ["stage angle to the rows [rad]", valuePm(r.stage_angle_rad, r.stage_angle_se_rad), "stage_angle_rad"],
    ];
    // Without a stated distance the angles are those at an assumed one: one translation
    // identifies tan θ over the distance.
    const wd = `${num(r.working_distance_mm, 4)}${r.working_distance_stated ? "" : " (assumed: the bench states none)"}`;
    clear($("#perp-result"),
      rows.flatMap(([name, value, key]) => [el("dt", {}, name), el("dd", { "data-perp": key }, value)]),
      el("dt", {}, "at a working distance of [mm]"), el("dd", { "data-perp": "working_distance_mm" }, wd),
      el("dt", {}, "reading"), el("dd", {}, `${r.points} points, ${num(r.residual_px, 3)} px about the fit`,
        r.significant ? " — the tilt is significant: adjust the mount" : " — no significant tilt"));
    status.textContent = `checked ${new Date().toLocaleTimeString()}`;
    $("#perp-result").dataset.loaded = "true";
    return { rows, significant: r.significant };
  } catch (e) {
    showError($("#perp-error"), e);
    status.textContent = "";
    return null;
  }
}

/** One reading in the history the user adjusts the mount by, newest first. */
function addReading(reading) {
  const list = $("#perp-history");
  const n = list.children.length + 1;
  const words = reading.rows.map(([name, value]) => `${name} ${value}`);
  list.prepend(el("li", { "data-reading": String(n), "data-significant": String(reading.significant) },
    `${new Date().toLocaleTimeString()} — ${words.join("; ") || "no tilt separated"}${reading.significant ? " (significant)" : ""}`));
}

/** Checks once, or again and again while "keep checking" is ticked: the readings follow the
 * mount as the user adjusts it. */
async function perpendicularity() {
  const btn = $("#perp-btn");
  btn.disabled = true;
  try {
    do {
      const reading = await checkPerpendicularity();
      if (!reading) break;
      addReading(reading);
    } while ($("#perp-live").checked);
  } finally {
    btn.disabled = false;
  }
}

$("#perp-btn").addEventListener("click", perpendicularity);

$("#camera-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const f = ev.target;
  showError($("#camera-error"), null);
  $("#camera-notice").textContent = "";
  try {
    const applied = await api("/camera", {
      method: "PATCH",
      body: { exposure_us: Number(f.exposure_us.value), gain_db: Number(f.gain_db.value) },
    });
    $("#camera-notice").textContent = `camera set: ${num(applied.exposure_us)} µs, ${num(applied.gain_db)} dB`;
    f.exposure_us.value = applied.exposure_us;
    f.gain_db.value = applied.gain_db;
    await loadBench();
    await snapshot();
  } catch (e) {
    showError($("#camera-error"), e);
  }
});

// ---------- experiments ----------

function loadExperiments() {
  return loadRunList("/experiments?limit=50", "experiments", $("#experiment-list"), "no experiment yet: start one below");
}

function parseMoves(text) {
  const moves = [];
  for (const [i, line] of text.split("\n").entries()) {
    const t = line.trim();
    if (!t || t.startsWith("#")) continue;
    const parts = t.split(/[\s,;]+/);
    if (parts.length !== 3 || !parts.slice(1).every((p) => Number.isFinite(Number(p)))) {
      throw new Error(`moves, line ${i + 1}: write "id dx_mm dy_mm", e.g. "x5mm 5.0 0.0"`);
    }
    moves.push({ id: parts[0], dx_mm: Number(parts[1]), dy_mm: Number(parts[2]) });
  }
  return moves;
}

$("#experiment-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const f = ev.target;
  const err = $("#experiment-error");
  showError(err, null);
  try {
    const checked = (name) => [...f.querySelectorAll(`input[name=${name}]:checked`)].map((i) => i.value);
    const body = {
      name: f.run_name.value.trim(),
      patterns: checked("pattern"),
      schemes: checked("scheme"),
      moves: parseMoves(f.moves.value),
      step_series: [],
      repeats: Number(f.repeats.value),
      new_layout_per_repeat: f.new_layout_per_repeat.checked,
      static_frames: Number(f.static_frames.value),
      frames_averaged: Number(f.frames_averaged.value),
      settle_ms: Number(f.settle_ms.value),
      dic: {
        subset_px: Number(f.subset_px.value),
        step_px: Number(f.step_px.value),
        strain_window: Number(f.strain_window.value),
        prefilter_sigma_px: Number(f.prefilter_sigma_px.value),
      },
    };
    $("#start-experiment").disabled = true;
    const run = await api("/experiments", { method: "POST", body });
    location.href = `/experiments/${run.id}`;
  } catch (e) {
    showError(err, e);
    $("#start-experiment").disabled = false;
  }
});

// ---------- forms that start runs ----------

/**
 * A form whose textarea `field` holds a run's JSON body: submitted, it is POSTed to `/{kind}` and
 * the page goes to the new run's (`/{kind}/{id}`); a body that is not JSON or a refusal is shown
 * in `error`.
 */
function startsRuns({ form, field, what, kind, button, error }) {
  form.addEventListener("submit", async (ev) => {
    ev.preventDefault();
    showError(error, null);
    let body;
    try {
      body = JSON.parse(form[field].value);
    } catch (e) {
      showError(error, `${what} is not JSON: ${e.message}`);
      return;
    }
    button.disabled = true;
    try {
      const run = await api(`/${kind}`, { method: "POST", body });
      location.href = `/${kind}/${run.id}`;
    } catch (e) {
      showError(error, e);
      button.disabled = false;
    }
  });
}

// ---------- design maps ----------

/** config/sweeps/smoke.toml as JSON: 3 prints x 3 schemes x 2 sub-pixel positions x 3 seeds. */
const SMOKE_SPEC = {
  name: "smoke",
  seed: 7,
  seeds: 3,
  move_mm: [0.7692307692307693, 0.0],
  camera: { width: 384, height: 384, scale_px_per_mm: 26.0, exposure_level: 0.5 },
  axes: {
    dot_diameter_px: [2.0, 4.0, 7.0],
    schemes: ["ff100", "ff50", "ff25"],
    noise: [{ full_well_e: 30000.0, read_noise_e: 1.5, gain: 0.46 }],
    subpixel_x: [0.0, 0.5],
  },
  dic: { subset_px: 31, step_px: 16, strain_window: 5 },
};

function loadSweeps() {
  return loadRunList("/sweeps?limit=50", "sweeps", $("#sweep-list"), "no design map yet: start one below");
}

$("#sweep-form").spec.value = JSON.stringify(SMOKE_SPEC, null, 2);

startsRuns({ form: $("#sweep-form"), field: "spec", what: "the spec", kind: "sweeps", button: $("#start-sweep"), error: $("#sweep-error") });

// ---------- calibrations ----------

/** A plan with every field left to its default but the name and the target. */
const DEFAULT_PLAN = { name: "camera-card", pattern: "a" };

function loadCalibrations() {
  return loadRunList("/calibrations?limit=50", "calibrations", $("#calibration-list"), "no calibration yet: start one below");
}

$("#calibration-form").plan.value = JSON.stringify(DEFAULT_PLAN, null, 2);

startsRuns({ form: $("#calibration-form"), field: "plan", what: "the plan", kind: "calibrations", button: $("#start-calibration"), error: $("#calibration-error") });

// ---------- datasets ----------

async function loadDatasets() {
  try {
    const list = await api("/datasets?limit=1000");
    const rows = list.map((d) => {
      const m = /^experiment:(.+)$/.exec(d.source || "");
      return el("tr", { "data-id": d.id },
        el("td", {}, el("a", { href: `/datasets/${d.id}`, class: "mono" }, d.id)),
        el("td", {}, d.name),
        el("td", {}, m ? el("a", { href: `/experiments/${m[1]}` }, `experiment ${m[1]}`) : d.source),
        el("td", { class: "num" }, String(d.runs)),
        el("td", { class: "num" }, `${d.width} × ${d.height}`),
        el("td", {}, when(d.created_at)));
    });
    clear($("#dataset-list"), rows.length ? rows : [el("tr", {}, el("td", { colspan: 6, class: "muted" }, "no dataset yet: upload one below, or run an experiment"))]);
  } catch (e) {
    clear($("#dataset-list"), el("tr", {}, el("td", { colspan: 6, class: "error" }, e.message)));
  }
}

$("#upload-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const files = [...$("#upload-files").files];
  const err = $("#upload-error");
  showError(err, null);
  if (!files.some((f) => f.name === "dataset.json")) {
    showError(err, "select dataset.json together with its TIFF frames");
    return;
  }
  const form = new FormData();
  // One part per file, named by its file name (what the API expects).
  for (const f of files) form.append(f.name, f, f.name);
  const total = files.reduce((a, f) => a + f.size, 0);
  $("#upload-status").textContent = `uploading ${files.length} files (${num(total / 1e6, 3)} MB)…`;
  $("#upload-btn").disabled = true;
  try {
    const record = await api("/datasets", { method: "POST", body: form });
    location.href = `/datasets/${record.id}`;
  } catch (e) {
    showError(err, e);
    $("#upload-status").textContent = "";
    $("#upload-btn").disabled = false;
  }
});

loadBench();
loadExperiments();
loadSweeps();
loadCalibrations();
loadDatasets();
// No snapshot here: on real hardware every snapshot is an acquisition, taken only on request.
setInterval(() => { loadBench(); loadExperiments(); loadCalibrations(); loadSweeps(); }, 4000);

