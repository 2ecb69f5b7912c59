"""Tool > Light barrier: TCP position and tool-axis direction (runout) from crossed laser beams.

Two solvers of the same measurement (a ``beam`` recording, ``robot-recording/1``):

- :func:`light_barrier_two_heights` is the closed form of the runout/offset method [1]_,
  re-derived here (the supplied text lost its equations (6)-(16)): shaft-centre offsets at two
  (or more) heights from the midpoints of enter/leave positions, projection angles,
  ``R = Ry(theta) Rx(phi)``, offsets at the flange and the tool height from a tip search.
  It needs the paper's set-up: flange orientation held constant during the sweeps, level
  beams, horizontal sweeps.
- :func:`tcp_light_barrier` (the API's ``tool.light_barrier``) fits the same unknowns to ALL
  triggers by nonlinear least squares, for any orientations, beams and passes, and reports
  residuals, covariance and 95% bounds.

Geometry and notation (all derivations in ``docs/methods/light_barrier.md``)
---------------------------------------------------------------------------
Trigger k: flange pose ``T_base_flange = (R_k, p_k)``, beam ``P_b + mu u_b`` (``u_b`` unit),
shaft diameter ``d``, ``r = d/2``. Unknown tool: TCP ``t`` and unit axis ``a`` (pointing from
the flange towards the tip), both in flange. In base the TCP is ``c_k = R_k t + p_k`` and the
axis ``w_k = R_k a``.

(1)  ``n_k = (w_k x u_b) / |w_k x u_b|``, ``m_k = n_k sign(n_k . v_k)`` (``v_k`` the TCP
     velocity: the common normal oriented along the motion);
(2)  enter: ``(c_k - P_b) . m_k = -r``;  leave: ``(c_k - P_b) . m_k = +r``;
(3)  tip: ``(c_k - P_b) . nv_k = 0``, ``nv_k = (v_k - (v_k.u_b) u_b) / |...|``.

References
----------
.. [1] S.-D. Lin et al., laser-sensor TCP calibration of runout and offset (Techman
   TM5-900), Sensors/Applied Sciences (2022), as supplied in the project's seeds
   (``seeds/paper-laser-sensor-tcp-runout-offset.txt``; bibliographic details not given).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from solvers.beam_cycle import EDGES, cross3, as_beams
from solvers.errors import CalibrationError
from solvers.frames import angle_between_deg, axis_angle_deg, rotation_matrix
from solvers.report import (CalibrationResult, Finding, QualityReport, bounds95,
                            leave_one_out_bad_point, residual_sigma)
from solvers.validate import FloatArray, as_array, as_transforms

METHOD = "tool.light_barrier"
# axis tilts: of the tool axis towards the tool frame's x and y axes (see tool_frame)
PARAMETER_NAMES = ("tcp_x_mm", "tcp_y_mm", "tcp_z_mm", "axis_tilt_x_deg", "axis_tilt_y_deg")
MIN_HEIGHT_SPREAD_MM = 1.0  # enter/leave heights along the axis closer than this = one height
#: A measured shaft diameter this far (mm) from tool_diameter_mm is flagged ``diameter_mismatch``
#: (when it is also beyond 4 standard errors of the measurement).
DIAMETER_TOL_MM = 0.05


@dataclass(frozen=True)
class _Triggers:
    """Checked triggers, one row each: flange R, p; beam point, direction; motion direction."""

    R: FloatArray  # (N, 3, 3)
    p: FloatArray  # (N, 3)
    P: FloatArray  # (N, 3) beam point
    U: FloatArray  # (N, 3) beam unit direction
    V: FloatArray  # (N, 3) unit motion direction, NaN where unknown (tip without velocity)
    edges: tuple[str, ...]
    beam_ids: tuple[str, ...]
    r_mm: float
    has_velocity: bool

    @property
    def n(self) -> int:
        return len(self.edges)

    @property
    def sweep(self) -> FloatArray:
        return np.array([e != "tip" for e in self.edges])

    @property
    def tip(self) -> FloatArray:
        return np.array([e == "tip" for e in self.edges])


def _unit(v: FloatArray) -> FloatArray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _validate(flange_poses: object, beam_ids: object, edges: object, beams: object,
              tool_diameter_mm: object, velocities_mm_s: object | None) -> _Triggers:
    T = as_transforms(flange_poses, "flange_poses", min_count=1)
    n = len(T)
    B = as_beams(beams)
    ids = _strings(beam_ids, "beam_ids", "beam ids")
    eds = _strings(edges, "edges", "'enter' | 'leave' | 'tip'")
    for name, seq in (("beam_ids", ids), ("edges", eds)):
        if len(seq) != n:
            raise CalibrationError((name,), f"has {len(seq)} entries for {n} flange_poses")
    for k, b in enumerate(ids):
        if b not in B:
            raise CalibrationError(("beam_ids", k),
                                   f"unknown beam '{b}'; the sensor has {sorted(B)}")
    for k, e in enumerate(eds):
        if e not in EDGES:
            raise CalibrationError(("edges", k), f"must be 'enter', 'leave' or 'tip', got '{e}'")
    d = float(as_array(tool_diameter_mm, "tool_diameter_mm", ()))
    if d <= 0:
        raise CalibrationError(("tool_diameter_mm",), f"must be positive, got {d}")
    R, p = T[:, :3, :3], T[:, :3, 3]
    P = np.array([B[b].point_mm for b in ids])
    U = np.array([B[b].direction for b in ids])
    V = np.full((n, 3), np.nan)
    if velocities_mm_s is not None:
        vel = as_array(velocities_mm_s, "velocities_mm_s", (n, 3))
        for k in range(n):
            speed = float(np.linalg.norm(vel[k]))
            if speed < 1e-9:
                raise CalibrationError(("velocities_mm_s", k),
                                       "is zero: a trigger happens while moving")
            V[k] = vel[k] / speed
    else:
        for k, e in enumerate(eds):
            if e != "tip":
                V[k] = _infer_motion(p, ids, eds, k)
    for k, e in enumerate(eds):
        if e == "tip" and np.all(np.isfinite(V[k])):
            along = V[k] - (V[k] @ U[k]) * U[k]
            if np.linalg.norm(along) < 1e-3:
                raise CalibrationError(("velocities_mm_s", k),
                                       f"tip search moves along beam '{ids[k]}'")
    return _Triggers(R, p, P, U, V, tuple(eds), tuple(ids), 0.5 * d, velocities_mm_s is not None)


def _strings(value: object, loc: str, what: str) -> list[str]:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise CalibrationError((loc,), f"must be a list of {what}, one per flange pose")
    return [str(v) for v in value]  # type: ignore[union-attr]


def _infer_motion(p: FloatArray, ids: list[str], eds: list[str], k: int) -> FloatArray:
    """Motion direction at enter/leave k without velocities: towards the matching leave (from
    the matching enter) of the same beam, else towards the next (from the previous) sample."""
    b, n = ids[k], len(ids)
    j = None
    if eds[k] == "enter":
        for i in range(k + 1, n):
            if ids[i] == b and eds[i] != "tip":
                j = i if eds[i] == "leave" else None
                break
        step = p[j] - p[k] if j is not None else (p[k + 1] - p[k] if k + 1 < n else np.zeros(3))
    else:
        for i in range(k - 1, -1, -1):
            if ids[i] == b and eds[i] != "tip":
                j = i if eds[i] == "enter" else None
                break
        step = p[k] - p[j] if j is not None else (p[k] - p[k - 1] if k > 0 else np.zeros(3))
    norm = float(np.linalg.norm(step))
    if norm < 1e-9:
        raise CalibrationError(("velocities_mm_s",),
                               f"not given, and the approach side of trigger {k} cannot be "
                               "inferred from the neighbouring poses: give the TCP velocities")
    return step / norm


def _residuals(tr: _Triggers, t: FloatArray, a: FloatArray, jacobian: bool = False
               ) -> FloatArray | tuple[FloatArray, FloatArray, FloatArray]:
    """Signed distance error (mm) of every trigger, equations (2) and (3) of the module doc.

    With ``jacobian`` also returns d r / d t (N, 3) and d r / d a (N, 3), ``a`` taken as a
    free 3-vector (the caller chains in its normalisation). With ``n' = w x u``:
    d(d.n'/|n'|)/dw = (u x d)/|n'| - (d.n') (w - (w.u) u)/|n'|^3, and for the tip plane
    with ``v = w``, ``q = P w`` (``P = I - u u^T``): d(d.q/|q|)/dw = P d/|q| - (d.q) q/|q|^3.
    """
    c = np.einsum("kij,j->ki", tr.R, t) + tr.p
    w = np.einsum("kij,j->ki", tr.R, a)
    dvec = c - tr.P
    res = np.empty(tr.n)
    d_dt = np.zeros((tr.n, 3))  # in base; mapped to flange below
    d_dw = np.zeros((tr.n, 3))
    sw, tp = tr.sweep, tr.tip
    if sw.any():
        n_raw = cross3(w[sw], tr.U[sw])
        nn = np.maximum(np.linalg.norm(n_raw, axis=1, keepdims=True), 1e-300)
        nvec = n_raw / nn
        sgn = np.where(np.einsum("ki,ki->k", nvec, tr.V[sw]) < 0, -1.0, 1.0)
        side = np.where(np.array(tr.edges)[sw] == "enter", -1.0, 1.0)
        dn = np.einsum("ki,ki->k", dvec[sw], nvec)
        res[sw] = sgn * dn - side * tr.r_mm
        if jacobian:
            u = tr.U[sw]
            wu = np.einsum("ki,ki->k", w[sw], u)[:, None]
            d_dt[sw] = sgn[:, None] * nvec
            d_dw[sw] = sgn[:, None] * (cross3(u, dvec[sw]) / nn
                                       - dn[:, None] * (w[sw] - wu * u) / nn**2)
    if tp.any():
        known = np.all(np.isfinite(tr.V[tp]), axis=1)[:, None]
        v = np.where(known, tr.V[tp], w[tp])  # no velocity: moving along the axis
        q = v - np.einsum("ki,ki->k", v, tr.U[tp])[:, None] * tr.U[tp]
        qn = np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-300)
        nv = q / qn
        dq = np.einsum("ki,ki->k", dvec[tp], nv)
        res[tp] = dq
        if jacobian:
            d_dt[tp] = nv
            pd = dvec[tp] - np.einsum("ki,ki->k", dvec[tp], tr.U[tp])[:, None] * tr.U[tp]
            d_dw[tp] = np.where(known, 0.0, pd / qn - dq[:, None] * q / qn**2)
    if not jacobian:
        return res
    # c = R t + p and w = R a: d/dt = (d/dc) R, d/da = (d/dw) R
    return res, np.einsum("ki,kij->kj", d_dt, tr.R), np.einsum("ki,kij->kj", d_dw, tr.R)


def _tangent_basis(a: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The tilt directions of the axis ``a``: the x and y axes of :func:`tool_frame`."""
    R = tool_frame(np.zeros(3), a)[:3, :3]
    return R[:, 0], R[:, 1]


def tool_frame(tcp_mm: FloatArray, axis_flange: FloatArray) -> FloatArray:
    """T_flange_tcp with origin ``tcp_mm`` and z along ``axis_flange``; x is the flange x axis
    projected onto the plane normal to the axis (the unit vector normal to the axis closest to
    flange x: minimal twist), or flange y's projection when the axis lies along flange x.

    Examples
    --------
    >>> T = tool_frame(np.array([1.0, 2.0, 150.0]), np.array([0.0, 0.0, 1.0]))
    >>> np.allclose(T[:3, :3], np.eye(3)), T[:3, 3].tolist()
    (True, [1.0, 2.0, 150.0])
    """
    z = _unit(np.asarray(axis_flange, dtype=float))
    ref = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.99 else np.array([0.0, 1.0, 0.0])
    x = _unit(ref - (ref @ z) * z)
    R = np.column_stack([x, cross3(z, x), z])
    return rotation_matrix(Rotation.from_matrix(R), tcp_mm)


def runout_angles_deg(axis_flange: FloatArray) -> dict[str, float]:
    """Projection angles and the paper's X-Y Euler angles of a tool axis given in flange.

    ``theta_x = atan(a_x / a_z)``, ``theta_y = atan(a_y / a_z)`` (equation (9) of the docs);
    ``R = Ry(theta) @ Rx(phi)`` (rotate about flange X first, then about Y; SciPy's extrinsic
    ``"xy"``) with ``R @ z = a``: ``theta = theta_x``, ``phi = -atan(tan(theta_y) cos(theta_x))``.

    Examples
    --------
    >>> ang = runout_angles_deg(np.array([0.0, 0.0, 1.0]))
    >>> ang["runout_deg"], ang["theta_x_deg"], ang["phi_deg"]
    (0.0, 0.0, 0.0)
    """
    a = _unit(np.asarray(axis_flange, dtype=float))
    theta = float(np.degrees(np.arctan2(a[0], a[2])))
    phi = float(np.degrees(np.arctan2(-a[1], np.hypot(a[0], a[2]))))
    return {"runout_deg": axis_angle_deg(a, [0.0, 0.0, 1.0]),
            "theta_x_deg": float(np.degrees(np.arctan(a[0] / a[2]))) if abs(a[2]) > 1e-12 else 90.0,
            "theta_y_deg": float(np.degrees(np.arctan(a[1] / a[2]))) if abs(a[2]) > 1e-12 else 90.0,
            "theta_deg": theta + 0.0, "phi_deg": phi + 0.0}


# ----------------------------------------------------------------------------- closed form


@dataclass(frozen=True)
class ShaftAxis:
    """The shaft axis from the sweeps alone (no tip): the paper's runout and offset steps.

    ``base_point_mm`` is where the axis pierces the flange plane, ``(dX, dY, 0)`` (the tool's
    offset at the flange); ``axis_flange`` its unit direction (flange -> tip). ``planes`` holds
    for each sweep height ``(z_mm, dx_mm, dy_mm)``: the axis point in flange coordinates where
    the beams cut it (the paper's tool-centre offset at plane z). ``diameter_mm`` is the
    shaft diameter the enter/leave chords imply (a check on the input).
    """

    base_point_mm: FloatArray
    axis_flange: FloatArray
    planes: tuple[tuple[float, float, float], ...]
    diameter_mm: float
    n_passes: int
    flange_rotation: FloatArray


def _pairs(tr: _Triggers) -> list[tuple[int, int]]:
    """(enter, leave) index pairs of one beam with no other edge of that beam in between."""
    out = []
    for k, (b, e) in enumerate(zip(tr.beam_ids, tr.edges)):
        if e != "enter":
            continue
        for j in range(k + 1, tr.n):
            if tr.beam_ids[j] == b and tr.edges[j] != "tip":
                if tr.edges[j] == "leave":
                    out.append((k, j))
                break
    return out


def _shaft_axis(tr: _Triggers, orientation_tol_deg: float, level_tol_deg: float) -> ShaftAxis:
    pairs = _pairs(tr)
    if not pairs:
        raise CalibrationError(("edges",), "no enter followed by a leave of the same beam: "
                               "sweep the shaft across the beams")
    used = sorted({i for pr in pairs for i in pr})
    R0 = tr.R[used[0]]
    angles = angle_between_deg(R0, tr.R[used])  # one batched call
    for k, ang in zip(used, angles.tolist()):
        if ang > orientation_tol_deg:
            raise CalibrationError(("flange_poses", k),
                                   f"orientation differs from pose {used[0]} by {ang:.3f} deg; the "
                                   "closed form needs it held constant during the sweeps "
                                   "(tcp_light_barrier handles any orientation)")
    for b, u in {tr.beam_ids[k]: tr.U[k] for k in used}.items():
        tilt = float(np.degrees(np.arcsin(min(abs(u[2]), 1.0))))
        if tilt > level_tol_deg:
            raise CalibrationError(("beams", b, "direction"),
                                   f"is {tilt:.3f} deg off level; the closed form needs horizontal "
                                   "beams (tcp_light_barrier handles any)")
    rows, rhs, zeta = [], [], []
    for k, j in pairs:
        dz = abs(tr.p[j, 2] - tr.p[k, 2])
        if dz > 0.5:
            raise CalibrationError(("flange_poses", j),
                                   f"the pass from trigger {k} climbs {dz:.3f} mm; the closed form "
                                   "needs horizontal sweeps")
        mid = 0.5 * (tr.p[k] + tr.p[j])  # (5)
        u = tr.U[k]
        nh = _unit(np.array([-u[1], u[0], 0.0]))  # horizontal normal of the beam, z x u
        z = float(tr.P[k, 2] - mid[2])  # height of the beam plane relative to the flange origin
        rows.append([nh[0], nh[1], z * nh[0], z * nh[1]])  # (6)
        rhs.append(float(nh[:2] @ (tr.P[k, :2] - mid[:2])))
        zeta.append(z)
    M, y, zeta_arr = np.array(rows), np.array(rhs), np.array(zeta)
    if np.ptp(zeta_arr) < MIN_HEIGHT_SPREAD_MM:
        level = float(np.mean(zeta_arr))
        raise CalibrationError(("flange_poses",),
                               f"all sweeps cut the shaft at one height ({level:.1f} mm "
                               "from the flange): the runout is unobservable; add sweeps at a "
                               "second height (10 mm or more apart)")
    sv = np.linalg.svd(M / np.maximum(np.linalg.norm(M, axis=0), 1e-300), compute_uv=False)
    if len(M) < 4 or sv[-1] < 1e-6 * sv[0]:
        raise CalibrationError(("beam_ids",),
                               "the sweeps cross beams of one direction only (or too few passes): "
                               "the offset along the beam is unobservable; cross two beams at each "
                               "of two heights")
    Ax, Ay, Bx, By = np.linalg.lstsq(M, y, rcond=None)[0]
    w = np.sign(np.mean(zeta_arr)) * _unit(np.array([Bx, By, 1.0]))  # (7)
    a = R0.T @ w
    if abs(a[2]) < 1e-6:
        raise CalibrationError(("flange_poses",), "the fitted tool axis lies in the flange plane")
    q0 = R0.T @ np.array([Ax, Ay, 0.0])  # axis point at the flange origin's height, in flange
    s = q0 - (q0[2] / a[2]) * a  # (12) pierce point of the flange plane
    planes = []
    for z in np.unique(np.round(zeta_arr, 1)):
        q = R0.T @ np.array([Ax + z * Bx, Ay + z * By, z])  # (8)
        planes.append((float(q[2]), float(q[0]), float(q[1])))
    chords = [abs(float((tr.p[j] - tr.p[k]) @ _unit(cross3(w, tr.U[k])))) for k, j in pairs]
    return ShaftAxis(s, a, tuple(planes), float(np.mean(chords)), len(pairs), R0)


def shaft_axis_from_sweeps(flange_poses: object, beam_ids: object, edges: object, beams: object,
                           velocities_mm_s: object | None = None, *,
                           orientation_tol_deg: float = 0.05,
                           level_tol_deg: float = 0.05) -> ShaftAxis:
    """The shaft axis (offset at the flange and runout) from the sweeps only, equations (4)-(12).

    Stage 1 of the paper's cycle; the emulator uses it to aim the tip search. Tip triggers, if
    present, are ignored. See :func:`light_barrier_two_heights` for the parameters.

    Examples
    --------
    >>> from solvers.beam_cycle import plan_cycle, trigger_events
    >>> beams = {"bx": ([600, 0, 200], [1, 0, 0]), "by": ([600, 0, 200], [0, 1, 0])}
    >>> ev = [e for p in plan_cycle(beams, 6.0, [600, 0, 200], [10.0, 40.0]) if p.kind == "sweep"
    ...       for e in trigger_events(None, p, [1.0, -0.5, 120.0], [0.0, 0.0, 1.0], beams, 6.0)]
    >>> ax = shaft_axis_from_sweeps([e.T_base_flange for e in ev], [e.beam_id for e in ev],
    ...                             [e.edge for e in ev], beams)
    >>> np.round(ax.base_point_mm, 6).tolist(), round(ax.diameter_mm, 6)
    ([1.0, -0.5, 0.0], 6.0)
    """
    T = as_transforms(flange_poses, "flange_poses", min_count=1)
    tr = _validate(T, beam_ids, edges, beams, 1.0, velocities_mm_s)
    return _shaft_axis(tr, orientation_tol_deg, level_tol_deg)


def _tool_height(tr: _Triggers, s: FloatArray, a: FloatArray) -> float:
    """Z_h from the tip triggers, equation (14), least squares over all of them."""
    idx = np.flatnonzero(tr.tip)
    if not len(idx):
        raise CalibrationError(("edges",),
                               "no 'tip' trigger: the TCP height along the tool axis is "
                               "unobservable from enter/leave alone; add a tip search (move along "
                               "the tool axis towards a beam)")
    num, den = [], []
    for k in idx:
        w = tr.R[k] @ a
        v = tr.V[k] if np.all(np.isfinite(tr.V[k])) else w
        nv = _unit(v - (v @ tr.U[k]) * tr.U[k])
        num.append(float((tr.P[k] - tr.p[k] - tr.R[k] @ s) @ nv))
        den.append(float(w @ nv))
    num_a, den_a = np.array(num), np.array(den)
    if np.max(np.abs(den_a)) < 1e-3:
        raise CalibrationError(("edges", int(idx[0])),
                               "the tip search does not move along the tool axis towards the beam")
    return float(num_a @ den_a / (den_a @ den_a))


def light_barrier_two_heights(flange_poses: object, beam_ids: object, edges: object, beams: object,
                              tool_diameter_mm: float, velocities_mm_s: object | None = None, *,
                              orientation_tol_deg: float = 0.05, level_tol_deg: float = 0.05
                              ) -> CalibrationResult:
    """Closed-form runout/offset light-barrier calibration (the paper's method, re-derived).

    Set-up: level beams (any horizontal directions, e.g. along base x and y, crossing); the
    flange orientation ``R0`` held constant during the sweeps; horizontal straight sweeps; at
    least two sweep heights; one or more tip searches along the tool axis.

    Derivation (numbers as in ``docs/methods/light_barrier.md``). Work in base axes relative
    to the flange origin: the shaft axis is ``g + lam w`` with ``g = R0 t``, ``w = R0 a``.
    At height ``zeta`` above the flange origin its horizontal position is (4) ``A + zeta B``
    with ``B = w_xy / w_z`` and ``A = g_xy - g_z B``. During a horizontal sweep this point moves
    with the flange; the signed distance (B1) of the axis from a level beam is proportional to
    that point's horizontal offset across the beam, so enter (``-r``) and leave (``+r``) lie
    symmetrically about the instant when the axis cuts the beam line:

    (5)  ``p_mid = (p_enter + p_leave) / 2``   (the diameter drops out)
    (6)  ``nh_b . (p_mid + A + zeta B - P_b) = 0``, ``nh_b = z x u_b``, ``zeta = P_b,z - p_mid,z``

    Two beams at two heights give four equations (6) for ``A`` (2) and ``B`` (2); more passes
    are solved by least squares. Then

    (7)  ``w = sign(zeta) (B_x, B_y, 1) / |...|``, ``a = R0^T w``
    (8)  plane i: axis point ``R0^T (A + zeta_i B, zeta_i) = (dx_i, dy_i, z_i)`` in flange
    (9)  ``theta_x = atan((dx_2 - dx_1) / (z_2 - z_1))``,
         ``theta_y = atan((dy_2 - dy_1) / (z_2 - z_1))``
    (10) ``R = Ry(theta) Rx(phi)`` (about flange X first, then Y; SciPy extrinsic ``"xy"``)
    (11) ``theta = theta_x``, ``phi = -atan(tan(theta_y) cos(theta_x))``, so that ``R z = a``
    (12) offset at the flange: ``dX = dx_1 - z_1 tan(theta_x)``, ``dY = dy_1 - z_1 tan(theta_y)``
    (13) ``t = (dX, dY, 0) + Z_h a``
    (14) tip k: ``Z_h = (P_b - p_k - R_k s) . nv_k / ((R_k a) . nv_k)``, ``s = (dX, dY, 0)``

    Parameters
    ----------
    flange_poses : array (N, 4, 4)
        T_base_flange at each trigger.
    beam_ids : sequence of str
        The beam of each trigger (keys of ``beams``).
    edges : sequence of {"enter", "leave", "tip"}
    beams : mapping id -> (point_mm (3,), direction (3,))
        Beam lines in base.
    tool_diameter_mm : float
        Shaft diameter (not needed by (5)-(14); compared with the diameter the chords imply).
    velocities_mm_s : array (N, 3), optional
        Commanded TCP velocity at each trigger; without it a tip search is assumed to move
        exactly along the tool axis.

    Returns
    -------
    CalibrationResult
        ``frame`` = T_flange_tcp (z = tool axis, x = flange x projected normal to it); report
        residuals of (2)/(3) per trigger; ``extras``: runout_deg, offset_mm, theta_x_deg,
        theta_y_deg, theta_deg/phi_deg (R of (10)), base_point_mm, tool_height_mm, planes,
        diameter_measured_mm, signed_residuals_mm.

    Raises
    ------
    CalibrationError
        Bad input; no tip (``edges``); one sweep height; one beam direction; orientation not
        held (``flange_poses``, k); beam not level (``beams``, id, ``direction``).

    References
    ----------
    .. [1] S.-D. Lin et al., laser-sensor TCP calibration of runout and offset (Techman
       TM5-900), Sensors/Applied Sciences (2022), as supplied in the project's seeds.

    Examples
    --------
    >>> from solvers.beam_cycle import plan_cycle, trigger_events
    >>> beams = {"bx": ([600, 0, 200], [1, 0, 0]), "by": ([600, 0, 200], [0, 1, 0])}
    >>> ev = [e for p in plan_cycle(beams, 6.0, [600, 0, 200], [10.0, 40.0])
    ...       for e in trigger_events(None, p, [0.0, 0.0, 100.0], [0.0, 0.0, 1.0], beams, 6.0)]
    >>> res = light_barrier_two_heights([e.T_base_flange for e in ev], [e.beam_id for e in ev],
    ...                                 [e.edge for e in ev], beams, 6.0)
    >>> np.round(res.frame[:3, 3], 6).tolist()
    [0.0, 0.0, 100.0]
    """
    tr = _validate(flange_poses, beam_ids, edges, beams, tool_diameter_mm, velocities_mm_s)
    if not tr.tip.any():
        _tool_height(tr, np.zeros(3), np.array([0.0, 0.0, 1.0]))  # raises the named error
    ax = _shaft_axis(tr, orientation_tol_deg, level_tol_deg)
    a, s = ax.axis_flange, ax.base_point_mm
    z_h = _tool_height(tr, s, a)
    t = s + z_h * a  # (13)
    res = _residuals(tr, t, a)
    extras = _extras(t, a, res) | {
        "base_point_mm": s, "tool_height_mm": z_h, "planes": ax.planes,
        "diameter_measured_mm": ax.diameter_mm, "closed_form": True}
    warnings = []
    if abs(ax.diameter_mm - 2 * tr.r_mm) > DIAMETER_TOL_MM:
        warnings.append(_diameter_finding(ax.diameter_mm, 2 * tr.r_mm, "the enter/leave chords"))
    warnings += _one_way_findings(tr, a)
    report = QualityReport(residuals_mm=np.abs(res), warnings=tuple(warnings), extras=extras)
    return CalibrationResult(METHOD, tool_frame(t, a), report)


def _extras(t: FloatArray, a: FloatArray, res: FloatArray) -> dict:
    """The report's extras: pendant's own quantities and, beside them, the paper's [1]_.

    pendant: ``runout_deg``, ``offset_mm`` (the TCP's distance from the flange z axis),
    ``theta_x_deg``/``theta_y_deg`` (projection angles ``atan(a_x/a_z)``, ``atan(a_y/a_z)``),
    ``theta_deg``/``phi_deg`` (``R = Ry(theta) Rx(phi)``), ``tcp_mm``, ``axis_flange``.
    The paper (flange frame, right-handed, angles counter-clockwise about +X / +Y):
    ``base_point_mm`` = ``S = t - (t_z / a_z) a``, where the tool axis pierces the flange
    plane (the tool's base); ``paper_offset_x_mm``/``paper_offset_y_mm`` = ``(δX, δY)`` = S's
    x, y: the offset, the TCP's displacement with the rotation removed (0 for pure runout);
    ``paper_offset_mm`` = ``|S|``; ``paper_tool_height_mm`` = ``Z_h = t_z / a_z`` (S to TCP);
    ``paper_theta_x_deg``/``paper_theta_y_deg`` = ``θx``/``θy`` of the paper's
    ``R = Ry(θy) Rx(θx)`` with ``R e_z = a``: ``θy = atan(a_x / a_z)`` (pendant's
    ``theta_x_deg``), ``θx = -asin(a_y)`` (pendant's ``phi_deg``); ``paper_runout_deg`` the
    angle between the axis and flange z.
    """
    ang = runout_angles_deg(a)
    z_h = float(t[2] / a[2]) if abs(a[2]) > 1e-12 else float("nan")
    S = t - z_h * a if np.isfinite(z_h) else np.full(3, np.nan)
    S[2] = 0.0
    return {"runout_deg": ang["runout_deg"], "offset_mm": float(np.hypot(t[0], t[1])),
            "theta_x_deg": ang["theta_x_deg"], "theta_y_deg": ang["theta_y_deg"],
            "theta_deg": ang["theta_deg"], "phi_deg": ang["phi_deg"], "axis_flange": a.copy(),
            "tcp_mm": t.copy(), "signed_residuals_mm": res.copy(), "base_point_mm": S,
            "paper_runout_deg": ang["runout_deg"], "paper_theta_x_deg": ang["phi_deg"],
            "paper_theta_y_deg": ang["theta_deg"], "paper_offset_x_mm": float(S[0]),
            "paper_offset_y_mm": float(S[1]), "paper_offset_mm": float(np.hypot(S[0], S[1])),
            "paper_tool_height_mm": z_h}


def _diameter_finding(measured_mm: float, given_mm: float, source: str) -> Finding:
    return Finding("diameter_mismatch", (
        f"{source} imply a {measured_mm:.3f} mm shaft, not the {given_mm:.3f} mm given: check "
        f"tool_diameter_mm (a wrong diameter inflates the residuals and biases the TCP)"),
        ("tool_diameter_mm",))


def _diameter_fit(tr: _Triggers, res: FloatArray, J: FloatArray) -> tuple[float, float]:
    """The shaft diameter the triggers imply and its standard error (mm), at the fit.

    With the radius free, ``r_k`` gains ``-side_k δr`` (enter -1, leave +1, tip 0): the
    least-squares ``δr`` beside the 5 tool parameters is ``gᵀ res / |g_perp|²`` with
    ``g = side`` and ``g_perp`` its part orthogonal to J's columns (``res`` is already), its
    standard error ``σ' / |g_perp|`` with ``σ'² = (SSR - (gᵀres)²/|g_perp|²) / (N - 6)``.
    Returns (nan, nan) without enter/leave pairs to tell the diameter from the position.
    """
    g = np.array([0.0 if e == "tip" else (-1.0 if e == "enter" else 1.0) for e in tr.edges])
    Q, _ = np.linalg.qr(J)
    g_perp = g - Q @ (Q.T @ g)
    gg = float(g_perp @ g_perp)
    if gg < 1e-9 * max(float(g @ g), 1e-300) or tr.n <= 6:
        return float("nan"), float("nan")
    dr = float(g @ res) / gg
    ssr = max(float(res @ res) - dr * dr * gg, 0.0)
    return 2.0 * (tr.r_mm + dr), 2.0 * float(np.sqrt(ssr / (tr.n - 6) / gg))


def _one_way_findings(tr: _Triggers, a: FloatArray) -> list[Finding]:
    """``one_way_passes`` when a kind of pass ran in one direction only, so that a trigger
    latency (a trigger recorded late by a fixed distance along the motion) shifts the result
    unseen: sweeps when every beam was crossed one way only (the TCP across the beams), tip
    searches when all moved the same way along the tool axis (the TCP along the axis; without
    velocities every tip search is taken to move towards the tip). Passes both ways put the
    latency into the residuals, where it shows."""
    kinds = []
    seen: dict[str, set[bool]] = {}
    for k in np.flatnonzero(tr.sweep):
        nvec = cross3(tr.R[k] @ a, tr.U[k])
        seen.setdefault(tr.beam_ids[k], set()).add(bool(nvec @ tr.V[k] >= 0))
    if seen and all(len(v) == 1 for v in seen.values()):
        kinds.append("every beam was crossed in one direction only (the TCP across the beams)")
    tips = np.flatnonzero(tr.tip)
    ways = {bool(np.all(np.isfinite(tr.V[k])) and (tr.R[k] @ a) @ tr.V[k] < 0) for k in tips}
    if len(tips) and len(ways) == 1:
        way = "out of the beam (back along the axis)" if ways.pop() else "towards the tip"
        kinds.append(f"every tip search moved {way} (the TCP along the tool axis)")
    if not kinds:
        return []
    return [Finding("one_way_passes", (
        "; ".join(kinds) + ": a trigger latency shifts the result there unseen (0.2 mm late "
        "moves it 0.2 mm); passes both ways would show it in the residuals"),
        ("velocities_mm_s",))]


# ----------------------------------------------------------------------------- least squares


def _heights_along_axis(tr: _Triggers, t: FloatArray, a: FloatArray) -> FloatArray:
    """Axis parameter (mm from the TCP) of the point closest to the beam, per enter/leave."""
    c = np.einsum("kij,j->ki", tr.R, t) + tr.p
    w = np.einsum("kij,j->ki", tr.R, a)
    dvec = c - tr.P
    b = np.einsum("ki,ki->k", w, tr.U)
    along_u, along_w = np.einsum("ki,ki->k", tr.U, dvec), np.einsum("ki,ki->k", w, dvec)
    lam = (b * along_u - along_w) / np.maximum(1 - b * b, 1e-12)
    return lam[tr.sweep]


def _linear_tcp(tr: _Triggers, a: FloatArray) -> FloatArray:
    """TCP for a fixed axis: (2) and (3) are linear in t once ``a`` is fixed."""
    w = np.einsum("kij,j->ki", tr.R, a)
    rows, rhs = [], []
    for k in range(tr.n):
        if tr.edges[k] == "tip":
            v = tr.V[k] if np.all(np.isfinite(tr.V[k])) else w[k]
            nrm = v - (v @ tr.U[k]) * tr.U[k]
            target = 0.0
        else:
            nrm = cross3(w[k], tr.U[k])
            nrm = nrm * (1.0 if nrm @ tr.V[k] >= 0 else -1.0)
            target = -tr.r_mm if tr.edges[k] == "enter" else tr.r_mm
        size = float(np.linalg.norm(nrm))
        if size < 1e-9:
            continue  # axis along the beam (or tip search along it): no information
        nrm = nrm / size
        rows.append(nrm @ tr.R[k])
        rhs.append(target - float(nrm @ (tr.p[k] - tr.P[k])))
    if not rows:
        raise CalibrationError(("beams",), "every beam runs along the tool axis: nothing is measured")
    return np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0]


def _fit(tr: _Triggers, t0: FloatArray, a0: FloatArray, rounds: int = 2
         ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Levenberg-Marquardt on (t, two tilts of a about a0) with the analytic Jacobian; returns
    t, a and the Jacobian (N, 5) at the solution in mm per (mm, mm, mm, rad, rad)."""
    t, a = t0.copy(), _unit(a0)

    def model(x: FloatArray, a_c: FloatArray, e: FloatArray
              ) -> tuple[FloatArray, FloatArray, FloatArray]:
        raw = a_c + e @ x[3:]
        norm = np.linalg.norm(raw)
        a_x = raw / norm
        res, jt, ja = _residuals(tr, x[:3], a_x, jacobian=True)
        da = (np.eye(3) - np.outer(a_x, a_x)) / norm @ e  # d a / d (alpha, beta), (3, 2)
        return res, np.hstack([jt, ja @ da]), a_x

    for _ in range(rounds):  # a second round re-centres the tilt parameters on the solution
        e = np.column_stack(_tangent_basis(a))
        sol = least_squares(lambda x, a_c=a, e=e: model(x, a_c, e)[0], np.r_[t, 0.0, 0.0],
                            jac=lambda x, a_c=a, e=e: model(x, a_c, e)[1],
                            method="lm" if tr.n >= 5 else "trf", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                            max_nfev=500)
        t, a = sol.x[:3].copy(), model(sol.x, a, e)[2]
    _, J, _ = model(np.r_[t, 0.0, 0.0], a, np.column_stack(_tangent_basis(a)))
    return t, a, J


def _subset(tr: _Triggers, idx: Sequence[int]) -> _Triggers:
    i = np.asarray(idx, dtype=int)
    return _Triggers(tr.R[i], tr.p[i], tr.P[i], tr.U[i], tr.V[i], tuple(tr.edges[k] for k in i),
                     tuple(tr.beam_ids[k] for k in i), tr.r_mm, tr.has_velocity)


def _check_observable(tr: _Triggers) -> None:
    if not tr.tip.any():
        _tool_height(tr, np.zeros(3), np.array([0.0, 0.0, 1.0]))  # raises the named error
    if not tr.sweep.any():
        raise CalibrationError(("edges",), "no enter/leave triggers: the tool axis is "
                               "unobservable; sweep the shaft across the beams at two heights")
    lam = _heights_along_axis(tr, np.zeros(3), np.array([0.0, 0.0, 1.0]))
    if np.ptp(lam) < MIN_HEIGHT_SPREAD_MM:
        raise CalibrationError(("flange_poses",),
                               f"all enter/leave passes cut the shaft at one height "
                               f"({np.mean(lam):.1f} mm along the flange axis): the runout is "
                               "unobservable; add passes at a second height (10 mm or more apart)")


def _initial(tr: _Triggers) -> tuple[FloatArray, FloatArray, bool]:
    """Start from the closed form when its set-up holds, else from the flange axis."""
    try:
        ax = _shaft_axis(tr, orientation_tol_deg=1.0, level_tol_deg=1.0)
        a = ax.axis_flange
        return ax.base_point_mm + _tool_height(tr, ax.base_point_mm, a) * a, a, True
    except CalibrationError:
        a = np.array([0.0, 0.0, 1.0])
        return _linear_tcp(tr, a), a, False


def tcp_light_barrier(flange_poses: object, beam_ids: object, edges: object, beams: object,
                      tool_diameter_mm: float, velocities_mm_s: object | None = None, *,
                      find_bad_point: bool = True) -> CalibrationResult:
    """Tool > Light barrier: TCP and tool axis in flange from all beam triggers at once.

    Minimises ``sum_k r_k^2`` over the TCP ``t`` (3, mm) and the axis ``a`` (2 tilt angles),
    with ``r_k`` the signed distance error of trigger k (module doc (1)-(3)): for enter/leave
    ``(c_k - P_b) . m_k -/+ d/2`` (the axis' signed distance from the beam, oriented along the
    motion, minus its value at the edge), for a tip ``(c_k - P_b) . nv_k`` (the TCP's distance
    from the plane through the beam normal to the motion). Levenberg-Marquardt started from
    the closed form :func:`light_barrier_two_heights` (or from the flange axis when its set-up
    does not hold). Covariance ``(J^T J)^-1 sigma^2`` with ``sigma^2 = SSR / (N - 5)``.

    Parameters
    ----------
    flange_poses : array (N, 4, 4)
        T_base_flange at each trigger.
    beam_ids : sequence of str
        Beam of each trigger; keys of ``beams``.
    edges : sequence of {"enter", "leave", "tip"}
    beams : mapping id -> (point_mm (3,), direction (3,))
        Beam lines in base.
    tool_diameter_mm : float
        Shaft diameter (mm).
    velocities_mm_s : array (N, 3), optional
        Commanded TCP velocity (base) per trigger: gives the approach side of enter/leave and
        the tip plane. Without it the side is inferred from the enter -> leave motion of the
        same beam, and a tip search is assumed to move exactly along the tool axis.
    find_bad_point : bool, keyword-only
        Search for the one trigger that disagrees (leave one out: one refit per trigger, most
        of the solve time). False skips it (batch and Monte Carlo runs); the frame, the
        covariance and the bounds do not depend on it.

    Returns
    -------
    CalibrationResult
        ``frame`` = T_flange_tcp: origin the TCP, z the fitted tool axis, x the flange x axis
        projected normal to it (:func:`tool_frame`). ``report``: ``residuals_mm`` |r_k|,
        covariance of ``PARAMETER_NAMES`` (mm, deg), ``sigma_mm`` with ``dof = N - 5``, 95%
        bounds of the TCP position, the axis angle and the Mahalanobis distance (F quantiles
        of N - 5 dof), a bad trigger if one disagrees, findings ``diameter_mismatch`` (the
        triggers imply another shaft diameter) and ``one_way_passes`` (sweeps or tip searches
        one way only: latency unseen); ``extras`` runout_deg (tool axis vs flange z),
        offset_mm (TCP's distance from the flange axis), theta_x/y_deg, theta/phi_deg,
        tool_height_mm, tcp_mm, axis_flange, signed_residuals_mm, diameter_measured_mm,
        diameter_standard_error_mm and the paper's terms (``paper_*``, ``base_point_mm``;
        see :func:`_extras`).

    Raises
    ------
    CalibrationError
        Shapes, NaN, unknown beam id (``beam_ids``, k), unknown edge (``edges``, k); no tip
        trigger (``edges``: "add a tip search"); enter/leave at one height only
        (``flange_poses``: runout unobservable); triggers that do not fix the tool.

    Examples
    --------
    >>> from solvers.beam_cycle import plan_cycle, trigger_events
    >>> beams = {"bx": ([600, 0, 200], [1, 0, 0]), "by": ([600, 0, 200], [0, 1, 0])}
    >>> ev = [e for p in plan_cycle(beams, 6.0, [600, 0, 200], [10.0, 40.0])
    ...       for e in trigger_events(None, p, [0.5, 0.0, 105.0], [0.0, 0.0, 1.0], beams, 6.0)]
    >>> res = tcp_light_barrier([e.T_base_flange for e in ev], [e.beam_id for e in ev],
    ...                         [e.edge for e in ev], beams, 6.0, [e.tcp_velocity_mm_s for e in ev])
    >>> np.round(res.frame[:3, 3], 6).tolist(), round(res.report.extras["offset_mm"], 6)
    ([0.5, 0.0, 105.0], 0.5)
    """
    tr = _validate(flange_poses, beam_ids, edges, beams, tool_diameter_mm, velocities_mm_s)
    _check_observable(tr)
    t0, a0, closed = _initial(tr)
    t, a, J = _fit(tr, t0, a0)
    Js = J / np.maximum(np.linalg.norm(J, axis=0), 1e-300)
    sv = np.linalg.svd(Js, compute_uv=False)
    if tr.n < 5 or sv[-1] < 1e-7 * sv[0]:
        _, _, vt = np.linalg.svd(Js)
        worst = PARAMETER_NAMES[int(np.argmax(np.abs(vt[-1])))]
        raise CalibrationError(("flange_poses",),
                               f"the triggers do not determine the tool ({worst} is unobservable): "
                               "cross two non-parallel beams at two heights and add a tip search")
    res = _residuals(tr, t, a)
    sigma = residual_sigma(res, 5)
    scale = np.array([1.0, 1.0, 1.0, np.degrees(1.0), np.degrees(1.0)])  # rad -> deg for the tilts
    cov = np.linalg.inv(J.T @ J) * sigma**2 * np.outer(scale, scale)
    diameter, diameter_se = _diameter_fit(tr, res, J)

    def fit(indices: Sequence[int]):
        sub = _subset(tr, indices)
        _check_observable(sub)
        ts, as_, Jsub = _fit(sub, t, a, rounds=1)
        Jn = Jsub / np.maximum(np.linalg.norm(Jsub, axis=0), 1e-300)
        if np.linalg.matrix_rank(Jn, tol=1e-7) < 5:
            raise CalibrationError(("flange_poses",), "subset does not determine the tool")
        full = _residuals(tr, ts, as_)
        return tool_frame(ts, as_), lambda i: float(abs(full[i]))

    bad = (leave_one_out_bad_point(tr.n, fit, 5, floor_mm=0.02, k_sigma=4.0, min_points=10)
           if find_bad_point else None)
    warnings = []
    if abs(diameter - 2 * tr.r_mm) > max(DIAMETER_TOL_MM, 4.0 * diameter_se):
        warnings.append(_diameter_finding(diameter, 2 * tr.r_mm, "the enter/leave triggers"))
    warnings += _one_way_findings(tr, a)
    if not tr.has_velocity:
        warnings.append(Finding(
            "no_velocities", "no TCP velocities: approach sides inferred from the motion, tip "
            "searches assumed to move exactly along the tool axis", ("velocities_mm_s",),
            severity="info"))
    height = float(t[2] / a[2]) if abs(a[2]) > 1e-12 else None
    extras = _extras(t, a, res) | {"tool_height_mm": height, "closed_form_start": closed,
                                   "diameter_measured_mm": diameter,
                                   "diameter_standard_error_mm": diameter_se}
    report = QualityReport(
        residuals_mm=np.abs(res), parameter_names=PARAMETER_NAMES, covariance=cov, sigma_mm=sigma,
        **bounds95(cov, tr.n - 5, position=slice(0, 3), angle=slice(3, 5)),
        bad_point=bad, warnings=tuple(warnings),
        guidance=None if bad is None else bad.message(), extras=extras)
    return CalibrationResult(METHOD, tool_frame(t, a), report)
