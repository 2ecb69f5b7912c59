"""Conventions: every controller's pose notation round-trips through one 4x4 transform."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from solvers import frames
from solvers.errors import CalibrationError
from solvers.validate import as_array, as_transforms

coord = st.floats(-5000, 5000, allow_nan=False)
quats = st.lists(st.floats(-1, 1, allow_nan=False), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1)


# Within ~1e-7 rad of gimbal lock (B = +-90 deg) SciPy's as_euler treats the rotation as
# locked and sets the third angle to 0; the round trip is then exact only to about that
# angle (seen: 6e-8), hence 2e-7 (0.2 um at a 1 m lever) rather than machine precision.
GIMBAL_ATOL = 2e-7


def _T(q, t):
    return frames.rotation_matrix(Rotation.from_quat(q), t)


@settings(max_examples=200, deadline=None)
@given(quats, st.lists(coord, min_size=3, max_size=3))
def test_kuka_abc_round_trip(q, t):
    T = _T(q, t)
    assert np.allclose(frames.matrix_from_kuka(frames.kuka_from_matrix(T)), T, atol=GIMBAL_ATOL)


@settings(max_examples=200, deadline=None)
@given(quats, st.lists(coord, min_size=3, max_size=3))
def test_abb_quaternion_round_trip_scalar_first_and_canonical(q, t):
    T = _T(q, t)
    pos, quat = frames.abb_from_matrix(T)
    assert quat[0] >= 0 and np.isclose(np.linalg.norm(quat), 1)
    assert np.allclose(frames.matrix_from_abb(pos, quat), T, atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(quats, st.lists(coord, min_size=3, max_size=3))
def test_fanuc_wpr_round_trip(q, t):
    T = _T(q, t)
    assert np.allclose(frames.matrix_from_fanuc(frames.fanuc_from_matrix(T)), T, atol=GIMBAL_ATOL)


@settings(max_examples=200, deadline=None)
@given(quats, st.lists(coord, min_size=3, max_size=3))
def test_ur_rotation_vector_in_metres_round_trip(q, t):
    T = _T(q, t)
    p = frames.ur_from_matrix(T)
    assert np.allclose(p[:3] * 1000, T[:3, 3])
    assert np.linalg.norm(p[3:]) <= np.pi + 1e-9
    assert np.allclose(frames.matrix_from_ur(p), T, atol=1e-9)


def test_kuka_abc_is_rz_ry_rx():
    """A, B, C compose as Rz(A) Ry(B) Rx(C), written out with elementary rotations."""
    a, b, c = 30.0, -20.0, 75.0
    Rz = Rotation.from_rotvec([0, 0, np.radians(a)]).as_matrix()
    Ry = Rotation.from_rotvec([0, np.radians(b), 0]).as_matrix()
    Rx = Rotation.from_rotvec([np.radians(c), 0, 0]).as_matrix()
    assert np.allclose(frames.matrix_from_kuka([0, 0, 0, a, b, c])[:3, :3], Rz @ Ry @ Rx)


def test_fanuc_wpr_is_rz_ry_rx_of_r_p_w():
    w, p, r = 10.0, 20.0, 30.0
    assert np.allclose(frames.matrix_from_fanuc([0, 0, 0, w, p, r]),
                       frames.matrix_from_kuka([0, 0, 0, r, p, w]))


def test_abb_q1_is_the_scalar():
    """A 90 deg turn about z is [cos45, 0, 0, sin45] in ABB's order."""
    _, q = frames.abb_from_matrix(frames.matrix_from_kuka([0, 0, 0, 90, 0, 0]))
    assert np.allclose(q, [np.sqrt(0.5), 0, 0, np.sqrt(0.5)])


def test_invert_and_stacks():
    T = frames.matrix_from_kuka(np.array([[1, 2, 3, 10, 20, 30], [4, 5, 6, -40, 50, 60]]))
    assert np.allclose(T @ frames.invert(T), np.eye(4))


def test_nan_named_by_index():
    with pytest.raises(CalibrationError) as e:
        as_array([[0, 1, 2], [3, np.nan, 5]], "points_mm", (None, 3))
    assert e.value.loc == ("points_mm", 1, 1)


def test_not_a_rotation_named_by_pose():
    T = np.tile(np.eye(4), (3, 1, 1))
    T[2, 0, 0] = 2.0
    with pytest.raises(CalibrationError) as e:
        as_transforms(T, "flange_poses")
    assert e.value.loc == ("flange_poses", 2) and "rotation" in e.value.reason
