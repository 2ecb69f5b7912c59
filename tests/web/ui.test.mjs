// The pure helpers of web/ui.js under `node --test` (no browser, no build step).
// Run: node --test tests/web/   (tests/test_web_node.py runs it inside the suite)
import { test } from "node:test";
import assert from "node:assert/strict";
import { axesLabel, backupChanges, describeChange, describeSession, describeSnapshot, fmt,
         incrementUnit, isolate, jobText, num, parseNumbers, sig, when } from "../../web/ui.js";

test("num: fixed decimals, no -0.000, a dash for no value", () => {
  assert.equal(num(1.23456), "1.235");
  assert.equal(num(-0.0001), "0.000");
  assert.equal(num(-0.0001, 5), "-0.00010");
  assert.equal(num(12, 2), "12.00");
  assert.equal(num(null), "—");
  assert.equal(num(undefined), "—");
});

test("fmt: a tiny statistic reads as 1.2e-9, not 0.000", () => {
  assert.equal(fmt(1.2e-9), "1.2e-9");
  assert.equal(fmt(0), "0.000");
  assert.equal(fmt(0.04321), "0.043");
  assert.equal(fmt("n/a"), "n/a");
});

test("sig: 4 significant digits as the analysis page shows figures", () => {
  assert.equal(sig(0.81734), "0.8173");
  assert.equal(sig(3), "3");
  assert.equal(sig(1.5e-7), "1.50e-7");
  assert.equal(sig(0.000123456), "0.000123");
  assert.equal(sig(null), "–");
});

test("parseNumbers: commas, semicolons and spaces; a word is NaN", () => {
  assert.deepEqual(parseNumbers("0, -90; 90  0\n90,0"), [0, -90, 90, 0, 90, 0]);
  assert.ok(Number.isNaN(parseNumbers("1 two")[1]));
  assert.deepEqual(parseNumbers("  "), []);
});

test("axesLabel: the header names the external axes", () => {
  assert.equal(axesLabel("KR 6 R900 sixx", 6, { E1: 0, E2: 0, E3: 0, E4: 0 }), "KR 6 R900 sixx, 6 axes + E1–E4");
  assert.equal(axesLabel("UR10", 6, {}), "UR10, 6 axes");
  assert.equal(axesLabel("KR 6", 6, { E1: 0 }), "KR 6, 6 axes + E1");
});

test("incrementUnit: the rail travels in mm", () => {
  assert.equal(incrementUnit("joint", ["E4"]), "deg; E4: mm");
  assert.equal(incrementUnit("joint", []), "deg");
  assert.equal(incrementUnit("world", ["E4"]), "mm / deg");
});

const snap = (over = {}) => ({ name: "tool1", kind: "tool", x_mm: 1.5, y_mm: 0, z_mm: 200, a_deg: 0,
                               b_deg: 0, c_deg: -0.00001, ...over });

test("isolate: a name with a bidi control cannot reorder the rest of its line", () => {
  assert.equal(isolate("tool1"), "tool1");
  assert.equal(isolate(null), "");
  assert.equal(isolate("pen\u202e"), "\u2068pen\u202e\u2069");
  assert.equal(isolate("a\u2069\u202eb"), "\u2068a\u202eb\u2069");  // its own PDI cannot close ours
  assert.equal(describeSnapshot(snap({ name: "\u202ex" })), "\u2068\u202ex\u2069 [tool] 1.500 0.000 200.000 / 0.000 0.000 0.000");
});

test("describeSnapshot and describeChange: who, when, source, before -> after, quality", () => {
  assert.equal(describeSnapshot(snap()), "tool1 [tool] 1.500 0.000 200.000 / 0.000 0.000 0.000");
  assert.equal(describeSnapshot(snap({ name: "", x_mm: 0, z_mm: 0, c_deg: 0 })), "(unused)");
  assert.equal(describeSnapshot(null), "(unused)");
  const c = describeChange({ reason: "calibration", session_id: 4, changed_by: "alice",
                             changed_at: "2026-11-26T15:02:07.5+00:00", before: null,
                             after: snap({ method: "tool.xyz_4point", error_max_mm: 0.0412, error_rms_mm: 0.02 }) });
  assert.deepEqual(c, { when: "2026-11-26 15:02", who: "alice", source: "calibration (session 4)",
                        before: "(unused)", after: "tool1 [tool] 1.500 0.000 200.000 / 0.000 0.000 0.000",
                        quality: "tool.xyz_4point · max 0.041 mm · RMS 0.020 mm" });
  assert.equal(describeChange({ reason: "import", after: snap(), before: snap() }).who, "—");
  assert.equal(when(null), "—");
});

test("describeSession: which menu, which slot, how many points", () => {
  const s = { id: 7, title: "Tool > XYZ 4-point", target_no: 2, state: "open", created_at: "2026-11-26T15:10:00",
              steps: [{ required: true, filled: true }, { required: true, filled: false },
                      { required: true, filled: false }, { required: true, filled: false }] };
  assert.equal(describeSession(s, "TOOL"), "Tool > XYZ 4-point → TOOL 2: 1 of 4 points taught, open, opened 2026-11-26 15:10 (session 7)");
  assert.match(describeSession({ ...s, steps: [] }, "TOOL"), /: 0 points taught/);
});

test("describeSession: whose it is, the viewer's own marked", () => {
  const s = { id: 7, title: "Tool > XYZ 4-point", target_no: 2, state: "open", created_at: "2026-11-26T15:10:00",
              steps: [], opened_by: "olga" };
  assert.equal(describeSession(s, "TOOL", "eva"), "Tool > XYZ 4-point → TOOL 2: 0 points taught, open, opened 2026-11-26 15:10 by olga (session 7)");
  assert.match(describeSession(s, "TOOL", "olga"), /opened 2026-11-26 15:10 by olga \(yours\) \(session 7\)$/);
  assert.match(describeSession({ ...s, opened_by: null }, "TOOL", "olga"), /opened 2026-11-26 15:10 \(session 7\)$/); // not recorded
});

test("jobText: what the job is doing, in words", () => {
  assert.equal(jobText({ state: "running", progress: 0.1, message: "restoring the backup" }), "restoring the backup: 10 %");
  assert.equal(jobText({ state: "queued", progress: 0, message: "" }), "waiting for a worker");
  assert.equal(jobText({ state: "failed", error: { detail: [{ loc: ["text"], msg: "bad" }] } }), "failed: bad");
  assert.equal(jobText({ state: "done" }), "done");
});

test("backupChanges: only the slots the backup would change, and those it would empty", () => {
  const pose = { x: 1.5, y: 0, z: 200, a: 0, b: 0, c: 0 };
  const current = { tool: [{ number: 1, name: "tool1", kind: "tool", pose },
                           { number: 2, name: "new", kind: "tool", pose: { ...pose, x: 9 } },
                           { number: 3, name: "", kind: "tool", pose: { x: 0, y: 0, z: 0, a: 0, b: 0, c: 0 } }],
                    base: [] };
  const entry = (number, over = {}) => ({ table: "tool", number, name: "tool1", kind: "tool", x_mm: 1.5, y_mm: 0,
                                          z_mm: 200, a_deg: 0, b_deg: 0, c_deg: 0, ...over });
  const out = backupChanges({ entries: [entry(1, { x_mm: 1.5000000001 }), entry(3, { name: "old" })] }, current);
  assert.deepEqual(out.map((c) => [c.table, c.number, c.before && c.before.name, c.after && c.after.name]),
                   [["tool", 2, "new", null], ["tool", 3, "", "old"]]);
});
