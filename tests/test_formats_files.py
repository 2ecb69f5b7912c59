"""Whole controller files a cell can trust (issue 7): the right kind of every frame, byte-
identical round trips, patches that touch only the edited slot, whole files only, one set of
bounds, names that cannot break a line, FANUC and UR read back what they write.

The files in tests/data are written from the vendors' documented syntax: a KSS 8
``$config.dat`` (CR LF, FOLDs, exponent notation, names with spaces, unused slots, an
external TCP, a robot-held workpiece, a base on a DKP positioner) and a RAPID module (a
stationary tool with a load, a robot-held work object with its loaddata, a work object moved
by STN1, an oframe, declarations pendant cannot use).
"""

from __future__ import annotations

import difflib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from server.formats import (
    EXPORTERS,
    PATCHERS,
    READERS,
    FormatError,
    FrameEntry,
    LoadData,
    canonical_order,
    export_abb,
    export_kuka,
    read_abb,
    read_fanuc,
    read_kuka,
    read_ur,
)
from solvers.frames import Pose, angle_between_deg

DATA = Path(__file__).parent / "data"
KUKA = (DATA / "kuka_cell7_config.dat").read_bytes().decode()
ABB = (DATA / "abb_cell7.mod").read_text()


def changed_lines(a: str, b: str) -> list[str]:
    """The lines a diff of a -> b removes or adds (without the +/- and the line end)."""
    return [d[2:].rstrip("\r\n") for d in difflib.ndiff(a.splitlines(True), b.splitlines(True))
            if d[:1] in "+-"]


def by_slot(entries: list[FrameEntry]) -> dict[tuple[str, int], FrameEntry]:
    return {("tool" if e.kind in ("tool", "workpiece") else "base", e.number): e for e in entries}


def same_frame(p: Pose, q: Pose, deg: float = 1e-9, mm: float = 1e-9) -> bool:
    P, Q = p.as_matrix(), q.as_matrix()
    return float(angle_between_deg(P[:3, :3], Q[:3, :3])) <= deg and \
        bool(np.allclose(P[:3, 3], Q[:3, 3], atol=mm, rtol=0))


# --------------------------------------------------------------------------- kinds


def test_kuka_kinds_follow_the_interpolation_mode():
    """#BASE is the conventional mode (robot carries the tool, the base stands still); #TCP is
    external-TCP mode (TOOL slot: a held workpiece, BASE slot: a stationary tool)."""
    got = {(e.kind, e.number, e.name) for e in read_kuka(KUKA).entries}
    assert got == {("tool", 1, "Pointer 180"), ("tool", 2, "MIG torch 22 deg"),
                   ("workpiece", 3, "Door panel LH"), ("tool", 4, "Spindle 8 mm"),
                   ("tool", 6, "old probe"), ("base", 1, "Table 1"),
                   ("fixed_tool", 2, "Glue nozzle 1.2mm"),
                   ("coordinated_base", 3, "Turntable fixture"), ("base", 8, "Pallet 2")}
    slots = by_slot(read_kuka(KUKA).entries)
    assert slots[("base", 3)].mech_unit == "DKP_400_1"  # MACHINE_FRAME_DAT[3] PARENT
    assert slots[("tool", 3)].load.inertia_axes_deg == (89.777, -0.721, 0.991)  # CM A, B, C
    text = export_kuka([FrameEntry(1, "gripper", "tool", Pose(0, 0, 100)),
                        FrameEntry(2, "part", "workpiece", Pose(0, 0, 50))])
    assert "TOOL_TYPE[1]=#BASE" in text and "TOOL_TYPE[2]=#TCP" in text


def test_abb_kinds_and_what_cannot_be_used_is_listed_not_refused():
    parsed = read_abb(ABB)
    slots = by_slot(parsed.entries)
    assert slots[("base", 1)].kind == "fixed_tool"
    assert slots[("base", 1)].load == LoadData(4.5, (0, 12, 135), (0.02, 0.03, 0.01))
    turntable = slots[("base", 3)]
    assert (turntable.kind, turntable.mech_unit) == ("coordinated_base", "STN1")
    # uframe * oframe: 412.5 mm up, turned 15 deg, then 150 mm out along the turned X
    assert same_frame(turntable.pose, Pose(150 * np.cos(np.radians(15)),
                                           150 * np.sin(np.radians(15)), 437.5, 15, 0, 0), mm=1e-6)
    assert slots[("tool", 5)].kind == "workpiece" and slots[("tool", 5)].load.mass_kg == 18.75
    assert [(s.line, s.field) for s in parsed.skipped] == [(37, "tSet"), (39, "tCopy"),
                                                           (40, "tTemp")]
    assert "array" in parsed.skipped[0].reason and "literal" in parsed.skipped[1].reason


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("fmt, text", [("kuka", KUKA), ("abb", ABB)])
def test_import_export_with_no_change_is_byte_identical(fmt, text):
    parsed = READERS[fmt](text)
    assert PATCHERS[fmt](parsed.entries, text) == text


def test_kuka_one_edited_slot_touches_only_its_lines_and_changed_numbers():
    entries = read_kuka(KUKA).entries
    torch = by_slot(entries)[("tool", 2)]
    edited = replace(torch, pose=replace(torch.pose, z=357.125),
                     load=replace(torch.load, mass_kg=7.1))
    out = export_kuka([edited if e is torch else e for e in entries], template=KUKA)
    assert changed_lines(KUKA, out) == [
        "TOOL_DATA[2]={X 148.320,Y -2.10500,Z 356.870,A 0.0,B 67.5000,C 0.0}",
        "TOOL_DATA[2]={X 148.320,Y -2.10500,Z 357.125,A 0.0,B 67.5000,C 0.0}",
        "LOAD_DATA[2]={M 6.80000,CM {X 42.5000,Y 0.0,Z 118.300,A 0.0,B 22.5000,C 0.0},"
        "J {X 0.0450000,Y 0.0520000,Z 0.0180000}}",
        "LOAD_DATA[2]={M 7.1,CM {X 42.5000,Y 0.0,Z 118.300,A 0.0,B 22.5000,C 0.0},"
        "J {X 0.0450000,Y 0.0520000,Z 0.0180000}}"]
    assert "\r\n" in out and "\n" not in out.replace("\r\n", "")  # the controller's CR LF kept
    assert read_kuka(out).entries == canonical_order(
        [edited if e is torch else e for e in entries])


def test_kuka_patch_changes_kind_name_unit_and_empties_a_slot():
    entries = [e for e in read_kuka(KUKA).entries if e.number != 8 or e.kind != "base"]
    slots = by_slot(entries)
    slots[("tool", 3)] = replace(slots[("tool", 3)], kind="tool", name="Gripper only", load=None)
    slots[("base", 3)] = replace(slots[("base", 3)], mech_unit="DKP_400_2")
    slots[("base", 2)] = replace(slots[("base", 2)], load=LoadData(2.5, (0, 0, 120)))
    slots[("tool", 9)] = FrameEntry(9, "new probe", "tool", Pose(0, 0, 222))
    out = export_kuka(list(slots.values()), template=KUKA)
    changed = changed_lines(KUKA, out)
    touched = {line.split("=")[0] for line in changed}
    assert touched == {"TOOL_NAME[3,]", "TOOL_TYPE[3]", "LOAD_DATA[3]", "MACHINE_FRAME_DAT[3]",
                       ";pendant BASE_LOAD[2]", "BASE_DATA[8]", "BASE_NAME[8,]", "BASE_TYPE[8]",
                       "TOOL_DATA[9]", "TOOL_NAME[9,]", "TOOL_TYPE[9]"}
    assert read_kuka(out).entries == canonical_order(slots.values())


def test_abb_one_edited_slot_touches_only_its_lines():
    entries = read_abb(ABB).entries
    table = by_slot(entries)[("base", 2)]
    moved = replace(table, pose=replace(table.pose, z=-214.5))
    out = export_abb([moved if e is table else e for e in entries], template=ABB)
    diff = changed_lines(ABB, out)
    assert len(diff) == 2 and all("wTable" in d for d in diff)
    assert "[[10,20,0],[0.996194698091746,0,0,0.0871557427476582]]" in out  # oframe kept
    assert read_abb(out).entries == canonical_order([moved if e is table else e for e in entries])


def test_abb_patch_changes_kinds_loads_and_adds_and_removes_declarations():
    slots = by_slot(read_abb(ABB).entries)
    slots[("tool", 5)] = replace(slots[("tool", 5)], load=None)  # its loaddata goes
    slots[("base", 1)] = replace(slots[("base", 1)], load=None)  # tool0's load
    # tooldata -> wobjdata
    slots[("tool", 3)] = replace(slots[("tool", 3)], kind="workpiece", load=None)
    del slots[("tool", 4)]
    slots[("base", 9)] = FrameEntry(9, "Fixture B", "coordinated_base", Pose(1, 2, 3, 4, 5, 6),
                                    mech_unit="STN1")
    out = export_abb(list(slots.values()), template=ABB)
    assert "wDoorPanel_load" not in out and "tSpare" not in out
    assert "PERS tooldata tGlueNozzle:=[FALSE,[[1250.4,-320.75,880],[0,0.707106781186548," \
           "0.707106781186548,0]],[0.001,[0,0,0.001],[1,0,0,0],0,0,0]];" in out
    assert "PROC main()" in out and "tCopy:=tGripper" in out  # the rest stays
    back = read_abb(out)
    assert back.entries == canonical_order(slots.values())
    assert [s.field for s in back.skipped] == ["tSet", "tCopy", "tTemp"]


def test_kuka_abb_kuka_keeps_kind_load_unit_and_rotation():
    """Every kind (robot-held tool, stationary tool, base, held workpiece, coordinated base)
    crosses KUKA -> ABB -> KUKA with its load and its rotation to 1e-9 deg."""
    kuka = read_kuka(KUKA).entries
    kuka = [replace(e, load=LoadData(2.5, (0, 0, 120), (0.01, 0.02, 0.03), (10, 20, 30)))
            if e.kind == "fixed_tool" else e for e in kuka]
    abb = read_abb(export_abb(kuka)).entries
    back = read_kuka(export_kuka(abb)).entries
    for e, a, b in zip(kuka, abb, back):
        for x in (a, b):
            assert (x.number, x.name, x.kind, x.mech_unit) == (e.number, e.name, e.kind,
                                                               e.mech_unit)
            assert same_frame(x.pose, e.pose), (e, x)
            assert (x.load is None) == (e.load is None)
            if e.load is not None:
                assert x.load.mass_kg == e.load.mass_kg and x.load.com_mm == e.load.com_mm
                assert x.load.inertia_kgm2 == e.load.inertia_kgm2
                assert same_frame(Pose(0, 0, 0, *x.load.inertia_axes_deg),
                                  Pose(0, 0, 0, *e.load.inertia_axes_deg))


def test_abb_kuka_abb_keeps_every_kind():
    abb = read_abb(ABB).entries
    back = read_abb(export_abb(read_kuka(export_kuka(abb)).entries)).entries
    assert [(e.kind, e.number, e.name, e.mech_unit) for e in back] == \
        [(e.kind, e.number, e.name, e.mech_unit) for e in abb]
    for e, b in zip(abb, back):
        assert same_frame(e.pose, b.pose) and (e.load is None) == (b.load is None)


@pytest.mark.parametrize("fmt, read", [("fanuc", read_fanuc), ("ur", read_ur)])
def test_fanuc_and_ur_read_back_what_they_write(fmt, read):
    entries = [e for e in read_kuka(KUKA).entries if e.number <= 9]
    entries = [replace(e, load=replace(e.load, inertia_axes_deg=(0, 0, 0))) if e.load else e
               for e in entries]  # FANUC has no principal axes
    text = (DATA / f"{fmt}_cell7.{'txt' if fmt == 'fanuc' else 'script'}").read_text()
    assert EXPORTERS[fmt](entries) == text  # the data file is what pendant writes
    back = read(text).entries
    assert EXPORTERS[fmt](back) == text  # and what it reads writes the same text again
    for e, b in zip(entries, back):
        assert (b.number, b.kind, b.mech_unit) == (e.number, e.kind, e.mech_unit)
        assert b.name == e.name[:16] if fmt == "fanuc" else b.name == e.name
        assert same_frame(b.pose, e.pose, deg=1e-5, mm=1e-6)
        assert (b.load is None) == (e.load is None)


# --------------------------------------------------------------------------- refusals


def cut(text: str, before: str) -> str:
    return text[:text.index(before)]


@pytest.mark.parametrize("text, line, field", [
    (cut(KUKA, "TOOL_DATA[5]="), cut(KUKA, "TOOL_DATA[5]=").count("\n"), "ENDDAT"),
    (cut(KUKA, "DECL CHAR BASE_NAME"), cut(KUKA, "DECL CHAR BASE_NAME").count("\n"), "ENDDAT"),
    (KUKA.replace("TOOL_NAME[7,]=\" \"\r\n", ""), KUKA.count("\n") - 1, "TOOL_NAME[7]"),
    (KUKA.split("DEFDAT")[1], 1, "DEFDAT"),
])
def test_kuka_cut_short_is_refused_with_the_line_where_it_ends(text, line, field):
    with pytest.raises(FormatError) as err:
        read_kuka(text)
    assert err.value.loc == ("file", f"line {line}", field), err.value
    assert "cut short" in err.value.reason or "every slot" in err.value.reason \
        or "DEFDAT" in err.value.reason


def test_abb_without_endmodule_is_refused():
    text = cut(ABB, "ENDMODULE")
    with pytest.raises(FormatError) as err:
        read_abb(text)
    assert err.value.loc == ("file", f"line {text.count(chr(10))}", "ENDMODULE")
    assert "cut short" in err.value.reason


@pytest.mark.parametrize("old, new, field, reason", [
    ("Z 180.000,A 0.0", "Z 2.0E+07,A 0.0", "TOOL_DATA[1].Z", "1e+06 mm"),
    ("B 67.5000,C 0.0}", "B 9E+99,C 0.0}", "TOOL_DATA[2].B", "10000 deg"),
    ('"Pointer 180"', '"' + "P" * 30 + '"', "TOOL_NAME[1,]", "at most 24"),
])
def test_kuka_values_beyond_the_bounds_are_refused(old, new, field, reason):
    with pytest.raises(FormatError) as err:
        read_kuka(KUKA.replace(old, new, 1))
    assert err.value.loc[2] == field and reason in err.value.reason


# --------------------------------------------------------------------------- names


@pytest.mark.parametrize("name", ["pointer\nUTOOL 9 evil", "a\u2028UTOOL 8", "b\x85UFRAME 7",
                                  "c\rPAYLOAD 3", 'q"uote\u2029'])
def test_no_name_can_add_a_line_to_any_format(name):
    entries = [FrameEntry(1, name, "tool", Pose(0, 0, 100), LoadData(1.0)),
               FrameEntry(2, name, "base", Pose(1, 2, 3))]
    clean = [FrameEntry(1, "x", "tool", Pose(0, 0, 100), LoadData(1.0)),
             FrameEntry(2, "x", "base", Pose(1, 2, 3))]
    for fmt, writer in EXPORTERS.items():
        text = writer(entries)
        assert not any(c in text for c in "\r\x85\u2028\u2029"), fmt
        assert len(text.splitlines()) == len(writer(clean).splitlines()), fmt
        back = READERS[fmt](text).entries
        assert [e.number for e in back] == [1, 2], fmt


def test_kuka_unit_patch_takes_the_machine_index_and_a_file_without_the_array_gets_it():
    entries = read_kuka(KUKA).entries
    moved = [replace(e, mech_unit="KR 210 R2700-2") if e.kind == "coordinated_base" else e
             for e in entries]
    out = export_kuka(moved, template=KUKA)
    assert changed_lines(KUKA, out)[1] == \
        'MACHINE_FRAME_DAT[3]={MACH_DEF_INDEX 1,PARENT[] "KR 210 R2700-2",GEOMETRY[] " "}'
    # a $config.dat without MACHINE_FRAME_DAT: the array is added before ENDDAT
    plain = "".join(s for s in KUKA.splitlines(True) if "MACHINE_FRAME" not in s)
    out = export_kuka(entries, template=plain)
    assert read_kuka(out).entries == entries
    assert out.count("MACHINE_FRAME_DAT[") == 33  # DECL and the 32 slots


def test_abb_a_held_work_object_moved_to_a_base_slot_takes_its_loaddata_along():
    """Tool 5 emptied (its wobjdata and loaddata go), base 7 new (declared before ENDMODULE)."""
    slots = by_slot(read_abb(ABB).entries)
    panel = slots.pop(("tool", 5))
    slots[("base", 7)] = replace(panel, number=7, kind="base", load=None)
    out = export_abb(list(slots.values()), template=ABB)
    assert "wDoorPanel_load" not in out
    assert read_abb(out).entries == canonical_order(slots.values())
