"""A pure simulator of external kinematics with hidden errors, for the ``ext.*`` solvers.

Three machines, each with the truth and what its machine data (the *nominal*) claims:

- :class:`Turntable`: one rotary axis E1; hidden errors: the axis tilted against nominal, a
  root offset, a reversed sign, a scale (gear ratio) error.
- :class:`Positioner`: tilt (E1) carrying turn (E2); each axis as a turntable, and the turn
  axis shifted along the common normal so it does not intersect the tilt axis.
- :class:`LinearUnit`: a rail (E1 in mm) carrying the robot; hidden errors: the travel
  direction tilted, a reversed direction, an encoder scale error.

Touch-ups are the TCP positions a calibrated tool reports in the robot base (isotropic
Gaussian noise per coordinate) with the recorded axis values, and the flange poses that put
that tool there (random orientations about straight down). No server, no database, no I/O:
every function takes a ``numpy.random.Generator`` when it draws.

Conventions as in the solvers: ``T_base_flange(θ) = T_base_root @ Rz(s k θ)`` for a rotary
axis with sign s and scale k; the root frame's z is the axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from solvers.external.common import line_distance, rz
from solvers.validate import FloatArray

#: the pointer the touch-ups are made with: T_flange_tcp
DEFAULT_TOOL = np.eye(4)
DEFAULT_TOOL[:3, 3] = [0.0, 0.0, 150.0]


def _frame(R: FloatArray, t: FloatArray) -> FloatArray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


@dataclass(frozen=True)
class TouchUps:
    """What the pendant records: TCP positions in the robot base (mm), the axis values (deg or mm)
    and the flange poses ``T_base_flange`` (N, 4, 4) that put ``tool`` (T_flange_tcp) there."""

    points_mm: FloatArray
    axis_values: FloatArray
    flange_poses: FloatArray
    tool: FloatArray = field(default_factory=lambda: DEFAULT_TOOL.copy())


def touch(points_true_mm: FloatArray, axis_values: FloatArray, sigma_mm: float,
          rng: np.random.Generator, tool: FloatArray = DEFAULT_TOOL) -> TouchUps:
    """Touch-ups of the true points with noise N(0, sigma²) per coordinate; flange orientations
    tilted up to 30 deg from straight down about a random horizontal axis, random twist."""
    P = np.asarray(points_true_mm, dtype=float)
    P = P + rng.normal(0.0, sigma_mm, P.shape)
    n = len(P)
    az = rng.uniform(0, 2 * np.pi, n)
    tilt = np.radians(rng.uniform(0, 30, n))
    R = (Rotation.from_rotvec(tilt[:, None] * np.c_[np.cos(az), np.sin(az), np.zeros(n)])
         * Rotation.from_euler("x", 180, degrees=True)
         * Rotation.from_euler("z", rng.uniform(-180, 180, (n, 1)), degrees=True)).as_matrix()
    F = np.tile(np.eye(4), (n, 1, 1))
    F[:, :3, :3] = R
    F[:, :3, 3] = P - R @ tool[:3, 3]
    return TouchUps(points_mm=P, axis_values=np.asarray(axis_values, dtype=float).copy(),
                    flange_poses=F, tool=np.array(tool, dtype=float))


def rotary_root(nominal_root: FloatArray, *, tilt_deg: float = 0.0, tilt_about_deg: float = 0.0,
                root_offset_mm: float = 0.0, offset_dir_deg: float = 90.0) -> FloatArray:
    """True root frame: the nominal one tilted by ``tilt_deg`` about its in-plane direction at
    ``tilt_about_deg`` (from its x), and shifted ``root_offset_mm`` perpendicular to its axis
    towards ``offset_dir_deg``."""
    N = np.asarray(nominal_root, dtype=float)
    b = np.radians(tilt_about_deg)
    axis_in_root = np.array([np.cos(b), np.sin(b), 0.0])
    dR = Rotation.from_rotvec(np.radians(tilt_deg) * (N[:3, :3] @ axis_in_root)).as_matrix()
    o = np.radians(offset_dir_deg)
    shift = root_offset_mm * (N[:3, :3] @ np.array([np.cos(o), np.sin(o), 0.0]))
    return _frame(dR @ N[:3, :3], N[:3, 3] + shift)


@dataclass(frozen=True)
class Turntable:
    """A one-axis turntable: ``root`` (true T_base_root), ``sign`` and ``scale`` of the axis,
    and ``nominal_root`` (the machine data)."""

    root: FloatArray
    nominal_root: FloatArray
    sign: int = 1
    scale: float = 1.0

    def flange(self, values_deg: FloatArray) -> FloatArray:
        """True ``T_base_flange`` (N, 4, 4) at the recorded axis values."""
        return self.root @ rz(self.sign * self.scale * np.asarray(values_deg, dtype=float))

    def mark(self, mark_flange_mm: FloatArray, values_deg: FloatArray) -> FloatArray:
        """The true mark position in the robot base at each axis value (N, 3)."""
        F = self.flange(values_deg)
        return F[:, :3, :3] @ np.asarray(mark_flange_mm, dtype=float) + F[:, :3, 3]

    def touch_mark(self, mark_flange_mm: FloatArray, values_deg: FloatArray, sigma_mm: float,
                   rng: np.random.Generator) -> TouchUps:
        return touch(self.mark(mark_flange_mm, values_deg), values_deg, sigma_mm, rng)

    @property
    def axis(self) -> FloatArray:
        """The true axis direction about which increasing values turn right-handed."""
        return self.sign * self.root[:3, 2]

    def true_root_frame(self, mark_flange_mm: FloatArray) -> FloatArray:
        """The root frame as ``ext.root_point`` defines it for this mark: origin at the centre of
        the mark's circle, z = :attr:`axis`, x towards the mark at axis value 0."""
        m = np.asarray(mark_flange_mm, dtype=float)
        c_root = np.array([0.0, 0.0, m[2]])
        x_root = np.array([m[0], m[1], 0.0]) / np.hypot(m[0], m[1])
        R = self.root[:3, :3]
        z = self.axis
        x = R @ x_root
        return _frame(np.column_stack([x, np.cross(z, x), z]), R @ c_root + self.root[:3, 3])


def make_turntable(*, tilt_deg: float = 0.0, root_offset_mm: float = 0.0, sign: int = 1,
                   scale: float = 1.0, nominal_root: FloatArray | None = None) -> Turntable:
    """A turntable whose machine data says ``nominal_root`` (default: axis +z at
    (1500, 0, 300) mm in the robot base) with the given hidden errors.

    Examples
    --------
    >>> t = make_turntable(tilt_deg=1.0)
    >>> round(float(np.degrees(np.arccos(t.axis @ [0, 0, 1]))), 6)
    1.0
    """
    N = (_frame(np.eye(3), [1500.0, 0.0, 300.0]) if nominal_root is None
         else np.asarray(nominal_root, dtype=float))
    root = rotary_root(N, tilt_deg=tilt_deg, root_offset_mm=root_offset_mm)
    return Turntable(root, N, sign, scale)


@dataclass(frozen=True)
class Positioner:
    """Tilt (E1) carrying turn (E2). ``tilt`` is the first axis as a turntable;
    ``turn_in_tilt`` the true turn root in the tilt flange frame, ``nominal_turn_in_tilt`` the
    machine data's; ``turn_sign``, ``turn_scale`` of E2."""

    tilt: Turntable
    turn_in_tilt: FloatArray
    nominal_turn_in_tilt: FloatArray
    turn_sign: int = 1
    turn_scale: float = 1.0

    def flange(self, tilt_deg: FloatArray, turn_deg: FloatArray) -> FloatArray:
        """True ``T_base_flange`` of the turn axis (N, 4, 4)."""
        turn = rz(self.turn_sign * self.turn_scale * np.asarray(turn_deg, dtype=float))
        return self.tilt.flange(tilt_deg) @ self.turn_in_tilt @ turn

    def mark(self, mark_flange_mm: FloatArray, tilt_deg: FloatArray,
             turn_deg: FloatArray) -> FloatArray:
        F = self.flange(tilt_deg, turn_deg)
        return F[:, :3, :3] @ np.asarray(mark_flange_mm, dtype=float) + F[:, :3, 3]

    def turn_root_in_base(self, tilt_deg: float) -> FloatArray:
        """True turn root frame in the robot base at a tilt value."""
        return self.tilt.flange([tilt_deg])[0] @ self.turn_in_tilt

    def true_axes(self) -> tuple[float, float]:
        """(common normal length mm, angle between the axes deg) of the true axes."""
        T = self.turn_in_tilt
        d2 = T[:3, 2]
        L, _, _ = line_distance(np.zeros(3), np.array([0.0, 0.0, 1.0]), T[:3, 3], d2)
        return L, float(np.degrees(np.arccos(np.clip(d2[2], -1.0, 1.0))))


def make_positioner(*, tilt_deg: float = 0.0, root_offset_mm: float = 0.0, sign: int = 1,
                    scale: float = 1.0, turn_tilt_deg: float = 0.0, axis_offset_mm: float = 0.0,
                    turn_sign: int = 1, table_height_mm: float = 200.0,
                    nominal_tilt_root: FloatArray | None = None) -> Positioner:
    """A tilt-and-turn positioner: nominal tilt axis along base +x through (1400, 0, 600) mm
    (or the frame ``nominal_tilt_root``, z the tilt axis, x pointing down at tilt 0), the turn
    axis vertical at tilt 0, its table ``table_height_mm`` above the tilt axis.

    Hidden errors: the tilt axis' ``tilt_deg`` / ``root_offset_mm`` / ``sign`` / ``scale``, the
    turn axis tilted ``turn_tilt_deg`` in the tilt flange, shifted ``axis_offset_mm`` along the
    common normal (the tilt axis then misses the turn axis), and ``turn_sign``.

    Examples
    --------
    >>> p = make_positioner(axis_offset_mm=3.0)
    >>> [round(v, 6) for v in p.true_axes()]
    [3.0, 90.0]
    """
    nominal_tilt = (_frame(Rotation.from_euler("y", 90, degrees=True).as_matrix(),
                           [1400.0, 0.0, 600.0]) if nominal_tilt_root is None
                    else np.asarray(nominal_tilt_root, dtype=float))
    tilt = Turntable(rotary_root(nominal_tilt, tilt_deg=tilt_deg, root_offset_mm=root_offset_mm),
                     nominal_tilt, sign, scale)
    # in the tilt flange, base z is -x: the turn axis points along -x, its table above the axis
    nominal_turn = _frame(Rotation.from_euler("y", -90, degrees=True).as_matrix(),
                          [-table_height_mm, 0.0, 0.0])
    true_turn = rotary_root(nominal_turn, tilt_deg=turn_tilt_deg, tilt_about_deg=90.0)
    true_turn[:3, 3] += [0.0, axis_offset_mm, 0.0]  # along the common normal (tilt flange y)
    return Positioner(tilt, true_turn, nominal_turn, turn_sign)


@dataclass(frozen=True)
class LinearUnit:
    """A rail carrying the robot: ``T_world_base0`` is the robot base at encoder 0,
    ``direction_world`` the true travel per +1 encoder mm (times ``sign`` and ``scale``),
    ``nominal_direction_world`` the machine data's."""

    T_world_base0: FloatArray
    direction_world: FloatArray
    nominal_direction_world: FloatArray
    sign: int = 1
    scale: float = 1.0

    def base_pose(self, values_mm: FloatArray) -> FloatArray:
        """True ``T_world_base`` (N, 4, 4) at the recorded encoder values."""
        e = np.atleast_1d(np.asarray(values_mm, dtype=float))
        T = np.tile(self.T_world_base0, (len(e), 1, 1))
        T[:, :3, 3] += (self.sign * self.scale * e)[:, None] * self.direction_world
        return T

    def mark_in_base(self, mark_world_mm: FloatArray, values_mm: FloatArray) -> FloatArray:
        """The fixed world mark in the (moving) robot base at each encoder value (N, 3)."""
        T = self.base_pose(values_mm)
        d = np.asarray(mark_world_mm, dtype=float) - T[:, :3, 3]
        return np.einsum("nji,nj->ni", T[:, :3, :3], d)

    def touch_mark(self, mark_world_mm: FloatArray, values_mm: FloatArray, sigma_mm: float,
                   rng: np.random.Generator) -> TouchUps:
        return touch(self.mark_in_base(mark_world_mm, values_mm), values_mm, sigma_mm, rng)

    @property
    def travel_in_base(self) -> FloatArray:
        """True direction (robot base) the carriage moves for increasing encoder values."""
        return self.T_world_base0[:3, :3].T @ (self.sign * self.direction_world)

    @property
    def nominal_in_base(self) -> FloatArray:
        return self.T_world_base0[:3, :3].T @ self.nominal_direction_world


def make_linear_unit(*, direction_tilt_deg: float = 0.0, sign: int = 1, scale: float = 1.0,
                     base_yaw_deg: float = 0.0) -> LinearUnit:
    """A rail along world +x with the robot base at (0, 0, 0) at encoder 0, yawed
    ``base_yaw_deg`` on the carriage. Hidden errors: the travel direction tilted
    ``direction_tilt_deg`` (about world z, then half of it about y), ``sign``, ``scale``."""
    d = Rotation.from_euler("zy", [direction_tilt_deg, direction_tilt_deg / 2], degrees=True).apply(
        [1.0, 0.0, 0.0])
    T0 = _frame(Rotation.from_euler("z", base_yaw_deg, degrees=True).as_matrix(), np.zeros(3))
    return LinearUnit(T0, d, np.array([1.0, 0.0, 0.0]), sign, scale)


__all__ = ["TouchUps", "touch", "Turntable", "make_turntable", "Positioner", "make_positioner",
           "LinearUnit", "make_linear_unit", "rotary_root", "rz", "DEFAULT_TOOL"]
