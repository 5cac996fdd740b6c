// Charts drawn in the page (the server draws the figures; these are the live ones): a histogram
// of the snapshot and the history of a dataset's discrepancy. Axis labels carry units.

import { lengthPm } from "./common.js";

const NS = "http://www.w3.org/2000/svg";

function s(tag, attrs = {}, text) {
  const node = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, String(v));
  if (text !== undefined) node.textContent = text;
  return node;
}

/** About `n` "nice" ticks (1, 2, 5 × 10^k) covering [lo, hi]. */
export function niceTicks(lo, hi, n = 5) {
  if (!(hi > lo)) { lo -= 1; hi += 1; }
  const raw = (hi - lo) / n;
  const mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 5, 10].map((m) => m * mag).find((v) => v >= raw) || 10 * mag;
  const ticks = [];
  for (let k = Math.floor(lo / step); k <= Math.ceil(hi / step); k++) ticks.push(k * step);
  return ticks;
}

function tickLabel(v) {
  if (v === 0) return "0";
  const a = Math.abs(v);
  if (a >= 1e5 || a < 1e-3) return v.toExponential(1);
  return Number(v.toPrecision(3)).toString();
}

function frame(width, height, title) {
  const svg = s("svg", { viewBox: `0 0 ${width} ${height}`, "font-family": "sans-serif", "font-size": 12, role: "img" });
  svg.append(s("rect", { x: 0, y: 0, width, height, fill: "white" }));
  svg.append(s("text", { x: width / 2, y: 20, "text-anchor": "middle", "font-size": 14, "font-weight": "bold" }, title));
  return svg;
}

function axes(svg, { left, top, pw, ph, xTicks, yTicks, xOf, yOf, xLabel, yLabel, xTickText }) {
  for (const t of yTicks) {
    const y = yOf(t);
    svg.append(s("line", { x1: left, x2: left + pw, y1: y, y2: y, stroke: "#e3e3e3" }));
    svg.append(s("text", { x: left - 6, y: y + 4, "text-anchor": "end" }, tickLabel(t)));
  }
  for (const t of xTicks) {
    const x = xOf(t);
    svg.append(s("line", { x1: x, x2: x, y1: top + ph, y2: top + ph + 4, stroke: "#333" }));
    svg.append(s("text", { x, y: top + ph + 17, "text-anchor": "middle" }, xTickText ? xTickText(t) : tickLabel(t)));
  }
  svg.append(s("rect", { x: left, y: top, width: pw, height: ph, fill: "none", stroke: "#333" }));
  svg.append(s("text", { x: left + pw / 2, y: top + ph + 36, "text-anchor": "middle" }, xLabel));
  svg.append(s("text", { transform: `translate(14,${top + ph / 2}) rotate(-90)`, "text-anchor": "middle" }, yLabel));
}

/**
 * Histogram of grey levels: `counts` per bin, bins of `binWidth` from 0; `maxValue` the top of
 * the range (saturation), `unit` the grey-level unit.
 */
export function histogramSvg(counts, binWidth, maxValue, unit, title) {
  const [width, height] = [440, 260];
  const [left, right, top, bottom] = [64, 16, 32, 46];
  const [pw, ph] = [width - left - right, height - top - bottom];
  const svg = frame(width, height, title);
  const peak = Math.max(1, ...counts);
  const yTicks = niceTicks(0, peak, 4);
  const yMax = yTicks[yTicks.length - 1];
  const xOf = (v) => left + (pw * v) / maxValue;
  const yOf = (c) => top + ph * (1 - c / yMax);
  const xTicks = niceTicks(0, maxValue, 5).filter((t) => t <= maxValue);
  axes(svg, { left, top, pw, ph, xTicks, yTicks, xOf, yOf, xLabel: `grey level [${unit}]`, yLabel: "pixels", xTickText: null });
  const g = s("g", { class: "histogram" });
  counts.forEach((c, i) => {
    if (!c) return;
    const x0 = xOf(i * binWidth);
    const x1 = xOf(Math.min(maxValue, (i + 1) * binWidth));
    g.append(s("rect", { class: "hist-bin", x: x0, y: yOf(c), width: Math.max(0.8, x1 - x0), height: top + ph - yOf(c), fill: "#1f4e79" }));
  });
  svg.append(g);
  return svg;
}

/**
 * The discrepancy over model versions: a column per model version, in the order each was first
 * compared (a re-run lands on its version's column, not at the end as if the error had risen
 * back); one point per comparison (class "history-point", data-discrepancy in px, in the order
 * made); a line per manifest (the dataset as compared: a grown manifest is its own line) through
 * each version's latest comparison.
 */
export function historySvg(entries, title) {
  const [width, height] = [680, 340];
  const [left, right, top, bottom] = [78, 24, 36, 90];
  const [pw, ph] = [width - left - right, height - top - bottom];
  const svg = frame(width, height, title);
  svg.classList.add("history-chart");
  const values = entries.map((e) => Number(e.discrepancy_px)).filter(Number.isFinite);
  if (!values.length) {
    svg.append(s("text", { x: width / 2, y: height / 2, "text-anchor": "middle", fill: "#5d6678" }, "no comparison yet"));
    return svg;
  }
  const versionOf = (e) => `${e.model}\u0000${e.version ?? ""}`;
  const versions = [...new Set(entries.map(versionOf))];
  const manifests = [...new Set(entries.map((e) => e.manifest_version || ""))];
  const colours = ["#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00"];
  const colourOf = (e) => colours[manifests.indexOf(e.manifest_version || "") % colours.length];
  const yTicks = niceTicks(0, Math.max(...values) * 1.1, 5);
  const yMax = yTicks[yTicks.length - 1];
  const n = versions.length;
  const xOf = (k) => left + (n === 1 ? pw / 2 : (pw * (k + 0.5)) / n);
  const yOf = (v) => top + ph * (1 - v / yMax);
  const label = (k) => {
    const [model, version] = (versions[k] || "").split("\u0000");
    return version ? `${model} v${version.slice(0, 6)}` : model;
  };
  axes(svg, {
    left, top, pw, ph, xTicks: versions.map((_, k) => k), yTicks, xOf, yOf,
    xLabel: "model version, in the order first compared", yLabel: "discrepancy [px]", xTickText: label,
  });
  manifests.forEach((m, mi) => {
    const latest = new Map();
    for (const e of entries) if ((e.manifest_version || "") === m) latest.set(versionOf(e), e);
    const pts = versions.map((v, k) => (latest.has(v) ? [xOf(k), yOf(Number(latest.get(v).discrepancy_px))] : null)).filter(Boolean);
    svg.append(s("polyline", { class: "history-line", "data-manifest": m, points: pts.map((p) => p.join(",")).join(" "), fill: "none", stroke: colours[mi % colours.length], "stroke-width": 2 }));
    if (manifests.length > 1) {
      const runs = [...latest.values()].pop().manifest_runs;
      svg.append(s("text", { x: left + 4 + 170 * mi, y: height - 8, fill: colours[mi % colours.length], "font-size": 11 },
        m ? `— ${runs} runs (manifest ${m.slice(0, 6)})` : "— before manifests were recorded"));
    }
  });
  entries.forEach((e) => {
    const k = versions.indexOf(versionOf(e));
    const [x, y] = [xOf(k), yOf(Number(e.discrepancy_px))];
    const c = s("circle", {
      class: "history-point", cx: x, cy: y, r: 5, fill: colourOf(e),
      "data-discrepancy": e.discrepancy_px, "data-model": e.model, "data-version": e.version ?? "",
      "data-manifest": e.manifest_version || "",
    });
    const withError = e.discrepancy_se_px > 0 ? lengthPm(e.discrepancy_px, e.discrepancy_se_px) : Number(e.discrepancy_px).toPrecision(4);
    c.append(s("title", {}, `${label(k)}, ${e.time || ""}: ${withError} px` +
      `${e.manifest_runs ? `, ${e.manifest_runs} runs` : ""}${(e.effects || []).length ? " — effects: " + e.effects.join(", ") : ""}`));
    svg.append(c);
    svg.append(s("text", { x: x + 8, y: y - 6, "font-size": 11 }, Number(e.discrepancy_px).toPrecision(3)));
  });
  return svg;
}
