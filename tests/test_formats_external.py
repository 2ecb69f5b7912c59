"""External kinematics in controller files (issue 13, item 4): KUKA ``$ETn_...`` machine data
with ``MACHINE_DEF`` and the bases on the kinematic, ABB ``MOC.cfg`` base frames with the
coordinated work objects. Writers and readers round-trip every frame to 1e-9 mm / deg, names
cannot add a line, the rotations agree with the KUKA and ABB table exports, the chain is the
root-point solver's ``T_base_flange(θ) = T_base_root @ Rz(θ)``, and fragments written in the
documented layouts (docs/formats.md, "External kinematics") are read.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from server.service.bounds import unprintable
from server.formats import FormatError, FrameEntry, export_abb, export_kuka
from server.formats.external import (
    ExternalKinematic,
    abb_mechanical_units,
    flange_matrix,
    kuka_external_kinematics,
    kuka_machine_name,
    linear_unit,
    positioner_2axis,
    read_abb_external,
    read_kuka_external,
    turntable,
)
from solvers.errors import CalibrationError
from solvers.external import linear_unit as solve_linear_unit
from solvers.external import positioner_2axis as solve_positioner
from solvers.external import root_point
from solvers.external.common import rz
from solvers.external_sim import make_linear_unit, make_positioner
from solvers.frames import Pose, angle_between_deg, invert

RNG = np.random.default_rng(13)


def random_pose(rng: np.random.Generator, reach: float = 2000.0) -> Pose:
    return Pose(*rng.uniform(-reach, reach, 3), *rng.uniform(-179, 179, 3))


def same_T(P: np.ndarray, Q: np.ndarray, mm: float = 1e-9, deg: float = 1e-9) -> bool:
    return float(angle_between_deg(P[:3, :3], Q[:3, :3])) <= deg and \
        bool(np.allclose(P[:3, 3], Q[:3, 3], atol=mm, rtol=0))


def same_pose(p: Pose, q: Pose, mm: float = 1e-9, deg: float = 1e-9) -> bool:
    return same_T(p.as_matrix(), q.as_matrix(), mm, deg)


def same_chain(a: ExternalKinematic, b: ExternalKinematic, tol: float = 1e-9) -> bool:
    """Both give the same flange at every axis value tried (deg, or mm for a rail)."""
    grid = np.linspace(-170, 170, 5) if not a.linear else np.linspace(-1500, 3000, 5)
    for v in grid:
        q = [v] if len(a.axes) == 1 else [v, -0.7 * v + 20]
        if not same_T(flange_matrix(a, q), flange_matrix(b, q), tol, tol):
            return False
    return True


def cell(rng: np.random.Generator):
    """A turntable (ET1), a positioner (ET2, E2+E3) and a rail carrying the robot (ET4, E4),
    with two bases on the turntable and one on the positioner."""
    table = turntable(1, "TABLE", random_pose(rng), "E1", flange=random_pose(rng, 300))
    posi = positioner_2axis(2, "DKP_400_1", random_pose(rng), random_pose(rng, 500),
                            ("E2", "E3"), flange=random_pose(rng, 200))
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    rail_frame = np.eye(4)
    x = np.cross(d, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    rail_frame[:3, :3] = np.column_stack([x, np.cross(d, x), d])
    rail = linear_unit(4, "KL1500", rail_frame, "E4", root=random_pose(rng, 500))
    bases = [FrameEntry(17, "fixture A", "coordinated_base", random_pose(rng, 400), None, "TABLE"),
             FrameEntry(18, "fixture B", "coordinated_base", random_pose(rng, 400), None, "TABLE"),
             FrameEntry(20, "part", "coordinated_base", random_pose(rng, 400), None, "DKP_400_1")]
    return [table, posi, rail], bases


# --------------------------------------------------------------------------- the chain


def test_turntable_chain_is_the_root_point_convention():
    """A mark on the table touched at 4 axis values: root_point's T_base_root exported as a
    turntable gives back every touched point as flange(θ) @ mark-in-flange."""
    root_true = Pose(1450.0, -320.0, 280.0, 25.0, 3.0, -2.0).as_matrix()
    mark = np.array([230.0, 40.0, 0.0, 1.0])
    theta = np.array([0.0, 80.0, 170.0, 260.0])
    P = np.array([(root_true @ rz([t])[0] @ mark)[:3] for t in theta])
    res = root_point(P, theta)
    kin = turntable(1, "TABLE", res.frame)
    text = kuka_external_kinematics([kin])
    back = read_kuka_external(text.machine_dat, text.config_dat).kinematics[0]
    mark_in_flange = invert(flange_matrix(back, [0.0])) @ np.r_[P[0], 1.0]
    for t, p in zip(theta, P):
        assert np.allclose((flange_matrix(back, [t]) @ mark_in_flange)[:3], p, atol=1e-6)
        assert same_T(flange_matrix(back, [t]), res.frame @ rz([t])[0], 1e-9, 1e-9)


def test_linear_unit_travels_along_z_of_its_transformation():
    """The rail frame of ext.linear_unit (z = travel in the robot base) becomes $ETn_TA1KR:
    the robot base rides along that z, and $ETn_TFLA3 puts it back upright on the carriage."""
    d = np.array([0.6, 0.8, 0.0])
    rail = np.eye(4)
    rail[:3, :3] = np.column_stack([[0.0, 0.0, 1.0], np.cross(d, [0.0, 0.0, 1.0]), d])
    kin = linear_unit(1, "KL", rail)
    text = kuka_external_kinematics([kin])
    ta1kr = re.search(r"FRAME \$ET1_TA1KR=(\{.*\})", text.machine_dat).group(1)
    assert "#ERSYS" in text.machine_dat and "FRAME $ERSYSROOT=" in text.machine_dat
    back = read_kuka_external(text.machine_dat, text.config_dat).kinematics[0]
    assert back.kind == "linear_unit" and ta1kr.startswith("{X 0.0,Y 0.0,Z 0.0,")
    assert np.allclose(back.axis_frames[0].as_matrix()[:3, 2], d, atol=1e-12)
    for e in (-800.0, 0.0, 1234.5):
        T = flange_matrix(back, [e])
        assert np.allclose(T[:3, 3], e * d, atol=1e-9) and np.allclose(T[:3, :3], np.eye(3))


def test_positioner_chain_turns_the_turn_axis_with_the_tilt():
    """T_base_flange(τ, θ) = T_base_tiltroot Rz(τ) T_tiltflange_turnroot Rz(θ)."""
    tilt = Pose(1800, 0, 600, 0, 90, 0)
    x = Pose(0, 0, 250, 0, -90, 0)
    kin = positioner_2axis(1, "DKP", tilt, x)
    for tau, th in ((0, 0), (35, -120), (-90, 45)):
        want = tilt.as_matrix() @ rz([tau])[0] @ x.as_matrix() @ rz([th])[0]
        assert same_T(flange_matrix(kin, [tau, th]), want)


# --------------------------------------------------------------------------- KUKA


def test_kuka_round_trip_keeps_every_frame_to_1e9():
    for seed in range(20):
        kins, bases = cell(np.random.default_rng(seed))
        text = kuka_external_kinematics(kins, bases)
        back = read_kuka_external(text.machine_dat, text.config_dat)
        assert [k.number for k in back.kinematics] == [1, 2, 4]
        for a, b in zip(kins, back.kinematics):
            assert (a.name, a.kind, a.axes) == (b.name, b.kind, b.axes)
            assert same_pose(a.root, b.root) and same_pose(a.flange, b.flange)
            assert all(same_pose(p, q) for p, q in zip(a.axis_frames, b.axis_frames))
            assert same_chain(a, b)
        assert back.bases == bases  # shortest exact digits: the same doubles


def test_kuka_writes_the_documented_declarations():
    kins, bases = cell(RNG)
    text = kuka_external_kinematics(kins, bases)
    md, cd = text.machine_dat, text.config_dat
    assert "DECL EX_KIN $EX_KIN={ET1 #EASYS,ET2 #EBSYS,ET3 #NONE,ET4 #ERSYS,ET5 #NONE," \
           "ET6 #NONE}" in md
    assert "DECL ET_AX $ET2_AX={TR_A1 #E2,TR_A2 #E3,TR_A3 #NONE}" in md
    assert '$ET2_NAME[]="DKP_400_1"' in md
    for n in (1, 2, 4):
        for frame in ("TA1KR", "TA2A1", "TA3A2", "TFLA3"):
            assert len(re.findall(rf"^FRAME \$ET{n}_{frame}=\{{X [^,]+,Y [^,]+,Z [^,]+,A [^,]+,"
                                  r"B [^,]+,C [^,]+\}$", md, re.M)) == 1
    assert re.search(r'^MACHINE_DEF\[3\]=\{NAME\[\] "DKP_400_1",COOP_KRC_INDEX 1,PARENT\[\] " ",'
                     r"ROOT \{X .*\},MECH_TYPE #EBSYS,GEOMETRY\[\] \" \"\}$", cd, re.M)
    assert 'MACHINE_FRAME_DAT[20]={MACH_DEF_INDEX 3,PARENT[] "DKP_400_1",GEOMETRY[] " "}' in cd
    assert "BASE_TYPE[17]=#BASE" in cd and 'BASE_NAME[17,]="fixture A"' in cd
    assert "MACHINE_DEF[5]" not in cd  # the rail's root is $ERSYSROOT, not a MACHINE_DEF


def test_kuka_base_line_is_what_export_kuka_writes():
    """The bases' lines are those of the whole-file export (one writer for BASE_DATA and
    MACHINE_FRAME_DAT), and the whole file's reader sees them on the same machine."""
    kins, bases = cell(RNG)
    cd = kuka_external_kinematics(kins, bases).config_dat
    whole = export_kuka(bases, 16, 32)
    for b in bases:
        line = f"BASE_DATA[{b.number}]="
        assert next(x for x in cd.splitlines() if x.startswith(line)) == \
            next(x for x in whole.splitlines() if x.startswith(line))


def test_kuka_folds_the_frames_of_unused_axes_into_the_flange():
    """A one-axis kinematic still passes $ETn_TA2A1 and $ETn_TA3A2 (the chain is TA1KR(E1) :
    TA2A1(E2) : TA3A2(E3) : TFLA3 with the unused axes at rest)."""
    kin = turntable(1, "T", Pose(1000, 0, 0, 0, 0, 0))
    md = kuka_external_kinematics([kin]).machine_dat
    md = md.replace("FRAME $ET1_TA2A1={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}",
                    "FRAME $ET1_TA2A1={X 0.0,Y 0.0,Z 120.0,A 0.0,B 0.0,C 0.0}")
    md = md.replace("FRAME $ET1_TA3A2={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}",
                    "FRAME $ET1_TA3A2={X 0.0,Y 0.0,Z 0.0,A 90.0,B 0.0,C 0.0}")
    cd = kuka_external_kinematics([kin]).config_dat
    back = read_kuka_external(md, cd).kinematics[0]
    assert same_pose(back.flange, Pose(0, 0, 120, 90, 0, 0))
    assert np.allclose(flange_matrix(back, [90])[:3, 3], [1000, 0, 120], atol=1e-9)


def test_kuka_reads_a_fragment_written_as_the_machine_data_manual_shows_it():
    """$machine.dat lines as KUKA's machine-data manual gives them (``FRAME $ET1_TA1KR={X
    0.0,Y 0.0,Z 427.0,A 0.0,B 0.0,C 90.0}``, ``$ET1_NAME[]="REINHARD_1"``, ``DECL EX_KIN``,
    ``DECL ET_AX $ET1_AX={TR_A1 #E2,...}``), inside a whole file with other data, comments,
    spacing and CR LF; MACHINE_DEF and MACHINE_FRAME_DAT in the layout of $config.dat."""
    machine = "\r\n".join([
        "&ACCESS RV", "&REL 1", "DEFDAT  $MACHINE PUBLIC", ";FOLD EXTERNAL KINEMATICS",
        "DECL EX_KIN $EX_KIN={ET1 #EASYS,ET2 #NONE,ET3 #NONE,ET4 #NONE,ET5 #NONE,ET6 #NONE}",
        "DECL ET_AX $ET1_AX={TR_A1 #E2,TR_A2 #NONE,TR_A3 #NONE}",
        "DECL ET_AX $ET2_AX={TR_A1 #NONE,TR_A2 #NONE,TR_A3 #NONE}",
        '$ET1_NAME[]="REINHARD_1"  ; the table',
        "FRAME $ET1_TA1KR={X 0.0,Y 0.0,Z 427.0,A 0.0,B 0.0,C 90.0}",
        "FRAME $ET1_TA2A1={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}",
        "FRAME $ET1_TA3A2={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}",
        "FRAME $ET1_TFLA3={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}",
        "FRAME $ET2_TA1KR={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}",
        "INT $AXIS_TYPE[8]", "$AXIS_TYPE[8]=2", ";ENDFOLD", "ENDDAT", ""])
    config = "\r\n".join([
        "DEFDAT  $CONFIG",
        'MACHINE_DEF[1]={NAME[] "KR16",COOP_KRC_INDEX 1,PARENT[] "WORLD",ROOT {X 0.0,Y 0.0,'
        'Z 0.0,A 0.0,B 0.0,C 0.0},MECH_TYPE #ROBOT,GEOMETRY[] " "}',
        'MACHINE_DEF[2]={NAME[] "REINHARD_1",COOP_KRC_INDEX 1,PARENT[] " ",ROOT {X 1523.5,'
        'Y -12.25,Z 0.0,A 90.0,B 0.0,C 0.0},MECH_TYPE #EASYS,GEOMETRY[] " "}',
        'MACHINE_DEF[3]={NAME[] " ",COOP_KRC_INDEX 0,PARENT[] " ",ROOT {X 0.0,Y 0.0,Z 0.0,'
        'A 0.0,B 0.0,C 0.0},MECH_TYPE #NONE,GEOMETRY[] " "}',
        "BASE_DATA[17]={X 150.0,Y 0.0,Z 20.0,A 0.0,B 0.0,C 0.0}",
        'BASE_NAME[17,]="TABLE SIDE 1"', "BASE_TYPE[17]=#BASE",
        'MACHINE_FRAME_DAT[17]={MACH_DEF_INDEX 2,PARENT[] "REINHARD_1",GEOMETRY[] " "}',
        "BASE_DATA[1]={X 900.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}", "BASE_TYPE[1]=#BASE",
        'MACHINE_FRAME_DAT[1]={MACH_DEF_INDEX 0,PARENT[] " ",GEOMETRY[] " "}',
        "ENDDAT", ""])
    got = read_kuka_external(machine, config)
    (k,) = got.kinematics
    assert (k.number, k.name, k.kind, k.axes) == (1, "REINHARD_1", "turntable", ("E2",))
    assert same_pose(k.axis_frames[0], Pose(0, 0, 427, 0, 0, 90))
    assert same_pose(k.root, Pose(1523.5, -12.25, 0, 90, 0, 0))
    assert got.bases == [FrameEntry(17, "TABLE SIDE 1", "coordinated_base",
                                    Pose(150, 0, 20, 0, 0, 0), None, "REINHARD_1")]
    # the table's axis is 427 mm above the root: a point on it stays there while E2 turns
    assert np.allclose(flange_matrix(k, [77.0])[:3, 3], [1523.5, -12.25, 427.0])


@pytest.mark.parametrize("edit, loc, reason", [
    (lambda md, cd: (md.replace("$EX_KIN=", "$EX_KIX="), cd), ("machine_dat", "EX_KIN"),
     "no $EX_KIN"),
    (lambda md, cd: (md.replace("ET1 #EASYS", "ET1 #EXSYS"), cd),
     ("machine_dat", "line 3", "$EX_KIN.ET1"), "expected #NONE"),
    (lambda md, cd: (md, cd.replace("Z 300.0,A", "Z 3e7,A")),
     ("config_dat", "line 3", "MACHINE_DEF[2].ROOT.Z"), "must be within"),
    (lambda md, cd: (md.replace("TR_A2 #NONE", "TR_A2 #E7"), cd),
     ("machine_dat", "line 5", "$ET1_AX.TR_A2"), "expected #E1..#E6"),
    (lambda md, cd: (md, cd.replace('NAME[] "TABLE"', 'NAME[] "OTHER"')),
     ("config_dat", "MACHINE_DEF"), 'no MACHINE_DEF has NAME[] "TABLE"'),
    (lambda md, cd: (md.replace(",C 0.0}\nFRAME $ET1_TA2A1", "}\nFRAME $ET1_TA2A1"), cd),
     ("machine_dat", "line 7", "$ET1_TA1KR"), "missing C"),
    (lambda md, cd: (md + "FRAME $ET1_TFLA3={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}\n", cd),
     ("machine_dat", "line 11", "ET1_TFLA3"), "assigned twice (first on line 10)"),
    (lambda md, cd: (md.replace("TR_A2 #NONE,TR_A3 #NONE", "TR_A2 #E2,TR_A3 #E3"), cd),
     ("machine_dat", "line 5", "$ET1_AX"), "three-axis kinematics are not supported"),
    (lambda md, cd: (md.replace("TR_A3 #NONE", "TR_A3 #E3"), cd),
     ("machine_dat", "line 5", "$ET1_AX.TR_A2"), "without gaps"),
])
def test_kuka_reader_names_what_is_wrong(edit, loc, reason):
    text = kuka_external_kinematics([turntable(1, "TABLE", Pose(0, 0, 300, 0, 0, 0))])
    md, cd = edit(text.machine_dat, text.config_dat)
    with pytest.raises(FormatError) as err:
        read_kuka_external(md, cd)
    assert err.value.loc == loc
    assert reason in err.value.reason


def test_kuka_linear_unit_with_two_axes_and_missing_root_are_refused():
    text = kuka_external_kinematics([linear_unit(1, "KL", np.eye(4))])
    with pytest.raises(FormatError, match="one axis"):
        read_kuka_external(text.machine_dat.replace("TR_A2 #NONE", "TR_A2 #E2"), "")
    with pytest.raises(FormatError, match=r"\$ERSYSROOT"):
        read_kuka_external(text.machine_dat.replace("FRAME $ERSYSROOT", "FRAME $ERSYSROOX"), "")


# --------------------------------------------------------------------------- names


HOSTILE = ['T"\n}', 'A" ,PARENT[] "X', "X\u2028BASE_DATA[1]={X 9}", 'Q;}\\"\r\n-use_joint "R"',
           "E\x85F"]


def test_no_name_adds_a_line_in_any_format():
    """Base names with line breaks, quotes and braces; kinematic names with quotes, braces,
    ``;``, ``\\`` and MOC's ``-attribute`` syntax: every output has the lines of a plain
    name and reads back; a kinematic name with a control character is refused up front."""
    def texts(kname: str, bname: str) -> list[str]:
        kin = turntable(1, kname, Pose(1000, 0, 0, 0, 0, 0))
        base = FrameEntry(5, bname, "coordinated_base", Pose(1, 2, 3, 0, 0, 0), None, kname)
        k, a = kuka_external_kinematics([kin], [base]), abb_mechanical_units([kin], [base])
        return [k.machine_dat, k.config_dat, a.moc_cfg, a.rapid]

    plain = [t.count("\n") for t in texts("TABLE", "fixture")]
    for name in HOSTILE:
        kname = name.translate({ord(c): None for c in "\n\r\u2028\x85"})
        out = texts(kname, name)
        assert [t.count("\n") for t in out] == plain, name
        assert not any(re.search("[\r\u2028\u2029\x85]", t) for t in out)
        kk = read_kuka_external(out[0], out[1])
        assert len(kk.kinematics) == 1 and len(kk.bases) == 1
        assert kk.bases[0].mech_unit == kk.kinematics[0].name
        aa = read_abb_external(out[2], out[3])
        assert len(aa.kinematics) == 1 and aa.bases[0].mech_unit == aa.kinematics[0].name
        assert re.fullmatch(r"[A-Za-z]\w*", aa.kinematics[0].name)
    for name in ("A\nB", "A\u2028B", "A\x85B", "", "   ", "x" * 33):
        with pytest.raises(CalibrationError) as err:
            turntable(1, name, Pose())
        assert err.value.loc == ("name",)


def test_two_names_written_alike_are_refused():
    a = turntable(1, 'T"1', Pose())
    b = turntable(2, "T 1", Pose(), "E2")
    with pytest.raises(FormatError) as err:
        kuka_external_kinematics([a, b])
    assert err.value.loc == ("kinematics", 1, "name")


# --------------------------------------------------------------------------- ABB


def test_abb_round_trip_keeps_every_chain_to_1e9():
    for seed in range(20):
        kins, bases = cell(np.random.default_rng(seed))
        text = abb_mechanical_units(kins, bases)
        back = read_abb_external(text.moc_cfg, text.rapid)
        assert [(k.name, k.kind) for k in back.kinematics] == \
            [(k.name, k.kind) for k in kins]
        assert [k.axes for k in back.kinematics] == [("E1",), ("E2", "E3"), ("E4",)]
        for a, b in zip(kins, back.kinematics):
            if a.linear:
                assert same_chain(a, b)
            else:  # ABB has no flange frame: the work objects carry it
                assert same_chain(replace_flange(a), b)
        flanges = {k.name: k.flange.as_matrix() for k in kins}
        for want, got in zip(bases, back.bases):
            assert (want.number, want.name, got.mech_unit) == (got.number, got.name,
                                                                want.mech_unit)
            assert same_T(flanges[want.mech_unit] @ want.pose.as_matrix(), got.pose.as_matrix())


def replace_flange(k: ExternalKinematic) -> ExternalKinematic:
    return replace(k, flange=Pose())


def test_abb_writes_the_moc_attributes_of_the_public_files():
    kins, bases = cell(RNG)
    moc = abb_mechanical_units(kins, bases).moc_cfg
    assert moc.startswith("MOC:CFG_1.0:6:0::\n#\nMECHANICAL_UNIT:\n\n")
    joined = moc.replace("\\\n      ", " ")
    assert '-name "DKP_400_1" -use_single_0 "DKP_400_1_1" -use_single_1 "DKP_400_1_2"' in joined
    assert re.search(r'-name "ROB_1" -base_frame_pos_x \S+ .* -base_frame_coordinated "KL1500"',
                     joined)
    assert re.search(r'-name "DKP_400_1_2" .*-base_frame_coordinated "DKP_400_1_1"', joined)
    for line in moc.splitlines():
        assert len(line) <= 80 and (not line.startswith(" ") or line.startswith("      -"))
    for m in re.finditer(r"-name \"(\w+)\" -base_frame_pos_x (\S+) -base_frame_pos_y (\S+) "
                         r"-base_frame_pos_z (\S+)", joined):
        assert all(abs(float(v)) < 10 for v in m.groups()[1:])  # metres, not mm


def test_abb_quaternion_is_the_one_export_abb_writes_for_the_same_frame():
    """The SINGLE's base_frame_orient_u0..u3 and a wobjdata of the same pose from
    export_abb carry the same digits, scalar first."""
    for seed in range(10):
        pose = random_pose(np.random.default_rng(seed))
        moc = abb_mechanical_units([turntable(1, "STN1", pose)]).moc_cfg.replace("\\\n      ", " ")
        u = [re.search(rf"-base_frame_orient_u{i} (\S+)", moc).group(1) for i in range(4)]
        rapid = export_abb([FrameEntry(1, "w", "base", pose)])
        q = re.search(r"wobjdata w:=\[FALSE,TRUE,\"\",\[\[[^\]]*\],\[([^\]]*)\]\]", rapid).group(1)
        assert [float(x) for x in u] == [float(x) for x in q.split(",")]
        T = pose.as_matrix()
        assert float(u[0]) >= 0 and np.isclose(float(u[0]), np.sqrt(1 + np.trace(T[:3, :3])) / 2)


def test_abb_reads_a_track_in_the_layout_of_a_public_moc_cfg():
    """A robot on a track as RobotWare writes MOC.cfg: the robot's ``-base_frame_coordinated``
    names the track's single, the single has no base frame attributes (defaults: at the world
    origin), attributes are continued with ``\\``, flags have no value, numbers use E-notation."""
    moc = "\n".join([
        "MOC:CFG_1.0:5:0::", "#", "MECHANICAL_UNIT:", "",
        '      -name "TRACK7" -use_run_enable "" -use_activation_relay ""\\',
        '      -use_brake_relay "" -use_single_0 "TRACK7" -stand_by_state \\',
        "      -activate_at_start_up  -deactivation_forbidden ", "#", "ROBOT:", "",
        '      -name "ROB_1" -use_robot_serial_number "rob_1"\\',
        '      -use_robot_type "ROB1_6660_1.90_205" -use_robot_calib "r1_calib"\\',
        '      -use_joint_0 "rob1_1" -use_joint_1 "rob1_2" -use_joint_2 "rob1_3"\\',
        '      -base_frame_orient_u0 0 -base_frame_orient_u1 -0.707107\\',
        '      -base_frame_orient_u2 0.707107 -base_frame_pos_z 2.5E-001\\',
        '      -base_frame_coordinated "TRACK7" -base_mass 328 -base_mass_centre_x -0.0605',
        "#", "SINGLE:", "", '      -name "TRACK7" -use_single_type "TRACK7" -use_joint "TRACK7"',
        "#", "SINGLE_TYPE:", "", '      -name "TRACK7" -mechanics "TRACK" -use_sis "TRACK7"', ""])
    (k,) = read_abb_external(moc).kinematics
    assert (k.name, k.kind, k.axes) == ("TRACK7", "linear_unit", ("E1",))
    assert same_pose(k.root, Pose())
    R = k.flange.as_matrix()
    assert np.allclose(R[:3, 3], [0, 0, 250]) and np.allclose(
        R[:3, :3], np.array([[0, -1, 0], [-1, 0, 0], [0, 0, -1]]), atol=1e-6)


@pytest.mark.parametrize("edit, field, reason", [
    (lambda m: m.replace("-base_frame_orient_u0 1", "-base_frame_orient_u0 2"),
     "STN1.base_frame_orient", "length"),
    (lambda m: m.replace("-base_frame_pos_x 1.5", "-base_frame_pos_x 2e4"),
     "STN1.base_frame_pos_x", "must be within"),
    (lambda m: m.replace("-base_frame_pos_x 1.5", "-base_frame_pos_x abc"),
     "STN1.base_frame_pos_x", "expected a number"),
    (lambda m: m.replace('-use_single_0 "STN1"', '-use_single_0 "STN9"'),
     "STN1.use_single", "does not define"),
])
def test_abb_reader_names_what_is_wrong(edit, field, reason):
    moc = abb_mechanical_units([turntable(1, "STN1", Pose(1500, 0, 300, 0, 0, 0))]).moc_cfg
    with pytest.raises(FormatError) as err:
        read_abb_external(edit(moc))
    assert err.value.loc[0] == "moc_cfg" and err.value.loc[-1] == field
    assert reason in err.value.reason


def test_abb_reader_refuses_units_it_cannot_chain():
    """Two singles of one unit that do not carry each other (two stations), or a unit riding
    on another, are no kinematic pendant models: refused, naming the single."""
    posi = positioner_2axis(1, "STN1", Pose(1500, 0, 600, 0, 90, 0), Pose(0, 0, 200, 0, -90, 0))
    moc = abb_mechanical_units([posi]).moc_cfg
    with pytest.raises(FormatError) as err:
        read_abb_external(moc.replace('-base_frame_coordinated "STN1_1"', ""))
    assert err.value.loc[-1] == "STN1_2.base_frame_coordinated"
    moc = abb_mechanical_units([turntable(1, "STN1", Pose(1500, 0, 0, 0, 0, 0))]).moc_cfg
    with pytest.raises(FormatError) as err:
        read_abb_external(moc.rstrip("\n") + ' -base_frame_coordinated "TRACK"\n')
    assert err.value.loc[-1] == "STN1.base_frame_coordinated" and "TRACK" in err.value.reason


def test_abb_moc_cut_short_is_refused():
    moc = abb_mechanical_units([turntable(1, "STN1", Pose(1500, 0, 300, 0, 0, 0))]).moc_cfg
    with pytest.raises(FormatError, match="cut short"):
        read_abb_external(moc.rsplit("\n", 2)[0])


# --------------------------------------------------------------------------- the model


@pytest.mark.parametrize("kwargs, loc", [
    (dict(number=7), ("number",)), (dict(number=True), ("number",)),
    (dict(kind="gantry"), ("kind",)), (dict(axes=("E1", "E2")), ("axes",)),
    (dict(axes=("E7",)), ("axes", 0)), (dict(axis_frames=()), ("axis_frames",)),
    (dict(root=Pose(2e6, 0, 0, 0, 0, 0)), ("root", "x")),
    (dict(flange=Pose(0, 0, 0, 0, float("nan"), 0)), ("flange", "b")),
])
def test_model_refuses_bad_fields(kwargs, loc):
    base = dict(number=1, name="T", kind="turntable", root=Pose(), axis_frames=(Pose(),),
                flange=Pose(), axes=("E1",))
    with pytest.raises(CalibrationError) as err:
        ExternalKinematic(**{**base, **kwargs})
    assert err.value.loc == loc


def test_setup_refuses_what_no_controller_can_hold():
    t1 = turntable(1, "T1", Pose())
    cases = [
        ([t1, turntable(1, "T2", Pose(), "E2")], [], ("kinematics", 1, "number")),
        ([t1, turntable(2, "T2", Pose(), "E1")], [], ("kinematics", 1, "axes")),
        ([linear_unit(1, "L1", np.eye(4)), linear_unit(2, "L2", np.eye(4), "E2")], [],
         ("kinematics",)),
        ([t1], [FrameEntry(3, "b", "coordinated_base", Pose(), None, "T9")],
         ("bases", 0, "mech_unit")),
        ([linear_unit(1, "L1", np.eye(4))],
         [FrameEntry(3, "b", "coordinated_base", Pose(), None, "L1")], ("bases", 0, "mech_unit")),
        ([t1], [FrameEntry(3, "b", "base", Pose())], ("bases", 0, "kind")),
        ([t1], [FrameEntry(3, "b", "coordinated_base", Pose(), None, "T1")] * 2,
         ("bases", 1, "number")),
    ]
    for kins, bases, loc in cases:
        for write in (kuka_external_kinematics, abb_mechanical_units):
            with pytest.raises(FormatError) as err:
                write(kins, bases)
            assert err.value.loc == loc, (write.__name__, loc)


# --------------------------------------------------------------------------- patching


DATA = Path(__file__).parent / "data"
CELL7 = (DATA / "kuka_cell7_config.dat").read_bytes().decode()  # MACHINE_DEF[2] "DKP_400_1"
ABB7 = (DATA / "abb_cell7.mod").read_text()  # wTurntable on "STN1"
MACHINE7 = "\r\n".join([
    "&ACCESS RV", "&REL 2", "DEFDAT  $MACHINE PUBLIC", ";FOLD EXTERNAL KINEMATICS",
    "DECL EX_KIN $EX_KIN={ET1 #EASYS,ET2 #NONE,ET3 #NONE,ET4 #NONE,ET5 #NONE,ET6 #NONE}",
    "DECL ET_AX $ET1_AX={TR_A1 #E1,TR_A2 #E2,TR_A3 #NONE}",
    '$ET1_NAME[]="DKP_400_1"',
    "FRAME $ET1_TA1KR={X 0.0,Y 0.0,Z 700.000,A 0.0,B 90.0000,C 0.0}  ; tilt axis",
    "FRAME $ET1_TA2A1={X 0.0,Y 0.0,Z -250.000,A 0.0,B -90.0000,C 0.0}",
    "FRAME $ET1_TA3A2={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}",
    "FRAME $ET1_TFLA3={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}",
    "DECL ET_AX $ET2_AX={TR_A1 #NONE,TR_A2 #NONE,TR_A3 #NONE}",
    '$ET2_NAME[]=" "',
    "FRAME $ET2_TA1KR={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}",
    ";ENDFOLD", "ENDDAT", ""])


def changed_lines(a: str, b: str) -> list[str]:
    return [d[2:].rstrip("\r\n") for d in difflib.ndiff(a.splitlines(True), b.splitlines(True))
            if d[:1] in "+-"]


def test_kuka_patch_without_change_gives_the_files_back_byte_for_byte():
    setup = read_kuka_external(MACHINE7, CELL7)
    assert [(k.name, k.kind, k.axes) for k in setup.kinematics] == \
        [("DKP_400_1", "positioner_2axis", ("E1", "E2"))]
    assert [b.number for b in setup.bases] == [3]
    text = kuka_external_kinematics(setup.kinematics, setup.bases, machine_template=MACHINE7,
                                    config_template=CELL7)
    assert text.machine_dat == MACHINE7 and text.config_dat == CELL7


def test_kuka_patch_touches_only_the_numbers_that_changed():
    setup = read_kuka_external(MACHINE7, CELL7)
    (k,) = setup.kinematics
    moved = replace(k, root=replace(k.root, x=1850.5),
                    axis_frames=(k.axis_frames[0], replace(k.axis_frames[1], z=-251.25)))
    base = replace(setup.bases[0], pose=replace(setup.bases[0].pose, y=7.5))
    text = kuka_external_kinematics([moved], [base], machine_template=MACHINE7,
                                    config_template=CELL7)
    assert changed_lines(MACHINE7, text.machine_dat) == [
        "FRAME $ET1_TA2A1={X 0.0,Y 0.0,Z -250.000,A 0.0,B -90.0000,C 0.0}",
        "FRAME $ET1_TA2A1={X 0.0,Y 0.0,Z -251.25,A 0.0,B -90.0000,C 0.0}"]
    diff = changed_lines(CELL7, text.config_dat)
    assert len(diff) == 4 and any(x.startswith("MACHINE_DEF[2]=") and "X 1850.5," in x
                                  and "A 180.000," in x for x in diff)
    assert any(x.startswith("BASE_DATA[3]=") and ",Y 7.5," in x for x in diff)
    back = read_kuka_external(text.machine_dat, text.config_dat)
    assert same_chain(back.kinematics[0], moved) and back.bases == [base]


def test_kuka_patch_adds_a_kinematic_the_files_lack_and_refuses_a_full_machine_def():
    setup = read_kuka_external(MACHINE7, CELL7)
    table = turntable(3, "TABLE2", Pose(0, 2000, 0, 0, 0, 0), "E3")
    with pytest.raises(FormatError) as err:
        kuka_external_kinematics([*setup.kinematics, table], setup.bases,
                                 machine_template=MACHINE7, config_template=CELL7)
    assert err.value.loc[-1] == "MACHINE_DEF" and "MACHINE_DEF[4]" in err.value.reason
    text = kuka_external_kinematics([*setup.kinematics, table], setup.bases,
                                    machine_template=MACHINE7)
    added = changed_lines(MACHINE7, text.machine_dat)
    assert "DECL ET_AX $ET3_AX={TR_A1 #E3,TR_A2 #NONE,TR_A3 #NONE}" in added
    assert text.machine_dat.index("$ET3_TFLA3") < text.machine_dat.index("ENDDAT")
    assert "\r\nFRAME $ET3_TA1KR" in text.machine_dat  # the file's own line ends


def test_abb_patch_touches_only_the_attributes_that_changed():
    moc = "\r\n".join([
        "MOC:CFG_1.0:5:0::", "#", "MECHANICAL_UNIT:", "",
        '      -name "STN1" -use_run_enable "" -use_single_0 "STN1" -stand_by_state ', "#",
        "ROBOT:", "", '      -name "ROB_1" -use_robot_type "ROB1_6700_2.65_235"\\',
        "      -base_mass 55.1 -use_lin_jog \"ROB1\"", "#", "SINGLE:", "",
        '      -name "STN1" -use_single_type "STN1" -use_joint "STN1"\\',
        "      -base_frame_pos_x 1.85 -base_frame_orient_u0 6.12323E-17\\",
        "      -base_frame_orient_u3 1", ""])
    setup = read_abb_external(moc, ABB7)
    (k,) = setup.kinematics
    assert (k.name, k.kind) == ("STN1", "turntable")
    assert same_pose(k.root, Pose(1850, 0, 0, 180, 0, 0), 1e-9, 1e-6)
    assert [b.number for b in setup.bases] == [3] and setup.bases[0].mech_unit == "STN1"
    same = abb_mechanical_units([k], setup.bases, moc_template=moc, rapid_template=ABB7)
    assert same.moc_cfg == moc and same.rapid == ABB7
    moved = replace(k, root=Pose.from_matrix(k.root.as_matrix() @ Pose(0, 0, 12.5, 0, 0, 0)
                                             .as_matrix()))
    base = replace(setup.bases[0], pose=replace(setup.bases[0].pose, z=450.0))
    text = abb_mechanical_units([moved], [base], moc_template=moc, rapid_template=ABB7)
    diff = changed_lines(moc, text.moc_cfg)
    assert diff == ["      -base_frame_orient_u3 1", "      -base_frame_orient_u3 1\\",
                    "      -base_frame_pos_z 0.0125"]
    back = read_abb_external(text.moc_cfg, text.rapid)
    assert same_chain(back.kinematics[0], moved, 1e-6)
    assert same_pose(back.bases[0].pose, base.pose)
    assert len(changed_lines(ABB7, text.rapid)) == 2  # the wTurntable line, before and after
    with pytest.raises(FormatError) as err:
        abb_mechanical_units([replace(k, name="STN2")], [], moc_template=moc)
    assert err.value.loc == ("moc_template", "SINGLE STN2")


def test_kuka_reads_the_kl1500_frames_of_a_real_machine_dat():
    """The linear-unit frames of a KR C2 on a KL1500 as a robot-forum.com post quotes its
    $machine.dat (thread 35176, with the file's German comments): TA1KR turns z (the travel)
    horizontal 450 mm above the root, TFLA3 turns the robot upright again."""
    machine = "\n".join([
        "DECL EX_KIN $EX_KIN={ET1 #ERSYS,ET2 #NONE,ET3 #NONE,ET4 #NONE,ET5 #NONE,ET6 #NONE}",
        "DECL ET_AX $ET1_AX={TR_A1 #E1,TR_A2 #NONE,TR_A3 #NONE}", '$ET1_NAME[]="KL1500_1"',
        "FRAME $ET1_TA1KR={X 0.0,Y 0.0,Z 450.0,A 0.0,B 0.0,C 90.0} ;FRAME ZWISCHEN A1 UND "
        "FUSSPUNKT DER KIN IN TRAFO ET1",
        "FRAME $ET1_TA2A1={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0} ;ZWISCHEN A2 UND A1",
        "FRAME $ET1_TA3A2={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0} ;ZWISCHEN A3 UND A2",
        "FRAME $ET1_TFLA3={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C -90.0} ;ZWISCHEN FL UND A3",
        "FRAME $ERSYSROOT={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}", ""])
    (k,) = read_kuka_external(machine).kinematics
    assert (k.kind, k.name, k.axes) == ("linear_unit", "KL1500_1", ("E1",))
    for e in (0.0, 1000.0, 2750.0):
        T = flange_matrix(k, [e])
        assert np.allclose(T[:3, :3], np.eye(3), atol=1e-12)  # the robot stays upright
        assert np.allclose(T[:3, 3], [0.0, -e, 450.0], atol=1e-9)  # along the rail, 450 up


# --------------------------------------------------------------------------- from the solvers


def test_positioner_from_its_solver_predicts_the_mark_after_the_round_trip():
    """A simulated tilt-and-turn positioner whose axes miss each other by 3 mm: the solver's
    tilt root and T_tiltflange_turnroot, written to $machine.dat / $config.dat and read
    back, put a mark on the table where the positioner really carries it at new axis values."""
    pos = make_positioner(axis_offset_mm=3.0, turn_tilt_deg=0.5)
    mark = np.array([180.0, 60.0, 0.0])
    tilt_values, turn_values = np.array([-60.0, -20.0, 20.0, 60.0]), np.array([0, 90, 180, 270.0])
    tilt = pos.mark(mark, tilt_values, np.zeros(4))
    turn = pos.mark(mark, np.full(4, 20.0), turn_values)
    res = solve_positioner(tilt, tilt_values, turn, turn_values, 20.0)
    kin = positioner_2axis(1, "DKP_400_1", res.report.extras["tilt_root"], res.frame)
    text = kuka_external_kinematics([kin])
    back = read_kuka_external(text.machine_dat, text.config_dat).kinematics[0]
    mark_in_flange = invert(flange_matrix(back, [20.0, 0.0])) @ np.r_[turn[0], 1.0]
    for t, th in ((-45.0, 30.0), (10.0, -120.0), (55.0, 200.0)):
        want = pos.mark(mark, np.array([t]), np.array([th]))[0]
        assert np.allclose((flange_matrix(back, [t, th]) @ mark_in_flange)[:3], want, atol=1e-6)


def test_linear_unit_from_its_solver_carries_the_robot_along_the_rail():
    """A simulated rail tilted 1 deg: ext.linear_unit's T_base_rail through $machine.dat
    and back moves the robot base so that the fixed mark appears where the rail shows it."""
    rail = make_linear_unit(direction_tilt_deg=1.0)
    mark = np.array([1500.0, 400.0, 200.0])
    values = np.array([0.0, 400.0, 800.0, 1200.0, 1600.0])
    res = solve_linear_unit(rail.mark_in_base(mark, values), values)
    kin = linear_unit(1, "KL1500", res.frame)
    back = read_kuka_external(kuka_external_kinematics([kin]).machine_dat).kinematics[0]
    for e in (250.0, 1000.0, 2000.0):
        seen = invert(flange_matrix(back, [e])) @ np.r_[rail.mark_in_base(mark, [0.0])[0], 1.0]
        assert np.allclose(seen[:3], rail.mark_in_base(mark, [e])[0], atol=1e-6)


@settings(max_examples=150, deadline=None)
@given(kname=st.text(min_size=1, max_size=32).filter(
           lambda s: s.strip() and not any(unprintable(c) for c in s)),
       bname=st.text(max_size=64))
@example(kname='"', bname="\n")  # nothing of the name is left: KUKA writes ET1
def test_any_name_keeps_every_line_and_reads_back(kname: str, bname: str):
    """Whatever the names (any Unicode, quotes, braces, ``;``, ``-attr``, line breaks in a
    base's name): the texts have the lines of plain names, and each reads back with the
    base still on its kinematic."""
    kin = turntable(1, kname, Pose(1000, 0, 0, 0, 0, 0))
    base = FrameEntry(5, bname, "coordinated_base", Pose(1, 2, 3, 0, 0, 0), None, kname)
    plain = (kuka_external_kinematics([turntable(1, "T", Pose())],
                                      [FrameEntry(5, "b", "coordinated_base", Pose(), None, "T")]),
             abb_mechanical_units([turntable(1, "T", Pose())],
                                  [FrameEntry(5, "b", "coordinated_base", Pose(), None, "T")]))
    k, a = kuka_external_kinematics([kin], [base]), abb_mechanical_units([kin], [base])
    for got, want in zip((k.machine_dat, k.config_dat, a.moc_cfg, a.rapid),
                         (plain[0].machine_dat, plain[0].config_dat, plain[1].moc_cfg,
                          plain[1].rapid)):
        # a long name may continue a MOC.cfg instance on the next line ("\\"), nothing else
        assert len(got.replace("\\\n", " ").splitlines()) == \
            len(want.replace("\\\n", " ").splitlines())
    kk = read_kuka_external(k.machine_dat, k.config_dat)
    assert kk.bases[0].mech_unit == kk.kinematics[0].name == (kuka_machine_name(kname) or "ET1")
    aa = read_abb_external(a.moc_cfg, a.rapid)
    assert aa.bases[0].mech_unit == aa.kinematics[0].name
