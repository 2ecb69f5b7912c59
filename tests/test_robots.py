"""The robot library against independent published data: URDF chains and published poses.

Each arm's DH table in ``solvers/robots.py`` is checked against the vendor's or
ROS-Industrial's URDF, whose joint origins and axes were copied into
``tests/data/urdf_chains.json`` (each entry names its repository, path and commit). A tiny
URDF forward kinematics written here, independent of ``solvers/dh.py``,

    T_root_link = prod_k  Trans(xyz_k) @ RPY(rpy_k) @ Rot(axis_k, q_k),

with URDF's fixed-axis roll-pitch-yaw ``RPY = Rz(yaw) Ry(pitch) Rx(roll)``
(``Rotation.from_euler("xyz", rpy)``), gives ``T_base_tool0`` from the URDF's ROS-Industrial
``base`` frame (the controller's base/World frame) to its ``tool0`` (the controller's
flange frame). The library must satisfy

    T_base_flange_lib(q) = C_base @ T_base_tool0_urdf(M q) @ C_flange

for constant ``C_base`` and ``C_flange``; ``M`` maps controller joints to URDF joints
(identity, but for FANUC's J2/J3 coupling: URDF joint_3 = J3 + J2, fanuc_driver's
``J23_factor = 1`` for the LR Mate 200iD).

Constants found (``C_base`` is taken as the identity, ``C_flange`` is computed from
configuration 0 and must reproduce configurations 1..19 to 1e-6 mm / 1e-9 rad):

==================  ========  =========================================================
arm                 C_base    C_flange
==================  ========  =========================================================
kuka_kr6_r900_sixx  identity  identity   (URDF base = $ROBROOT, tool0 = $FLANGE)
abb_irb120          identity  identity   (URDF base = World,    tool0 = tool0)
ur5e, ur10          identity  identity   (URDF base = UR Base,  tool0 = tool flange);
                                         |t| < 1e-7 mm from the yaml's 2e-11 m residues
tm5_900             identity  identity   (URDF base = link_0,   tool0 = flange_link)
fanuc_lrmate200id   identity  identity   (URDF base = World, 330 mm above base_link)
==================  ========  =========================================================

So base and flange frames agree exactly, positions and orientations. The strict check
snaps joint-origin angles within 1e-6 rad of a multiple of 90 deg to it: Techman's file
writes pi/2 as 1.570796 (3.3e-7 rad short, 5e-4 mm at the flange); a second check runs the
literal file numbers at a tolerance that covers that rounding.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from solvers.dh import forward_kinematics
from solvers.robots import ROBOTS

CHAINS: dict = json.loads((Path(__file__).parent / "data" / "urdf_chains.json").read_text())
ARMS = sorted(k for k in CHAINS if not k.startswith("_"))
N_CONFIGS = 20
POS_TOL_MM = 1e-6
ROT_TOL_RAD = 1e-9


# --- an independent URDF forward kinematics -------------------------------------------------

def _snap_right_angles(rpy_rad: np.ndarray, tol_rad: float = 1e-6) -> np.ndarray:
    """Angles within ``tol_rad`` of a multiple of pi/2 become that multiple (file rounding)."""
    k = np.round(rpy_rad / (np.pi / 2))
    return np.where(np.abs(rpy_rad - k * np.pi / 2) < tol_rad, k * np.pi / 2, rpy_rad)


def _origin(joint: dict, snap: bool) -> np.ndarray:
    """Joint origin ``Trans(xyz) @ RPY(rpy)`` in mm; URDF rpy is fixed-axis X, Y, Z."""
    rpy = np.asarray(joint["rpy_rad"], dtype=float)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", _snap_right_angles(rpy) if snap else rpy).as_matrix()
    T[:3, 3] = np.asarray(joint["xyz_m"], dtype=float) * 1000.0
    return T


def _chain(joints: list[dict], q_rad: np.ndarray, snap: bool) -> np.ndarray:
    T = np.eye(4)
    k = 0
    for joint in joints:
        T = T @ _origin(joint, snap)
        if joint["type"] == "revolute":
            Rq = np.eye(4)
            axis = np.asarray(joint["axis"], dtype=float)
            Rq[:3, :3] = Rotation.from_rotvec(axis * q_rad[k]).as_matrix()
            T = T @ Rq
            k += 1
    return T


def urdf_base_tool0(arm: str, q_controller_deg: np.ndarray, snap: bool = True) -> np.ndarray:
    """``T_base_tool0`` (mm) of the URDF at the controller's joint values (degrees)."""
    c = CHAINS[arm]
    q_urdf = np.radians(np.asarray(c["controller_to_urdf"], dtype=float) @ q_controller_deg)
    T_root_tool0 = _chain(c["chain"], q_urdf, snap)
    T_root_base = _chain(c["base_chain"], np.zeros(0), snap)
    return np.linalg.inv(T_root_base) @ T_root_tool0


def _rotation_angle_rad(R1: np.ndarray, R2: np.ndarray) -> float:
    return float(Rotation.from_matrix(R1.T @ R2).magnitude())


def _configs(arm: str) -> np.ndarray:
    """20 random joint vectors inside the library's limits (seeded per arm)."""
    lim = ROBOTS[arm].limits_deg()
    rng = np.random.default_rng(sum(map(ord, arm)))
    return rng.uniform(lim[:, 0], lim[:, 1], size=(N_CONFIGS, ROBOTS[arm].dof))


# --- the chains in the JSON are the ones the library names -----------------------------------

def test_every_library_arm_has_a_urdf_chain_with_a_source():
    assert set(ARMS) == set(ROBOTS)
    for arm in ARMS:
        src = CHAINS[arm]["source"]
        assert src["repo"] and src["path"] and len(src["commit"]) == 40, arm
        n_rev = sum(j["type"] == "revolute" for j in CHAINS[arm]["chain"])
        assert n_rev == ROBOTS[arm].dof, arm


# --- forward kinematics: library vs URDF ----------------------------------------------------

@pytest.mark.parametrize("arm", ARMS)
def test_library_flange_matches_urdf_tool0_up_to_constant_frames(arm):
    """T_lib(q) = C_base @ T_urdf(q) @ C_flange with C_base = I and one C_flange for all q."""
    robot = ROBOTS[arm]
    q = _configs(arm)
    T_lib = forward_kinematics(robot, q)
    T_urdf = np.array([urdf_base_tool0(arm, qk) for qk in q])
    C_base = np.eye(4)
    C_flange = np.linalg.inv(C_base @ T_urdf[0]) @ T_lib[0]
    for k in range(1, N_CONFIGS):
        T = C_base @ T_urdf[k] @ C_flange
        dp = np.abs(T[:3, 3] - T_lib[k][:3, 3]).max()
        dr = _rotation_angle_rad(T[:3, :3], T_lib[k][:3, :3])
        where = f"{arm} config {k} (q={np.round(q[k], 3).tolist()})"
        assert dp < POS_TOL_MM, f"{where}: position off {dp:.3g} mm"
        assert dr < ROT_TOL_RAD, f"{where}: orientation off {dr:.3g} rad"
    # The constant itself: the flange origins coincide and the frames are the same frame.
    offset_mm = C_flange[:3, 3]
    assert np.linalg.norm(offset_mm) < POS_TOL_MM, f"{arm}: flange origins differ by {offset_mm}"
    angle_rad = _rotation_angle_rad(C_flange[:3, :3], np.eye(3))
    assert angle_rad < ROT_TOL_RAD, f"{arm}: flange frames rotated by {angle_rad:.3g} rad"


@pytest.mark.parametrize("arm", ARMS)
def test_literal_urdf_numbers_within_their_rounding(arm):
    """Unsnapped file numbers: within the rounding of the files (TM: 6-decimal pi/2)."""
    q = _configs(arm)
    T_lib = forward_kinematics(ROBOTS[arm], q)
    for k in range(N_CONFIGS):
        T = urdf_base_tool0(arm, q[k], snap=False)
        assert np.abs(T[:3, 3] - T_lib[k][:3, 3]).max() < 2e-3, arm
        assert _rotation_angle_rad(T[:3, :3], T_lib[k][:3, :3]) < 3e-6, arm


def test_fanuc_coupling_is_needed():
    """Without the J2/J3 coupling the LR Mate 200iD table would not match its URDF."""
    arm = "fanuc_lrmate200id"
    q = np.array([10.0, 30.0, -20.0, 40.0, 50.0, 60.0])
    c = CHAINS[arm]
    uncoupled = np.radians(q)
    T_root_base = _chain(c["base_chain"], np.zeros(0), True)
    T_uncoupled = np.linalg.inv(T_root_base) @ _chain(c["chain"], uncoupled, True)
    T_lib = forward_kinematics(ROBOTS[arm], q)
    assert np.allclose(urdf_base_tool0(arm, q), T_lib, atol=1e-9)
    assert np.abs(T_uncoupled[:3, 3] - T_lib[:3, 3]).max() > 50.0


# --- published poses -----------------------------------------------------------------------

def _R_xyz_fixed(deg):
    """Fixed-axis X, Y, Z (= FANUC W, P, R = URDF rpy): R = Rz(c) Ry(b) Rx(a)."""
    return Rotation.from_euler("xyz", deg, degrees=True).as_matrix()


PUBLISHED_ZERO_POSES = {
    # arm: (flange position mm at all joints zero, expected flange rotation, what says so)
    "kuka_kr6_r900_sixx": (
        (980.0, 0.0, 435.0),
        Rotation.from_euler("ZYX", [0, 90, 0], degrees=True).as_matrix(),  # A, B, C = 0, 90, 0
        "KR 6 R900 sixx $FLANGE at A1..A6 = 0; ABC from URDF tool0 rpy (0, 90 deg, 0)"),
    "abb_irb120": (
        (374.0, 0.0, 630.0),
        # scipy quat is x, y, z, w; ABB q1..q4 = 0.7071, 0, 0.7071, 0
        Rotation.from_quat([0, np.sqrt(0.5), 0, np.sqrt(0.5)]).as_matrix(),
        "IRB 120 tool0 at zero; quaternion from URDF tool0 rpy (0, 90 deg, 0)"),
    "ur5e": ((-817.2, -232.9, 62.8), None,
             "UR5e at zero in the UR Base frame (a2+a3, -(d4+d6), d1-d5)"),
    "ur10": ((-1184.3, -256.141, 11.6), None,
             "UR10 CB3 at zero in the UR Base frame (a2+a3, -(d4+d6), d1-d5)"),
    "fanuc_lrmate200id": ((465.0, 0.0, 365.0), _R_xyz_fixed([180, -90, 0]),  # W, P, R = 180, -90, 0
                          "LR Mate 200iD faceplate at zero in World; WPR from URDF tool0 rpy"),
    # No published TM5-900 zero pose at hand: derived from the URDF (z = 145.2 + 429 + 411.5 + 106,
    # y = -122.3 - 113.15), tool z along base -y.
    "tm5_900": ((0.0, -235.45, 1091.7), Rotation.from_euler("x", 90, degrees=True).as_matrix(),
                "TM5-900 at zero, from macro.tm5-900-nominal.urdf.xacro"),
}


@pytest.mark.parametrize("arm", sorted(PUBLISHED_ZERO_POSES))
def test_published_zero_pose(arm):
    position_mm, R_expected, _what = PUBLISHED_ZERO_POSES[arm]
    T = forward_kinematics(ROBOTS[arm], np.zeros(ROBOTS[arm].dof))
    assert np.allclose(T[:3, 3], position_mm, atol=1e-9), f"{arm}: {T[:3, 3]} != {position_mm}"
    T_urdf = urdf_base_tool0(arm, np.zeros(ROBOTS[arm].dof))
    assert np.allclose(T_urdf[:3, 3], position_mm, atol=1e-7), f"{arm} URDF: {T_urdf[:3, 3]}"
    if R_expected is not None:
        assert _rotation_angle_rad(T[:3, :3], R_expected) < 1e-12, arm


# --- joint limits ---------------------------------------------------------------------------

# Library limits that legitimately differ from the URDF's: (arm, joint index 0-based) -> why.
KNOWN_LIMIT_DIFFERENCES = {
    ("ur5e", 2): "URDF elbow +-180 deg is 'artificially' half the real +-360 (universal_robot#265)",
    ("ur10", 2): "URDF elbow +-pi is 'artificially' half the real +-2 pi (universal_robot #265)",
}
LIMIT_TOL_DEG = 0.2  # URDF limits are rad to 3-6 decimals (FANUC J1: 2.965 rad = 169.88 deg)


def _limit_differences(arm: str) -> dict[int, tuple]:
    revolute = [j for j in CHAINS[arm]["chain"] if j["type"] == "revolute"]
    lib = ROBOTS[arm].limits_deg()
    out = {}
    for i, j in enumerate(revolute):
        urdf_deg = np.degrees(j["limit_rad"])
        if np.abs(urdf_deg - lib[i]).max() > LIMIT_TOL_DEG:
            out[i] = (tuple(round(float(v), 2) for v in lib[i]),
                      tuple(round(float(v), 2) for v in urdf_deg))
    return out


@pytest.mark.parametrize("arm", ARMS)
def test_joint_limits_against_urdf(arm):
    """Where the library cites the URDF for its limits they must be the URDF's; elsewhere (data
    sheets) only the documented differences are allowed, so a new one is noticed."""
    diffs = _limit_differences(arm)
    cites_urdf = "limits: same urdf" in ROBOTS[arm].source.lower()
    unexplained = {i: d for i, d in diffs.items() if (arm, i) not in KNOWN_LIMIT_DIFFERENCES}
    if cites_urdf:
        detail = "; ".join(f"J{i + 1}: library {d[0]} vs URDF {d[1]} deg" for i, d in diffs.items())
        assert not diffs, f"{arm} cites its URDF for the limits, but {detail}"
    else:
        assert not unexplained, f"{arm}: undocumented limit differences: {unexplained}"
