"""Closed-form UR inverse kinematics: round trips through FK, branches, singularities, limits, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pilworld.kinematics import IK_JOINT_WEIGHTS, DHParams, IKError, dh_params, fk, ik_all, ik_nearest, ik_solve

MODELS = ("ur5e", "ur3e", "ur10e", "ur5")
N_RANDOM = 500


def _random_q(model: str, n: int = N_RANDOM) -> np.ndarray:
    rng = np.random.default_rng(sum(map(ord, model)))  # fixed per model: failures are reproducible
    return rng.uniform(-(math.pi - 0.1), math.pi - 0.1, size=(n, 6))


def _angle_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - b| modulo 2 pi, elementwise."""
    return np.asarray(np.abs((a - b + math.pi) % (2 * math.pi) - math.pi), dtype=np.float64)


def _pose_errors(q: np.ndarray, T: np.ndarray, dh: DHParams, tcp: np.ndarray | None = None) -> tuple[float, float]:
    """Worst position [m] and rotation-matrix-entry error of fk(q) against T."""
    Tq = fk(q, dh, tcp)
    return float(np.abs(Tq[..., :3, 3] - T[..., :3, 3]).max()), float(np.abs(Tq[..., :3, :3] - T[..., :3, :3]).max())


def _tcp() -> np.ndarray:
    tcp = np.eye(4)
    tcp[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # 90 deg about z, as grippers often are
    tcp[:3, 3] = [0.01, -0.02, 0.15]
    return tcp


@pytest.mark.parametrize("model", MODELS)
def test_ik_all_recovers_random_configurations(model: str) -> None:
    dh = dh_params(model)
    qs = _random_q(model)
    targets = fk(qs, dh)
    for q, T in zip(qs, targets, strict=True):
        sols = ik_all(T, dh)
        assert sols.dtype == np.float64 and sols.ndim == 2 and sols.shape[1] == 6 and 1 <= len(sols) <= 8
        assert np.all(sols > -math.pi) and np.all(sols <= math.pi)
        assert _angle_diff(sols, q).max(axis=1).min() <= 1e-7
        pos_err, rot_err = _pose_errors(sols, np.broadcast_to(T, (len(sols), 4, 4)), dh)
        assert pos_err <= 1e-8 and rot_err <= 1e-8


def test_generic_pose_has_eight_distinct_solutions() -> None:
    dh = dh_params("ur5e")
    sols = ik_all(fk([0.3, -1.2, 1.4, -0.9, 1.1, 0.4], dh), "ur5e")  # model names work like in fk
    assert sols.shape == (8, 6)
    assert np.all(_angle_diff(sols[:, None], sols[None]).max(axis=-1) + np.eye(8) > 1e-3)


@pytest.mark.parametrize("model", MODELS)
def test_ik_nearest_returns_the_seeded_configuration(model: str) -> None:
    dh = dh_params(model)
    qs = _random_q(model)
    seeds = qs + np.random.default_rng(7).uniform(-1e-3, 1e-3, qs.shape)
    targets = fk(qs, dh)
    w = np.asarray(IK_JOINT_WEIGHTS)
    exact = 0
    for q, seed, T in zip(qs, seeds, targets, strict=True):
        got = ik_nearest(T, dh, seed)
        assert got is not None and got.shape == (6,) and got.dtype == np.float64
        pos_err, rot_err = _pose_errors(got, T, dh)
        assert pos_err <= 1e-9 and rot_err <= 1e-9
        if np.abs(got - q).max() <= 1e-7:
            exact += 1
        else:  # only legitimate near a branch point (e.g. elbow almost straight): then it must be nearer
            assert (w * (got - seed) ** 2).sum() <= (w * (q - seed) ** 2).sum() + 1e-12
    assert exact >= 0.98 * len(qs)


@pytest.mark.parametrize("q5", [0.0, math.pi, -math.pi, 1e-12])
def test_wrist_singularity_is_deterministic_and_exact(q5: float) -> None:
    dh = dh_params("ur5e")
    q = np.array([0.4, -1.1, 1.3, -0.7, q5, 0.9])
    T = fk(q, dh)
    sols = ik_all(T, dh)
    assert len(sols) >= 1 and np.all(np.isfinite(sols))
    assert _pose_errors(sols, np.broadcast_to(T, (len(sols), 4, 4)), dh)[0] <= 1e-8
    singular = np.abs(np.sin(sols[:, 4])) < 1e-9
    assert singular.any() and np.all(sols[singular, 5] == 0.0)  # q6 = 0 chosen, q4 absorbs q4 +- q6
    np.testing.assert_array_equal(ik_all(T, dh), sols)
    # With a seed, the singular wrist keeps q6 where the seed has it, so the seed itself comes back.
    got = ik_nearest(T, dh, q)
    assert got is not None
    assert np.abs(_angle_diff(got, q)).max() <= 1e-9


@pytest.mark.parametrize("model", MODELS)
def test_random_wrist_singular_poses(model: str) -> None:
    # With z6 = +-z1 axes 2, 3, 4 and 6 are parallel: q6 = 0 is often not reachable by the elbow, in which
    # case the nearest reachable q6 must be chosen (regression: these used to come back empty).
    dh = dh_params(model)
    qs = _random_q(model, 200)
    qs[:, 4] = np.where(np.arange(len(qs)) % 2 == 0, 0.0, math.pi)
    for q, T in zip(qs, fk(qs, dh), strict=True):
        sols = ik_all(T, dh)
        assert len(sols) >= 1
        assert max(_pose_errors(sols, np.broadcast_to(T, (len(sols), 4, 4)), dh)) <= 1e-8
        got = ik_nearest(T, dh, q)
        assert got is not None and np.abs(got - q).max() <= 1e-7


@pytest.mark.parametrize("model", MODELS)
def test_tcp_offset_round_trips(model: str) -> None:
    dh, tcp = dh_params(model), _tcp()
    qs = _random_q(model, 50)
    for q, T in zip(qs, fk(qs, dh, tcp), strict=True):
        sols = ik_all(T, dh, tcp)
        assert _angle_diff(sols, q).max(axis=1).min() <= 1e-7
        assert max(_pose_errors(sols, np.broadcast_to(T, (len(sols), 4, 4)), dh, tcp)) <= 1e-8
        got = ik_nearest(T, dh, q + 1e-4, T_flange_tcp=tcp)
        assert got is not None and max(_pose_errors(got, T, dh, tcp)) <= 1e-9


@pytest.mark.parametrize("offset", [(3.0, 0.0, 0.0), (0.0, 0.0, 3.0), (0.0, 0.0, 0.0)])
def test_unreachable_target(offset: tuple[float, float, float]) -> None:
    # (0, 0, 0) puts the wrist centre on the base axis, inside the cylinder the shoulder offset d4 sweeps.
    T = np.eye(4)
    T[:3, 3] = offset
    assert ik_all(T, "ur5e").shape == (0, 6)
    assert ik_nearest(T, "ur5e", np.zeros(6)) is None
    with pytest.raises(IKError, match=r"unreachable for ur5e") as info:
        ik_solve(T, "ur5e", np.zeros(6))
    assert f"target TCP position {np.array2string(T[:3, 3], precision=4)} m" in str(info.value)
    assert isinstance(info.value, ValueError)


def test_custom_limits_are_respected() -> None:
    dh = dh_params("ur5e")
    q = np.array([-0.5, -1.2, -1.4, -0.9, -1.1, -0.4])  # elbow-down-ish branch, all joints negative
    T = fk(q, dh)
    # Limits [0, 2 pi] exclude the seed itself; the same pose is reached with every joint shifted by 2 pi.
    lower, upper = np.zeros(6), np.full(6, 2 * math.pi)
    got = ik_nearest(T, dh, q + 2 * math.pi - 0.05, lower=lower, upper=upper)
    assert got is not None
    np.testing.assert_allclose(got, q + 2 * math.pi, atol=1e-9)
    got = ik_nearest(T, dh, q, lower=lower, upper=upper)  # seed outside the limits: still a valid answer
    assert got is not None and np.all(got >= lower) and np.all(got <= upper)
    assert max(_pose_errors(got, T, dh)) <= 1e-9
    # Forbid a negative elbow: the other elbow branch is returned instead of the seed's.
    lower, upper = np.full(6, -2 * math.pi), np.full(6, 2 * math.pi)
    lower[2] = 0.0
    got = ik_nearest(T, dh, q, lower=lower, upper=upper)
    assert got is not None and got[2] >= 0.0 and np.all(got >= lower) and np.all(got <= upper)
    assert max(_pose_errors(got, T, dh)) <= 1e-9
    # A base window no solution's q1 falls into: reachable, but not within limits.
    q1s = ik_all(T, dh)[:, 0]
    gap = float(np.mod(q1s.min() + 1.0, 2 * math.pi))  # 1 rad past a solution; q1 branches are ~2.6 rad apart
    assert _angle_diff(q1s, np.full_like(q1s, gap)).min() > 0.2
    lower, upper = np.full(6, -2 * math.pi), np.full(6, 2 * math.pi)
    lower[0], upper[0] = gap - 0.1, gap + 0.1
    assert ik_nearest(T, dh, q, lower=lower, upper=upper) is None
    with pytest.raises(IKError, match=r"none is within the joint limits"):
        ik_solve(T, dh, q, lower=lower, upper=upper)


def test_slightly_non_orthonormal_rotation_is_accepted() -> None:
    dh = dh_params("ur10e")
    q = np.array([1.0, -2.0, 1.5, 0.3, -0.8, 2.5])
    T = fk(q, dh)
    T[:3, :3] *= 1.0 + 1e-9  # e.g. a pose that went through float32 or a few products
    got = ik_nearest(T, dh, q)
    assert got is not None and np.abs(got - q).max() <= 1e-7


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"T_base_tcp": np.full((4, 4), np.nan)}, "T_base_tcp"),
        ({"T_base_tcp": np.eye(3)}, "T_base_tcp"),
        ({"T_base_tcp": np.diag([2.0, 1.0, 1.0, 1.0])}, "T_base_tcp must be a rigid"),
        ({"T_base_tcp": np.diag([-1.0, 1.0, 1.0, 1.0])}, "T_base_tcp must be a rigid"),
        ({"T_flange_tcp": np.diag([1.0, 1.0, 1.0, 2.0])}, "T_flange_tcp must be a rigid"),
        ({"q_seed": np.zeros(5)}, "q_seed"),
        ({"q_seed": [0, 0, 0, 0, 0, math.inf]}, "q_seed"),
        ({"lower": np.ones(6), "upper": np.zeros(6)}, "lower <= upper"),
        ({"weights": -np.ones(6)}, "weights > 0"),
    ],
)
def test_invalid_input_raises_naming_the_argument(kwargs: dict[str, object], match: str) -> None:
    args: dict[str, object] = {"T_base_tcp": fk(np.full(6, 0.5), "ur5e"), "dh": "ur5e", "q_seed": np.zeros(6)}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        ik_nearest(**args)  # type: ignore[arg-type]


def test_non_ur_dh_table_is_rejected() -> None:
    odd = DHParams(name="odd", d=(0.1, 0.0, 0.0, 0.1, 0.1, 0.1), a=(0.0, -0.4, -0.4, 0.0, 0.0, 0.0), alpha=(0.0,) * 6)
    with pytest.raises(ValueError, match="Universal Robots DH structure"):
        ik_all(np.eye(4), odd)


def test_batch_of_random_poses_all_solve() -> None:
    """200 random reachable poses: ik_nearest lands on each (FK of its answer is the target, the seed's branch),
    and ik_all finds the seed among its solutions. Its per-call cost belongs to a bench, not to a test."""
    dh = dh_params("ur5e")
    qs = _random_q("speed", 200)
    targets = fk(qs, dh)
    for q, T in zip(qs, targets, strict=True):
        sol = ik_nearest(T, dh, q + 0.01)
        np.testing.assert_allclose(fk(sol, dh), T, atol=1e-9)
        assert np.max(np.abs(np.angle(np.exp(1j * (sol - q))))) < 1e-6
        sols = ik_all(T, dh)
        assert len(sols) >= 1
        assert min(np.max(np.abs(np.angle(np.exp(1j * (s - q))))) for s in sols) < 1e-6
