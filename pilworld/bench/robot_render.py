"""``pilworld bench robot_render``: the robot renderer's masks against the simulator's own segmentation.

Ground truth is the **full simulated scene** (:func:`sim_robot_parts`): a connected :class:`SimRobot`
with a task's objects laid out, each 14-d configuration written straight into qpos (no physics; arm
joints as given, finger joints at grip × half-open, the simulator's own mapping), ``mj_forward``, and
MuJoCo's segmentation of every model camera at the rig's image size. Only robot geoms are kept —
geoms of bodies named ``left_*``/``right_*``; ``{side}_finger_a``/``_b`` → fingers, the rest of the side
→ arm; a calibration board is not robot — so the table and objects occlude the robot, as they do in
the camera images. The backend under test renders the robot alone (:mod:`pilworld.control_video`).

Configurations (:func:`sample_configs`), "per arm": for each arm, N configurations in which that arm
takes a random configuration — each joint uniform within ±0.6 rad of
:data:`~simrig.poses.HOME_Q14` (the gripper stays over or beside the table, in front of the head
camera), grip uniform in [0, 1] — while the other arm takes a random configuration of its own (half of
the time) or stays at home. A draw is rejected (and counted) if any moving robot geom dips below
``z = 0.005`` m (its exact lowest point from its pose and size; geoms that already reach below that
at home — the bases and shoulders standing on the table — are exempt) or if a left geom and a right
geom overlap (``mj_geomDistance`` < 0).

Per configuration and view: the IoU of the robot mask (union of parts; a view where both are empty
is skipped and counted), the IoU of each part present in either, the mean |depth error| on pixels both
mark robot (GT depth from MuJoCo's depth render of the full scene), pixel counts; per view the mean
and the worst IoU and the worst configuration's index; the backend's time per chunk of 15
configurations × all views. ``python -m pilworld.bench.robot_render --json`` prints the result as the
last line of stdout; ``--out DIR`` writes a PNG of the worst configuration (GT | render | XOR per view).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from pilworld.bench.common import machine_info
from pilworld.bench.flags import add_json, add_rig
from pilworld.bench.output import emit
from pilworld.config.rig import RigConfig
from pilworld.control_video.robot_model import (
    BOX,
    CAPSULE,
    CYLINDER,
    ELLIPSOID,
    PART_NAMES,
    SPHERE,
    RobotModel,
    part_id,
)
from pilworld.control_video.robot_render import BACKENDS, Backend, make_robot_renderer
from pilworld.types import ARM_LAYOUT, ARM_SIDES, STATE_DIM
from simrig.files import SIM_RIG
from simrig.gl import make_renderer, mujoco
from simrig.poses import HOME_Q14
from simrig.robot import SimRobot

__all__ = [
    "CHUNK",
    "JOINT_SPAN",
    "TABLE_CLEARANCE",
    "robot_geom_parts",
    "run_robot_render_accuracy",
    "sample_configs",
    "sim_robot_parts",
]

JOINT_SPAN: Final = 0.6  # rad: each arm joint uniform within ± this of HOME_Q14
TABLE_CLEARANCE: Final = 0.005  # m: a moving robot geom's lowest point must stay above this
CHUNK: Final = 15  # configurations per timed chunk (K frames of a world-model round)


# ---------------------------------------------------------------------------------------------- ground truth


def robot_geom_parts(model: Any) -> NDArray[np.uint8]:
    """Part id of every geom of a full simulated-rig model (0 for table, floor, objects and a board)."""
    out = np.zeros(model.ngeom, dtype=np.uint8)
    for g in range(model.ngeom):
        body = model.body(int(model.geom_bodyid[g])).name
        name = model.geom(g).name
        side = next((s for s in ARM_SIDES if body.startswith(f"{s}_")), None)
        if side is None or "calibration" in name:
            continue
        out[g] = part_id(side, fingers=body in (f"{side}_finger_a", f"{side}_finger_b"))
    return out


def sim_robot_parts(
    sim: SimRobot, q14: NDArray[np.floating], *, depth: bool = True
) -> tuple[dict[str, NDArray[np.uint8]], dict[str, NDArray[np.float32]] | None]:
    """The simulator's segmentation of the robot, per camera, for configurations (N, 14) set into qpos.

    The scene (objects where ``sim``'s last reset laid them) is copied into a private ``MjData``, so
    ``sim`` itself is left as it was. Returns part ids ``view → (N, H, W) uint8`` and, with ``depth``,
    MuJoCo's depth of the full scene (camera-frame Z, 0 where the pixel is not robot).
    """
    if not sim.is_connected:
        raise ValueError("sim: expected a connected SimRobot (call connect() and reset() first)")
    q = np.asarray(q14, dtype=np.float64).reshape(-1, STATE_DIM)
    if not np.all(np.isfinite(q)):
        raise ValueError("q14: must be finite")
    m = sim._model  # the ground truth reads the simulator's own model and renders below the Robot contract
    d = mujoco.MjData(m)
    d.qpos[:] = sim._data.qpos
    lut = np.concatenate([robot_geom_parts(m), np.zeros(1, dtype=np.uint8)])  # index −1 → background
    arm_q = {s: np.array([m.joint(f"{s}_joint_{i}").qposadr[0] for i in range(1, 7)]) for s in ARM_SIDES}
    fin_q = {s: np.array([m.joint(f"{s}_finger_{f}").qposadr[0] for f in "ab"]) for s in ARM_SIDES}
    half = {s: getattr(sim.rig.arms, s).gripper.max_opening_m / 2 for s in ARM_SIDES}
    w, h = sim.spec.image_size
    views = tuple(sim.spec.cameras)
    parts = {v: np.zeros((q.shape[0], h, w), dtype=np.uint8) for v in views}
    depths = {v: np.zeros((q.shape[0], h, w), dtype=np.float32) for v in views} if depth else None
    renderer = make_renderer(m, w, h)
    try:
        for i in range(q.shape[0]):
            for side, (arm, grip) in ARM_LAYOUT.items():
                d.qpos[arm_q[side]] = q[i, arm]
                d.qpos[fin_q[side]] = np.clip(q[i, grip], 0.0, 1.0) * half[side]
            mujoco.mj_forward(m, d)
            for v in views:
                renderer.update_scene(d, camera=v)
                renderer.enable_segmentation_rendering()
                seg = renderer.render()
                renderer.disable_segmentation_rendering()
                p = lut[np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1)]
                parts[v][i] = p
                if depths is not None:
                    renderer.enable_depth_rendering()
                    depths[v][i] = np.where(p > 0, renderer.render(), 0.0)
                    renderer.disable_depth_rendering()
    finally:
        renderer.close()
    return parts, depths


# ---------------------------------------------------------------------------------------------- sampler


def _lowest_z(
    types: NDArray[np.int64], size: NDArray[np.float64], rbound: NDArray[np.float64], pos: Any, rot: Any
) -> Any:
    """Exact lowest z of each primitive (N, G) from its pose; the bounding sphere for anything else."""
    rz = rot[..., 2, :]  # (N, G, 3): the geom's axes' z components
    r, hz = size[:, 0], size[:, 1]
    ax = np.abs(rz[..., 2])
    drop = np.select(
        [types == SPHERE, types == CAPSULE, types == CYLINDER, types == BOX, types == ELLIPSOID],
        [
            np.broadcast_to(r, ax.shape),
            r + ax * hz,
            ax * hz + r * np.sqrt(np.clip(1.0 - ax**2, 0.0, None)),
            np.sum(np.abs(rz) * size, axis=-1),
            np.sqrt(np.sum((rz * size) ** 2, axis=-1)),
        ],
        default=np.broadcast_to(rbound, ax.shape),
    )
    return pos[..., 2] - drop


class _Sampler:
    """Draws and checks configurations against the robot model's geometry (see the module docstring)."""

    def __init__(self, robot: RobotModel) -> None:
        self.robot = robot
        m = robot.model
        self.types, self.size = robot.geom_type, robot.geom_size
        self.rbound = np.asarray(m.geom_rbound[robot.geom_ids], dtype=np.float64)
        pos, rot = robot.geom_poses(HOME_Q14[None])
        self.moving = _lowest_z(self.types, self.size, self.rbound, pos, rot)[0] >= TABLE_CLEARANCE
        left = np.isin(robot.geom_part, (part_id("left", False), part_id("left", True)))
        self.pairs = [(int(a), int(b)) for a in robot.geom_ids[left] for b in robot.geom_ids[~left]]
        self._data = mujoco.MjData(m)
        self._fromto = np.zeros(6)

    def below_table(self, q: NDArray[np.float64]) -> NDArray[np.bool_]:
        pos, rot = self.robot.geom_poses(q)
        low = _lowest_z(self.types, self.size, self.rbound, pos, rot)
        return np.asarray(np.any((low < TABLE_CLEARANCE) & self.moving, axis=-1), dtype=np.bool_)

    def arms_collide(self, q: NDArray[np.float64]) -> bool:
        m, d = self.robot.model, self._data
        d.qpos[:] = self.robot.qpos(q)
        mujoco.mj_kinematics(m, d)
        # 5 cm look-ahead: pairs farther apart than that return 5 cm without the exact distance.
        return any(mujoco.mj_geomDistance(m, d, a, b, 0.05, self._fromto) < 0.0 for a, b in self.pairs)


def _random_arm(rng: np.random.Generator, q: NDArray[np.float64], side: str) -> None:
    arm, grip = ARM_LAYOUT[side]
    q[arm] = HOME_Q14[arm] + rng.uniform(-JOINT_SPAN, JOINT_SPAN, 6)
    q[grip] = rng.uniform(0.0, 1.0)


def sample_configs(
    robot: RobotModel, configs_per_arm: int, seed: int = 0
) -> tuple[NDArray[np.float64], NDArray[np.int64], dict[str, int]]:
    """``configs_per_arm`` valid configurations per arm: (2N, 14), the arm index each varies, rejections."""
    if isinstance(configs_per_arm, bool) or not isinstance(configs_per_arm, int) or configs_per_arm < 1:
        raise ValueError(f"configs_per_arm: expected an integer >= 1, got {configs_per_arm!r}")
    rng = np.random.default_rng(seed)
    sampler = _Sampler(robot)
    out, which = [], []
    rejected = {"below_table": 0, "arms_collide": 0}
    for k, side in enumerate(ARM_SIDES):
        other = ARM_SIDES[1 - k]
        got = 0
        while got < configs_per_arm:
            q = HOME_Q14.copy()
            _random_arm(rng, q, side)
            if rng.uniform() < 0.5:
                _random_arm(rng, q, other)
            if sampler.below_table(q[None])[0]:
                rejected["below_table"] += 1
                continue
            if sampler.arms_collide(q):
                rejected["arms_collide"] += 1
                continue
            out.append(q)
            which.append(k)
            got += 1
    return np.stack(out), np.array(which, dtype=np.int64), rejected


# ---------------------------------------------------------------------------------------------- the bench


def _iou(a: NDArray[np.bool_], b: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Per-image IoU over (N, H, W); NaN where both are empty."""
    inter = np.sum(a & b, axis=(1, 2))
    union = np.sum(a | b, axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(union > 0, inter / np.maximum(union, 1), np.nan)


def _stats(x: NDArray[np.floating]) -> dict[str, float]:
    return {"mean": float(np.mean(x)), "min": float(np.min(x)), "max": float(np.max(x))}


def _diagnostic_png(
    path: Path, gt: dict[str, NDArray[np.uint8]], pred: dict[str, NDArray[np.uint8]], index: dict[str, int]
) -> None:
    """One row per view (its worst configuration): GT parts | rendered parts | XOR of the robot masks."""
    import cv2

    palette = np.array([[0, 0, 0], [70, 130, 230], [120, 220, 255], [230, 120, 60], [255, 210, 120]], np.uint8)
    rows = []
    for v, i in index.items():
        a, b = gt[v][i], pred[v][i]
        xor = np.zeros((*a.shape, 3), np.uint8)
        xor[(a > 0) & (b == 0)] = (255, 0, 0)  # missed by the render
        xor[(a == 0) & (b > 0)] = (0, 255, 0)  # extra in the render (e.g. occluded in the scene)
        rows.append(np.concatenate([palette[a], palette[b], xor], axis=1))
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0))) for r in rows]
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(np.concatenate(rows, axis=0), cv2.COLOR_RGB2BGR))


def run_robot_render_accuracy(
    rig_path: str | Path = SIM_RIG,
    configs_per_arm: int = 200,
    seed: int = 0,
    backend: Backend = "analytic",
    task: str = "sort_cubes",
    out: str | Path | None = None,
) -> dict[str, Any]:
    """The backend's robot masks (and depth) against the full-scene ground truth; a JSON-able dict."""
    if backend not in BACKENDS:
        raise ValueError(f"backend: expected one of {', '.join(BACKENDS)}, got {backend!r}")
    t0 = time.monotonic()
    rig = RigConfig.load(rig_path)
    robot = RobotModel.from_rig(rig)
    q, which, rejected = sample_configs(robot, configs_per_arm, seed)
    renderer = make_robot_renderer(rig, backend, robot=robot)
    with SimRobot(rig, task) as sim:
        sim.reset(seed=seed, history=0)
        t_gt = time.monotonic()
        gt, gt_depth = sim_robot_parts(sim, q)
        gt_s = time.monotonic() - t_gt
    views = renderer.cameras.names
    missing = [v for v in views if v not in gt]
    if missing:
        raise ValueError(f"rig {rig.name!r}: the simulator has no camera {missing}")
    pred: dict[str, list[NDArray[np.uint8]]] = {v: [] for v in views}
    pred_depth: dict[str, list[NDArray[np.float32]]] = {v: [] for v in views}
    chunk_ms = []
    has_depth = True
    for s in range(0, len(q), CHUNK):
        t = time.perf_counter()
        r = renderer.render(q[s : s + CHUNK], depth=True, shaded=False)
        chunk_ms.append((time.perf_counter() - t) * 1e3 * CHUNK / len(q[s : s + CHUNK]))
        for v in views:
            pred[v].append(r.parts[v])
            if r.depth is None:
                has_depth = False
            else:
                pred_depth[v].append(r.depth[v])
    close = getattr(renderer, "close", None)
    if callable(close):
        close()
    parts = {v: np.concatenate(pred[v]) for v in views}
    report: dict[str, Any] = {}
    worst_index: dict[str, int] = {}
    for v in views:
        a, b = gt[v] > 0, parts[v] > 0
        iou = _iou(a, b)
        valid = ~np.isnan(iou)
        worst = int(np.nanargmin(iou)) if valid.any() else -1
        worst_index[v] = max(worst, 0)
        part_iou = {}
        for pid, name in enumerate(PART_NAMES[1:], start=1):
            pi = _iou(gt[v] == pid, parts[v] == pid)
            part_iou[name] = None if np.all(np.isnan(pi)) else round(float(np.nanmean(pi)), 4)
        entry: dict[str, Any] = {
            "mean_iou": round(float(np.nanmean(iou)), 4) if valid.any() else None,
            "worst_iou": round(float(iou[worst]), 4) if valid.any() else None,
            "worst_config": worst,
            "worst_config_q14": q[worst].round(4).tolist() if valid.any() else None,
            "evaluated": int(valid.sum()),
            "skipped_both_empty": int((~valid).sum()),
            "mean_iou_per_arm": {
                side: round(float(np.nanmean(iou[valid & (which == k)])), 4) if np.any(valid & (which == k)) else None
                for k, side in enumerate(ARM_SIDES)
            },
            "iou_percentiles": {p: round(float(np.nanpercentile(iou, p)), 4) for p in (1, 5, 50)}
            if valid.any()
            else None,
            "part_iou": part_iou,
            "gt_pixels": _stats(a.sum(axis=(1, 2))),
            "render_pixels": _stats(b.sum(axis=(1, 2))),
        }
        if has_depth and gt_depth is not None:
            both = a & b
            err = np.abs(np.concatenate(pred_depth[v]) - gt_depth[v])[both]
            entry["depth_abs_err_mm"] = (
                {"mean": round(float(err.mean()) * 1e3, 3), "median": round(float(np.median(err)) * 1e3, 3)}
                if err.size
                else None
            )
        report[v] = entry
    result: dict[str, Any] = {
        "bench": "robot_render",
        "backend": backend,
        "rig": rig.name,
        "task": task,
        "seed": seed,
        "configs_per_arm": configs_per_arm,
        "configs": len(q),
        "image_size": list(sim.spec.image_size),
        "sampler": {"joint_span_rad": JOINT_SPAN, "table_clearance_m": TABLE_CLEARANCE, "rejected": rejected},
        "views": report,
        "ms_per_chunk": {
            "chunk": CHUNK,
            "views": len(views),
            **{k: round(x, 1) for k, x in _stats(np.array(chunk_ms)).items()},
        },
        "ground_truth_ms_per_chunk": round(gt_s * 1e3 * CHUNK / len(q), 1),
        "machine": machine_info(),
        "wall_s": round(time.monotonic() - t0, 1),
    }
    if out is not None:
        png = Path(out) / f"robot_render_worst_{backend}.png"
        _diagnostic_png(png, gt, parts, worst_index)
        result["diagnostic_png"] = str(png)
    return result


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``pilworld bench robot-render``'s options (``python -m pilworld.bench.robot_render`` has its own)."""
    add_rig(parser)
    parser.add_argument("--configs-per-arm", type=int, default=200, help="random configurations per arm (default 200)")
    parser.add_argument(
        "--backend", choices=BACKENDS, default="analytic", help="renderer under test (default analytic)"
    )
    parser.add_argument(
        "--task", default="sort_cubes", help="task whose scene is the ground truth (default sort_cubes)"
    )
    parser.add_argument("--out", type=Path, default=None, help="folder for the worst-case diagnostic PNG")
    parser.add_argument("--seed", type=int, default=0)
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """The IoU per view (mean and worst), then with ``--json`` the whole result."""
    result = run_robot_render_accuracy(
        args.rig,
        configs_per_arm=args.configs_per_arm,
        seed=args.seed,
        backend=args.backend,
        task=args.task,
        out=args.out,
    )
    lines = [
        f"{view:16s} mean IoU {r['mean_iou']:.4f}  worst {r['worst_iou']:.4f} (config {r['worst_config']})"
        for view, r in result["views"].items()
    ]
    return emit(args, result, lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pilworld.bench.robot_render", description=__doc__.split("\n")[0])
    ap.add_argument("--rig", default=str(SIM_RIG))
    ap.add_argument("--configs-per-arm", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--backend", choices=BACKENDS, default="analytic")
    ap.add_argument("--task", default="sort_cubes")
    ap.add_argument("--out", default=None, help="folder for the worst-case diagnostic PNG")
    ap.add_argument("--json", action="store_true", help="print one JSON object as the last line")
    args = ap.parse_args(argv)
    result = run_robot_render_accuracy(args.rig, args.configs_per_arm, args.seed, args.backend, args.task, args.out)
    if args.json:
        print(json.dumps(result))
    else:
        for v, e in result["views"].items():
            print(f"{v:16s} mean IoU {e['mean_iou']}  worst {e['worst_iou']} (config {e['worst_config']})")
        print(f"ms per chunk of {CHUNK} configs × {result['ms_per_chunk']['views']} views: {result['ms_per_chunk']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
