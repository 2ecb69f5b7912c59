// pendant: import a controller file into the selected controller, with a preview first.
// Self-contained: reads the controller from #controller, asks the service for a dry run
// (POST .../import with dry_run), shows per slot before -> after, kind changes and the
// declarations the file has that pendant skips, and imports only when asked. Each slot has
// a tick box: only the ticked ones are imported (the others keep what they hold, e.g. a TOOL 1
// calibrated before). The file is read as bytes: UTF-8 if it is, else Windows-1252, and the
// service is told which, so that its export writes the file back in the same encoding.

import { request, ApiError } from "/api.js";
import { backupChanges, describeSnapshot, isolate, jobText } from "/ui.js";

const $ = (s) => document.querySelector(s);
const SUFFIX = { json: "json", dat: "kuka", mod: "abb", modx: "abb", sys: "abb", txt: "fanuc", ls: "fanuc", script: "ur" };
let pending = null; // {path, format, text, encoding} of the previewed file

async function readFile(file) {
  const bytes = await file.arrayBuffer();
  try {
    return { text: new TextDecoder("utf-8", { fatal: true, ignoreBOM: true }).decode(bytes), encoding: "utf-8" };
  } catch {
    return { text: new TextDecoder("windows-1252").decode(bytes), encoding: "cp1252" };
  }
}

function ticked() {
  return [...document.querySelectorAll("#import-diff tbody input[type=checkbox]")];
}

function updateCommit() {
  const n = ticked().filter((b) => b.checked).length;
  $("#import-commit").disabled = n === 0;
  $("#import-commit").textContent = n === ticked().length ? "Import these changes" : `Import ${n} ticked slot(s)`;
}

function describe(slot) {
  if (!slot) return "(unused)";
  const p = slot.pose;
  const xyz = [p.x, p.y, p.z].map((v) => v.toFixed(3)).join(" ");
  const abc = [p.a, p.b, p.c].map((v) => v.toFixed(3)).join(" ");
  const load = slot.load ? `, ${slot.load.mass_kg} kg` : "";
  const unit = slot.mech_unit ? ` on ${isolate(slot.mech_unit)}` : "";
  return `${isolate(slot.name) || "(no name)"} [${slot.kind.replace("_", " ")}${unit}] ${xyz} / ${abc}${load}`;
}

/** What the import is doing now, in words ("" when it is done). */
function progress(text) {
  $("#import-progress").textContent = text;
}

function showError(err) {
  progress("");
  const detail = err instanceof ApiError && Array.isArray(err.detail) ? err.detail : [{ loc: [], msg: String(err.message || err) }];
  $("#import-err").textContent = detail.map((d) => `${(d.loc || []).filter((x) => x !== "body").join(" ")}: ${d.msg}`).join("; ");
}

function render(res) {
  const body = $("#import-diff tbody");
  body.replaceChildren();
  const head = $("#import-diff thead tr");
  if (head && !head.querySelector(".apply")) {
    const th = document.createElement("th");
    th.className = "apply";
    th.textContent = "Apply";
    head.prepend(th);
  }
  const changed = res.slots.filter((s) => s.changed);
  for (const s of changed) {
    const tr = document.createElement("tr");
    if (s.kind_change) tr.className = "kind-change";
    const box = document.createElement("input");
    box.type = "checkbox";
    box.checked = true;
    box.name = `${s.table}-${s.number}`;
    box.dataset.table = s.table;
    box.dataset.number = String(s.number);
    box.setAttribute("aria-label", `apply ${s.table} ${s.number}`);
    box.addEventListener("change", updateCommit);
    const td0 = document.createElement("td");
    td0.append(box);
    tr.append(td0);
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
  updateCommit();
  $("#import-preview").hidden = false;
}

async function preview(ev) {
  ev.preventDefault();
  $("#import-err").textContent = "";
  $("#saved-note")?.remove(); // a message belongs to the action that raised it
  $("#import-preview").hidden = true;
  const file = $("#import-file").files[0];
  if (!file) { $("#import-err").textContent = "file: choose a controller file"; return; }
  const ext = file.name.split(".").pop().toLowerCase();
  const format = $("#import-format").value || SUFFIX[ext];
  if (!format) { $("#import-err").textContent = `format: cannot tell the format of ${file.name}; choose one`; return; }
  const path = `/controllers/${$("#controller").value}/import`;
  progress(`Reading ${file.name}…`);
  pending = { path, format, ...(await readFile(file)) };
  try {
    progress(`Checking ${file.name} (${format}) with the service; nothing is written…`);
    const res = await request("POST", path, { body: { format, text: pending.text, encoding: pending.encoding, dry_run: true } });
    if (format === "json") await renderBackup(res);
    else render(res);
    progress("");
  } catch (err) { pending = null; showError(err); }
}

// ------------------------------------------------------------------------------ JSON backup

/** A JSON backup's preview: the service has checked it (dry run); the page compares its slots
 * with the tables as they are now. A backup replaces the whole controller, so no tick boxes. */
async function renderBackup(res) {
  const doc = JSON.parse(pending.text); // the service has read it: it is JSON
  const cid = $("#controller").value;
  progress("Comparing the backup with the tables as they are…");
  const [tool, base] = await Promise.all([request("GET", `/controllers/${cid}/tools`), request("GET", `/controllers/${cid}/bases`)]);
  const changes = backupChanges(doc, { tool, base });
  $("#import-diff thead tr .apply")?.remove();
  $("#import-diff tbody").replaceChildren(...changes.map((c) => {
    const tr = document.createElement("tr");
    if (c.before && c.after && c.before.kind !== c.after.kind) tr.className = "kind-change";
    const kind = c.before && c.after && c.before.kind !== c.after.kind ? `${c.before.kind} -> ${c.after.kind}` : "";
    for (const text of [`${c.table} ${c.number}`, "", describeSnapshot(c.before), describeSnapshot(c.after), kind]) {
      const td = document.createElement("td");
      td.textContent = text;
      tr.append(td);
    }
    return tr;
  }));
  $("#import-skipped").replaceChildren();
  const n = (k) => (doc[k] || []).length;
  $("#import-summary").textContent = `Restoring this backup replaces the whole controller: ${changes.length} slot(s) change, ` +
    `${res.entries} slot(s), ${n("external_kinematics")} external kinematic(s), ${n("history")} history row(s) and ` +
    `${n("sessions")} session(s) come from the backup. Nothing is written yet.`;
  $("#import-commit").disabled = false;
  $("#import-commit").textContent = "Restore this backup";
  $("#import-preview").hidden = false;
}

/** Restore the previewed backup: the service runs it as a job; its progress is shown in words. */
async function restoreBackup() {
  if (!window.confirm("Restore this backup? It replaces this controller's tables, history and sessions " +
                      "(the audit trail keeps every earlier change).")) return;
  progress("Sending the backup…");
  const job = await request("POST", pending.path, { body: { format: "json", text: pending.text } });
  pending = null;
  $("#import-commit").disabled = true;
  let j = job;
  while (j.state === "queued" || j.state === "running") {
    progress(`Restore job ${job.id}: ${jobText(j)}`); // "restoring the backup: 10 %"
    await new Promise((ok) => setTimeout(ok, 200)); // poll the job's state
    j = await request("GET", `/jobs/${job.id}`);
  }
  if (j.state !== "done") throw new ApiError(422, [{ loc: [], msg: `the restore ${jobText(j)}` }]);
  progress("");
  $("#import-summary").textContent = `Restored: ${j.result.entries} slot(s) and ${j.result.history} history row(s) from the backup.`;
  if (window.pendant?.reloadTables) await window.pendant.reloadTables();
  else $("#controller").dispatchEvent(new Event("change"));
}

async function commit() {
  if (!pending) return;
  $("#import-err").textContent = "";
  $("#saved-note")?.remove(); // a message belongs to the action that raised it
  try {
    if (pending.format === "json") { await restoreBackup(); return; }
    const n = ticked().filter((b) => b.checked).length;
    progress(`Importing ${n} slot(s) from the ${pending.format} file…`);
    const boxes = ticked();
    const body = { format: pending.format, text: pending.text, encoding: pending.encoding };
    if (boxes.some((b) => !b.checked)) {
      body.slots = boxes.filter((b) => b.checked).map((b) => ({ table: b.dataset.table, number: Number(b.dataset.number) }));
    }
    const res = await request("POST", pending.path, { body });
    progress("");
    $("#import-summary").textContent = `Imported: ${res.slots.filter((s) => s.changed).length} slot(s) changed.`;
    $("#import-commit").disabled = true;
    pending = null;
    if (window.pendant?.reloadTables) await window.pendant.reloadTables(); // the Frames tables show it
    else $("#controller").dispatchEvent(new Event("change"));
  } catch (err) { showError(err); }
}

function cancel() {
  pending = null;
  progress("");
  $("#import-preview").hidden = true;
  $("#import-summary").textContent = "";
}

document.addEventListener("DOMContentLoaded", () => {
  $("#import-form").addEventListener("submit", preview);
  $("#import-commit").addEventListener("click", commit);
  $("#import-cancel").addEventListener("click", cancel);
});
