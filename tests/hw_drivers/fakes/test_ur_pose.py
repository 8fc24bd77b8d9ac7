"""UR pose vectors <-> transforms (hw_drivers/fakes/ur_pose.py) and the path lines the fake controller reads."""

from __future__ import annotations

import numpy as np
import pytest

from hw_drivers.fakes.ur_pose import interpolate, matrix_to_pose, matrix_to_rotvec, pose_to_matrix, rotvec_to_matrix
from hw_drivers.fakes.ur_protocol import parse_path


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-5, 0.5, 2.0, np.pi - 1e-3, np.pi - 1e-7])
def test_rotvec_round_trip(angle: float) -> None:
    rng = np.random.default_rng(1)
    for _ in range(20):
        axis = rng.normal(size=3)
        rv = axis / np.linalg.norm(axis) * angle
        R = rotvec_to_matrix(rv)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(rotvec_to_matrix(matrix_to_rotvec(R)), R, atol=1e-9)
        if angle < np.pi - 1e-3:  # at pi, rv and -rv are the same rotation
            np.testing.assert_allclose(matrix_to_rotvec(R), rv, atol=1e-9)


def test_pose_round_trip_and_bad_input() -> None:
    pose = np.array([0.1, -0.2, 0.3, 0.4, -0.5, 0.6])
    np.testing.assert_allclose(matrix_to_pose(pose_to_matrix(pose)), pose, atol=1e-12)
    with pytest.raises(ValueError, match="pose"):
        pose_to_matrix([0.0, 0.0, np.nan, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="pose"):
        pose_to_matrix([0.0, 0.0, 0.0])


def test_interpolate_ends_and_middle() -> None:
    T0, T1 = pose_to_matrix([0, 0, 0, 0, 0, 0]), pose_to_matrix([1.0, 2.0, 3.0, 0, 0, 1.0])
    np.testing.assert_allclose(interpolate(T0, T1, 0.0), T0, atol=1e-12)
    np.testing.assert_allclose(interpolate(T0, T1, 1.0), T1, atol=1e-12)
    np.testing.assert_allclose(matrix_to_pose(interpolate(T0, T1, 0.5)), [0.5, 1.0, 1.5, 0, 0, 0.5], atol=1e-12)


def test_parse_path_reads_ur_rtde_waypoint_lines() -> None:
    body = "\tsignal_async_progress(0)\n\tmovej([0.1,0.2,0.3,0.4,0.5,0.6],a=1.4,v=1.05,r=0.01)\n"
    body += "\tsignal_async_progress(1)\n\tmovel(p[0.5,0,0.3,0,3.14,0],a=0.5,v=0.25,r=0)\n\ttextmsg(1)\n"
    path = parse_path(body)
    assert [(m, p, v) for m, p, _, v in path] == [("movej", False, 1.05), ("movel", True, 0.25)]
    np.testing.assert_allclose(path[1][2], [0.5, 0, 0.3, 0, 3.14, 0])
    assert parse_path("def rtde_control():\n  textmsg(1)\n") == []
