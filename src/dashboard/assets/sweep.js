// One design map (a sweep): live progress over SSE, then the recommendations, the heat maps with
// the paper's points, the bias plots and every cell with its 95 % interval.
import { api, el, $, clear, num, when, badge, showError, setupToken, runPage, progressBar, inlineSvg, pageId, TERMINAL, API, eventLog, downloadLink, table } from "./common.js";

setupToken();
const id = pageId();
const base = `/sweeps/${encodeURIComponent(id)}`;
const bar = progressBar("progress");
$("#progress-slot").append(bar.node);
$("#run-id").textContent = id;
document.title = `ffdic — design map ${id}`;

function axisText(values) {
  return values && values.length ? values.join(", ") : "—";
}

function showRecord(r) {
  clear($("#run-status"), badge(r.status));
  bar.set(r.progress, r.status);
  $("#run-message").textContent = r.message || "";
  const spec = r.request || {};
  const axes = spec.axes || {};
  const cam = spec.camera || {};
  const dic = spec.dic || {};
  const schemes = (axes.schemes || []).map((s) => (typeof s === "string" ? s : s.name));
  const noise = (axes.noise || []).map((n) => `${n.full_well_e} e⁻ / ${n.read_noise_e} e⁻`);
  clear($("#run-info"), [
    ["name", spec.name || "—"],
    ["sensor", cam.width ? `${cam.width} × ${cam.height} px at ${cam.scale_px_per_mm} px/mm` : "—"],
    ["model", spec.model || "none (an ideal bench)"],
    ["move", spec.move_mm ? `(${spec.move_mm.join(", ")}) mm` : "0"],
    ["dot diameters [reduced px]", axisText(axes.dot_diameter_px)],
    ["patterns", axisText(axes.patterns)],
    ["schemes", axisText(schemes)],
    ["noise", noise.length ? noise.join("; ") : "none"],
    ["PSF σ [px]", axisText(axes.psf_sigma_px)],
    ["sub-pixel x / y [px]", `${axisText(axes.subpixel_x)} / ${axisText(axes.subpixel_y)}`],
    ["realisations", String(spec.seeds ?? "—")],
    ["DIC", `subset ${dic.subset_px ?? "41"} px, step ${dic.step_px ?? "20"} px, strain window ${dic.strain_window ?? "7"}`],
    ["created", when(r.created_at)],
    ["finished", when(r.finished_at)],
  ].flatMap(([k, v]) => [el("dt", {}, k), el("dd", {}, v)]));
  $("#cancel-btn").classList.toggle("hidden", TERMINAL.includes(r.status));
}

const onEvent = eventLog(bar, $("#run-message"), $("#events"));

/** "0.00123 [0.00118, 0.00129]": a mean with its 95 % interval. */
function withInterval(s) {
  if (!s) return "—";
  return `${num(s.mean, 3)} [${num(s.lo, 3)}, ${num(s.hi, 3)}]`;
}

const STATS = [["u_std_px", "std u"], ["v_std_px", "std v"], ["exx_std", "std εxx"]];

async function showHeatmaps(figures, stat) {
  const names = figures.filter((f) => f.startsWith(`map_${stat}_`));
  const slots = names.map((f) => el("div", { class: "figure", "data-figure": f }));
  clear($("#heatmaps"), slots);
  await Promise.all(names.map((f, i) => inlineSvg(slots[i], `${API}${base}/plots/${f}`)
    .catch((e) => clear(slots[i], el("p", { class: "error" }, `${f}: ${e.message}`)))));
}

async function showResults() {
  $("#results").classList.remove("hidden");
  let map;
  try {
    map = await api(`${base}/map`);
  } catch (e) {
    showError($("#run-error"), e);
    return;
  }
  clear($("#recommendations"), table(
    ["scheme", "fill x × y", "conditions", "prints within 10 %", "best", "best std u [px, 95 %]"],
    map.recommendations.map((r) => [r.scheme, `${num(r.fill_x, 2)} × ${num(r.fill_y, 2)}`, r.conditions,
      r.within_10_percent.join(", "), r.best_print, withInterval(r.best_u_std_px)])));

  let stat = STATS[0][0];
  const pickers = STATS.map(([key, label]) => el("button", {
    type: "button", class: key === stat ? "" : "secondary", "data-stat": key,
    onclick: async () => {
      stat = key;
      for (const b of pickers) b.className = b.dataset.stat === stat ? "" : "secondary";
      await showHeatmaps(map.figures, stat);
    },
  }, label));
  clear($("#stat-pickers"), pickers);
  await showHeatmaps(map.figures, stat);

  const bias = map.figures.filter((f) => f.startsWith("bias_"));
  $("#bias-title").classList.toggle("hidden", bias.length === 0);
  const biasSlots = bias.map((f) => el("div", { class: "figure", "data-figure": f }));
  clear($("#bias"), biasSlots);
  await Promise.all(bias.map((f, i) => inlineSvg(biasSlots[i], `${API}${base}/plots/${f}`).catch(() => {})));

  clear($("#cells"), table(
    ["print", "scheme", "noise", "PSF σ", "sub-pixel", "n", "std u [px]", "std v [px]", "bias u [px]", "bias v [px]", "std εxx", "valid"],
    map.cells.map((c) => [c.print, c.scheme,
      c.noise ? `${c.noise.full_well_e} / ${c.noise.read_noise_e} e⁻` : "model",
      String(c.psf_sigma_px), `(${c.subpixel_px.join(", ")})`, String(c.n),
      withInterval(c.stats.u_std_px), withInterval(c.stats.v_std_px),
      withInterval(c.stats.u_bias_px), withInterval(c.stats.v_bias_px),
      withInterval(c.stats.exx_std), num(c.stats.valid_fraction.mean, 3)])));

  clear($("#downloads"), el("ul", { class: "links" },
    downloadLink(`${API}${base}/map.csv`, "map.csv (one row per cell, means and 95 % bounds)"),
    downloadLink(`${API}${base}/map`, "map.json"),
    map.figures.map((f) => downloadLink(`${API}${base}/plots/${f}`, f))));
  $("#results").dataset.loaded = "true";
}

runPage({
  recordUrl: base,
  eventsUrl: `/jobs/${encodeURIComponent(id)}/events`,
  cancelUrl: `/jobs/${encodeURIComponent(id)}/cancel`,
  what: "the sweep",
  showRecord,
  onEvent,
  showResults,
});
