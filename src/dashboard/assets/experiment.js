// One experiment: live progress over SSE, then Figures 5 and 6, the study, maps and downloads.
import { api, el, $, clear, num, when, badge, setupToken, runPage, progressBar, inlineSvg, pageId, um, mm, TERMINAL, API, eventLog, downloadLink } from "./common.js";

setupToken();
const id = pageId();
const base = `/experiments/${encodeURIComponent(id)}`;
const bar = progressBar("progress");
$("#progress-slot").append(bar.node);
$("#run-id").textContent = id;
document.title = `ffdic — experiment ${id}`;
/** The bench scale, px/mm, from the dataset the run made (null until known). */
let scale = null;
let lastRecord = null;

/** The scale of the run's dataset; the record is shown again with moves in px once known. */
async function loadScale(r) {
  if (scale || !r.dataset_id) return;
  try {
    scale = (await api(`/datasets/${encodeURIComponent(r.dataset_id)}/details`)).scale_px_per_mm;
    if (lastRecord) showRecord(lastRecord);
  } catch (_) { /* moves stay in mm only */ }
}

function showRecord(r) {
  lastRecord = r;
  if (r.dataset_id && !scale) loadScale(r);
  clear($("#run-status"), badge(r.status));
  bar.set(r.progress, r.status);
  $("#run-message").textContent = r.message || "";
  const req = r.request || {};
  const schemes = (req.schemes || []).map((s) => (typeof s === "string" ? s : s.name));
  const patterns = (req.patterns || []).map((p) => (typeof p === "string" ? p : p.label));
  const dic = req.dic || {};
  clear($("#run-info"), [
    ["name", req.name || "—"],
    ["patterns", patterns.join(", ") || "—"],
    ["moves", (req.moves || []).map((m) => `${m.id} (${mm(m.dx_mm)}, ${mm(m.dy_mm)}) mm` +
      (scale ? ` = (${num(m.dx_mm * scale)}, ${num(m.dy_mm * scale)}) px` : "")).join("; ") || "—"],
    ["scale", scale ? `${num(scale)} px/mm (1 px = ${num(1000 / scale, 3)} µm)` : "—"],
    ["schemes", schemes.join(", ") || "—"],
    ["DIC", `subset ${dic.subset_px ?? "—"} px, step ${dic.step_px ?? "—"} px, strain window ${dic.strain_window ?? "—"}`],
    ["created", when(r.created_at)],
    ["started", when(r.started_at)],
    ["finished", when(r.finished_at)],
  ].flatMap(([k, v]) => [el("dt", {}, k), el("dd", {}, v)]));
  $("#cancel-btn").classList.toggle("hidden", TERMINAL.includes(r.status));
}

const onEvent = eventLog(bar, $("#run-message"), $("#events"));

const FIGURES = ["figure5_u", "figure5_exx", "figure6_v", "figure6_eyy"];

async function showResults(r) {
  $("#results").classList.remove("hidden");
  await Promise.all(FIGURES.map((f) =>
    inlineSvg($(`#${f}`), `${API}${base}/plots/${f}.svg`).catch((e) => clear($(`#${f}`), el("p", { class: "error" }, `${f}: ${e.message}`)))));

  // The study as a table.
  try {
    const study = await api(`${base}/results`);
    // Reduced-image px: a reduced pixel spans `block` sensor pixels, so µm = px · block / scale.
    const blockOf = (scheme) => {
      const s = (r.request && r.request.schemes || []).find((x) => (typeof x === "string" ? x : x.name) === scheme);
      return s && typeof s === "object" && s.x ? s.x.block : (scheme === "native" ? 1 : 2);
    };
    const stdUm = (row, k) => {
      const v = um(row[k].std * blockOf(row.scheme), scale);
      return v === null ? "" : ` (${num(v, 3)})`;
    };
    const head = ["pattern", "scheme", "captures", "valid points", "std u [px (µm)]", "std v [px (µm)]", "std εxx [µε]", "std εyy [µε]", "Δ std u [95 %]", "Δ std v [95 %]", "Δ std εxx"];
    const signed = (x) => `${x >= 0 ? "+" : ""}${x.toFixed(1)}`;
    // The increase, its paired-bootstrap interval when there is one, "n.s." when it holds 0.
    const inc = (row, k) => {
      if (!row.increase_pct) return "—";
      let text = `${signed(row.increase_pct[k])} %`;
      const ci = row.increase_ci95 && row.increase_ci95[k];
      if (ci && ci[0] !== null && ci[1] !== null) {
        text += ` [${signed(ci[0])}, ${signed(ci[1])}]`;
        if (ci[0] <= 0 && ci[1] >= 0) text += " n.s.";
      }
      return text;
    };
    // A std with its 95 % interval when the grid held enough blocks for one.
    const std = (row, k, factor = 1) => {
      const s = row[k];
      const ci = s.ci95;
      const text = num(s.std * factor);
      return ci && ci[0] !== null && ci[1] !== null ? `${text} [${num(ci[0] * factor, 3)}, ${num(ci[1] * factor, 3)}]` : text;
    };
    // Rows pooling several independent captures say so; absent means one capture.
    const captures = (row) => ((row.repeats || 1) > 1 ? `n = ${row.repeats} captures` : "1");
    clear($("#study-table"), el("table", {},
      el("thead", {}, el("tr", {}, head.map((h, i) => el("th", { class: i > 1 ? "num" : "" }, h)))),
      el("tbody", {}, study.rows.map((row) => el("tr", { "data-repeats": row.repeats || 1 },
        el("td", {}, row.pattern), el("td", {}, row.scheme),
        el("td", { class: "num" }, captures(row)),
        el("td", { class: "num" }, `${row.valid} / ${row.points}`),
        el("td", { class: "num" }, std(row, "u") + stdUm(row, "u")), el("td", { class: "num" }, std(row, "v") + stdUm(row, "v")),
        el("td", { class: "num" }, std(row, "exx", 1e6)), el("td", { class: "num" }, std(row, "eyy", 1e6)),
        el("td", { class: "num" }, inc(row, "u")), el("td", { class: "num" }, inc(row, "v")),
        el("td", { class: "num" }, inc(row, "exx")))))));
  } catch (e) {
    clear($("#study-table"), el("p", { class: "error" }, e.message));
  }

  // Maps: map_{pattern}_{scheme}_{field}.svg, chosen by pattern and scheme; every field the run
  // drew is shown, in this order.
  const FIELDS = ["u", "v", "exx", "eyy", "exy"];
  const maps = (r.result_files || [])
    .map((f) => /^plots\/map_(.+)_([^_]+)_(u|v|exx|eyy|exy)\.svg$/.exec(f))
    .filter(Boolean)
    .map((m) => ({ file: m[0].slice("plots/".length), pattern: m[1], scheme: m[2], field: m[3] }));
  const patterns = [...new Set(maps.map((m) => m.pattern))];
  const schemes = [...new Set(maps.map((m) => m.scheme))];
  if (!maps.length) {
    clear($("#maps"), el("p", { class: "muted" }, "this run has no maps"));
  } else {
    const pick = (name, values) => el("label", {}, name,
      el("select", { id: `map-${name}` }, values.map((v) => el("option", { value: v }, v))));
    clear($("#map-pickers"), pick("pattern", patterns), pick("scheme", schemes));
    const draw = async () => {
      const [p, s] = [$("#map-pattern").value, $("#map-scheme").value];
      const chosen = FIELDS.map((f) => maps.find((m) => m.pattern === p && m.scheme === s && m.field === f)).filter(Boolean);
      const boxes = chosen.map((m) => el("div", { class: "figure map", "data-field": m.field }));
      clear($("#maps"), boxes);
      await Promise.all(chosen.map((m, i) => inlineSvg(boxes[i], `${API}${base}/plots/${m.file}`)));
    };
    $("#map-pattern").addEventListener("change", draw);
    $("#map-scheme").addEventListener("change", draw);
    await draw();
  }

  // Downloads.
  const frames = (r.result_files || []).filter((f) => f.startsWith("frames/")).map((f) => f.slice(7));
  // The run names the dataset its frames became (runs stored before that field: look it up).
  const ds = r.dataset_id
    ? { id: r.dataset_id }
    : (await api("/datasets?limit=1000").catch(() => [])).find((d) => d.source === `experiment:${id}`);
  clear($("#downloads"),
    el("ul", { class: "links" },
      downloadLink(`${API}${base}/results.csv`, "study.csv (CSV)"),
      downloadLink(`${API}${base}/results`, "study.json (JSON)"),
      FIGURES.map((f) => downloadLink(`${API}${base}/plots/${f}.svg`, `${f}.svg`))),
    el("h3", {}, `Frames (16-bit TIFF) and manifest`),
    el("ul", { class: "links" }, frames.map((f) => downloadLink(`${API}${base}/frames/${encodeURIComponent(f)}`, f))),
    ds ? el("p", {}, "The frames are also dataset ", el("a", { href: `/datasets/${ds.id}` }, ds.id), ": compare them with a model and diagnose there.") : null);
  $("#results").dataset.loaded = "true";
}

runPage({
  recordUrl: base,
  eventsUrl: `${base}/events`,
  cancelUrl: `${base}/cancel`,
  what: "the experiment",
  showRecord,
  onEvent,
  showResults,
});
