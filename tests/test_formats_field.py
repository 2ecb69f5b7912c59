"""Controller files from the field (issue 23), one test per defect: the traits of real
KUKA and ABB files that pendant read wrongly or wrote back changed. The files are our own
(tests/data/controller-files, made by make_corpus.py there)."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import pytest

from api_helpers import C, ok
from server import formats
from server.formats import FormatError, read_abb, read_kuka
from server.formats.abb import export_abb

CORPUS = Path(__file__).parent / "data" / "controller-files"


def load(name: str) -> tuple[str, str]:
    """(text, encoding) of a corpus file: UTF-8 if it is valid UTF-8, else Windows-1252."""
    raw = (CORPUS / name).read_bytes()
    try:
        return raw.decode("utf-8"), "utf-8"
    except UnicodeDecodeError:
        return raw.decode("cp1252"), "cp1252"


def imp(client, fmt: str, name: str, **extra):  # noqa: ANN001, ANN201
    text, encoding = load(name)
    body = {"format": fmt, "text": text, **extra}
    if encoding != "utf-8":
        body["encoding"] = encoding
    return client.post(f"{C}/import", json=body)


def put(client, path: str, body: dict) -> dict:  # noqa: ANN001
    return ok(client.put(f"{C}{path}", json=body, headers={"If-Match": "*"}))


# ---------------------------------------------------------------- 1. untouched values stay

def test_get_gives_every_digit_and_a_partial_put_changes_only_what_it_names(client):
    ok(imp(client, "kuka", "kuka_krc4_crlf_cp1252.dat"))
    tool = ok(client.get(f"{C}/tools/1"))
    assert tool["pose"]["y"] == 3.01155138 and tool["pose"]["x"] == 148.320007
    assert ok(client.get(f"{C}/bases/1"))["pose"]["b"] == 0.238999218
    after = put(client, "/tools/1", {"pose": {"x": 149.320007}})
    assert after["pose"] == {**tool["pose"], "x": 149.320007}  # y, z, a, b, c as they were
    assert after["load"] == tool["load"]
    out = client.get(f"{C}/export", params={"format": "kuka"}).content.decode("cp1252")
    assert "TOOL_DATA[1]={X 149.320007,Y 3.01155138,Z 357.125,A 0.0,B 67.5,C 0.0}" in out
    assert "B 0.238999218" in out


def test_a_partial_load_keeps_the_rest_and_null_removes_it(client):
    put(client, "/tools/4", {"load": {"mass_kg": 2.0, "com_mm": [0, 0, 55.5]}})
    assert put(client, "/tools/4", {"load": {"mass_kg": 3.0}})["load"]["com_mm"] == [0, 0, 55.5]
    assert put(client, "/tools/4", {"load": None})["load"] is None
    r = client.put(f"{C}/tools/5", json={"load": {"com_mm": [0, 0, 1]}}, headers={"If-Match": "*"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"][-2:] == ["load", "mass_kg"]


def test_abb_quaternion_keeps_its_text_when_only_x_changes(client):
    ok(imp(client, "abb", "abb_program_cp1252_crlf.mod"))
    put(client, "/tools/1", {"pose": {"x": 1.0}})
    out = client.get(f"{C}/export", params={"format": "abb"}).content.decode("cp1252")
    assert "tGripper:=[TRUE,[[1,3.01155138,185.5],[0.99998,0.00625,0,0]]" in out


def test_abb_work_object_defined_by_its_oframe_is_edited_there_without_float_dust():
    text, _ = load("abb_program_cp1252_crlf.mod")
    entries = read_abb(text).entries
    fixture = next(e for e in entries if e.name == "wFixture")
    turned = formats.FrameEntry(fixture.number, fixture.name, fixture.kind,
                                fixture.pose.__class__(*fixture.pose.as_array()[:3],
                                                       fixture.pose.a + 1, fixture.pose.b,
                                                       fixture.pose.c))
    out = export_abb([turned if e is fixture else e for e in entries], template=text)
    line = next(s for s in out.splitlines() if "wFixture" in s)
    assert '[FALSE,TRUE,"",[[0,0,0],[1,0,0,0]],[[812.5,-240.125,305],[' in line
    assert not re.search(r"\de-1\d", line)  # no 2.27e-13 where the value is zero
    back = next(e for e in read_abb(out).entries if e.name == "wFixture")
    assert back.pose.a == pytest.approx(fixture.pose.a + 1, abs=1e-6)


# ---------------------------------------------------------------- 2. encodings

def test_export_is_in_the_files_own_encoding(client):
    raw = (CORPUS / "kuka_krc4_crlf_cp1252.dat").read_bytes()
    ok(imp(client, "kuka", "kuka_krc4_crlf_cp1252.dat"))
    put(client, "/bases/1", {"name": "Tisch 2"})
    r = client.get(f"{C}/export", params={"format": "kuka"})
    assert "windows-1252" in r.headers["content-type"]
    assert b'TOOL_NAME[1,]="Greifer \xd6l"' in r.content and b"\xc3" not in r.content
    assert len(r.content) == len(raw)
    ok(imp(client, "abb", "abb_program_cp1252_crlf.mod"))
    assert b'TPWrite "Cart\xf3n detectado."' in client.get(f"{C}/export", params={"format": "abb"}).content


def test_a_name_the_encoding_cannot_hold_is_refused_naming_it(client):
    ok(imp(client, "kuka", "kuka_krc4_crlf_cp1252.dat"))
    put(client, "/tools/1", {"name": "Greifer \u4e00"})
    r = client.get(f"{C}/export", params={"format": "kuka"})
    assert r.status_code == 422
    assert "cp1252" in r.json()["detail"][0]["msg"]


# ---------------------------------------------------------------- 3. ABB line endings

def test_abb_patch_keeps_each_lines_own_ending():
    text, _ = load("abb_mixed_endings.mod")
    entries = read_abb(text).entries
    moved = [formats.FrameEntry(e.number, e.name, e.kind, e.pose.__class__(
        e.pose.x + 1, *e.pose.as_array()[1:]), e.load) if e.number == 1 and e.kind == "tool"
        else e for e in entries]
    out = export_abb(moved, template=text)
    ends = lambda t: re.findall(r"\r\n|\n", t)  # noqa: E731
    assert ends(out) == ends(text)
    assert sum(a != b for a, b in zip(text.splitlines(), out.splitlines())) == 1


# ---------------------------------------------------------------- 4. KUKA slot type kept

def test_kuka_base_type_zero_blank_slot_stays_a_used_slot(client):
    res = ok(imp(client, "kuka", "kuka_krc4_crlf_cp1252.dat", dry_run=True))
    tool2 = next(s for s in res["slots"] if (s["table"], s["number"]) == ("tool", 2))
    assert tool2["after"] is not None and tool2["after"]["kind"] == "tool"
    ok(imp(client, "kuka", "kuka_krc4_crlf_cp1252.dat"))
    put(client, "/tools/1", {"pose": {"z": 358}})
    out = client.get(f"{C}/export", params={"format": "kuka"}).content.decode("cp1252")
    assert "TOOL_TYPE[2]=#BASE" in out and "BASE_TYPE[3]=#BASE" in out


# ---------------------------------------------------------------- 5. routine data

def test_abb_routine_parameters_and_routine_data_are_skipped_and_named():
    text, _ = load("abb_program_cp1252_crlf.mod")
    parsed = read_abb(text)
    tools = [(e.number, e.name) for e in parsed.entries if e.kind == "tool"]
    assert tools == [(1, "tGripper"), (2, "tSpare"), (3, "tPen")]  # tTemp is no tool 1
    skipped = {k.field: (k.line, k.reason) for k in parsed.skipped}
    assert skipped["Tool"][0] == 21 and "parameter of PROC MoveWith" in skipped["Tool"][1]
    assert skipped["tTemp"][0] == 16 and "inside PROC main" in skipped["tTemp"][1]


def test_abb_preview_names_the_skipped_routine_data(client):
    res = ok(imp(client, "abb", "abb_program_cp1252_crlf.mod", dry_run=True))
    assert {(k["line"], k["field"]) for k in res["skipped"]} >= {(16, "tTemp"), (21, "Tool")}


# ---------------------------------------------------------------- 6. a missing ';'

def test_abb_missing_semicolon_is_refused_naming_the_line(client):
    text = ("MODULE M\n  PERS tooldata t1:=[TRUE,[[0,0,100],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]]\n"
            "  PERS tooldata t2:=[TRUE,[[0,0,200],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];\n"
            "ENDMODULE\n")
    with pytest.raises(FormatError) as err:
        read_abb(text)
    assert err.value.loc == ("file", "line 2", "t1") and "no ';'" in err.value.reason
    before = client.get(f"{C}/export", params={"format": "json"}).json()["entries"]
    r = client.post(f"{C}/import", json={"format": "abb", "text": text})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "file", "line 2", "t1"]
    assert client.get(f"{C}/export", params={"format": "json"}).json()["entries"] == before


# ---------------------------------------------------------------- 7. every slot unused

def test_kuka_file_with_every_slot_unused_imports_calibrates_and_exports(client):
    put(client, "/tools/3", {"name": "old"})
    res = ok(imp(client, "kuka", "kuka_all_unused.dat"))
    assert res["entries"] == 0 and ok(client.get(f"{C}/tools/3"))["name"] == ""
    put(client, "/tools/1", {"name": "pointer", "pose": {"z": 180}})
    out = client.get(f"{C}/export", params={"format": "kuka"}).text
    assert "TOOL_DATA[1]={X 0.0,Y 0.0,Z 180.0,A 0.0,B 0.0,C 0.0}" in out
    assert 'TOOL_NAME[1,]="pointer"' in out and "TOOL_TYPE[1]=#BASE" in out
    assert read_kuka(out).entries[0].name == "pointer"


# ---------------------------------------------------------------- 8. ABB mass -1

def test_abb_tool_mass_minus_one_is_read_as_no_load_with_a_named_warning():
    parsed = read_abb(load("abb_program_cp1252_crlf.mod")[0])
    spare = next(e for e in parsed.entries if e.name == "tSpare")
    assert spare.load is None and spare.pose.x == 10
    warn = next(k for k in parsed.skipped if k.field == "tSpare.tload.mass")
    assert warn.line == 9 and "not set" in warn.reason


def test_abb_36_tools_read_whole_and_patch_one():
    text, _ = load("abb_backup_36_tools.sys")
    entries = read_abb(text).entries
    assert sum(e.kind == "tool" for e in entries) == 36
    assert export_abb(entries, template=text) == text


# ---------------------------------------------------------------- 9. a #NONE slot's name

def test_kuka_none_slot_keeps_its_name(client):
    ok(imp(client, "kuka", "kuka_krc4_crlf_cp1252.dat"))
    base = ok(client.get(f"{C}/bases/10"))
    assert base["name"] == "KukaReburn"
    assert 'BASE_NAME[10,]="KukaReburn"' in client.get(f"{C}/export", params={"format": "kuka"}).text


# ---------------------------------------------------------------- import chosen slots

def test_an_import_of_chosen_slots_keeps_the_calibrated_ones(client):
    put(client, "/tools/1", {"name": "calibrated", "pose": {"x": 1.25, "z": 201.5}})
    res = ok(imp(client, "kuka", "kuka_krc4_crlf_cp1252.dat",
                 slots=[{"table": "tool", "number": 3}, {"table": "base", "number": 1}]))
    assert {(s["table"], s["number"]) for s in res["slots"]} == {("tool", 3), ("base", 1)}
    assert ok(client.get(f"{C}/tools/1"))["name"] == "calibrated"
    assert ok(client.get(f"{C}/tools/3"))["name"] == "Tür links"
    out = client.get(f"{C}/export", params={"format": "kuka"}).content.decode("cp1252")
    assert "TOOL_DATA[1]={X 1.25,Y 0.0,Z 201.5,A 0.0,B 0.0,C 0.0}" in out
    assert 'TOOL_NAME[1,]="calibrated"' in out
    r = imp(client, "kuka", "kuka_krc4_crlf_cp1252.dat", slots=[{"table": "tool", "number": 17}])
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "slots", 0]
    assert "does not name tool 17" in r.json()["detail"][0]["msg"]


# ---------------------------------------------------------------- FANUC and UR

@pytest.mark.parametrize("fmt, name, changed_lines", [("fanuc", "fanuc_crlf.txt", 4),
                                                      ("ur", "ur_crlf.script", 2)])
def test_fanuc_and_ur_imports_come_back_whole_with_only_the_changed_lines(client, fmt, name,
                                                                         changed_lines):
    """pendant's own FANUC listing and UR script: a no-change export is the file, byte for
    byte (CR LF kept); a change rewrites only the lines that carry the changed values."""
    raw = (CORPUS / name).read_bytes()
    text = raw.decode()
    ok(client.post(f"{C}/import", json={"format": fmt, "text": text}))
    assert client.get(f"{C}/export", params={"format": fmt}).content == raw
    before = read = formats.READERS[fmt](text).entries
    tool = next(e for e in before if e.kind == "tool")
    base = next(e for e in before if e.kind == "base")
    put(client, f"/tools/{tool.number}", {"pose": {"x": tool.pose.x + 1}})
    put(client, f"/bases/{base.number}", {"pose": {"a": base.pose.a + 1}})
    out = client.get(f"{C}/export", params={"format": fmt}).content.decode()
    assert re.findall(r"\r\n|\n", out) == re.findall(r"\r\n|\n", text)
    diff = [(a, b) for a, b in zip(text.splitlines(), out.splitlines()) if a != b]
    assert len(diff) == changed_lines
    read = {(e.kind, e.number): e for e in formats.READERS[fmt](out).entries}
    assert read[("tool", tool.number)].pose.x == pytest.approx(tool.pose.x + 1, abs=1e-6)
    assert read[("base", base.number)].pose.a == pytest.approx(base.pose.a + 1, abs=1e-6)


def test_the_backup_keeps_the_files_encoding_and_the_cli_exports_its_bytes(client, db_url, capsysbinary):
    """The kept Windows-1252 file goes through a JSON backup and restore, and ``pendant
    export`` writes its bytes (not UTF-8)."""
    from api_helpers import finish_job
    from server.cli.main import main

    raw = (CORPUS / "kuka_krc4_crlf_cp1252.dat").read_bytes()
    ok(imp(client, "kuka", "kuka_krc4_crlf_cp1252.dat"))
    backup = client.get(f"{C}/export", params={"format": "json"}).text
    r = client.post(f"{C}/import", json={"format": "json", "text": backup,
                                         "slots": [{"table": "tool", "number": 1}]})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "slots"]
    other = f"/controllers/{ok(client.post('/controllers', json={'name': 'restored'}))['id']}"
    finish_job(client, client.post(f"{other}/import", json={"format": "json", "text": backup}))
    assert client.get(f"{other}/export", params={"format": "kuka"}).content == raw
    capsysbinary.readouterr()
    assert main(["export", "cell-1", "--format", "kuka", "--db", db_url]) == 0
    assert capsysbinary.readouterr().out == raw


# ------------------------------------------------------- FANUC: the controller's SYSFRAME.VA

def test_fanuc_sysframe_from_a_controller_imports_and_comes_back_with_only_the_changed_numbers(
        client):
    """A controller's SYSFRAME.VA (CR LF, two motion groups, Uninitialized and zero frames, a
    hand-spaced line): group 1's tools and user frames become tools and bases, the
    positioner's frames are named as left out; a no-change export is the file byte for byte,
    a change rewrites only the numbers of the frame that changed, an Uninitialized tool that
    gets a frame gets the controller's lines."""
    raw = (CORPUS / "fanuc_sysframe_crlf.va").read_bytes()
    text = raw.decode("ascii")
    r = ok(client.post(f"{C}/import", json={"format": "fanuc", "text": text}))
    assert [(s["field"], s["line"]) for s in r["skipped"]] == [("$MNUFRAME[2,1]", 38),
                                                               ("$MNUTOOL[2,1]", 114)]
    tools = {n: ok(client.get(f"{C}/tools/{n}")) for n in (1, 2, 3)}
    assert [tools[3]["pose"][k] for k in "xyzabc"] == pytest.approx(
        [12.5, -1234.567, 310.25, 180.0, 45.0, 0.0], abs=1e-9)  # A = R, B = P, C = W
    assert tools[1]["kind"] == "tool" and tools[1]["name"] == ""
    assert not any(tools[2]["pose"][k] for k in "xyzabc")  # Uninitialized: unused
    base2 = ok(client.get(f"{C}/bases/2"))
    assert [base2["pose"][k] for k in "xyz"] == pytest.approx([800.125, 600.0, -12.5])
    assert client.get(f"{C}/export", params={"format": "fanuc"}).content == raw

    put(client, "/tools/1", {"pose": {"x": 2.25}})
    out = client.get(f"{C}/export", params={"format": "fanuc"}).content.decode("ascii")
    assert out.count("\r\n") == text.count("\r\n") and "\n" not in out.replace("\r\n", "")
    diff = [(a, b) for a, b in zip(text.split("\r\n"), out.split("\r\n")) if a != b]
    assert diff == [("  X:     1.250   Y:    -0.500   Z:   185.000",
                     "  X:     2.250   Y:    -0.500   Z:   185.000")]

    put(client, "/tools/2", {"pose": {"x": 10.0, "y": 0.0, "z": 99.5, "a": 0.0, "b": 0.0,
                                      "c": 0.0}})
    out = client.get(f"{C}/export", params={"format": "fanuc"}).content.decode("ascii")
    rows = out.split("\r\n")
    tool_table = next(i for i, row in enumerate(rows) if row.startswith("[*SYSTEM*]$MNUTOOL "))
    at = rows.index("    [1,2] = ", tool_table)  # as the file prints its other frames
    assert rows[at + 1:at + 4] == [
        "  Group: 1   Config: N D B, 0, 0, 0",
        "  X:    10.000   Y:     0.000   Z:    99.500",
        "  W:     0.000   P:     0.000   R:     0.000"]
    again = {(e.kind, e.number): e for e in formats.READERS["fanuc"](out).entries}
    assert again[("tool", 2)].pose.z == pytest.approx(99.5)
    assert again[("tool", 1)].pose.x == pytest.approx(2.25)

    put(client, "/tools/12", {"pose": {"z": 50.0}})  # a KUKA-kind table has 16 tools
    r = client.get(f"{C}/export", params={"format": "fanuc"})
    assert r.status_code == 422, r.text
    d = r.json()["detail"][0]
    assert "tool 12" in d["loc"] and "has no $MNUTOOL[1,12] (its table holds tools 1..10)" \
        in d["msg"], d


def test_fanuc_sysframe_angles_are_fixed_xyz_as_scipy_reads_them():
    """W, P, R of $MNUFRAME are rotations about the fixed X, Y, Z axes (R = Rz(R) Ry(P)
    Rx(W)): scipy's Rotation 'xyz' (extrinsic) is the judge."""
    from scipy.spatial.transform import Rotation

    text = (CORPUS / "fanuc_sysframe_crlf.va").read_bytes().decode("ascii")
    base2 = next(e for e in formats.READERS["fanuc"](text).entries
                 if e.kind == "base" and e.number == 2)
    R = Rotation.from_euler("xyz", [0.5, -0.25, 179.5], degrees=True).as_matrix()
    assert base2.pose.as_matrix()[:3, :3] == pytest.approx(R, abs=1e-12)


@pytest.mark.parametrize("edit, loc, reason", [
    (("X:  1500.000", "X:  15OO.000"), ["file", "line 7", "$MNUFRAME[1,1]"],
     "expected 'X: <mm>  Y: <mm>  Z: <mm>', got 'X:  15OO.000"),
    (("  W:     0.000   P:     0.000   R:    90.000\r\n", ""), ["file", "line 5",
                                                               "$MNUFRAME[1,1]"],
     "the frame's W, P, R line is missing"),
    (("Z:   185.000", "Z:   2e7"), ["file", "line 79", "$MNUTOOL[1,1].Z"],
     "must be within -1e+06..1e+06 mm"),
    (("Z:   185.000", "Z:    1.#INF"), ["file", "line 79", "$MNUTOOL[1,1]"],
     "expected 'X: <mm>  Y: <mm>  Z: <mm>', got 'X:     1.250   Y:    -0.500   Z:    1.#INF'"),
    (("Z:   185.000", "Z:   185.000abc"), ["file", "line 79", "$MNUTOOL[1,1]"],
     "expected 'X: <mm>  Y: <mm>  Z: <mm>'"),
    (("    [1,2] = Uninitialized", "    [1,1] = Uninitialized"), ["file", "line 81",
                                                                 "$MNUTOOL[1,1]"],
     "listed twice (first at line 77)"),
    (("    [1,3] = \r\n  Group: 1   Config: N D B, 0, 0, 0\r\n  X:    12.500 Y:   -1234.567"
      "   Z:   310.250\r\n", "    [1,3] = \r\n"), ["file", "line 83", "$MNUTOOL[1,3]"],
     "W, P, R before X, Y, Z"),
    (("    [1,9] = \r\n  Group: 1", "    [1,12] = \r\n  Group: 1"), ["file", "line 34",
                                                                   "$MNUFRAME[1,12]"],
     "frames are numbered 1..9 (the table's ARRAY[..,9])"),
])
def test_a_bad_sysframe_is_refused_naming_the_line_and_the_frame(client, edit, loc, reason):
    text = (CORPUS / "fanuc_sysframe_crlf.va").read_bytes().decode("ascii")
    assert edit[0] in text
    before = client.get(f"{C}/export", params={"format": "json"}).content
    r = client.post(f"{C}/import", json={"format": "fanuc", "text": text.replace(edit[0], edit[1], 1)})
    assert r.status_code == 422, r.text
    d = r.json()["detail"][0]
    assert d["loc"][-3:] == loc and reason in d["msg"], d
    assert client.get(f"{C}/export", params={"format": "json"}).content == before


def test_pendant_import_reads_a_va_file_by_its_suffix(client, db_url, tmp_path, capsys):
    from server.cli.main import main

    f = tmp_path / "SYSFRAME.VA"
    f.write_bytes((CORPUS / "fanuc_sysframe_crlf.va").read_bytes())
    assert main(["import", str(f), "--controller", "cell-1", "--db", db_url, "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"tool +3: '\(unused\)' -> '' \(tool\)", out) and "-1234.567" in out, out


def test_fanuc_sysframe_keeps_w_p_r_that_name_the_same_rotation_otherwise():
    """Near P = 90 deg many W, P, R name one rotation (W 10 P 90 R 20 is W -10 P 90 R 0): an
    export with nothing changed, or with only X changed, keeps the file's W, P, R line."""
    text = (CORPUS / "fanuc_sysframe_crlf.va").read_bytes().decode("ascii")
    wpr = "  W:     0.000   P:   -90.000   R:     0.000"
    locked = text.replace(wpr, "  W:    10.000   P:    90.000   R:    20.000")
    assert locked != text
    entries = formats.READERS["fanuc"](locked).entries
    assert formats.PATCHERS["fanuc"](entries, locked) == locked
    t1 = next(e for e in entries if (e.kind, e.number) == ("tool", 1))
    moved = [replace(e, pose=replace(e.pose, x=e.pose.x + 1)) if e is t1 else e
             for e in entries]
    out = formats.PATCHERS["fanuc"](moved, locked)
    assert [(a, b) for a, b in zip(locked.split("\r\n"), out.split("\r\n")) if a != b] == [
        ("  X:     1.250   Y:    -0.500   Z:   185.000", "  X:     2.250   Y:    -0.500   Z:   185.000")]


def test_fanuc_sysframe_last_line_uninitialized_and_a_base_on_a_positioner():
    """An Uninitialized last line without a line end gets its four lines, the last again
    without one; a base on a positioner has no place in the robot's $MNUFRAME: refused."""
    text = ("[*SYSTEM*]$MNUTOOL  Storage: SHADOW  Access: RW  : ARRAY[1,10] OF POSITION\n"
            "    [1,1] = \n  Group: 1   Config: N D B, 0, 0, 0\n"
            "  X:     1.000   Y:     0.000   Z:   100.000\n"
            "  W:     0.000   P:     0.000   R:     0.000\n    [1,2] = Uninitialized")
    (tool,) = formats.READERS["fanuc"](text).entries
    out = formats.PATCHERS["fanuc"]([tool, replace(tool, number=2)], text)
    assert out.endswith("\n    [1,2] = \n  Group: 1   Config: N D B, 0, 0, 0\n"
                        "  X:     1.000   Y:     0.000   Z:   100.000\n"
                        "  W:     0.000   P:     0.000   R:     0.000"), out
    frames = (CORPUS / "fanuc_sysframe_crlf.va").read_bytes().decode("ascii")
    entries = formats.READERS["fanuc"](frames).entries
    base = next(e for e in entries if e.kind == "base")
    with pytest.raises(FormatError, match="a base on the external axis unit POS1"):
        formats.PATCHERS["fanuc"]([replace(base, kind="coordinated_base", mech_unit="POS1")
                                   if e is base else e for e in entries], frames)


D = "1" * 5000  # Python's int() refuses more than 4300 digits with a ValueError


@pytest.mark.parametrize("fmt, name, old, new, line", [
    ("kuka", "kuka_krc4_crlf_cp1252.dat", "TOOL_DATA[16]", f"TOOL_DATA[{D}]", 15),  # a size
    ("kuka", "kuka_krc4_crlf_cp1252.dat", "TOOL_DATA[1]=", f"TOOL_DATA[{D}]=", 16),  # an index
    ("abb", "abb_mixed_endings.mod", "! pendant: tool 1 ", f"! pendant: tool {D} ", 3),
    ("fanuc", "fanuc_crlf.txt", " [1,1] =  ! tool", f" [1,{D}] =  ! tool", 25),
    ("fanuc", "fanuc_sysframe_crlf.va", "ARRAY[2,9] OF POSITION", f"ARRAY[2,{D}] OF POSITION", 4),
    ("ur", "ur_crlf.script", "# tool 1 ", f"# tool {D} ", 5),
    ("kuka", "kuka_krc4_crlf_cp1252.dat", "TOOL_DATA[1]=", "TOOL_DATA[\u0663]=", 16),
])
def test_an_index_of_thousands_of_digits_is_refused_naming_its_line(client, fmt, name, old, new,
                                                                    line):
    """An index or a table size of 5000 digits in a controller file: 422 naming the file's
    line, nothing imported (it was a 500, Python's int() refusing the string); one written in
    another script's digits (int() reads "\u0663" as 3) too."""
    text, encoding = load(name)
    assert old in text
    body = {"format": fmt, "text": text.replace(old, new, 1)}
    if encoding != "utf-8":
        body["encoding"] = encoding
    before = ok(client.get(f"{C}/tools"))
    r = client.post(f"{C}/import", json=body)
    assert r.status_code == 422, r.text[:300]
    detail = r.json()["detail"][0]
    assert f"line {line}" in detail["loc"] and "an index " in detail["msg"], detail
    assert ok(client.get(f"{C}/tools")) == before


def test_a_machine_def_index_of_thousands_of_digits_is_kept_and_exports_still_work(client):
    """A $config.dat whose MACHINE_DEF has an index of 5000 digits imports (pendant does not
    read MACHINE_DEF from it) and every later export keeps the line byte for byte: each export
    answered 500 (Python's int() refusing the string)."""
    text, encoding = load("kuka_krc4_crlf_cp1252.dat")
    odd = f'MACHINE_DEF[{D}]={{NAME[] "TABLE1"}}'
    ok(client.post(f"{C}/import", json={"format": "kuka", "encoding": encoding,
                                         "text": text.replace("ENDDAT", odd + "\r\nENDDAT", 1)}))
    r = client.get(f"{C}/export", params={"format": "kuka"})
    assert r.status_code == 200 and odd.encode("cp1252") + b"\r\n" in r.content


def test_a_fanuc_payload_line_without_its_number_is_refused_naming_the_line(client):
    """``PAYLOAD [ 1 ...`` (the number out of its columns): 422 naming line 19; it was a 500
    (found by mutating the corpus files)."""
    text, _ = load("fanuc_crlf.txt")
    r = client.post(f"{C}/import", json={"format": "fanuc",
                                         "text": text.replace("PAYLOAD  1", "PAYLOAD [ 1", 1)})
    assert r.status_code == 422, r.text[:300]
    detail = r.json()["detail"][0]
    assert "line 19" in detail["loc"] and "payload's number" in detail["msg"], detail


@pytest.mark.parametrize("old, new", [("UTOOL    1  Pointer", "UTOOL 1  Pointer"),
                                      ("UTOOL    1  Pointer", "UTOOL\u0663\u0663\u0663  Pointer")])
def test_a_fanuc_row_whose_columns_moved_is_refused_naming_the_line(client, old, new):
    """A UTOOL row with its number out of columns 8-10 (typed by hand): 422 naming line 6; it
    was taken as a comment and the tool silently left out of the import."""
    text, _ = load("fanuc_crlf.txt")
    assert old in text
    r = client.post(f"{C}/import", json={"format": "fanuc", "text": text.replace(old, new, 1)})
    assert r.status_code == 422, r.text[:300]
    detail = r.json()["detail"][0]
    assert "line 6" in detail["loc"] and "columns 8-10" in detail["msg"], detail
