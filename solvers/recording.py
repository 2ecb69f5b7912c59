"""A robot recording (``robot-recording/1``) as the solvers see it: arrays, not JSON.

``server/formats/recording.py`` parses and validates the JSON document and builds a
:class:`RecordingData`; the analysis and the simulator work on this dataclass only.
The format itself is described in ``docs/recording-format.md``.

Conventions carried over from the format:

- ``robot`` is the recording's own DH table (``theta_i = direction_i * q_i + offset_i``),
  with no joint coupling: a coupled arm's file holds the decoupled joint values.
- ``tool`` is the nominal TCP the controller used, ``T_flange_tcp`` (4, 4); its z axis is
  the tool axis.
- Samples are in the order recorded; the robot moved directly from one sample to the next.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from solvers.dh import RobotModel
from solvers.errors import CalibrationError
from solvers.frames import Pose
from solvers.validate import FloatArray

FORMAT = "robot-recording/1"

RecordingKind = Literal["touch", "tracker", "beam"]
Edge = Literal["enter", "leave", "tip"]

#: Fewest samples a recording of each kind must hold (the rigid model's unknowns, plus one
#: to leave a residual): touch 4 (XYZ 4-point), tracker 4 (9 unknowns, 3 per sample),
#: beam 6 (5 unknowns, 1 per trigger).
MIN_SAMPLES: dict[str, int] = {"touch": 4, "tracker": 4, "beam": 6}


@dataclass(frozen=True, eq=False)
class RecordingData:
    """One recording: the robot, the nominal tool and payload, and N samples.

    Attributes
    ----------
    kind : {'touch', 'tracker', 'beam'}
    robot : RobotModel
        Built from the file's DH table; ``name`` is the file's ``robot.model``; joint limits
        are not in the format and are left at +-360 deg.
    tool : ndarray, shape (4, 4)
        ``T_flange_tcp`` the controller used (nominal).
    payload_mass_kg : float
        0 when the file has no ``payload``.
    payload_com_mm : ndarray, shape (3,)
        Payload centre of mass in the flange frame.
    start_joints_deg : ndarray, shape (n,) or None
        Where the robot came from before the first sample.
    t_s : ndarray, shape (N,)
        Seconds since the recording began, non-decreasing.
    joints_deg : ndarray, shape (N, n)
        What the controller showed at each sample.
    measured_mm : ndarray, shape (N, 3) or None
        ``tracker`` only: the TCP as the instrument measured it, instrument frame.
    beams : dict[str, tuple[ndarray, ndarray]]
        ``beam`` only: beam id -> (point_mm (3,), unit direction (3,)) in the robot base frame.
    tool_diameter_mm : float or None
        ``beam`` only: the diameter of the tool's cylindrical shaft.
    beam_ids, edges : ndarray of str, shape (N,), or None
        ``beam`` only: which beam triggered and how ('enter', 'leave', 'tip').
    tcp_velocity_mm_s : ndarray, shape (N, 3) or None
        ``beam`` only: commanded TCP velocity at the trigger, base frame.
    recorded_at : str or None
        ISO 8601 time stamp as written in the file.
    link_masses : solvers.gravity.LinkMasses or None
        The arm's link masses as the file gives them (``robot.link_masses``), else None.
    """

    kind: RecordingKind
    robot: RobotModel
    tool: FloatArray
    t_s: FloatArray
    joints_deg: FloatArray
    payload_mass_kg: float = 0.0
    payload_com_mm: FloatArray = field(default_factory=lambda: np.zeros(3))
    start_joints_deg: FloatArray | None = None
    measured_mm: FloatArray | None = None
    beams: dict[str, tuple[FloatArray, FloatArray]] = field(default_factory=dict)
    tool_diameter_mm: float | None = None
    beam_ids: np.ndarray | None = None
    edges: np.ndarray | None = None
    tcp_velocity_mm_s: FloatArray | None = None
    recorded_at: str | None = None
    link_masses: Any = None    # solvers.gravity.LinkMasses from the file, or None

    @property
    def n_samples(self) -> int:
        return int(len(self.t_s))

    @property
    def tcp_mm(self) -> FloatArray:
        """The nominal TCP position in the flange frame, (3,)."""
        return np.asarray(self.tool, dtype=float)[:3, 3].copy()


def motion_signs(joints_deg: FloatArray, start_joints_deg: FloatArray | None = None) -> FloatArray:
    """Direction in which each joint last moved before each sample, (N, n) of -1, 0, +1.

    ``s[k] = sign(q[k] - q[k-1])`` with ``q[-1] = start_joints_deg``. A joint that did not
    move between two samples keeps the sign it had (its gear stays on the same flank);
    0 where nothing is known yet (the first samples without ``start_joints_deg``).

    Examples
    --------
    >>> motion_signs(np.array([[0.0], [1.0], [1.0], [0.5]])).ravel().tolist()
    [0.0, 1.0, 1.0, -1.0]
    >>> motion_signs(np.array([[0.0], [1.0]]), np.array([2.0])).ravel().tolist()
    [-1.0, 1.0]
    """
    q = np.atleast_2d(np.asarray(joints_deg, dtype=float))
    prev = np.empty_like(q)
    prev[1:] = q[:-1]
    prev[0] = q[0] if start_joints_deg is None else np.asarray(start_joints_deg, dtype=float)
    s = np.sign(q - prev)
    for k in range(1, len(s)):
        keep = s[k] == 0
        s[k, keep] = s[k - 1, keep]
    return s


def last_motion_sign(rec: RecordingData) -> FloatArray:
    """:func:`motion_signs` of a recording's joints: (N, n) of -1, 0, +1."""
    return motion_signs(rec.joints_deg, rec.start_joints_deg)


def _pose_dict(p: Pose) -> dict[str, float]:
    return {"x": p.x, "y": p.y, "z": p.z, "a": p.a, "b": p.b, "c": p.c}


def _floats(a: object) -> list:
    return np.asarray(a, dtype=float).tolist()


def recording_document(rec: RecordingData) -> dict[str, Any]:
    """The ``robot-recording/1`` document (JSON-ready dict) of a recording, not validated.

    ``server.formats.recording.to_document`` adds the validation; ``parse_recording`` reads it back.
    ``direction`` is written only where it is -1; ``base_pose`` / ``flange_pose`` only when
    not the identity; ``payload`` only with a mass.

    Raises
    ------
    CalibrationError
        The robot has a joint coupling: the format holds decoupled joint values, so write a
        robot with ``coupling=None`` and ``q_dh = C q``.
    """
    robot = rec.robot
    if robot.coupling is not None and not np.allclose(robot.coupling_matrix(), np.eye(robot.dof)):
        raise CalibrationError(("robot", "joints"), "the format has no joint coupling: write the "
                               "decoupled joint values and a robot with coupling=None")
    joints = []
    for j in robot.joints:
        row: dict[str, Any] = {"a_mm": float(j.a_mm), "alpha_deg": float(j.alpha_deg),
                               "d_mm": float(j.d_mm), "offset_deg": float(j.offset_deg)}
        if int(j.direction) != 1:
            row["direction"] = int(j.direction)
        joints.append(row)
    doc: dict[str, Any] = {"format": FORMAT, "kind": rec.kind}
    if rec.recorded_at is not None:
        doc["recorded_at"] = rec.recorded_at
    doc["robot"] = {"model": robot.name, "dh_convention": robot.dh_convention, "joints": joints}
    if robot.base_pose != Pose():
        doc["robot"]["base_pose"] = _pose_dict(robot.base_pose)
    if robot.flange_pose != Pose():
        doc["robot"]["flange_pose"] = _pose_dict(robot.flange_pose)
    if rec.link_masses is not None:
        lm = {"mass_kg": [float(x) for x in rec.link_masses.mass_kg]}
        if rec.link_masses.com_mm is not None:
            lm["com_mm"] = [_floats(c) for c in rec.link_masses.com_mm]
        doc["robot"]["link_masses"] = lm
    doc["tool"] = _pose_dict(Pose.from_matrix(np.asarray(rec.tool, dtype=float)))
    if rec.payload_mass_kg:
        doc["payload"] = {"mass_kg": float(rec.payload_mass_kg),
                          "com_mm": _floats(rec.payload_com_mm)}
    if rec.start_joints_deg is not None:
        doc["start_joints_deg"] = _floats(rec.start_joints_deg)
    if rec.kind == "beam":
        doc["sensor"] = {"beams": [{"id": k, "point_mm": _floats(p), "direction": _floats(d)}
                                   for k, (p, d) in rec.beams.items()],
                         "tool_diameter_mm": float(rec.tool_diameter_mm or 0.0)}
    samples = []
    for k in range(rec.n_samples):
        s: dict[str, Any] = {"t_s": float(rec.t_s[k]), "joints_deg": _floats(rec.joints_deg[k])}
        if rec.kind == "tracker":
            s["measured_mm"] = _floats(rec.measured_mm[k])  # type: ignore[index]
        elif rec.kind == "beam":
            s["beam"] = str(rec.beam_ids[k])  # type: ignore[index]
            s["edge"] = str(rec.edges[k])  # type: ignore[index]
            s["tcp_velocity_mm_s"] = _floats(rec.tcp_velocity_mm_s[k])  # type: ignore[index]
        samples.append(s)
    doc["samples"] = samples
    return doc


__all__ = ["FORMAT", "recording_document", "RecordingData", "RecordingKind", "Edge", "MIN_SAMPLES",
           "motion_signs",
           "last_motion_sign"]
