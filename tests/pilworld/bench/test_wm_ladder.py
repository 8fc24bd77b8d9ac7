"""``pilworld bench wm-ladder``: the wrappers do what the rungs claim, and the bench's JSON holds together.

A random ``tiny`` model (32×32, run resized on the 128×128 simulated rig) stands in for the shipped one;
one task, one checkpoint, one subtask, two rounds.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from pilworld.bench import wm_ladder as wl
from pilworld.cli.main import main
from pilworld.config.rig import RigConfig
from pilworld.types import LEFT_GRIP, RIGHT_GRIP, ChunkSpec, Observation, Segment, Start, Subtask
from pilworld.world_model.latent.checkpoint import save_model
from pilworld.world_model.latent.config import preset
from pilworld.world_model.latent.model import PilWorldModel

SIM = "configs/rig/sim_dual_ur5e.yaml"
SPEC = ChunkSpec(rounds=2)
TASK = "stack_bowls"
CHECKPOINT = "scripted_step_30k"
VIEWS = ("cam_high", "cam_left_wrist", "cam_right_wrist")


@pytest.fixture(autouse=True)
def one_thread() -> Any:
    """One torch thread: on a busy 2-core machine two threads make the tiny model ~50x slower."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="module")
def tiny_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A random tiny model whose output head is perturbed, so its predictions depend on their inputs."""
    torch.manual_seed(0)
    model = PilWorldModel(preset("tiny"))
    with torch.no_grad():
        torch.nn.init.normal_(model.denoiser.token_out.weight, std=0.05)
    folder = tmp_path_factory.mktemp("tiny") / "model"
    save_model(model.eval(), folder)
    return folder


def _obs(rng: np.random.Generator, t: float, size: int = 32) -> Observation:
    images = {v: rng.integers(0, 256, (size, size, 3), dtype=np.uint8) for v in VIEWS}
    return Observation(images=images, state=rng.normal(size=14).astype(np.float32), timestamp=t)


class _FakeEnv:
    """A branch whose observations report 'measured' states unrelated to the commands."""

    def __init__(self, spec: ChunkSpec) -> None:
        self._spec = spec
        self.rng = np.random.default_rng(0)
        self.t = 0.0

    @property
    def origin(self) -> str:
        return "real"

    @property
    def spec(self) -> ChunkSpec:
        return self._spec

    def reset(self, start: Start) -> Observation:
        return start.observation

    def step(self, chunk: Any) -> Segment:
        n = self._spec.frames
        obs = []
        for _ in range(n):
            self.t += 0.1
            obs.append(_obs(self.rng, self.t))
        actions = np.asarray(chunk, dtype=np.float32)[: self._spec.executed_steps]
        return Segment(observations=tuple(obs), actions=actions, stride=self._spec.stride)


def _start(rng: np.random.Generator) -> Start:
    sub = Subtask(task=TASK, index=0, instruction="stack the bowls", seed=0)
    return Start(subtask=sub, observation=_obs(rng, 0.0))


def test_state_contract_env_reports_the_commanded_actions() -> None:
    spec = ChunkSpec(frames=4, stride=3, horizon=12)
    chunk = np.random.default_rng(1).normal(size=(12, 14)).astype(np.float32)
    grips = [LEFT_GRIP, RIGHT_GRIP]
    segs = {}
    for mode in wl.STATE_MODES:
        env = wl.StateContractEnv(_FakeEnv(spec), mode)
        start = _start(np.random.default_rng(2))
        assert env.reset(start) is start.observation  # the start keeps its measured state in every mode
        segs[mode] = env.step(chunk), env
    measured = segs["real"][0]
    commanded = chunk[spec.stride_indices()]
    for k in range(spec.frames):
        np.testing.assert_array_equal(segs["commanded"][0].observations[k].state, commanded[k])
        arms = segs["arms_commanded"][0].observations[k].state
        np.testing.assert_array_equal(np.delete(arms, grips), np.delete(commanded[k], grips))
        np.testing.assert_array_equal(arms[grips], measured.observations[k].state[grips])
        assert not np.allclose(measured.observations[k].state, commanded[k])
        for mode in wl.STATE_MODES:  # images, times and executed actions are the branch's own
            o = segs[mode][0].observations[k]
            for v in VIEWS:
                np.testing.assert_array_equal(o.images[v], measured.observations[k].images[v])
            assert o.timestamp == measured.observations[k].timestamp
    np.testing.assert_array_equal(segs["commanded"][0].actions, measured.actions)
    assert len(segs["commanded"][1].gaps) == spec.frames and segs["commanded"][1].gaps[0][1] > 0
    assert all(g[1] == 0 for g in segs["arms_commanded"][1].gaps)
    with pytest.raises(ValueError, match="mode"):
        wl.StateContractEnv(_FakeEnv(spec), "imagined")


def test_autoencoded_env_changes_images_but_not_states(tiny_dir: Path) -> None:
    rig = RigConfig.load(SIM)
    model, _, resized = wl.load_ladder_model(tiny_dir, rig, ChunkSpec(), TASK)
    assert resized  # 32×32 on the 128×128 rig
    native = model.model  # type: ignore[attr-defined]
    ae = wl.autoencoder_for(native)
    assert isinstance(ae, wl.FrameAutoencoder)
    spec = ChunkSpec(frames=4, stride=3, horizon=12)
    rng = np.random.default_rng(3)
    start = _start(rng)
    env = wl.AutoencodedEnv(_FakeEnv(spec), ae)
    first = env.reset(start)
    raw_env = _FakeEnv(spec)  # the same seed: the frames the wrapped env saw
    chunk = np.zeros((12, 14), dtype=np.float32)
    seg, raw = env.step(chunk), raw_env.step(chunk)
    for o, r in [(first, start.observation), *zip(seg.observations, raw.observations, strict=True)]:
        np.testing.assert_array_equal(o.state, r.state)
        assert o.timestamp == r.timestamp
        for v in VIEWS:
            assert o.images[v].shape == r.images[v].shape
            assert not np.array_equal(o.images[v], r.images[v])
        # The env decodes a batch, this a single frame: convolutions may round a pixel the other way (±1).
        again = ae(np.asarray(r.images["cam_high"])[None])[0]
        np.testing.assert_allclose(o.images["cam_high"].astype(int), again.astype(int), atol=1)
    assert set(env.mse) == set(VIEWS) and all(len(m) == 1 + spec.frames for m in env.mse.values())
    # A model without encode/decode gets a reason instead of an autoencoder.
    reason = wl.autoencoder_for(wl.SeedShifted(native, 0))
    assert isinstance(reason, str) and "no frame autoencoder" in reason


def test_teacher_forced_round_one_is_the_free_round_one(tiny_dir: Path, tmp_path: Path) -> None:
    cfg = wl.LadderConfig(
        model=str(tiny_dir), tasks=(TASK,), checkpoints=(CHECKPOINT,), subtasks=1, spec=SPEC, out=str(tmp_path)
    )
    lab = wl.Lab(cfg)
    try:
        pair = cfg.plan()[0]
        rollout, _ = lab.real(pair)
        model, _, _ = lab.model(TASK)
        rounds = list(
            wl.teacher_forced_predictions(model, lab.gamma, SPEC, rollout, pair.seed, lab.rig_cfg.control_rate_hz)
        )
        assert [r for r, _, _ in rounds] == [0, 1]
        _, tf0, free0 = rounds[0]
        _, tf1, free1 = rounds[1]
        for v in VIEWS:
            assert tf0[v].shape == (SPEC.frames, 128, 128, 3)
            np.testing.assert_array_equal(tf0[v], free0[v])
        # From round 2 on the free loop conditions on its own frames, the teacher-forced one on the real ones.
        assert not np.array_equal(tf1["cam_high"], free1["cam_high"])
        errors = wl.teacher_forced_errors(model, lab.gamma, SPEC, rollout, pair.seed, lab.rig_cfg.control_rate_hz)
        assert errors["teacher_forced"][0] == errors["free"][0]
        assert errors["frozen"][0] == errors["frozen_start"][0]  # both hold the start frame in round 1
        assert errors["frozen"][1] != errors["frozen_start"][1]
        # The kept real branch loads back as the rollout that was run.
        again, _ = lab.real(pair)
        assert lab.real_runs == 1
        for a, b in zip(again.observations, rollout.observations, strict=True):
            np.testing.assert_array_equal(a.images["cam_high"], b.images["cam_high"])
            np.testing.assert_array_equal(a.state, b.state)
        np.testing.assert_array_equal(again.segments[1].actions, rollout.segments[1].actions)
        assert len(again.start.history) == len(rollout.start.history) == SPEC.history
    finally:
        lab.close()


def test_degradations_change_images_only() -> None:
    from pilworld.data.episode import Episode

    rng = np.random.default_rng(4)
    ep = Episode(
        images={v: rng.integers(0, 256, (3, 128, 128, 3), dtype=np.uint8) for v in VIEWS},
        state=np.zeros((3, 14), dtype=np.float32),
        action=np.zeros((3, 14), dtype=np.float32),
        task="stack the bowls",
    )
    assert wl.degrade_episode(ep, "plain") is ep
    for kind in ("blur", "artefact"):
        d = wl.degrade_episode(ep, kind, rng=np.random.default_rng(0))
        assert d.state is ep.state
        for v in VIEWS:
            assert d.images[v].shape == ep.images[v].shape and d.images[v].dtype == np.uint8
            assert not np.array_equal(d.images[v], ep.images[v])
    with pytest.raises(ValueError, match="degradation"):
        wl.degrade_episode(ep, "sharpen")


def test_teacher_forced_episode_keeps_the_start_and_takes_the_predictions() -> None:
    from pilworld.data.episode import Episode

    ep = Episode(
        images={v: np.zeros((5, 8, 8, 3), dtype=np.uint8) for v in VIEWS},
        state=np.zeros((5, 14), dtype=np.float32),
        action=np.zeros((5, 14), dtype=np.float32),
        task="stack the bowls",
    )
    frames = {v: [np.full((2, 8, 8, 3), 1, np.uint8), np.full((2, 8, 8, 3), 2, np.uint8)] for v in VIEWS}
    forced = wl.teacher_forced_episode(ep, frames)
    for v in VIEWS:
        assert forced.images[v][:, 0, 0, 0].tolist() == [0, 1, 1, 2, 2]
    assert forced.state is ep.state and forced.origin == "imagined"
    with pytest.raises(ValueError, match="4 frames predicted for 5"):
        wl.teacher_forced_episode(
            dataclasses.replace(ep, images={v: np.zeros((6, 8, 8, 3), np.uint8) for v in VIEWS}), frames
        )


def test_a_learned_judges_drop_is_counted_on_episodes_judged_both_ways() -> None:
    from pilworld.bench.wm_ladder.stats import learned_summary

    truth = [True, True, False, False]
    plain = [{"success": True}, {"success": True}, {"success": False}, {"success": None}]
    degraded = [{"success": True}, {"success": False}, {"success": False}, {"success": False}]
    s = learned_summary(list(zip(truth, degraded, strict=True)), plain)
    assert (s["n"], s["judged"], s["abstained"]) == (4, 4, 0)
    assert s["agreement"] == 0.75
    assert s["both_judged"] == 3 and s["verdicts_changed"] == 1
    assert s["agreement_drop_points"] == round(100 * (1.0 - 2 / 3), 2)


def test_the_pairs_a_re_render_changed_are_listed_per_judge() -> None:
    from pilworld.bench.wm_ladder.teacher_forced import _judges_summary

    def rec(real: bool, ref: tuple[bool, bool], learned: tuple[bool | None, bool | None]) -> dict[str, Any]:
        return {
            "real": real,
            "reference": {
                k: {"success": v, "hallucination_frame": None}
                for k, v in zip(("plain", "teacher_forced"), ref, strict=True)
            },
            "learned": {"plain": {"success": learned[0]}, "teacher_forced": {"success": learned[1]}},
        }

    s = _judges_summary(
        [
            ("a", rec(True, (True, True), (True, False))),
            ("b", rec(False, (True, False), (None, True))),
            ("c", rec(True, (True, True), (True, True))),
        ]
    )
    assert s is not None
    assert s["changed"]["learned"] == [{"pair": "a", "real": True, "plain": True, "teacher_forced": False}]
    assert [c["pair"] for c in s["changed"]["reference"]] == ["b"]  # an abstention is no change


def _run_cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, dict[str, Any] | None, str]:
    code = main(args)
    out = capsys.readouterr()
    lines = out.out.strip().splitlines()
    return code, (json.loads(lines[-1]) if code == 0 else None), out.err


@pytest.mark.slow  # a whole quick bench, ~20 s idle: keeps the default suite near its 15 min
def test_cli_json_and_resume(tiny_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ladder"
    args = ["bench", "wm-ladder", "--quick", "--model", str(tiny_dir), "--tasks", TASK, "--checkpoints", CHECKPOINT]
    args += ["--subtasks", "1", "--rounds", "2", "--out", str(out), "--no-progress", "--json"]
    code, r, _ = _run_cli(args, capsys)
    assert code == 0 and r is not None
    assert r["model"] == str(tiny_dir) and r["model_resized"] is True and r["n_pairs"] == 1
    assert r["seeds"]["layout_seeds"] == [wl.LADDER_SEED0]
    assert r["rungs"] == list(wl.RUNGS) and r["skipped"] == {}
    for rung in wl.RUNGS:
        assert r[rung]["n"] == 1 and r[rung]["seeds"] == [wl.LADDER_SEED0]
        assert (out / f"{rung}.json").is_file() and (out / f"{rung}.jsonl").is_file()
    s = r["state_contract"]
    assert set(s["sr"]) == set(wl.STATE_MODES) and all(len(s["sr_ci95"][m]) == 2 for m in wl.STATE_MODES)
    assert set(s["delta_vs_real"]) == {"commanded", "arms_commanded"}
    assert s["real_branches_run"] == 1  # the other rungs reuse the kept real branch
    rep = r["representation"]
    assert set(rep["sr"]) == {"real", "autoencoded"} and set(rep["judges"]) == {"plain", "autoencoded"}
    assert 0 <= rep["judges"]["plain"]["hallucination_fp_rate"] <= 1 and rep["real_branches_run"] == 0
    assert set(rep["autoencoder_psnr"]) == {*VIEWS, "all"}
    jf = r["judge_fairness"]
    assert jf["degradations"] == list(wl.DEGRADATIONS)
    for d in wl.DEGRADATIONS:
        assert {"agreement", "hallucination_fp_rate", "fault_recall", "fault_outcomes"} <= set(jf[d])
        assert sum(jf[d]["fault_outcomes"].values()) == 1
    assert jf["plain"]["psnr_vs_plain"]["cam_high"] == 100.0  # the undegraded copy is bit-identical
    learned = jf["learned"]  # the shipped learned judge beside the hand-written one, on the same frames
    assert set(learned) == set(wl.DEGRADATIONS)
    for d in wl.DEGRADATIONS:
        assert learned[d]["n"] == 1 and learned[d]["judged"] + learned[d]["abstained"] == 1
    tf = r["teacher_forced"]
    j = tf["judges"]
    assert j["n"] == 1 and set(j["reference"]) == set(j["learned"]) == {"plain", "teacher_forced"}
    assert j["learned"]["teacher_forced"]["n"] == 1
    assert [row["round"] for row in tf["rounds"]] == [1, 2]
    first = tf["rounds"][0]
    assert first["teacher_forced"] == first["free"] and first["compounding_db"] == 0.0
    assert len(tf["head"]["teacher_forced"]) == len(tf["all_views"]["free"]) == 2

    # A rerun reuses every record and the kept real branch: same figures, nothing run again.
    code, again, _ = _run_cli(args, capsys)
    assert code == 0 and again is not None
    for rung in wl.RUNGS:
        assert again[rung]["real_branches_run"] == 0
        assert {k: v for k, v in again[rung].items() if k != "real_branches_run"} == {
            k: v for k, v in r[rung].items() if k != "real_branches_run"
        }


def test_bad_input_is_one_line(tiny_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ["bench", "wm-ladder", "--out", str(tmp_path), "--no-progress"]
    for extra, needle in (
        (["--subtasks", "0"], "--subtasks"),
        (["--model", str(tmp_path / "missing")], "model:"),
        (["--model", str(tmp_path)], "config.json missing"),
        (["--rungs", "state_contract,flying"], "rungs:"),
        (["--tasks", "juggle"], "tasks:"),
        (["--judge", str(tmp_path / "no_judge")], "no such judge folder"),
    ):
        code, _, err = _run_cli(base + extra, capsys)
        assert code == 2, extra
        assert err.strip().count("\n") == 0 and needle in err, err
    with pytest.raises(ValueError, match="subtasks"):
        wl.LadderConfig(subtasks=0)
