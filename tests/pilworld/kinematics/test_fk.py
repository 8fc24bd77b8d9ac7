"""Forward kinematics of the UR family against the published DH tables and an independent reference."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pilworld.kinematics import (
    UR_MODELS,
    DHParams,
    UrArm,
    dh_params,
    fk,
    fk_flange,
    fk_frames,
    joint_transforms,
)

# The non-zero entries (d1, a2, a3, d4, d5, d6) of Universal Robots' published DH tables, copied here
# independently of pilworld.kinematics.ur_dh so a typo in either place fails the tests.
PUBLISHED: dict[str, tuple[float, float, float, float, float, float]] = {
    "ur3e": (0.15185, -0.24355, -0.2132, 0.13105, 0.08535, 0.0921),
    "ur5e": (0.1625, -0.425, -0.3922, 0.1333, 0.0997, 0.0996),
    "ur10e": (0.1807, -0.6127, -0.57155, 0.17415, 0.11985, 0.11655),
    "ur16e": (0.1807, -0.4784, -0.36, 0.17415, 0.11985, 0.11655),
    "ur20": (0.2363, -0.862, -0.7287, 0.201, 0.1593, 0.1543),
    "ur30": (0.2363, -0.637, -0.5037, 0.201, 0.1593, 0.1543),
    "ur3": (0.1519, -0.24365, -0.21325, 0.11235, 0.08535, 0.0819),
    "ur5": (0.089159, -0.425, -0.39225, 0.10915, 0.09465, 0.0823),
    "ur10": (0.1273, -0.612, -0.5723, 0.163941, 0.1157, 0.0922),
}
ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)


# --- independent reference: plain Python, elementary transforms, no pilworld helpers -------------


def _matmul(A: list[list[float]], B: list[list[float]]) -> list[list[float]]:
    return [[sum(A[i][k] * B[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def _rz(t: float) -> list[list[float]]:
    c, s = math.cos(t), math.sin(t)
    return [[c, -s, 0.0, 0.0], [s, c, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]


def _rx(t: float) -> list[list[float]]:
    c, s = math.cos(t), math.sin(t)
    return [[1.0, 0.0, 0.0, 0.0], [0.0, c, -s, 0.0], [0.0, s, c, 0.0], [0.0, 0.0, 0.0, 1.0]]


def _tz(d: float) -> list[list[float]]:
    return [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, d], [0.0, 0.0, 0.0, 1.0]]


def _tx(a: float) -> list[list[float]]:
    return [[1.0, 0.0, 0.0, a], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]


def reference_fk(q: list[float], model: str) -> list[list[float]]:
    """Flange pose as the product over joints of Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)."""
    d1, a2, a3, d4, d5, d6 = PUBLISHED[model]
    d = (d1, 0.0, 0.0, d4, d5, d6)
    a = (0.0, a2, a3, 0.0, 0.0, 0.0)
    T = [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]
    for i in range(6):
        for E in (_rz(q[i]), _tz(d[i]), _tx(a[i]), _rx(ALPHA[i])):
            T = _matmul(T, E)
    return T


# --- tables ----------------------------------------------------------------------------------------


def test_model_list_is_the_published_table() -> None:
    assert set(UR_MODELS) == set(PUBLISHED)


@pytest.mark.parametrize("model", sorted(PUBLISHED))
def test_dh_table_matches_published_values(model: str) -> None:
    p = dh_params(model)
    d1, a2, a3, d4, d5, d6 = PUBLISHED[model]
    assert p.name == model
    assert p.d == (d1, 0.0, 0.0, d4, d5, d6)
    assert p.a == (0.0, a2, a3, 0.0, 0.0, 0.0)
    np.testing.assert_array_equal(p.alpha_array, ALPHA)
    for arr in (p.d_array, p.a_array, p.alpha_array, p.lower_limits, p.upper_limits):
        assert arr.dtype == np.float64
        assert arr.shape == (6,)
    np.testing.assert_array_equal(p.lower_limits, np.full(6, -2 * math.pi))
    np.testing.assert_array_equal(p.upper_limits, np.full(6, 2 * math.pi))


@pytest.mark.parametrize(
    ("name", "canonical"),
    [("UR5e", "ur5e"), (" ur10E ", "ur10e"), ("ur5_cb3", "ur5"), ("UR3-CB3", "ur3"), ("ur10cb3", "ur10")],
)
def test_dh_params_names_are_case_insensitive_with_cb3_aliases(name: str, canonical: str) -> None:
    assert dh_params(name) is dh_params(canonical)


def test_dh_params_is_frozen() -> None:
    p = dh_params("ur5e")
    with pytest.raises(AttributeError):
        p.name = "other"  # type: ignore[misc]


# --- zero configuration ----------------------------------------------------------------------------


@pytest.mark.parametrize("model", sorted(PUBLISHED))
def test_zero_configuration_flange_position(model: str) -> None:
    d1, a2, a3, d4, d5, d6 = PUBLISHED[model]
    T = fk_flange(np.zeros(6), model)
    np.testing.assert_allclose(T[:3, 3], [a2 + a3, -(d4 + d6), d1 - d5], rtol=0, atol=1e-12)
    # The twists sum to Rx(pi/2): the flange z axis points along -y of the base, its x along +x.
    np.testing.assert_allclose(T[:3, :3], [[1, 0, 0], [0, 0, -1], [0, 1, 0]], rtol=0, atol=1e-12)


# --- random configurations vs the reference --------------------------------------------------------


@pytest.mark.parametrize("model", sorted(PUBLISHED))
def test_random_configurations_match_reference(model: str) -> None:
    rng = np.random.default_rng(sorted(PUBLISHED).index(model))
    q = rng.uniform(-2 * math.pi, 2 * math.pi, size=(1000, 6))
    T = fk(q, model)
    assert T.shape == (1000, 4, 4)
    ref = np.array([reference_fk([float(v) for v in row], model) for row in q])
    np.testing.assert_allclose(T[:, :3, 3], ref[:, :3, 3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(T[:, :3, :3], ref[:, :3, :3], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(T[:, 3, :], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (1000, 4)))


def test_frames_chain_joint_transforms() -> None:
    q = np.random.default_rng(1).uniform(-3, 3, size=(7, 6))
    links = joint_transforms(q, "ur5e")
    frames = fk_frames(q, "ur5e")
    assert links.shape == (7, 6, 4, 4)
    assert frames.shape == (7, 7, 4, 4)
    np.testing.assert_array_equal(frames[:, 0], np.broadcast_to(np.eye(4), (7, 4, 4)))
    for i in range(6):
        np.testing.assert_allclose(frames[:, i + 1], frames[:, i] @ links[:, i], rtol=0, atol=1e-15)
    np.testing.assert_allclose(frames[:, 6], fk_flange(q, "ur5e"), rtol=0, atol=1e-15)
    # Frame 1 sits at height d1 above the base and rotates with joint 1 only.
    np.testing.assert_allclose(frames[:, 1, :3, 3], np.broadcast_to([0, 0, 0.1625], (7, 3)), atol=1e-15)


# --- batching and dtypes ---------------------------------------------------------------------------


@pytest.mark.parametrize("batch", [(), (5,), (2, 3)])
def test_batched_shapes_agree_with_single_evaluation(batch: tuple[int, ...]) -> None:
    dh = dh_params("ur10e")
    q = np.random.default_rng(2).uniform(-6, 6, size=(*batch, 6))
    T = fk(q, dh)
    assert T.shape == (*batch, 4, 4)
    assert T.dtype == np.float64
    assert fk_frames(q, dh).shape == (*batch, 7, 4, 4)
    assert joint_transforms(q, dh).shape == (*batch, 6, 4, 4)
    for idx in np.ndindex(*batch):
        np.testing.assert_array_equal(T[idx], fk(q[idx], dh))


def test_float32_and_list_input_are_computed_in_float64() -> None:
    q32 = np.random.default_rng(3).uniform(-3, 3, size=(4, 6)).astype(np.float32)
    T = fk(q32, "ur5e")
    assert T.dtype == np.float64
    np.testing.assert_array_equal(T, fk(q32.astype(np.float64), "ur5e"))
    np.testing.assert_array_equal(fk(q32[0].tolist(), "ur5e"), T[0])


# --- TCP -------------------------------------------------------------------------------------------


def test_tcp_z_offset_moves_point_along_flange_z() -> None:
    q = np.random.default_rng(5).uniform(-3, 3, size=(50, 6))
    tcp = np.eye(4)
    tcp[2, 3] = 0.15
    flange = fk_flange(q, "ur5e")
    T = fk(q, "ur5e", tcp)
    np.testing.assert_allclose(T[:, :3, 3] - flange[:, :3, 3], 0.15 * flange[:, :3, 2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(T[:, :3, :3], flange[:, :3, :3], rtol=0, atol=1e-15)

    arm = UrArm.from_model("UR5e", tcp)
    np.testing.assert_allclose(arm.fk(q), T, rtol=0, atol=1e-15)
    pos = arm.tcp_position(q)
    assert pos.shape == (50, 3)
    np.testing.assert_allclose(np.linalg.norm(pos - flange[:, :3, 3], axis=-1), 0.15, rtol=0, atol=1e-12)


def test_ur_arm_defaults_to_flange_and_is_immutable() -> None:
    arm = UrArm(dh_params("ur3e"))
    q = np.zeros((2, 6))
    np.testing.assert_array_equal(arm.fk(q), fk_flange(q, "ur3e"))
    assert arm.frames(q).shape == (2, 7, 4, 4)
    assert arm.tcp_position(q[0]).shape == (3,)
    with pytest.raises(ValueError, match="read-only"):
        arm.tcp[0, 3] = 1.0
    with pytest.raises(AttributeError):
        arm.dh = dh_params("ur5e")  # type: ignore[misc]


# --- errors ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(5,), (2, 7), (6, 5), ()])
def test_wrong_last_dimension_raises(shape: tuple[int, ...]) -> None:
    with pytest.raises(ValueError, match=r"q must have shape \(\.\.\., 6\).*got shape") as info:
        fk(np.zeros(shape), "ur5e")
    assert str(shape) in str(info.value)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_q_raises(bad: float) -> None:
    q = np.zeros((3, 6))
    q[1, 4] = bad
    with pytest.raises(ValueError, match=r"q must contain only finite.*index \(1, 4\)"):
        fk(q, "ur5e")


def test_unknown_model_raises_listing_valid_names() -> None:
    with pytest.raises(ValueError, match="unknown UR model name 'ur7e'") as info:
        dh_params("ur7e")
    for name in PUBLISHED:
        assert name in str(info.value)
    with pytest.raises(ValueError, match="unknown UR model"):
        fk(np.zeros(6), "kuka")


@pytest.mark.parametrize(
    ("tcp", "match"),
    [
        (np.eye(3), r"tcp must be a single \(4, 4\)"),
        (np.diag([2.0, 1.0, 1.0, 1.0]), "tcp must be a finite rigid transform"),
        (np.full((4, 4), math.nan), "tcp must be a finite rigid transform"),
    ],
)
def test_bad_tcp_raises(tcp: np.ndarray, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        fk(np.zeros(6), "ur5e", tcp)
    with pytest.raises(ValueError, match=match):
        UrArm(dh_params("ur5e"), tcp)


def test_dh_params_validates_its_table() -> None:
    with pytest.raises(ValueError, match=r"DHParams\.d must be 6 finite floats"):
        DHParams("bad", (0.0,) * 5, (0.0,) * 6, (0.0,) * 6)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"DHParams\.joint_limits"):
        DHParams("bad", (0.0,) * 6, (0.0,) * 6, (0.0,) * 6, ((1.0, -1.0),) * 6)
