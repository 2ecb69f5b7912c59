"""ABB external kinematics: ``MOC.cfg`` base frames of the mechanical units' singles and of the
robot on a track (``-base_frame_pos_x`` .. ``-base_frame_orient_u3``,
``-base_frame_coordinated``), the coordinated ``wobjdata`` in a RAPID module; fragments or the
controller's own files patched.

The chain and the model: :mod:`server.formats.external.model`; sources: docs/formats.md.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from typing import Iterable

import numpy as np

from server.service.bounds import check_value
from server.formats.abb import _quat, export_abb, rapid_name, read_abb
from server.formats.external.model import (ExternalKinematic, ExternalSetup, _check_setup,
                                           _pose, positioner_2axis, turntable)
from server.formats.model import FormatError, FrameEntry, family_of
from solvers.errors import CalibrationError
from solvers.frames import Pose, angle_between_deg, matrix_from_abb
from solvers.validate import FloatArray

__all__ = ["AbbExternalText", "abb_mechanical_units", "read_abb_external", "abb_unit_name"]


@dataclass(frozen=True)
class AbbExternalText:
    """The ABB texts: a ``MOC.cfg`` fragment (base frames of the mechanical units' singles
    and of the robot) and a RAPID module with the coordinated work objects."""

    moc_cfg: str
    rapid: str


_MOC_ATTRS = ("base_frame_pos_x", "base_frame_pos_y", "base_frame_pos_z",
              "base_frame_orient_u0", "base_frame_orient_u1", "base_frame_orient_u2",
              "base_frame_orient_u3")
_MOC_DEFAULT = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
QUAT_NORM_TOL = 1e-3


def abb_unit_name(k: ExternalKinematic, taken: set[str] | None = None) -> str:
    """The mechanical unit's name in ABB files: a RAPID identifier (letters, digits, ``_``,
    a letter first, at most 32) made from ``k.name`` (:func:`~server.formats.abb.rapid_name`).

    Examples
    --------
    >>> abb_unit_name(turntable(1, 'STN 1" -use_joint', Pose()))
    'STN_1_use_joint'
    """
    return rapid_name(k.name, "coordinated_base", k.number, set() if taken is None else taken)


def _moc_num(v: float) -> str:
    """A MOC number with the shortest exact digits (``1.5``, ``-4.35114E-05``)."""
    s = repr(float(v) + 0.0)
    return s.upper() if "e" in s else s.removesuffix(".0") if s.endswith(".0") else s


def _moc_base_frame(T: FloatArray) -> list[tuple[str, str]]:
    """``(attribute, value)`` of ``base_frame_pos_x .. base_frame_orient_u3`` of ``T``
    (metres; u0 the scalar)."""
    q = _quat(T)
    values = [*(T[:3, 3] / 1000.0), *q]
    return [(a, _moc_num(v)) for a, v in zip(_MOC_ATTRS, values)]


def _moc_instance(parts: list[str]) -> list[str]:
    """One instance, 6 spaces in, continued with ``\\`` within 80 columns, as RobotWare
    writes MOC.cfg."""
    lines, cur = [], "      "
    for p in parts:
        if len(cur) + len(p) + 1 > 79 and cur.strip():
            lines.append(cur.rstrip() + "\\")
            cur = "      "
        cur += ("" if not cur.strip() else " ") + p
    lines.append(cur.rstrip())
    return lines


def abb_mechanical_units(kinematics: Iterable[ExternalKinematic],
                         bases: Iterable[FrameEntry] = (), robot: str = "ROB_1",
                         module_name: str = "ExtUnits", *, moc_template: str | None = None,
                         rapid_template: str | None = None) -> AbbExternalText:
    """ABB ``MOC.cfg`` base frames of the external kinematics and the work objects on them.

    Per kinematic (name ``u`` = :func:`abb_unit_name`):

    - ``MECHANICAL_UNIT``: ``-name "u" -use_single_0 "u"`` (a positioner ``"u_1"``,
      ``-use_single_1 "u_2"``);
    - ``SINGLE``: ``-name "u"`` with ``-base_frame_pos_x/y/z`` (metres) and
      ``-base_frame_orient_u0..u3`` (quaternion, u0 the scalar): the frame of the axis in
      world (``root @ F_1``); the positioner's turn single ``"u_2"`` has
      ``-base_frame_coordinated "u_1"`` and its frame ``F_2`` in the tilt's moving frame;
    - a linear unit: ``ROBOT -name "ROB_1" -base_frame_coordinated "u"`` with the robot's
      base frame on the carriage (``flange``).

    The work objects are ``wobjdata`` with ``ufprog FALSE`` and ``ufmec "u"`` whose
    ``uframe`` is in the unit's moving frame: ``flange @ T_flange_base``
    (:func:`~server.formats.abb.export_abb`). Quaternions are those ``export_abb`` writes
    for the same rotation.

    Parameters
    ----------
    kinematics, bases
        As :func:`kuka_external_kinematics`.
    robot : str
        The ``ROBOT`` instance a linear unit carries.
    module_name : str
        The RAPID module of a fresh export.
    moc_template, rapid_template : str, optional, keyword-only
        The controller's whole ``MOC.cfg`` / RAPID module imported before: the base-frame
        attributes of its ``ROBOT`` and ``SINGLE`` instances are patched in place (a position
        that moved by more than 1e-9 mm, the quaternion when the rotation turned by more than
        1e-9 deg; an attribute RobotWare left out is added on a continuation line unless its
        default holds); the work objects go through
        :func:`~server.formats.abb.export_abb` with the template. With no change both come
        back byte for byte.

    Raises
    ------
    FormatError
        As :func:`kuka_external_kinematics`; ``("robot",)`` for a robot name that is no
        identifier; ``("moc_template", "SINGLE <name>")`` when the template lacks the
        instance (the units themselves are the controller's configuration).

    Examples
    --------
    >>> t = abb_mechanical_units([turntable(1, "STN1", Pose(1500, 0, 300, 90, 0, 0))])
    >>> print(t.moc_cfg)
    MOC:CFG_1.0:6:0::
    #
    MECHANICAL_UNIT:
    <BLANKLINE>
          -name "STN1" -use_single_0 "STN1"
    #
    SINGLE:
    <BLANKLINE>
          -name "STN1" -base_frame_pos_x 1.5 -base_frame_pos_y 0\\
          -base_frame_pos_z 0.3 -base_frame_orient_u0 0.707106781186548\\
          -base_frame_orient_u1 0 -base_frame_orient_u2 0\\
          -base_frame_orient_u3 0.707106781186548
    <BLANKLINE>
    """
    if not isinstance(robot, str) or not re.fullmatch(r"[A-Za-z]\w{0,31}", robot):
        raise FormatError(("robot",), f"must be an identifier, got {robot!r}")
    taken: set[str] = {robot.upper()}
    unit_names: dict[str, str] = {}

    def written(k: ExternalKinematic) -> str:
        if k.name not in unit_names:
            unit_names[k.name] = abb_unit_name(k, taken)
        return unit_names[k.name]

    kins, base_list, by_name = _check_setup(kinematics, bases, written)
    insts = _moc_items(kins, unit_names, robot)
    if moc_template is None:
        lines = ["MOC:CFG_1.0:6:0::"]
        for typ in ("MECHANICAL_UNIT", "ROBOT", "SINGLE"):
            chosen = [attrs for t, attrs in insts if t == typ]
            if chosen:
                lines += ["#", f"{typ}:"]
                for attrs in chosen:
                    lines += ["", *_moc_instance([f"-{a} {v}" for a, v in attrs])]
        moc = "\n".join(lines) + "\n"
    else:
        moc = _patch_moc(moc_template, insts)
    wobjs = []
    for b in base_list:
        k = by_name[b.mech_unit]  # type: ignore[index]
        pose = b.pose if k.flange == Pose() else _pose(k.flange.as_matrix() @ b.pose.as_matrix())
        wobjs.append(replace(b, pose=pose, mech_unit=unit_names[k.name]))
    if rapid_template is None:
        rapid = export_abb(wobjs, module_name=module_name)
    else:
        units = {u.upper() for u in unit_names.values()}
        slots = {b.number for b in wobjs}
        keep = [e for e in read_abb(rapid_template).entries
                if not (e.kind == "coordinated_base" and (e.mech_unit or "").upper() in units)
                and not (family_of(e.kind) == "stationary" and e.number in slots)]
        rapid = export_abb(keep + wobjs, template=rapid_template)
    return AbbExternalText(moc, rapid)


def _moc_items(kins: list[ExternalKinematic], unit_names: dict[str, str],
               robot: str) -> list[tuple[str, list[tuple[str, str]]]]:
    """``(TYPE, [(attribute, value)])`` of every instance the kinematics need."""
    out: list[tuple[str, list[tuple[str, str]]]] = []
    for k in kins:
        u = unit_names[k.name]
        first = k.root.as_matrix() @ k.axis_frames[0].as_matrix()
        if k.kind == "positioner_2axis":
            s1, s2 = f"{u}_1", f"{u}_2"
            out.append(("MECHANICAL_UNIT", [("name", f'"{u}"'), ("use_single_0", f'"{s1}"'),
                                            ("use_single_1", f'"{s2}"')]))
            out.append(("SINGLE", [("name", f'"{s1}"'), *_moc_base_frame(first)]))
            out.append(("SINGLE", [("name", f'"{s2}"'),
                                   *_moc_base_frame(k.axis_frames[1].as_matrix()),
                                   ("base_frame_coordinated", f'"{s1}"')]))
        else:
            out.append(("MECHANICAL_UNIT", [("name", f'"{u}"'), ("use_single_0", f'"{u}"')]))
            out.append(("SINGLE", [("name", f'"{u}"'), *_moc_base_frame(first)]))
        if k.linear:
            out.append(("ROBOT", [("name", f'"{robot}"'), *_moc_base_frame(k.flange.as_matrix()),
                                  ("base_frame_coordinated", f'"{u}"')]))
    return out


def _same_moc_value(old: object, new: str) -> bool:
    if new.startswith('"'):
        return old == new[1:-1]
    try:
        return float(old) == float(new)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False


def _same_frame_attrs(inst: _MocInst, want: dict[str, str], name: str) -> set[str]:
    """The base-frame attributes of ``inst`` that need no rewrite: each position within 1e-9
    mm of the wanted one, the four quaternion values when the rotation is within 1e-9 deg
    (a value read and written back differs only in float dust, 6.12323E-17 for 0)."""
    if not all(a in want for a in _MOC_ATTRS):
        return set()
    old = _moc_frame(inst.attrs, inst.line, name)
    new = matrix_from_abb([float(want[a]) * 1000.0 for a in _MOC_ATTRS[:3]],
                          [float(want[a]) for a in _MOC_ATTRS[3:]])
    same = {a for a, o, n in zip(_MOC_ATTRS[:3], old[:3, 3], new[:3, 3]) if abs(o - n) <= 1e-9}
    if float(angle_between_deg(old[:3, :3], new[:3, :3])) <= 1e-9:
        same |= set(_MOC_ATTRS[3:])
    return same


def _patch_moc(template: str, insts: list[tuple[str, list[tuple[str, str]]]]) -> str:
    """``template`` (a whole MOC.cfg) with the base-frame attributes of its ``ROBOT`` and
    ``SINGLE`` instances patched: a value that changed is rewritten in place, one the file
    lacks (RobotWare leaves defaults out) is added on a continuation line of its instance
    unless the default holds; every other byte kept. The mechanical units themselves are
    the controller's configuration: a ``SINGLE`` or ``ROBOT`` the file lacks is refused."""
    crlf = template.count("\r\n") > template.count("\n") / 2
    text = _lf(template)
    scanned = {(i.typ, str(i.attrs.get("name", "")).upper()): i for i in _moc_scan(text)}
    defaults = dict(zip(_MOC_ATTRS, _MOC_DEFAULT))
    edits: list[tuple[int, int, str]] = []
    for typ, attrs in insts:
        if typ == "MECHANICAL_UNIT":
            continue
        name = attrs[0][1][1:-1]
        inst = scanned.get((typ, name.upper()))
        if inst is None:
            raise FormatError(("moc_template", f"{typ} {name}"),
                              f'the MOC.cfg has no {typ} -name "{name}": configure the unit '
                              "on the controller (or name the kinematic like its unit)")
        add = []
        same = _same_frame_attrs(inst, dict(attrs[1:]), name)
        for a, v in attrs[1:]:
            if a in same:
                continue
            if a in inst.spans:
                if not _same_moc_value(inst.attrs[a], v):
                    edits.append((*inst.spans[a], v))
            elif a not in inst.attrs and not (a in defaults and float(v) == defaults[a]):
                add.append(f"-{a} {v}")
        if add:
            edits.append((inst.end, inst.end, "\\\n" + "\n".join(_moc_instance(add))))
    out = text
    for start, end, repl in sorted(edits, reverse=True):
        out = out[:start] + repl + out[end:]
    return out.replace("\n", "\r\n") if crlf else out


@dataclass
class _MocInst:
    """One MOC.cfg instance: its type, first line, attributes (a flag without a value is
    True), the offsets of each value in the text and the offset where its last line ends."""

    typ: str
    line: int
    attrs: dict[str, object]
    spans: dict[str, tuple[int, int]]
    end: int


_MOC_TOKEN = re.compile(r'\s*-(\w+)(?:\s+("[^"]*"|[^\s"-][^\s"]*|-[\d.][^\s"]*))?')


def _moc_scan(text: str) -> list[_MocInst]:
    """Every instance of a MOC.cfg (LF line ends), joined across ``\\`` continuations."""
    if not isinstance(text, str):
        raise FormatError(("moc_cfg",), f"expected text, got {type(text).__name__}")
    out: list[_MocInst] = []
    typ: str | None = None
    joined, offs, start = "", [], 0  # offs: offset in text of each joined character
    pos = 0
    for number, raw in enumerate(text.split("\n"), 1):
        line_at, pos = pos, pos + len(raw) + 1
        s = raw.strip()
        if not joined and (not s or s.startswith("#") or re.fullmatch(r"\w+:CFG_[\d.]+:.*", s)):
            typ = None if s.startswith("#") else typ
            continue
        m = re.fullmatch(r"([A-Z][A-Z0-9_]*):", s)
        if not joined and m:
            typ = m.group(1)
            continue
        if not joined:
            start = number
        body = raw.rstrip()
        more = body.endswith("\\")
        body = body[:-1] if more else body
        joined += body + " "
        offs += [line_at + i for i in range(len(body))] + [-1]
        if more:
            continue
        if typ is not None:
            out.append(_moc_parse(joined, offs, typ, start, line_at + len(raw.rstrip())))
        joined, offs = "", []
    if joined.strip():
        raise FormatError(("moc_cfg", f"line {start}"), "an instance ends with '\\' at the "
                          "end of the file: the file was cut short")
    return out


def _moc_parse(joined: str, offs: list[int], typ: str, line: int, end: int) -> _MocInst:
    attrs: dict[str, object] = {}
    spans: dict[str, tuple[int, int]] = {}
    pos = 0
    while pos < len(joined.rstrip()):
        m = _MOC_TOKEN.match(joined, pos)
        if not m:
            raise FormatError(("moc_cfg", f"line {line}"),
                              f"cannot read {joined[pos:].strip()[:40]!r}")
        key, val = m.group(1), m.group(2)
        attrs[key] = True if val is None else val[1:-1] if val.startswith('"') else val
        if val is not None and -1 not in offs[m.start(2):m.end(2)]:
            spans[key] = (offs[m.start(2)], offs[m.end(2) - 1] + 1)
        pos = m.end()
    return _MocInst(typ, line, attrs, spans, end)


def _moc_instances(text: str) -> dict[str, list[tuple[dict[str, object], int]]]:
    """``TYPE -> [(attributes, line)]`` of a MOC.cfg (any line ends)."""
    out: dict[str, list[tuple[dict[str, object], int]]] = {}
    for inst in _moc_scan(_lf(text)):
        out.setdefault(inst.typ, []).append((inst.attrs, inst.line))
    return out


def _lf(text: object) -> object:
    return text.replace("\r\n", "\n").replace("\r", "\n") if isinstance(text, str) else text


def _moc_frame(attrs: dict[str, object], line: int, name: str) -> FloatArray:
    """``T`` (mm) of an instance's base frame; absent attributes take their defaults."""
    v = []
    for a, default in zip(_MOC_ATTRS, _MOC_DEFAULT):
        raw = attrs.get(a, default)
        try:
            x = float(raw)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise FormatError(("moc_cfg", f"line {line}", f"{name}.{a}"),
                              f"expected a number, got {raw!r}") from None
        v.append(x)
    pos = np.array(v[:3]) * 1000.0
    for a, x in zip("xyz", pos):
        try:
            check_value(float(x), "mm", (a,))
        except CalibrationError as err:
            raise FormatError(("moc_cfg", f"line {line}", f"{name}.base_frame_pos_{a}"),
                              err.reason) from None
    q = np.array(v[3:])
    norm = float(np.linalg.norm(q))
    if not math.isfinite(norm) or abs(norm - 1.0) > QUAT_NORM_TOL:
        raise FormatError(("moc_cfg", f"line {line}", f"{name}.base_frame_orient"),
                          f"the quaternion u0..u3 has length {norm:.6g}; expected 1")
    return matrix_from_abb(pos, q)


def read_abb_external(moc_cfg: str, rapid: str | None = None,
                      robot: str = "ROB_1") -> ExternalSetup:
    """The external kinematics of a ``MOC.cfg`` (whole or the fragment
    :func:`abb_mechanical_units` writes) and the coordinated work objects of a RAPID module.

    Every ``MECHANICAL_UNIT`` with ``-use_single_0`` (and ``-use_single_1``) is a kinematic,
    numbered in file order, its axes E1, E2, ... in that order: a unit whose single the
    ``ROBOT`` ``robot`` names in ``-base_frame_coordinated`` is the linear unit carrying the
    robot (flange = the robot's base frame), two singles make a positioner (the second's
    base frame in the first's moving frame), one a turntable. A single's base frame is its
    axis frame in world (root), the axis frames read back as identity except the turn axis'.
    Attributes a file leaves out take their defaults (position 0, quaternion [1, 0, 0, 0]).
    Work objects: the ``coordinated_base`` entries of :func:`~server.formats.abb.read_abb`
    whose ``ufmec`` is one of these units.

    Raises
    ------
    FormatError
        ``("moc_cfg", "line N", "<instance>.<attribute>")``: a number that is not one, a
        position beyond the bounds, a quaternion far from unit length, a unit naming a
        single the file does not have, more than two singles; the RAPID module's own errors.

    Examples
    --------
    >>> k = turntable(1, "STN1", Pose(1500, 0, 300, 90, 0, 0))
    >>> t = abb_mechanical_units([k])
    >>> back = read_abb_external(t.moc_cfg).kinematics[0]
    >>> from server.formats.external import flange_matrix
    >>> bool(np.allclose(flange_matrix(back, [30]), flange_matrix(k, [30]), atol=1e-9))
    True
    """
    inst = _moc_instances(moc_cfg)
    singles = {str(a.get("name", "")): (a, line) for a, line in inst.get("SINGLE", [])}
    robot_attrs = next(((a, line) for a, line in inst.get("ROBOT", [])
                        if str(a.get("name", "")).upper() == robot.upper()), None)
    kins: list[ExternalKinematic] = []
    axis_no = 1
    for attrs, line in inst.get("MECHANICAL_UNIT", []):
        name = str(attrs.get("name", ""))
        used = [str(attrs[f"use_single_{i}"]) for i in range(6) if f"use_single_{i}" in attrs]
        if not used:
            continue  # a robot's unit: no singles
        if len(used) > 2:
            raise FormatError(("moc_cfg", f"line {line}", f"{name}.use_single_2"),
                              "more than two singles: only turntables, two-axis positioners "
                              "and linear units are supported")
        for s in used:
            if s not in singles:
                raise FormatError(("moc_cfg", f"line {line}", f"{name}.use_single"),
                                  f"names the single {s!r}, which the file does not define")
        a1, l1 = singles[used[0]]
        T1 = _moc_frame(a1, l1, used[0])
        moved_by = [str(singles[u][0].get("base_frame_coordinated", "")) for u in used]
        if moved_by[0].strip() or (len(used) == 2 and moved_by[1] != used[0]):
            i = 0 if moved_by[0].strip() else 1
            raise FormatError(("moc_cfg", f"line {singles[used[i]][1]}",
                               f"{used[i]}.base_frame_coordinated"),
                              f"is {moved_by[i]!r}: supported are a unit on the floor and, in a "
                              f"two-axis positioner, its second single moved by the first "
                              f"({used[0]!r})")
        axes = tuple(f"E{axis_no + i}" for i in range(len(used)))
        axis_no += len(used)
        number = len(kins) + 1
        try:
            if len(used) == 2:
                a2, l2 = singles[used[1]]
                T2 = _moc_frame(a2, l2, used[1])
                kins.append(positioner_2axis(number, name, _pose(T1), _pose(T2), axes))
            elif robot_attrs is not None and \
                    str(robot_attrs[0].get("base_frame_coordinated", "")) == used[0]:
                Tr = _moc_frame(robot_attrs[0], robot_attrs[1], robot)
                kins.append(ExternalKinematic(number, name, "linear_unit", _pose(T1), (Pose(),),
                                              _pose(Tr), axes))
            else:
                kins.append(turntable(number, name, _pose(T1), axes[0]))
        except CalibrationError as err:
            raise FormatError(("moc_cfg", f"line {line}", f"{name}.{err.loc[0]}"),
                              err.reason) from None
    bases: list[FrameEntry] = []
    if rapid is not None:
        units = {k.name: k for k in kins if not k.linear}
        bases = [e for e in read_abb(rapid).entries
                 if e.kind == "coordinated_base" and e.mech_unit in units]
    return ExternalSetup(kins, bases)
