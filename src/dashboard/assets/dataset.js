// One dataset: compare it with a model, diagnose the missing effect, add the winner as a new
// model version, and watch the discrepancy fall in the history chart.
import { api, apiText, el, $, clear, num, when, showError, setupToken, follow, progressBar, inlineSvg, pageId, API, ApiError } from "./common.js";
import { historySvg } from "./charts.js";

setupToken();
const id = pageId();
const base = `/datasets/${encodeURIComponent(id)}`;
$("#dataset-id").textContent = id;
document.title = `ffdic — dataset ${id}`;
$("#history-svg-link").href = `${API}${base}/history.svg`;
let models = [];
let busy = false;

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
    const d = await api(base);
    $("#dataset-name").textContent = d.name;
    const m = /^experiment:(.+)$/.exec(d.source || "");
    const tifs = d.files.filter((f) => /\.tiff?$/i.test(f));
    clear($("#dataset-info"), [
      ["name", d.name],
      ["source", m ? el("a", { href: `/experiments/${m[1]}` }, `experiment ${m[1]}`) : d.source],
      ["runs", String(d.runs)],
      ["frames", `${tifs.length} TIFF, ${d.width} × ${d.height} px`],
      ["created", when(d.created_at)],
      ["files", el("span", { class: "mono small" }, d.files.join(", "))],
    ].flatMap(([k, v]) => [el("dt", {}, k), el("dd", {}, v)]));
  } catch (e) {
    showError($("#dataset-error"), e);
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

async function showComparison(job) {
  const cmp = await api(`/jobs/${job.id}/files/results/comparison.json`);
  $("#comparison").classList.remove("hidden");
  $("#comparison-model").textContent = `${cmp.model.name} (version ${cmp.model.version})`;
  clear($("#comparison-summary"), [
    ["discrepancy", el("strong", { id: "comparison-discrepancy", "data-discrepancy": cmp.discrepancy_px }, `${num(cmp.discrepancy_px)} px`)],
    ["rigid (stage landing, bias)", `${num(cmp.parts && cmp.parts.rigid_px)} px`],
    ["systematic (field)", `${num(cmp.parts && cmp.parts.field_px)} px`],
    ["random (std)", `${num(cmp.parts && cmp.parts.std_px)} px`],
    ["model effects", (cmp.model.effects && (Array.isArray(cmp.model.effects) ? cmp.model.effects : Object.keys(cmp.model.effects)).join(", ")) || "—"],
  ].flatMap(([k, v]) => [el("dt", {}, k), el("dd", {}, v)]));
  const runs = [...(cmp.runs || [])].sort((a, b) => b.discrepancy_px - a.discrepancy_px);
  clear($("#comparison-runs"), el("table", {},
    el("thead", {}, el("tr", {}, ["run", "scheme", "discrepancy [px]", "rigid [px]", "field [px]", "std [px]", "mean Δu [px]", "mean Δv [px]"].map((h, i) => el("th", { class: i > 1 ? "num" : "" }, h)))),
    el("tbody", {}, runs.map((r) => el("tr", {},
      el("td", {}, r.id), el("td", {}, r.scheme),
      el("td", { class: "num" }, num(r.discrepancy_px)), el("td", { class: "num" }, num(r.rigid_px)),
      el("td", { class: "num" }, num(r.field_px)),
      el("td", { class: "num" }, num(r.std_px)),
      el("td", { class: "num" }, num(r.mean_diff_px && r.mean_diff_px[0])),
      el("td", { class: "num" }, num(r.mean_diff_px && r.mean_diff_px[1])))))));
  await showPlots(job, $("#comparison-plots"));
}

async function showPlots(job, container) {
  const plots = (job.result_files || []).filter((f) => f.startsWith("plots/") && f.endsWith(".svg"));
  const boxes = plots.map((p) => el("div", { class: "figure", "data-plot": p.slice(6) }));
  clear(container, boxes.length ? boxes : [el("p", { class: "muted" }, "no plots")]);
  await Promise.all(plots.map((p, i) => inlineSvg(boxes[i], `${API}/jobs/${job.id}/files/plots/${encodeURIComponent(p.slice(6))}`)
    .catch((e) => clear(boxes[i], el("p", { class: "error" }, e.message)))));
}

function paramText(c) {
  const keys = Object.keys(c.params || {});
  if (!keys.length) return "—";
  return keys.map((k) => {
    const se = c.stderr && c.stderr[k];
    return `${k} = ${num(c.params[k])}${se !== undefined && se !== null ? " ± " + num(se, 2) : ""}`;
  }).join("; ");
}

let lastDiagnosis = null;

async function showDiagnosis(job, body) {
  const d = await api(`/jobs/${job.id}/files/results/diagnosis.json`);
  lastDiagnosis = { job, d, body };
  $("#diagnosis").classList.remove("hidden");
  $("#diagnosis-model").textContent = `${d.model.name} (version ${d.model.version}), discrepancy ${num(d.discrepancy_px)} px`;
  const v = $("#diagnosis-verdict");
  v.dataset.verdict = d.verdict;
  v.className = `verdict ${d.verdict !== "none" ? "found" : ""}`;
  v.textContent = d.verdict !== "none"
    ? `Verdict: ${d.verdict} — the model lacks it`
    : "Verdict: none — no candidate explains the discrepancy beyond its noise";
  const rounds = (d.rounds || []).length > 1 ? d.rounds : [];
  clear($("#diagnosis-rounds"), rounds.map((r) => el("li", { "data-verdict": r.verdict },
    `${r.model}: ${num(r.discrepancy_px)} ± ${num(r.discrepancy_se_px)} px → ${r.verdict}` +
    (r.after_px != null ? ` → ${num(r.after_px)} px` : ""))));
  if ((d.verdicts || []).length > 1) {
    v.textContent = `Found, in order: ${d.verdicts.join(", ")} — discrepancy ${num(d.discrepancy_px)} → ${num(d.final_discrepancy_px)} px`;
  }
  clear($("#candidates"), el("table", { id: "candidate-table" },
    el("thead", {}, el("tr", {}, ["#", "effect", "fitted parameters ± standard error", "discrepancy with it [px]", "drop [px]", "ΔBIC", "significant"].map((h, i) => el("th", { class: i >= 3 && i <= 5 ? "num" : "" }, h)))),
    el("tbody", {}, d.candidates.map((c, i) => el("tr", { class: c.effect === d.verdict ? "winner" : "", "data-effect": c.effect },
      el("td", {}, String(i + 1)), el("td", {}, c.effect), el("td", { class: "small" }, paramText(c)),
      el("td", { class: "num" }, num(c.discrepancy_px)), el("td", { class: "num" }, num(c.drop_px)),
      el("td", { class: "num" }, num(c.delta_bic, 5)), el("td", {}, c.significant ? "yes" : "no"))))));
  const notes = [];
  for (const c of d.confounded || []) {
    notes.push(el("li", {}, `${c.effects.join(" and ")} are confounded (${c.evidence}): separate them with ${c.separate_with}`));
  }
  for (const n of d.not_identifiable || []) {
    notes.push(el("li", {}, `${n.effect} cannot be identified from this dataset: ${n.reason}; add ${n.runs_to_add}`));
  }
  clear($("#identifiability"), notes.length ? [el("h3", {}, "What this dataset cannot tell apart"), el("ul", {}, notes)] : []);
  const add = $("#add-winner");
  const hasWinner = d.verdict !== "none" && (job.result_files || []).includes("results/winner-model.toml");
  add.classList.toggle("hidden", !hasWinner);
  add.disabled = false;
  add.textContent = (d.verdicts || []).length > 1
    ? `Add ${d.verdicts.join(" + ")} as a new model version`
    : `Add ${d.verdict} as a new model version`;
  $("#add-notice").textContent = "";
}

async function guard(fn) {
  if (busy) return;
  busy = true;
  for (const b of ["#compare-btn", "#diagnose-btn", "#find-all-btn", "#add-winner"]) $(b).disabled = true;
  try {
    await fn();
  } catch (e) {
    showError($("#job-error"), e);
  } finally {
    busy = false;
    for (const b of ["#compare-btn", "#diagnose-btn", "#find-all-btn", "#add-winner"]) $(b).disabled = false;
  }
}

$("#compare-btn").addEventListener("click", () => guard(async () => {
  const job = await runJob("comparisons", settings($("#model").value));
  await showComparison(job);
  await loadHistory();
}));

$("#find-all-btn").addEventListener("click", () => guard(async () => {
  const body = { ...settings($("#model").value), rounds: 4 };
  const job = await runJob("diagnoses", body);
  await showDiagnosis(job, body);
  await loadHistory();
}));

$("#diagnose-btn").addEventListener("click", () => guard(async () => {
  const body = settings($("#model").value);
  const job = await runJob("diagnoses", body);
  await showDiagnosis(job, body);
  await loadHistory();
}));

$("#add-winner").addEventListener("click", () => guard(async () => {
  if (!lastDiagnosis) return;
  const { job, body } = lastDiagnosis;
  const toml = await apiText(`/jobs/${job.id}/files/results/winner-model.toml`);
  let name;
  try {
    const added = await api("/models", { method: "POST", body: { toml } });
    name = added.name;
    $("#add-notice").textContent = `model ${added.name} (version ${added.version}) added; comparing…`;
  } catch (e) {
    // Added before (same name): compare with the stored one.
    const m = /^\s*name\s*=\s*"([^"]+)"/m.exec(toml);
    if (!(e instanceof ApiError && e.status === 409 && m)) throw e;
    name = m[1];
    $("#add-notice").textContent = `model ${name} exists already; comparing…`;
  }
  await loadModels(name);
  const cmp = await runJob("comparisons", { ...body, model: name });
  await showComparison(cmp);
  const entries = await loadHistory();
  const last = entries[entries.length - 1];
  $("#add-notice").textContent = `model ${name} added: discrepancy now ${last ? num(last.discrepancy_px) : "—"} px`;
  $("#add-winner").classList.add("hidden");
}));

async function main() {
  await loadDataset();
  try {
    await loadModels();
  } catch (e) {
    showError($("#job-error"), e);
  }
  await loadHistory();
}

main();
