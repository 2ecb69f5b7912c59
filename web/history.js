// pendant: a slot's history on the teach pendant, and Restore of an earlier state.
// Self-contained (like import.js): reads the controller from #controller. Click a row of the
// Frames tables (or pick table and number and press Show history) to list every change of the
// slot, newest first: when, who, the source (calibration and its session, edit, import,
// restore), before -> after and the quality figures. Restore asks first, then calls
// POST .../{n}/restore/{history_id} with the slot's ETag as If-Match (web/api.js keeps it):
// a slot someone changed since this page read it is refused (412), never overwritten.

import { request, ApiError } from "/api.js";
import { el, describeChange, describeSnapshot, isolate } from "/ui.js";

const $ = (s) => document.querySelector(s);
const PATH = { tool: "tools", base: "bases", extkin: "external-kinematics" };
const LABEL = { tool: "TOOL", base: "BASE", extkin: "EX_KIN" };
const shown = { table: null, number: null };

const slotPath = (table, number) => `/controllers/${$("#controller").value}/${PATH[table]}/${number}`;

function counted() { // tests wait for window.pendant.pending === 0
  const p = window.pendant;
  return { onStart() { if (p) p.pending += 1; }, onEnd() { if (p) p.pending -= 1; } };
}

function showError(err) {
  const detail = err instanceof ApiError && Array.isArray(err.detail) ? err.detail
    : [{ loc: [], msg: err instanceof ApiError ? String(err.detail) : String(err.message || err) }];
  $("#history-err").textContent = detail.map((d) => d.msg).join("; ");
}

/** A snapshot of an external kinematic in the same terms as a tool or base slot. */
function extSnapshot(s) {
  if (!s || !s.axes || !s.axes.length) return s;
  return { ...s, kind: `${s.kind} ${Array.isArray(s.axes) ? s.axes.join(",") : s.axes}` }; // axes: ["E1"] or "E1"
}

async function show(table, number) {
  $("#saved-note")?.remove();
  $("#history-err").textContent = "";
  $("#history-note").textContent = "";
  shown.table = table;
  shown.number = number;
  $("#history-table").value = table;
  $("#history-number").value = String(number);
  const path = slotPath(table, number);
  const [slot, rows] = await Promise.all([request("GET", path, counted()), // keeps its ETag
                                          request("GET", `${path}/history`, counted())]);
  const name = slot.name ? ` (${isolate(slot.name)})` : "";
  $("#history-title").textContent = `${LABEL[table]} ${number}${name}: ${rows.length} change${rows.length === 1 ? "" : "s"}`;
  const body = $("#history-rows tbody");
  body.replaceChildren(...rows.slice().reverse().map((h) => {
    const ext = table === "extkin";
    const c = describeChange(ext ? { ...h, before: extSnapshot(h.before), after: extSnapshot(h.after) } : h);
    const restore = el("button", { type: "button", class: "small", "data-history": h.id,
                                   "aria-label": `Restore ${LABEL[table]} ${number} to before change ${h.id}`,
                                   text: "Restore", onclick: () => restoreTo(h, c) });
    return el("tr", { "data-history": h.id },
      el("td", { class: "when", text: c.when }), el("td", { text: c.who }), el("td", { text: c.source }),
      el("td", { class: "change" }, el("div", { class: "before", text: c.before }),
                                    el("div", { class: "after", text: `→ ${c.after}` })),
      el("td", { text: c.quality }), el("td", {}, restore));
  }));
  $("#history-view").hidden = false;
}

async function restoreTo(h, c) {
  const table = shown.table, number = shown.number;
  const before = table === "extkin" ? describeSnapshot(extSnapshot(h.before)) : c.before;
  if (!window.confirm(`Restore ${LABEL[table]} ${number} to how it was before the change of ${c.when} ` +
                      `(${c.source}, by ${c.who})?\n\n${before}\n\nThe restore is itself recorded in the history.`)) return;
  try {
    $("#history-err").textContent = "";
    const path = slotPath(table, number);
    const out = await request("POST", `${path}/restore/${h.id}`, counted());
    await show(table, number);
    $("#history-note").textContent = `Restored ${LABEL[table]} ${number}: ${isolate(out.name) || "(no name)"}`;
    await window.pendant?.reloadTables?.();
  } catch (err) { showError(err); }
}

function pick(ev) { // a click on a row of the Frames tables shows that slot's history
  const tr = ev.target.closest("tr[data-number]");
  if (!tr || ev.target.closest("button, a, input, select")) return;
  const table = { "tool-table": "tool", "base-table": "base", "ext-table": "extkin" }[tr.closest("table").id];
  if (table) show(table, Number(tr.dataset.number)).catch(showError);
}

document.addEventListener("DOMContentLoaded", () => {
  for (const id of ["#tool-table", "#base-table", "#ext-table"]) $(id)?.addEventListener("click", pick);
  $("#history-form").addEventListener("submit", (ev) => {
    ev.preventDefault();
    const n = Number($("#history-number").value);
    show($("#history-table").value, n).catch(showError);
  });
  $("#history-close").addEventListener("click", () => { $("#history-view").hidden = true; });
});
