"""External kinematics in controller files: KUKA ``$ETn_...`` machine data with ``MACHINE_DEF``
and the bases on it, ABB ``MOC.cfg`` base frames with the coordinated work objects.

An :class:`ExternalKinematic` is a turntable (one rotary axis), a two-axis positioner (tilt,
then turn) or a linear unit carrying the robot (one linear axis), as the KUKA machine data
describe it: a chain of frames from the kinematic's root to its flange,

.. code-block:: text

    T_world_flange(q) = root @ F_1 @ J_1(q_1) [@ F_2 @ J_2(q_2)] @ flange

with ``J_k = Rz(q_k)`` (deg) for a rotary axis and ``J_k = Tz(q_k)`` (mm) for a linear one:
**z of each axis frame is the axis of revolution or translation**. ``root`` is the kinematic's
root in world (KUKA ``MACHINE_DEF[k].ROOT`` of a base kinematic, ``$ERSYSROOT`` of a linear
unit); ``axis_frames`` are ``$ETn_TA1KR``, ``$ETn_TA2A1`` (each axis' frame in the previous
axis' moving frame); ``flange`` is ``$ETn_TFLA3``. In this service world = the robot base
(for a linear unit: the robot base at rail value 0), so a root point of
:func:`solvers.external.root_point` (``T_base_flange(θ) = T_base_root @ Rz(θ)``) is
``root = T_base_root`` with identity axis frame and flange (:func:`turntable`).

Bases on a kinematic are :class:`~server.formats.model.FrameEntry` of kind
``coordinated_base`` whose ``mech_unit`` is the kinematic's name and whose pose is
``T_flange_base`` (KUKA ``BASE_DATA[n]`` with ``MACHINE_FRAME_DAT[n]`` naming the machine;
ABB ``wobjdata`` with ``ufprog FALSE``, ``ufmec`` the unit).

Pure functions, text in and dataclasses out; which names and layouts were checked against
public sources is in docs/formats.md ("External kinematics").
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from typing import Iterable, Literal, get_args

import numpy as np

from server.bounds import MECH_UNIT_CHARS, check_name, check_value
from server.formats import kuka as _kuka
from server.formats.abb import _quat, export_abb, rapid_name, read_abb
from server.formats.model import FormatError, FrameEntry, family_of, one_line
from solvers.errors import CalibrationError
from solvers.external.common import rz
from solvers.frames import Pose, angle_between_deg, invert, matrix_from_abb, translation
from solvers.validate import FloatArray

__all__ = [
    "ExternalKinematic", "ExternalSetup", "KukaExternalText", "AbbExternalText", "KINDS",
    "turntable", "positioner_2axis", "linear_unit", "flange_matrix",
    "kuka_external_kinematics", "read_kuka_external",
    "abb_mechanical_units", "read_abb_external",
]

ExternalKind = Literal["turntable", "positioner_2axis", "linear_unit"]
KINDS: tuple[str, ...] = get_args(ExternalKind)
AXIS_COUNT = {"turntable": 1, "positioner_2axis": 2, "linear_unit": 1}
MAX_KINEMATICS = 6  # KUKA ET1..ET6 ($EX_KIN has six entries)
KUKA_ET_NAME_CHARS = 20  # $ETn_NAME[] (width not verified; see docs/formats.md)
_AXIS = re.compile(r"E([1-6])")


# --------------------------------------------------------------------------- model


def _check_pose(p: object, loc: tuple[str | int, ...]) -> Pose:
    if not isinstance(p, Pose):
        raise CalibrationError(loc, f"must be a Pose, got {type(p).__name__}")
    for k, x in zip("xyzabc", p.as_array()):
        check_value(float(x), "mm" if k in "xyz" else "deg", (*loc, k))
    return p


@dataclass(frozen=True)
class ExternalKinematic:
    """One external kinematic: its number, name, kind, axes and frame chain (mm, deg).

    Parameters
    ----------
    number : int
        1..6: KUKA ``ETn``; ABB numbers the units in file order.
    name : str
        KUKA ``$ETn_NAME[]`` and ``MACHINE_DEF[k].NAME[]``; ABB the mechanical unit
        (``ufmec``). At most 32 characters, none that breaks a line.
    kind : {"turntable", "positioner_2axis", "linear_unit"}
    root : Pose
        ``T_world_root``: the kinematic's root in world (= robot base here).
    axis_frames : tuple of Pose
        One per axis: axis k's frame in the previous axis' moving frame (the first in the
        root), z = the axis; KUKA ``$ETn_TA1KR``, ``$ETn_TA2A1``.
    flange : Pose
        The flange in the last axis' moving frame (KUKA ``$ETn_TFLA3``); for a linear unit
        the robot base on the carriage.
    axes : tuple of str
        The external axes in chain order, ``"E1"`` .. ``"E6"``.

    Examples
    --------
    >>> k = turntable(1, "TABLE", Pose(1500, 0, 300, 0, 0, 0))
    >>> k.kind, k.axes, flange_matrix(k, [90])[:3, 0].round(6).tolist()
    ('turntable', ('E1',), [0.0, 1.0, 0.0])
    """

    number: int
    name: str
    kind: ExternalKind
    root: Pose
    axis_frames: tuple[Pose, ...]
    flange: Pose = Pose()
    axes: tuple[str, ...] = ("E1",)

    def __post_init__(self) -> None:
        if isinstance(self.number, bool) or not isinstance(self.number, int) \
                or not 1 <= self.number <= MAX_KINEMATICS:
            raise CalibrationError(("number",), f"must be an integer 1..{MAX_KINEMATICS}, "
                                   f"got {self.number!r}")
        if self.kind not in KINDS:
            raise CalibrationError(("kind",), f"must be one of {', '.join(KINDS)}, "
                                   f"got {self.kind!r}")
        if not isinstance(self.name, str) or not self.name.strip():
            raise CalibrationError(("name",), "must be a non-blank text")
        check_name(self.name, ("name",), MECH_UNIT_CHARS)
        axes, frames = tuple(self.axes), tuple(self.axis_frames)
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "axis_frames", frames)
        want = AXIS_COUNT[self.kind]
        if len(axes) != want:
            raise CalibrationError(("axes",), f"a {self.kind} has {want} axis"
                                   f"{'es' if want > 1 else ''}, got {len(axes)}")
        for i, a in enumerate(axes):
            if not isinstance(a, str) or not _AXIS.fullmatch(a):
                raise CalibrationError(("axes", i), f"must be E1..E6, got {a!r}")
        if len(set(axes)) != len(axes):
            raise CalibrationError(("axes",), f"an axis is named twice: {', '.join(axes)}")
        if len(frames) != want:
            raise CalibrationError(("axis_frames",), f"one frame per axis: {want}, "
                                   f"got {len(frames)}")
        _check_pose(self.root, ("root",))
        _check_pose(self.flange, ("flange",))
        for i, p in enumerate(frames):
            _check_pose(p, ("axis_frames", i))

    @property
    def linear(self) -> bool:
        """True for a linear unit (its axis translates along z), False for rotary axes."""
        return self.kind == "linear_unit"


def flange_matrix(kin: ExternalKinematic, values: object) -> FloatArray:
    """``T_world_flange`` of ``kin`` at axis values ``values`` (deg, or mm for a linear unit).

    ``root @ F_1 @ J(q_1) [@ F_2 @ J(q_2)] @ flange`` with ``J = Rz(q)`` (rotary, through
    SciPy's ``Rotation``) or ``J = Tz(q)`` (linear).

    Examples
    --------
    >>> k = turntable(1, "T", Pose(1000, 0, 0, 0, 0, 0))
    >>> flange_matrix(k, [30.0])[:3, 3].tolist()
    [1000.0, 0.0, 0.0]
    """
    q = np.atleast_1d(np.asarray(values, dtype=float))
    if q.shape != (len(kin.axes),) or not np.all(np.isfinite(q)):
        raise CalibrationError(("values",), f"expected {len(kin.axes)} finite axis value(s), "
                               f"got {q.tolist()}")
    T = kin.root.as_matrix()
    for F, v in zip(kin.axis_frames, q):
        J = translation([0.0, 0.0, v]) if kin.linear else rz([v])[0]
        T = T @ F.as_matrix() @ J
    return T @ kin.flange.as_matrix()


def _pose(T: FloatArray) -> Pose:
    return Pose.from_matrix(T, decimals=12)


def turntable(number: int, name: str, root_frame: Pose | FloatArray, axis: str = "E1",
              flange: Pose = Pose()) -> ExternalKinematic:
    """A turntable from a root point: ``root = T_base_root`` (``ext.root_point`` /
    ``ext.root_point_numeric``), identity axis frame, so ``T_base_flange(θ) = T_base_root @
    Rz(θ) @ flange``.

    Examples
    --------
    >>> turntable(2, "TABLE", Pose(0, 1500, 0, 90, 0, 0), "E2").axis_frames
    (Pose(x=0.0, y=0.0, z=0.0, a=0.0, b=0.0, c=0.0),)
    """
    root = root_frame if isinstance(root_frame, Pose) else _pose(np.asarray(root_frame))
    return ExternalKinematic(number, name, "turntable", root, (Pose(),), flange, (axis,))


def positioner_2axis(number: int, name: str, tilt_root: Pose | FloatArray,
                     tilt_to_turn: Pose | FloatArray, axes: tuple[str, str] = ("E1", "E2"),
                     flange: Pose = Pose()) -> ExternalKinematic:
    """A tilt-and-turn positioner from ``ext.positioner_2axis``: ``root = T_base_tiltroot``
    (``extras["tilt_root"]``), ``$ETn_TA1KR`` identity, ``$ETn_TA2A1 = T_tiltflange_turnroot``
    (the result's ``frame``), so ``T_base_flange(τ, θ) = T_base_tiltroot Rz(τ)
    T_tiltflange_turnroot Rz(θ) flange``.
    """
    as_pose = (lambda p: p if isinstance(p, Pose) else _pose(np.asarray(p)))
    return ExternalKinematic(number, name, "positioner_2axis", as_pose(tilt_root),
                             (Pose(), as_pose(tilt_to_turn)), flange, tuple(axes))


def linear_unit(number: int, name: str, rail_frame: Pose | FloatArray, axis: str = "E1",
                root: Pose = Pose()) -> ExternalKinematic:
    """A linear unit carrying the robot from ``ext.linear_unit``: ``$ETn_TA1KR = T_base_rail``
    (z = the travel direction), ``$ETn_TFLA3`` its inverse (the robot base on the carriage),
    root the world (``$ERSYSROOT``), so the robot base at rail value e is
    ``root @ Tz(e)`` along the travel: ``T_world_robotbase(e) = root @ T_base_rail @ Tz(e) @
    T_base_rail⁻¹``.

    Examples
    --------
    >>> k = linear_unit(3, "RAIL", Pose(0, 0, 0, 0, 90, 0))  # travel along base +x
    >>> flange_matrix(k, [500.0])[:3, 3].round(9).tolist()
    [500.0, 0.0, 0.0]
    """
    F = rail_frame.as_matrix() if isinstance(rail_frame, Pose) else np.asarray(rail_frame)
    return ExternalKinematic(number, name, "linear_unit", root, (_pose(F),), _pose(invert(F)),
                             (axis,))


@dataclass(frozen=True)
class ExternalSetup:
    """What a reader found: the kinematics by number and the bases on them (by slot)."""

    kinematics: list[ExternalKinematic]
    bases: list[FrameEntry] = field(default_factory=list)


def _check_setup(kinematics: Iterable[ExternalKinematic], bases: Iterable[FrameEntry],
                 written_name) -> tuple[list[ExternalKinematic], list[FrameEntry], dict]:
    """Unique numbers, axes and written names; at most one linear unit; every base on a
    listed rotary kinematic. Returns (kinematics by number, bases by slot, name -> kin)."""
    kins = sorted(kinematics, key=lambda k: k.number)
    seen_num: dict[int, int] = {}
    seen_axis: dict[str, int] = {}
    seen_name: dict[str, int] = {}
    for i, k in enumerate(kins):
        if not isinstance(k, ExternalKinematic):
            raise FormatError(("kinematics", i), f"expected an ExternalKinematic, got "
                              f"{type(k).__name__}")
        if k.number in seen_num:
            raise FormatError(("kinematics", i, "number"), f"ET{k.number} is used twice")
        seen_num[k.number] = i
        for a in k.axes:
            if a in seen_axis:
                raise FormatError(("kinematics", i, "axes"), f"{a} already moves kinematic "
                                  f"{kins[seen_axis[a]].name!r}")
            seen_axis[a] = i
        w = written_name(k).upper()
        if w in seen_name:
            raise FormatError(("kinematics", i, "name"), f"{k.name!r} is written as {w!r}, "
                              f"like {kins[seen_name[w]].name!r}: give them distinct names")
        seen_name[w] = i
    if sum(k.linear for k in kins) > 1:
        raise FormatError(("kinematics",), "one linear unit can carry the robot, not two")
    by_name = {k.name: k for k in kins}
    out: list[FrameEntry] = []
    slots: dict[int, int] = {}
    for i, b in enumerate(bases):
        if not isinstance(b, FrameEntry) or b.kind != "coordinated_base":
            raise FormatError(("bases", i, "kind"), "must be a coordinated_base FrameEntry")
        k = by_name.get(b.mech_unit or "")
        if k is None:
            raise FormatError(("bases", i, "mech_unit"), f"{b.mech_unit!r} is none of the "
                              f"kinematics ({', '.join(map(repr, by_name)) or 'none given'})")
        if k.linear:
            raise FormatError(("bases", i, "mech_unit"), f"{k.name!r} is a linear unit: it "
                              "carries the robot, not a base")
        if b.number in slots:
            raise FormatError(("bases", i, "number"), f"base {b.number} is given twice")
        slots[b.number] = i
        out.append(b)
    return kins, sorted(out, key=lambda b: b.number), by_name


# --------------------------------------------------------------------------- KUKA


@dataclass(frozen=True)
class KukaExternalText:
    """The two KUKA fragments: for ``KRC:\\R1\\Mada\\$machine.dat`` and for
    ``KRC:\\R1\\System\\$config.dat`` (lines joined by ``"\\n"``)."""

    machine_dat: str
    config_dat: str


_FRAMES = ("TA1KR", "TA2A1", "TA3A2", "TFLA3")
_EASYS = "ABCDEF"


def kuka_machine_name(name: str) -> str:
    """A kinematic's name as KUKA files carry it (``$ETn_NAME[]``, ``MACHINE_DEF NAME[]``,
    ``MACHINE_FRAME_DAT PARENT[]``): one line, no ``"``, at most 20 characters, trimmed.

    Examples
    --------
    >>> kuka_machine_name('DKP "400"\\nBASE_DATA[1]={X 9}')
    'DKP  400  BASE_DATA['
    """
    return one_line(name).replace('"', " ").strip()[:KUKA_ET_NAME_CHARS].strip()


def _kname(k: ExternalKinematic) -> str:
    """The name KUKA files give kinematic ``k`` (``ETn`` when nothing of its name is left)."""
    return kuka_machine_name(k.name) or f"ET{k.number}"


def _machine_def_index(k: ExternalKinematic) -> int:
    """``MACHINE_DEF`` index of ETn: n + 1 (index 1 is the robot)."""
    return k.number + 1


def _ex_kin_type(k: ExternalKinematic) -> str:
    return "#ERSYS" if k.linear else f"#E{_EASYS[k.number - 1]}SYS"


def kuka_external_kinematics(kinematics: Iterable[ExternalKinematic],
                             bases: Iterable[FrameEntry] = (), *,
                             machine_template: str | None = None,
                             config_template: str | None = None) -> KukaExternalText:
    """The KUKA machine data of external kinematics and the ``$config.dat`` entries of the
    bases on them.

    ``$machine.dat``: ``DECL EX_KIN $EX_KIN={ET1 #EASYS,...}`` (``#EASYS`` .. ``#EFSYS`` a
    base kinematic ETn by its number, ``#ERSYS`` the linear unit carrying the robot),
    ``DECL ET_AX $ETn_AX={TR_A1 #E1,TR_A2 #NONE,TR_A3 #NONE}``, ``$ETn_NAME[]="..."``,
    ``FRAME $ETn_TA1KR``, ``$ETn_TA2A1``, ``$ETn_TA3A2`` (identity for unused axes) and
    ``$ETn_TFLA3``, and ``FRAME $ERSYSROOT`` (the linear unit's root). ``$config.dat``:
    ``MACHINE_DEF[n+1]={NAME[] "...",COOP_KRC_INDEX 1,PARENT[] " ",ROOT {...},MECH_TYPE
    #EASYS,GEOMETRY[] " "}`` (the root of base kinematic ETn) and, per base,
    ``BASE_DATA[n]`` (``T_flange_base``), ``BASE_NAME[n,]``, ``BASE_TYPE[n]=#BASE`` and
    ``MACHINE_FRAME_DAT[n]={MACH_DEF_INDEX n+1,PARENT[] "...",GEOMETRY[] " "}``.
    Reals have the shortest digits that read back as the same double (``krl_real``); names
    go through :func:`kuka_machine_name` (a name cannot add a line).

    Parameters
    ----------
    kinematics : iterable of ExternalKinematic
        Every external kinematic of the cell (ETn not listed is written ``#NONE``).
    bases : iterable of FrameEntry
        ``coordinated_base`` entries whose ``mech_unit`` is a listed (rotary) kinematic.
    machine_template, config_template : str, optional, keyword-only
        The whole ``$machine.dat`` / ``$config.dat`` imported before: the result is that file
        with only the values that changed rewritten (numbers whose value did not change keep
        their digits, with no change the file comes back byte for byte); variables it lacks
        are added before ``ENDDAT``. A ``MACHINE_DEF`` is found by its ``NAME[]``, else
        ``MACHINE_DEF[n+1]`` is used when free and declared; the bases go through
        :func:`~server.formats.kuka.export_kuka` with the template (their slots are replaced
        whole).

    Raises
    ------
    FormatError
        ``("kinematics", i, field)``: a number or axis used twice, two names written alike,
        two linear units; ``("bases", i, field)``: a base not a ``coordinated_base``, on no
        listed kinematic or on the linear unit, a slot given twice;
        ``("config_template", "line N", "MACHINE_DEF")``: no free entry for a new kinematic;
        a template's own read errors.

    Examples
    --------
    >>> t = kuka_external_kinematics([turntable(1, "TABLE", Pose(1500, 0, 300, 0, 0, 0))])
    >>> print("\\n".join(t.machine_dat.splitlines()[2:9]))
    DECL EX_KIN $EX_KIN={ET1 #EASYS,ET2 #NONE,ET3 #NONE,ET4 #NONE,ET5 #NONE,ET6 #NONE}
    ; ET1: turntable
    DECL ET_AX $ET1_AX={TR_A1 #E1,TR_A2 #NONE,TR_A3 #NONE}
    $ET1_NAME[]="TABLE"
    FRAME $ET1_TA1KR={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}
    FRAME $ET1_TA2A1={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}
    FRAME $ET1_TA3A2={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}
    >>> print(t.config_dat.splitlines()[-1])
    MACHINE_DEF[2]={NAME[] "TABLE",COOP_KRC_INDEX 1,PARENT[] " ",ROOT {X 1500.0,Y 0.0,Z 300.0,A 0.0,B 0.0,C 0.0},MECH_TYPE #EASYS,GEOMETRY[] " "}
    """
    kins, base_list, by_name = _check_setup(kinematics, bases, _kname)
    machine = _machine_items(kins)
    config = _config_items(kins, {k.number: _machine_def_index(k) for k in kins})
    if machine_template is None:
        md = ["; External kinematics written by pendant (docs/formats.md): put these values",
              "; into the same declarations of KRC:\\R1\\Mada\\$machine.dat",
              *(line for _, line, _ in machine)]
        md_text = "\n".join(md) + "\n"
    else:
        md_text = _patch_krl(machine_template, machine, "machine_template")
    if config_template is None:
        cd = ["; Bases on external kinematics written by pendant (docs/formats.md): put these",
              "; values into the same entries of KRC:\\R1\\System\\$config.dat",
              *(line for _, line, _ in config)]
        for b in base_list:
            k = by_name[b.mech_unit]  # type: ignore[index]
            n = b.number
            cd += [f"BASE_DATA[{n}]={_kuka._frame(b.pose)}",
                   f"BASE_NAME[{n},]={_kuka._name(b.name)}", f"BASE_TYPE[{n}]=#BASE",
                   f"MACHINE_FRAME_DAT[{n}]="
                   f"{_kuka._machine_frame(_kname(k), _machine_def_index(k))}"]
        cd_text = "\n".join(cd) + "\n"
    else:
        cd_text = _patch_config(config_template, kins, base_list, by_name)
    return KukaExternalText(md_text, cd_text)


#: (variable, line to write, target: an aggregate's values by key path or a string's text)
_Item = tuple[str | None, str, object]


def _frame_target(p: Pose) -> dict[tuple[str, ...], object]:
    return {(k,): float(x) for k, x in zip(_kuka._FRAME_KEYS, p.as_array())}


def _machine_items(kins: list[ExternalKinematic]) -> list[_Item]:
    """The ``$machine.dat`` lines of ``kins`` with what each must hold (for patching)."""
    by_num = {k.number: k for k in kins}
    types = {f"ET{n}": _ex_kin_type(by_num[n]) if n in by_num else "#NONE"
             for n in range(1, MAX_KINEMATICS + 1)}
    ex_kin = ",".join(f"{et} {t}" for et, t in types.items())
    items: list[_Item] = [("EX_KIN", f"DECL EX_KIN $EX_KIN={{{ex_kin}}}",
                           {(et,): t for et, t in types.items()})]
    for k in kins:
        n = k.number
        axes = {f"TR_A{i}": f"#{a}" for i, a in enumerate([*k.axes, "NONE", "NONE"][:3], 1)}
        ax = ",".join(f"{tr} {a}" for tr, a in axes.items())
        frames = [*k.axis_frames, Pose(), Pose()][:3] + [k.flange]
        items += [(None, f"; ET{n}: {k.kind.replace('_', ' ')}", None),
                  (f"ET{n}_AX", f"DECL ET_AX $ET{n}_AX={{{ax}}}",
                   {(tr,): a for tr, a in axes.items()}),
                  (f"ET{n}_NAME[]", f'$ET{n}_NAME[]="{_kname(k)}"', _kname(k))]
        items += [(f"ET{n}_{sfx}", f"FRAME $ET{n}_{sfx}={_kuka._frame(p)}", _frame_target(p))
                  for sfx, p in zip(_FRAMES, frames)]
        if k.linear:
            items.append(("ERSYSROOT", f"FRAME $ERSYSROOT={_kuka._frame(k.root)}",
                          _frame_target(k.root)))
    return items


def _config_items(kins: list[ExternalKinematic], index: dict[int, int]) -> list[_Item]:
    """The ``MACHINE_DEF`` lines of the base kinematics (ETn at ``index[n]``)."""
    items: list[_Item] = []
    for k in kins:
        if k.linear:
            continue
        i, name, typ = index[k.number], _kname(k), _ex_kin_type(k)
        target = {("NAME[]",): name, ("MECH_TYPE",): typ,
                  **{("ROOT", *key): v for key, v in _frame_target(k.root).items()}}
        items.append((f"MACHINE_DEF[{i}]",
                      f'MACHINE_DEF[{i}]={{NAME[] "{name}",COOP_KRC_INDEX 1,PARENT[] " ",'
                      f'ROOT {_kuka._frame(k.root)},MECH_TYPE {typ},GEOMETRY[] " "}}', target))
    return items


def _patch_krl(template: str, items: list[_Item], what: str) -> str:
    """``template`` (a whole KRL data file) with each item's values patched into its line,
    and the lines of items it lacks added before ``ENDDAT``; other bytes kept."""
    found = _krl_values(template, what)
    lines = template.splitlines(keepends=True)
    eol = "\r\n" if lines and lines[0].endswith("\r\n") else "\n"
    added = []
    for key, line, target in items:
        if key is None:
            continue
        if key not in found:
            added.append(line + eol)
            continue
        f = found[key]
        raw = lines[f.line - 1]
        a, b = f.span
        rhs = raw[a:b]
        if isinstance(target, dict):
            new = _kuka._patch_numbers(rhs, target, f.line, key)
        else:
            new = rhs if re.fullmatch(r'"\s*' + re.escape(str(target)) + r'\s*"', rhs) \
                else f'"{target}"'
        lines[f.line - 1] = raw[:a] + new + raw[b:]
    if added:
        at = next((i for i, raw in enumerate(lines)
                   if _kuka._ENDDAT.match(_kuka._strip_comment(raw))), len(lines))
        if at == len(lines) and lines and not lines[-1].endswith(("\n", "\r")):
            lines[-1] += eol
        lines[at:at] = added
    return "".join(lines)


def _patch_config(template: str, kins: list[ExternalKinematic], bases: list[FrameEntry],
                  by_name: dict[str, ExternalKinematic]) -> str:
    """A whole ``$config.dat`` with the kinematics' ``MACHINE_DEF`` entries (where the file
    names them, else at index n + 1) and the bases on them patched in (``export_kuka``)."""
    found = _krl_values(template, "config_template")
    defs = _machine_defs(found)
    decl = re.search(r"^[ \t]*DECL\s+\w+\s+MACHINE_DEF\s*\[\s*(\d+)\s*\]", template,
                     re.IGNORECASE | re.MULTILINE)
    index: dict[int, int] = {}
    for k in kins:
        if k.linear:
            continue
        name = _kname(k).upper()
        if name in defs:
            index[k.number] = defs[name][1]
            continue
        i = _machine_def_index(k)
        key = f"MACHINE_DEF[{i}]"
        if key in found:
            other = _agg_at(found[key], "config_template", key).get("NAME[]")
            if isinstance(other, str) and other[1:-1].strip():
                raise FormatError(("config_template", f"line {found[key].line}", key),
                                  f"holds {other} and no MACHINE_DEF names {_kname(k)!r}: "
                                  "free the entry or name the kinematic like it")
        if decl and i > int(decl.group(1)):
            line = template.count("\n", 0, decl.start()) + 1
            raise FormatError(("config_template", f"line {line}", "MACHINE_DEF"),
                              f"declared with {decl.group(1)} entries; ET{k.number} "
                              f"({_kname(k)!r}) needs MACHINE_DEF[{i}]: enlarge the array on "
                              "the controller or free an entry")
        index[k.number] = i
    text = _patch_krl(template, _config_items(kins, index), "config_template")
    written = {_kname(k).upper() for k in kins}
    slots = {b.number for b in bases}
    keep = [e for e in _kuka.read_kuka(text).entries
            if not (e.kind == "coordinated_base" and (e.mech_unit or "").upper() in written)
            and not (family_of(e.kind) == "stationary" and e.number in slots)]
    new = [replace(b, mech_unit=_kname(by_name[b.mech_unit])) for b in bases]  # type: ignore
    return _kuka.export_kuka(keep + new, template=text)


_KRL_LINE = re.compile(r"^\s*(?:DECL\s+)?(?:GLOBAL\s+)?(?:\w+\s+)?\$?(\w+)\s*(\[[^\]]*\])?\s*=\s*"
                       r"(.*?)\s*$", re.IGNORECASE)
#: the variables the readers use: one of them assigned twice is refused
_USED = re.compile(r"EX_KIN|ERSYSROOT|ET[1-6]_(AX|NAME\[\]|TA1KR|TA2A1|TA3A2|TFLA3)|"
                   r"(MACHINE_DEF|MACHINE_FRAME_DAT|BASE_DATA|BASE_TYPE)\[\d+\]|BASE_NAME\[\d+,\]")


@dataclass
class _Found:
    value: object
    line: int
    span: tuple[int, int] = (0, 0)  # of the right-hand side in its line


def _krl_values(text: str, what: str) -> dict[str, _Found]:
    """``{VARIABLE[index]: (right-hand side, line)}`` of every assignment or initialised
    declaration in a KRL data text (comments, headers, DEFDAT lines left out)."""
    if not isinstance(text, str):
        raise FormatError((what,), f"expected text, got {type(text).__name__}")
    out: dict[str, _Found] = {}
    for number, raw in enumerate(text.splitlines(), 1):
        code = _kuka._strip_comment(raw)
        if not code.strip() or code.lstrip().startswith("&"):
            continue
        m = _KRL_LINE.match(code)
        if not m:
            continue
        key = (m.group(1) + re.sub(r"\s+", "", m.group(2) or "")).upper()
        if key in out and _USED.fullmatch(key):
            raise FormatError((what, f"line {number}", key),
                              f"assigned twice (first on line {out[key].line})")
        out.setdefault(key, _Found(m.group(3), number, m.span(3)))
    return out


def _frame_at(found: _Found, what: str, fld: str) -> Pose:
    try:
        agg = _kuka._parse_aggregate(str(found.value), found.line, fld)
        return Pose(*_kuka._components(agg, _kuka._FRAME_KEYS, _kuka._UNITS, found.line, fld))
    except FormatError as err:
        raise FormatError((what, f"line {found.line}", str(err.loc[-1])), err.reason) from None


def _agg_at(found: _Found, what: str, fld: str) -> dict[str, object]:
    try:
        return _kuka._parse_aggregate(str(found.value), found.line, fld)
    except FormatError as err:
        raise FormatError((what, f"line {found.line}", str(err.loc[-1])), err.reason) from None


def _quoted(found: _Found, what: str, fld: str) -> str:
    m = re.fullmatch(r'"([^"]*)"', str(found.value))
    if not m:
        raise FormatError((what, f"line {found.line}", fld), 'expected a quoted name "..."')
    return m.group(1).strip()


def read_kuka_external(machine_dat: str, config_dat: str = "") -> ExternalSetup:
    """The external kinematics of a ``$machine.dat`` (whole or the fragment
    :func:`kuka_external_kinematics` writes) and the bases on them in a ``$config.dat``.

    Kinematic ETn exists when ``$EX_KIN`` gives it a type other than ``#NONE``: ``#ERSYS``
    is the linear unit carrying the robot (root ``$ERSYSROOT``), ``#EASYS`` .. ``#EFSYS`` a
    base kinematic (root ``MACHINE_DEF[k].ROOT`` of the entry whose ``NAME[]`` is
    ``$ETn_NAME[]``); its axes are the ``TR_A1..3`` of ``$ETn_AX`` up to the first ``#NONE``
    (one axis: turntable, two: positioner). The constant frames of unused axes
    (``$ETn_TA2A1``, ``$ETn_TA3A2``) are folded into the flange, as the chain
    ``TA1KR(E1) : TA2A1(E2) : TA3A2(E3) : TFLA3`` prescribes. Bases: every ``BASE_DATA[n]``
    whose ``MACHINE_FRAME_DAT[n]`` names one of these kinematics.

    Raises
    ------
    FormatError
        ``("machine_dat" | "config_dat", "line N", field)``: an unreadable frame or aggregate,
        a value beyond server/bounds.py, an assignment given twice; ``$EX_KIN`` missing or
        with an unknown type; a kinematic without its ``$ETn_AX``, ``$ETn_NAME``, frames,
        ``MACHINE_DEF`` or ``$ERSYSROOT``; a linear unit with more than one axis; three axes.

    Examples
    --------
    >>> k = turntable(1, "TABLE", Pose(1500, 0, 300, 0, 0, 0))
    >>> t = kuka_external_kinematics([k])
    >>> read_kuka_external(t.machine_dat, t.config_dat).kinematics == [k]
    True
    """
    mv = _krl_values(machine_dat, "machine_dat")
    cv = _krl_values(config_dat, "config_dat")
    if "EX_KIN" not in mv:
        raise FormatError(("machine_dat", "EX_KIN"), "no $EX_KIN: which external kinematics "
                          "exist is not said (DECL EX_KIN $EX_KIN={ET1 #EASYS,...})")
    ex_kin = _agg_at(mv["EX_KIN"], "machine_dat", "$EX_KIN")
    defs = _machine_defs(cv)
    kins = []
    for n in range(1, MAX_KINEMATICS + 1):
        typ = str(ex_kin.get(f"ET{n}", "#NONE")).upper()
        if typ == "#NONE":
            continue
        if not re.fullmatch(r"#E[A-F]SYS|#ERSYS", typ):
            raise FormatError(("machine_dat", f"line {mv['EX_KIN'].line}", f"$EX_KIN.ET{n}"),
                              f"expected #NONE, #EASYS..#EFSYS or #ERSYS, got {typ}")
        kins.append(_read_et(n, typ, mv, defs))
    return ExternalSetup(kins, _read_bases(cv, kins))


def _need(values: dict[str, _Found], key: str, what: str, why: str) -> _Found:
    if key not in values:
        raise FormatError((what, key), f"missing: {why}")
    return values[key]


def _read_et(n: int, typ: str, mv: dict[str, _Found], defs: dict[str, tuple[Pose, int]]
             ) -> ExternalKinematic:
    what = "machine_dat"
    ax_found = _need(mv, f"ET{n}_AX", what, f"$EX_KIN lists ET{n}; its axes $ET{n}_AX")
    ax = _agg_at(ax_found, what, f"$ET{n}_AX")
    axes: list[str] = []
    for i in (1, 2, 3):
        a = str(ax.get(f"TR_A{i}", "#NONE")).upper()
        if a == "#NONE":
            later = [j for j in range(i + 1, 4) if str(ax.get(f"TR_A{j}", "#NONE")).upper()
                     != "#NONE"]
            if later:
                raise FormatError((what, f"line {ax_found.line}", f"$ET{n}_AX.TR_A{i}"),
                                  f"#NONE before TR_A{later[0]}: the axes are assigned from "
                                  "left to right without gaps")
            break
        if not re.fullmatch(r"#E[1-6]", a):
            raise FormatError((what, f"line {ax_found.line}", f"$ET{n}_AX.TR_A{i}"),
                              f"expected #E1..#E6 or #NONE, got {a}")
        axes.append(a[1:])
    if len(axes) == 3:
        raise FormatError((what, f"line {ax_found.line}", f"$ET{n}_AX"),
                          "three-axis kinematics are not supported (turntable, two-axis "
                          "positioner, linear unit)")
    if not axes:
        raise FormatError((what, f"line {ax_found.line}", f"$ET{n}_AX"), "no axis assigned")
    name_found = _need(mv, f"ET{n}_NAME[]", what, f"the name of ET{n}, $ET{n}_NAME[]")
    name = _quoted(name_found, what, f"$ET{n}_NAME[]")
    frames = [_frame_at(_need(mv, f"ET{n}_{s}", what, f"the frame $ET{n}_{s}"), what,
                        f"$ET{n}_{s}") for s in _FRAMES]
    used, rest = frames[:len(axes)], frames[len(axes):]
    flange_T = np.eye(4)
    for p in rest:  # TA2A1 / TA3A2 of unused axes are constant links before TFLA3
        flange_T = flange_T @ p.as_matrix()
    flange = rest[-1] if len(rest) == 1 else _pose(flange_T)
    if typ == "#ERSYS":
        if len(axes) != 1:
            raise FormatError((what, f"line {ax_found.line}", f"$ET{n}_AX"),
                              "a linear unit (#ERSYS) has one axis")
        root = _frame_at(_need(mv, "ERSYSROOT", what, "the linear unit's root $ERSYSROOT"),
                         what, "$ERSYSROOT")
        kind = "linear_unit"
    else:
        if name.upper() not in defs:
            raise FormatError(("config_dat", "MACHINE_DEF"),
                              f'no MACHINE_DEF has NAME[] "{name}" ($ET{n}_NAME[] on line '
                              f"{name_found.line}): its root point is there")
        root = defs[name.upper()][0]
        kind = "turntable" if len(axes) == 1 else "positioner_2axis"
    try:
        return ExternalKinematic(n, name, kind, root, tuple(used), flange,  # type: ignore[arg-type]
                                 tuple(axes))
    except CalibrationError as err:
        raise FormatError((what, f"line {name_found.line}", f"ET{n}.{err.loc[0]}"),
                          err.reason) from None


def _machine_defs(cv: dict[str, _Found]) -> dict[str, tuple[Pose, int]]:
    """``NAME -> (ROOT, index)`` of every ``MACHINE_DEF[k]`` with a name."""
    out: dict[str, tuple[Pose, int]] = {}
    for key, found in cv.items():
        m = re.fullmatch(r"MACHINE_DEF\[(\d+)\]", key)
        if not m:
            continue
        fld = f"MACHINE_DEF[{m.group(1)}]"
        agg = _agg_at(found, "config_dat", fld)
        name = agg.get("NAME[]")
        if not isinstance(name, str):
            raise FormatError(("config_dat", f"line {found.line}", f"{fld}.NAME"),
                              'expected NAME[] "..."')
        if not name[1:-1].strip() or not isinstance(agg.get("ROOT"), dict):
            continue
        root = agg["ROOT"]
        try:
            pose = Pose(*_kuka._components(root, _kuka._FRAME_KEYS,  # type: ignore[arg-type]
                                           _kuka._UNITS, found.line, f"{fld}.ROOT"))
        except FormatError as err:
            raise FormatError(("config_dat", f"line {found.line}", str(err.loc[-1])),
                              err.reason) from None
        out[name[1:-1].strip().upper()] = (pose, int(m.group(1)))
    return out


def _read_bases(cv: dict[str, _Found], kins: list[ExternalKinematic]) -> list[FrameEntry]:
    names = {k.name.upper(): k for k in kins if not k.linear}
    out = []
    for key, found in cv.items():
        m = re.fullmatch(r"MACHINE_FRAME_DAT\[(\d+)\]", key)
        if not m:
            continue
        n = int(m.group(1))
        try:
            unit = _kuka._parse_value("MACHINE_FRAME_DAT", str(found.value), found.line, key,
                                      None)
        except FormatError as err:
            raise FormatError(("config_dat", f"line {found.line}", str(err.loc[-1])),
                              err.reason) from None
        if unit is None or str(unit).upper() not in names:
            continue
        data = _need(cv, f"BASE_DATA[{n}]", "config_dat", f"{key} names {unit!r}; "
                     f"the base itself, BASE_DATA[{n}]")
        pose = _frame_at(data, "config_dat", f"BASE_DATA[{n}]")
        name = _quoted(cv[f"BASE_NAME[{n},]"], "config_dat", f"BASE_NAME[{n},]") \
            if f"BASE_NAME[{n},]" in cv else ""
        typ = str(cv[f"BASE_TYPE[{n}]"].value).upper() if f"BASE_TYPE[{n}]" in cv else "#BASE"
        if typ != "#BASE":
            raise FormatError(("config_dat", f"line {cv[f'BASE_TYPE[{n}]'].line}",
                               f"BASE_TYPE[{n}]"), f"{key} names a kinematic, so the base is "
                              f"used with IPO mode #BASE, got {typ}")
        try:
            out.append(FrameEntry(n, name, "coordinated_base", pose, None,
                                  names[str(unit).upper()].name))
        except CalibrationError as err:
            raise FormatError(("config_dat", f"line {data.line}", f"BASE[{n}].{err.loc[0]}"),
                              err.reason) from None
    return sorted(out, key=lambda b: b.number)


# --------------------------------------------------------------------------- ABB


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
