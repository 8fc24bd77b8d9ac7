"""``pilworld bench calibration``: intrinsics accuracy, hand-eye accuracy and the hand-eye stability sweep.

Three parts, each timed:

* **Intrinsics** (the issue's synthetic acceptance, same protocol as ``tests/calib/test_intrinsics.py``):
  per seed, 20 views of the A3 board (``configs/board/charuco_12x9_a3.yaml``) are rendered through a known
  640x480 lens (:data:`TRUE_CAMERA`, radial and tangential distortion), detected, given 0.3 px Gaussian
  noise per corner coordinate and calibrated. Reported over the seeds: the median of the worse of
  ``|Δfx|/fx`` and ``|Δfy|/fy`` (``intrinsics_focal_rel_err`` as a fraction, ``..._percent`` in percent),
  the median principal-point error, the median and the largest RMS, and how often each 95 % interval
  covers the truth (``intrinsics_ci95_coverage`` is the lowest over the parameters).
* **Hand-eye** (``handeye_trans_err_mm``, ``handeye_rot_err_deg``, ``gripper_reproj_err_px``): from the
  rendered simulated-rig calibration ``pilworld.calibration.sim_handeye.run_sim_handeye`` when it is
  installed (``handeye_source: "sim_rendered"``), else from the synthetic scene of :mod:`calib.sweep` with
  exact FK, 20 poses, 0.3 px corner noise and the refined solver, medians over the trials (``"synthetic"``;
  the gripper reprojection error is then the mean pixel distance, at 1024x1024, between the TCPs projected
  with the estimated and the true ``T_cam_base``). The synthetic figures are always reported as well
  (``handeye_synthetic``): the sim's renders carry only the detector's error, not 0.3 px of noise.
* **Sweep** (:func:`calib.sweep.run_sweep`): translation and rotation error of ``T_cam_base`` per method
  against pixel noise, FK noise, number of poses and rotation span, with a chart (:func:`plot_sweep`).
* **Wrist cameras** (eye-in-hand; docs/calibration.md): per wrist camera of the simulated rig, ``wrist_seeds`` full
  calibrations (:func:`pilworld.calibration.sim_handeye.run_sim_wrist`: board flat on the table, 20 poses,
  1024 px) and the *largest* error of ``T_tcp_cam`` over the seeds (``wrist_trans_err_mm_max``,
  ``wrist_rot_err_deg_max``, per camera under ``wrist``); with the synthetic source (``--quick``), the
  same from :func:`calib.sweep.make_in_hand_trial` scenes (0.3 px, FK 0.02°). ``wrist_degenerate`` holds
  the refusal messages of a pure-translation and a single-axis motion set, and ``wrist_sweep`` the
  eye-in-hand stability sweep (:func:`calib.sweep.run_in_hand_sweep`, a few values per axis).
"""

from __future__ import annotations

import importlib
import math
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, Final

import numpy as np
from tqdm import tqdm

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.detect import BoardDetector
from calib.handeye_refine import refine_eye_to_hand
from calib.handeye_solve import solve_eye_to_hand
from calib.intrinsics import IntrinsicsOptions, calibrate_intrinsics
from calib.rotations import pose_difference
from calib.sweep import (
    AXES,
    DEFAULT_VALUES,
    IN_HAND_DEFAULTS,
    IN_HAND_VALUES,
    THRESHOLD_DEG,
    THRESHOLD_MM,
    SweepConditions,
    count_points,
    make_in_hand_trial,
    make_trial,
    run_in_hand_sweep,
    run_sweep,
    solve_in_hand_trial,
)
from calib.synthetic import perturb_detection, synthetic_views
from pilworld.bench.common import machine_info
from simrig.files import SIM_RIG

__all__ = [
    "A3_BOARD",
    "DEFAULT_OUT",
    "TRUE_CAMERA",
    "intrinsics_figures",
    "plot_sweep",
    "run_calibration_bench",
    "synthetic_handeye_figures",
    "wrist_degeneracy_checks",
    "wrist_figures",
]

ROOT = Path(__file__).resolve().parents[2]
A3_BOARD: Final = ROOT / "configs" / "board" / "charuco_12x9_a3.yaml"
DEFAULT_OUT: Final = Path("bench_out") / "calibration"

#: The "unknown" lens of the intrinsics acceptance (tests/calib/scenes.py): 640x480, radial + tangential.
TRUE_CAMERA: Final = CameraModel(
    K=np.array([[600.0, 0.0, 322.5], [0.0, 603.0, 237.8], [0.0, 0.0, 1.0]]),
    dist=np.array([-0.12, 0.08, 0.0008, -0.0005, -0.02]),
    T_cam_base=np.eye(4),
    width=640,
    height=480,
)
_PARAMS: Final = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
NOISE_PX: Final = 0.3
#: The issue's intrinsics acceptance.
ACCEPT_FOCAL_REL: Final = 0.003
ACCEPT_PP_PX: Final = 1.5
ACCEPT_RMS_PX: Final = 0.5
ACCEPT_COVERAGE: Final = 0.8


def _truth() -> dict[str, float]:
    K, d = TRUE_CAMERA.K, TRUE_CAMERA.dist
    return {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2], **dict(zip(_PARAMS[4:], d, strict=True))}


def intrinsics_figures(
    seeds: Sequence[int], *, views: int = 20, board_path: Path = A3_BOARD, progress: bool = True
) -> dict[str, Any]:
    """The intrinsics acceptance figures over ``seeds`` (see the module docstring)."""
    if not seeds:
        raise ValueError("--seeds: need at least one seed for the intrinsics figures")
    board = ChArUcoBoard.from_yaml(board_path)
    truth = _truth()
    f_err, pp_err, rms, held = [], [], [], []
    covered = dict.fromkeys(_PARAMS, 0)
    for seed in tqdm(seeds, desc="intrinsics seeds", unit="seed", disable=not progress):
        rendered = synthetic_views(board, TRUE_CAMERA, views, seed=seed)
        detector = BoardDetector(board)
        rng = np.random.default_rng(10_000 + seed)  # the test's noise draws
        dets = [
            perturb_detection(detector.detect(v.image, f"view_{i:02d}.png"), NOISE_PX, rng)
            for i, v in enumerate(rendered)
        ]
        result = calibrate_intrinsics(dets, IntrinsicsOptions(seed=seed))
        f_err.append(max(abs(result.value(k) - truth[k]) / truth[k] for k in ("fx", "fy")))
        pp_err.append(math.hypot(result.value("cx") - truth["cx"], result.value("cy") - truth["cy"]))
        rms.append(result.rms_px)
        if result.held_out_rms_px is not None:
            held.append(result.held_out_rms_px)
        for name, (lo, hi) in result.intervals95.items():
            covered[name] += int(lo <= truth[name] <= hi)
    n = len(seeds)
    coverage = {k: v / n for k, v in covered.items()}
    focal, pp, rms_max = float(np.median(f_err)), float(np.median(pp_err)), float(np.max(rms))
    return {
        "intrinsics_focal_rel_err": focal,
        "intrinsics_focal_rel_err_percent": 100.0 * focal,
        "intrinsics_pp_err_px": pp,
        "intrinsics_rms_px": float(np.median(rms)),
        "intrinsics_rms_px_max": rms_max,
        "intrinsics_held_out_rms_px": float(np.median(held)) if held else None,
        "intrinsics_ci95_coverage": min(coverage.values()),
        "intrinsics_ci95_coverage_per_param": coverage,
        "intrinsics_acceptance_met": bool(
            focal <= ACCEPT_FOCAL_REL
            and pp <= ACCEPT_PP_PX
            and rms_max <= ACCEPT_RMS_PX
            and min(coverage.values()) >= ACCEPT_COVERAGE
        ),
        "intrinsics_seeds": n,
        "intrinsics_views": views,
        "intrinsics_noise_px": NOISE_PX,
        "intrinsics_board": board.name,
    }


def synthetic_handeye_figures(trials: int, *, poses: int = 20, progress: bool = True) -> dict[str, Any]:
    """Refined eye-to-hand on the synthetic scene of :mod:`calib.sweep` with exact FK; medians over trials."""
    cond = SweepConditions(poses=poses, fk_noise_deg=0.0)
    trans, rot, reproj = [], [], []
    camera = None
    for k in tqdm(range(trials), desc="hand-eye (synthetic)", unit="trial", disable=not progress):
        trial = make_trial(cond, 50_000 + k)
        camera = trial.camera
        start = solve_eye_to_hand(trial.T_base_gripper, trial.T_cam_board, method="shah")
        refined = refine_eye_to_hand(
            start.T_cam_base,
            start.T_gripper_board,
            trial.T_base_gripper,
            [trial.board_points] * poses,
            list(trial.image_points),
            camera.K,
            camera.dist,
        )
        dt, dr = pose_difference(refined.T_cam_base, camera.T_cam_base)
        trans.append(1e3 * dt)
        rot.append(dr)
        # The TCP of every pose, projected with the solved and with the true camera pose.
        tcp = trial.T_base_gripper_true[:, :3, 3]
        uv_true, _ = camera.project(tcp)
        uv_est, _ = camera.with_pose(refined.T_cam_base).project(tcp)
        reproj.append(float(np.linalg.norm(uv_est - uv_true, axis=1).mean()))
    if camera is None:
        raise ValueError("synthetic hand-eye: trials must be >= 1")
    return {
        "handeye_trans_err_mm": float(np.median(trans)),
        "handeye_rot_err_deg": float(np.median(rot)),
        "gripper_reproj_err_px": float(np.median(reproj)),
        "trans_err_mm_p90": float(np.percentile(trans, 90)),
        "rot_err_deg_p90": float(np.percentile(rot, 90)),
        "trials": trials,
        "poses": poses,
        "pixel_noise_px": cond.pixel_noise_px,
        "fk_noise_deg": cond.fk_noise_deg,
        "rotation_span_deg": cond.rotation_span_deg,
        "image_size": [camera.width, camera.height],
        "method": "refined",
    }


def _sim_handeye(rig_path: Path, poses: int, seed: int) -> dict[str, Any]:
    module = importlib.import_module("pilworld.calibration.sim_handeye")
    from pilworld.config.rig import RigConfig

    result: dict[str, Any] = dict(module.run_sim_handeye(RigConfig.load(rig_path), "left", poses=poses, seed=seed))
    return result


def handeye_figures(
    source: str, *, trials: int, poses: int, rig_path: Path, seed: int, progress: bool
) -> dict[str, Any]:
    """Headline hand-eye figures from ``source`` ("auto", "sim" or "synthetic"); labels where they came from."""
    if source not in ("auto", "sim", "synthetic"):
        raise ValueError(f"--handeye-source: expected auto, sim or synthetic, got {source!r}")
    reason, sim = None, None
    if source in ("auto", "sim"):
        try:
            sim = _sim_handeye(rig_path, poses, seed)
        except ModuleNotFoundError as exc:
            if source == "sim" or exc.name not in ("pilworld.calibration", "pilworld.calibration.sim_handeye"):
                raise
            reason = f"pilworld.calibration.sim_handeye is not available ({exc})"
    # Always computed (about a second): noisy pixels, unlike the sim's clean renders.
    syn = synthetic_handeye_figures(trials, poses=poses, progress=progress)
    keys = ("handeye_trans_err_mm", "handeye_rot_err_deg", "gripper_reproj_err_px")
    if sim is not None:
        return {
            **{k: float(sim[k]) for k in keys},
            "handeye_source": "sim_rendered",
            "handeye": {"arm": "left", "rig": str(rig_path), **sim},
            "handeye_synthetic": syn,
        }
    detail = {k: v for k, v in syn.items() if k not in keys}
    if reason is not None:
        detail["fallback_reason"] = reason
    return {**{k: syn[k] for k in keys}, "handeye_source": "synthetic", "handeye": detail, "handeye_synthetic": syn}


WRIST_CAMERAS: Final = ("cam_left_wrist", "cam_right_wrist")


def _wrist_sim(rig_path: Path, camera: str, poses: int, seed: int, resolution: int) -> dict[str, Any]:
    module = importlib.import_module("pilworld.calibration.sim_handeye")
    from pilworld.config.rig import RigConfig

    result: dict[str, Any] = dict(
        module.run_sim_wrist(RigConfig.load(rig_path), camera, poses=poses, seed=seed, resolution=resolution)
    )
    return result


def _wrist_synthetic(poses: int, seed: int) -> dict[str, Any]:
    trial = make_in_hand_trial(replace(IN_HAND_DEFAULTS, poses=poses), seed)
    refined = solve_in_hand_trial(trial, ("refined",))["refined"]
    if refined.refused is not None:  # pragma: no cover - the defaults always determine the mount
        raise ValueError(f"synthetic wrist calibration refused: {refined.refused}")
    return {"wrist_trans_err_mm": refined.trans_mm, "wrist_rot_err_deg": refined.rot_deg, "poses": float(poses)}


def wrist_figures(
    source: str,
    *,
    seeds: int = 10,
    poses: int = 20,
    resolution: int = 1024,
    rig_path: Path = SIM_RIG,
    cameras: Sequence[str] = WRIST_CAMERAS,
    progress: bool = True,
) -> dict[str, Any]:
    """Eye-in-hand accuracy per wrist camera over ``seeds`` seeds: the largest errors against the truth.

    ``source`` "sim" renders the simulated rig (:func:`pilworld.calibration.sim_handeye.run_sim_wrist`),
    "synthetic" uses :func:`calib.sweep.make_in_hand_trial` scenes (0.3 px, FK 0.02°; other draws per camera).
    """
    if source not in ("sim", "synthetic"):
        raise ValueError(f"wrist source: expected sim or synthetic, got {source!r}")
    if isinstance(seeds, bool) or not isinstance(seeds, int) or seeds < 1:
        raise ValueError(f"wrist seeds: expected an integer >= 1, got {seeds!r}")
    per_camera: dict[str, Any] = {}
    total = seeds * len(cameras)
    with tqdm(total=total, desc=f"wrist cameras ({source})", unit="run", disable=not progress) as bar:
        for camera in cameras:
            runs = []
            for seed in range(seeds):
                if source == "sim":
                    run = _wrist_sim(rig_path, camera, poses, seed, resolution)
                else:  # other draws per camera (the synthetic scene has no arm)
                    run = _wrist_synthetic(poses, 70_000 + 1000 * cameras.index(camera) + seed)
                runs.append(run)
                bar.update(1)
            trans = [r["wrist_trans_err_mm"] for r in runs]
            rot = [r["wrist_rot_err_deg"] for r in runs]
            entry: dict[str, Any] = {
                "trans_err_mm_max": float(np.max(trans)),
                "rot_err_deg_max": float(np.max(rot)),
                "trans_err_mm_median": float(np.median(trans)),
                "rot_err_deg_median": float(np.median(rot)),
                "trans_err_mm_per_seed": trans,
                "rot_err_deg_per_seed": rot,
            }
            if source == "sim":
                for key in ("board_reproj_err_px", "sigma_translation_mm", "sigma_rotation_deg", "residual_rms_px"):
                    entry[f"{key}_max"] = float(np.max([r[key] for r in runs]))
                entry["rotation_span_deg_min"] = float(np.min([r["rotation_span_deg"] for r in runs]))
                entry["seconds_per_run"] = float(np.median([r["seconds"] for r in runs]))
            per_camera[camera] = entry
    trans_max = max(e["trans_err_mm_max"] for e in per_camera.values())
    rot_max = max(e["rot_err_deg_max"] for e in per_camera.values())
    return {
        "wrist_trans_err_mm_max": trans_max,
        "wrist_rot_err_deg_max": rot_max,
        "wrist_acceptance_met": bool(trans_max <= THRESHOLD_MM and rot_max <= THRESHOLD_DEG),
        "wrist_source": "sim_rendered" if source == "sim" else "synthetic",
        "wrist": {
            "seeds": seeds,
            "poses": poses,
            "resolution": resolution if source == "sim" else 1024,
            "thresholds": {"trans_mm": THRESHOLD_MM, "rot_deg": THRESHOLD_DEG},
            "cameras": per_camera,
        },
    }


def wrist_degeneracy_checks() -> dict[str, Any]:
    """Pure translation and rotations about one axis must be refused, with a message naming the motion to add."""
    from calib.handeye import DegenerateMotionError
    from calib.handeye_solve import solve_eye_in_hand
    from calib.rotations import rigid, rotation_exp
    from calib.sweep import T_BASE_BOARD, T_TCP_CAM
    from pilworld.geometry import invert_transform

    start = rigid(np.diag([1.0, -1.0, -1.0]), [0.4, 0.1, 0.4])
    sets = {
        "pure_translation": [start @ rigid(np.eye(3), [0.04 * k, 0.02 * (k % 2), 0.01 * k]) for k in range(6)],
        "single_axis": [
            start @ rigid(rotation_exp([math.radians(a), 0.0, 0.0]), [0.0, 0.01 * k, 0.0])
            for k, a in enumerate((-30, -15, 0, 10, 25))
        ],
    }
    expected = {
        "pure_translation": "add rotations about two different axes",
        "single_axis": "add rotations about a second axis",
    }
    out: dict[str, Any] = {}
    for name, G in sets.items():
        C = [invert_transform(T_TCP_CAM) @ invert_transform(g) @ T_BASE_BOARD for g in G]
        try:
            solve_eye_in_hand(G, C)
            message, refused = None, False
        except DegenerateMotionError as exc:
            message, refused = str(exc), True
        out[name] = {
            "refused": refused,
            "names_the_motion_to_add": bool(message is not None and expected[name] in message),
            "message": message,
        }
    out["all_refused_with_advice"] = all(v["refused"] and v["names_the_motion_to_add"] for v in out.values())
    return out


_STYLE: Final = {"park_martin": "tab:blue", "shah": "tab:orange", "refined": "black"}


def plot_sweep(sweep: dict[str, Any], path: Path) -> Path:
    """Chart of :meth:`calib.sweep.SweepResult.to_dict`: rows = axes, columns = translation and rotation error.

    Solid line and marker: median over the trials; dotted line of the same colour: 90th percentile; an ×
    on the top edge: the method refused at least half of the trials there; black dashed: the acceptance
    bound. Values are evenly spaced (the axes include 0), labelled with their values.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    axes_data: dict[str, dict[str, list[dict[str, Any]]]] = sweep["axes"]
    units = sweep.get("units", {a: u for a, (_, u) in AXES.items()})
    methods: list[str] = list(sweep["methods"])
    cmap = plt.get_cmap("tab10")
    others = [m for m in methods if m not in _STYLE]
    colours = {**_STYLE, **{m: cmap(2 + i) for i, m in enumerate(others)}}
    rows = list(axes_data)
    fig, grid = plt.subplots(len(rows), 2, figsize=(13, 3.3 * len(rows)), squeeze=False)
    floors = {"trans_mm": 1e-2, "rot_deg": 1e-3}
    tops = {"trans_mm": 3e3, "rot_deg": 3e2}
    bounds = {"trans_mm": THRESHOLD_MM, "rot_deg": THRESHOLD_DEG}
    labels = {"trans_mm": "translation error (mm)", "rot_deg": "rotation error (deg)"}
    for r, axis in enumerate(rows):
        for c, metric in enumerate(("trans_mm", "rot_deg")):
            ax = grid[r][c]
            values: list[float] = []
            for j, method in enumerate(methods):
                stats = axes_data[axis][method]
                values = [s["value"] for s in stats]
                x = np.arange(len(stats)) + (j - (len(methods) - 1) / 2) * 0.025
                med = np.array([np.nan if s[f"{metric}_median"] is None else s[f"{metric}_median"] for s in stats])
                p90 = np.array([np.nan if s[f"{metric}_p90"] is None else s[f"{metric}_p90"] for s in stats])
                ours = not method.startswith("opencv_")
                style = {
                    "color": colours[method],
                    "lw": 2.2 if method == "refined" else (1.6 if ours else 1.0),
                    "alpha": 1.0 if ours else 0.75,
                }
                ax.plot(x, np.maximum(med, floors[metric]), marker="o" if ours else ".", ms=4, label=method, **style)
                ax.plot(x, np.maximum(p90, floors[metric]), ls=":", **{**style, "alpha": 0.8 if ours else 0.45})
                refused = [i for i, s in enumerate(stats) if 2 * s["refused"] >= s["trials"]]
                if refused:
                    ax.plot(x[refused], [tops[metric] * 0.6] * len(refused), ls="none", marker="x", ms=8, mew=2,
                            color=colours[method])  # fmt: skip
            ax.axhline(bounds[metric], color="k", ls="--", lw=1)
            ax.set_yscale("log")
            ax.set_ylim(floors[metric], tops[metric])
            ax.set_xticks(range(len(values)), [f"{v:g}" for v in values])
            ax.set_xlabel(f"{axis.replace('_', ' ')} ({units.get(axis, '')})")
            ax.set_ylabel(labels[metric])
            ax.grid(True, which="major", alpha=0.3)
    d = sweep["defaults"]
    fig.suptitle(
        f"Eye-to-hand T_cam_base error vs conditions ({sweep['trials']} trials per point; defaults: "
        f"{d['pixel_noise_px']} px, FK {d['fk_noise_deg']}°, {d['poses']} poses, span {d['rotation_span_deg']}°; "
        f"OpenCV {sweep['opencv_version']})\nsolid = median, dotted = p90, × at top = refused in ≥ half the trials, "
        f"dashed = acceptance ({THRESHOLD_MM} mm, {THRESHOLD_DEG}°); opencv_* run without the motion check",
        fontsize=10,
    )
    handles, names = grid[0][0].get_legend_handles_labels()
    fig.legend(handles, names, loc="lower center", ncol=min(len(methods), 5), fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.05, 1, 0.95))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    from PIL import Image  # matplotlib's own dependency

    with Image.open(path) as img:  # a 256-colour palette: a third of the size, no visible loss on line art
        quantized = img.convert("RGB").quantize(colors=256)
    quantized.save(path, optimize=True)
    return path


def run_calibration_bench(
    *,
    seeds: int = 20,
    views: int = 20,
    trials: int = 30,
    quick: bool = False,
    out_dir: Path = DEFAULT_OUT,
    handeye_source: str | None = None,
    handeye_poses: int = 20,
    rig_path: Path = SIM_RIG,
    seed: int = 0,
    progress: bool = True,
    wrist_seeds: int = 10,
    wrist_poses: int = 20,
    wrist_trials: int = 5,
) -> dict[str, Any]:
    """All four parts (see the module docstring); ``quick`` shrinks them to a few seconds for tests.

    ``wrist_seeds`` calibrations per wrist camera (``wrist_poses`` poses each); ``wrist_trials`` trials per
    point of the eye-in-hand sweep. The wrist cameras use the simulated rig unless the hand-eye source
    is synthetic (``--quick`` or ``--handeye-source synthetic``).
    """
    for name, value, low in (("--seeds", seeds, 1), ("--views", views, 4), ("--trials", trials, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{name}: expected an integer >= {low}, got {value!r}")
    if quick:
        seeds, trials = min(seeds, 2), min(trials, 2)
    source = handeye_source or ("synthetic" if quick else "auto")
    t_total = time.perf_counter()
    out: dict[str, Any] = {"bench": "calibration", "quick": quick}

    t0 = time.perf_counter()
    out |= intrinsics_figures(range(seeds), views=views, progress=progress)
    t_intr = time.perf_counter() - t0

    t0 = time.perf_counter()
    out |= handeye_figures(
        source, trials=max(trials, 3) if not quick else trials, poses=handeye_poses, rig_path=rig_path, seed=seed,
        progress=progress,
    )  # fmt: skip
    t_he = time.perf_counter() - t0

    with tqdm(
        total=trials * count_points(DEFAULT_VALUES), desc="hand-eye sweep", unit="trial", disable=not progress
    ) as bar:
        sweep = run_sweep(trials, seed=seed, progress=bar.update).to_dict()
    out["sweep"] = sweep.pop("axes")
    out["sweep_settings"] = sweep
    out["opencv_version"] = sweep["opencv_version"]
    out["opencv_methods_available"] = sweep["opencv_methods_available"]

    chart = plot_sweep({**sweep, "axes": out["sweep"]}, Path(out_dir) / "calibration_sweep.png")
    out["chart"] = str(chart)
    out["seconds"] = {
        "intrinsics": t_intr,
        "handeye": t_he,
        "sweep": sweep["seconds"],
        "total": time.perf_counter() - t_total,
    }
    t0 = time.perf_counter()
    wrist_source = "synthetic" if out["handeye_source"] == "synthetic" else "sim"
    n_wrist = min(wrist_seeds, 2) if quick else wrist_seeds
    out |= wrist_figures(wrist_source, seeds=n_wrist, poses=wrist_poses, rig_path=rig_path, progress=progress)
    out["wrist_degenerate"] = wrist_degeneracy_checks()
    wrist_sweep = run_in_hand_sweep(min(wrist_trials, 2) if quick else wrist_trials, seed=seed).to_dict()
    out["wrist_sweep"] = wrist_sweep.pop("axes")
    out["wrist_sweep_settings"] = {**wrist_sweep, "values": {k: list(v) for k, v in IN_HAND_VALUES.items()}}
    out["seconds"]["wrist"] = time.perf_counter() - t0
    out["seconds"]["total"] = time.perf_counter() - t_total
    out["machine"] = machine_info()
    return out


# ---------------------------------------------------------------------- pilworld bench calibration
# The command's options, run and summary. Imported here rather than at the top, so that this block can be
# appended without touching the module's own imports.
import argparse  # noqa: E402

from pilworld.bench.flags import add_json  # noqa: E402
from pilworld.bench.output import emit  # noqa: E402


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seeds", type=int, default=20, help="intrinsics seeds, 20 views each (default 20)")
    parser.add_argument("--views", type=int, default=20, help="views per intrinsics seed (default 20)")
    parser.add_argument("--trials", type=int, default=30, help="hand-eye trials per sweep point (default 30)")
    parser.add_argument(
        "--handeye-source",
        choices=["auto", "sim", "synthetic"],
        default=None,
        help="headline hand-eye figures: rendered simulated rig (sim), synthetic, or sim when available "
        "(auto, the default; --quick defaults to synthetic)",
    )
    parser.add_argument("--handeye-poses", type=int, default=20, help="gripper poses of the headline run (default 20)")
    parser.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config of the sim hand-eye run")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="chart folder (created)")
    parser.add_argument("--quick", action="store_true", help="2 seeds, 2 trials per point: a few seconds (tests)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars on stderr")
    parser.add_argument("--seed", type=int, default=0)
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    r = run_calibration_bench(
        seeds=args.seeds,
        views=args.views,
        trials=args.trials,
        quick=args.quick,
        out_dir=args.out,
        handeye_source=args.handeye_source,
        handeye_poses=args.handeye_poses,
        rig_path=args.rig,
        seed=args.seed,
        progress=not args.no_progress,
    )
    return emit(args, r, summary_lines(r))


def summary_lines(r: dict[str, Any]) -> list[str]:
    """Intrinsics, the headline hand-eye figures (and the synthetic ones beside sim), eye-in-hand, the sweep."""
    lines = [
        f"intrinsics ({r['intrinsics_seeds']} seeds x {r['intrinsics_views']} views, {r['intrinsics_noise_px']} px): "
        f"|Δf|/f {r['intrinsics_focal_rel_err_percent']:.3f} %, principal point {r['intrinsics_pp_err_px']:.2f} px, "
        f"RMS {r['intrinsics_rms_px']:.3f} px (max {r['intrinsics_rms_px_max']:.3f}), 95 % intervals cover "
        f">= {r['intrinsics_ci95_coverage']:.0%} of seeds",
        f"hand-eye ({r['handeye_source']}): {r['handeye_trans_err_mm']:.3g} mm, {r['handeye_rot_err_deg']:.3g}°, "
        f"gripper reprojection {r['gripper_reproj_err_px']:.3g} px",
    ]
    syn = r["handeye_synthetic"]
    if r["handeye_source"] != "synthetic":
        lines.append(
            f"hand-eye (synthetic, {syn['pixel_noise_px']} px noise, {syn['poses']} poses): "
            f"{syn['handeye_trans_err_mm']:.3g} mm, {syn['handeye_rot_err_deg']:.3g}°"
        )
    if "wrist" in r:
        for cam, w in r["wrist"]["cameras"].items():
            lines.append(
                f"eye-in-hand {cam} ({r['wrist_source']}): max {w['trans_err_mm_max']:.3g} mm, "
                f"{w['rot_err_deg_max']:.3g}° over the seeds (median {w['trans_err_mm_median']:.3g} mm, "
                f"{w['rot_err_deg_median']:.3g}°)"
            )
    settings = r["sweep_settings"]
    lines.append(f"sweep: {settings['trials']} trials per point, OpenCV {r['opencv_version']} (median mm / median deg)")
    for axis, per in r["sweep"].items():
        lines.append(f"  {axis}:")
        for method, stats in per.items():
            cells = [
                f"{s['value']:g}: "
                + (
                    "refused"
                    if s["trans_mm_median"] is None
                    else f"{s['trans_mm_median']:.2f}/{s['rot_deg_median']:.2f}"
                )
                for s in stats
            ]
            lines.append(f"    {method:<18} " + "  ".join(cells))
    lines.append(f"chart: {r['chart']}")
    return lines
