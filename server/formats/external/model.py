"""The model of an external kinematic, for the KUKA ``$ETn_...`` machine data with
``MACHINE_DEF`` and the bases on it and the ABB ``MOC.cfg`` base frames with the coordinated
work objects.

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

The writers and readers are in :mod:`server.formats.external.kuka` and
:mod:`server.formats.external.abb`; everything is re-exported by this package. Pure
functions, text in and dataclasses out; which names and layouts were checked against public
sources is in docs/formats.md ("External kinematics").
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Iterable, Literal, get_args

import numpy as np

from server.service.bounds import MECH_UNIT_CHARS, check_name, check_value
from server.formats.model import FormatError, FrameEntry
from solvers.errors import CalibrationError
from solvers.external.common import rz
from solvers.frames import Pose, invert, translation
from solvers.validate import FloatArray

__all__ = ["ExternalKinematic", "ExternalKind", "ExternalSetup", "KINDS", "AXIS_COUNT",
           "MAX_KINEMATICS", "turntable", "positioner_2axis", "linear_unit", "flange_matrix"]

ExternalKind = Literal["turntable", "positioner_2axis", "linear_unit"]
KINDS: tuple[str, ...] = get_args(ExternalKind)
AXIS_COUNT = {"turntable": 1, "positioner_2axis": 2, "linear_unit": 1}
MAX_KINEMATICS = 6  # KUKA ET1..ET6 ($EX_KIN has six entries)
_AXIS = re.compile(r"E([1-6])")




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
