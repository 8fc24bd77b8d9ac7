"""``bench reprojection``: how well the scene reprojection prior of Γ⁺ predicts the true future frames.

**Clips.** Closed-loop runs of scripted checkpoints on the simulated rig with held-out layouts (seeds
from :data:`~pilworld.bench.world_model.HELDOUT_SEED0` = 1,000,000 on; the best checkpoint and a weaker
one alternate by seed), the first ``subtasks`` subtasks of each run back to back, every round one clip:
the current frame of every view, the K stride-aligned commands the policy sent (what Γ⁺ is given), the
measured joint states and the true frames at stride Δ. Every frame is also rendered through MuJoCo's
segmentation (robot, table, floor beyond the table, objects and fixtures). The robot pixels the prior
removes come from the analytic robot render, as Γ⁺ computes them (``--masks segmentation``: the true ones).

**Scores.** For frames k = 1 … K, pooled over clips: PSNR = 10 log₁₀(255² / MSE) of the prior against the
true frame over the prior's valid pixels, the frozen frame (the current frame copied) on the SAME pixels,
and the valid fraction. The prior is also split by the true future label and by fill source, so that the
table shows where the plane assumption breaks: object surfaces above the plane, the floor beyond the
table's edge (0.75 m below the plane), disoccluded pixels (the plane point was hidden behind an object
in the source view) — and what servo lag costs (the same prior from the measured instead of the
commanded joints).

``python -m pilworld.bench.reprojection [--quick] [--json]``; the JSON object is the last line.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from pilworld.bench.common import machine_info
from pilworld.bench.flags import add_json, add_rig
from pilworld.bench.output import emit
from pilworld.config.rig import RigConfig
from pilworld.control_video.cameras import RigCameras
from pilworld.control_video.lag import estimate_lag, lagged_poses
from pilworld.control_video.reprojection import SOURCE_HEAD, SOURCE_OWN, ReprojectionPrior, SceneReprojector
from pilworld.types import HEAD_VIEW, ChunkSpec, Subtask
from simrig.files import SIM_RIG

DEFAULT_TASKS = ("sort_cubes", "stack_blocks", "stack_bowls")
REPORT_FRAMES = (1, 5, 10, 15)  # 1-based k reported in the summary
ACCEPT_GAIN_DB = 3.0  # at the last frame the prior must beat the frozen frame by this much (wrists pooled)

# Segmentation labels of a rendered pixel.
NOTHING, TABLE, FLOOR, OBJECT, ROBOT = 0, 1, 2, 3, 4
LABEL_NAMES = {NOTHING: "nothing", TABLE: "table", FLOOR: "floor", OBJECT: "object", ROBOT: "robot"}


@dataclass(frozen=True)
class Clip:
    """One closed-loop round: the current frame, the K stride-aligned commands and the true future."""

    task: str
    seed: int
    checkpoint: str
    images: dict[str, NDArray[np.uint8]]  # view → (H, W, 3) current frame
    labels: dict[str, NDArray[np.uint8]]  # view → (H, W) segmentation label of the current frame
    state: NDArray[np.float64]  # (14,) measured joints at the current frame
    commands: NDArray[np.float64]  # (K, 14) stride-aligned commands sent
    executed: NDArray[np.float64]  # (KΔ, 14) every command sent in the round
    future_states: NDArray[np.float64]  # (K, 14) measured joints at the future frames
    future_images: dict[str, NDArray[np.uint8]]  # view → (K, H, W, 3)
    future_labels: dict[str, NDArray[np.uint8]]  # view → (K, H, W)

    def robot_masks(self) -> tuple[dict[str, NDArray[np.bool_]], dict[str, NDArray[np.bool_]]]:
        return (
            {v: m == ROBOT for v, m in self.labels.items()},
            {v: m == ROBOT for v, m in self.future_labels.items()},
        )


class _Segmenter:
    """MuJoCo segmentation renders of a :class:`SimRobot`'s cameras, as :data:`LABEL_NAMES` labels."""

    def __init__(self, robot: Any) -> None:
        from simrig.gl import make_renderer, mujoco

        self._robot = robot
        model = robot._model  # the sim rig has no public handle on its MjModel; read-only use
        w, h = robot.spec.image_size
        self._renderer = make_renderer(model, w, h)
        self._renderer.enable_segmentation_rendering()
        lut = np.full(model.ngeom + 1, OBJECT, dtype=np.uint8)  # index 0 = no geom (id −1)
        for g in range(model.ngeom):
            body = model.body(int(model.geom_bodyid[g])).name
            name = model.geom(g).name
            if body.startswith(("left_", "right_")):
                lut[g + 1] = ROBOT
            elif name == "table":
                lut[g + 1] = TABLE
            elif name == "floor":
                lut[g + 1] = FLOOR
        lut[0] = NOTHING
        self._lut = lut
        self._geom_type = int(mujoco.mjtObj.mjOBJ_GEOM)

    def __call__(self, camera: str) -> NDArray[np.uint8]:
        self._renderer.update_scene(self._robot._data, camera=camera)
        seg = np.asarray(self._renderer.render())  # (H, W, 2) int32: object id, object type
        ids = np.where(seg[..., 1] == self._geom_type, seg[..., 0], -1)
        labels: NDArray[np.uint8] = self._lut[ids + 1]
        return labels

    def close(self) -> None:
        self._renderer.close()


def collect_clips(
    rig: RigConfig,
    *,
    tasks: tuple[str, ...] = DEFAULT_TASKS,
    episodes: int = 2,
    subtasks: int = 2,
    seed0: int = 1_000_000,
    spec: ChunkSpec | None = None,
    progress: bool = False,
) -> list[Clip]:
    """``episodes`` held-out runs per task (``subtasks`` subtasks each, R rounds each) as clips."""
    from pilworld.bench.world_model import TRAINING_SEEDS, heldout_checkpoints
    from pilworld.policies.scripted import ScriptedPolicy
    from simrig.robot import SimRobot

    spec = spec or ChunkSpec()
    if seed0 < TRAINING_SEEDS.stop:
        raise ValueError(f"seed0: expected a held-out seed >= {TRAINING_SEEDS.stop}, got {seed0}")
    checkpoints = heldout_checkpoints()
    clips: list[Clip] = []
    robot = SimRobot(rig, tasks[0])
    robot.connect()
    try:
        for task in tasks:
            robot.reset(seed=seed0, subtask=0, task=task, history=0)
            segment = _Segmenter(robot)
            try:
                for e in range(episodes):
                    seed = seed0 + e
                    ckpt = checkpoints[e % len(checkpoints)]
                    clips += _run(
                        robot,
                        segment,
                        ScriptedPolicy(robot.rig, ckpt, horizon=spec.horizon),
                        task,
                        seed,
                        ckpt,
                        subtasks,
                        spec,
                    )
                    if progress:
                        print(f"bench reprojection: {task} seed {seed} {ckpt}: {len(clips)} clips", file=sys.stderr)
            finally:
                segment.close()
    finally:
        robot.disconnect()
    return clips


def _run(
    robot: Any, segment: _Segmenter, policy: Any, task: str, seed: int, ckpt: str, subtasks: int, spec: ChunkSpec
) -> list[Clip]:
    views = robot.spec.cameras
    start = robot.reset(seed=seed, subtask=0, history=spec.history, stride=spec.stride)
    policy.reset(seed=seed * 100)
    obs = start.observation
    labels = {v: segment(v) for v in views}
    out = []
    for k in range(min(subtasks, robot.task.num_subtasks)):
        robot.subtask = Subtask(task, k, robot.task.instruction, seed)
        for _ in range(spec.rounds):
            chunk = np.asarray(policy.infer(obs, robot.task.instruction), dtype=np.float64)
            commands, states, frames, frame_labels, executed = [], [], [], [], []
            for step, action in enumerate(chunk[: spec.executed_steps]):
                sent = robot.send_action(action)
                executed.append(np.asarray(sent, dtype=np.float64))
                if (step + 1) % spec.stride == 0:
                    o = robot.observe()
                    commands.append(np.asarray(sent, dtype=np.float64))
                    states.append(np.asarray(o.state, dtype=np.float64))
                    frames.append(o)
                    frame_labels.append({v: segment(v) for v in views})
            out.append(
                Clip(
                    task=task,
                    seed=seed,
                    checkpoint=ckpt,
                    images={v: np.asarray(obs.images[v]) for v in views},
                    labels=labels,
                    state=np.asarray(obs.state, dtype=np.float64),
                    commands=np.stack(commands),
                    executed=np.stack(executed),
                    future_states=np.stack(states),
                    future_images={v: np.stack([f.images[v] for f in frames]) for v in views},
                    future_labels={v: np.stack([fl[v] for fl in frame_labels]) for v in views},
                )
            )
            obs, labels = frames[-1], frame_labels[-1]
    return out


class _Pool:
    """Pooled squared errors per frame index: prior, frozen (same pixels), valid and total counts."""

    def __init__(self, frames: int) -> None:
        self.prior = np.zeros(frames)
        self.frozen = np.zeros(frames)
        self.abs = np.zeros(frames)
        self.n = np.zeros(frames)
        self.total = np.zeros(frames)

    def add(
        self, prior: NDArray[np.uint8], frozen: NDArray[np.uint8], true: NDArray[np.uint8], sel: NDArray[np.bool_]
    ) -> None:
        """``prior``, ``true`` (K, H, W, 3), ``frozen`` (H, W, 3), ``sel`` (K, H, W) pixels to score."""
        d_p = prior.astype(np.float32) - true
        d_f = frozen.astype(np.float32)[None] - true
        w = sel[..., None]
        self.prior += np.einsum("khwc,khwc->k", d_p * w, d_p)
        self.frozen += np.einsum("khwc,khwc->k", d_f * w, d_f)
        self.abs += np.abs(d_p * w).sum(axis=(1, 2, 3))
        self.n += sel.sum(axis=(1, 2)) * 3
        self.total += sel[0].size

    def merged(self, other: _Pool) -> _Pool:
        out = _Pool(len(self.n))
        for f in ("prior", "frozen", "abs", "n", "total"):
            setattr(out, f, getattr(self, f) + getattr(other, f))
        return out

    def summary(self, frames: tuple[int, ...] = REPORT_FRAMES) -> dict[str, Any]:
        idx = [k - 1 for k in frames if k <= len(self.n)]
        return {
            "k": [i + 1 for i in idx],
            "prior_psnr": [_psnr(self.prior[i], self.n[i]) for i in idx],
            "frozen_psnr": [_psnr(self.frozen[i], self.n[i]) for i in idx],
            "gain_db": [_gain(self.prior[i], self.frozen[i], self.n[i]) for i in idx],
            "prior_mae": [_round(self.abs[i] / self.n[i]) if self.n[i] else None for i in idx],
            "fraction": [_round(self.n[i] / 3 / self.total[i], 4) if self.total[i] else 0.0 for i in idx],
        }

    def pooled(self) -> dict[str, Any]:
        """All frames together."""
        n, total = self.n.sum(), self.total.sum()
        return {
            "fraction": _round(n / 3 / total, 4) if total else 0.0,
            "prior_psnr": _psnr(self.prior.sum(), n),
            "frozen_psnr": _psnr(self.frozen.sum(), n),
            "gain_db": _gain(self.prior.sum(), self.frozen.sum(), n),
            "prior_mae": _round(self.abs.sum() / n) if n else None,
        }


def _psnr(sse: float, n: float) -> float | None:
    """PSNR of the pooled MSE (None without pixels; capped at 100 dB for identical images)."""
    if n == 0:
        return None
    mse = max(sse / n, 1e-10)
    return _round(10.0 * np.log10(255.0**2 / mse))


def _gain(sse_prior: float, sse_frozen: float, n: float) -> float | None:
    if n == 0:
        return None
    return _round(10.0 * np.log10(max(sse_frozen, 1e-10 * n) / max(sse_prior, 1e-10 * n)))


def _round(x: float, digits: int = 2) -> float:
    return round(float(x), digits)


MASK_SOURCES = ("render", "segmentation")


def _render_masks(
    renderer: Any, clip: Clip, poses: NDArray[np.float64]
) -> tuple[dict[str, NDArray[np.bool_]], dict[str, NDArray[np.bool_]]]:
    """The robot masks Γ⁺ itself uses: the analytic render of the current state and of the K poses."""
    out = renderer.render(np.concatenate([clip.state[None], poses]), depth=False, shaded=False)
    return {v: p[0] > 0 for v, p in out.parts.items()}, {v: p[1:] > 0 for v, p in out.parts.items()}


def score_clips(
    clips: list[Clip],
    cameras: RigCameras,
    *,
    timing_repeats: int = 3,
    renderer: Any = None,
    lag_steps: float = 0.0,
) -> dict[str, Any]:
    """Score the prior on ``clips`` (see the module docstring); also times one prior per clip.

    ``renderer`` (a robot renderer of the same rig) gives the robot masks as Γ⁺ computes them; None
    uses the simulator's segmentation of the robot (the true masks). The future poses are the commands
    delayed by ``lag_steps`` control steps, as Γ⁺ places them (:mod:`pilworld.control_video.lag`).
    """
    spec = ChunkSpec()
    prior_fn = SceneReprojector(cameras)
    label_fn = SceneReprojector(cameras, interpolation="nearest")
    plain_fn = SceneReprojector(cameras, match_head_colour=False)
    views = cameras.names
    wrists = tuple(v for v in views if cameras.view(v).moves)
    k = clips[0].commands.shape[0]
    per_view = {v: _Pool(k) for v in views}
    by_source = {(v, s): _Pool(k) for v in wrists for s in (SOURCE_OWN, SOURCE_HEAD)}
    measured = {v: _Pool(k) for v in wrists}
    plain = {v: _Pool(k) for v in wrists}
    breaks = {name: _Pool(k) for name in _BREAK_ROWS}
    breaks_by_source = {(name, s): _Pool(k) for name in _BREAK_ROWS for s in (SOURCE_OWN, SOURCE_HEAD)}
    moving = {v: 0 for v in wrists}
    times: list[float] = []
    for clip in clips:
        poses = lagged_poses(clip.executed, clip.state, spec, lag_steps)
        now_masks, future_masks = clip.robot_masks() if renderer is None else _render_masks(renderer, clip, poses)
        best = float("inf")
        for _ in range(timing_repeats):
            t0 = time.perf_counter()
            prior = prior_fn(clip.images, clip.state, poses, now_masks, future_masks)
            best = min(best, time.perf_counter() - t0)
        times.append(best)
        from_state = prior_fn(clip.images, clip.state, clip.future_states, now_masks, future_masks)
        unmatched = plain_fn(clip.images, clip.state, poses, now_masks, future_masks)
        label_images = {v: np.repeat(clip.labels[v][..., None], 3, axis=2) for v in views}
        warped_labels = label_fn(label_images, clip.state, poses, now_masks, future_masks)
        for v in views:
            valid = prior.valid[v]
            true = clip.future_images[v]
            per_view[v].add(prior.images[v], clip.images[v], true, valid)
            if v not in wrists:
                continue
            moving[v] += int(np.abs(clip.commands[-1] - clip.state).max() > 1e-3)
            for s in (SOURCE_OWN, SOURCE_HEAD):
                by_source[(v, s)].add(prior.images[v], clip.images[v], true, prior.source[v] == s)
            measured[v].add(from_state.images[v], clip.images[v], true, from_state.valid[v])
            plain[v].add(unmatched.images[v], clip.images[v], true, unmatched.valid[v])
            for name, sel in _break_masks(prior, warped_labels, clip.future_labels[v], v).items():
                breaks[name].add(prior.images[v], clip.images[v], true, sel)
                for s in (SOURCE_OWN, SOURCE_HEAD):
                    breaks_by_source[(name, s)].add(prior.images[v], clip.images[v], true, sel & (prior.source[v] == s))

    wrist_pool = _merge([per_view[v] for v in wrists])
    last = k  # the acceptance frame
    gain_last = _gain(wrist_pool.prior[last - 1], wrist_pool.frozen[last - 1], wrist_pool.n[last - 1]) or 0.0
    valid_of_all = {name: pool.pooled()["fraction"] for name, pool in breaks.items()}
    total_valid = sum(valid_of_all.values()) or 1.0
    return {
        "views": {v: per_view[v].summary() | {"all_frames": per_view[v].pooled()} for v in views},
        "wrists_pooled": wrist_pool.summary() | {"all_frames": wrist_pool.pooled()},
        "wrists_by_source": {
            f"{v}/{'own' if s == SOURCE_OWN else 'head'}": pool.summary() for (v, s), pool in by_source.items()
        },
        "wrists_from_measured_state": _merge(list(measured.values())).summary(),
        "wrists_without_colour_match": _merge(list(plain.values())).summary(),
        "plane_breaks": {
            name: pool.pooled()
            | {"share_of_valid": _round(valid_of_all[name] / total_valid, 4), "what": _BREAK_ROWS[name]}
            for name, pool in breaks.items()
        },
        "plane_breaks_by_source": {
            f"{name}/{'own' if src == SOURCE_OWN else 'head'}": pool.pooled()
            for (name, src), pool in breaks_by_source.items()
        },
        "plane_breaks_k15": {name: pool.summary(frames=(last,)) for name, pool in breaks.items()},
        "clips_with_moving_wrist": moving,
        "ms_per_chunk_p50": _round(1e3 * float(np.median(times))),
        "ms_per_chunk_mean": _round(1e3 * float(np.mean(times))),
        "acceptance": {
            "rule": f"wrists pooled, k = {last}: prior PSNR >= frozen PSNR + {ACCEPT_GAIN_DB} dB",
            "gain_db": _round(gain_last),
            "passed": bool(gain_last >= ACCEPT_GAIN_DB),
        },
    }


_BREAK_ROWS = {
    "table": "true future pixel on the table, the source pixel on the table too (the plane holds)",
    "object": "true future pixel on an object or fixture (above the plane)",
    "beyond_edge": "true future pixel on the floor beyond the table edge (0.75 m below the plane)",
    "disoccluded": "true future pixel on table or floor, its warped source pixel on an object (hidden in the source)",
}


def _break_masks(
    prior: ReprojectionPrior, warped: ReprojectionPrior, future_labels: NDArray[np.uint8], view: str
) -> dict[str, NDArray[np.bool_]]:
    valid = prior.valid[view] & warped.valid[view]
    src = warped.images[view][..., 0]  # the source label each valid pixel was filled from
    flat = (future_labels == TABLE) | (future_labels == FLOOR)
    return {
        "table": valid & (future_labels == TABLE) & (src == TABLE),
        "object": valid & (future_labels == OBJECT),
        "beyond_edge": valid & (future_labels == FLOOR) & (src != OBJECT),
        "disoccluded": valid & flat & (src == OBJECT),
    }


def _merge(pools: list[_Pool]) -> _Pool:
    out = pools[0]
    for p in pools[1:]:
        out = out.merged(p)
    return out


def _sized(rig: RigConfig, size: int) -> RigConfig:
    return RigConfig.model_validate({**rig.model_dump(), "image_size": {"width": size, "height": size}})


def run_reprojection_bench(
    rig_path: str | Path = SIM_RIG,
    *,
    quick: bool = False,
    tasks: tuple[str, ...] = DEFAULT_TASKS,
    episodes: int | None = None,
    subtasks: int | None = None,
    size: int | None = None,
    seed0: int = 1_000_000,
    masks: str = "render",
    progress: bool = False,
) -> dict[str, Any]:
    """Collect held-out clips and score the prior; ``quick``: one task, one run, 64×64 (for tests).

    ``masks``: ``render`` — the robot's pixels from the analytic robot render of the current state and
    of the commands, as Γ⁺ computes them; ``segmentation`` — the simulator's true robot pixels.
    """
    if masks not in MASK_SOURCES:
        raise ValueError(f"masks: expected one of {', '.join(MASK_SOURCES)}, got {masks!r}")
    cv2.setNumThreads(1)  # the figure one rollout worker gets
    t0 = time.perf_counter()
    if quick:
        tasks = tasks[:1]
    episodes = episodes if episodes is not None else (1 if quick else 3)
    subtasks = subtasks if subtasks is not None else (1 if quick else 3)
    size = size if size is not None else (64 if quick else 128)
    if episodes < 1 or subtasks < 1 or size < 16:
        raise ValueError(f"episodes, subtasks must be >= 1 and size >= 16, got {episodes}, {subtasks}, {size}")
    rig = _sized(RigConfig.load(rig_path), size)
    spec = ChunkSpec()
    clips = collect_clips(
        rig, tasks=tasks, episodes=episodes, subtasks=subtasks, seed0=seed0, spec=spec, progress=progress
    )
    t_collect = time.perf_counter() - t0
    cameras = RigCameras.from_rig(rig)
    renderer = None
    if masks == "render":
        from pilworld.control_video.robot_render import make_robot_renderer

        renderer = make_robot_renderer(rig, "analytic", cameras=cameras)
    lag = estimate_lag(
        np.stack([c.executed for c in clips]),
        np.stack([c.state for c in clips]),
        np.stack([c.future_states for c in clips]),
        spec,
    )
    scores = score_clips(clips, cameras, renderer=renderer, lag_steps=rig.control_lag_steps)
    if rig.control_lag_steps > 0:
        without = score_clips(clips, cameras, renderer=renderer, timing_repeats=1)
        scores["wrists_without_lag"] = without["wrists_pooled"]
    return {
        "benchmark": "reprojection",
        **scores,
        "clips": len(clips),
        "tasks": list(tasks),
        "episodes_per_task": episodes,
        "subtasks_per_run": subtasks,
        "seeds": [seed0, seed0 + episodes - 1],
        "image_size": [size, size],
        "K": spec.frames,
        "stride": spec.stride,
        "head_view": HEAD_VIEW,
        "masks": {
            "render": "analytic robot render of the current state and the commands (what Γ⁺ uses)",
            "segmentation": "MuJoCo segmentation of the robot geoms (the true robot pixels)",
        }[masks],
        "future_pose": (
            f"commands delayed by the rig's control_lag_steps = {rig.control_lag_steps:g} (as Γ⁺ places the arm); "
            "wrists_without_lag: the stride-aligned commands; wrists_from_measured_state: the measured joints"
        ),
        "lag_estimate": lag,
        "collect_seconds": _round(t_collect),
        "seconds": _round(time.perf_counter() - t0),
        "rig": rig.name,
        **machine_info(),
    }


_SOURCE_COLOURS = np.array([[0, 0, 0], [60, 170, 60], [70, 110, 230]], dtype=np.uint8)  # none, own, head


def example_figure(clips: list[Clip], cameras: RigCameras, path: str | Path, *, rows: int = 6) -> None:
    """A PNG: per (clip, moving wrist view), current | prior k=1, 8, 15 | sources k=15 | true k=15 | |error| k=15."""
    prior_fn = SceneReprojector(cameras)
    wrists = [v for v in cameras.names if cameras.view(v).moves]
    poses = [(clip, v) for clip in clips for v in wrists]
    moved = [(c, v) for c, v in poses if _camera_motion(cameras, c, v) > 0.05]
    lines = []
    for clip, v in moved[:: max(1, len(moved) // rows)][:rows]:
        prior = prior_fn(clip.images, clip.state, clip.commands, *clip.robot_masks())
        last = clip.commands.shape[0] - 1
        err = np.abs(prior.images[v][last].astype(np.int16) - clip.future_images[v][last]).astype(np.uint8)
        err[~prior.valid[v][last]] = 0
        tiles = [clip.images[v], *(prior.images[v][k] for k in (0, 7, last))]
        tiles += [_SOURCE_COLOURS[prior.source[v][last]], clip.future_images[v][last], err]
        lines.append(np.concatenate(tiles, axis=1))
    if not lines:
        raise ValueError("figure: no clip with a moving wrist camera")
    image = np.concatenate(lines, axis=0)
    if not cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR)):
        raise ValueError(f"figure: cannot write {path}")


def _camera_motion(cameras: RigCameras, clip: Clip, view: str) -> float:
    """Metres the camera centre of ``view`` travels from the current frame to the last future frame."""
    poses = cameras.poses(np.stack([clip.state, clip.commands[-1]]))[view]
    centres = -np.einsum("kji,kj->ki", poses[:, :3, :3], poses[:, :3, 3])
    return float(np.linalg.norm(centres[1] - centres[0]))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The bench's options, for ``python -m pilworld.bench.reprojection`` and ``pilworld bench reprojection``."""
    add_rig(parser)
    parser.add_argument("--quick", action="store_true", help="one task, one run, one subtask, 64x64 (seconds)")
    parser.add_argument("--episodes", type=int, default=None, help="runs per task (default 3; quick 1)")
    parser.add_argument("--subtasks", type=int, default=None, help="subtasks per run (default 3; quick 1)")
    parser.add_argument("--size", type=int, default=None, help="image size in pixels (default 128; quick 64)")
    add_json(parser, "print the JSON object as the last line")
    parser.add_argument("--figure", type=Path, default=None, help="also write an example PNG (quick clips)")
    parser.add_argument(
        "--masks",
        choices=MASK_SOURCES,
        default="render",
        help="robot pixels from the analytic render as Γ⁺ computes them (default) or the simulator's segmentation",
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pilworld.bench.reprojection", description=__doc__.split("\n")[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


def run(args: argparse.Namespace) -> int:
    """Run the bench for parsed options (see :func:`add_arguments`); prints the table or the JSON line."""
    try:
        if args.figure is not None:
            rig = _sized(RigConfig.load(args.rig), args.size or 128)
            clips = collect_clips(rig, tasks=DEFAULT_TASKS, episodes=1, subtasks=1)
            example_figure(clips, RigCameras.from_rig(rig), args.figure)
        result = run_reprojection_bench(
            args.rig,
            quick=args.quick,
            episodes=args.episodes,
            subtasks=args.subtasks,
            size=args.size,
            masks=args.masks,
            progress=True,
        )
    except ValueError as exc:
        print(f"bench reprojection: error: {exc}", file=sys.stderr)
        return 2
    return emit(args, result, () if args.json else [format_table(result)])


def format_table(result: dict[str, Any]) -> str:
    """The summary as text: PSNR per view and frame, and the plane-break table."""
    lines = [
        f"bench reprojection: {result['clips']} clips, {result['image_size'][0]}² px, "
        f"{result['ms_per_chunk_p50']} ms per chunk (p50, one thread)"
    ]
    rows = [
        *result["views"].items(),
        ("wrists pooled", result["wrists_pooled"]),
        ("wrists, measured pose", result["wrists_from_measured_state"]),
        ("wrists, no colour match", result["wrists_without_colour_match"]),
    ]
    for name, s in rows:
        cells = "  ".join(
            f"k={k}: {_db(p)}/{_db(f)} ({v:.0%})"
            for k, p, f, v in zip(s["k"], s["prior_psnr"], s["frozen_psnr"], s["fraction"], strict=True)
        )
        lines.append(f"  {name:24s} prior/frozen dB (valid)  {cells}")
    lines.append("  plane breaks (wrists, all k): share of valid, prior / frozen dB, prior MAE")
    for name, row in result["plane_breaks"].items():
        lines.append(
            f"    {name:12s} {row['share_of_valid']:6.1%}  {_db(row['prior_psnr']):>5s} / {_db(row['frozen_psnr']):>5s}"
            f"  {row['prior_mae']}"
        )
    acc = result["acceptance"]
    lines.append(f"  acceptance ({acc['rule']}): gain {acc['gain_db']} dB -> {'PASS' if acc['passed'] else 'FAIL'}")
    return "\n".join(lines)


def _db(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f}"


if __name__ == "__main__":
    raise SystemExit(main())
