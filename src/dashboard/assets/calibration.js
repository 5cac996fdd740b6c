// One calibration: live progress over SSE, then its camera card as a person reads it — every
// number with its standard error and whether it is significant, the stage's map, the imaging
// chain, what the card leaves unexplained, and how to use it (the text form is results/card.txt).
import { api, el, $, clear, num, when, badge, showError, setupToken, runPage, progressBar, pageId, TERMINAL, API, eventLog, downloadLink, table, lengthPm, valuePm } from "./common.js";

setupToken();
const id = pageId();
const base = `/calibrations/${encodeURIComponent(id)}`;
const files = `/jobs/${encodeURIComponent(id)}/files/results`;
const bar = progressBar("progress");
$("#progress-slot").append(bar.node);
$("#run-id").textContent = id;
document.title = `ffdic — calibration ${id}`;

function patternText(p) {
  if (!p) return "—";
  return typeof p === "string" ? `preset ${p}` : (p.label || JSON.stringify(p));
}

function showRecord(r) {
  clear($("#run-status"), badge(r.status));
  bar.set(r.progress, r.status);
  $("#run-message").textContent = r.message || "";
  const plan = r.request || {};
  const sizes = plan.move_sizes_mm || [];
  // A record states the count it ran (CalibrationPlan::with_phase_scan_stated); null only in
  // records made before it did.
  const scan = plan.phase_scan_count;
  clear($("#run-info"), [
    ["name", plan.name || "—"],
    ["target", patternText(plan.pattern)],
    ["move sizes [mm]", sizes.length ? sizes.map((s) => num(s, 4)).join(", ") : "from the field and the DIC's reach"],
    ["print", plan.print_characterised ? "characterised" : "nominal (calibrated to the frames)"],
    ["phase scan", scan == null ? "not stated" : scan ? `${scan} steps of ${num(plan.phase_scan_step_px, 3)} px per axis` : "none"],
    ["static frames", String(plan.static_frames ?? "—")],
    ["rounds", String(plan.rounds ?? "—")],
    ["model", plan.model || "—"],
    ["created", when(r.created_at)],
    ["finished", when(r.finished_at)],
  ].flatMap(([k, v]) => [el("dt", {}, k), el("dd", {}, v)]));
  $("#cancel-btn").classList.toggle("hidden", TERMINAL.includes(r.status));
}

const onEvent = eventLog(bar, $("#run-message"), $("#events"));

/** "yes" when `v` lies more than `z` standard errors from zero. */
function mark(v, se, z) {
  return Math.abs(v) > z * se ? "yes" : "no";
}

function geometryRows(card) {
  return card.geometry.flatMap((g) => Object.entries(g.params).map(([name, v]) => {
    const se = g.stderr[name];
    return [g.effect, name, valuePm(v, se), se === undefined ? "—" : mark(v, se, card.z_significant)];
  }));
}

/** The stage's numbers; which are significant is the map's own finding (`significant`). */
function stageRows(s) {
  return [
    ["x scale [px/mm]", "scale_x", s.scale_x_px_per_mm, s.scale_x_se_px_per_mm, s.nominal_scale_px_per_mm],
    ["y scale [px/mm]", "scale_y", s.scale_y_px_per_mm, s.scale_y_se_px_per_mm, s.nominal_scale_px_per_mm],
    ["angle to the rows [rad]", "angle", s.angle_rad, s.angle_se_rad, 0],
    ["skew of the axes [rad]", "skew", s.skew_rad, s.skew_se_rad, 0],
  ].map(([name, test, v, se, against]) =>
    [name, valuePm(v, se), num(against, 6), s.significant.includes(test) ? "yes" : "no"]);
}

function paramsText(params, stderr) {
  return Object.entries(params)
    .map(([k, v]) => `${k} = ${valuePm(v, stderr[k])}`)
    .join(", ");
}

function showCard(doc) {
  const card = doc.card;
  const z = card.z_significant;
  $("#card-model").textContent = doc.model;
  const found = [...card.geometry.filter((g) => g.significant).map((g) => g.effect),
    ...((card.stage && card.stage.significant) || []).map((s) => `stage ${s}`)];
  const f = $("#card-found");
  f.dataset.found = found.join(",");
  f.className = `verdict ${found.length ? "found" : ""}`;
  f.textContent = found.length ? `Found: ${found.join(", ")}` : "Found: nothing significant";
  const gap = Math.hypot(card.baseline_se_px, card.card_se_px);
  const fall = card.card_px > 0 ? ` (${num(card.baseline_px / card.card_px, 3)} times smaller)` : "";
  $("#card-discrepancy").textContent =
    `Discrepancy on the calibration's own runs: ${card.baseline_model} ${lengthPm(card.baseline_px, card.baseline_se_px)} px → ` +
    `the card ${lengthPm(card.card_px, card.card_se_px)} px` +
    (card.baseline_px - card.card_px > 2 * gap ? fall : ": the difference is within its standard errors, not a finding");
  $("#card-significance").textContent =
    `Significant: beyond ${num(z, 3)} standard errors, a ${num(100 * card.false_alarm_rate, 2)} % family-wise false-alarm rate over every number of the card.`;
  clear($("#card-geometry"), card.geometry.length
    ? table(["effect", "parameter", "value ± SE", "significant"], geometryRows(card))
    : el("p", { class: "muted small" }, "no geometric term fitted"));
  clear($("#card-geometry-notes"), card.geometry.flatMap((g) => [
    ...Object.entries(g.derived || {}).map(([k, v]) => el("li", {}, `${g.effect}: ${k} = ${num(v)}`)),
    ...(g.notes || []).map((n) => el("li", {}, `${g.effect}: ${n}`)),
  ]));
  const s = card.stage;
  clear($("#card-stage"), s
    ? table(["", "value ± SE", "against", "significant"], stageRows(s))
    : el("p", { class: "muted small" }, "not mapped: moves along both axes, at least three runs, are needed"));
  $("#card-stage-note").textContent = s
    ? `${s.runs} runs scatter ${num(s.residual_px, 3)} px about the map. The stage is the length standard: its travel error and the camera's scale are one number.`
    : "";
  clear($("#card-imaging"), table(["effect", "parameters", "identifiable"],
    card.imaging.map((i) => [i.effect,
      Object.keys(i.params).length
        ? paramsText(i.params, i.stderr) + (i.significant ? "" : " (not significant)")
        : "not fitted",
      i.identifiable ? "yes" : `no — separate it with ${i.separate_with || "another run"}`])));
  clear($("#card-not-fitted"), (card.not_identifiable || []).length
    ? el("ul", { class: "small" }, card.not_identifiable.map((n) => el("li", {}, `not fitted: ${n}`)))
    : null);
  const left = $("#card-unexplained");
  left.dataset.significant = String(card.unexplained.significant);
  left.textContent = card.unexplained.summary;
  clear($("#card-use"),
    "The card is the stored model ", el("span", { class: "mono" }, doc.model),
    ": subtract what it explains from a measurement with ", el("span", { class: "mono" }, `ffdic analyze --card ${doc.model}`),
    ", or diagnose and compare against it. The frames are the dataset ",
    el("a", { href: `/datasets/${encodeURIComponent(doc.dataset_id)}`, class: "mono" }, doc.dataset_id), ".");
}

async function showResults() {
  $("#results").classList.remove("hidden");
  let doc;
  try {
    doc = await api(`${base}/card`);
  } catch (e) {
    showError($("#run-error"), e);
    return;
  }
  showCard(doc);
  clear($("#downloads"), el("ul", { class: "links" },
    downloadLink(`${API}${base}/card`, "card.json (the card, the rounds, the plan and the experiment it became)"),
    downloadLink(`${API}${files}/card.txt`, "card.txt (as ffdic calibrate prints it)"),
    downloadLink(`${API}${files}/card-model.toml`, "card-model.toml (the card's model)"),
    downloadLink(`${API}${files}/diagnosis.json`, "diagnosis.json (the rounds)")));
  $("#results").dataset.loaded = "true";
}

runPage({
  recordUrl: base,
  eventsUrl: `/jobs/${encodeURIComponent(id)}/events`,
  cancelUrl: `/jobs/${encodeURIComponent(id)}/cancel`,
  what: "the calibration",
  showRecord,
  onEvent,
  showResults,
});
