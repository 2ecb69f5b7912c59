// pendant: the browser teach pendant. Plain ES module, no build step, no libraries.
//
// Every panel talks to the REST service of this origin. A refused request (422) answers
// {"detail": [{"loc": ["body", ...field], "msg": reason}]}; showErrors() puts each msg beside
// the element whose data-loc (or name) is that field, else in the panel's own error line.

import { request, ApiError } from "/api.js";
import { axesLabel, describeSession, el, fmt, incrementUnit, isolate, num, parseNumbers } from "/ui.js";

const $ = (sel, root = document) => root.querySelector(sel);
const $$ = (sel, root = document) => [...root.querySelectorAll(sel)];
const AXES_XYZABC = ["X", "Y", "Z", "A", "B", "C"];
const POSE_KEYS = ["x", "y", "z", "a", "b", "c"];
const PARAM_FIELDS = {
  tool_no: { label: "Touching tool (tool number)", type: "int", min: 1, max: 16 },
  reference_tool_no: { label: "Reference tool (tool number)", type: "int", min: 1, max: 16 },
  fixed_tool_no: { label: "Fixed tool (base number)", type: "int", min: 1, max: 32 },
  known_points_mm: { label: "Known points in the new frame (mm): x y z per line", type: "points" },
  pose: { label: "Frame (x, y, z mm; a, b, c deg)", type: "pose" },
  ext_no: { label: "External kinematic (EX_KIN number)", type: "int", min: 1, max: 6 },
};
const TABLE_LABEL = { tool: "TOOL", base: "BASE", extkin: "EX_KIN" };

const state = {
  cid: null, // controller id
  controller: null,
  robot: null,
  methods: [],
  session: null,
  report: null,
  step: null, // the step the person is on (index)
  tools: [],
  bases: [],
  exts: [], // external kinematics (EX_KIN 1..6)
  targets: {}, // the slot last opened per table: each menu proposes its own (tool, base, extkin)
  me: undefined, // the user logged in (whoami), once asked
};

/** The external kinematics each ext menu calibrates (server.service.external.METHOD_KINDS). */
const EXT_KINDS = { "ext.root_point": ["turntable", "positioner"], "ext.linear_unit": ["linear_unit"],
                    "ext.positioner_2axis": ["positioner"] };

// Tests wait for `window.pendant.pending === 0` (no request in flight).
const pendant = { pending: 0, state, reloadTables: () => loadTables() };
window.pendant = pendant;

// ------------------------------------------------------------------------------ requests

/** Counts each request in pendant.pending and marks #main busy while any is in flight. */
const inFlight = {
  onStart() {
    pendant.pending += 1;
    $("#main").setAttribute("aria-busy", "true");
  },
  onEnd() {
    pendant.pending -= 1;
    if (pendant.pending === 0) $("#main").setAttribute("aria-busy", "false");
  },
};

/** `method` `path` with an optional JSON `body`, counted in flight (see web/api.js). */
const api = (method, path, body) => request(method, path, { body, ...inFlight });

const ctl = (suffix = "") => `/controllers/${state.cid}${suffix}`;

// ------------------------------------------------------------------------------ errors

function clearErrors(scope) {
  for (const e of $$(".err", scope)) e.textContent = "";
  for (const e of $$("[aria-invalid]", scope)) e.removeAttribute("aria-invalid");
}

function visible(e) {
  return !e.closest("[hidden]") && e.getClientRects().length > 0;
}

/** The visible element of `scope` that stands for API field `loc` (most specific match first). */
function fieldFor(scope, loc) {
  const parts = loc.filter((p, i) => !(i === 0 && ["body", "query", "path"].includes(p)));
  const aliases = [parts];
  if (parts[0] === "flange_poses") aliases.push(["points", ...parts.slice(1)]); // solver loc = step order
  for (const alias of aliases) {
    for (let n = alias.length; n > 0; n--) {
      const key = alias.slice(0, n).join(".");
      const found = [...scope.querySelectorAll(`[data-loc="${CSS.escape(key)}"], [name="${CSS.escape(key)}"]`)];
      const el = found.find(visible);
      if (el) return el;
    }
  }
  return null;
}

/** The error line beside `el`: its own .err child, or the nearest ancestor's. */
function errSlotFor(el) {
  for (let e = el; e && e !== document.body; e = e.parentElement) {
    const own = [...e.children].find((c) => c.classList.contains("err"));
    if (own) return own;
  }
  return null;
}

function panelErr(scope) {
  return [...scope.children].find((c) => c.classList.contains("panel-err")) || $(".panel-err", scope);
}

function showErrors(scope, err, fallback = null) {
  const fallbackSlot = (fallback && errSlotFor(fallback)) || panelErr(scope);
  if (!(err instanceof ApiError)) {
    fallbackSlot.textContent = String(err && err.message ? err.message : err);
    return;
  }
  const items = Array.isArray(err.detail) ? err.detail : [{ loc: [], msg: String(err.detail) }];
  for (const item of items) {
    const loc = item.loc || [];
    const el = fieldFor(scope, loc);
    const slot = el ? errSlotFor(el) : null;
    const target = slot || fallbackSlot;
    const text = item.msg || "refused";
    target.textContent = target.textContent ? `${target.textContent}; ${text}` : text;
    if (el) {
      const input = el.matches("input, select, textarea") ? el : el.querySelector("input, select, textarea");
      if (input) input.setAttribute("aria-invalid", "true");
    }
  }
}

/** Run an action of a panel: clear every message on the page (a message belongs to the
 * action that raised it, so the next action, in any panel, takes it away), then show any
 * failure beside the right field (an error naming no field of the panel goes beside
 * `fallback`, else to the panel's line). */
async function act(scope, fn, fallback = null) {
  clearErrors(document);
  $("#saved-note")?.remove();
  try {
    await fn();
  } catch (err) {
    showErrors(scope, err, fallback);
  }
}

/** The service's default aim (POST /robot/approach `noise_mm`), read from its OpenAPI schema
 * so the page states the value the service uses. */
async function loadAimDefault() {
  const spec = await api("GET", "/openapi.json");
  const v = spec.components.schemas.ApproachIn.properties.noise_mm.default;
  if (Number.isFinite(v)) $("#aim").value = String(v);
}

// ------------------------------------------------------------------------------ formatting

// num(), fmt(), el(): web/ui.js (shared with the analysis page)

function poseCells(row, pose) {
  row.replaceChildren(...POSE_KEYS.map((k) => el("td", { text: pose ? num(pose[k], 2) : "—", title: pose ? String(pose[k]) : "" })));
}

function slotName(table, no) {
  if (!no) return table === "tool" ? "flange" : "world";
  const rows = table === "tool" ? state.tools : state.bases;
  const e = rows.find((r) => r.number === no);
  return e && e.name ? e.name : "empty";
}

// ------------------------------------------------------------------------------ controller

async function loadControllers() {
  const list = await api("GET", "/controllers");
  const sel = $("#controller");
  sel.replaceChildren(...list.map((c) => el("option", { value: c.id, text: `${c.name} (${c.robot_name})` })));
  if (!list.length) {
    panelErr($("#topbar")).textContent = "no controller: create one with POST /controllers";
    return;
  }
  const keep = list.find((c) => c.id === state.cid) || list[0];
  sel.value = String(keep.id);
  await selectController(keep.id);
}

async function selectController(id) {
  state.cid = Number(id);
  state.controller = await api("GET", ctl());
  state.session = null;
  state.report = null;
  state.cell = null;
  await Promise.all([loadTables(), loadRobot()]);
  $("#robot-name").textContent = axesLabel(state.controller.robot_name, state.controller.dof, state.robot.external_axes);
  renderParams();
  for (const a of $$(".exports a")) a.href = ctl(`/export?format=${a.dataset.format}`);
  state.step = null;
  renderSession(); // with no session: lists the open ones to resume (none is taken over unasked)
  renderJogRows();
}

// ------------------------------------------------------------------------------ robot

async function loadRobot(robot) {
  state.robot = robot || (await api("GET", ctl("/robot")));
  renderRobot();
}

function renderRobot() {
  const r = state.robot;
  if (!r) return;
  poseCells($("#tcp-pose"), r.tcp_pose);
  poseCells($("#flange-pose"), r.flange_pose);
  $("#tcp-caption").textContent =
    `TCP in BASE ${r.active_base_no} (${slotName("base", r.active_base_no)}), ` +
    `TOOL ${r.active_tool_no} (${slotName("tool", r.active_tool_no)})`;
  $("#active-tool").value = String(r.active_tool_no);
  $("#active-base").value = String(r.active_base_no);
  // joint inputs follow the robot unless the person is typing into one
  for (const inp of $$("#jog-rows input[data-joint]")) {
    if (document.activeElement !== inp) inp.value = num(r.joints_deg[Number(inp.dataset.joint)], 3);
  }
  for (const out of $$("#jog-rows output[data-axis]")) {
    out.textContent = num(r.tcp_pose[POSE_KEYS[AXES_XYZABC.indexOf(out.dataset.axis)]], 3);
  }
  for (const out of $$("#jog-rows output[data-ext]")) {
    out.textContent = num((r.external_axes || {})[out.dataset.ext], 3);
  }
}

/** The cell's linear external axes (the rail, E4: mm); the others turn (deg). */
function linearAxes() {
  return Object.keys((state.robot && state.robot.external_axes) || {}).filter((a) => a === "E4");
}

function jogMode() {
  return $('#jog-panel input[name="mode"]:checked').value;
}

function renderJogRows() {
  const mode = jogMode();
  const rows = $("#jog-rows");
  const dof = state.controller ? state.controller.dof : 6;
  $("#inc-unit").textContent = incrementUnit(mode, linearAxes());
  const make = (axis, middle, dataLoc) =>
    el("div", { class: "field jog-row", "data-loc": dataLoc },
      el("span", { class: "axis", text: axis }),
      el("button", { type: "button", class: "jog", "aria-label": `Jog ${axis} minus`, "data-axis": axis, "data-sign": "-1", text: "−" }),
      middle,
      el("button", { type: "button", class: "jog", "aria-label": `Jog ${axis} plus`, "data-axis": axis, "data-sign": "1", text: "+" }),
      el("span", { class: "err", role: "alert" }));
  const list = [];
  if (mode === "joint") {
    for (let i = 0; i < dof; i++) {
      const inp = el("input", { type: "number", step: "any", name: `joints_deg.${i}`, "data-joint": i,
                                "aria-label": `A${i + 1} (deg)` });
      list.push(make(`A${i + 1}`, inp, `joints_deg.${i}`));
    }
    const ext = state.robot && state.robot.external_axes;
    for (const axis of Object.keys(ext || {})) { // the cell's external axes: E1..E4
      const unit = linearAxes().includes(axis) ? "mm" : "deg";
      list.push(make(axis, el("output", { "data-ext": axis, "aria-label": `${axis} (${unit})` }), `axis.${axis}`));
    }
    $("#move-joints").hidden = false;
  } else {
    for (const axis of AXES_XYZABC) {
      list.push(make(axis, el("output", { "data-axis": axis, "aria-label": `${axis} of the TCP` }), `axis.${axis}`));
    }
    $("#move-joints").hidden = true;
  }
  rows.replaceChildren(...list);
  renderRobot();
}

async function jog(axis, sign) {
  if (axis.startsWith("E")) { // an external axis: jogged like a joint (deg; the rail mm)
    const raw = Number($("#increment").value.trim());
    if (!Number.isFinite(raw)) throw new ApiError(422, [{ loc: ["body", "increment"], msg: "give the increment as a number" }]);
    await loadRobot(await api("POST", ctl("/robot/jog"), { mode: "joint", axis, increment: sign * raw }));
    return;
  }
  const raw = $("#increment").value.trim();
  const increment = raw === "" ? NaN : sign * Number(raw);
  if (!Number.isFinite(increment)) {
    throw new ApiError(422, [{ loc: ["body", "increment"], msg: "give the increment as a number" }]);
  }
  const robot = await api("POST", ctl("/robot/jog"), { mode: jogMode(), axis, increment });
  await loadRobot(robot);
}

async function moveJoints() {
  const joints = $$("#jog-rows input[data-joint]").map((i) => Number(i.value));
  const bad = joints.findIndex((q) => !Number.isFinite(q));
  if (bad >= 0) throw new ApiError(422, [{ loc: ["body", "joints_deg", bad], msg: "give the joint value in degrees" }]);
  await loadRobot(await api("PUT", ctl("/robot/joints"), { joints_deg: joints }));
}

async function setActive(which, value) {
  const body = which === "tool" ? { tool_no: Number(value) } : { base_no: Number(value) };
  await loadRobot(await api("PUT", ctl("/robot/active"), body));
}

// ------------------------------------------------------------------------------ tables

async function loadTables() {
  const [tools, bases, exts] = await Promise.all([api("GET", ctl("/tools")), api("GET", ctl("/bases")),
                                                  api("GET", ctl("/external-kinematics"))]);
  state.tools = tools;
  state.bases = bases;
  state.exts = exts;
  renderTable($("#tool-table tbody"), tools, "tool");
  renderTable($("#base-table tbody"), bases, "base");
  // an external kinematic as a table row: its root frame, its kind and axes
  renderTable($("#ext-table tbody"), exts.map((e) => ({ ...e, pose: e.root,
    kind: e.kind === "none" ? "none" : `${e.kind} ${e.axes.join(",")}` })), "extkin");
  const opts = (rows, table) => [el("option", { value: 0, text: `0 ${table === "tool" ? "flange" : "world"}` }),
    ...rows.map((e) => el("option", { value: e.number, text: `${e.number} ${e.name || ""}`.trim() }))];
  const at = $("#active-tool");
  const ab = $("#active-base");
  at.replaceChildren(...opts(tools, "tool"));
  ab.replaceChildren(...opts(bases, "base"));
  if (state.robot) renderRobot();
}

function renderTable(tbody, rows, table) {
  tbody.replaceChildren(...rows.map((e) => {
    const p = e.pose;
    const used = e.name || POSE_KEYS.some((k) => p[k] !== 0) || (e.kind !== "none" && table === "extkin");
    const pv = e.provenance;
    const prov = [];
    if (used && pv && pv.method) {
      prov.push(el("div", { text: pv.method }));
      const q = [];
      if (pv.error_max_mm !== null && pv.error_max_mm !== undefined) q.push(`max ${fmt(pv.error_max_mm)} mm`);
      if (pv.session_id) q.push(`session ${pv.session_id}`);
      if (q.length) prov.push(el("div", { text: q.join(" · ") }));
      const by = pv.updated_by ? ` by ${pv.updated_by}` : "";
      if (pv.updated_at) prov.push(el("div", { class: "changed", text: `changed${by} at ${pv.updated_at.slice(0, 16).replace("T", " ")}` }));
    }
    const width = Math.max(...POSE_KEYS.map((k) => num(p[k]).length)) + 1; // aligned, no wider than needed
    const cols = (keys) => keys.map((k) => num(p[k]).padStart(width)).join("");
    const frame = used ? [el("div", { text: cols(["x", "y", "z"]) }), el("div", { class: "abc", text: cols(["a", "b", "c"]) })] : [];
    return el("tr", { class: used ? "used" : "unused", "data-number": e.number, "aria-label": `${table} ${e.number}` },
      el("td", { class: "num", text: String(e.number) }),
      el("td", { class: "name", text: e.name || "" }),
      el("td", { text: used ? e.kind.replace("_", " ") : "" }),
      el("td", { class: "frame" }, ...frame),
      el("td", { class: "prov" }, ...prov));
  }));
}

function showTab(which) {
  for (const t of ["tool", "base", "ext"]) {
    $(`#tab-${t}`).setAttribute("aria-selected", String(t === which));
    $(`#${t}-wrap`).hidden = t !== which;
  }
}

// ------------------------------------------------------------------------------ wizard

async function loadMethods() {
  state.methods = await api("GET", "/methods");
  const sel = $("#method");
  const groups = new Map();
  for (const m of state.methods) {
    if (!groups.has(m.menu)) groups.set(m.menu, el("optgroup", { label: m.menu.replace("_", " ") }));
    groups.get(m.menu).append(el("option", { value: m.name, text: m.title }));
  }
  sel.replaceChildren(...groups.values());
  renderParams();
}

function methodOf(name) {
  return state.methods.find((m) => m.name === name);
}

/** The slot a menu proposes: an ext menu the EX_KIN of the kind it calibrates, the others the
 * slot last opened in their own table (never a number carried over from another table). */
function proposedSlot(m) {
  const kinds = EXT_KINDS[m.name];
  if (kinds) {
    const e = state.exts.find((x) => kinds.includes(x.kind));
    if (e) return e.number;
  }
  return state.targets[m.table] || 1;
}

function renderParams() {
  const m = methodOf($("#method").value);
  if (!m) return;
  const t = $("#target_no");
  t.max = { tool: 16, base: 32, extkin: 6 }[m.table];
  t.value = proposedSlot(m);
  $("#target-label").textContent = { tool: "Tool number", base: "Base number",
                                     extkin: "External kinematic (EX_KIN)" }[m.table];
  const box = $("#params");
  const fields = [];
  for (const [name, help] of Object.entries(m.required_params)) {
    const spec = PARAM_FIELDS[name] || { label: name, type: "text" };
    let input;
    if (spec.type === "int") {
      input = el("input", { id: `param-${name}`, name, type: "number", min: spec.min, max: spec.max, value: 1,
                            "aria-label": spec.label });
    } else if (spec.type === "points") {
      input = el("textarea", { id: `param-${name}`, name, rows: 4, "aria-label": spec.label, placeholder: "30 30 0\n220 20 0\n190 160 0" });
    } else if (spec.type === "pose") {
      input = el("span", { class: "pose-inputs", "data-loc": "params.pose" },
        ...POSE_KEYS.map((k) => el("input", { name: k, "data-loc": `params.pose.${k}`, type: "number", step: "any",
                                               value: 0, "aria-label": `pose ${k}` })));
    } else {
      input = el("input", { id: `param-${name}`, name, "aria-label": spec.label });
    }
    fields.push(el("div", { class: "field", "data-loc": `params.${name}`, title: help },
      el("label", { for: `param-${name}`, text: spec.label }), input, el("span", { class: "err", role: "alert" })));
  }
  box.replaceChildren(...fields);
  if (m.required_params.known_points_mm) prefillKnownPoints(m).catch((err) => showErrors($("#wizard"), err));
}

/** Indirect menus: start from the marked points of the cell's drawing (point_1, point_2, ...). */
async function prefillKnownPoints(m) {
  if (!state.cid) return;
  const cell = state.cell || (state.cell = await api("GET", ctl("/cell")));
  const pts = m.menu === "base" ? cell.base_points_mm : cell.workpiece_points_mm;
  const lines = Object.entries(pts).filter(([k]) => k.startsWith("point_")).map(([, p]) => p.join(" "));
  const area = $('#params textarea[name="known_points_mm"]');
  if (area && !area.value) area.value = lines.join("\n");
}

function readParams(m) {
  const params = {};
  for (const name of Object.keys(m.required_params)) {
    const spec = PARAM_FIELDS[name] || { type: "text" };
    const field = $(`#params [data-loc="params.${name}"]`);
    if (spec.type === "int") params[name] = Number($(`[name="${name}"]`, field).value);
    else if (spec.type === "points") {
      const lines = $("textarea", field).value.split("\n").map((l) => l.trim()).filter(Boolean);
      params[name] = lines.map((l) => parseNumbers(l));
      const bad = params[name].findIndex((p) => p.length !== 3 || p.some((v) => !Number.isFinite(v)));
      if (bad >= 0) throw new ApiError(422, [{ loc: ["body", "params", name, bad], msg: `line ${bad + 1}: give x y z in mm` }]);
    } else if (spec.type === "pose") {
      params[name] = Object.fromEntries(POSE_KEYS.map((k) => [k, Number($(`[name="${k}"]`, field).value)]));
    } else params[name] = $("input", field).value;
  }
  return params;
}

async function openSession() {
  const m = methodOf($("#method").value);
  const body = { method: m.name, target_no: Number($("#target_no").value), params: readParams(m) };
  state.session = await api("POST", ctl("/sessions"), body);
  state.targets[m.table] = body.target_no;
  state.report = null;
  state.step = null;
  renderSession();
}

function currentStep() {
  const s = state.session;
  if (!s) return null;
  if (state.step !== null && s.steps.some((st) => st.index === state.step)) return s.steps.find((st) => st.index === state.step);
  return s.steps.find((st) => st.required && !st.filled) || suggestedStep();
}

/** After the required steps, the next optional step at the orientation the report suggests
 * (`next_orientation`, the one that shrinks the TCP's uncertainty most), as a Move to. */
function suggestedStep() {
  const s = state.session;
  const r = state.report || (s && s.report);
  if (s && r && s.extra_steps_allowed && r.extras && Number.isFinite(r.extras.next_axis_value_deg)) {
    // ext menus: the axis value the report suggests for the next touch-up of the mark
    const first = s.steps.find((st) => st.required && st.target && st.external_axes);
    if (!first) return null;
    const axis = Object.keys(first.external_axes)[0];
    const v = r.extras.next_axis_value_deg;
    return { index: Math.max(...s.steps.map((st) => st.index)) + 1, required: false, filled: false,
             suggested: true, target: first.target, tilt_deg: first.tilt_deg, around_deg: first.around_deg,
             spin_deg: 0, tool_point_mm: null, external_axes: { ...first.external_axes, [axis]: v }, // the whole chain
             prompt: `Optional: touch the mark with ${axis} at ${fmt(v, 0)} deg, as the report suggests (Move to goes there), then Compute again` };
  }
  if (!s || !r || !r.next_orientation || !s.extra_steps_allowed) return null;
  const first = s.steps.find((st) => st.required && st.target);
  if (!first) return null;
  const index = Math.max(...s.steps.map((st) => st.index)) + 1;
  return { index, required: false, filled: false, suggested: true, target: first.target,
           flange_orientation: r.next_orientation, tool_point_mm: null,
           prompt: `Optional: touch up from the orientation the report suggests (Move to goes there), then Compute again` };
}

function renderSession() {
  const s = state.session;
  const wizard = $("#wizard");
  $("#open-form").hidden = !!s;
  $("#session").hidden = !s;
  renderReport();
  if (!s) {
    loadOpenSessions().catch((err) => showErrors(wizard, err));
    return;
  }
  $("#session-title").textContent = `${s.title} → ${TABLE_LABEL[s.target_table]} ${s.target_no}`;
  $("#session-state").textContent = s.state;
  $("#session-params").replaceChildren(...Object.entries(s.params || {}).map(([k, v]) =>
    el("span", { class: "field param", "data-loc": `params.${k}` },
      el("span", { class: "param-text", text: `${k} = ${typeof v === "object" ? JSON.stringify(v) : v}` }),
      el("span", { class: "err", role: "alert" }))));
  const steps = $("#steps");
  const cur = currentStep();
  steps.replaceChildren(...s.steps.map((st) => el("li", {
      class: `step${st.filled ? " filled" : ""}${cur && cur.index === st.index ? " current" : ""}`,
      "data-loc": `points.${st.index}` },
    el("button", { type: "button", class: "step-pick", "aria-label": `Step ${st.index + 1}: ${st.prompt}${st.filled ? " (taught)" : ""}`,
                   onclick: () => { state.step = st.index; renderSession(); } },
      el("span", { class: "tick", text: st.filled ? "✓" : String(st.index + 1) }),
      // the service's prompts for optional steps already say "optional"
      el("span", { class: "step-text", text: st.prompt + (st.required || /optional/i.test(st.prompt) ? "" : " (optional)") })),
    el("span", { class: "err", role: "alert" }))));
  const n = s.steps.filter((st) => st.required).length;
  const done = s.steps.filter((st) => st.required && st.filled).length;
  const lb = s.method === "tool.light_barrier";
  $("#paste-ext-field").hidden = !s.method.startsWith("ext.");
  $("#run-cycle").hidden = !lb;
  $("#touch-up").hidden = lb;
  $("#move-to").closest(".field").hidden = !(cur && cur.target);
  $(".aim", wizard).hidden = !(cur && cur.target);
  if (cur && cur.suggested) {
    $("#step-label").textContent = `Step ${cur.index + 1} (optional, ${s.extra_steps_allowed} left)`;
    $("#prompt").textContent = cur.prompt;
    $("#touch-up").hidden = false;
  } else if (cur) {
    $("#step-label").textContent = `Step ${cur.index + 1} of ${Math.max(n, cur.index + 1)}` + (cur.filled ? " (taught; touch up again to re-teach)" : "");
    $("#prompt").textContent = cur.prompt;
  } else if (lb) {
    $("#step-label").textContent = `${s.steps.length} beam triggers recorded`;
    $("#prompt").textContent = "Run the measuring cycle: the robot sweeps the tool through the crossed beams, then Compute.";
  } else {
    const taught = s.steps.filter((st) => st.filled).length;
    $("#step-label").textContent = taught > n ? `All ${n} steps taught, ${taught - n} optional` : `All ${n} steps taught`;
    const what = s.method.startsWith("ext.") ? "an axis value" : "an orientation"; // ext menus: E1 at -45 deg
    $("#prompt").textContent = n ? (s.extra_steps_allowed ? `Compute: the report then suggests ${what} for an optional step (${s.extra_steps_allowed} left), or touch up again here.` : "Compute.")
                                 : "No touch-up needed: Compute.";
    $("#touch-up").hidden = !(n && s.extra_steps_allowed);
  }
  $("#compute").textContent = done < n ? `Compute (${done}/${n} taught)` : "Compute";
  $("#compute").classList.toggle("primary", done >= n);
  $("#touch-up").classList.toggle("primary", !!cur);
}

async function refreshSession(s) {
  state.session = s || (await api("GET", ctl(`/sessions/${state.session.id}`)));
  if (state.session.state !== "computed") state.report = null;
  renderSession();
}

/** R = Rz(a) Ry(b) Rx(c) of a KUKA pose (degrees), as rows: the flange's orientation. */
function rotationOf(p) {
  const r = Math.PI / 180;
  const [ca, sa, cb, sb, cc, sc] = [Math.cos(p.a * r), Math.sin(p.a * r), Math.cos(p.b * r),
                                    Math.sin(p.b * r), Math.cos(p.c * r), Math.sin(p.c * r)];
  return [[ca * cb, ca * sb * sc - sa * cc, ca * sb * cc + sa * sc],
          [sa * cb, sa * sb * sc + ca * cc, sa * sb * cc - ca * sc],
          [-sb, cb * sc, cb * cc]];
}

/** An optional step already taught goes back where it was taught (the suggested orientation or
 * axis value the person used then), not to the service's default for that step. */
function whereTaught(st) {
  const p = !st.required && st.filled && st.point;
  if (!p || st.tool_point_mm) return st;
  if (st.external_axes) { // ext menus: the axis values it was touched at
    const taught = p.external_axes || {};
    return { ...st, external_axes: Object.fromEntries(Object.entries(st.external_axes)
      .map(([k, v]) => [k, taught[k] ?? v])) };
  }
  return p.flange_pose ? { ...st, flange_orientation: rotationOf(p.flange_pose) } : st;
}

async function moveTo() {
  const current = currentStep();
  if (!current || !current.target) return;
  const st = whereTaught(current);
  if (st.external_axes) { // ext menus: the external axes go to the step's values first
    await loadRobot(await api("PUT", ctl("/robot/external"), { values: st.external_axes }));
  }
  const body = st.flange_orientation
    ? { target: st.target, flange_orientation: st.flange_orientation }
    : { target: st.target, tilt_deg: st.tilt_deg, around_deg: st.around_deg, spin_deg: st.spin_deg };
  if (st.tool_point_mm) body.tool_point_mm = st.tool_point_mm;
  if ($("#ideal-aim").checked) body.noise_mm = 0;
  else if ($("#aim").value.trim() !== "") body.noise_mm = Number($("#aim").value); // the service judges it
  await loadRobot(await api("POST", ctl("/robot/approach"), body));
}

async function touchUp(extraBody = {}) {
  const st = currentStep();
  const body = { ...extraBody };
  if (st) body.step = st.index;
  const s = await api("POST", ctl(`/sessions/${state.session.id}/touch-up`), body);
  state.step = null;
  await refreshSession(s);
}

async function touchUpJoints() {
  const text = $("#paste-joints").value.trim();
  const joints = parseNumbers(text);
  if (!joints.length || joints.some((q) => !Number.isFinite(q))) {
    throw new ApiError(422, [{ loc: ["body", "joints_deg"], msg: "paste the joint values in degrees, e.g. 0, -90, 90, 0, 90, 0" }]);
  }
  const body = { joints_deg: joints };
  const ext = $("#paste-ext").value.trim();
  if (!$("#paste-ext-field").hidden && ext) { // ext menus: the external axis values recorded with them
    const values = parseNumbers(ext);
    if (values.some((v) => !Number.isFinite(v)) || values.length > 6) {
      throw new ApiError(422, [{ loc: ["body", "external_axes"], msg: "give E1, E2, ... as numbers, e.g. 45, 0, 0, 0" }]);
    }
    body.external_axes = Object.fromEntries(values.map((v, i) => [`E${i + 1}`, v]));
  }
  await touchUp(body);
}

async function runCycle() {
  const out = await api("POST", ctl(`/sessions/${state.session.id}/run-cycle`));
  await refreshSession(out.session);
  await loadRobot();
}

async function compute() {
  state.report = await api("POST", ctl(`/sessions/${state.session.id}/compute`));
  state.session = await api("GET", ctl(`/sessions/${state.session.id}`));
  renderSession();
  $("#report").scrollIntoView({ block: "nearest" });
}

/** Save; a slot of another kind (or a named slot not calibrated here) answers 409 naming it:
 * the person is asked, and only a yes saves (with confirm=true). */
async function save() {
  const path = ctl(`/sessions/${state.session.id}/save`);
  let entry;
  try {
    entry = await api("POST", path);
  } catch (err) {
    const d = err instanceof ApiError && err.status === 409 && Array.isArray(err.detail) ? err.detail[0] : null;
    if (!d || !d.loc || d.loc[1] !== "confirm") throw err;
    const what = d.msg.split(/[:;] save with/)[0]; // the slot's kind and name, what it would become
    if (!window.confirm(`${what}.\n\nReplace it?`)) {
      throw new ApiError(409, [{ loc: ["query", "confirm"], msg: `not saved: ${what}` }]);
    }
    entry = await api("POST", `${path}?confirm=true`);
  }
  state.session = null;
  state.report = null;
  renderSession();
  await loadTables();
  const table = entry.root ? "extkin" : entry.table; // an external kinematic has a root frame
  const pose = entry.root || entry.pose;
  showTab(table === "extkin" ? "ext" : table);
  await loadRobot();
  const note = $("#wizard .panel-err");
  note.textContent = "";
  $("#saved-note")?.remove();
  $("#open-form").append(el("p", { id: "saved-note", class: "saved", role: "status",
    text: `Saved into ${TABLE_LABEL[table]} ${entry.number} (${isolate(entry.name)}): ` +
          `${num(pose.x)} ${num(pose.y)} ${num(pose.z)} / ${num(pose.a)} ${num(pose.b)} ${num(pose.c)}` }));
}

async function discard() {
  const s = state.session;
  const taught = s.steps.filter((st) => st.filled).length;
  const what = state.report ? "the computed result and " : "";
  if (!window.confirm(`Discard ${s.title} → ${TABLE_LABEL[s.target_table]} ${s.target_no}? ` +
                      `This drops ${what}${taught} touch-up${taught === 1 ? "" : "s"}; nothing is written.`)) return;
  await api("POST", ctl(`/sessions/${state.session.id}/discard`));
  state.session = null;
  state.report = null;
  renderSession();
}

// ------------------------------------------------------------------------------ open sessions

/** Who is logged in (`/auth/me`'s user), asked once; null when the service does not say. */
async function whoami() {
  if (state.me === undefined) state.me = await api("GET", "/auth/me").then((me) => me.user, () => null);
  return state.me;
}

/** The controller's unfinished sessions (open or computed), listed above Open session with
 * their menu, slot, points taught and who opened them (the viewer's own marked "yours");
 * Resume takes the one the person picks. A session opened elsewhere (a script, another page,
 * another user) is never taken over without being picked. */
async function loadOpenSessions() {
  const cid = state.cid;
  const [all, me] = await Promise.all([api("GET", ctl("/sessions")), whoami()]);
  const open = all.filter((s) => s.state === "open" || s.state === "computed");
  if (cid !== state.cid || state.session) return; // the person moved on meanwhile
  const box = $("#open-sessions");
  box.hidden = !open.length;
  $("#open-sessions-h").textContent = `Open sessions (${open.length}): resume one, or open a new one below`;
  $("#open-sessions ul").replaceChildren(...open.slice().reverse().map((s) => el("li", {
      "data-session": s.id, class: me && s.opened_by === me ? "mine" : null },
    el("span", { class: "session-text", text: describeSession(s, TABLE_LABEL[s.target_table], me) }),
    el("button", { type: "button", class: "small", "aria-label": `Resume session ${s.id}`, text: "Resume",
                   onclick: () => act($("#wizard"), () => resumeSession(s.id)) }))));
}

async function resumeSession(id) {
  state.session = await api("GET", ctl(`/sessions/${id}`)); // keeps its ETag for the next command
  state.report = state.session.state === "computed" ? state.session.report : null;
  state.step = null;
  renderSession();
}

// ------------------------------------------------------------------------------ report

function stat(label, value, unit = "") {
  return el("div", { class: "stat" }, el("span", { class: "stat-label", text: label }),
    el("span", { class: "stat-value", text: value === null || value === undefined ? "—" : `${fmt(value)}${unit ? " " + unit : ""}` }));
}

/** Residual per touch-up as bars (inline SVG); the bad point red, its threshold dashed. */
function residualChart(r) {
  const NS = "http://www.w3.org/2000/svg";
  const values = r.residuals_mm || [];
  const W = 520, H = 132, left = 64, right = 12, top = 14, bottom = 28;
  const threshold = r.bad_point ? r.bad_point.threshold_mm : null;
  const loo = r.bad_point ? r.bad_point.residual_mm : null; // its distance from the fit of the others
  const vmax = Math.max(...values, threshold || 0, loo || 0, 0.001); // exact touch-ups: a flat 1 µm scale
  const svg = document.createElementNS(NS, "svg");
  const s = (tag, attrs, text) => {
    const e = document.createElementNS(NS, tag);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    return e;
  };
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  svg.setAttribute("class", "chart");
  svg.setAttribute("role", "img");
  svg.setAttribute("aria-label", `Residual per touch-up, mm: ${values.map((v) => fmt(v)).join(", ")}` +
    (r.bad_point ? `; touch-up ${r.bad_point.index + 1} is ${fmt(loo)} mm off the fit of the others` : ""));
  const ph = H - top - bottom, pw = W - left - right;
  svg.append(s("line", { x1: left, y1: top + ph, x2: W - right, y2: top + ph, class: "axis" }));
  svg.append(s("line", { x1: left, y1: top, x2: left, y2: top + ph, class: "axis" }));
  for (const f of [0, 0.5, 1]) {
    const y = top + ph - f * ph;
    svg.append(s("text", { x: left - 6, y: y + 4, "text-anchor": "end", class: "tick-label" }, fmt(f * vmax)));
    if (f > 0) svg.append(s("line", { x1: left, y1: y, x2: W - right, y2: y, class: "grid" }));
  }
  svg.append(s("text", { x: 4, y: top - 2, class: "tick-label" }, "mm"));
  const n = Math.max(values.length, 1);
  const slot = pw / n;
  const bw = Math.min(48, slot * 0.6);
  values.forEach((v, i) => {
    const h = (v / vmax) * ph;
    const x = left + slot * i + (slot - bw) / 2;
    const bad = r.bad_point && r.bad_point.index === i;
    const rect = s("rect", { x, y: top + ph - h, width: bw, height: Math.max(h, 0.5), class: bad ? "bar bad" : "bar" });
    rect.append(s("title", {}, `touch-up ${i + 1}: ${fmt(v)} mm`));
    svg.append(rect);
    if (bad) { // dashed outline: how far it is from the fit of the others (what the threshold judges)
      const hl = (loo / vmax) * ph;
      const o = s("rect", { x, y: top + ph - hl, width: bw, height: hl, class: "loo" });
      o.append(s("title", {}, `touch-up ${i + 1}: ${fmt(loo)} mm off the fit of the others`));
      svg.append(o);
      svg.append(s("text", { x: x + bw / 2, y: top + ph - hl - 3, "text-anchor": "middle", class: "tick-label loo-label" }, fmt(loo)));
    }
    svg.append(s("text", { x: x + bw / 2, y: top + ph + 14, "text-anchor": "middle", class: "tick-label" }, String(i + 1)));
  });
  if (threshold) {
    const y = top + ph - (threshold / vmax) * ph;
    svg.append(s("line", { x1: left, y1: y, x2: W - right, y2: y, class: "threshold" }));
  }
  svg.append(s("text", { x: left + pw / 2, y: H - 2, "text-anchor": "middle", class: "tick-label" }, "touch-up"));
  return svg;
}

/** Root point: the marks and the fitted circle seen along the axis (the root frame's XY plane,
 * its centre at the origin, x towards the mark at axis value 0), as inline SVG. */
function topView(r) {
  const NS = "http://www.w3.org/2000/svg";
  const tv = r.extras.top_view;
  const pts = tv.points_mm || [];
  const radius = tv.radius_mm || Math.max(...pts.map(([x, y]) => Math.hypot(x, y)), 1);
  const S = 240, pad = 28, k = (S / 2 - pad) / radius;
  const s = (tag, attrs, text) => {
    const e = document.createElementNS(NS, tag);
    for (const [a, v] of Object.entries(attrs)) e.setAttribute(a, v);
    if (text !== undefined) e.textContent = text;
    return e;
  };
  const X = (x) => S / 2 + k * x, Y = (y) => S / 2 - k * y;
  const svg = s("svg", { viewBox: `0 0 ${S} ${S}`, class: "chart top-view", role: "img", id: "top-view",
                         "aria-label": `Top view along the axis: ${pts.length} marks on the fitted circle of radius ${fmt(radius, 2)} mm` });
  svg.append(s("circle", { cx: X(0), cy: Y(0), r: k * radius, class: "fit-circle" }));
  svg.append(s("line", { x1: X(-radius * 0.08), y1: Y(0), x2: X(radius * 0.08), y2: Y(0), class: "axis" }));
  svg.append(s("line", { x1: X(0), y1: Y(-radius * 0.08), x2: X(0), y2: Y(radius * 0.08), class: "axis" }));
  svg.append(s("line", { x1: X(0), y1: Y(0), x2: X(radius), y2: Y(0), class: "grid" }));
  pts.forEach(([x, y], i) => {
    const bad = r.bad_point && r.bad_point.index === i;
    const dot = s("circle", { cx: X(x), cy: Y(y), r: 4, class: bad ? "mark bad" : "mark" });
    dot.append(s("title", {}, `touch-up ${i + 1}: ${fmt(r.residuals_mm[i])} mm off the circle`));
    svg.append(dot);
    svg.append(s("text", { x: X(x * 1.12), y: Y(y * 1.12) + 4, "text-anchor": "middle", class: "tick-label" }, String(i + 1)));
  });
  svg.append(s("text", { x: 4, y: 12, class: "tick-label" }, `centre, r ${fmt(radius, 1)} mm; x: the mark at axis 0`));
  return svg;
}

function renderReport() {
  const r = state.report;
  const sec = $("#report");
  sec.hidden = !r;
  if (!r) return;
  const s = state.session;
  $("#report-h").textContent = `Report: ${s ? s.title : r.method}`;
  const f = r.frame;
  const body = $("#report-body");
  const frameRow = el("table", { class: "pose-table", "aria-label": "Result frame" },
    el("caption", { text: s ? `Result for ${TABLE_LABEL[s.target_table]} ${s.target_no}` : "Result" }),
    el("thead", {}, el("tr", {}, ...AXES_XYZABC.map((a) => el("th", { text: a })))),
    el("tbody", {}, el("tr", {}, ...POSE_KEYS.map((k) => el("td", { text: num(f[k]) })))));
  const stats = el("div", { class: "stats" },
    stat("Max", r.max_error_mm, "mm"), stat("Mean", r.mean_error_mm, "mm"), stat("RMS", r.rms_error_mm, "mm"),
    stat("95% position", r.position_bound95_mm, "mm"),
    ...(r.angle_bound95_deg !== null ? [stat("95% angle", r.angle_bound95_deg, "deg")] : []),
    ...(r.max_error_deg !== null ? [stat("Max angle", r.max_error_deg, "deg")] : []),
    ...(r.tre_mm !== null ? [stat("TRE", r.tre_mm, "mm")] : []),
    ...(r.sigma_mm !== null ? [stat("σ touch-up", r.sigma_mm, "mm")] : []));
  const notes = el("ul", { class: "notes", "aria-label": "Warnings" });
  if (r.bad_point) notes.append(el("li", { class: "warning bad-point", text: `Bad point: ${r.bad_point.message}` }));
  for (const w of r.warnings) {
    if (r.bad_point && w.code === "bad_point") continue; // said once, above
    notes.append(el("li", { class: w.severity === "error" ? "error" : "warning", text: `${w.severity}: ${w.message}` }));
  }
  if (!r.bad_point && !r.warnings.length) notes.append(el("li", { class: "ok", text: "No warnings." }));
  const next = suggestedStep();
  const offer = next ? `. Or press Move to in Calibration: it goes to that ${next.external_axes ? "axis value" : "orientation"}.` : "";
  const guidance = r.guidance ? el("p", { class: "guidance" }, el("strong", { text: "Guidance: " }), r.guidance + offer) : null;
  const top = r.extras && r.extras.top_view ? [topView(r)] : [];
  // the threshold's label under the chart, not over the bars (it covered bars 4 and 5)
  const legend = r.bad_point ? el("p", { class: "chart-legend", id: "chart-legend",
    text: `Dashed line: allowed off the others ${fmt(r.bad_point.threshold_mm)} mm; dashed outline: touch-up ` +
          `${r.bad_point.index + 1} off the fit of the others ${fmt(r.bad_point.residual_mm)} mm` }) : null;
  body.replaceChildren(frameRow, stats, residualChart(r), ...(legend ? [legend] : []), ...top, notes,
                       ...(guidance ? [guidance] : []));
  if (s) $("#save").textContent = `Save into ${TABLE_LABEL[s.target_table]} ${s.target_no}`;
}

// ------------------------------------------------------------------------------ wiring

function wire() {
  const top = $("#topbar");
  $("#controller").addEventListener("change", (e) => act(top, () => selectController(e.target.value)));
  $("#active-tool").addEventListener("change", (e) => act(top, () => setActive("tool", e.target.value)));
  $("#active-base").addEventListener("change", (e) => act(top, () => setActive("base", e.target.value)));

  const jogPanel = $("#jog-panel");
  for (const r of $$('input[name="mode"]', jogPanel)) r.addEventListener("change", () => { clearErrors(jogPanel); renderJogRows(); });
  for (const b of $$("[data-inc]", jogPanel)) b.addEventListener("click", () => { $("#increment").value = b.dataset.inc; });
  $("#jog-rows").addEventListener("click", (e) => {
    const b = e.target.closest("button.jog");
    if (b) act(jogPanel, () => jog(b.dataset.axis, Number(b.dataset.sign)), b.closest(".jog-row"));
  });
  $("#move-joints").addEventListener("click", () => act(jogPanel, moveJoints));
  $("#home").addEventListener("click", () => act(jogPanel, async () => loadRobot(await api("POST", ctl("/robot/home")))));

  const wizard = $("#wizard");
  $("#method").addEventListener("change", () => { clearErrors(wizard); renderParams(); });
  $("#open-session").addEventListener("click", () => { $("#saved-note")?.remove(); act(wizard, openSession); });
  $("#move-to").addEventListener("click", () => act(wizard, moveTo, $("#move-to")));
  $("#touch-up").addEventListener("click", () => act(wizard, () => touchUp(), $("#current")));
  $("#touch-up-joints").addEventListener("click", () => act(wizard, touchUpJoints));
  $("#run-cycle").addEventListener("click", () => act(wizard, runCycle));
  $("#compute").addEventListener("click", () => act(wizard, compute, $("#compute")));
  $("#discard").addEventListener("click", () => act(wizard, discard));
  $("#ideal-aim").addEventListener("change", (e) => { $("#aim").disabled = e.target.checked; });
  const report = $("#report");
  $("#save").addEventListener("click", () => act(report, save));
  $("#discard-report").addEventListener("click", () => act(report, discard));

  $("#tab-tool").addEventListener("click", () => showTab("tool"));
  $("#tab-base").addEventListener("click", () => showTab("base"));
  $("#tab-ext").addEventListener("click", () => showTab("ext"));
}

async function main() {
  wire();
  await act($("#topbar"), async () => {
    await loadMethods();
    await loadControllers();
    await loadAimDefault();
  });
  document.body.dataset.ready = "true";
}

main();
