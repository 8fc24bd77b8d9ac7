"""The shipped world model in a closed loop on the simulated rig: the picked cube is carried into its slot.

This is what the tracked objects are for: before them, v2's imagined branch lost every carried object
and the judge failed every rollout (docs/world_model.md, "Where v2 stands").
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

from hw_drivers.safety import SafetyFilter
from pilworld.config.rig import RigConfig
from pilworld.control_video.gamma import ControlVideo
from pilworld.envs import ImaginedEnv
from pilworld.judges.base import JudgeContext
from pilworld.judges.vision_success import VisionSuccessJudge
from pilworld.paired.episodes import rollout_episode
from pilworld.policies.registry import make_policy
from pilworld.rollout import Rollout, closed_loop
from pilworld.types import ChunkSpec, Start
from pilworld.world_model import DEFAULT_CHECKPOINT
from pilworld.world_model.base import PredictRequest
from pilworld.world_model.composite.model import CompositeWorldModel
from pilworld.world_model.loader import load_world_model
from simrig.robot import SimRobot
from simrig.tasks import load_task

ROOT = Path(__file__).resolve().parents[4]
SIM_RIG = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
SEED = 1_000_000  # held out: the model was trained on seeds 0–19
SPEC = ChunkSpec()


class Imagined(NamedTuple):
    rig: RigConfig
    model: CompositeWorldModel
    start: Start
    result: Rollout


@pytest.fixture(scope="module")
def rollout() -> Imagined:
    rig = RigConfig.load(SIM_RIG)
    with SimRobot(rig, "sort_cubes") as sim:
        start = sim.reset(seed=SEED, subtask=0, history=SPEC.history, stride=SPEC.stride)
        safety = SafetyFilter(sim.spec)
    model = load_world_model(DEFAULT_CHECKPOINT)
    assert isinstance(model, CompositeWorldModel)
    model.bind_rig(rig)
    env = ImaginedEnv(model, ControlVideo.from_rig(rig, SPEC), SPEC, control_rate_hz=rig.control_rate_hz, safety=safety)
    policy = make_policy("scripted_step_30k", rig, SPEC)
    policy.reset(seed=SEED)
    result = closed_loop(policy, env, start.subtask.instruction, SPEC.rounds, start=start)
    return Imagined(rig, model, start, result)


def test_the_carried_cube_ends_in_its_slot(rollout: Imagined) -> None:
    rig, model, result = rollout.rig, rollout.model, rollout.result
    scene = model._scene
    assert scene is not None
    task = load_task("sort_cubes")
    target = task.subtask_object(0)  # subtask 0: the first cube into the first slot
    slot = task.regions["slot_0"]
    assert slot.half_size is not None
    cube = next(o for o in scene.objects if o.name == target)
    assert cube.moved and cube.held_by is None
    assert (
        abs(cube.pose.x - slot.centre[0]) < slot.half_size[0] and abs(cube.pose.y - slot.centre[1]) < slot.half_size[1]
    )
    assert cube.pose.z == pytest.approx(0.0)
    episode = rollout_episode(result, checkpoint="scripted_step_30k", seed=SEED, extra={"sim_task": "sort_cubes"})
    verdict = VisionSuccessJudge().judge(episode, JudgeContext(rig, "sort_cubes"))
    assert verdict.success, verdict.reason
    # While it was held the robot measured the cube's width, as the real gripper does.
    grips = np.asarray(episode.state)[:, [6, 13]]
    held = grips[(grips > 0.06) & (grips < 0.85)]
    assert held.size and np.allclose(held.min(), 0.035 / 0.085, atol=0.02)


def test_a_request_that_does_not_continue_the_rollout_gets_its_own_objects(rollout: Imagined) -> None:
    model, start = rollout.model, rollout.start
    scene = model._scene
    assert scene is not None
    before = [(o.name, o.pose) for o in scene.objects]
    obs = start.observation
    request = PredictRequest.build(
        model.info,
        current=dict(obs.images),
        history=None,
        control=np.zeros((SPEC.frames, 128, 128, 3), np.uint8),
        actions=np.repeat(np.asarray(obs.state, np.float64)[None], SPEC.frames, 0),
        instruction=start.subtask.instruction,
        state=obs.state,
    )
    frames, states = model.predict_with_state(request)
    assert model._scene is scene and [(o.name, o.pose) for o in scene.objects] == before
    assert frames["cam_high"].shape == (SPEC.frames, 128, 128, 3) and states.shape == (SPEC.frames, 14)
