"""``pilworld bench stability``: the probes' chunk transforms and the action shuffle's transplant, the wrong rigs
given to the models (the perturbed rig, and world model v2 bound to it: nothing changes at zero, the frames move
with an error), the horizon sweep (on a synthetic paired set with known figures and on a real 2-round paired
run judged by the image-only judge), the probes' summaries on hand-made records of two models, the tables,
chart and CLI summary of a result, and the probes of both default models from one start (about 20 s).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from hw_drivers.safety import SafetyLimits
from pilworld.bench.charts import stability_chart
from pilworld.bench.results_tables import stability_tables
from pilworld.bench.stability import (
    CAL_SHIFTS_PX,
    DEFAULT_MODELS,
    HEAD_ERRORS,
    HORIZONS,
    JITTER_RAD,
    ROBOT_ERRORS,
    SHUFFLE_ROUNDS,
    WRIST_ERRORS,
    RigError,
    horizon_sweep,
    probe,
    resolve_models,
    rig_errors,
    transplant,
)
from pilworld.bench.stability.metrics import frame_mse as _mse
from pilworld.bench.stability.metrics import frame_psnr as _psnr
from pilworld.bench.stability.probe_chunks import fast_chunk as _fast
from pilworld.bench.stability.probe_chunks import hold_chunk as _hold
from pilworld.bench.stability.probe_chunks import jitter_chunk as _jitter
from pilworld.bench.stability.probe_chunks import offset_chunk as _offset
from pilworld.bench.stability.probe_chunks import reverse_chunk as _reverse
from pilworld.bench.stability.summary import summarize_probes as _summarize_probes
from pilworld.config.rig import RigConfig
from pilworld.control_video.gamma import ControlVideo
from pilworld.control_video.probes import mismatched_robot, perturbed_cameras, perturbed_rig, shifted_principal_point
from pilworld.data.outcomes import Outcome, read_outcomes, record_outcomes
from pilworld.data.pairs import load_pairs
from pilworld.data.reader import EpisodeStore
from pilworld.judges.base import judge_dataset
from pilworld.judges.vision import VisionJudge
from pilworld.paired import PairedConfig, paired_run
from pilworld.types import ChunkSpec, Start, Subtask
from tests.pilworld.metrics.synthetic import ROUNDS, K, SynthPair, write_paired

SIM = "configs/rig/sim_dual_ur5e.yaml"
PNG = b"\x89PNG\r\n\x1a\n"
GRIPS = [6, 13]
ARMS = [0, 1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 12]
H = ChunkSpec().horizon  # rows of a policy chunk
K_SIM = ChunkSpec().frames
VIEWS = ["cam_high", "cam_left_wrist", "cam_right_wrist"]


def _chunk(seed: int = 0) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """A policy-like chunk (a smooth drift away from the state) and the state; grippers differ from the state's."""
    rng = np.random.default_rng(seed)
    state = rng.uniform(-1.0, 1.0, size=14).astype(np.float32)
    state[GRIPS] = 0.2
    drift = rng.uniform(-0.01, 0.01, size=14).astype(np.float32)
    base = (state[None] + np.arange(1, H + 1, dtype=np.float32)[:, None] * drift[None]).astype(np.float32)
    base[:, GRIPS] = np.linspace(0.3, 0.9, H, dtype=np.float32)[:, None]
    return base, state


def _psnr_ref(a: NDArray[np.uint8], b: NDArray[np.uint8]) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return 100.0 if mse == 0 else 20.0 * math.log10(255.0) - 10.0 * math.log10(mse)


# ---------------------------------------------------------------------- chunk transforms


@pytest.mark.parametrize("transform", [_hold, _reverse, _fast, _offset])
def test_transforms_keep_the_policy_grippers_and_do_not_touch_the_chunk(
    transform: Callable[[NDArray[np.float32], NDArray[np.float32]], NDArray[np.float32]],
) -> None:
    base, state = _chunk()
    before = base.copy()
    out = transform(base, state)
    assert out.shape == base.shape and out.dtype == np.float32
    np.testing.assert_array_equal(out[:, GRIPS], base[:, GRIPS])
    np.testing.assert_array_equal(base, before)
    assert not np.array_equal(out[:, ARMS], base[:, ARMS])  # the arms' motion does change


def test_hold_reverse_fast_arm_motion() -> None:
    """hold: the state on every row; reverse: the displacement mirrored about the state; fast: ×3."""
    base, state = _chunk()
    disp = base[:, ARMS] - state[None, ARMS]
    np.testing.assert_array_equal(_hold(base, state)[:, ARMS], np.repeat(state[None, ARMS], H, axis=0))
    np.testing.assert_allclose(_reverse(base, state)[:, ARMS] - state[None, ARMS], -disp, atol=1e-6)
    fast = _fast(base, state)[:, ARMS]
    np.testing.assert_allclose(fast - state[None, ARMS], 3.0 * disp, atol=1e-6)  # small steps: exactly ×3
    big = base.copy()
    big[:, ARMS] = state[None, ARMS] + 0.2 * np.arange(1, H + 1, dtype=np.float32)[:, None]
    steps = np.diff(np.vstack([state[None, ARMS], _fast(big, state)[:, ARMS]]), axis=0)
    assert np.abs(steps).max() <= 0.1 + 1e-6  # ×3 of 0.2 rad per step is capped at the joints' top speed


def test_offset_ramps_both_shoulder_lifts_to_0_3_rad() -> None:
    """Columns 1 and 8 get 0.3·min(i/(K·Δ), 1) on row i (0.3 from the last executed row); others the policy's."""
    base, state = _chunk()
    out = _offset(base, state)
    ramp = 0.3 * np.minimum(np.arange(1, H + 1) / ChunkSpec().executed_steps, 1.0)
    for col in (1, 8):
        np.testing.assert_allclose(out[:, col] - base[:, col], ramp, atol=1e-6)
        assert out[-1, col] - base[-1, col] == pytest.approx(0.3, abs=1e-6)
    others = [c for c in range(14) if c not in (1, 8)]
    np.testing.assert_array_equal(out[:, others], base[:, others])
    assert SafetyLimits().max_arm_step > 0.3 / H  # the ramp adds less than the filter's step cap


def test_jitter_stays_under_the_safety_step_cap() -> None:
    """On a constant chunk: arm noise of about JITTER_RAD, at most 2·JITTER_RAD, so consecutive arm targets
    differ by less than the safety filter's cap; grippers untouched; reproducible from the generator."""
    _, state = _chunk()
    base = np.repeat(state[None], H, axis=0).astype(np.float32)
    base[:, GRIPS] = 0.7
    out = _jitter(base, state, np.random.default_rng(0))
    assert out.shape == base.shape and out.dtype == np.float32
    noise = out[:, ARMS] - base[:, ARMS]
    assert np.abs(noise).max() <= 2 * JITTER_RAD + 1e-6
    assert 0.5 * JITTER_RAD < float(noise.std()) < 1.2 * JITTER_RAD
    steps = np.abs(np.diff(out[:, ARMS], axis=0))
    assert steps.max() < SafetyLimits().max_arm_step == 0.35
    np.testing.assert_array_equal(out[:, GRIPS], base[:, GRIPS])
    np.testing.assert_array_equal(out, _jitter(base, state, np.random.default_rng(0)))
    assert not np.array_equal(out, _jitter(base, state, np.random.default_rng(1)))


# ---------------------------------------------------------------------- the action shuffle's transplant


def test_transplant_moves_the_arms_by_the_donor_displacement_with_the_donor_grippers() -> None:
    """Arms: this state + (donor − donor state), row by row; grippers: the donor's commands; inputs untouched."""
    donor, donor_state = _chunk(1)
    _, state = _chunk(2)
    before = (donor.copy(), donor_state.copy(), state.copy())
    out = transplant(donor, donor_state, state)
    assert out.shape == donor.shape == (H, 14) and out.dtype == np.float32
    np.testing.assert_allclose(out[:, ARMS] - state[None, ARMS], donor[:, ARMS] - donor_state[None, ARMS], atol=1e-6)
    np.testing.assert_array_equal(out[:, GRIPS], donor[:, GRIPS])
    for a, b in zip(before, (donor, donor_state, state), strict=True):
        np.testing.assert_array_equal(a, b)
    # The first command is as close to this state as the donor's was to its own: the safety filter's start gate.
    assert np.abs(out[0, ARMS] - state[ARMS]).max() == pytest.approx(np.abs(donor[0, ARMS] - donor_state[ARMS]).max())
    assert np.abs(out[0, ARMS] - state[ARMS]).max() < SafetyLimits().start_command_tolerance
    # A donor standing still transplants to standing still here.
    still = np.repeat(donor_state[None], H, axis=0)
    np.testing.assert_allclose(transplant(still, donor_state, state)[:, ARMS], np.repeat(state[None, ARMS], H, 0))


def test_transplant_rejects_mismatched_shapes() -> None:
    donor, state = _chunk()
    with pytest.raises(ValueError, match="transplant"):
        transplant(donor, state[:7], state)
    with pytest.raises(ValueError, match="transplant"):
        transplant(donor[0], state, state)


# ---------------------------------------------------------------------- wrong rigs


@pytest.mark.parametrize("px", [5.0, 10.0, 20.0])
def test_shifted_camera_moves_projections_by_px(px: float) -> None:
    """The principal point moves px/√2 on both axes, so every projection moves px pixels diagonally."""
    cam = RigConfig.load(SIM).head_camera_model
    K0 = np.array(cam.K, dtype=np.float64).copy()
    shifted = shifted_principal_point(cam, px)
    d = px / math.sqrt(2.0)
    K1 = np.array(shifted.K, dtype=np.float64)
    assert K1[0, 2] == pytest.approx(K0[0, 2] + d) and K1[1, 2] == pytest.approx(K0[1, 2] + d)
    mask = np.ones((3, 3), dtype=bool)
    mask[0, 2] = mask[1, 2] = False
    np.testing.assert_array_equal(K1[mask], K0[mask])
    np.testing.assert_array_equal(np.array(cam.K), K0)  # the rig's camera is not modified
    np.testing.assert_array_equal(shifted.dist, cam.dist)
    np.testing.assert_array_equal(shifted.T_cam_base, cam.T_cam_base)
    assert (shifted.width, shifted.height, shifted.name) == (cam.width, cam.height, cam.name)

    uv = np.array([[u, v] for u in (32.0, 64.0, 96.0) for v in (40.0, 64.0, 90.0)])
    table, valid = cam.backproject_to_plane(uv, 0.0)
    assert valid.all()
    uv0, vis0 = cam.project(table)
    uv1, _ = shifted.project(table)
    assert vis0.all()
    moved = uv1 - uv0
    np.testing.assert_allclose(np.linalg.norm(moved, axis=1), px, atol=0.05)
    np.testing.assert_allclose(moved, np.full_like(moved, d), atol=0.05)


def test_shift_zero_is_the_same_camera() -> None:
    cam = RigConfig.load(SIM).head_camera_model
    np.testing.assert_array_equal(np.array(shifted_principal_point(cam, 0.0).K), np.array(cam.K))


def test_rig_errors_are_the_issue_s_list_with_their_parameters() -> None:
    errors = rig_errors()
    assert [e.kind for e in errors] == ["principal_point"] * 3 + ["head_extrinsics"] * 3 + ["wrist_mount"] * 2 + [
        "robot_model"
    ] * 3
    assert [e.shift_px for e in errors[:3]] == [s for s in CAL_SHIFTS_PX if s] == [5.0, 10.0, 20.0]
    assert [(e.translation_m, e.rotation_deg) for e in errors[3:6]] == list(HEAD_ERRORS)
    assert HEAD_ERRORS == ((0.002, 0.2), (0.005, 0.5), (0.010, 1.0))
    assert (
        [(e.translation_m, e.rotation_deg) for e in errors[6:8]] == list(WRIST_ERRORS) == [(0.002, 0.5), (0.005, 1.0)]
    )
    assert [(e.radius_scale, e.rgba) for e in errors[8:]] == list(ROBOT_ERRORS)
    keys = [e.key for e in errors]
    assert len(set(keys)) == len(keys)
    assert [e.moves_head for e in errors] == [True] * 6 + [False] * 5
    js = [e.to_json() for e in errors]
    assert json.loads(json.dumps(js)) == js  # JSON as is
    assert js[0]["params"] == {"shift_px": 5.0}
    assert js[5]["params"] == {"translation_m": 0.01, "rotation_deg": 1.0, "seed": 0}
    assert js[10]["params"] == {"radius_scale": 1.0, "rgba": [0.8, 0.3, 0.3, 1.0]}
    assert js[5]["label"] == "head camera extrinsics 10 mm, 1°" and js[6]["label"] == "wrist camera mounts 2 mm, 0.5°"
    with pytest.raises(ValueError, match="kind"):
        RigError("focal_length")


def test_perturbed_rig_writes_the_wrong_calibration(tmp_path: Path) -> None:
    """All zeros: the same cameras bit for bit (through the written head file); errors: the principal point moved,
    the head camera as perturbed_cameras moves it, the wrist mounts moved by exactly their size; arms unchanged."""
    rig = RigConfig.load(SIM)
    same = perturbed_rig(rig, tmp_path / "zero")
    assert same.head_camera.file == str(tmp_path / "zero" / "cam_high.yaml")
    assert same.head_camera_model == rig.head_camera_model
    for w in rig.wrist_cameras:
        assert same.wrist_camera_model(w) == rig.wrist_camera_model(w)
        assert same.wrist_cameras[w] == rig.wrist_cameras[w]
    assert same.arms == rig.arms and same.image_size == rig.image_size

    wrong = perturbed_rig(
        rig,
        tmp_path / "wrong",
        principal_shift_px=10.0,
        head_translation_m=0.01,
        head_rotation_deg=1.0,
        wrist_translation_m=0.005,
        wrist_rotation_deg=1.0,
        seed=3,
    )
    cams = perturbed_cameras(
        rig, head_translation_m=0.01, head_rotation_deg=1.0, wrist_translation_m=0.005, wrist_rotation_deg=1.0, seed=3
    )
    head = wrong.head_camera_model
    np.testing.assert_allclose(head.K, shifted_principal_point(rig.head_camera_model, 10.0).K)
    np.testing.assert_array_equal(head.T_cam_base, cams.view("cam_high").model.T_cam_base)
    moved = np.linalg.norm(head.camera_center_in_base() - rig.head_camera_model.camera_center_in_base())
    assert moved == pytest.approx(0.01, abs=1e-9)
    for w in rig.wrist_cameras:
        got, nominal = wrong.wrist_camera_model(w), rig.wrist_camera_model(w)
        np.testing.assert_allclose(got.T_cam_base, cams.view(w).model.T_cam_base, atol=1e-12)
        assert np.linalg.norm(got.camera_center_in_base() - nominal.camera_center_in_base()) == pytest.approx(0.005)
        np.testing.assert_array_equal(got.K, nominal.K)
    assert wrong.arms == rig.arms


@pytest.fixture(scope="module")
def sim_start() -> tuple[Start, NDArray[np.float32]]:
    """One start of sort_cubes (layout 7,000,500, subtask 0) and the 30k policy's chunk from it."""
    from pilworld.paired.stations import SimStation
    from pilworld.policies.registry import make_policy
    from simrig.tasks import make_task

    spec = ChunkSpec(rounds=1)
    rig = RigConfig.load(SIM)
    with SimStation(SIM, "sort_cubes") as station:
        sub = Subtask("sort_cubes", 0, make_task("sort_cubes").instruction, 7_000_500)
        start = station.start(sub, "scripted_step_30k", spec)
    policy = make_policy("scripted_step_30k", rig, spec)
    policy.reset(seed=0)
    return start, np.asarray(policy.infer(start.observation, start.subtask.instruction), dtype=np.float32)


def _imagine(name: str, start: Start, chunk: NDArray[np.float32], given: RigConfig, robot: Any = None) -> Any:
    """One round of the bench variant ``name`` bound to the rig ``given`` (and robot model), Γ drawn with it."""
    from pilworld.bench.stability import known_models
    from pilworld.envs import ImaginedEnv
    from pilworld.paired.runner import PairedConfig, load_model
    from pilworld.world_model.composite.model import CompositeWorldModel

    v = known_models()[name]
    rig = RigConfig.load(SIM)
    cfg = PairedConfig(
        rig=SIM,
        task="sort_cubes",
        checkpoints=["scripted_step_30k"],
        subtasks=1,
        out="",
        world_model=v.world_model,
        adapter=v.adapter,
    )
    model = load_model(cfg, rig, "sort_cubes")[0]
    assert isinstance(model, CompositeWorldModel)  # both default models are v2's
    if given is not rig or robot is not None:
        model.bind_rig(given, robot=robot)
    env = ImaginedEnv(model, ControlVideo.from_rig(given, ChunkSpec(rounds=1)), ChunkSpec(rounds=1))
    env.reset(start)
    seg = env.step(chunk)
    return {v: np.stack([o.images[v] for o in seg.observations]) for v in VIEWS}, np.stack(
        [o.state for o in seg.observations]
    )


@pytest.mark.parametrize("name", DEFAULT_MODELS)
def test_v2_bound_to_a_zero_error_rig_imagines_the_same_frames(
    name: str, sim_start: tuple[Start, NDArray[np.float32]], tmp_path: Path
) -> None:
    start, chunk = sim_start
    rig = RigConfig.load(SIM)
    frames, states = _imagine(name, start, chunk, rig)
    same, same_states = _imagine(name, start, chunk, perturbed_rig(rig, tmp_path), mismatched_robot(rig))
    for v in VIEWS:
        np.testing.assert_array_equal(same[v], frames[v], err_msg=v)
    np.testing.assert_array_equal(same_states, states)


@pytest.mark.parametrize("name", DEFAULT_MODELS)
def test_v2_bound_to_a_wrong_rig_imagines_other_frames(
    name: str, sim_start: tuple[Start, NDArray[np.float32]], tmp_path: Path
) -> None:
    """A 10 px principal point and a (10 mm, 1°) head error move the head view (the shipped model's render and
    prior, the paper-faithful model's markers), a (5 mm, 1°) wrist mount error a wrist view."""
    start, chunk = sim_start
    rig = RigConfig.load(SIM)
    frames, _ = _imagine(name, start, chunk, rig)
    pp = _imagine(name, start, chunk, perturbed_rig(rig, tmp_path / "pp", principal_shift_px=10.0))[0]
    head = _imagine(
        name, start, chunk, perturbed_rig(rig, tmp_path / "h", head_translation_m=0.01, head_rotation_deg=1)
    )[0]
    wrist = _imagine(
        name, start, chunk, perturbed_rig(rig, tmp_path / "w", wrist_translation_m=0.005, wrist_rotation_deg=1)
    )[0]
    for wrong in (pp, head):
        assert _mse(wrong["cam_high"], frames["cam_high"]) > 1.0
    assert max(_mse(wrist[v], frames[v]) for v in VIEWS[1:]) > 1.0


def test_shipped_v2_renders_a_mismatched_robot_model(sim_start: tuple[Start, NDArray[np.float32]]) -> None:
    """Thicker links (and another colour, through the render's shade) change the shipped model's head view."""
    start, chunk = sim_start
    rig = RigConfig.load(SIM)
    frames, _ = _imagine("pilworld", start, chunk, rig)
    for robot in (mismatched_robot(rig, radius_scale=1.2), mismatched_robot(rig, rgba=(0.8, 0.3, 0.3, 1.0))):
        assert _mse(_imagine("pilworld", start, chunk, rig, robot)[0]["cam_high"], frames["cam_high"]) > 0.1


def test_resolve_models() -> None:
    assert [v.name for v in resolve_models()] == list(DEFAULT_MODELS) == ["pilworld", "v2_paper_gamma"]
    assert [v.name for v in resolve_models(["v2_markers", "pilworld"])] == ["v2_markers", "pilworld"]
    with pytest.raises(ValueError, match=r"unknown nope; known: .*pilworld.*v2_paper_gamma"):
        resolve_models(["pilworld", "nope"])
    with pytest.raises(ValueError, match="twice"):
        resolve_models(["pilworld", "pilworld"])
    with pytest.raises(ValueError, match="at least one"):
        resolve_models([])


# ---------------------------------------------------------------------- horizon sweep, synthetic


def test_horizon_sweep_on_a_synthetic_run(tmp_path: Path) -> None:
    """Exact HFR per horizon from hand-set hallucination frames (checker verdicts and real branches ignored)
    and per-round PSNR at the frame ending each round, beside the start frame held still."""
    root = write_paired(tmp_path / "run", [SynthPair(subtask=0, offset=5), SynthPair(subtask=1, offset=10)])
    T = 1 + ROUNDS * K
    record_outcomes(
        root,
        [
            Outcome(0, "vision", "vision", False, T, 2),  # pair 0 imagined: hallucinates at frame 2
            Outcome(0, "sim_checker", "sim_state", False, T, 1),  # a checker: not part of HFR
            Outcome(1, "vision", "vision", True, T, 1),  # a real branch: not part of HFR
            Outcome(2, "vision", "vision", True, T),  # pair 1 imagined: no hallucination
        ],
    )
    r = horizon_sweep(root, ROUNDS, K)
    assert r["pairs"] == 2 and r["run"] == str(root)
    t1, t2 = 1 + K, 1 + 2 * K
    assert r["rows"] == [
        {"rounds": 1, "frames": t1, "hfr": pytest.approx((2 / t1 + 1.0) / 2), "n": 2},
        {"rounds": 2, "frames": t2, "hfr": pytest.approx((2 / t2 + 1.0) / 2), "n": 2},
    ]
    store = EpisodeStore(root)
    imag = [store.frames(i, "cam_high") for i in (0, 2)]
    real = [store.frames(i, "cam_high") for i in (1, 3)]
    # Round 1 ends on frame K: the imagined frame is the real one + offset (no clipping: real pixels 40..199).
    assert r["per_round"][0]["psnr_head"] == pytest.approx((20 * math.log10(255 / 5) + 20 * math.log10(255 / 10)) / 2)
    for row, rnd in zip(r["per_round"], (1, 2), strict=True):
        k = rnd * K
        assert row["round"] == rnd and row["n"] == 2
        assert row["psnr_head"] == pytest.approx(
            np.mean([_psnr_ref(i[k], re[k]) for i, re in zip(imag, real, strict=True)])
        )
        assert row["psnr_head_frozen"] == pytest.approx(np.mean([_psnr_ref(re[0], re[k]) for re in real]))
    assert len(r["per_round"]) == 2

    # Horizons up to the rounds asked for; rounds beyond the stored frames get no per-round row.
    longer = horizon_sweep(root, 5, K)
    assert [row["rounds"] for row in longer["rows"]] == [h for h in HORIZONS if h <= 5] == [1, 2, 5]
    assert longer["rows"][2]["hfr"] == pytest.approx((2 / (1 + 5 * K) + T / (1 + 5 * K)) / 2)
    assert [row["round"] for row in longer["per_round"]] == [1, 2]
    assert [row["rounds"] for row in horizon_sweep(root, 1, K)["rows"]] == [1]


def test_horizon_sweep_without_verdicts(tmp_path: Path) -> None:
    """An unjudged run has no HFR (None, n = 0) but still its per-round error."""
    root = write_paired(tmp_path / "run", [SynthPair(offset=5)])
    r = horizon_sweep(root, ROUNDS, K)
    assert [(row["hfr"], row["n"]) for row in r["rows"]] == [(None, 0), (None, 0)]
    assert [row["n"] for row in r["per_round"]] == [1, 1]


# ---------------------------------------------------------------------- horizon sweep, real run


@pytest.fixture(scope="module")
def judged_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2-round paired run (sort_cubes, scripted_step_30k, 1 subtask) judged by the image-only judge."""
    out = tmp_path_factory.mktemp("stability") / "run"
    cfg = PairedConfig(
        rig=SIM,
        task="sort_cubes",
        checkpoints=["scripted_step_30k"],
        subtasks=1,
        out=str(out),
        spec=ChunkSpec(rounds=2),
    )
    paired_run(cfg, progress=False)
    judge_dataset(out, [VisionJudge()], RigConfig.load(SIM), workers=1)
    return out


def test_horizon_sweep_on_a_real_run(judged_run: Path) -> None:
    """HFR rows for horizons 1 and 2 only, in [0, 1], from the imagined branch's vision verdict; per-round
    PSNR finite for rounds 1 and 2."""
    r = horizon_sweep(judged_run, 2, K_SIM)
    assert r["pairs"] == 1 and r["run"] == str(judged_run)
    assert [(row["rounds"], row["frames"], row["n"]) for row in r["rows"]] == [(1, 1 + K_SIM, 1), (2, 1 + 2 * K_SIM, 1)]
    (pair,) = load_pairs(judged_run).pairs
    (verdict,) = [o for o in read_outcomes(judged_run) if o.episode_index == pair.imagined and o.judge_id == "vision"]
    t_h = verdict.num_frames if verdict.first_hallucination_frame is None else verdict.first_hallucination_frame
    for row in r["rows"]:
        assert 0.0 <= row["hfr"] <= 1.0
        assert row["hfr"] == pytest.approx(min(t_h, row["frames"]) / row["frames"])
    assert [row["round"] for row in r["per_round"]] == [1, 2]
    for row in r["per_round"]:
        assert row["n"] == 1
        assert math.isfinite(row["psnr_head"]) and math.isfinite(row["psnr_head_frozen"])
        assert 5.0 < row["psnr_head"] <= 100.0
    assert [row["rounds"] for row in horizon_sweep(judged_run, 1, K_SIM)["rows"]] == [1]


# ---------------------------------------------------------------------- probe summaries


def _views(high: float, left: float) -> dict[str, float]:
    return {"cam_high": high, "cam_left_wrist": left}


def _div(high: tuple[float, float], left: tuple[float, float]) -> dict[str, dict[str, float]]:
    return {
        "cam_high": {"pred": high[0], "real": high[1]},
        "cam_left_wrist": {"pred": left[0], "real": left[1]},
    }


ERRORS = rig_errors()
CAMERA_KEYS = [e.key for e in ERRORS if e.moves_head]


def _record(
    i: int,
    hold: tuple[tuple[float, float], tuple[float, float]],
    policy: float,
    kinds: tuple[str, ...],
    errors: list[str],
    shuffle: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """A start's record: error e (index j in ERRORS) costs j + 1 dB in the head view, 0.5 dB in the wrist view."""
    rec: dict[str, Any] = {
        "pair": f"p{i}",
        "task": "sort_cubes",
        "div:hold": _div(*hold),
        "div:reverse": _div((1.0 + i, 2.0), (float(i), 0.0)),  # the left view never differs in reality
        "psnr:policy": _views(policy, policy + 10),
        "psnr:frozen": _views(20.0 + i, 30.0),
    }
    for j, e in enumerate(ERRORS):
        if e.key in errors:
            rec[f"psnr:err:{e.key}"] = _views(policy - (j + 1), policy + 10 - 0.5)
    for n, kind in enumerate(kinds):
        rec[f"psnr:{kind}"] = _views(policy - 2 - n, policy)
    if shuffle is not None:
        rec["shuffle"] = shuffle
    return rec


def _shuffle(pred: float, real: float, shuffled: float, own: float, same: bool) -> dict[str, Any]:
    return {
        "div": {"cam_high": {"pred": pred, "real": real}, "cam_left_wrist": {"pred": 0.0, "real": 1.0}},
        "psnr": {
            "cam_high": {"shuffled": shuffled, "own": own, "frozen": 15.0},
            "cam_left_wrist": {"shuffled": 30.0, "own": 30.0, "frozen": 25.0},
        },
        "same": same,
    }


def _two_models() -> dict[str, list[dict[str, Any]]]:
    """Records of a model that binds the rig (every error reaches it) and one that does not (head errors only)."""
    every = [e.key for e in ERRORS]
    return {
        "binds": [
            _record(0, ((2.0, 4.0), (0.0, 0.0)), 30.0, ("fast", "jitter"), every, _shuffle(1.0, 4.0, 20.0, 22.0, True)),
            _record(
                1, ((4.0, 1.0), (0.0, 2.0)), 32.0, ("fast", "jitter"), every[1:], _shuffle(6.0, 2.0, 21.0, 22.0, True)
            ),
            _record(2, ((1.0, 1.0), (6.0, 2.0)), 34.0, ("jitter",), every, _shuffle(0.0, 0.0, 24.0, 23.0, False)),
        ],
        "no_bind": [
            _record(0, ((0.0, 4.0), (0.0, 0.0)), 25.0, ("fast", "jitter", "offset"), CAMERA_KEYS),
            _record(1, ((0.0, 1.0), (0.0, 2.0)), 27.0, ("fast", "jitter", "offset"), CAMERA_KEYS),
        ],
    }


def test_summarize_probes_on_hand_made_records_of_two_models() -> None:
    """Counterfactual ratio = median of per-start pred/real (starts with no real difference skipped); each wrong
    rig's PSNR and its change from the right rig over the starts that ran it; errors that do not reach a model
    have no figures; OOD rows over the starts that ran the kind; the action shuffle's figures per view."""
    recs = _two_models()
    views = ["cam_high", "cam_left_wrist"]
    s = _summarize_probes(recs["binds"], views, ERRORS, [e.key for e in ERRORS])
    t = _summarize_probes(recs["no_bind"], views, ERRORS, CAMERA_KEYS)
    assert s["starts"] == 3 and t["starts"] == 2

    hold, reverse = s["counterfactual"]["rows"]
    assert hold["alternative"] == "hold" and reverse["alternative"] == "reverse"
    # Ratios 0.5, 4, 1: median 1 (not their mean 1.83, nor the ratio of means 7/6).
    assert hold["cam_high"] == {
        "mse_pred": pytest.approx(7 / 3),
        "mse_real": pytest.approx(2.0),
        "ratio_median": pytest.approx(1.0),
        "distinct_share": 1.0,
    }
    # Start 0 has no real difference: ratios 0 and 3 only; 1 of 3 predictions differs at all.
    assert hold["cam_left_wrist"]["ratio_median"] == pytest.approx(1.5)
    assert hold["cam_left_wrist"]["distinct_share"] == pytest.approx(1 / 3)
    assert reverse["cam_high"]["ratio_median"] == pytest.approx(1.0)  # 1/2, 2/2, 3/2
    assert reverse["cam_left_wrist"]["ratio_median"] is None  # never a real difference
    assert t["counterfactual"]["rows"][0]["cam_high"]["distinct_share"] == 0.0  # the second model ignores "hold"
    assert t["counterfactual"]["rows"][0]["cam_high"]["ratio_median"] == 0.0

    cal, robot = s["calibration"]["rows"], s["robot_mismatch"]["rows"]
    assert [r["key"] for r in cal] == ["none"] + [e.key for e in ERRORS[:8]]
    assert [r["key"] for r in robot] == [e.key for e in ERRORS[8:]]
    none = cal[0]
    assert none["psnr_head"] == pytest.approx(32.0) and none["delta_db"] == 0.0 and none["n"] == 3
    assert none["per_view"] == {"cam_high": pytest.approx(32.0), "cam_left_wrist": pytest.approx(42.0)}
    # Error 0 (5 px) is missing from start 1: over starts 0 and 2 (policy 30, 34) it costs exactly 1 dB.
    pp5 = cal[1]
    assert pp5["kind"] == "principal_point" and pp5["params"] == {"shift_px": 5.0} and pp5["applies"]
    assert pp5["n"] == 2 and pp5["psnr_head"] == pytest.approx(31.0) and pp5["delta_db"] == pytest.approx(-1.0)
    assert pp5["delta_per_view"] == {"cam_high": pytest.approx(-1.0), "cam_left_wrist": pytest.approx(-0.5)}
    for j, row in enumerate(cal[2:] + robot, start=1):
        assert (
            row["n"] == 3
            and row["delta_db"] == pytest.approx(-(j + 1))
            and row["psnr_head"] == pytest.approx(32.0 - (j + 1))
        )
    assert s["robot_mismatch"]["baseline"]["psnr_head"] == pytest.approx(32.0)
    # The model without bind_rig: head errors only; wrist mounts and robot models do not reach it.
    t_rows = t["calibration"]["rows"][1:] + t["robot_mismatch"]["rows"]
    assert [r["applies"] for r in t_rows] == [True] * 6 + [False] * 5
    for r in t_rows[6:]:
        assert r["n"] == 0 and r["psnr_head"] is None and r["delta_db"] is None
    assert t_rows[0]["psnr_head"] == pytest.approx(25.0) and t_rows[0]["delta_db"] == pytest.approx(-1.0)

    ood = {row["kind"]: row for row in s["ood_actions"]["rows"]}
    assert list(ood) == ["policy", "fast", "jitter", "offset"]
    assert [ood[k]["n"] for k in ood] == [3, 2, 3, 0]
    assert ood["fast"]["psnr_head"] == pytest.approx(29.0)  # starts 0 and 1: 28, 30
    assert ood["offset"]["psnr_head"] is None
    assert s["ood_actions"]["frozen_per_view"] == {"cam_high": pytest.approx(21.0), "cam_left_wrist": 30.0}
    assert [row["n"] for row in t["ood_actions"]["rows"]] == [2, 2, 2, 2]

    sh = s["action_shuffle"]
    assert sh["rounds"] == SHUFFLE_ROUNDS == 2 and sh["n"] == 3
    head = sh["per_view"]["cam_high"]
    # pred/real 1/4, 6/2 and a start where neither differs (skipped): median of 0.25 and 3.
    assert head["ratio_median"] == pytest.approx(1.625) and head["distinct_share"] == pytest.approx(2 / 3)
    assert head["mse_pred"] == pytest.approx(7 / 3) and head["mse_real"] == pytest.approx(2.0)
    assert head["psnr_shuffled"] == pytest.approx(65 / 3) and head["psnr_own"] == pytest.approx(67 / 3)
    assert head["gap_db"] == pytest.approx(2 / 3) and head["psnr_frozen"] == 15.0
    left = sh["per_view"]["cam_left_wrist"]
    assert left["ratio_median"] == 0.0 and left["distinct_share"] == 0.0 and left["gap_db"] == 0.0
    assert sh["deterministic_share"] == pytest.approx(2 / 3)
    assert t["action_shuffle"]["n"] == 0 and t["action_shuffle"]["deterministic_share"] is None
    assert t["action_shuffle"]["per_view"]["cam_high"]["psnr_shuffled"] is None


def test_summarize_no_probe_records() -> None:
    """No start finished: every figure is None, counts 0."""
    s = _summarize_probes([], ["cam_high"], ERRORS, [e.key for e in ERRORS])
    assert s["starts"] == 0
    for row in s["counterfactual"]["rows"]:
        assert row["cam_high"] == {"mse_pred": None, "mse_real": None, "ratio_median": None, "distinct_share": None}
    rows = s["calibration"]["rows"] + s["robot_mismatch"]["rows"]
    assert all(row["psnr_head"] is None and row["delta_db"] is None and row["n"] == 0 for row in rows)
    assert all(row["psnr_head"] is None and row["n"] == 0 for row in s["ood_actions"]["rows"])
    assert s["action_shuffle"]["n"] == 0 and s["action_shuffle"]["per_view"]["cam_high"]["ratio_median"] is None


def _result(summaries: dict[str, dict[str, Any]], horizon: dict[str, Any], faith: dict[str, Any]) -> dict[str, Any]:
    """A bench result of these per-model probe summaries, each with the same horizon and faithfulness."""
    models = {
        name: {"label": f"{name} label", "horizon": horizon, "failure_faithfulness": faith, **s}
        for name, s in summaries.items()
    }
    return {
        "bench": "stability",
        "quick": True,
        "models": models,
        "probe_protocol": {"starts": 3, "errors": [e.to_json() for e in ERRORS]},
        "refused": [{"pair": "p0", "kind": "offset", "round": 1, "error": "too fast"}],
        "wall_s": 12.5,
    }


def _hand_made_result(tmp_path: Path) -> dict[str, Any]:
    recs = _two_models()
    views = ["cam_high", "cam_left_wrist"]
    root = write_paired(tmp_path / "run", [SynthPair(subtask=0, offset=5)])
    T = 1 + ROUNDS * K
    record_outcomes(root, [Outcome(0, "vision", "vision", False, T, 2)])
    horizon = horizon_sweep(root, ROUNDS, K)
    faith = {"real_failures": 3, "imagined_also_failed": 2 / 3, "real_successes": 1, "imagined_also_succeeded": 0.0}
    return _result(
        {
            "binds": {"binds_rig": True, **_summarize_probes(recs["binds"], views, ERRORS, [e.key for e in ERRORS])},
            "no_bind": {"binds_rig": False, **_summarize_probes(recs["no_bind"], views, ERRORS, CAMERA_KEYS)},
        },
        horizon,
        faith,
    )


def test_stability_tables_print_the_models_side_by_side(tmp_path: Path) -> None:
    text = stability_tables(_hand_made_result(tmp_path))
    t1 = 1 + K
    assert "| model | HFR at R = 1 | HFR at R = 2 |" in text
    assert f"| binds | {2 / t1:.3f} |" in text and f"| no_bind | {2 / t1:.3f} |" in text
    assert "| start frame held (frozen) |" in text
    assert "| binds | 3 | 66.7 | 1 | 0.0 |" in text
    assert "| binds: policy vs hold | 2 / 2 (1.00) | 2 / 1 (1.50) |" in text
    assert "| no_bind: policy vs hold | 0 / 2 (0.00) |" in text
    # Wrong rigs: a row per error, for each model its head PSNR and its change (head / wrist).
    assert "| the rig's calibration | 32.00 | 0.00 / 0.00 | 26.00 | 0.00 / 0.00 |" in text
    assert "| head principal point +5 px | 31.00 | -1.00 / -0.50 | 25.00 | -1.00 / -0.50 |" in text
    assert "| wrist camera mounts 2 mm, 0.5° | 25.00 | -7.00 / -0.50 | does not reach it |  |" in text
    assert "| robot colour (0.8, 0.3, 0.3, 1) | 21.00 | -11.00 / -0.50 | does not reach it |  |" in text
    assert "| binds: fast | 29.00 | 31.00 | 2 |" in text and "| no_bind: offset | 22.00 | 26.00 | 2 |" in text
    assert "| binds: cam_high | 2 / 2 (1.62) | 66.7 | 21.67 | 22.33 | 15.00 | 3 | 66.7 |" in text
    assert "| no_bind: cam_high | — / — (—) | — | — | — | — | 0 | — |" in text
    assert "refused by the safety filter: 1." in text


def test_stability_chart_of_two_models(tmp_path: Path) -> None:
    path = stability_chart(_hand_made_result(tmp_path), tmp_path / "sub" / "stability.png")
    assert path == tmp_path / "sub" / "stability.png" and path.read_bytes()[:8] == PNG


def test_cli_summary_and_models_flag(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``pilworld bench stability --models a,b``: the names reach the bench; the summary prints each model's
    key figures; ``--json`` ends with the whole result."""
    import pilworld.bench.stability as stability
    from pilworld.cli.main import main

    result = _hand_made_result(tmp_path)
    seen: dict[str, Any] = {}

    def fake_run(**kwargs: Any) -> dict[str, Any]:
        seen.update(kwargs)
        return result

    monkeypatch.setattr(stability, "run_stability", fake_run)
    argv = ["bench", "stability", "--quick", "--models", "v2_markers, pilworld", "--out", str(tmp_path / "o"), "--json"]
    assert main(argv) == 0
    assert seen["models"] == ["v2_markers", "pilworld"] and seen["quick"] is True and seen["progress"] is False
    out = capsys.readouterr().out
    assert "stability (quick): 2 model(s), 3 probe starts, 1 probe chunk(s) refused" in out
    assert "[binds] binds label" in out and "[no_bind] no_bind label" in out
    assert "head principal point +5 px: -1.00 (cam_high -1.00, cam_left_wrist -0.50)" in out
    assert "robot link radii ×0.8: does not reach this model" in out
    assert "action shuffle (2 rounds, 3 starts), head view: MSE ratio model/sim 1.62" in out
    assert json.loads(out.strip().splitlines()[-1])["chart"] == str(tmp_path / "o" / "stability.png")
    assert (tmp_path / "o" / "stability.png").read_bytes()[:8] == PNG
    monkeypatch.setattr(stability, "run_stability", fake_run)
    assert main(["bench", "stability", "--quick", "--out", str(tmp_path / "o")]) == 0
    assert seen["models"] is None  # the bench's default models


def test_psnr_and_mse() -> None:
    a = np.full((2, 4, 4, 3), 100, dtype=np.uint8)
    b = a + np.uint8(5)
    assert _mse(a, b) == 25.0 and _mse(b, a) == 25.0 and _mse(a, a) == 0.0
    assert _psnr(a, b) == pytest.approx(10 * math.log10(255.0**2 / 25.0))
    assert _psnr(a, a) == 100.0


# ---------------------------------------------------------------------- the probes end to end


@pytest.fixture(scope="module")
def probed() -> dict[str, Any]:
    """The probes of both default models from one start (sort_cubes, scripted_step_30k)."""
    return probe(rig=SIM, tasks=("sort_cubes",), checkpoints=("scripted_step_30k",), starts=1, progress=False)


PAIR = "sort_cubes/scripted_step_30k/seed7000500/subtask0"


def test_probe_models_protocol_and_counterfactual(probed: dict[str, Any]) -> None:
    assert list(probed["models"]) == list(DEFAULT_MODELS)
    p = probed["protocol"]
    assert p["starts"] == 1 and p["seed0"] == 7_000_500 and p["shuffle_rounds"] == 2
    assert [e["key"] for e in p["errors"]] == [e.key for e in rig_errors()]
    for name, m in probed["models"].items():
        assert m["starts"] == 1 and m["binds_rig"] is True, name
        rows = m["counterfactual"]["rows"]
        assert [row["alternative"] for row in rows] == ["hold", "reverse"]
        for row in rows:
            assert set(row) == {"alternative", *VIEWS}
            for v in VIEWS:
                assert row[v]["mse_pred"] >= 0.0 and row[v]["mse_real"] >= 0.0, (name, v)
            # The policy moves the arms, hold and reverse do not: the head camera sees different futures.
            assert row["cam_high"]["mse_real"] > 0.0 and row["cam_high"]["ratio_median"] >= 0.0


def test_probe_wrong_rigs(probed: dict[str, Any]) -> None:
    """Every error reaches both v2 models, once per start, with a finite PSNR; the right rig's row is the policy's
    chunk of the OOD table; the shipped model loses PSNR with a wrong head camera."""
    for name, m in probed["models"].items():
        cal, robot = m["calibration"]["rows"], m["robot_mismatch"]["rows"]
        assert [r["key"] for r in cal + robot] == ["none"] + [e.key for e in rig_errors()]
        assert cal[0]["delta_db"] == 0.0 and cal[0]["psnr_head"] == m["ood_actions"]["rows"][0]["psnr_head"]
        for row in cal + robot:
            assert row["applies"] and row["n"] == 1, (name, row["key"])
            assert math.isfinite(row["psnr_head"]) and math.isfinite(row["delta_db"]), (name, row["key"])
            assert set(row["per_view"]) == set(VIEWS) == set(row["delta_per_view"])
            assert row["delta_db"] == pytest.approx(row["psnr_head"] - cal[0]["psnr_head"])
    shipped = {r["key"]: r for r in probed["models"]["pilworld"]["calibration"]["rows"]}
    assert shipped["pp20px"]["delta_db"] < -0.5 and shipped["head10mm1deg"]["delta_db"] < -0.5
    assert min(shipped["wrist5mm1deg"]["delta_per_view"][v] for v in VIEWS[1:]) < -0.5


def test_probe_ood_actions_and_refusals(probed: dict[str, Any]) -> None:
    """Every OOD kind has a row; a kind the safety filter refused is listed in ``refused`` and has no PSNR."""
    refused = probed["refused"]
    assert isinstance(refused, list)
    for item in refused:
        assert item["pair"] == PAIR
        assert item["kind"] in ("fast", "jitter", "offset")  # the start counted: policy, hold, reverse ran
    refused_kinds = {item["kind"] for item in refused}
    for m in probed["models"].values():
        ood = m["ood_actions"]["rows"]
        assert [row["kind"] for row in ood] == ["policy", "fast", "jitter", "offset"]
        for row in ood:
            assert set(row["per_view"]) == set(VIEWS)
            if row["kind"] in refused_kinds:
                assert row["n"] == 0 and row["psnr_head"] is None, row["kind"]
            else:
                assert row["n"] == 1 and math.isfinite(row["psnr_head"]), row["kind"]
                assert row["psnr_head"] == row["per_view"]["cam_high"]
        assert set(m["ood_actions"]["frozen_per_view"]) == set(VIEWS)


def test_probe_action_shuffle(probed: dict[str, Any]) -> None:
    """Two rounds of the donor's chunks: both futures differ in reality, the models' are deterministic, their
    PSNRs finite; the simulator's side is shared by the models."""
    sims = []
    for name, m in probed["models"].items():
        sh = m["action_shuffle"]
        assert sh["rounds"] == 2 and sh["n"] == 1 and sh["deterministic_share"] == 1.0, name
        assert set(sh["per_view"]) == set(VIEWS)
        for v, s in sh["per_view"].items():
            assert s["mse_pred"] >= 0.0 and math.isfinite(s["psnr_shuffled"]) and math.isfinite(s["psnr_own"]), v
            assert s["gap_db"] == pytest.approx(s["psnr_own"] - s["psnr_shuffled"])
        assert sh["per_view"]["cam_high"]["mse_real"] > 0.0  # another episode's chunks: another real future
        assert sh["per_view"]["cam_high"]["distinct_share"] == 1.0
        sims.append({v: (s["mse_real"], s["psnr_frozen"]) for v, s in sh["per_view"].items()})
    assert sims[0] == sims[1]


def test_stability_tables_and_chart_from_the_probe_and_sweep(
    probed: dict[str, Any], judged_run: Path, tmp_path: Path
) -> None:
    """The bench's tables and chart draw from these results (including a None PSNR of a refused kind)."""
    from pilworld.bench.paired import failure_faithfulness

    result = _result(
        {k: {kk: vv for kk, vv in m.items() if kk != "label"} for k, m in probed["models"].items()},
        horizon_sweep(judged_run, 2, K_SIM),
        failure_faithfulness(str(judged_run)),
    )
    text = stability_tables(result)
    assert "| pilworld: policy vs hold |" in text and "| v2_paper_gamma: cam_right_wrist |" in text
    path = stability_chart(result, tmp_path / "sub" / "stability.png")
    assert path.read_bytes()[:8] == PNG
