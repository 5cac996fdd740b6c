// One dataset: compare it with a model, diagnose the missing effect, add the winner as a new
// model version, and watch the discrepancy fall in the history chart.
import { api, apiText, el, $, clear, num, when, badge, showError, setupToken, follow, progressBar, inlineSvg, pageId, pxUm, plusMinus, lengthPm, valuePm, um, mm, API, ApiError } from "./common.js";
import { historySvg } from "./charts.js";

setupToken();
const id = pageId();
const base = `/datasets/${encodeURIComponent(id)}`;
$("#dataset-id").textContent = id;
document.title = `ffdic — dataset ${id}`;
$("#history-svg-link").href = `${API}${base}/history.svg`;
let models = [];
let busy = false;
/** The dataset's scale, px/mm (from its manifest): µm beside every px. */
let scale = null;

const NATIVE = { name: "native", x: { block: 1, first: 0, active: 1 }, y: { block: 1, first: 0, active: 1 } };

/** The analysis settings of the form, as the comparison and diagnosis requests take them. */
function settings(model) {
  const f = $("#model-form");
  const schemes = [...f.querySelectorAll("input[name=scheme]:checked")].map((i) => (i.value === "native" ? NATIVE : i.value));
  const body = { model };
  if (schemes.length) body.schemes = schemes;
  body.dic = {
    subset_px: Number(f.subset_px.value),
    step_px: Number(f.step_px.value),
    strain_window: Number(f.strain_window.value),
    prefilter_sigma_px: Number(f.prefilter_sigma_px.value),
  };
  return body;
}

async function loadDataset() {
  try {
    const [d, details] = await Promise.all([api(base), api(`${base}/details`).catch(() => null)]);
    $("#dataset-name").textContent = d.name;
    const m = /^experiment:(.+)$/.exec(d.source || "");
    const frames = d.files.filter((f) => /\.(tiff?|png|bmp)$/i.test(f));
    scale = details ? details.scale_px_per_mm : null;
    const runs = details ? details.runs.map((r) => el("li", { "data-run": r.id },
      el("span", { class: "mono" }, r.id),
      r.pattern ? ` pattern ${r.pattern}: ` : ": ",
      `move (${mm(r.dx_mm)}, ${mm(r.dy_mm)}) mm = (${num(r.dx_px)}, ${num(r.dy_px)}) px`,
      r.static_repeats ? `, ${r.static_repeats} static repeat${r.static_repeats > 1 ? "s" : ""}` : "")) : [];
    clear($("#dataset-info"), [
      ["name", d.name],
      ["source", m ? el("a", { href: `/experiments/${m[1]}` }, `experiment ${m[1]}`) : d.source],
      ["scale", details ? `${num(details.scale_px_per_mm)} px/mm (1 px = ${num(1000 / details.scale_px_per_mm, 3)} µm)` : "—"],
      ["frames", `${frames.length}, ${d.width} × ${d.height} px${details && details.bit_depth ? `, ${details.bit_depth} bit` : ""}`],
      ["stage repeatability", details && details.stage_repeatability_um != null ? `${num(details.stage_repeatability_um)} µm (1σ)` : "—"],
      ["runs", runs.length ? el("ol", { class: "runs" }, runs) : String(d.runs)],
      ["created", when(d.created_at)],
      ["files", el("span", { class: "mono small" }, d.files.join(", "))],
    ].flatMap(([k, v]) => [el("dt", {}, k), el("dd", {}, v)]));
  } catch (e) {
    showError($("#dataset-error"), e);
  }
}

/** The dataset's comparisons and diagnoses, newest first, each reopenable. */
async function loadJobs() {
  try {
    const jobs = await api(`${base}/jobs`);
    const headline = (j) => {
      if ((j.kind === "diagnosis" || j.kind === "on_bench") && j.verdicts.length) {
        return `${j.verdicts.join(", ")} — ${pxUm(j.discrepancy_px, scale)}` +
          (j.final_discrepancy_px != null ? ` → ${pxUm(j.final_discrepancy_px, scale)}` : "");
      }
      return j.discrepancy_px != null ? pxUm(j.discrepancy_px, scale) : "—";
    };
    const rows = jobs.map((j) => el("tr", { "data-kind": j.kind, "data-id": j.id },
      el("td", {}, when(j.created_at)),
      el("td", {}, j.kind),
      el("td", { class: "mono" }, j.model || "—"),
      el("td", {}, badge(j.status)),
      el("td", { class: "num" }, headline(j)),
      el("td", {}, j.status === "succeeded" && j.kind !== "analysis"
        ? el("a", {
          class: "open", href: jobUrl(j.id),
          onclick: (ev) => { ev.preventDefault(); guard(() => reopen(j)); },
        }, "open")
        : el("span", { class: "muted small" }, j.message || ""))));
    clear($("#job-list"), rows.length ? rows : [el("tr", {}, el("td", { colspan: 6, class: "muted" }, "nothing yet: compare or diagnose above"))]);
  } catch (e) {
    clear($("#job-list"), el("tr", {}, el("td", { colspan: 6, class: "error" }, e.message)));
  }
}

/** The page of this dataset showing job `jobId`'s result: a URL to bookmark or paste. */
function jobUrl(jobId) {
  return `${location.pathname}?job=${encodeURIComponent(jobId)}`;
}

/** The address bar and the section's link name the job shown. */
function showJobUrl(link, jobId) {
  history.replaceState(null, "", jobUrl(jobId));
  link.href = jobUrl(jobId);
  link.dataset.job = jobId;
}

/** Shows a listed job's results again, as when it had just run. */
async function reopen(j) {
  const job = await api(`/jobs/${j.id}`);
  if (j.kind === "comparison") {
    await showComparison(job);
    $("#comparison").scrollIntoView({ block: "start" });
  } else {
    await showDiagnosis(job, { ...(job.request || {}) });
    if (j.kind === "on_bench") await showOnBench(job);
    $("#diagnosis").scrollIntoView({ block: "start" });
  }
}

async function loadModels(select) {
  models = await api("/models");
  const sel = $("#model");
  const keep = select || sel.value || "baseline";
  clear(sel, models.map((m) => el("option", { value: m.name }, `${m.name} (${m.source}${m.effects.length ? ": " + m.effects.join(", ") : ""})`)));
  if (models.some((m) => m.name === keep)) sel.value = keep;
  describeModel();
}

function describeModel() {
  const m = models.find((x) => x.name === $("#model").value);
  $("#model-description").textContent = m ? `${m.description} — version ${m.version}` : "";
}
$("#model").addEventListener("change", describeModel);

async function loadHistory() {
  try {
    const h = await api(`${base}/history`);
    const entries = h.entries || [];
    const box = $("#history");
    clear(box, historySvg(entries, `Discrepancy of dataset ${id} against its models`));
    box.dataset.points = String(entries.length);
    return entries;
  } catch (e) {
    clear($("#history"), el("p", { class: "error" }, e.message));
    return [];
  }
}

/** Submits a comparison or diagnosis job and follows it to its end; returns the final record. */
async function runJob(kind, body) {
  const bar = progressBar("job-progress");
  clear($("#job-slot"), bar.node);
  showError($("#job-error"), null);
  $("#job-message").textContent = `${kind} queued…`;
  const job = await api(`${base}/${kind}`, { method: "POST", body });
  const path = `/jobs/${job.id}`;
  const final = await follow(path, `${path}/events`, (e) => {
    bar.set(e.progress);
    if (e.message) $("#job-message").textContent = e.message;
  }, (r) => bar.set(r.progress, r.status));
  bar.set(final.progress, final.status);
  $("#job-message").textContent = final.message || final.status;
  if (final.status !== "succeeded") throw new Error(`${kind} ${final.status}: ${final.message || ""}`);
  return final;
}

/** The comparison shown: its runs and schemes fill the figure picker. */
let lastComparison = null;

async function showComparison(job) {
  const cmp = await api(`/jobs/${job.id}/files/results/comparison.json`);
  lastComparison = cmp;
  showJobUrl($("#comparison-link"), job.id);
  $("#comparison").classList.remove("hidden");
  $("#comparison-model").textContent = `${cmp.model.name} (version ${cmp.model.version})`;
  const part = (k) => lengthUm(cmp.parts && cmp.parts[k], cmp.parts_se && cmp.parts_se[k]);
  clear($("#comparison-summary"), [
    ["discrepancy", el("strong", { id: "comparison-discrepancy", "data-discrepancy": cmp.discrepancy_px }, lengthUm(cmp.discrepancy_px, cmp.discrepancy_se_px))],
    ["rigid (stage landing, bias)", part("rigid_px")],
    ["systematic (field)", part("field_px")],
    ["random (std)", part("std_px")],
    ["model effects", (cmp.model.effects && (Array.isArray(cmp.model.effects) ? cmp.model.effects : Object.keys(cmp.model.effects)).join(", ")) || "—"],
  ].flatMap(([k, v]) => [el("dt", {}, k), el("dd", {}, v)]));
  const runs = [...(cmp.runs || [])].sort((a, b) => b.discrepancy_px - a.discrepancy_px);
  clear($("#comparison-runs"), el("table", {},
    el("thead", {}, el("tr", {}, ["run", "scheme", "discrepancy", "rigid", "field", "std", "mean Δu", "mean Δv"].map((h, i) => el("th", { class: i > 1 ? "num" : "" }, i > 1 ? `${h} [px]` : h)))),
    el("tbody", {}, runs.map((r) => el("tr", {},
      el("td", {}, r.id), el("td", {}, r.scheme),
      el("td", { class: "num" }, lengthPm(r.discrepancy_px, r.discrepancy_se_px)),
      el("td", { class: "num" }, lengthPm(r.rigid_px, r.rigid_se_px)),
      el("td", { class: "num" }, lengthPm(r.field_px, r.field_se_px)),
      el("td", { class: "num" }, lengthPm(r.std_px, r.std_se_px)),
      el("td", { class: "num" }, plusMinus(r.mean_diff_px && r.mean_diff_px[0], r.mean_diff_se_px && r.mean_diff_se_px[0])),
      el("td", { class: "num" }, plusMinus(r.mean_diff_px && r.mean_diff_px[1], r.mean_diff_se_px && r.mean_diff_se_px[1])))))),
    el("p", { class: "small muted" }, "± one standard error from the noise of both analyses; < x: below its noise (debiased to zero), x twice its standard error."));
  showAccuracy(cmp);
  await showPlots(job, $("#comparison-plots"));
}

/** "0.00202 ± 0.00004 px (0.155 µm)": a length, its error and its size on the target. */
function lengthUm(px, se) {
  const u = um(px, scale);
  return `${lengthPm(px, se)} px${u === null || !(px > 0) ? "" : ` (${num(u, 3)} µm)`}`;
}

/** The measured side against the commanded move, in the order of the commanded moves. */
function showAccuracy(cmp) {
  const runs = [...(cmp.runs || [])].filter((r) => r.accuracy)
    .sort((a, b) => Math.hypot(...a.accuracy.commanded_px) - Math.hypot(...b.accuracy.commanded_px));
  const pm = plusMinus;
  clear($("#comparison-accuracy"), runs.length ? el("table", { id: "accuracy-table" },
    el("thead", {}, el("tr", {}, ["run", "scheme", "commanded u, v [px]", "bias u [px]", "bias v [px]", "std u, v [px]", "bias [µm]", "std [µm]"]
      .map((h, i) => el("th", { class: i > 1 ? "num" : "" }, h)))),
    el("tbody", {}, runs.map((r) => {
      const a = r.accuracy;
      return el("tr", { "data-run": r.id },
        el("td", {}, r.id), el("td", {}, r.scheme),
        el("td", { class: "num" }, `${num(a.commanded_px[0])}, ${num(a.commanded_px[1])}`),
        el("td", { class: "num" }, pm(a.bias_px[0], a.bias_se_px[0])),
        el("td", { class: "num" }, pm(a.bias_px[1], a.bias_se_px[1])),
        el("td", { class: "num" }, `${num(a.std_px[0], 3)}, ${num(a.std_px[1], 3)}`),
        el("td", { class: "num" }, `${num(a.bias_um[0], 3)}, ${num(a.bias_um[1], 3)}`),
        el("td", { class: "num" }, `${num(a.std_um[0], 3)}, ${num(a.std_um[1], 3)}`));
    }))) : el("p", { class: "muted" }, "no run with a commanded move"));
}

/** Figures every view of the picker keeps: the summary that leads, and the accuracy. */
const ALWAYS_SHOWN = ["summary.svg", "accuracy_vs_commanded.svg"];

/** A file-name-safe run or scheme, as the plots' names hold it (report/comparison_figures.rs). */
const fileSafe = (t) => String(t).replace(/[^A-Za-z0-9_-]/g, "_");

/** Whether figure `name` belongs to the picker's choice ("", "run:ID", "scheme:S", "images"). */
function picked(name, choice) {
  if (!choice || ALWAYS_SHOWN.includes(name)) return true;
  const [kind, value] = choice.split(/:(.*)/s);
  if (kind === "images") return /^(spectrum|noise_vs_mean|mean_map)_/.test(name);
  if (kind === "run") return name.startsWith(`residual_${fileSafe(value)}_`);
  if (kind === "scheme") return new RegExp(`_${fileSafe(value)}(_[uv])?\\.svg$`).test(name);
  return true;
}

async function showPlots(job, container) {
  const files = (job.result_files || []).filter((f) => f.startsWith("plots/") && f.endsWith(".svg"));
  // The summary leads; the rest keep the order the job wrote them.
  const plots = [...files.filter((f) => f === "plots/summary.svg"), ...files.filter((f) => f !== "plots/summary.svg")];
  const boxes = plots.map((p) => el("div", { class: "figure", "data-plot": p.slice(6) }));
  const cmpRuns = lastComparison ? lastComparison.runs || [] : [];
  const picker = el("select", { id: "plot-picker", "aria-label": "which figures to show" },
    el("option", { value: "" }, `all ${boxes.length} figures`),
    ...[...new Set(cmpRuns.map((r) => r.id))].map((r) => el("option", { value: `run:${r}` }, `run ${r}`)),
    ...[...new Set(cmpRuns.map((r) => r.scheme))].map((sc) => el("option", { value: `scheme:${sc}` }, `scheme ${sc}`)),
    el("option", { value: "images" }, "image statistics"));
  picker.addEventListener("change", () => {
    for (const b of boxes) b.classList.toggle("hidden", !picked(b.dataset.plot, picker.value));
  });
  const bar = el("p", { class: "small" }, "Show: ", picker);
  clear(container, boxes.length ? [bar, ...boxes] : [el("p", { class: "muted" }, "no plots")]);
  await Promise.all(plots.map((p, i) => inlineSvg(boxes[i], `${API}/jobs/${job.id}/files/plots/${encodeURIComponent(p.slice(6))}`)
    .catch((e) => clear(boxes[i], el("p", { class: "error" }, e.message)))));
}

function paramText(c) {
  const keys = Object.keys(c.params || {});
  if (!keys.length) return "—";
  return keys.map((k) => {
    return `${k} = ${valuePm(c.params[k], c.stderr && c.stderr[k])}`;
  }).join("; ");
}

let lastDiagnosis = null;

// What the final model leaves unexplained (issue 32): never a silent "none" over a residual.
function showUnexplained(d) {
  const left = d.final_unexplained || d.unexplained_after || d.unexplained;
  const box = $("#unexplained");
  if (!left) { clear(box, []); return; }
  box.dataset.significant = String(left.significant);
  const items = [el("h3", {}, left.significant ? "Left unexplained" : "Nothing significant left")];
  items.push(el("p", { class: "small" }, left.summary));
  if (d.withheld) items.push(el("p", { class: "small" }, `Not named: ${d.withheld.reason}`));
  if (d.partial) items.push(el("p", { class: "small" }, `The verdict is partial: it explains ${Math.round(100 * (d.explained_fraction || 0))} % of the model's unexplained low-order field.`));
  clear(box, items);
}

async function showDiagnosis(job, body) {
  const d = await api(`/jobs/${job.id}/files/results/diagnosis.json`);
  showJobUrl($("#diagnosis-link"), job.id);
  lastDiagnosis = { job, d, body };
  $("#diagnosis").classList.remove("hidden");
  $("#diagnosis-model").textContent = `${d.model.name} (version ${d.model.version}), discrepancy ${lengthUm(d.discrepancy_px, d.discrepancy_se_px)}`;
  const v = $("#diagnosis-verdict");
  v.dataset.verdict = d.verdict;
  v.className = `verdict ${d.verdict !== "none" ? "found" : ""}`;
  v.textContent = d.verdict !== "none"
    ? `Verdict: ${d.verdict} — the model lacks it`
    : "Verdict: none — no candidate explains the discrepancy beyond its noise";
  const rounds = (d.rounds || []).length > 1 ? d.rounds : [];
  clear($("#diagnosis-rounds"), rounds.map((r) => el("li", { "data-verdict": r.verdict },
    `${r.model}: ${lengthUm(r.discrepancy_px, r.discrepancy_se_px)} → ${r.verdict}` +
    (r.after_px != null ? ` → ${pxUm(r.after_px, scale)}` : ""))));
  if ((d.verdicts || []).length > 1) {
    v.textContent = `Found, in order: ${d.verdicts.join(", ")} — discrepancy ${pxUm(d.discrepancy_px, scale)} → ${pxUm(d.final_discrepancy_px, scale)}`;
  }
  clear($("#candidates"), el("table", { id: "candidate-table" },
    el("thead", {}, el("tr", {}, ["#", "effect", "fitted parameters ± standard error", "discrepancy with it [px (µm)]", "drop [px] ± SE", "ΔBIC", "significant"].map((h, i) => el("th", { class: i >= 3 && i <= 5 ? "num" : "" }, h)))),
    el("tbody", {}, d.candidates.map((c, i) => el("tr", { class: c.effect === d.verdict ? "winner" : "", "data-effect": c.effect },
      el("td", {}, String(i + 1)), el("td", {}, c.effect), el("td", { class: "small" }, paramText(c)),
      el("td", { class: "num" }, pxUm(c.discrepancy_px, scale)), el("td", { class: "num" }, plusMinus(c.drop_px, c.criteria && c.criteria.drop_se_px)),
      el("td", { class: "num" }, num(c.delta_bic, 5)), el("td", {}, c.significant ? "yes" : "no"))))));
  const notes = [];
  for (const c of d.confounded || []) {
    notes.push(el("li", {}, `${c.effects.join(" and ")} are confounded (${c.evidence}): separate them with ${c.separate_with}`));
  }
  for (const n of d.not_identifiable || []) {
    notes.push(el("li", {}, `${n.effect} cannot be identified from this dataset: ${n.reason}; add ${n.runs_to_add}`));
  }
  clear($("#identifiability"), notes.length ? [el("h3", {}, "What this dataset cannot tell apart"), el("ul", {}, notes)] : []);
  const runs = d.runs_to_separate || [];
  $("#on-bench").classList.toggle("hidden", !runs.length);
  $("#on-bench-btn").textContent = `Resolve on the bench: capture ${runs.map((r) => SEPARATING_RUNS[r] || r).join(", ")}`;
  $("#on-bench-btn").dataset.runs = runs.join(" ");
  clear($("#on-bench-result"), []);
  $("#on-bench-notice").textContent = "";
  showUnexplained(d);
  const add = $("#add-winner");
  const hasWinner = d.verdict !== "none" && (job.result_files || []).includes("results/winner-model.toml");
  add.classList.toggle("hidden", !hasWinner);
  add.disabled = false;
  add.textContent = (d.verdicts || []).length > 1
    ? `Add ${d.verdicts.join(" + ")} as a new model version`
    : `Add ${d.verdict} as a new model version`;
  $("#add-notice").textContent = "";
}

/** The kinds of runs a bench captures to separate effects, in words (diagnose/separating_runs.rs). */
const SEPARATING_RUNS = {
  several_move_sizes: "moves of several sizes",
  both_axes: "moves along x and along y",
  step_series: "a sub-pixel step series",
  static_repeats: "static repeat frames",
};

/** What a diagnosis left open, as the on-bench document holds it: one line each. */
function openLines(open) {
  if (!open) return [];
  return [
    ...(open.confounded || []).map((c) => `${c.effects.join(" and ")} confounded (${c.evidence})`),
    ...(open.not_identifiable || []).map((n) => `${n.effect} not identifiable`),
  ];
}

/** An on-bench job's capture and the ambiguity before and after it. */
async function showOnBench(job) {
  const doc = await api(`/jobs/${job.id}/files/results/on-bench.json`);
  $("#on-bench").classList.remove("hidden");
  const b = doc.bench || {};
  const box = $("#on-bench-result");
  if (!b.dataset) {
    clear(box, el("p", { class: "muted" }, job.message || "nothing captured"));
    return;
  }
  const [before, after] = [openLines(doc.open_before), openLines(doc.open_after)];
  const verdicts = (r) => (r && r.verdicts && r.verdicts.length ? r.verdicts.join(", ") : "none");
  const plan = b.plan || {};
  const moves = (plan.moves || []).map((m) => `(${num(m.dx_mm, 3)}, ${num(m.dy_mm, 3)})`).join(" ") || "none";
  const steps = (plan.step_series || []).reduce((n, st) => n + st.count, 0);
  const pairs = ((b.design || {}).pairs || []).map((p) => el("li", { "data-pair": p.effects.join(" ") },
    `${p.effects.join(" and ")}: their fields' correlation ${num(p.correlation_before, 3)} with the dataset's moves, ${num(p.correlation_after, 3)} with the bench's`));
  const rows = [...new Set([...before, ...after])].map((line) => el("tr", { "data-open": line },
    el("td", {}, line),
    el("td", {}, before.includes(line) ? "open" : "—"),
    el("td", { class: after.includes(line) ? "" : "resolved" }, after.includes(line) ? "open" : "resolved")));
  clear(box, [
    el("h3", {}, "On the bench"),
    el("p", { class: "small" }, `Captured ${(b.runs || []).map((r) => SEPARATING_RUNS[r] || r).join(", ")}: moves (x, y) ${moves} mm, ${steps} phase-scan steps, ${plan.static_frames || 0} static frames. The dataset with them: `,
      el("a", { href: `/datasets/${encodeURIComponent(b.dataset)}`, class: "mono", id: "on-bench-dataset" }, b.dataset), "."),
    pairs.length ? el("ul", { class: "small", id: "on-bench-design" }, pairs) : null,
    el("table", { id: "on-bench-table" },
      el("thead", {}, el("tr", {}, ["what the dataset left open", "before", "with the bench's runs"].map((h) => el("th", {}, h)))),
      el("tbody", {}, rows.length ? rows : [el("tr", {}, el("td", { colspan: 3, class: "muted" }, "nothing was open"))])),
    el("p", { class: "small", id: "on-bench-verdicts" }, `Verdicts: ${verdicts(doc.before)} → ${verdicts(doc.after)}; discrepancy ${lengthUm(doc.before.discrepancy_px, doc.before.discrepancy_se_px)} → ${doc.after ? lengthUm(doc.after.discrepancy_px, doc.after.discrepancy_se_px) : "—"} against ${doc.before.model.name}.`),
  ]);
}

/** The buttons that start work: one job at a time. */
const BUTTONS = ["#compare-btn", "#diagnose-btn", "#find-all-btn", "#add-winner", "#user-effect-btn", "#on-bench-btn"];

async function guard(fn) {
  if (busy) return;
  busy = true;
  for (const b of BUTTONS) $(b).disabled = true;
  try {
    await fn();
  } catch (e) {
    showError($("#job-error"), e);
  } finally {
    busy = false;
    for (const b of BUTTONS) $(b).disabled = false;
  }
}

$("#compare-btn").addEventListener("click", () => guard(async () => {
  const job = await runJob("comparisons", settings($("#model").value));
  await showComparison(job);
  await loadHistory();
  await loadJobs();
}));

$("#find-all-btn").addEventListener("click", () => guard(async () => {
  const body = { ...settings($("#model").value), rounds: 4 };
  const job = await runJob("diagnoses", body);
  await showDiagnosis(job, body);
  await loadHistory();
  await loadJobs();
}));

$("#on-bench-btn").addEventListener("click", () => guard(async () => {
  const body = lastDiagnosis ? lastDiagnosis.body : settings($("#model").value);
  $("#on-bench-notice").textContent = "diagnosing, capturing on the bench, diagnosing again…";
  const job = await runJob("on-bench", body);
  await showDiagnosis(job, body);
  await showOnBench(job);
  await loadHistory();
  await loadJobs();
}));

$("#diagnose-btn").addEventListener("click", () => guard(async () => {
  const body = settings($("#model").value);
  const job = await runJob("diagnoses", body);
  await showDiagnosis(job, body);
  await loadHistory();
  await loadJobs();
}));

/** The winner's TOML under another `name` (its first `name = "…"` line). */
function renamed(toml, name) {
  return toml.replace(/^(\s*name\s*=\s*)"[^"]*"/m, `$1"${name}"`);
}

/** Most fresh names tried when the winner's name, and then the derived ones, hold other models. */
const FRESH_NAMES = 5;

/**
 * Stores the diagnosis's winner. A model name is a version for good, so when the name holds
 * another model (fitted on another dataset: 409) the winner is stored under a fresh name, the
 * name with this dataset's id (then .2, .3…), and the page says so. Never reports another model
 * as added; any other error is shown and nothing is compared.
 */
async function addWinner(toml) {
  const m = /^\s*name\s*=\s*"([^"]+)"/m.exec(toml);
  if (!m) throw new Error("the winner model has no name");
  const wanted = m[1];
  const names = [wanted, `${wanted}.${id}`, ...Array.from({ length: FRESH_NAMES - 1 }, (_, k) => `${wanted}.${id}.${k + 2}`)];
  for (const name of names) {
    try {
      const added = await api("/models", { method: "POST", body: { toml: name === wanted ? toml : renamed(toml, name) } });
      return { added, wanted };
    } catch (e) {
      if (!(e instanceof ApiError && e.status === 409)) throw e;
      // The name holds another model (or is an embedded one): try the next.
    }
  }
  throw new Error(`the names ${names.join(", ")} all hold other models: nothing was added`);
}

$("#add-winner").addEventListener("click", () => guard(async () => {
  if (!lastDiagnosis) return;
  const { job, body } = lastDiagnosis;
  const toml = await apiText(`/jobs/${job.id}/files/results/winner-model.toml`);
  $("#add-notice").textContent = "adding…";
  let added, wanted;
  try {
    ({ added, wanted } = await addWinner(toml));
  } catch (e) {
    $("#add-notice").textContent = "";
    throw e;
  }
  const name = added.name;
  const what = name === wanted
    ? `model ${name} (version ${added.version})`
    : `a different model named ${wanted} is stored already (fitted on another dataset); this dataset's winner is model ${name}`;
  $("#add-notice").textContent = `${what}; comparing…`;
  await loadModels(name);
  const cmp = await runJob("comparisons", { ...body, model: name });
  await showComparison(cmp);
  const entries = await loadHistory();
  await loadJobs();
  const last = entries[entries.length - 1];
  $("#add-notice").textContent = `${what} added: discrepancy now ${last ? pxUm(last.discrepancy_px, scale) : "—"}`;
  $("#add-winner").classList.add("hidden");
}));

/**
 * The user effect of the form as a TOML table (`[effects.user.NAME]`, values left to the fit);
 * throws naming what is wrong with a parameter line. TOML basic strings take JSON's escapes.
 */
function userEffectToml(form) {
  const name = form.effect.value.trim();
  if (!/^[A-Za-z][A-Za-z0-9_]*$/.test(name)) throw new Error(`effect name '${name}': letters, digits and _, starting with a letter`);
  const lines = [`[effects.user.${name}]`];
  for (const key of ["u", "v", "intensity"]) {
    const text = form[key].value.trim();
    if (text) lines.push(`${key} = ${JSON.stringify(text)}`);
  }
  const params = form.params.value.split("\n").map((l) => l.trim()).filter((l) => l);
  if (!params.length) throw new Error("at least one parameter: name min max [unit]");
  for (const line of params) {
    const [p, lo, hi, ...unit] = line.split(/\s+/);
    const min = Number(lo), max = Number(hi);
    if (!p || !Number.isFinite(min) || !Number.isFinite(max)) throw new Error(`parameter line '${line}': name min max [unit]`);
    lines.push(`[effects.user.${name}.params.${p}]`, `min = ${min}`, `max = ${max}`);
    if (unit.length) lines.push(`unit = ${JSON.stringify(unit.join(" "))}`);
  }
  return { name, table: lines.join("\n") + "\n" };
}

$("#user-effect-btn").addEventListener("click", () => guard(async () => {
  const notice = $("#user-effect-notice");
  const base = $("#model").value;
  const { name, table } = userEffectToml($("#user-effect-form"));
  notice.textContent = "adding…";
  const detail = await api(`/models/${encodeURIComponent(base)}`);
  const toml = `${renamed(detail.toml, `${base}+${name}`)}\n${table}`;
  let added;
  try {
    ({ added } = await addWinner(toml));
  } catch (e) {
    notice.textContent = "";
    throw e;
  }
  await loadModels(added.name);
  notice.textContent = `model ${added.name} holds user.${name}; diagnosing…`;
  const body = settings(added.name);
  const job = await runJob("diagnoses", body);
  await showDiagnosis(job, body);
  await loadJobs();
  const c = lastDiagnosis.d.candidates.find((x) => x.effect === `user.${name}`);
  notice.textContent = c
    ? `user.${name}: ${paramText(c)}; discrepancy with it ${pxUm(c.discrepancy_px, scale)} (drop ${pxUm(c.drop_px, scale)})`
    : `user.${name} could not be fitted on this dataset's runs`;
}));

async function main() {
  await loadDataset();
  try {
    await loadModels();
  } catch (e) {
    showError($("#job-error"), e);
  }
  await loadHistory();
  await loadJobs();
  // A result's own URL (`?job=ID`) opens it.
  const wanted = new URLSearchParams(location.search).get("job");
  if (wanted) {
    await guard(async () => {
      await reopen(await api(`/jobs/${encodeURIComponent(wanted)}`));
    });
  }
}

main();
