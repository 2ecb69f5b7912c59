"""Controller file formats: KUKA $config.dat, ABB RAPID, FANUC UTOOL/UFRAME, UR script.

Real-looking files read back exactly; every kind lands in the controller's right slot;
known conversions give the controller's own numbers; a bad line is named.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from server.formats import (
    EXPORTERS,
    FILE_NAMES,
    IMPORTERS,
    FormatError,
    FrameEntry,
    LoadData,
    canonical_order,
    export_abb,
    export_fanuc,
    export_kuka,
    export_ur,
    import_abb,
    import_kuka,
    read_kuka,
)
from server.formats.abb import rapid_name
from solvers.errors import CalibrationError
from solvers.frames import Pose, fanuc_from_matrix, matrix_from_ur

DATA = Path(__file__).parent / "data"
KUKA_FILE = (DATA / "kuka_config.dat").read_text()
ABB_FILE = (DATA / "abb_calib.mod").read_text()

POINTER = FrameEntry(1, "pointer", "tool", Pose(0, 0, 180, 0, 0, 0),
                     LoadData(2.5, (0, 0, 80), (0.01, 0.01, 0.005)))
PANEL = FrameEntry(2, "panel", "workpiece", Pose(10, 20, 300, 0, 90 - 1e-3, 0),
                   LoadData(12.0, (0, 5, 150)))
TABLE = FrameEntry(1, "table", "base", Pose(1200, -300, 15, 90, 0, 0))
NOZZLE = FrameEntry(4, "nozzle", "fixed_tool", Pose(800, 500, 900, 0, 180, 0))
ALL = [POINTER, PANEL, TABLE, NOZZLE]


def line_of(text: str, start: str) -> str:
    return next(s for s in text.splitlines() if s.startswith(start))


def row_of(text: str, label: str, number: int) -> list[str]:
    """A FANUC table row, split into words."""
    return next(s.split() for s in text.splitlines() if s.split()[:2] == [label, str(number)])


def close_poses(p: Pose, q: Pose, atol: float = 1e-9) -> bool:
    return bool(np.allclose(p.as_matrix(), q.as_matrix(), atol=atol))


# --------------------------------------------------------------------------- model


def test_model_refuses_a_load_on_a_stationary_frame_and_bad_numbers():
    with pytest.raises(CalibrationError, match="not carried by the robot"):
        FrameEntry(1, "table", "base", Pose(), LoadData(1.0))
    with pytest.raises(CalibrationError, match="kind"):
        FrameEntry(1, "x", "gripper", Pose())  # type: ignore[arg-type]
    with pytest.raises(CalibrationError, match="number"):
        FrameEntry(0, "x", "tool", Pose())
    with pytest.raises(CalibrationError, match="finite"):
        FrameEntry(1, "x", "tool", Pose(math.nan))
    with pytest.raises(CalibrationError, match="mass_kg"):
        LoadData(-2.0)


def test_format_error_names_file_line_and_field():
    e = FormatError.at_line(12, "TOOL_DATA[3]", "bad")
    assert isinstance(e, CalibrationError)
    assert e.loc == ("file", "line 12", "TOOL_DATA[3]") and e.line == 12 and e.reason == "bad"
    for reader in IMPORTERS.values():
        with pytest.raises(FormatError, match="expected text"):
            reader(b"TOOL_DATA[1]={X 0}")  # type: ignore[arg-type]


def test_every_format_writes_every_kind():
    for fmt, writer in EXPORTERS.items():
        text = writer(ALL)
        assert text.endswith("\n") and FILE_NAMES[fmt]
        for e in ALL:
            assert e.name in text, (fmt, e.name)
    for fmt, reader in IMPORTERS.items():
        assert reader(EXPORTERS[fmt](ALL))[0].kind == "tool"


# --------------------------------------------------------------------------- KUKA


def test_kuka_reads_a_real_config_dat():
    entries = import_kuka(KUKA_FILE)
    by = {(e.kind, e.number): e for e in entries}
    assert sorted(by) == sorted([("tool", 1), ("tool", 2), ("workpiece", 3), ("tool", 4), ("tool", 6),
                                 ("base", 1), ("base", 2), ("fixed_tool", 3), ("fixed_tool", 5),
                                 ("base", 8)])
    assert by[("tool", 1)] == FrameEntry(1, "Pointer", "tool", Pose(0, 0, 180, 0, 0, 0),
                                         LoadData(2.5, (0, 0, 80), (0.01, 0.01, 0.005)))
    panel = by[("workpiece", 3)]  # TOOL_TYPE[3]=#BASE: the robot holds the workpiece
    assert panel.name == "Gripper+panel" and panel.pose == Pose(0, 0, 380.79, -90, -90, -90)
    assert panel.load == LoadData(129.297, (38.804, -94.451, 136.873), (5.25, 5.572, 7.658),
                                  (89.777, -0.721, 0.991))
    assert by[("tool", 4)].pose.y == 6.19999992e-05 and by[("tool", 4)].load is None  # M -1
    assert by[("tool", 6)].name == "old probe"  # #NONE with a frame: a tool all the same
    assert by[("fixed_tool", 3)].name == "Glue nozzle"  # BASE_TYPE[3]=#TCP: external TCP
    assert by[("base", 8)].pose == Pose(1250, 400, 12.5, 12.3456, -0.15, 0.08)
    assert entries == canonical_order(entries)


def test_kuka_file_import_export_import_is_the_identity():
    entries = import_kuka(KUKA_FILE)
    text = export_kuka(entries)
    assert import_kuka(text) == entries
    assert export_kuka(import_kuka(text)) == text


def test_kuka_export_writes_slots_as_the_controller_does():
    text = export_kuka(ALL)
    assert line_of(text, "TOOL_DATA[1]=") == "TOOL_DATA[1]={X 0.0,Y 0.0,Z 180.0,A 0.0,B 0.0,C 0.0}"
    assert line_of(text, "TOOL_NAME[1,]") == 'TOOL_NAME[1,]="pointer"'
    assert line_of(text, "TOOL_TYPE[1]") == "TOOL_TYPE[1]=#BASE"  # conventional: robot-held tool
    assert line_of(text, "LOAD_DATA[1]=") == \
        "LOAD_DATA[1]={M 2.5,CM {X 0.0,Y 0.0,Z 80.0,A 0.0,B 0.0,C 0.0},J {X 0.01,Y 0.01,Z 0.005}}"
    assert line_of(text, "TOOL_TYPE[2]") == "TOOL_TYPE[2]=#TCP"  # external TCP: held workpiece
    assert line_of(text, "BASE_TYPE[1]") == "BASE_TYPE[1]=#BASE"
    assert line_of(text, "BASE_TYPE[4]") == "BASE_TYPE[4]=#TCP"  # fixed tool = external TCP
    assert line_of(text, "BASE_DATA[4]=") == "BASE_DATA[4]={X 800.0,Y 500.0,Z 900.0,A 0.0,B 180.0,C 0.0}"
    # unused slots, as KSS writes them
    assert line_of(text, "TOOL_DATA[16]=") == "TOOL_DATA[16]={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}"
    assert line_of(text, "TOOL_NAME[16,]") == 'TOOL_NAME[16,]=" "'
    assert line_of(text, "TOOL_TYPE[16]") == "TOOL_TYPE[16]=#NONE"
    assert line_of(text, "LOAD_DATA[16]=") == \
        "LOAD_DATA[16]={M -1.0,CM {X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0},J {X 0.0,Y 0.0,Z 0.0}}"
    assert line_of(text, "BASE_TYPE[32]") == "BASE_TYPE[32]=#NONE"
    for decl in ("DECL FRAME TOOL_DATA[16]", "DECL CHAR TOOL_NAME[16,24]", "DECL LOAD LOAD_DATA[16]",
                 "DECL IPO_M_T TOOL_TYPE[16]", "DECL FRAME BASE_DATA[32]", "DECL CHAR BASE_NAME[32,24]",
                 "DECL IPO_M_T BASE_TYPE[32]"):
        assert decl in text.splitlines()
    assert sum(s.startswith("TOOL_DATA[") for s in text.splitlines()) == 16
    assert sum(s.startswith("BASE_DATA[") for s in text.splitlines()) == 32
    assert import_kuka(text) == canonical_order(ALL)


def test_kuka_export_keeps_every_digit_and_cleans_names():
    e = FrameEntry(1, 'a "long" name that goes past 24 chars', "tool",
                   Pose(0.1 + 0.2, 1e-7, -123456.78901234567, 1 / 3, -0.0, 179.99999999999997))
    text = export_kuka([e], tool_slots=2, base_slots=1)
    assert "Y 1.0E-07" in text
    back = import_kuka(text)[0]
    assert back.pose == e.pose
    assert back.name == "a  long  name that goes"[:24].strip()


def test_kuka_reads_any_spacing_case_comments_and_crlf():
    text = ("&ACCESS RVP\r\n&REL 3\r\nDEFDAT $config PUBLIC\r\n;FOLD tools\r\n"
            "decl frame tool_data[1]\r\n"
            "  tool_data[1] = { x 12.5 , y -3.25,Z 3.1e2 ,a 0, b 0.0 ,c -45.0 } ; re-taught\r\n"
            'Tool_Name[1,] = "drill; 6mm"   ; name with a semicolon\r\n'
            "tool_type[1]=#base\r\n"
            "load_data[1]={m 1.5 , cm {x 0,y 0,z 55,a 0,b 0,c 0}, j {x 0.002,y 0.002,z 0.001}}\r\n"
            "$BASE_DATA[1]={X 1,Y 2,Z 3,A 4,B 5,C 6}\r\nBASE_NAME[1,]=\" \"\r\n"
            "BASE_TYPE[1]=#NONE\r\n;ENDFOLD\r\nENDDAT\r\n")
    tool, base = import_kuka(text)
    assert tool == FrameEntry(1, "drill; 6mm", "tool", Pose(12.5, -3.25, 310, 0, 0, -45),
                              LoadData(1.5, (0, 0, 55), (0.002, 0.002, 0.001)))
    assert base == FrameEntry(1, "", "base", Pose(1, 2, 3, 4, 5, 6))


def test_kuka_skips_unused_slots_but_keeps_a_tool_at_the_flange():
    unused = "{M -1,CM {X 0,Y 0,Z 0,A 0,B 0,C 0},J {X 0,Y 0,Z 0}}"
    text = ("DEFDAT $CONFIG\nTOOL_DATA[1]={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}\n"
            "TOOL_NAME[1,]=\" \"\nTOOL_TYPE[1]=#NONE\nLOAD_DATA[1]=" + unused + "\n"
            "TOOL_DATA[2]={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}\nTOOL_NAME[2,]=\" \"\n"
            "TOOL_TYPE[2]=#BASE\nLOAD_DATA[2]=" + unused + "\n"
            "TOOL_DATA[3]={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}\nTOOL_NAME[3,]=\"spare\"\n"
            "TOOL_TYPE[3]=#NONE\nLOAD_DATA[3]=" + unused + "\nENDDAT\n")
    parsed = read_kuka(text)
    # issue 23 (9): a #NONE zero slot with a name keeps it (the slot is not unused)
    assert parsed.entries == [FrameEntry(2, "", "tool", Pose()), FrameEntry(3, "spare", "tool", Pose())]
    assert parsed.unused == [("robot_held", 1)]  # listed, so that an import empties it


@pytest.mark.parametrize("line, field, reason", [
    ("TOOL_DATA[3]={X 0.0,Y abc,Z 0.0,A 0.0,B 0.0,C 0.0}", "TOOL_DATA[3].Y", "expected a number"),
    ("TOOL_DATA[3]={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0}", "TOOL_DATA[3]", "missing C"),
    ("TOOL_DATA[3]={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0,D 1}", "TOOL_DATA[3]", "unknown component D"),
    ("TOOL_DATA[3]={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0", "TOOL_DATA[3]", "expected ',' or '}'"),
    ("TOOL_DATA[3]", "TOOL_DATA", "cannot read"),
    ("TOOL_TYPE[3]=#ROBOT", "TOOL_TYPE[3]", "#TCP, #BASE or #NONE"),
    ("TOOL_NAME[3,]=gripper", "TOOL_NAME[3,]", "quoted name"),
    ("TOOL_NAME[3]=\"gripper\"", "TOOL_NAME[3,]", "TOOL_NAME[n,]"),
    ("TOOL_DATA[0]={X 0,Y 0,Z 0,A 0,B 0,C 0}", "TOOL_DATA[0]", "start at 1"),
    ("TOOL_DATA[17]={X 0,Y 0,Z 0,A 0,B 0,C 0}", "TOOL_DATA[17]", "beyond DECL TOOL_DATA[16] on line 2"),
    ("TOOL_DATA[2]={X 0,Y 0,Z 9,A 0,B 0,C 0}", "TOOL_DATA[2]", "assigned twice (first on line 3)"),
    ("TOOL_DATA[3]={X 2.0E+07,Y 0,Z 0,A 0,B 0,C 0}", "TOOL_DATA[3].X", "-1e+06..1e+06 mm"),
    ("TOOL_DATA[3]={X 0,Y 0,Z 0,A 9E+99,B 0,C 0}", "TOOL_DATA[3].A", "-10000..10000 deg"),
    ("LOAD_DATA[3]={M 2E4,CM {X 0,Y 0,Z 0,A 0,B 0,C 0},J {X 0,Y 0,Z 0}}", "LOAD_DATA[3].M", "0..10000 kg"),
    ("TOOL_NAME[3,]=\"" + "x" * 70 + "\"", "TOOL_NAME[3,]", "at most 24"),
    ("LOAD_DATA[3]={M -3.0,CM {X 0,Y 0,Z 0,A 0,B 0,C 0},J {X 0,Y 0,Z 0}}", "LOAD_DATA[3].M", "-1"),
    ("LOAD_DATA[3]={M 3.0,CM {X 0,Y 0,Z 0,A 0,B 0,C 0}}", "LOAD_DATA[3]", "missing J"),
    ("LOAD_DATA[3]={M 3.0,CM {X 0,Y 0,Z 0},J {X 0,Y 0,Z 0}}", "LOAD_DATA[3].CM", "missing A"),
])
def test_kuka_malformed_line_is_named(line, field, reason):
    text = ("DEFDAT $CONFIG\nDECL FRAME TOOL_DATA[16]\nTOOL_DATA[2]={X 0,Y 0,Z 1,A 0,B 0,C 0}\n"
            "DECL CHAR TOOL_NAME[16,24]\n" + line + "\nENDDAT\n")
    with pytest.raises(FormatError) as err:
        import_kuka(text)
    assert err.value.loc == ("file", "line 5", field)
    assert reason in err.value.reason


def test_kuka_malformed_line_in_the_real_file_is_named():
    lines = KUKA_FILE.splitlines()
    k = next(i for i, s in enumerate(lines) if s.startswith("LOAD_DATA[2]="))
    lines[k] = lines[k].replace("Z 118.300", "Z 118,300")
    with pytest.raises(FormatError) as err:
        import_kuka("\n".join(lines))
    assert err.value.loc[:2] == ("file", f"line {k + 1}")
    assert err.value.loc[2].startswith("LOAD_DATA[2]")


def test_kuka_export_refuses_what_does_not_fit():
    with pytest.raises(FormatError) as err:
        export_kuka([POINTER, FrameEntry(1, "part", "workpiece", Pose())])
    assert err.value.loc == ("entries", 1, "number") and "shares" in err.value.reason
    with pytest.raises(FormatError) as err:
        export_kuka([TABLE, FrameEntry(33, "far", "base", Pose())])
    assert err.value.loc == ("entries", 1, "number") and "32" in err.value.reason
    with pytest.raises(FormatError, match="tool_slots"):
        export_kuka([], tool_slots=0)
    # a base and a tool may both be number 1: different arrays
    assert len(import_kuka(export_kuka([POINTER, TABLE]))) == 2


# --------------------------------------------------------------------------- ABB


def _decl(text: str, name: str) -> str:
    m = re.search(r"PERS \w+ " + name + r":=(.*);", text)
    assert m, name
    return m.group(1)


def test_abb_writes_each_kind_as_abb_documents_it():
    text = export_abb(ALL, module_name="Cell4Calib")
    assert text.startswith("MODULE Cell4Calib\n") and text.rstrip().endswith("ENDMODULE")
    assert _decl(text, "pointer") == "[TRUE,[[0,0,180],[1,0,0,0]],[2.5,[0,0,80],[1,0,0,0],0.01,0.01,0.005]]"
    nozzle = _decl(text, "nozzle")  # stationary tool: robhold FALSE, tframe in world
    assert nozzle.startswith("[FALSE,[[800,500,900],[0,0,1,0]],")
    assert nozzle.endswith(",[0.001,[0,0,0.001],[1,0,0,0],0,0,0]]")  # ABB refuses mass 0
    assert _decl(text, "table").startswith('[FALSE,TRUE,"",[[1200,-300,15],[0.7071067811865')
    assert _decl(text, "table").endswith("],[[0,0,0],[1,0,0,0]]]")
    assert _decl(text, "panel").startswith('[TRUE,TRUE,"",[[10,20,300],')  # the robot holds it
    assert _decl(text, "panel_load") == "[12,[0,5,150],[1,0,0,0],0,0,0]"
    assert 'PERS tooldata pointer:=' in text and "PERS wobjdata panel:=" in text


def test_abb_quaternion_of_a_tool_turned_90_deg_about_z():
    text = export_abb([FrameEntry(1, "t", "tool", Pose(0, 0, 100, 90, 0, 0))])
    q = [float(x) for x in re.search(r"\[\[0,0,100\],\[([^\]]*)\]", text).group(1).split(",")]
    assert q == pytest.approx([0.7071068, 0, 0, 0.7071068], abs=1e-7)


def test_abb_unknown_or_zero_load_becomes_the_minimum_abb_accepts():
    text = export_abb([FrameEntry(1, "a", "tool", Pose()),
                       FrameEntry(2, "b", "tool", Pose(), LoadData(0.0))])
    assert _decl(text, "a").endswith(",[0.001,[0,0,0.001],[1,0,0,0],0,0,0]]")
    assert _decl(text, "b").endswith(",[0.001,[0,0,0],[1,0,0,0],0,0,0]]")
    a, b = import_abb(text)
    assert a.load is None and b.load == LoadData(0.001)


def test_abb_names_become_rapid_identifiers():
    taken: set[str] = set()
    assert rapid_name("Gripper A (left)", "tool", 1, taken) == "Gripper_A_left"
    assert rapid_name("gripper-a-left", "tool", 2, taken) == "gripper_a_left_2"  # RAPID ignores case
    assert rapid_name("", "base", 3, taken) == "wobj3"
    assert rapid_name("tool0", "tool", 4, taken) == "tool0_2"  # the system's own tool0
    assert rapid_name("Schweißbrenner", "tool", 5, taken) == "Schweibrenner"
    assert len(rapid_name("x" * 50, "tool", 6, taken)) == 32
    entries = [FrameEntry(1, "Gripper A (left)", "tool", Pose()), FrameEntry(2, "", "tool", Pose()),
               FrameEntry(3, "Gripper A [left]", "tool", Pose())]
    assert import_abb(export_abb(entries)) == entries  # numbers and names survive via comments
    with pytest.raises(FormatError, match="RAPID identifier"):
        export_abb(entries, module_name="3 calib")


def test_abb_reads_a_real_module():
    entries = import_abb(ABB_FILE)
    by = {e.name: e for e in entries}
    assert [(e.kind, e.number, e.name) for e in entries] == [
        ("tool", 1, "tGripper"), ("tool", 2, "tTorch"), ("tool", 3, "tSpindle"), ("tool", 4, "tPen"),
        ("workpiece", 5, "wPanel"), ("fixed_tool", 1, "tGlueNozzle"), ("base", 2, "wTable"),
        ("base", 3, "wFixtureA")]
    assert by["tGripper"].load == LoadData(3.2, (0, 0, 65), (0.012, 0.012, 0.006))
    assert by["tSpindle"].pose.y == 6.2e-05 and by["tSpindle"].load is None  # tool0's load
    assert by["tPen"].pose == Pose(0, 0, 120, 0, 0, 0)  # const, lower case, spread over lines
    assert by["tTorch"].pose.b == pytest.approx(67.5, abs=1e-4)  # 6-digit quaternion in the file
    assert by["tTorch"].load.inertia_axes_deg[1] == pytest.approx(22.5, abs=1e-4)
    assert by["wPanel"].load.mass_kg == 129.297  # from loaddata wPanel_load
    assert by["tGlueNozzle"].load == LoadData(2.5, (0, 0, 120))  # the stationary tool's tload
    # work object pose = uframe * oframe
    fixture = by["wFixtureA"].pose
    assert (fixture.x, fixture.y) == pytest.approx((885.94 + 20, -145.63 - 10), abs=1e-4)
    assert fixture.a == pytest.approx(-80, abs=1e-4)


def test_abb_file_import_export_import_reproduces_every_value():
    entries = import_abb(ABB_FILE)
    again = import_abb(export_abb(entries))
    assert again == entries


@pytest.mark.parametrize("pose", [Pose(1, 2, 3, 30, 90, 40), Pose(1, 2, 3, -30, -90, 40),
                                  Pose(0, 0, 0, -180, 0, -180), Pose(0, 0, 0, 0, 89.9999999, 0)])
def test_abb_round_trip_at_gimbal_lock_and_the_180_deg_seam(pose):
    back = import_abb(export_abb([FrameEntry(1, "x", "tool", pose)]))
    assert close_poses(back[0].pose, pose)
    assert import_abb(export_abb(back)) == back


@pytest.mark.parametrize("decl, line, field, reason", [
    ("PERS tooldata t1:=[TRUE,[[0,0,100],[1,0,0,0]],[1,[0,0,0],[1,0,0,0],0,0]];",
     3, "t1.tload", "[mass,[cx,cy,cz]"),
    ("PERS tooldata t1:=[TRUE,[[0,0,100],[1,0,0]],[1,[0,0,0],[1,0,0,0],0,0,0]];",
     3, "t1.tframe.rot", "[num, num, num, num]"),
    ("PERS tooldata t1:=[TRUE,[[0,0,100],[2,0,0,0]],[1,[0,0,0],[1,0,0,0],0,0,0]];",
     3, "t1.tframe.rot", "length 2"),
    ("PERS tooldata t1:=[TRUE,\n  [[0,0,100],[1,0,0,0]]\n  [1,[0,0,0],[1,0,0,0],0,0,0]];", 5, "t1",
     "expected ',' or ']'"),
    ("PERS tooldata t1:=[TRUE,[[0,0,100],[1,0,0,0]],[1,[0,0,0],[1,0,0,0],0,0,0]]", 3, "t1", "no ';'"),
    ("PERS wobjdata w1:=[FALSE,TRUE,[[0,0,0],[1,0,0,0]],[[0,0,250],[1,0,0,0]]];", 3, "w1", "robhold,ufprog"),
    ('! pendant: base 1 "t"\n  PERS tooldata t1:=[TRUE,[[0,0,1],[1,0,0,0]],[1,[0,0,0],[1,0,0,0],0,0,0]];',
     3, "t1", "comment says base"),
])
def test_abb_malformed_data_is_named(decl, line, field, reason):
    text = "MODULE M\n  ! cell 4\n  " + decl + "\nENDMODULE\n"
    with pytest.raises(FormatError) as err:
        import_abb(text)
    assert err.value.loc == ("file", f"line {line}", field)
    assert reason in err.value.reason


# --------------------------------------------------------------------------- FANUC, UR


def test_fanuc_wpr_are_kuka_cba_and_kinds_map_to_utool_and_uframe():
    tool = FrameEntry(3, "torch", "tool", Pose(1, 2, 3, 30, 20, 10))
    text = export_fanuc([tool, PANEL, TABLE, NOZZLE])
    row = row_of(text, "UTOOL", 3)
    assert row[:3] == ["UTOOL", "3", "torch"]
    assert [float(v) for v in row[3:]] == [1, 2, 3, 10, 20, 30]  # W, P, R = C, B, A
    assert row_of(text, "UTOOL", 2)[2] == "panel"  # workpiece: Remote TCP tool
    assert row_of(text, "UFRAME", 1)[2] == "table"
    assert row_of(text, "UFRAME", 4)[2] == "nozzle"  # Remote TCP frame
    assert "$MNUTOOL  Storage: SHADOW  Access: RW  : ARRAY[1,10] OF POSITION" in text
    assert " [1,3] =  ! tool \"torch\"" in text
    assert re.search(r"W:\s+10\.000000\s+P:\s+20\.000000\s+R:\s+30\.000000", text)
    assert "[*SYSTEM*]$MNUFRAME" in text
    wpr = fanuc_from_matrix(TABLE.pose.as_matrix())[3:]
    assert [float(v) for v in row_of(text, "UFRAME", 1)[6:]] == pytest.approx(wpr, abs=1e-6)


def test_fanuc_payload_in_cm_and_kgf_cm_s2_and_slot_limits():
    text = export_fanuc([POINTER])
    row = row_of(text, "PAYLOAD", 1)
    assert [float(v) for v in row[1:]] == pytest.approx([1, 2.5, 0, 0, 8.0, 0.10197, 0.10197, 0.050986],
                                                        rel=1e-4)
    with pytest.raises(FormatError) as err:
        export_fanuc([FrameEntry(11, "t", "tool", Pose())])
    assert err.value.loc == ("entries", 0, "number") and "10" in err.value.reason
    with pytest.raises(FormatError):
        export_fanuc([FrameEntry(10, "b", "base", Pose())])


def test_ur_script_in_metres_and_rotation_vectors():
    tool = FrameEntry(2, "probe", "tool", Pose(100, 200, 300, 90, 0, 0),
                      LoadData(1.25, (0, 10, 45)))
    text = export_ur([tool, TABLE, PANEL, NOZZLE, FrameEntry(1, "bare", "tool", Pose())])
    assert "global tool_2 = p[0.1, 0.2, 0.3, 0.0, 0.0, 1.570796326795]" in text
    assert "def use_tool_2():\n  set_tcp(tool_2)\n  set_payload(1.25, [0.0, 0.01, 0.045])\nend" in text
    assert "def use_tool_1():\n  set_tcp(tool_1)\n  # load not known" in text
    m = re.search(r"global base_1 = p\[([^\]]*)\]", text)
    p = [float(v) for v in m.group(1).split(",")]
    assert np.allclose(matrix_from_ur(p), TABLE.pose.as_matrix(), atol=1e-6)
    assert "global workpiece_2 = p[" in text and "global fixed_tool_4 = p[" in text


# --------------------------------------------------------------------------- round trips

KINDS = ("tool", "workpiece", "base", "fixed_tool")
coord = st.floats(-5000, 5000, allow_nan=False, allow_infinity=False)
angle = st.floats(-180, 180, allow_nan=False)
small = st.floats(0, 50, allow_nan=False)
names = st.text(st.sampled_from("abcXYZ019 _-+."), max_size=24).map(str.strip)
loads = st.builds(LoadData, st.floats(0.01, 500), st.tuples(coord, coord, coord),
                  st.tuples(small, small, small), st.tuples(angle, st.floats(-89, 89), angle))


@st.composite
def entry_lists(draw):
    slots = draw(st.lists(st.tuples(st.sampled_from(KINDS), st.integers(1, 16)), max_size=8,
                          unique_by=lambda s: (s[0] in ("tool", "workpiece"), s[1])))
    out = []
    for kind, number in slots:
        pose = Pose(draw(coord), draw(coord), draw(coord),
                    draw(angle), draw(st.floats(-89.9, 89.9)), draw(angle))
        load = draw(st.none() | loads) if kind in ("tool", "workpiece") else None
        out.append(FrameEntry(number, draw(names), kind, pose, load))
    return out


@settings(max_examples=150, deadline=None)
@given(entry_lists())
def test_kuka_round_trip_is_exact(entries):
    assert import_kuka(export_kuka(entries)) == canonical_order(entries)


@settings(max_examples=150, deadline=None)
@given(entry_lists())
def test_abb_round_trip_to_1e_9(entries):
    back = import_abb(export_abb(entries))
    want = canonical_order(entries)
    assert [(e.kind, e.number, e.name) for e in back] == [(e.kind, e.number, e.name) for e in want]
    for b, w in zip(back, want):
        assert (b.pose.x, b.pose.y, b.pose.z) == (w.pose.x, w.pose.y, w.pose.z)
        assert close_poses(b.pose, w.pose)
        assert (b.load is None) == (w.load is None)
        if w.load is not None:
            assert (b.load.mass_kg, b.load.com_mm, b.load.inertia_kgm2) == \
                   (w.load.mass_kg, w.load.com_mm, w.load.inertia_kgm2)
            assert close_poses(Pose(0, 0, 0, *b.load.inertia_axes_deg),
                               Pose(0, 0, 0, *w.load.inertia_axes_deg))
    assert import_abb(export_abb(back)) == back  # a second trip changes nothing


@settings(max_examples=50, deadline=None)
@given(entry_lists())
def test_fanuc_and_ur_export_every_entry(entries):
    entries = [e for e in entries if e.number <= (10 if e.kind in ("tool", "workpiece") else 9)]
    fanuc, ur = export_fanuc(entries), export_ur(entries)
    for e in entries:
        label = "UTOOL" if e.kind in ("tool", "workpiece") else "UFRAME"
        xyzwpr = [float(v) for v in row_of(fanuc, label, e.number)[-6:]]
        kuka = Pose(*xyzwpr[:3], *xyzwpr[:2:-1])  # A, B, C = R, P, W
        assert np.allclose(kuka.as_matrix(), e.pose.as_matrix(), atol=1e-4)
        m = re.search(rf"global {e.kind}_{e.number} = p\[([^\]]*)\]", ur)
        p = [float(v) for v in m.group(1).split(",")]
        assert np.allclose(matrix_from_ur(p), e.pose.as_matrix(), atol=1e-5)
