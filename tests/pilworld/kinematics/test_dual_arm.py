"""Dual-arm composition: each side is base pose · FK · TCP of its own 6 joints."""

from __future__ import annotations

import numpy as np
import pytest

from pilworld.geometry import pose_to_matrix
from pilworld.kinematics import dh_params, fk
from pilworld.kinematics.dual_arm import ArmMount, DualArmKinematics


def _kin() -> DualArmKinematics:
    tcp = pose_to_matrix(np.array([0.0, 0.0, 0.15]), np.zeros(3))
    left = ArmMount(dh_params("ur5e"), pose_to_matrix(np.array([-0.4, 0.3, 0.0]), np.array([0, 0, np.pi])), tcp)
    right = ArmMount(dh_params("ur3e"), pose_to_matrix(np.array([-0.4, -0.3, 0.1]), np.array([0.1, 0, 3.0])), tcp)
    return DualArmKinematics(left, right)


def test_gripper_points_compose_each_arm_independently() -> None:
    kin = _kin()
    q = np.random.default_rng(0).uniform(-3, 3, size=(20, 14))
    pts = kin.gripper_points(q)
    assert pts.shape == (20, 2, 3)
    for i in range(20):
        for side, sl, mount in ((0, slice(0, 6), kin.left), (1, slice(7, 13), kin.right)):
            T = mount.T_rig_base @ fk(q[i, sl], mount.dh) @ mount.T_flange_tcp
            np.testing.assert_allclose(pts[i, side], T[:3, 3], atol=1e-12)
    # Grip entries do not move the points.
    q2 = q.copy()
    q2[:, [6, 13]] += 0.7
    np.testing.assert_array_equal(kin.gripper_points(q2), pts)
    np.testing.assert_array_equal(kin.gripper_openings(q2), q2[:, [6, 13]])


def test_dual_arm_errors() -> None:
    kin = _kin()
    with pytest.raises(ValueError, match=r"q14 must have shape \(\.\.\., 14\); got shape \(13,\)"):
        kin.gripper_points(np.zeros(13))
    with pytest.raises(ValueError, match="q14 must contain only finite values; got nan at index"):
        kin.gripper_points(np.full(14, np.nan))
    with pytest.raises(ValueError, match="T_rig_base: expected a rigid 4x4"):
        ArmMount(dh_params("ur5e"), np.eye(4) * 2, np.eye(4))
