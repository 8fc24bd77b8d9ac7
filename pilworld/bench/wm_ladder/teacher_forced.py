"""Rung 3, teacher-forced vs free: one-chunk quality against the errors that compound from round to round."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from pilworld.bench.wm_ladder.lab import Lab
from pilworld.bench.wm_ladder.model import SeedShifted
from pilworld.bench.wm_ladder.settings import HEAD, Frames
from pilworld.bench.wm_ladder.stats import frame_mse, judge_summary, judgement, learned_judgement, learned_summary, psnr
from pilworld.data.episode import Episode
from pilworld.paired.runner import PairedSubtask
from pilworld.rollout import Rollout
from pilworld.types import ChunkSpec, Observation, Segment, Start
from pilworld.world_model.base import WorldModel


def _real_sequence(rollout: Rollout) -> list[Observation]:
    """The real history frames, then the start, then every recorded frame."""
    return [*rollout.start.history, *rollout.observations]


def _imagined_env(lab_gamma: Any, model: WorldModel, spec: ChunkSpec, rate_hz: float, seed: int) -> Any:
    from pilworld.envs import ImaginedEnv

    # No safety filter: the chunks replayed are the real branch's executed commands, already filtered.
    return ImaginedEnv(model, lab_gamma, spec, control_rate_hz=rate_hz, seed=seed, safety=None)


def teacher_forced_predictions(
    model: WorldModel, gamma: Any, spec: ChunkSpec, rollout: Rollout, seed: int, rate_hz: float
) -> Iterator[tuple[int, dict[str, Frames], dict[str, Frames]]]:
    """Per round r: (r, teacher-forced prediction, free prediction), each {view: uint8[K, H, W, 3]}.

    Teacher-forced round r: a fresh imagined branch reset at the real observation that starts round r with
    the real frames before it as history, stepping the real executed chunk of round r, with round r's noise
    seed. Free: one imagined branch from the real start stepping the real executed chunks in turn (its own
    frames fed back). Round 0 is the same call in both.
    """
    seq = _real_sequence(rollout)
    hist = len(rollout.start.history)
    free = _imagined_env(gamma, model, spec, rate_hz, seed)
    free.reset(rollout.start)
    at = hist
    for r, segment in enumerate(rollout.segments):
        executed = np.asarray(segment.actions, dtype=np.float32)
        start_r = Start(
            subtask=rollout.start.subtask, observation=seq[at], history=tuple(seq[max(0, at - spec.history) : at])
        )
        tf = _imagined_env(gamma, SeedShifted(model, r), spec, rate_hz, seed)
        tf.reset(start_r)
        tf_seg: Segment = tf.step(executed)
        free_seg: Segment = free.step(executed)
        views = list(seq[0].images)
        yield (
            r,
            {v: np.stack([np.asarray(o.images[v]) for o in tf_seg.observations]) for v in views},
            {v: np.stack([np.asarray(o.images[v]) for o in free_seg.observations]) for v in views},
        )
        at += len(segment.observations)


def teacher_forced_record(lab: Lab, pair: PairedSubtask, index: int) -> dict[str, Any]:
    """The round errors of :func:`teacher_forced_errors` and, under ``judges``, the success verdicts of the
    hand-written judge and the learned one on the real episode and on its teacher-forced re-render (every
    frame after the start replaced by the model's prediction from the real frames before it): what the
    world model's faithful-but-imperfect frames do to a judge (docs/judges.md, "Fairness")."""
    from pilworld.judges.vision import VisionJudge

    rollout, real_ok = lab.real(pair)
    model, _, _ = lab.model(pair.subtask.task)
    frames: dict[str, list[Frames]] = {}
    rec: dict[str, Any] = teacher_forced_errors(
        model, lab.gamma, lab.spec, rollout, pair.seed, lab.rig_cfg.control_rate_hz, frames=frames
    )
    ep = lab.episode(pair, rollout)
    forced = teacher_forced_episode(ep, frames)
    ctx = lab.context(pair.subtask.task)
    reference = VisionJudge()
    judges: dict[str, Any] = {
        "real": real_ok,
        "reference": {k: judgement(reference.judge(e, ctx)) for k, e in (("plain", ep), ("teacher_forced", forced))},
    }
    if lab.learned is not None:
        judges["learned"] = {
            k: learned_judgement(lab.learned.judge(e, ctx)) for k, e in (("plain", ep), ("teacher_forced", forced))
        }
    rec["judges"] = judges
    return rec


def teacher_forced_episode(ep: Episode, frames: dict[str, list[Frames]]) -> Episode:
    """``ep`` with every frame after the start replaced by the teacher-forced predictions, round after round."""
    images = {}
    for v, real in ep.images.items():
        predicted = np.concatenate(frames[v]) if frames.get(v) else np.zeros((0, *real.shape[1:]), np.uint8)
        if 1 + predicted.shape[0] != real.shape[0]:
            raise ValueError(f"teacher-forced {v}: {predicted.shape[0]} frames predicted for {real.shape[0] - 1}")
        images[v] = np.concatenate([real[:1], predicted.astype(np.uint8)])
    return dataclasses.replace(ep, images=images, origin="imagined")


def teacher_forced_errors(
    model: WorldModel,
    gamma: Any,
    spec: ChunkSpec,
    rollout: Rollout,
    seed: int,
    rate_hz: float,
    *,
    frames: dict[str, list[Frames]] | None = None,
) -> dict[str, Any]:
    """Per round and view, the MSE (levels², over the round's K frames) of teacher-forced, free and frozen.

    ``frames``, when given, receives each view's teacher-forced predictions round after round."""
    seq = rollout.observations
    views = list(seq[0].views)
    out: dict[str, list[dict[str, float]]] = {"teacher_forced": [], "free": [], "frozen": [], "frozen_start": []}
    at = 0
    for r, tf, free in teacher_forced_predictions(model, gamma, spec, rollout, seed, rate_hz):
        n = len(rollout.segments[r].observations)
        if frames is not None:
            for v in views:
                frames.setdefault(v, []).append(tf[v])
        real = {v: np.stack([np.asarray(o.images[v]) for o in seq[at + 1 : at + 1 + n]]) for v in views}
        held = {v: np.repeat(np.asarray(seq[at].images[v])[None], n, axis=0) for v in views}
        first = {v: np.repeat(np.asarray(seq[0].images[v])[None], n, axis=0) for v in views}
        out["teacher_forced"].append({v: frame_mse(tf[v], real[v]) for v in views})
        out["free"].append({v: frame_mse(free[v], real[v]) for v in views})
        out["frozen"].append({v: frame_mse(held[v], real[v]) for v in views})
        out["frozen_start"].append({v: frame_mse(first[v], real[v]) for v in views})
        at += n
    return out


def teacher_forced_summary(
    records: Sequence[tuple[PairedSubtask, dict[str, Any]]], views: Sequence[str]
) -> dict[str, Any]:
    kinds = ("teacher_forced", "free", "frozen", "frozen_start")
    rounds = max((len(r["free"]) for _, r in records), default=0)
    rows = []
    per_view: dict[str, dict[str, list[float | None]]] = {v: {k: [] for k in kinds} for v in [*views, "all"]}
    for i in range(rounds):
        have = [r for _, r in records if len(r["free"]) > i]
        row: dict[str, Any] = {"round": i + 1, "n": len(have)}
        for k in kinds:
            mses = {v: float(np.mean([r[k][i][v] for r in have])) for v in views}
            psnrs = {v: psnr(m) for v, m in mses.items()}
            psnrs["all"] = psnr(float(np.mean(list(mses.values()))))
            row[k] = psnrs
            for v, p in psnrs.items():
                per_view[v][k].append(p)
        row["compounding_db"] = round(row["teacher_forced"]["all"] - row["free"]["all"], 3)
        row["tf_gain_over_frozen_head_db"] = (
            round(row["teacher_forced"][HEAD] - row["frozen"][HEAD], 3) if HEAD in views else None
        )
        rows.append(row)
    return {
        "n": len(records),
        "metric": "pooled PSNR (dB) over the round's K frames of every pair",
        "rounds": rows,
        "head": per_view.get(HEAD, {}),
        "all_views": per_view["all"],
        "judges": _judges_summary([(p.pair_id, r["judges"]) for p, r in records if "judges" in r]),
    }


def _judges_summary(named: Sequence[tuple[str, dict[str, Any]]]) -> dict[str, Any] | None:
    """Each judge's agreement with the checker on the real episodes and on their teacher-forced re-renders,
    and under ``changed`` the pairs whose verdict the re-render changed (to look at: a re-render that loses
    an object changes the outcome it shows, and a judge should follow it)."""
    if not named:
        return None
    recs = [r for _, r in named]
    out: dict[str, Any] = {"n": len(recs)}
    truth = [bool(r["real"]) for r in recs]
    out["reference"] = {
        k: judge_summary(list(zip(truth, [r["reference"][k] for r in recs], strict=True)))
        for k in ("plain", "teacher_forced")
    }
    if all("learned" in r for r in recs):
        plain = [r["learned"]["plain"] for r in recs]
        out["learned"] = {
            "plain": learned_summary(list(zip(truth, plain, strict=True))),
            "teacher_forced": learned_summary(
                list(zip(truth, [r["learned"]["teacher_forced"] for r in recs], strict=True)), plain
            ),
        }
    out["changed"] = {judge: _changed(named, judge) for judge in ("reference", "learned") if judge in out}
    return out


def _changed(named: Sequence[tuple[str, dict[str, Any]]], judge: str) -> list[dict[str, Any]]:
    """The pairs whose ``judge`` verdict differs between the real episode and its re-render (an abstention, whose
    success is None, is no change)."""
    out = []
    for pair, r in named:
        plain, forced = r[judge]["plain"]["success"], r[judge]["teacher_forced"]["success"]
        if plain is not None and forced is not None and bool(plain) != bool(forced):
            out.append({"pair": pair, "real": bool(r["real"]), "plain": bool(plain), "teacher_forced": bool(forced)})
    return out
