"""Probes 3-7: each chunk executed once on the simulator and imagined by every model from the same start."""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from hw_drivers.errors import SafetyViolationError
from pilworld.bench.stability.metrics import frame_mse, frame_psnr
from pilworld.bench.stability.models import Imaginer, resolve_models
from pilworld.bench.stability.probe_chunks import (
    FAST_STEP_RAD,
    JITTER_RAD,
    fast_chunk,
    hold_chunk,
    jitter_chunk,
    offset_chunk,
    reverse_chunk,
    transplant,
)
from pilworld.bench.stability.rig_errors import RigError, rig_errors
from pilworld.bench.stability.settings import DONOR_SEED_OFFSET, PROBE_SEED0, SHUFFLE_ROUNDS, Chunk, Frames
from pilworld.bench.stability.summary import summarize_probes
from pilworld.bench.variants import ModelVariant
from pilworld.types import ChunkSpec, Subtask


def _frames(segments: Sequence[Any], views: Sequence[str]) -> Frames:
    """The frames of consecutive segments per view, the rounds one after the other."""
    return {v: np.stack([o.images[v] for seg in segments for o in seg.observations]) for v in views}


ChunkMaker = Callable[[Any], Chunk]  # the observation a round starts from → its chunk


class _Prober:
    """The probes of one start after another: each chunk executed once on the simulator, imagined by each model."""

    def __init__(
        self,
        station: Any,
        rig: str | Path,
        rig_cfg: Any,
        variants: Sequence[ModelVariant],
        checkpoints: tuple[str, ...],
        seed0: int,
        folder: Path,
    ) -> None:
        from pilworld.control_video.gamma import ControlVideo
        from pilworld.policies.registry import make_policy

        self.station = station
        self.rig_cfg = rig_cfg
        self.spec = ChunkSpec(rounds=1)
        self.views = list(rig_cfg.cameras)
        self.errors = rig_errors()
        self.policies = {c: make_policy(c, rig_cfg, self.spec) for c in checkpoints}
        self.rng = np.random.default_rng(seed0)
        wrong = {e.key: (e.rig(rig_cfg, folder), e.robot(rig_cfg)) for e in self.errors}
        self.imaginers = [Imaginer(v, rig, rig_cfg, wrong) for v in variants]
        self.gammas: dict[str, Any] = {"": ControlVideo.from_rig(rig_cfg, self.spec)}
        for key, (given, _) in wrong.items():  # Γ's markers drawn through the head camera the models are given
            self.gammas[key] = ControlVideo.from_rig(given, self.spec)
        self.refused: list[dict[str, Any]] = []

    def sim(self, pair: Any, subtask: Subtask, kind: str, chunks: Sequence[Chunk | ChunkMaker]) -> list[Any]:
        """Rounds on the simulator from a fresh start of ``subtask`` (a chunk, or a function of the observation
        its round starts from), as many as the safety filter accepts (a refusal is listed under ``kind``)."""
        from pilworld.envs import RobotEnv

        env = RobotEnv(self.station.robot, self.spec, pace=self.station.pace)  # the simulator: no wall-clock pacing
        obs = env.reset(self.station.start(subtask, pair.checkpoint, self.spec))
        segments: list[Any] = []
        for i, chunk in enumerate(chunks):
            try:
                segments.append(env.step(chunk(obs) if callable(chunk) else chunk))
            except SafetyViolationError as exc:  # counted; the probe goes on without this chunk
                self.refused.append({"pair": pair.pair_id, "kind": kind, "round": i + 1, "error": str(exc)})
                break
            obs = segments[-1].last
        return segments

    def imagine(
        self, im: Imaginer, pair: Any, start: Any, chunks: Sequence[Chunk], kind: str, error: RigError | None = None
    ) -> Frames | None:
        """``chunks`` imagined round after round from ``start`` (None: the safety filter refused one)."""
        from pilworld.envs import ImaginedEnv, SafetyFilter

        env = ImaginedEnv(
            im.model(pair.subtask.task, error),
            self.gammas["" if error is None else error.key],
            self.spec,
            control_rate_hz=self.rig_cfg.control_rate_hz,
            seed=pair.seed,
            steps=im.variant.steps,
            safety=SafetyFilter(self.station.robot.spec),
        )
        env.reset(start)
        try:
            return _frames([env.step(c) for c in chunks], self.views)
        except SafetyViolationError as exc:
            self.refused.append({"pair": pair.pair_id, "kind": kind, "model": im.variant.name, "error": str(exc)})
            return None

    def run(self, pair: Any) -> dict[str, dict[str, Any]]:
        """One start's record per model (none: the policy's chunk or a counterfactual alternative was refused)."""
        from pilworld.paired.runner import PairedSubtask

        sub: Subtask = pair.subtask
        views = self.views
        policy = self.policies[pair.checkpoint]
        start = self.station.start(sub, pair.checkpoint, self.spec)
        state = np.asarray(start.observation.state, dtype=np.float32)
        policy.reset(seed=pair.seed)
        base = np.asarray(policy.infer(start.observation, sub.instruction), dtype=np.float32)
        chunks = {
            "hold": hold_chunk(base, state),
            "reverse": reverse_chunk(base, state),
            "fast": fast_chunk(base, state),
        }
        chunks["jitter"] = jitter_chunk(base, state, self.rng)
        chunks["offset"] = offset_chunk(base, state)

        def policy_chunk(obs: Any) -> Chunk:
            return np.asarray(policy.infer(obs, sub.instruction), dtype=np.float32)

        # The policy's chunk, then (the action shuffle's reference) its next chunks from the simulator's frames.
        own: list[Chunk] = [base]

        def own_chunk(obs: Any) -> Chunk:
            own.append(policy_chunk(obs))
            return own[-1]

        real: dict[str, Frames] = {}
        segments = self.sim(pair, sub, "policy", [base, *[own_chunk] * (SHUFFLE_ROUNDS - 1)])
        if not segments:
            return {}
        real["policy"] = _frames(segments[:1], views)
        for kind, chunk in chunks.items():
            got = self.sim(pair, sub, kind, [chunk])
            if got:
                real[kind] = _frames(got, views)
        if not {"hold", "reverse"} <= set(real):
            return {}
        shuffled: list[Chunk] = []
        if len(segments) == SHUFFLE_ROUNDS:
            real["own"] = _frames(segments, views)
            # The donor: the same subtask on another layout. Its rounds but the last run on the simulator; its last
            # chunk comes from where they leave it. Then its chunks transplanted onto this start.
            donor = PairedSubtask(
                pair.checkpoint,
                Subtask(task=sub.task, index=sub.index, instruction=sub.instruction, seed=sub.seed + DONOR_SEED_OFFSET),
            )
            donated: list[tuple[Chunk, Chunk]] = []  # (chunk, the donor's state it was computed at)

            def donor_chunk(obs: Any) -> Chunk:
                donated.append((policy_chunk(obs), np.asarray(obs.state, dtype=np.float32)))
                return donated[-1][0]

            def shuffled_chunk(obs: Any) -> Chunk:
                chunk, at = donated[len(shuffled)]
                shuffled.append(transplant(chunk, at, np.asarray(obs.state, dtype=np.float32)))
                return shuffled[-1]

            policy.reset(seed=donor.seed)
            ran = self.sim(pair, donor.subtask, "donor", [donor_chunk] * (SHUFFLE_ROUNDS - 1))
            if len(ran) == SHUFFLE_ROUNDS - 1:
                last = (
                    ran[-1].last if ran else self.station.start(donor.subtask, pair.checkpoint, self.spec).observation
                )
                donor_chunk(last)
                got = self.sim(pair, sub, "shuffle", [shuffled_chunk] * SHUFFLE_ROUNDS)
                if len(got) == SHUFFLE_ROUNDS:
                    real["shuffle"] = _frames(got, views)
        out: dict[str, dict[str, Any]] = {}
        for im in self.imaginers:
            rec = self._record(im, pair, start, own, chunks, shuffled, real)
            if rec is not None:
                out[im.variant.name] = rec
        return out

    def _record(
        self,
        im: Imaginer,
        pair: Any,
        start: Any,
        own: list[Chunk],
        chunks: dict[str, Chunk],
        shuffled: list[Chunk],
        real: dict[str, Frames],
    ) -> dict[str, Any] | None:
        views, K = self.views, self.spec.frames
        imag_own = self.imagine(im, pair, start, own if "own" in real else own[:1], "policy")
        if imag_own is None:
            return None
        imag: dict[str, Frames] = {"policy": {v: f[:K] for v, f in imag_own.items()}}
        for kind, chunk in chunks.items():
            if kind in real:
                got = self.imagine(im, pair, start, [chunk], kind)
                if got is not None:
                    imag[kind] = got
        if not {"hold", "reverse"} <= set(imag):
            return None
        rec: dict[str, Any] = {"pair": pair.pair_id, "task": pair.subtask.task}
        for kind, frames in imag.items():
            rec[f"psnr:{kind}"] = {v: frame_psnr(frames[v], real[kind][v]) for v in views}
        still = {v: np.repeat(start.observation.images[v][None], K, axis=0) for v in views}
        rec["psnr:frozen"] = {v: frame_psnr(still[v], real["policy"][v]) for v in views}
        for alt in ("hold", "reverse"):
            rec[f"div:{alt}"] = {
                v: {
                    "pred": frame_mse(imag["policy"][v], imag[alt][v]),
                    "real": frame_mse(real["policy"][v], real[alt][v]),
                }
                for v in views
            }
        for error in self.errors:
            if im.applies(error):
                wrong = self.imagine(im, pair, start, own[:1], f"policy@{error.key}", error)
                if wrong is not None:
                    rec[f"psnr:err:{error.key}"] = {v: frame_psnr(wrong[v], real["policy"][v]) for v in views}
        if "shuffle" in real:
            first = self.imagine(im, pair, start, shuffled, "shuffle")
            again = self.imagine(im, pair, start, shuffled, "shuffle")
            if first is not None and again is not None:
                held = {v: np.repeat(start.observation.images[v][None], len(first[v]), axis=0) for v in views}
                rec["shuffle"] = {
                    "div": {
                        v: {
                            "pred": frame_mse(imag_own[v], first[v]),
                            "real": frame_mse(real["own"][v], real["shuffle"][v]),
                        }
                        for v in views
                    },
                    "psnr": {
                        v: {
                            "shuffled": frame_psnr(first[v], real["shuffle"][v]),
                            "own": frame_psnr(imag_own[v], real["own"][v]),
                            "frozen": frame_psnr(held[v], real["shuffle"][v]),
                        }
                        for v in views
                    },
                    "same": all(np.array_equal(first[v], again[v]) for v in views),
                }
        return rec


def probe(
    *,
    rig: str | Path,
    tasks: tuple[str, ...],
    checkpoints: tuple[str, ...],
    starts: int,
    models: Sequence[ModelVariant] | None = None,
    seed0: int = PROBE_SEED0,
    progress: bool = True,
) -> dict[str, Any]:
    """Probes 3-7 from ``starts`` subtasks per task × checkpoint (layouts from ``seed0``), for each model
    (default ``DEFAULT_MODELS``): ``{"models": {name: summary}, "protocol": …, "refused": […]}``."""
    from pilworld.config.rig import RigConfig
    from pilworld.paired.runner import plan_subtasks
    from pilworld.paired.stations import SimStation
    from simrig.tasks import make_task

    variants = list(models) if models is not None else resolve_models()
    rig_cfg = RigConfig.load(rig)
    plan = []
    for task in tasks:
        t = make_task(task)
        plan += plan_subtasks(task, starts, seed0, checkpoints, t.num_subtasks, t.instruction)
    records: dict[str, list[dict[str, Any]]] = {v.name: [] for v in variants}
    from pilworld.paired.imagined_branch import torch_threads

    with (
        torch_threads(1),
        tempfile.TemporaryDirectory(prefix="pilworld-stability-") as folder,
        SimStation(rig, tasks[0]) as station,
    ):
        prober = _Prober(station, rig, rig_cfg, variants, checkpoints, seed0, Path(folder))
        for pair in tqdm(plan, desc="probes", unit="start", disable=not progress):
            for name, rec in prober.run(pair).items():
                records[name].append(rec)
    imaginers, errors, views = prober.imaginers, prober.errors, prober.views
    summaries = {}
    for im in imaginers:
        applies = [e.key for e in errors if im.binds_rig is not None and im.applies(e)]
        summaries[im.variant.name] = {
            "label": im.variant.label,
            "binds_rig": im.binds_rig,
            **summarize_probes(records[im.variant.name], views, errors, applies),
        }
    protocol = {
        "tasks": list(tasks),
        "checkpoints": list(checkpoints),
        "starts_per_checkpoint": starts,
        "starts": len(plan),
        "seed0": seed0,
        "rounds": 1,
        "shuffle_rounds": SHUFFLE_ROUNDS,
        "donor_seed_offset": DONOR_SEED_OFFSET,
        "jitter_rad": JITTER_RAD,
        "jitter_seed": seed0,
        "fast_step_rad": FAST_STEP_RAD,
        "errors": [e.to_json() for e in errors],
        "models": [v.name for v in variants],
    }
    return {"models": summaries, "protocol": protocol, "refused": prober.refused}
