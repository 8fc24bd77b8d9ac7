"""Scripted checkpoints: chunks of the right shape and range, observation-only (they act on what the
head camera shows, never on simulator state), graded checkpoints and their errors."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from pilworld.collection.rollout import run_subtask
from pilworld.policies.scripted import BEST_CHECKPOINT, CHECKPOINTS, ScriptedPolicy, checkpoint
from pilworld.policies.scripted.skill import errors_for
from pilworld.types import HEAD_VIEW, LEFT_ARM, RIGHT_ARM, ChunkSpec, Observation
from simrig.robot import SimRobot
from simrig.tasks import TASK_NAMES, load_task

ROOT = Path(__file__).resolve().parents[3]
SIM = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
ARM = np.r_[LEFT_ARM, RIGHT_ARM]
INSTRUCTIONS = [load_task(t).instruction for t in TASK_NAMES]


def _check_chunk(robot: SimRobot, chunk: NDArray[np.float32], state: NDArray[np.float32]) -> None:
    assert chunk.dtype == np.float32 and chunk.shape == (50, 14)
    assert np.all(np.isfinite(chunk))
    lo, hi = robot.spec.lower_array, robot.spec.upper_array
    assert np.all(chunk >= lo - 1e-6) and np.all(chunk <= hi + 1e-6)
    jump = float(np.abs(chunk[0, ARM] - state[ARM]).max())
    assert jump < 0.15, f"first row is {jump:.3f} rad from the measured state"


# ---------------------------------------------------------------------- chunks


@pytest.mark.parametrize("task", TASK_NAMES)
def test_infer_returns_continuous_chunks_within_limits(robots: Callable[[str], SimRobot], task: str) -> None:
    robot = robots(task)
    # As collection starts a run: the lead-in brings the arms home (tool down) before the first query.
    start = robot.reset(seed=4, subtask=0, history=5)
    policy = ScriptedPolicy(robot.rig, BEST_CHECKPOINT, seed=400)
    seen: list[int] = []

    def checked(obs: Observation, instruction: str) -> NDArray[np.float32]:
        chunk = policy.infer(obs, instruction)
        _check_chunk(robot, chunk, obs.state)
        seen.append(1)
        return chunk

    rec = run_subtask(robot, checked, start.observation, robot.task.instruction, record=False)
    assert len(seen) == ChunkSpec().rounds
    assert len(rec.commands) == ChunkSpec().rounds * ChunkSpec().executed_steps
    # At a subtask start the policy moves something: it does not just hold still.
    assert np.ptp(np.stack(rec.commands)[:, ARM], axis=0).max() > 0.1


def test_infer_needs_only_the_observation(robots: Callable[[str], SimRobot]) -> None:
    robot = SimRobot(SIM, "sort_cubes")
    robot.connect()
    start = robot.reset(seed=2, subtask=1, history=0)
    obs = start.observation
    # An observation rebuilt by hand from plain arrays, after the simulator is gone.
    by_hand = Observation(
        images={view: np.array(image, copy=True) for view, image in obs.images.items()},
        state=np.array(obs.state, dtype=np.float32, copy=True),
        timestamp=123.0,
    )
    robot.disconnect()
    assert not robot.is_connected
    policy = ScriptedPolicy(robot.rig, BEST_CHECKPOINT, seed=201)
    chunk = policy.infer(by_hand, robot.task.instruction)
    _check_chunk(robot, chunk, by_hand.state)
    again = ScriptedPolicy(robot.rig, BEST_CHECKPOINT, seed=201).infer(obs, robot.task.instruction)
    np.testing.assert_array_equal(chunk, again)  # nothing but the observation went into it
    # The head image alone suffices: the wrist views are not needed.
    head_only = Observation(images={HEAD_VIEW: obs.images[HEAD_VIEW]}, state=obs.state, timestamp=0.0)
    np.testing.assert_array_equal(
        ScriptedPolicy(robot.rig, BEST_CHECKPOINT, seed=201).infer(head_only, robot.task.instruction), chunk
    )


def test_infer_rejects_observations_it_cannot_use(robots: Callable[[str], SimRobot]) -> None:
    robot = robots("sort_cubes")
    obs = robot.reset(seed=0, subtask=0, history=0).observation
    policy = ScriptedPolicy(robot.rig)
    wrist_only = Observation(images={"cam_left_wrist": obs.images["cam_left_wrist"]}, state=obs.state, timestamp=0.0)
    with pytest.raises(ValueError, match="needs the 'cam_high' image"):
        policy.infer(wrist_only, robot.task.instruction)
    short = Observation(images=dict(obs.images), state=obs.state[:7], timestamp=0.0)
    with pytest.raises(ValueError, match=r"expected 14 values, got shape \(7,\)"):
        policy.infer(short, robot.task.instruction)


def test_unknown_instruction_lists_the_known_ones(robots: Callable[[str], SimRobot]) -> None:
    robot = robots("sort_cubes")
    obs = robot.reset(seed=0, subtask=0, history=0).observation
    policy = ScriptedPolicy(robot.rig)
    with pytest.raises(ValueError, match="instruction: the scripted policies know") as info:
        policy.infer(obs, "make me a coffee.")
    for instruction in INSTRUCTIONS:
        assert repr(instruction) in str(info.value)
    assert "'make me a coffee.'" in str(info.value)
    # Case and surrounding space do not matter.
    assert policy.infer(obs, "  Sort the Cubes by size.\n").shape == (50, 14)


# ---------------------------------------------------------------------- observation-only (acceptance)


def _blind(
    infer: Callable[[Observation, str], NDArray[np.float32]],
) -> Callable[[Observation, str], NDArray[np.float32]]:
    """The policy with its head camera covered: ``cam_high`` is all zeros in every observation it gets."""

    def wrapped(obs: Observation, instruction: str) -> NDArray[np.float32]:
        images = dict(obs.images)
        images[HEAD_VIEW] = np.zeros_like(images[HEAD_VIEW])
        return infer(Observation(images=images, state=obs.state, timestamp=obs.timestamp), instruction)

    return wrapped


@pytest.mark.parametrize("task", TASK_NAMES)
def test_policies_depend_on_the_head_image(robots: Callable[[str], SimRobot], task: str) -> None:
    robot = robots(task)
    normal, blind = [], []
    for seed in range(3):
        for results, wrap in ((normal, False), (blind, True)):
            start = robot.reset(seed=seed, subtask=0, history=0)
            policy = ScriptedPolicy(robot.rig, BEST_CHECKPOINT, seed=seed * 100)
            infer = _blind(policy.infer) if wrap else policy.infer
            rec = run_subtask(robot, infer, start.observation, robot.task.instruction, record=False)
            assert rec.check is not None
            results.append(rec.check.success)
    print(f"{task}: best checkpoint succeeds on {sum(normal)}/3 starts, {sum(blind)}/3 with cam_high blanked")
    assert not any(blind), "a policy that cannot see the table must not succeed"
    assert sum(normal) >= 2


# ---------------------------------------------------------------------- checkpoints and their errors


def test_checkpoints_are_ordered_and_named() -> None:
    skills = [c.skill for c in CHECKPOINTS]
    assert all(0.0 <= a < b <= 1.0 for a, b in itertools.pairwise(skills))  # worst → best
    assert skills[-1] == 1.0
    assert BEST_CHECKPOINT == CHECKPOINTS[-1].name == "scripted_step_30k"
    assert len({c.name for c in CHECKPOINTS}) == len(CHECKPOINTS)
    for c in CHECKPOINTS:
        assert checkpoint(c.name) == c


def test_unknown_checkpoint_lists_the_names() -> None:
    with pytest.raises(ValueError, match="unknown scripted checkpoint 'step_99k'") as info:
        checkpoint("step_99k")
    for c in CHECKPOINTS:
        assert c.name in str(info.value)
    from pilworld.config.rig import RigConfig

    with pytest.raises(ValueError, match="choose one of scripted_step_01k"):
        ScriptedPolicy(RigConfig.load(SIM), "step_99k")


def test_errors_are_deterministic_per_seed_and_object() -> None:
    a = errors_for(0.35, 7, "cube_small")
    assert errors_for(0.35, 7, "cube_small") == a
    assert errors_for(0.35, 8, "cube_small") != a
    assert errors_for(0.35, 7, "cube_large") != a
    assert errors_for(0.35, -3, "cube_small") == errors_for(0.35, -3, "cube_small")  # negative seeds work too
    best = errors_for(1.0, 7, "cube_small")
    assert best.grasp_offset == (0.0, 0.0) and best.place_offset == (0.0, 0.0)
    assert best.release_extra == 0.0 and best.speed == 1.0
    worst = errors_for(0.0, 7, "cube_small")
    assert worst.speed == pytest.approx(0.55) and 0.0 <= worst.release_extra <= 0.06
    # Worse skill scales the same draws up.
    mid = errors_for(0.5, 7, "cube_small")
    np.testing.assert_allclose(np.array(worst.grasp_offset) * 0.5, mid.grasp_offset)


@pytest.mark.parametrize("skill", [-0.1, 1.5])
def test_errors_reject_skill_outside_the_unit_interval(skill: float) -> None:
    with pytest.raises(ValueError, match=r"skill: expected a value in \[0, 1\]"):
        errors_for(skill, 0, "cube_small")


def test_policy_reset_draws_the_episode_errors(robots: Callable[[str], SimRobot]) -> None:
    robot = robots("stack_blocks")
    obs = robot.reset(seed=1, subtask=0, history=0).observation
    worst = ScriptedPolicy(robot.rig, CHECKPOINTS[0].name, seed=5)
    first = worst.infer(obs, robot.task.instruction)
    worst.reset(seed=5)
    np.testing.assert_array_equal(worst.infer(obs, robot.task.instruction), first)
    worst.reset(seed=6)
    assert not np.array_equal(worst.infer(obs, robot.task.instruction), first)
    assert worst.seed == 6 and worst.name == "scripted_step_01k"


def test_scripted_policies_cannot_reach_the_simulator() -> None:
    """Observation-only by construction: no policy module imports MuJoCo or the simulated robot."""
    import ast

    forbidden = ("mujoco", "simrig.robot", "simrig.gl", "simrig.scene")
    package = Path(__file__).resolve().parents[3] / "pilworld" / "policies" / "scripted"
    files = sorted(package.glob("*.py"))
    assert files
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            bad = [n for n in names if any(n == f or n.startswith(f + ".") for f in forbidden)]
            assert not bad, f"{path.name} imports {bad}: a scripted policy must see observations only"
