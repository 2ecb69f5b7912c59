// pendant: import a controller file into the selected controller, with a preview first.
// Self-contained: reads the controller from #controller, asks the service for a dry run
// (POST .../import with dry_run), shows per slot before -> after, kind changes and the
// declarations the file has that pendant skips, and imports only when asked.

import { request, ApiError } from "/api.js";

const $ = (s) => document.querySelector(s);
const SUFFIX = { dat: "kuka", mod: "abb", modx: "abb", sys: "abb", txt: "fanuc", ls: "fanuc", script: "ur" };
let pending = null; // {path, format, text} of the previewed file

function describe(slot) {
  if (!slot) return "(unused)";
  const p = slot.pose;
  const xyz = [p.x, p.y, p.z].map((v) => v.toFixed(3)).join(" ");
  const abc = [p.a, p.b, p.c].map((v) => v.toFixed(3)).join(" ");
  const load = slot.load ? `, ${slot.load.mass_kg} kg` : "";
  const unit = slot.mech_unit ? ` on ${slot.mech_unit}` : "";
  return `${slot.name || "(no name)"} [${slot.kind.replace("_", " ")}${unit}] ${xyz} / ${abc}${load}`;
}

function showError(err) {
  const detail = err instanceof ApiError && Array.isArray(err.detail) ? err.detail : [{ loc: [], msg: String(err.message || err) }];
  $("#import-err").textContent = detail.map((d) => `${(d.loc || []).filter((x) => x !== "body").join(" ")}: ${d.msg}`).join("; ");
}

function render(res) {
  const body = $("#import-diff tbody");
  body.replaceChildren();
  const changed = res.slots.filter((s) => s.changed);
  for (const s of changed) {
    const tr = document.createElement("tr");
    if (s.kind_change) tr.className = "kind-change";
    for (const text of [`${s.table} ${s.number}`, s.line ?? "", describe(s.before), describe(s.after), s.kind_change || ""]) {
      const td = document.createElement("td");
      td.textContent = String(text);
      tr.append(td);
    }
    body.append(tr);
  }
  const skipped = $("#import-skipped");
  skipped.replaceChildren(...res.skipped.map((k) => {
    const li = document.createElement("li");
    li.textContent = `line ${k.line}: ${k.field}: ${k.reason}`;
    return li;
  }));
  $("#import-summary").textContent = `${changed.length} slot(s) would change` +
    (res.skipped.length ? `, ${res.skipped.length} declaration(s) skipped` : "") + ". Nothing is written yet.";
  $("#import-commit").disabled = changed.length === 0;
  $("#import-preview").hidden = false;
}

async function preview(ev) {
  ev.preventDefault();
  $("#import-err").textContent = "";
  $("#import-preview").hidden = true;
  const file = $("#import-file").files[0];
  if (!file) { $("#import-err").textContent = "file: choose a controller file"; return; }
  const ext = file.name.split(".").pop().toLowerCase();
  const format = $("#import-format").value || SUFFIX[ext];
  if (!format) { $("#import-err").textContent = `format: cannot tell the format of ${file.name}; choose one`; return; }
  const path = `/controllers/${$("#controller").value}/import`;
  pending = { path, format, text: await file.text() };
  try {
    render(await request("POST", path, { body: { format, text: pending.text, dry_run: true } }));
  } catch (err) { pending = null; showError(err); }
}

async function commit() {
  if (!pending) return;
  $("#import-err").textContent = "";
  try {
    const res = await request("POST", pending.path, { body: { format: pending.format, text: pending.text } });
    $("#import-summary").textContent = `Imported: ${res.slots.filter((s) => s.changed).length} slot(s) changed.`;
    $("#import-commit").disabled = true;
    pending = null;
    $("#controller").dispatchEvent(new Event("change")); // the pendant reloads its tables
  } catch (err) { showError(err); }
}

function cancel() {
  pending = null;
  $("#import-preview").hidden = true;
  $("#import-summary").textContent = "";
}

document.addEventListener("DOMContentLoaded", () => {
  $("#import-form").addEventListener("submit", preview);
  $("#import-commit").addEventListener("click", commit);
  $("#import-cancel").addEventListener("click", cancel);
});
