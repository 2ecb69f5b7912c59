// pendant: the analysis page. Plain ES module, no build step, no libraries.
//
// A person uploads (or pastes) a robot-recording/1 document; the page POSTs it as it is to
// /recordings (so the service, not the browser, judges it: a NaN or a wrong joint count
// comes back as a 422 naming the field), then POST /recordings/{id}/analyze, and shows the
// analysis-report/1: verdict, RMS before/after, where the mismatch is, each finding, what is
// not identifiable, and per-sample residual plots before (rigid model) and after (final
// model). The page only draws what the report carries; it computes no statistics itself.
//
// Per-sample residuals are read from `baseline.residuals_mm` and `final.residuals_mm` (or
// `residuals.baseline_mm` / `residuals.final_mm`): |r_k| in mm, one per sample, in sample
// order. A report without them gets a note in place of the plot.
//
// The analysis is a job of the service: POST .../analyze answers 202 with the job; the page
// polls GET /jobs/{id} (progress in the status line, a Cancel button) and, once it is done,
// reads the report from the job's result link. A failed job's error is shown like a refused
// request's.
//
// ?analysis=ID shows the stored report GET /analysis/ID.

import { request, ApiError } from "/api.js";
import { el, sig as num } from "/ui.js";

const $ = (sel, root = document) => root.querySelector(sel);
const SVG = "http://www.w3.org/2000/svg";

const EFFECTS = {
  joint_offset: "Joint offset",
  link_length: "Link length",
  link_twist: "Link twist",
  joint_compliance: "Joint compliance",
  backlash: "Backlash",
  thermal_drift: "Thermal drift",
  trigger_latency: "Trigger latency",
  tool_deflection: "Tool deflection",
  gear_transmission_error: "Gear transmission error",
};
const VERDICTS = {
  explained: ["Explained", "The findings bring the residual down to the noise level."],
  no_missing_physics: ["No missing physics", "The rigid model fits to the noise level: nothing is missing."],
  unexplained_structure: ["Unexplained structure",
    "Structure remains that no known effect explains; see where the mismatch is."],
};
const UNITS = [["_deg_per_Nm", "deg/Nm"], ["_mm_per_N", "mm/N"], ["_mm", "mm"], ["_deg", "deg"],
  ["_ms", "ms"], ["_s", "s"], ["_kg", "kg"]];
const EVIDENCE = {
  p_value: "p-value", candidates_tested: "candidates tested", correlation_r: "correlation r",
  identifiability: "identifiability", t_value: "t value",
  heldout_rms_before_mm: "held-out RMS before", structure_share: "of the structure it explains",
  indistinguishable_from: "indistinguishable from",
};

// Tests wait for `window.analysisPage.pending === 0` (nothing in flight, file reads included).
const page = { pending: 0, recording: null, report: null };
window.analysisPage = page;

// ------------------------------------------------------------------------------ requests

/** Run an async job, counting it in page.pending from the first synchronous moment. */
async function busy(job) {
  page.pending += 1;
  $("#main").setAttribute("aria-busy", "true");
  for (const b of document.querySelectorAll("#input-panel button")) b.disabled = true;
  try {
    await job();
  } finally {
    page.pending -= 1;
    if (page.pending === 0) {
      $("#main").setAttribute("aria-busy", "false");
      for (const b of document.querySelectorAll("#input-panel button")) b.disabled = false;
    }
  }
}

const FINAL = ["done", "failed", "cancelled"];
const POLL_MS = 300;

/** Follow a job (the 202 answer) until it ends, showing its progress; resolves to the job. */
async function waitJob(job, what) {
  const cancel = $("#cancel-job");
  cancel.hidden = false;
  cancel.disabled = false;
  cancel.onclick = () => {
    cancel.disabled = true;
    request("POST", job.links.cancel).catch(() => {});
  };
  try {
    while (!FINAL.includes(job.state)) {
      setStatus(`${what}: ${job.state}, ${Math.round(100 * job.progress)} % (${job.message}) …`);
      await new Promise((resolve) => setTimeout(resolve, POLL_MS));
      job = await request("GET", job.links.self);
    }
    return job;
  } finally {
    cancel.hidden = true;
    cancel.onclick = null;
  }
}

// ------------------------------------------------------------------------------ formatting

// el() and num() (4 significant digits: ui.js sig()) come from web/ui.js, shared with the pendant

function svg(tag, attrs = {}, text) {
  const e = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) {
    // a style through the CSSOM: the page's Content-Security-Policy refuses style attributes
    if (k === "style") e.style.cssText = v;
    else e.setAttribute(k, v);
  }
  if (text !== undefined) e.textContent = text;
  return e;
}

function isNum(v) { return typeof v === "number" && Number.isFinite(v); }

function mm(v) {
  if (!isNum(v)) return "–";
  return `${Math.abs(v) < 0.01 && v !== 0 ? v.toFixed(4) : v.toFixed(3)} mm`;
}

function unitOf(key) {
  for (const [suffix, unit] of UNITS) if (key.endsWith(suffix)) return [key.slice(0, -suffix.length), unit];
  return [key, ""];
}

function effectName(effect) { return EFFECTS[effect] || String(effect).replace(/_/g, " "); }

/** "Link length J2 (a2)": the DH parameter (in the finding or its parameters) tells a2 from d2. */
function findingTitle(f) {
  const hasJoint = f.joint !== null && f.joint !== undefined;
  const joint = hasJoint ? ` J${f.joint}` : "";
  const p = f.dh_parameter || (f.parameters || {}).dh_parameter;
  const dh = p ? ` (${p}${hasJoint ? f.joint : ""})` : f.effect === "link_twist" && hasJoint ? ` (α${f.joint})` : "";
  // one gear finding per harmonic; a not-identifiable note carries its harmonic (or the
  // list of harmonics left out) at the top level
  const k = (f.parameters || {}).periods_per_turn ?? f.periods_per_turn;
  const harmonic = f.effect !== "gear_transmission_error" ? ""
    : isNum(k) ? ` (${k} per turn)`
    : Array.isArray(k) && k.length ? ` (${k.length > 1 ? `${k[0]}–${k[k.length - 1]}` : k[0]} per turn)` : "";
  return `${effectName(f.effect)}${joint}${dh}${harmonic}`;
}

/** A p-value as a person reads it: 0.012, 3.1e-5, or "< 1e-15" below what a double resolves. */
function pValue(p) {
  if (!isNum(p)) return num(p);
  if (p < 1e-15) return "< 1e-15";
  if (p < 0.001) return p.toExponential(1);
  return p.toFixed(3);
}

/** structure_share: the effect's share of what the best generic smooth-function group would
 * explain at that step; above 1 the effect explains more than that group did. */
function structureShare(v) {
  if (!isNum(v)) return num(v);
  return v > 1 ? `all of it (${Math.round(v * 100)} % of what the best generic group explains)`
               : `${Math.round(v * 100)} %`;
}

/** The sign convention of a finding's value, in words (nominal DH from the recording, when known). */
function signWords(f, robot) {
  const P = f.parameters || {};
  const j = f.joint;
  const joints = robot && Array.isArray(robot.joints) ? robot.joints : null;
  if (f.effect === "link_length" && isNum(P.delta_mm)) {
    const name = `${P.dh_parameter || "length"}${j ?? ""}`;
    const nominal = joints && joints[j - 1] ? joints[j - 1][`${P.dh_parameter}_mm`] : undefined;
    if (!isNum(nominal) || nominal === 0) return `true minus nominal ${name}`;
    const longer = Math.abs(nominal + P.delta_mm) > Math.abs(nominal);
    const mm3 = (v) => Math.abs(v).toFixed(3);
    return `true minus nominal: |${name}| is ${mm3(nominal + P.delta_mm)} mm, not ${mm3(nominal)}: ` +
           `${mm3(P.delta_mm)} mm ${longer ? "longer" : "shorter"}`;
  }
  if (f.effect === "link_twist" && isNum(P.delta_alpha_deg)) return `true minus nominal α${j ?? ""}`;
  if (f.effect === "joint_offset" && isNum(P.offset_deg)) {
    return `true minus shown: joint ${j} stands ${num(Math.abs(P.offset_deg))} deg further ${P.offset_deg > 0 ? "positive" : "negative"} than it shows`;
  }
  if (f.effect === "trigger_latency" && isNum(P.latency_ms)) return P.latency_ms >= 0 ? "recorded late" : "recorded early";
  return "";
}

/** ["body", "samples", 3, "joints_deg"] -> "samples[3].joints_deg" (the JSON path). */
function fieldPath(loc) {
  const parts = Array.isArray(loc) ? loc.slice(["body", "query", "path"].includes(loc[0]) ? 1 : 0) : [];
  let out = "";
  for (const p of parts) out += typeof p === "number" ? `[${p}]` : (out ? `.${p}` : String(p));
  return out;
}

/** Line and column of a character offset of the text (a JSON decode error's loc). */
function lineCol(text, offset) {
  const before = text.slice(0, offset).split("\n");
  return `line ${before.length}, column ${before[before.length - 1].length + 1}`;
}

// ------------------------------------------------------------------------------ errors

function clearErrors() {
  const box = $("#upload-error");
  box.replaceChildren();
  box.hidden = true;
  for (const e of document.querySelectorAll("[aria-invalid]")) e.removeAttribute("aria-invalid");
}

/** A refused request: each item of the 422's detail with its field, beside the upload box. */
function showError(err, text, step) {
  const box = $("#upload-error");
  const items = Array.isArray(err.detail) ? err.detail : [{ loc: [], msg: String(err.detail ?? err.message) }];
  const list = el("ul");
  for (const d of items) {
    const loc = Array.isArray(d.loc) ? d.loc : [];
    let where = fieldPath(loc);
    if (loc[0] === "body" && loc.length === 2 && typeof loc[1] === "number" && text) {
      where = `the JSON text at ${lineCol(text, loc[1])}`; // json_invalid: loc is the offset
    }
    if (loc[0] === "query" && loc[1]) $(`#${loc[1]}`)?.setAttribute("aria-invalid", "true");
    else if (loc[0] !== "path") $("#paste").setAttribute("aria-invalid", "true");
    const li = el("li", { "data-loc": where });
    if (where) li.append(el("code", { class: "loc", text: where }), " ");
    li.append(el("span", { class: "msg", text: d.msg ?? "" }));
    list.append(li);
  }
  const head = err.status ? `${step} was refused (${err.status}):` : `${step} failed:`;
  box.replaceChildren(el("p", { class: "err-head", text: head }), list);
  box.hidden = false;
  setStatus(`${step} was refused; nothing was analysed.`, "err");
}

function setStatus(text, kind = "") {
  const s = $("#status");
  s.textContent = text;
  s.className = `status ${kind}`;
}

// ------------------------------------------------------------------------------ the flow

async function analyseText(text) {
  clearErrors();
  $("#report").hidden = true;
  $("#empty").hidden = false;
  $("#notes-panel").hidden = true;
  $("#recording-panel").hidden = true;
  page.report = null;
  if (!text.trim()) {
    showError(new ApiError(0, [{ loc: ["body"], msg: "is empty: choose a file, paste a recording or simulate one" }]),
      text, "Reading the recording");
    return;
  }
  setStatus("Storing the recording …");
  let rec;
  try {
    rec = await request("POST", "/recordings", { bodyText: text }); // as given: the service judges it
  } catch (err) {
    showError(err, text, "Storing the recording");
    return;
  }
  page.recording = rec;
  showRecording(rec);
  setStatus(`Analysing recording ${rec.id} (${rec.n_samples} ${rec.kind} samples) …`);
  const q = new URLSearchParams({ folds: $("#folds").value || "5", seed: $("#seed").value || "0" });
  if ($("#split").value) q.set("split", $("#split").value);
  let job;
  try {
    job = await request("POST", `/recordings/${rec.id}/analyze?${q}`);
    job = await waitJob(job, `Analysing recording ${rec.id} (${rec.n_samples} ${rec.kind} samples)`);
  } catch (err) {
    showError(err, text, "The analysis");
    return;
  }
  if (job.state === "cancelled") {
    setStatus(`The analysis of recording ${rec.id} was cancelled; nothing was stored.`, "err");
    return;
  }
  if (job.state !== "done") {
    showError(new ApiError(job.error.status, job.error.detail), text, "The analysis");
    return;
  }
  let rep;
  try {
    rep = await request("GET", job.links.result);
  } catch (err) {
    showError(err, text, "Reading the report");
    return;
  }
  render(rep);
  page.analysed = inputKey(text);
  if (rep.id !== undefined) history.replaceState(null, "", `?analysis=${rep.id}`);
  setStatus(`Analysis ${rep.id ?? ""} of recording ${rec.id}: ${rep.verdict}.`, "ok");
}

/** What an analysis ran on: the text, folds, seed and split. */
function inputKey(text = $("#paste").value) {
  return JSON.stringify([text, $("#folds").value || "5", $("#seed").value || "0", $("#split").value]);
}

function showRecording(rec) {
  const dl = $("#recording-info");
  dl.replaceChildren();
  for (const [k, v] of [["Recording", rec.id], ["Robot", rec.robot], ["Kind", rec.kind], ["Samples", rec.n_samples]]) {
    if (v === undefined) continue;
    dl.append(el("dt", { text: k }), el("dd", { text: String(v) }));
  }
  $("#recording-panel").hidden = false;
}

async function loadStored(id) {
  setStatus(`Loading analysis ${id} …`);
  try {
    const rep = await request("GET", `/analysis/${encodeURIComponent(id)}`);
    render(rep);
    setStatus(`Analysis ${id}: ${rep.verdict}.`, "ok");
  } catch (err) {
    showError(err, "", `Loading analysis ${id}`);
  }
}

// ------------------------------------------------------------------------------ the report

function render(rep) {
  if (page.report && page.report.recording_id !== rep.recording_id) page.robot = null;
  page.report = rep;
  renderVerdict(rep);
  renderPlots(rep);
  renderLocate(rep.locate || {});
  renderFindings(rep.findings || [], page.robot || null);
  if (!page.robot && rep.recording_id !== undefined) nominalRobot(rep);
  renderNotes(rep);
  renderMore(rep);
  $("#empty").hidden = true;
  $("#report").hidden = false;
}

/** The recording's robot (nominal DH), for the sign words; drawn again once it arrives. */
async function nominalRobot(rep) {
  try {
    const doc = await request("GET", `/recordings/${encodeURIComponent(rep.recording_id)}`);
    if (page.report !== rep || !doc || !doc.robot) return;
    page.robot = doc.robot;
    renderFindings(rep.findings || [], page.robot);
  } catch {
    // the words fall back to "true minus nominal"
  }
}

function renderVerdict(rep) {
  const [label, text] = VERDICTS[rep.verdict] || [String(rep.verdict), ""];
  const v = $("#verdict");
  v.textContent = label;
  v.dataset.verdict = rep.verdict;
  v.className = `verdict v-${rep.verdict}`;
  const sp = rep.split || {};
  const how = sp.method ? ` Held-out: ${sp.folds}-fold ${sp.method} split${sp.method === "blocked" ? " (contiguous runs in recorded order)" : ""}.` : "";
  $("#verdict-text").textContent = `${text} ${rep.n_samples ?? "?"} ${rep.kind ?? ""} samples.${how}`;
  const b = rep.baseline || {};
  const f = rep.final || {};
  const nb = b.parameters ? Object.keys(b.parameters).length : undefined;
  const nf = (rep.findings || []).length;
  const rows = [
    ["before", "Rigid model (baseline)", b.rms_mm, b.heldout_rms_mm, nb],
    ["after", `With ${nf} finding${nf === 1 ? "" : "s"} (final)`, f.rms_mm, f.heldout_rms_mm, f.n_parameters],
  ];
  const tbody = $("#metrics tbody");
  tbody.replaceChildren();
  for (const [key, name, rms, held, np] of rows) {
    tbody.append(el("tr", { "data-row": key }, el("th", { text: name }),
      el("td", { class: "rms", text: mm(rms) }), el("td", { class: "heldout", text: mm(held) }),
      el("td", { text: np === undefined ? "–" : String(np) })));
  }
  if (isNum(f.noise_mm)) {
    tbody.append(el("tr", { "data-row": "noise" }, el("th", { text: "Noise level (estimated)" }),
      el("td", { text: mm(f.noise_mm) }), el("td"), el("td")));
  }
}

// ------------------------------------------------------------------------------ plots

/** Per-sample |r_k| of "baseline" or "final" if the report carries them, else null. */
function residuals(rep, which) {
  const block = rep[which];
  if (block && Array.isArray(block.residuals_mm)) return block.residuals_mm;
  const r = rep.residuals;
  if (r && Array.isArray(r[`${which}_mm`])) return r[`${which}_mm`];
  return null;
}

/** Round numbers for an axis from 0 to at least max. */
function ticks(max, target = 5) {
  if (!(max > 0)) return [0, 1];
  const raw = max / target;
  const mag = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => s >= raw);
  const out = [];
  for (let v = 0; v < max + step * 0.999; v += step) out.push(Number(v.toPrecision(6)));
  return out;
}

const W = 560, H = 230, M = { l: 52, r: 10, t: 12, b: 34 };
const SW = 400, SH = 190; // the small RMS-by-model chart

function axes(root, yTicks, top, unit, w = W, h = H) {
  const pw = w - M.l - M.r, ph = h - M.t - M.b;
  const y = (v) => M.t + ph * (1 - v / top);
  for (const t of yTicks) {
    root.append(svg("line", { class: "grid", x1: M.l, x2: M.l + pw, y1: y(t), y2: y(t) }));
    root.append(svg("text", { class: "tick", x: M.l - 5, y: y(t) + 4, "text-anchor": "end" }, num(t)));
  }
  root.append(svg("text", { class: "axis-label", x: 12, y: M.t + ph / 2, transform: `rotate(-90 12 ${M.t + ph / 2})`,
    "text-anchor": "middle" }, unit));
  root.append(svg("line", { class: "axis", x1: M.l, x2: M.l + pw, y1: M.t + ph, y2: M.t + ph }));
  return { pw, ph, y };
}

/** A dashed level line; the RMS label sits at the right end, the noise label at the left. */
function hline(root, cls, yv, label, pw) {  // cls: rms | noise
  root.append(svg("line", { class: cls, x1: M.l, x2: M.l + pw, y1: yv, y2: yv }));
  const right = cls === "rms";
  root.append(svg("text", { class: `${cls}-label level-label`, x: right ? M.l + pw - 4 : M.l + 4, y: yv - 4,
    "text-anchor": right ? "end" : "start" }, label));
}

/** Bars of |r_k| per sample (0-based sample numbers, as the locate block's). */
function residualChart(values, { top, rms, noise, worst, label }) {
  const root = svg("svg", { viewBox: `0 0 ${W} ${H}`, class: "chart", role: "img", style: `max-width: ${W}px`,
    "aria-label": `${label}: |r_k| of ${values.length} samples`, "data-n": values.length });
  const yTicks = ticks(top);
  const topTick = yTicks[yTicks.length - 1];
  const { pw, ph, y } = axes(root, yTicks, topTick, "|r| mm");
  const n = values.length;
  const slot = pw / Math.max(n, 1);
  const gap = slot > 4 ? slot * 0.18 : 0;
  const bars = svg("g", { class: "bars" });
  values.forEach((v, k) => {
    const h = isNum(v) ? Math.min(v, topTick) / topTick * ph : 0;
    const rect = svg("rect", { class: worst.has(k) ? "bar worst" : "bar", x: M.l + k * slot + gap / 2,
      y: M.t + ph - h, width: Math.max(slot - gap, 0.5), height: h, "data-sample": k });
    rect.append(svg("title", {}, `sample ${k}: ${isNum(v) ? mm(v) : "–"}`));
    bars.append(rect);
  });
  root.append(bars);
  const every = Math.max(1, ticks(n, 8)[1] || 1);
  for (let k = 0; k < n; k += every) {
    root.append(svg("text", { class: "tick", x: M.l + (k + 0.5) * slot, y: M.t + ph + 14, "text-anchor": "middle" }, String(k)));
  }
  root.append(svg("text", { class: "axis-label", x: M.l + pw / 2, y: H - 3, "text-anchor": "middle" }, "sample"));
  if (isNum(noise) && noise <= topTick) hline(root, "noise", y(noise), `noise ${mm(noise)}`, pw);
  if (isNum(rms) && rms <= topTick) hline(root, "rms", y(rms), `RMS ${mm(rms)}`, pw);
  return root;
}

/** Grouped bars: RMS and held-out RMS of the rigid model and after each finding. */
function stepsChart(rep) {
  const b = rep.baseline || {};
  const models = [{ name: "rigid", title: "rigid model", rms: b.rms_mm, held: b.heldout_rms_mm }];
  (rep.findings || []).forEach((f, i) => models.push({ name: `+${i + 1}`, title: `+ ${findingTitle(f)}`,
    rms: f.rms_mm, held: f.heldout_rms_mm }));
  const vals = models.flatMap((m) => [m.rms, m.held]).filter(isNum);
  const top = Math.max(...vals, 1e-9) * 1.05; // headroom above the tallest bar
  const yTicks = ticks(top, 4);
  const topTick = yTicks[yTicks.length - 1];
  const root = svg("svg", { viewBox: `0 0 ${SW} ${SH}`, class: "chart", role: "img", style: `max-width: ${SW}px`,
    "aria-label": "RMS model by model" });
  const { pw, ph, y } = axes(root, yTicks, topTick, "mm", SW, SH);
  const slot = Math.min(pw / models.length, 110);
  models.forEach((m, i) => {
    const x0 = M.l + i * slot + slot * 0.15;
    const bw = slot * 0.33;
    [["step-rms", m.rms, "RMS"], ["step-held", m.held, "held-out RMS"]].forEach(([cls, v, what], j) => {
      const h = isNum(v) ? v / topTick * ph : 0;
      const r = svg("rect", { class: `step ${cls}`, x: x0 + j * (bw + 2), y: M.t + ph - h, width: bw, height: h });
      r.append(svg("title", {}, `${m.title}: ${what} ${mm(v)}`));
      root.append(r);
    });
    const t = svg("text", { class: "tick", x: x0 + bw, y: M.t + ph + 14, "text-anchor": "middle" }, m.name);
    t.append(svg("title", {}, m.title));
    root.append(t);
  });
  const f = rep.final || {};
  if (isNum(f.noise_mm) && f.noise_mm <= topTick) hline(root, "noise", y(f.noise_mm), `noise ${mm(f.noise_mm)}`, pw);
  root.append(svg("text", { class: "axis-label", x: M.l + pw / 2, y: SH - 3, "text-anchor": "middle" },
    "dark: RMS, light: held-out RMS; +k: with findings 1..k"));
  return root;
}

function renderPlots(rep) {
  const before = residuals(rep, "baseline");
  const after = residuals(rep, "final");
  const worst = new Set(((rep.locate || {}).worst_samples || []).filter(Number.isInteger));
  const same = $("#same-scale").checked;
  const maxOf = (a) => Math.max(0, ...(a || []).filter(isNum));
  const b = rep.baseline || {}, f = rep.final || {};
  const shared = Math.max(maxOf(before), maxOf(after), 1e-9);
  const plots = [
    ["#plot-before", before, "baseline.residuals_mm", { rms: b.rms_mm, noise: undefined, worst, label: "before" }],
    ["#plot-after", after, "final.residuals_mm", { rms: f.rms_mm, noise: f.noise_mm, worst: new Set(), label: "after" }],
  ];
  for (const [sel, values, field, opts] of plots) {
    const body = $(`${sel} .plot-body`);
    if (!values) {
      const rms = sel === "#plot-before" ? b.rms_mm : f.rms_mm;
      body.replaceChildren(el("p", { class: "no-data", text:
        `The report carries no per-sample residuals (field ${field}); only the RMS is known: ${mm(rms)}.` }));
      continue;
    }
    const top = same ? shared : Math.max(maxOf(values), 1e-9);
    body.replaceChildren(residualChart(values, { ...opts, top }));
  }
  $("#plot-steps .plot-body").replaceChildren(stepsChart(rep));
}

// ------------------------------------------------------------------------------ locate, findings, notes

function renderLocate(loc) {
  $("#locate-summary").textContent = loc.summary || "";
  const ol = $("#worst-samples");
  ol.replaceChildren(...(loc.worst_samples || []).map((k) => el("li", { "data-sample": k, text: `sample ${k}` })));
  const dirs = Object.entries(loc.directions || {});
  $("#directions-box").hidden = dirs.length === 0;
  $("#directions tbody").replaceChildren(...dirs.map(([name, share]) => shareRow(name, share, `${Math.round(share * 100)}%`)));
  const corr = loc.correlations || [];
  $("#correlations-box").hidden = corr.length === 0;
  $("#correlations tbody").replaceChildren(...corr.map((c) => shareRow(c.feature, Math.abs(c.r), `r = ${num(c.r)}`)));
  const un = loc.unexplained || [];
  $("#unexplained").replaceChildren(...un.map((u) => el("li", { text:
    `Unexplained structure varies with ${u.varies_with} (p = ${pValue(u.p_value)})` })));
}

function shareRow(name, share, text) {
  const bar = el("span", { class: "share-bar" });
  bar.style.width = `${Math.max(0, Math.min(1, share)) * 100}%`;
  return el("tr", {}, el("th", { text: name }), el("td", { class: "share" }, bar), el("td", { class: "share-val", text }));
}

function paramRows(params) {
  const rows = [];
  for (const [key, value] of Object.entries(params || {})) {
    if (key.endsWith("_std") && key.slice(0, -4) in params) continue;
    const [name, unit] = unitOf(key);
    const std = params[`${key}_std`];
    const text = isNum(value) ? `${num(value)}${isNum(std) ? ` ± ${num(std)}` : ""}${unit ? ` ${unit}` : ""}` : String(value);
    rows.push(el("tr", { "data-param": key }, el("th", { text: name.replace(/_/g, " ") }), el("td", { text })));
  }
  return rows;
}

function evidenceRows(ev) {
  return Object.entries(ev || {}).map(([key, value]) => {
    let [name, unit] = unitOf(key);
    name = EVIDENCE[key] || name.replace(/_/g, " ");
    if (EVIDENCE[key]) unit = key.endsWith("_mm") ? "mm" : "";
    const text = Array.isArray(value) ? value.join(", ")
      : key === "p_value" ? pValue(value)
      : key === "structure_share" ? structureShare(value)
      : `${num(value)}${unit ? ` ${unit}` : ""}`;
    return el("tr", { "data-evidence": key }, el("th", { text: name }), el("td", { text }));
  });
}

function renderFindings(findings, robot = null) {
  $("#no-findings").hidden = findings.length > 0;
  const ol = $("#findings");
  ol.replaceChildren();
  findings.forEach((f, i) => {
    const li = el("li", { class: "finding", "data-effect": f.effect, "data-joint": f.joint ?? "" });
    // collapsible: the strongest finding open, the others one line each until opened
    const box = el("details", { class: "finding-box" });
    box.open = i === 0;
    const head = el("h3", {}, el("span", { class: "rank", text: `${i + 1}` }),
      el("span", { class: "title", text: findingTitle(f) }), el("span", { class: "headline", text: headline(f) }),
      el("code", { class: "code", text: f.effect }));
    box.append(el("summary", {}, head));
    li.append(box);
    box.append(el("p", { class: "explanation", text: f.explanation || "" }));
    const grid = el("div", { class: "finding-grid" });
    const p = el("table", { class: "params", "aria-label": "parameters" },
      el("caption", { text: "Parameters" }), el("tbody", {}, ...paramRows(f.parameters)));
    const fit = el("table", { class: "params", "aria-label": "fit with this finding" },
      el("caption", { text: "With this and earlier findings" }),
      el("tbody", {}, el("tr", {}, el("th", { text: "RMS" }), el("td", { text: mm(f.rms_mm) })),
        el("tr", {}, el("th", { text: "held-out RMS" }), el("td", { text: mm(f.heldout_rms_mm) }))));
    const ev = el("table", { class: "params evidence", "aria-label": "evidence" },
      el("caption", { text: "Evidence" }), el("tbody", {}, ...evidenceRows(f.evidence)));
    const words = signWords(f, robot);
    if (words) p.querySelector("tbody").append(el("tr", { "data-param": "sign" }, el("th", { text: "sign" }), el("td", { class: "sign-words", text: words })));
    grid.append(p, fit, ev);
    box.append(grid);
    ol.append(li);
  });
}

/** The value of a finding on its one line: "−0.824 ± 0.033 mm". */
function headline(f) {
  const P = f.parameters || {};
  const key = Object.keys(P).find((k) => isNum(P[k]) && !k.endsWith("_std") && !k.includes("_std_"));
  if (!key) return "";
  const [, unit] = unitOf(key);
  const std = P[`${key}_std`];
  return `${num(P[key])}${isNum(std) ? ` ± ${num(std)}` : ""}${unit ? ` ${unit}` : ""}`;
}

function noteItem(n, extra) {
  const li = el("li", { "data-effect": n.effect, "data-joint": n.joint ?? "" });
  li.append(el("strong", { text: findingTitle(n) }), `: ${n.reason || ""}`);
  if (extra) li.append(el("span", { class: "muted", text: ` (${extra})` }));
  return li;
}

/** The rigid model's parameters the poses cannot determine (report.identifiability). */
function identItem(n) {
  const li = el("li", { "data-effect": "rigid_setup", "data-joint": "" });
  li.append(el("strong", { text: (n.parameters || []).join(", ") }), `: ${n.reason || ""}. `,
    el("span", { text: `Would determine it: ${n.poses_that_would_determine_it || ""}.` }));
  return li;
}

/** The gear harmonics left out for too little travel, all joints on one line. */
function shortTravelItem(notes) {
  const li = el("li", { "data-effect": "gear_transmission_error", "data-joint": "" });
  const per = notes.map((n) => {
    const k = n.periods_per_turn;
    return `J${n.joint}: ${k.length > 1 ? `${k[0]}–${k[k.length - 1]}` : k[0]}`;
  }).join(", ");
  li.append(el("strong", { text: "Gear transmission error, harmonics per turn not tested" }),
    `: ${per}. Each joint's travel covers less than one period of them: over part of a period a gear error looks like a smooth trend and does not carry over to other poses; spread the joint over a full period (better two) to test them.`);
  return li;
}

function renderNotes(rep) {
  const all = rep.not_identifiable || [];
  const short = all.filter((n) => Array.isArray(n.periods_per_turn));
  const ni = all.filter((n) => !Array.isArray(n.periods_per_turn));
  const setup = ((rep.identifiability || {}).not_identifiable) || [];
  $("#not-identifiable").replaceChildren(...setup.map(identItem), ...ni.map((n) => noteItem(n)),
    ...(short.length ? [shortTravelItem(short)] : []));
  $("#notes-panel").hidden = all.length + setup.length === 0;
  // the best fit of a step beyond the limit of the possible (report.refused_as_implausible)
  const rf = rep.refused_as_implausible || [];
  $("#refused").replaceChildren(...rf.map((n) => noteItem(n)));
  $("#refused-panel").hidden = rf.length === 0;
  const wh = rep.withheld || [];
  $("#withheld").replaceChildren(...wh.map((n) => noteItem(n,
    isNum(n.p_value_with_structure) ? `p with the structure = ${pValue(n.p_value_with_structure)}` : "")));
  $("#withheld-panel").hidden = wh.length === 0;
}

function renderMore(rep) {
  $("#baseline-params tbody").replaceChildren(...paramRows((rep.baseline || {}).parameters));
  $("#report-json").textContent = JSON.stringify(rep, null, 1);
  const a = $("#report-link");
  if (rep.id !== undefined) {
    a.href = `/analysis/${rep.id}`;
    a.textContent = `GET /analysis/${rep.id}`;
  }
  $("#model-download").disabled = rep.id === undefined;
  $("#model-status").textContent = "";
}

/** Download the stored report's fitted robot-model/1 (GET /analysis/{id}/model). */
async function downloadModel() {
  const id = page.report && page.report.id;
  if (id === undefined) return;
  let model;
  try {
    model = await request("GET", `/analysis/${encodeURIComponent(id)}/model`);
  } catch (err) {
    const d = (err.detail && err.detail[0] && err.detail[0].msg) || err.message;
    $("#model-status").textContent = `No model: ${d}`;
    return;
  }
  const blob = new Blob([JSON.stringify(model, null, 1)], { type: "application/json" });
  const link = el("a", { href: URL.createObjectURL(blob), download: `robot-model-${id}.json` });
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(link.href), 0);
  $("#model-status").textContent = `robot-model-${id}.json: ${model.effects.length} effects; use it with pendant predict.`;
}

// ------------------------------------------------------------------------------ wiring

function init() {
  $("#file").addEventListener("change", (ev) => {
    const file = ev.target.files && ev.target.files[0];
    if (!file) return;
    busy(async () => {
      const text = await file.text();
      $("#paste").value = text;
      // choosing a file only reads it: Analyse (with the folds and seed as set) runs it
      setStatus(`Read ${file.name} (${text.length} characters): press Analyse.`);
    });
  });
  $("#analyse").addEventListener("click", () => busy(async () => {
    if (page.report && page.analysed === inputKey()) { // pressed again on the same input
      setStatus(`Already analysed: analysis ${page.report.id ?? ""}. Change the text, folds, seed or split to run again.`, "ok");
      return;
    }
    await analyseText($("#paste").value);
  }));
  $("#simulate").addEventListener("click", () => busy(async () => {
    let text;
    try {
      const r = await fetch("/example-recording.json");
      if (!r.ok) throw new Error(`${r.status} ${r.statusText}`);
      text = await r.text();
    } catch (err) {
      showError(new ApiError(0, [{ loc: [], msg: `no example recording: ${err.message}` }]), "", "Simulate");
      return;
    }
    $("#paste").value = text;
    $("#file").value = "";
    await analyseText(text);
  }));
  $("#model-download").addEventListener("click", () => busy(downloadModel));
  $("#same-scale").addEventListener("change", () => { if (page.report) renderPlots(page.report); });
  const stored = new URLSearchParams(location.search).get("analysis");
  const done = () => { document.body.dataset.ready = "1"; };
  if (stored) busy(() => loadStored(stored)).then(done);
  else done();
}

init();
