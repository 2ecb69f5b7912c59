// pendant: the small helpers both pages share (the teach pendant and the analysis page).
// Plain ES module, no build step, no imports: the pure functions run under `node --test`
// (tests/web/ui.test.mjs) as they do in the browser; only el() needs a document.

/** An element: `attrs` are attributes, except `class`, `text` (textContent) and `onX`
 * (an event listener); a null, undefined or false attribute and a null child are left out. */
export function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === null || v === undefined || v === false) continue;
    if (k === "class") e.className = v;
    else if (k === "text") e.textContent = v;
    else if (k.startsWith("on") && typeof v === "function") e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children) if (c !== null && c !== undefined) e.append(c);
  return e;
}

/** A name (a user's, a slot's from a controller file) inside a line of text. One holding a
 * bidirectional control (a right-to-left override U+202E, an embedding, an isolate) is isolated
 * (U+2068 ... U+2069) without its own isolate marks, so it cannot reorder what follows it on
 * the line (a slot's numbers); any other name is returned as it is. */
export function isolate(name) {
  const s = String(name ?? "");
  return /[\u061c\u200e\u200f\u202a-\u202e\u2066-\u2069]/.test(s)
    ? `\u2068${s.replace(/[\u2066-\u2069]/g, "")}\u2069` : s;
}

/** A pose coordinate: `digits` fixed decimals, no "-0.000"; "—" for no value. */
export function num(v, digits = 3) {
  if (v === null || v === undefined) return "—";
  if (typeof v !== "number" || !Number.isFinite(v)) return String(v);
  return (Math.abs(v) < 0.5 * 10 ** -digits ? 0 : v).toFixed(digits);
}

/** A statistic: fixed decimals, or 1.2e-9 when it would read 0.000; "—" for no value. */
export function fmt(v, digits = 3) {
  if (v === null || v === undefined) return "—";
  if (typeof v !== "number") return String(v);
  if (v !== 0 && Math.abs(v) < 10 ** -digits) return v.toExponential(1);
  return v.toFixed(digits);
}

/** A measured figure to 4 significant digits (1e-5 .. 1e6 plainly, else 1.23e-7); "–" for none. */
export function sig(v) {
  if (typeof v !== "number" || !Number.isFinite(v)) return v === null || v === undefined ? "–" : String(v);
  if (Number.isInteger(v)) return String(v);
  const a = Math.abs(v);
  if (a !== 0 && (a < 1e-5 || a >= 1e6)) return v.toExponential(2);
  if (a < 1e-3) return v.toPrecision(3);
  return String(Number(v.toPrecision(4)));
}

/** The numbers of a pasted text ("0, -90; 90 0" -> [0, -90, 90, 0]); a word becomes NaN. */
export function parseNumbers(text) {
  return text.split(/[\s,;]+/).filter((s) => s !== "").map(Number);
}

/** "2026-11-26T15:02:07.123+00:00" -> "2026-11-26 15:02" (the stored UTC time, as written). */
export function when(iso) {
  return iso ? iso.slice(0, 16).replace("T", " ") : "—";
}

// ------------------------------------------------------------------------------ the header

/** "KR 6 R900 sixx, 6 axes + E1–E4": the robot's joints and the cell's external axes. */
export function axesLabel(robotName, dof, externalAxes) {
  const ext = Object.keys(externalAxes || {});
  const extra = ext.length === 0 ? "" : ext.length === 1 ? ` + ${ext[0]}` : ` + ${ext[0]}–${ext[ext.length - 1]}`;
  return `${robotName}, ${dof} axes${extra}`;
}

/** The unit of the jog increment: joints turn in deg, and a linear external axis (the rail,
 * E4) travels in mm, so in joint mode on a cell with a rail the label names both; Cartesian
 * modes move X, Y, Z in mm and turn A, B, C in deg. `linearAxes`: the cell's mm axes. */
export function incrementUnit(mode, linearAxes = []) {
  if (mode !== "joint") return "mm / deg";
  return linearAxes.length ? `deg; ${linearAxes.join(", ")}: mm` : "deg";
}

// ------------------------------------------------------------------------------ history

const POSE = [["x_mm", "y_mm", "z_mm"], ["a_deg", "b_deg", "c_deg"]];

/** A slot's values from its history (the before/after snapshot) in one line:
 * `name [kind] x y z / a b c`; "(unused)" for an empty, nameless zero slot. */
export function describeSnapshot(snap) {
  if (!snap) return "(unused)";
  const pose = (keys) => keys.map((k) => num(snap[k])).join(" ");
  const zero = POSE.flat().every((k) => !snap[k]);
  if (!snap.name && zero) return "(unused)";
  return `${isolate(snap.name) || "(no name)"} [${String(snap.kind || "").replace("_", " ")}] ${pose(POSE[0])} / ${pose(POSE[1])}`;
}

/** What a history row's change did, as a person reads it: the source and the quality figures. */
export function describeChange(h) {
  const SOURCE = { calibration: "calibration", edit: "edit by hand", restore: "restore",
                   import: "file import", backup: "backup restore" };
  let source = SOURCE[h.reason] || h.reason;
  if (h.session_id) source += ` (session ${h.session_id})`;
  const after = h.after || {};
  const q = [];
  if (after.method) q.push(after.method);
  if (after.error_max_mm !== null && after.error_max_mm !== undefined) q.push(`max ${fmt(after.error_max_mm)} mm`);
  if (after.error_rms_mm !== null && after.error_rms_mm !== undefined) q.push(`RMS ${fmt(after.error_rms_mm)} mm`);
  return { when: when(h.changed_at), who: h.changed_by || "—", source, before: describeSnapshot(h.before),
           after: describeSnapshot(h.after), quality: q.join(" · ") };
}

// ------------------------------------------------------------------------------ sessions

/** One open session for the list a person picks from: which menu, its slot, the points
 * taught, when and by whom it was opened ("by alice", and "(yours)" when `me`, the user
 * logged in, opened it; nothing when the service did not record who). `label` is the
 * table's name ("TOOL", "BASE", "EX_KIN"). */
export function describeSession(s, label, me = null) {
  const required = s.steps.filter((st) => st.required).length;
  const taught = s.steps.filter((st) => st.filled).length;
  const points = required ? `${taught} of ${required} point${required === 1 ? "" : "s"} taught`
                          : `${taught} point${taught === 1 ? "" : "s"} taught`;
  const by = s.opened_by ? ` by ${isolate(s.opened_by)}${s.opened_by === me ? " (yours)" : ""}` : "";
  return `${s.title} → ${label} ${s.target_no}: ${points}, ${s.state}, opened ${when(s.created_at)}${by} (session ${s.id})`;
}

// ------------------------------------------------------------------------------ jobs

/** A job's progress as a person reads it: what it is doing and how far ("restoring the
 * backup: 10 %"; "done"; "failed: reason"). */
export function jobText(job) {
  if (job.state === "done") return "done";
  if (job.state === "failed") {
    const d = job.error && job.error.detail;
    const msg = Array.isArray(d) ? d.map((x) => x.msg).join("; ") : (job.message || "failed");
    return `failed: ${msg}`;
  }
  if (job.state === "queued") return "waiting for a worker";
  const pct = Math.round((job.progress || 0) * 100);
  return `${job.message || job.state}: ${pct} %`;
}

// ------------------------------------------------------------------------------ backups

/** The slots a JSON backup (`pendant-backup/1`) would change, against the tables as they are:
 * [{table, number, before, after}] for each slot whose values differ; `current` is
 * {tool: [EntryOut], base: [EntryOut]}. The service checks the document; this only previews. */
export function backupChanges(doc, current) {
  const pose = (p) => p ? { x_mm: p.x, y_mm: p.y, z_mm: p.z, a_deg: p.a, b_deg: p.b, c_deg: p.c } : {};
  const now = new Map();
  for (const table of ["tool", "base"]) {
    for (const e of current[table] || []) now.set(`${table} ${e.number}`, { name: e.name, kind: e.kind, ...pose(e.pose) });
  }
  const keys = ["name", "kind", ...POSE.flat()];
  const seen = new Set();
  const out = [];
  for (const e of doc.entries || []) {
    const key = `${e.table} ${e.number}`;
    seen.add(key);
    const before = now.get(key) || null;
    const after = Object.fromEntries(keys.map((k) => [k, e[k]]));
    const same = before && keys.every((k) => (k in before ? before[k] : null) === (after[k] ?? null)
                                      || (typeof after[k] === "number" && Math.abs(before[k] - after[k]) < 5e-7));
    if (!same) out.push({ table: e.table, number: e.number, before, after });
  }
  for (const [key, before] of now) { // a slot the backup does not hold is emptied
    if (seen.has(key) || describeSnapshot(before) === "(unused)") continue;
    const [table, number] = key.split(" ");
    out.push({ table, number: Number(number), before, after: null });
  }
  return out.sort((a, b) => a.table.localeCompare(b.table) || a.number - b.number);
}
