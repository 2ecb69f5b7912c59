"""The field corpus (tests/data/field_corpus, written by make_field_corpus.py there): controller
files with traits real ones have and tests/data/controller-files lacks -- a KSS 5 $config.dat
with six-digit reals and the declarations around the tables, a hand-edited $config.dat (UTF-8
with a BOM, lower case, no DECL, free spacing, E-notation, -0.0, no last line end), a RobotWare
6 module (TASK PERS, LOCAL, %%% header, multi-line declarations with comments inside, arrays,
RECORD, 9E+09, a wobjdata with uframe and oframe turned), a UTF-8 system module with a BOM,
and a one-group SYSFRAME.VA with LF and no last line end. The public files each trait was
checked against are named in make_field_corpus.py.

For each file: the import reads the values the file holds (checked against the numbers in
the text), an export with no change is the file byte for byte, and changing one value
changes that value's text only (through the formats' public functions and through the REST
API). A file that cannot be read is refused naming its line and the reason."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import pytest

from api_helpers import C, ok
from server import formats
from server.formats import FormatError

CORPUS = Path(__file__).parent / "data" / "field_corpus"
FILES = {  # file -> format
    "kuka_kss5_6digit_cp1252_crlf.dat": "kuka",
    "kuka_hand_edited_utf8_bom.dat": "kuka",
    "abb_rw6_task_pers_cp1252_crlf.mod": "abb",
    "abb_sysmodule_utf8_bom_lf.sys": "abb",
    "fanuc_sysframe_one_group_lf.va": "fanuc",
    "ur_commented_bom_no_final_eol.script": "ur",
    "fanuc_listing_commented_no_final_eol.txt": "fanuc",
}
NUM = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
ABB_ARM = "abb_irb120"


def load(name: str) -> tuple[bytes, str, str]:
    raw = (CORPUS / name).read_bytes()
    text, encoding = formats.decode_file(raw)
    return raw, text, encoding


def entries(name: str) -> list[formats.FrameEntry]:
    return formats.READERS[FILES[name]](load(name)[1]).entries


def slot(es: list[formats.FrameEntry], kind: str, number: int) -> formats.FrameEntry:
    return next(e for e in es if (e.kind, e.number) == (kind, number))


def lines_with_ends(text: str) -> list[tuple[str, str]]:
    parts = re.split(r"(\r\n|\r|\n)", text)
    return list(zip(parts[0::2], parts[1::2] + [""]))


def changed_numbers(old: str, new: str) -> list[tuple[int, str, str]]:
    """(line, old text, new text) of every number whose text differs; everything else (the
    lines, their endings, the text between the numbers) must be equal."""
    a, b = lines_with_ends(old), lines_with_ends(new)
    assert len(a) == len(b), "a line was added or removed"
    out = []
    for i, ((la, ea), (lb, eb)) in enumerate(zip(a, b), 1):
        assert ea == eb, f"line {i}: its ending changed from {ea!r} to {eb!r}"
        if la != lb:
            assert NUM.split(la) == NUM.split(lb), f"line {i}: more than numbers changed:\n{la}\n{lb}"
            out += [(i, x, y) for x, y in zip(NUM.findall(la), NUM.findall(lb)) if x != y]
    return out


def line_of(text: str, needle: str) -> int:
    return next(i for i, (s, _) in enumerate(lines_with_ends(text), 1) if needle in s)


# ------------------------------------------------------------------ 1. the values read

def test_kss5_file_reads_six_digit_reals_kinds_names_and_loads():
    """KSS 5 prints reals with six significant digits (380.790, -90.0000, M -1.00000); the
    declarations around the tables (E6AXIS with E1..E6, STRUC/ENUM, SIGNAL ... TO ...,
    MACHINE_TOOL_DAT, MACHINE_FRAME_DAT with PARENT[] "WORLD") are left alone."""
    es = entries("kuka_kss5_6digit_cp1252_crlf.dat")
    assert [(e.kind, e.number) for e in es] == [("tool", 1), ("tool", 2), ("workpiece", 3),
                                                ("tool", 4), ("base", 1), ("fixed_tool", 2),
                                                ("base", 11)]
    t1, t2 = slot(es, "tool", 1), slot(es, "tool", 2)
    assert t1.name == "Schweißzange Öl" and t1.pose.as_array().tolist() == [0, 0, 380.79, -90, -90, -90]
    assert t1.load.mass_kg == 21.0 and t1.load.inertia_kgm2 == (1.05, 1.05, 0.55)
    assert t2.load.inertia_axes_deg == (89.777, -0.721, 0.991)
    assert slot(es, "workpiece", 3).load is None  # M -1.00000: not set
    b1 = slot(es, "base", 1)
    assert b1.mech_unit is None and b1.name == "Vorrichtung 10A"  # PARENT[] "WORLD": no unit
    assert slot(es, "fixed_tool", 2).pose.as_array().tolist() == [21.84, 1866.09, 658.47, 90, 0, 180]
    t4 = slot(es, "tool", 4)  # #NONE, but a frame, a name and a load: a tool
    assert t4.name == "Fräser alt" and t4.pose.y == 3.01155138 and t4.load.mass_kg == 42.0494804
    assert slot(es, "base", 11).pose.c == -0.0897579566 and slot(es, "base", 11).name == ""


def test_hand_edited_kuka_file_reads_lower_case_no_decl_and_e_notation():
    es = entries("kuka_hand_edited_utf8_bom.dat")
    t1 = slot(es, "tool", 1)
    assert t1.name == "Stift; lang"  # a ';' inside the string is not a comment
    assert t1.pose.as_array().tolist() == [100.0, 0.0, 0.0015, 0.0, 90.0, 0.0]  # 1.0E+02, 1.5e-3
    assert t1.load.inertia_kgm2 == (0.001, 0.001, 0.0005)
    assert slot(es, "workpiece", 2).pose.z == 250.0  # "2.5E+2", tab-indented, trailing comment
    assert slot(es, "base", 1).pose.as_array().tolist() == [1000.0, -250.0, 0, 0, 0, 0]
    assert len(es) == 3  # #none slots with zero frames and blank names are unused


def test_rw6_module_reads_task_local_multiline_and_skips_what_it_cannot_use():
    p = formats.READERS["abb"](load("abb_rw6_task_pers_cp1252_crlf.mod")[1])
    es = p.entries
    assert [(e.kind, e.number, e.name) for e in es] == [
        ("tool", 1, "tWeldGun"), ("tool", 2, "tFlip"), ("tool", 3, "tProbe"),
        ("base", 1, "U_kal"), ("base", 2, "wTable")]
    assert slot(es, "tool", 1).load.inertia_kgm2 == (0.034, 0.069, 0.044)
    flip = slot(es, "tool", 2)  # [1.91069E-15,-1,-4.37114E-08,-4.37114E-08]: half a turn about x
    assert flip.pose.c == pytest.approx(180.0) and abs(flip.pose.a) < 1e-5
    assert flip.load.mass_kg == 0.0
    probe = slot(es, "tool", 3)  # over five lines, with '!' comments inside the aggregate
    assert probe.pose.as_array().tolist() == [0.5, -0.25, 120.75, 0, 0, 0]
    assert probe.load.com_mm == (0.0, 0.0, 40.0)
    # uframe [[1000,-250,12.5], 90 deg about x] @ oframe [[50,20,0], 30 deg about z]
    assert slot(es, "base", 1).pose.as_array()[:3] == pytest.approx([1050, -250, 32.5], abs=1e-3)
    assert [(s.line, s.field) for s in p.skipped] == [(22, "tSpare")]  # the array of tooldata


def test_sysmodule_with_bom_reads_lower_case_pers_const_and_a_bang_inside_a_string():
    es = entries("abb_sysmodule_utf8_bom_lf.sys")
    assert [(e.kind, e.number, e.name) for e in es] == [("tool", 1, "tNozzle"), ("tool", 2, "tRef"),
                                                        ("base", 1, "wJig")]
    assert slot(es, "tool", 1).pose.b == pytest.approx(10.0, abs=1e-5)


def test_one_group_sysframe_reads_tools_and_frames():
    es = entries("fanuc_sysframe_one_group_lf.va")
    assert [(e.kind, e.number) for e in es] == [("tool", 1), ("tool", 2), ("base", 1)]
    assert slot(es, "tool", 2).pose.as_array().tolist() == pytest.approx(
        [12.125, -3.5, 240.0, 0.0, -30.0, 180.0])  # A = R, B = P, C = W
    assert slot(es, "base", 1).pose.as_array().tolist() == [1200.0, -350.25, 0, 90, 0, 0]


def test_pendants_own_files_as_a_person_keeps_them_read_whole():
    """pendant's UR script and FANUC listing with a comment line added, a hand-spaced line
    and no line end after the last line read as the files they came from."""
    data = Path(__file__).parent / "data"
    for name, fmt, src in (("ur_commented_bom_no_final_eol.script", "ur", "ur_cell7.script"),
                           ("fanuc_listing_commented_no_final_eol.txt", "fanuc", "fanuc_cell7.txt")):
        text = load(name)[1]
        assert formats.READERS[fmt](text).entries == formats.READERS[fmt]((data / src).read_text()).entries


@pytest.mark.parametrize("old,new,field", [
    ("set_payload(6.8,  [", "set_payload(6.8 [", "tool_2.payload"),
    ("global tool_6 =  p[", "global tool_6 = [", "tool_6"),
])
def test_ur_line_that_cannot_be_read_is_refused_naming_it_not_dropped(old, new, field):
    """A set_payload or global line the reader cannot take is named at its own line, never
    read as "no load" (nor blamed on the tool's comment line)."""
    text = load("ur_commented_bom_no_final_eol.script")[1]
    bad = text.replace(old, new)
    assert bad != text
    with pytest.raises(FormatError) as err:
        formats.READERS["ur"](bad)
    assert err.value.loc == ("file", f"line {line_of(bad, new)}", field)


# ------------------------------------------------------------------ 2. byte for byte

@pytest.mark.parametrize("name", FILES)
def test_no_change_export_is_the_file_byte_for_byte(name):
    raw, text, encoding = load(name)
    out = formats.PATCHERS[FILES[name]](entries(name), text)
    assert formats.encode_file(out, encoding) == raw


# ------------------------------------------------------------------ 3. one value changed

CHANGES = [  # file, slot, field, new value, (the needle of the line that changes, old, new text)
    ("kuka_kss5_6digit_cp1252_crlf.dat", ("tool", 2), "x", 421.39, ("TOOL_DATA[2]=", "420.390", "421.39")),
    ("kuka_kss5_6digit_cp1252_crlf.dat", ("tool", 1), "a", -89.5, ("TOOL_DATA[1]=", "-90.0000", "-89.5")),
    ("kuka_kss5_6digit_cp1252_crlf.dat", ("base", 1), "z", -215.0, ("BASE_DATA[1]=", "-215.137", "-215.0")),
    ("kuka_kss5_6digit_cp1252_crlf.dat", ("tool", 2), "mass", 13.5, ("LOAD_DATA[2]=", "12.9297", "13.5")),
    # a #NONE slot with a frame: the new number goes in, its TYPE stays #NONE
    ("kuka_kss5_6digit_cp1252_crlf.dat", ("tool", 4), "z", 170.0, ("TOOL_DATA[4]=", "166.257782", "170.0")),
    ("kuka_kss5_6digit_cp1252_crlf.dat", ("base", 11), "b", 0.25, ("BASE_DATA[11]=", "0.254145205", "0.25")),
    ("kuka_hand_edited_utf8_bom.dat", ("tool", 1), "x", 101.0, ("tool_data[1]", "1.0E+02", "101.0")),
    ("kuka_hand_edited_utf8_bom.dat", ("tool", 1), "y", 0.25, ("tool_data[1]", "-0.0", "0.25")),
    ("kuka_hand_edited_utf8_bom.dat", ("workpiece", 2), "z", 251.0, ("tool_data[2]", "2.5E+2", "251.0")),
    ("abb_rw6_task_pers_cp1252_crlf.mod", ("tool", 1), "x", 110.186, ("tWeldGun", "109.186", "110.186")),
    ("abb_rw6_task_pers_cp1252_crlf.mod", ("tool", 2), "z", 95.0, ("tFlip", "0", "95")),
    ("abb_rw6_task_pers_cp1252_crlf.mod", ("tool", 3), "x", 1.5, ("[ [ 0.5,", "0.5", "1.5")),
    ("abb_rw6_task_pers_cp1252_crlf.mod", ("tool", 3), "mass", 0.35, ("[ 0.3,", "0.3", "0.35")),
    ("abb_rw6_task_pers_cp1252_crlf.mod", ("base", 2), "x", 451.0, ("wTable", "450", "451")),
    # a work object with both uframe and oframe turned (public "U_kal", 6-digit quaternion):
    # a new X moves the uframe's x by as much; its quaternion keeps its text
    ("abb_rw6_task_pers_cp1252_crlf.mod", ("base", 1), "x", 1051.0, ("U_kal", "1000", "1001")),
    ("abb_sysmodule_utf8_bom_lf.sys", ("tool", 2), "z", 151.0, ("tRef", "150", "151")),
    ("fanuc_sysframe_one_group_lf.va", ("tool", 2), "x", 13.125, ("12.125", "12.125", "13.125")),
    # pendant's own files with a comment line of the user's, a hand-spaced line and no line
    # end after the last line: the comment, the spacing and the missing line end stay
    ("ur_commented_bom_no_final_eol.script", ("tool", 4), "z", 314.0, ("global tool_4", "0.313237", "0.314")),
    ("fanuc_listing_commented_no_final_eol.txt", ("base", 1), "x", 1334.5,  # the row, the listing
     [("UFRAME   1", "1333.940000", "1334.500000"), ("1333.940000   Y:", "1333.940000", "1334.500000")]),
]


def changed(e: formats.FrameEntry, fld: str, value: float) -> formats.FrameEntry:
    if fld == "mass":
        return replace(e, load=replace(e.load, mass_kg=value))
    return replace(e, pose=replace(e.pose, **{fld: value}))


@pytest.mark.parametrize("name,key,fld,value,expect", CHANGES,
                         ids=[f"{c[0].split('_')[0]}-{c[1][0]}{c[1][1]}-{c[2]}" for c in CHANGES])
def test_one_changed_value_changes_only_its_text(name, key, fld, value, expect):
    raw, text, encoding = load(name)
    es = entries(name)
    i = next(j for j, e in enumerate(es) if (e.kind, e.number) == key)
    new = list(es)
    new[i] = changed(es[i], fld, value)
    out = formats.PATCHERS[FILES[name]](new, text)
    formats.encode_file(out, encoding)  # still fits the file's encoding
    expect = expect if isinstance(expect, list) else [expect]
    assert changed_numbers(text, out) == [(line_of(text, needle), o, n) for needle, o, n in expect]
    assert formats.READERS[FILES[name]](out).entries == formats.canonical_order(new)


# ------------------------------------------------------------------ 4. through the REST API

def controller_for(client, fmt: str) -> str:  # noqa: ANN001
    if fmt != "abb":
        return C  # the demo KUKA cell takes KUKA files and a SYSFRAME.VA
    cid = ok(client.post("/controllers", json={"name": "abb-field", "robot": ABB_ARM}))["id"]
    return f"/controllers/{cid}"


@pytest.mark.parametrize("name", FILES)
def test_api_import_export_keeps_the_bytes_and_a_put_changes_one_number(client, name):
    """POST .../import (the file's own encoding), GET .../export: the same bytes (a BOM, CR LF,
    Windows-1252, no last line end); PUT one tool's X (a JSON Merge Patch): one number's text
    differs, in its line, and the file reads back with that change."""
    raw, text, encoding = load(name)
    fmt = FILES[name]
    path = controller_for(client, fmt)
    ok(client.post(f"{path}/import", json={"format": fmt, "text": text, "encoding": encoding}))
    r = client.get(f"{path}/export", params={"format": fmt})
    assert r.content == raw
    tool = next(e for e in entries(name) if e.kind == "tool")
    x = ok(client.get(f"{path}/tools/{tool.number}"))["pose"]["x"]
    assert x == tool.pose.x  # every digit
    ok(client.put(f"{path}/tools/{tool.number}", json={"pose": {"x": x + 2}},
                  headers={"If-Match": "*"}))
    out = client.get(f"{path}/export", params={"format": fmt}).content
    assert out.startswith(b"\xef\xbb\xbf") == raw.startswith(b"\xef\xbb\xbf")
    new_text = formats.decode_file(out)[0]
    changes = changed_numbers(text, new_text)  # pendant's FANUC listing has X twice
    assert len(changes) == (2 if name.startswith("fanuc_listing") else 1), changes
    scale = 1000.0 if fmt == "ur" else 1.0  # URScript is in metres
    assert all(float(c[2]) * scale == pytest.approx(x + 2, abs=1e-9) for c in changes)
    back = {(e.kind, e.number): e for e in formats.READERS[fmt](new_text).entries}
    assert back[("tool", tool.number)].pose.x == x + 2


@pytest.mark.parametrize("name", FILES)
def test_cli_import_by_suffix_and_export_give_the_files_bytes(client, db_url, tmp_path, capsysbinary,
                                                               name):
    """``pendant import FILE`` finds the format by the suffix and the encoding by the bytes (a
    BOM, Windows-1252); ``pendant export`` writes the same bytes back."""
    from server.cli.main import main

    controller = "cell-1"
    if FILES[name] == "abb":
        controller = ok(client.post("/controllers", json={"name": "abb-cli", "robot": ABB_ARM}))["name"]
    f = tmp_path / name
    f.write_bytes((CORPUS / name).read_bytes())
    assert main(["import", str(f), "--controller", controller, "--db", db_url]) == 0
    capsysbinary.readouterr()
    assert main(["export", controller, "--format", FILES[name], "--db", db_url]) == 0
    assert capsysbinary.readouterr().out == (CORPUS / name).read_bytes()


def test_api_preview_names_each_slots_own_line(client):
    """The preview (dry_run) gives each slot the line it starts on: a tab-indented KUKA line
    after a BOM, a RAPID declaration over five lines, a TASK PERS after a RECORD."""
    for name, path, want in (
            ("kuka_hand_edited_utf8_bom.dat", C, {("tool", 1): "tool_data[1]",
                                                  ("tool", 2): "tool_data[2]",
                                                  ("base", 1): "base_data[1]"}),
            ("abb_rw6_task_pers_cp1252_crlf.mod", None, {("tool", 1): "tWeldGun",
                                                         ("tool", 3): "tProbe",
                                                         ("base", 1): "U_kal"})):
        raw, text, encoding = load(name)
        path = path or controller_for(client, "abb")
        r = ok(client.post(f"{path}/import", json={"format": FILES[name], "text": text,
                                                    "encoding": encoding, "dry_run": True}))
        lines = {(s["table"], s["number"]): s["line"] for s in r["slots"]}
        for (table, number), needle in want.items():
            assert lines[(table, number)] == line_of(text.lstrip("\ufeff"), needle), (name, needle)


# ------------------------------------------------------------------ 5. refused, naming the line

KUKA5 = "kuka_kss5_6digit_cp1252_crlf.dat"


@pytest.mark.parametrize("old,new,field,where,reason", [
    ("TOOL_DATA[5]={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}\r\n", "", "TOOL_DATA[5]", "ENDDAT",
     "not assigned"),  # a gap in the array (a cut or hand-edited file): named at ENDDAT
    ("Z 259.650,A 0.0,B 0.0,C 0.0}", "Z 259.650,A 0.0,B 0.0,C 0.0,E1 0.0}", "TOOL_DATA[2]",
     "TOOL_DATA[2]=", "unknown component E1"),  # E1 belongs to an E6POS, not to a FRAME
    ("Z 259.650", "Z 259,650", "TOOL_DATA[2]", "TOOL_DATA[2]=",
     "expected a component name"),  # a decimal comma
    ("Z 259.650", "Z 1.0E+400", "TOOL_DATA[2].Z", "TOOL_DATA[2]=", "must be within"),  # inf
])
def test_kuka_file_that_cannot_be_read_is_refused_naming_its_line(old, new, field, where, reason):
    text = load(KUKA5)[1]
    bad = text.replace(old, new, 1)
    assert bad != text
    with pytest.raises(FormatError) as err:
        formats.READERS["kuka"](bad)
    assert err.value.loc == ("file", f"line {line_of(bad, where)}", field)
    assert reason in err.value.reason


@pytest.mark.parametrize("old,new,field,line,reason", [
    ("[[50,20,0],[0.965926,0,0,0.258819]]];", "[[50,20,0],[0.965926,0,0,0.258819]]]", "U_kal", 23,
     "no ';' ends this declaration"),
    ("[ 1, 0, 0, 0 ] ],   ! no turn", "[ 1, 0, 0.5, 0 ] ],   ! no turn", "tProbe.tframe.rot", 17,
     "quaternion has length"),
    ("[[109.186,", "[[9E+09,", "tWeldGun.tframe.trans[1]", 15, "must be within"),
])
def test_abb_module_that_cannot_be_read_is_refused_naming_its_line(old, new, field, line, reason):
    text = load("abb_rw6_task_pers_cp1252_crlf.mod")[1]
    bad = text.replace(old, new, 1)
    assert bad != text
    with pytest.raises(FormatError) as err:
        formats.READERS["abb"](bad)
    assert err.value.loc == ("file", f"line {line}", field) and reason in err.value.reason


def test_api_names_the_line_of_a_bad_file_and_changes_nothing(client):
    text = load(KUKA5)[1].replace("Z 259.650", "Z 2.0E+7", 1)
    before = client.get(f"{C}/export", params={"format": "json"}).json()["entries"]
    r = client.post(f"{C}/import", json={"format": "kuka", "text": text, "encoding": "cp1252"})
    assert r.status_code == 422, r.text
    (err,) = r.json()["detail"]
    assert f"line {line_of(text, 'TOOL_DATA[2]=')}" in err["loc"] and "TOOL_DATA[2].Z" in err["loc"]
    assert client.get(f"{C}/export", params={"format": "json"}).json()["entries"] == before


@pytest.mark.parametrize("brk", ["\u2028", "\x85", "\x0c"], ids=["U+2028", "NEL", "form-feed"])
def test_kuka_line_numbers_count_only_real_line_ends(brk):
    """A comment pasted into a UTF-8 $config.dat can hold U+2028 (from a web page or a PDF),
    U+0085 or a form feed: characters Python's str.splitlines() takes for line ends, a
    controller and an editor do not. The line named in an error (and the preview's slot
    line) is the one an editor shows."""
    text = load("kuka_hand_edited_utf8_bom.dat")[1].lstrip("\ufeff")
    text = text.replace("von Hand bearbeitet – Prüfstand", f"von Hand bearbeitet{brk}Prüfstand")
    p = formats.READERS["kuka"](text)
    assert p.slot_lines[("robot_held", 2)] == line_of(text, "tool_data[2]")
    bad = text.replace("2.5E+2", "2.5E+7")
    with pytest.raises(FormatError) as err:
        formats.READERS["kuka"](bad)
    assert err.value.loc == ("file", f"line {line_of(bad, 'tool_data[2]')}", "TOOL_DATA[2].Z")
    assert formats.PATCHERS["kuka"](p.entries, text) == text


# ------------------------------------------------------------------ 6. very long files

def test_very_long_files_come_back_whole_and_in_seconds():
    """A $config.dat whose user globals run to 50 000 points (E6POS with E1..E6, ~6 MB) and a
    RobotWare backup module with 999 tooldata, 999 wobjdata and 999 robtargets: read, a
    no-change export and a one-value change each take seconds at most, and only the value
    changes."""
    import time

    text = load(KUKA5)[1]
    points = "".join(f"DECL E6POS XP{n}={{X {n}.5,Y -2.0,Z 3.0,A 0.0,B 90.0,C 0.0,S 6,T 27,E1 0.0,"
                     f"E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}} ; Punkt {n}\r\n" for n in range(50_000))
    kuka = text.replace(";FOLD USER GLOBALS\r\n", ";FOLD USER GLOBALS\r\n" + points)
    abb = "\r\n".join(
        ["MODULE user(SYSMODULE)"]
        + [f"  PERS tooldata t{n}:=[TRUE,[[{n}.5,0,100],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];\r\n"
           f"  PERS wobjdata w{n}:=[FALSE,TRUE,\"\",[[{n},0,0],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];\r\n"
           f"  CONST robtarget p{n}:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];"
           for n in range(1, 1000)] + ["ENDMODULE", ""])
    for fmt, big, key, needle in (("kuka", kuka, ("tool", 2), "TOOL_DATA[2]="),
                                  ("abb", abb, ("tool", 500), "PERS tooldata t500:=")):
        start = time.monotonic()
        es = formats.READERS[fmt](big).entries
        assert formats.PATCHERS[fmt](es, big) == big
        i = next(j for j, e in enumerate(es) if (e.kind, e.number) == key)
        es[i] = changed(es[i], "x", es[i].pose.x + 1)
        out = formats.PATCHERS[fmt](es, big)
        assert time.monotonic() - start < 30, fmt
        assert [c[0] for c in changed_numbers(big, out)] == [line_of(big, needle)]


def test_kuka_machine_dat_line_numbers_count_only_real_line_ends():
    """The same for the external kinematics' $machine.dat / $config.dat reader: a comment
    with U+2028 before a bad value does not shift the line the error names."""
    from server.formats.external import kuka_external_kinematics, read_kuka_external, turntable
    from solvers.frames import Pose

    files = kuka_external_kinematics([turntable(1, "TABLE", Pose(0, 0, 300, 0, 0, 0))])
    md = "; Fahrachse\u2028Drehtisch\n" + files.machine_dat.replace("TR_A2 #NONE", "TR_A2 #E7")
    with pytest.raises(FormatError) as err:
        read_kuka_external(md, files.config_dat)
    assert err.value.loc == ("machine_dat", f"line {line_of(md, 'TR_A2 #E7')}", "$ET1_AX.TR_A2")


@pytest.mark.parametrize("name,key,fld,value,expect", [c for c in CHANGES if c[0].startswith(
    ("ur_", "fanuc_listing"))], ids=["ur", "fanuc-listing"])
def test_pendants_own_files_with_cr_line_ends_read_and_keep_them(name, key, fld, value, expect):
    """Line ends of a lone CR (a file saved on a classic Mac, or by an editor set so): the UR
    and FANUC readers split at LF only and refused the file as "cut short" (one long line),
    while the KUKA reader and the patcher count CR as a line end. They read it, an export
    without a change is the file byte for byte, and a change keeps the CRs."""
    text = load(name)[1].replace("\r\n", "\n").replace("\n", "\r")
    es = formats.READERS[FILES[name]](text).entries
    assert es == entries(name)
    assert formats.PATCHERS[FILES[name]](es, text) == text
    i = next(j for j, e in enumerate(es) if (e.kind, e.number) == key)
    new = list(es)
    new[i] = changed(es[i], fld, value)
    out = formats.PATCHERS[FILES[name]](new, text)
    assert "\n" not in out and formats.READERS[FILES[name]](out).entries == \
        formats.canonical_order(new)
    expect = expect if isinstance(expect, list) else [expect]
    assert changed_numbers(text, out) == [(line_of(text, needle), o, n) for needle, o, n in expect]
