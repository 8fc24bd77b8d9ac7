"""Mocked hardware end to end: the real client libraries drive the fake rig (docs/hardware.md).

The real branch of a subtask runs through ``DualArmRobot`` — two ``URArm``s (ur_rtde) on the fake
UR controllers, a Dynamixel gripper (dynamixel_sdk) and a Robotiq gripper (pyserial, Modbus RTU) on
pseudo-terminals, three ``OpenCVCamera``s on the MJPEG server — and must end as the same subtask on
``SimRobot`` directly does, with the objects within 5 mm. Faults injected mid-run end in typed
errors within a bound, with the arms stopped and what was recorded so far readable.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from hw_drivers.errors import DeviceConnectionError, ProtectiveStopError, RobotError, StaleObservationError
from pilworld.config.rig import RigConfig
from pilworld.data.outcomes import read_outcomes
from pilworld.data.reader import EpisodeStore
from pilworld.envs import RobotEnv
from pilworld.paired import PairedConfig, paired_run
from pilworld.paired.operator import ConsoleOperator
from pilworld.paired.stations import HardwareStation
from pilworld.policies.registry import make_policy
from pilworld.rollout import closed_loop
from pilworld.types import ChunkSpec, Subtask
from simrig.robot import SimRobot
from simrig.tasks import make_task

FAKE = "configs/rig/fake_dual_ur5e.yaml"
SIM = "configs/rig/sim_dual_ur5e.yaml"
CKPT = "scripted_step_30k"


class Answers:
    """Scripted answers to the operator's prompts; records the questions."""

    def __init__(self, *answers: str) -> None:
        self.answers = list(answers)
        self.asked: list[str] = []

    def __call__(self, question: str) -> str:
        self.asked.append(question)
        return self.answers.pop(0) if self.answers else ""


def _operator(*answers: str) -> tuple[ConsoleOperator, Answers]:
    ask = Answers(*answers)
    return ConsoleOperator(ask=ask, tell=lambda _: None), ask


def _subtask(task: str, seed: int, index: int) -> Subtask:
    return Subtask(task=task, index=index, instruction=make_task(task).instruction, seed=seed)


# The fake rig runs in real time beside the test. A machine that cannot give it the CPU it needs pauses its physics,
# its controllers' 2 ms cycles or the drivers' servo loops, and commands then take effect late: what runs is a
# different run, not a wrong one, and comparing its outcome with SimRobot's says nothing. Past this bound the
# comparison is skipped, naming the pauses. Idle here the worst pause is 0.09 s (physics; cycles 15 ms, servo
# 10 ms); with the test's processes frozen 60 ms of every 100 ms (SIGSTOP), 0.17 s, and the outcomes still matched.
PAUSE_VOID_S = 0.3


def _timing(station: HardwareStation) -> dict[str, float]:
    """The longest pauses of the run so far [s]: the fake's physics and controller cycles, the servo loops."""
    arms = getattr(station.robot, "arms", {})
    servo = max((a.servo_stats().period_max_ms for a in arms.values()), default=0.0) / 1000.0
    return {**station.fake.timing(), "servo_period_max_s": servo}


def _reset_timing(station: HardwareStation) -> None:
    for arm in getattr(station.robot, "arms", {}).values():
        arm.reset_servo_stats()


def _skip_if_paused(timing: dict[str, float], what: str) -> None:
    late = {k: round(v, 3) for k, v in timing.items() if v > PAUSE_VOID_S}
    if late:
        pytest.skip(f"{what}: this machine paused the real-time rig ({late} s, bound {PAUSE_VOID_S} s): void")


def _on_sim(sub: Subtask, spec: ChunkSpec) -> tuple[bool, dict[str, np.ndarray], list[np.ndarray]]:
    """The same subtask on SimRobot directly (the fake rig's scenes start at home: no lead-in): the checker's
    verdict, the object positions and the chunks the policy returned."""
    rig = RigConfig.load(SIM)
    with SimRobot(SIM, sub.task) as robot:
        start = robot.reset(seed=sub.seed, subtask=sub.index, history=0)
        policy = make_policy(CKPT, rig, spec)
        policy.reset(seed=sub.seed)
        rollout = closed_loop(policy, RobotEnv(robot, spec, pace=False), sub.instruction, spec.rounds, start=start)
        check = robot.check_subtask(sub.index)
        poses = {n: np.asarray(p.xyz) for n, p in robot.object_poses().items()}
        return check.success, poses, [np.asarray(c) for c in rollout.chunks]


def _replayed_on_fake_rig(
    sub: Subtask, spec: ChunkSpec, chunks: list[np.ndarray]
) -> tuple[dict[str, bool], dict[str, np.ndarray]]:
    """SimRobot's chunks sent through the drivers as they were queried there: no policy decides anything."""
    operator, _ = _operator("", "y")
    with HardwareStation(FAKE, operator) as station:
        start = station.start(sub, CKPT, spec)
        _reset_timing(station)
        env = RobotEnv(station.robot, spec, pace=True)
        env.reset(start)
        try:
            frames = 1 + sum(len(env.step(chunk).observations) for chunk in chunks)
        except RobotError:  # e.g. a watchdog stop after a pause of the machine's making
            _skip_if_paused(_timing(station), "replayed chunks")
            raise
        _skip_if_paused(_timing(station), "replayed chunks")
        verdicts = station.verdicts(sub, CKPT, 0, frames)
        poses = {n: np.asarray(p) for n, p in station.fake.object_poses().items()}
    return {o.judge_id: o.success for o in verdicts}, poses


def _on_fake_rig(sub: Subtask, spec: ChunkSpec) -> tuple[dict[str, bool], dict[str, np.ndarray], list[str]]:
    operator, ask = _operator("", "y")
    rig = RigConfig.load(SIM)
    with HardwareStation(FAKE, operator) as station:
        start = station.start(sub, CKPT, spec)
        policy = make_policy(CKPT, rig, spec)
        policy.reset(seed=sub.seed)
        _reset_timing(station)
        env = RobotEnv(station.robot, spec, pace=True)
        try:
            rollout = closed_loop(policy, env, sub.instruction, spec.rounds, start=start)
        except RobotError:  # e.g. the policy, planning from a late look, asked for too large a step
            _skip_if_paused(_timing(station), "closed loop")
            raise
        _skip_if_paused(_timing(station), "closed loop")
        verdicts = station.verdicts(sub, CKPT, 0, len(rollout.observations))
        poses = {n: np.asarray(p) for n, p in station.fake.object_poses().items()}
    return {o.judge_id: o.success for o in verdicts}, poses, ask.asked


def _compare(task: str, seed: int, index: int) -> None:
    spec = ChunkSpec(rounds=5)
    sub = _subtask(task, seed, index)
    verdicts, poses, asked = _on_fake_rig(sub, spec)
    success, sim_poses, _ = _on_sim(sub, spec)
    assert verdicts["sim_checker"] == success, f"fake rig {verdicts}, SimRobot {success}"
    assert verdicts["operator"] is True  # the scripted operator said "y"
    assert len(asked) == 2 and "scene is ready" in asked[0] and "succeed" in asked[1]
    _assert_objects_within(poses, sim_poses, 0.005)


def _assert_objects_within(poses: dict[str, np.ndarray], sim_poses: dict[str, np.ndarray], bound_m: float) -> None:
    gaps = {n: float(np.linalg.norm(poses[n] - sim_poses[n])) for n in sim_poses}
    assert max(gaps.values()) < bound_m, (
        f"object positions differ: { {n: f'{g * 1000:.2f} mm' for n, g in gaps.items()} }"
    )


def test_a_mocked_hardware_subtask_ends_as_on_the_simulator() -> None:
    _compare("sort_cubes", 11, 0)


@pytest.mark.slow
def test_a_mocked_hardware_subtask_of_a_stacking_task_ends_as_on_the_simulator() -> None:
    """stack_bowls 13/0, SimRobot's chunks replayed through the drivers: the bowls nest as on SimRobot.

    Replayed, for the reason the tower test below gives: in closed loop the policy sees the head camera's JPEG
    frames, whose age grows with the machine's load; in the CI run of c1189c0 (every core busy) its plan on
    this subtask missed the medium bowl, which then stayed where it was (288 mm from where SimRobot put it),
    while it passed on this machine unloaded. The closed-loop comparison stays on sort_cubes, whose outcome
    does not hang on a frame's age.
    """
    sub = _subtask("stack_bowls", 13, 0)
    spec = ChunkSpec(rounds=5)
    success, sim_poses, chunks = _on_sim(sub, spec)
    verdicts, poses = _replayed_on_fake_rig(sub, spec, chunks)
    assert verdicts["sim_checker"] == success, f"fake rig {verdicts}, SimRobot {success}"
    # 5 mm, not the tower's 1 mm: with every core busy the fake's 500 Hz servo loops slip and the bowls, which
    # slide on each other as they nest, ended up to 2 mm from SimRobot's (1 of 4 loaded runs here).
    _assert_objects_within(poses, sim_poses, 0.005)


@pytest.mark.slow
def test_the_simulators_commands_through_the_drivers_build_the_same_tower() -> None:
    """stack_blocks 12/1 (the third block onto a two-block tower), SimRobot's chunks replayed on the fake rig.

    Replayed, not in closed loop: there the policy sees the head camera's JPEG frames, up to 1/camera_fps old,
    instead of SimRobot's renders, and on this subtask its plan puts the top block ~4 mm from where it puts it
    on SimRobot (3.6-4.2 mm where it went on to succeed); in 5 of 17 runs here and in the CI run of 2bdffd2 its
    next look judged the tower unfinished and it knocked the tower over. The drivers and the fake's physics
    are not the cause: replayed, the blocks end within 0.04 mm of SimRobot's (4 of 4 runs). This test pins
    that down; the closed-loop tests keep the policy in the loop on subtasks whose outcome does not hang on a
    few pixels.
    """
    sub = _subtask("stack_blocks", 12, 1)
    spec = ChunkSpec(rounds=5)
    success, sim_poses, chunks = _on_sim(sub, spec)
    assert success  # a finished three-block tower: the hardest placement the tasks have
    verdicts, poses = _replayed_on_fake_rig(sub, spec, chunks)
    assert verdicts["sim_checker"] is True, f"fake rig {verdicts}"
    _assert_objects_within(poses, sim_poses, 0.001)


def test_paired_run_on_the_fake_rig_with_operator_prompts(tmp_path: Path) -> None:
    """``pilworld paired run --rig fake_dual_ur5e.yaml``: prompts answered, both branches and both judges stored."""
    out = tmp_path / "paired"
    operator, ask = _operator("", "n")
    cfg = PairedConfig(
        rig=FAKE, task="sort_cubes", checkpoints=[CKPT], subtasks=1, out=str(out), spec=ChunkSpec(rounds=1)
    )
    summary = paired_run(cfg, progress=False, operator=operator)
    assert summary["branches_run"] == 2
    store = EpisodeStore(out)
    assert sorted(store.load(i).origin for i in range(store.num_episodes)) == ["imagined", "real"]
    judges = {(o.judge_id, o.judge_kind): o.success for o in read_outcomes(out)}
    assert judges[("operator", "human")] is False  # what the operator answered
    assert ("sim_checker", "sim_state") in judges
    assert any("scene is ready" in q for q in ask.asked) and any("succeed" in q for q in ask.asked)


@pytest.fixture
def station() -> Iterator[HardwareStation]:
    operator, _ = _operator()
    with HardwareStation(FAKE, operator) as st:
        yield st


def _run_until_error(station: HardwareStation, inject: tuple[str, str], bound_s: float) -> RobotError:
    """Stream commands at the control rate; inject the fault after 0.5 s; the typed error must follow in time."""
    robot = station.robot
    q = robot.observe().state.astype(np.float64)
    period = 1.0 / robot.spec.control_rate_hz
    t_fault: float | None = None
    t0 = time.monotonic()
    with pytest.raises(RobotError) as caught:
        while time.monotonic() - t0 < 10.0:
            if t_fault is None and time.monotonic() - t0 > 0.5:
                station.fake.inject(*inject)
                t_fault = time.monotonic()
            robot.send_action(q)
            robot.observe()
            time.sleep(period)
    assert t_fault is not None, f"the error came before the fault was injected: {caught.value!r}"
    took = time.monotonic() - t_fault
    assert took < bound_s, f"{inject}: {type(caught.value).__name__} after {took:.2f} s (bound {bound_s} s)"
    return caught.value


@pytest.mark.slow
@pytest.mark.parametrize(
    ("fault", "error", "bound_s"),
    [
        (("left_arm", "protective_stop"), ProtectiveStopError, 1.0),
        (("right_arm", "disconnect"), DeviceConnectionError, 1.0),
        (("cameras", "stall"), StaleObservationError, 1.5),
        (("right_gripper", "stall"), RobotError, 5.0),  # 3 tries of the fake rig's 1 s reply timeout
    ],
)
def test_an_injected_fault_stops_the_robot_with_a_typed_error(
    station: HardwareStation, fault: tuple[str, str], error: type[RobotError], bound_s: float
) -> None:
    err = _run_until_error(station, fault, bound_s)
    assert isinstance(err, error), f"{fault}: got {type(err).__name__}: {err}"
    # The arms are stopped: the simulated joints no longer move.
    before = np.asarray(station.fake.request("state"))
    time.sleep(0.3)
    after = np.asarray(station.fake.request("state"))
    assert float(np.abs(after - before)[[0, 1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 12]].max()) < 1e-3


@pytest.mark.slow
def test_a_fault_mid_run_keeps_the_recorded_episodes_readable(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A protective stop after the first pair: the run stops with the typed error, the pair stays readable."""
    import pilworld.paired.runner as runner
    from pilworld.paired.stations import open_station as real_open

    stations: list[HardwareStation] = []

    def capture(*args: object, **kwargs: object) -> object:
        st = real_open(*args, **kwargs)  # type: ignore[arg-type]
        stations.append(st)  # type: ignore[arg-type]
        return st

    monkeypatch.setattr(runner, "open_station", capture)

    def after(pair: object, origin: str) -> None:
        if origin == "real":
            stations[0].fake.inject("left_arm", "protective_stop")

    out = tmp_path / "paired"
    operator, _ = _operator()
    cfg = PairedConfig(
        rig=FAKE, task="sort_cubes", checkpoints=[CKPT], subtasks=2, out=str(out), spec=ChunkSpec(rounds=1)
    )
    with pytest.raises(ProtectiveStopError):
        paired_run(cfg, progress=False, operator=operator, on_branch=after)
    store = EpisodeStore(out)
    assert store.num_episodes == 2
    for i in range(2):
        assert store.load(i).length > 1


def test_the_fake_rig_reports_how_well_it_kept_real_time(station: HardwareStation) -> None:
    """The pauses a loaded machine puts into the real-time rig are measured (the void rule above rests on them)."""
    timing = _timing(station)
    assert set(timing) == {"physics_lag_max_s", "controller_gap_max_s", "servo_period_max_s"}
    assert all(0.0 <= v < 60.0 for v in timing.values()), timing
    assert timing["controller_gap_max_s"] > 0.0 and timing["servo_period_max_s"] > 0.0  # cycles ran
