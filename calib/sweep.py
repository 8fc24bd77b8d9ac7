"""Stability sweep of the eye-to-hand solvers on synthetic data: where does each method fail?

Pure geometry, no rendering (a few ms per trial). The scene is the simulated rig's head camera
(:data:`HEAD_CAMERA`: 1024x1024, 46° vertical field of view, mild distortion, ~1 m above the table looking
down) and the A4 ChArUco board (7x5, 24 corners) rigidly held by a gripper with a known
``T_gripper_board``. One trial:

1. **Poses.** The board centre is placed at ``depth_m`` along the optical axis (±``offset_m`` at random in
   each direction), frontal to the camera, then tilted about its centre by a rotation vector of length at
   most ``span/2``: the first two poses by ``±span/2`` about one random axis (so the gripper orientations
   differ by exactly ``span``), the others by ``U(0.3, 1) · span/2`` about random axes. No two
   orientations then differ by more than ``span`` (the triangle inequality on SO(3)). Poses whose board
   leaves the image are drawn again. The true gripper pose follows from the model
   ``T_cam_board = T_cam_base · T_base_gripper · T_gripper_board``.
2. **Detections.** The 24 corners are projected through the true camera and given i.i.d. Gaussian noise
   of ``pixel_noise_px`` per coordinate; ``T_cam_board`` is measured by ``solvePnP`` (IPPE, then LM) with
   the true intrinsics, as the calibration tool does after an intrinsics calibration.
3. **FK noise.** The gripper poses handed to the solvers are perturbed in the gripper frame by a rotation
   of ``N(0, σ)`` degrees about each axis and a translation of ``N(0, σ_rad · fk_lever_m)`` per axis, i.e. the
   displacement a joint error of ``σ`` causes at ``fk_lever_m`` (0.5 m: a UR5e's forearm) from the joint.
4. **Methods.** ``park_martin`` (AX = XB) and ``shah`` (AX = ZB) :mod:`calib.handeye_solve` (with its
   motion check: degenerate motion raises :class:`~calib.handeye.DegenerateMotionError`), ``refined``
   (Shah, then the Huber LM of :mod:`calib.handeye_refine` on the noisy pixels) and, when the installed
   cv2 has them, ``opencv_<name>`` for OpenCV's TSAI, PARK, HORAUD, ANDREFF, DANIILIDIS (``calibrateHandEye``)
   and SHAH, LI (``calibrateRobotWorldHandEye``). OpenCV's methods run *without* our motion check, to
   show what they return on poor motion (TSAI returns the identity without raising, shared/REFERENCES.md).

A method that raises (our degeneracy check, a cv2 error) or returns a non-finite pose is counted as
**refused** -- the right answer to motion that cannot determine the transform -- separately from trials
whose answer is wrong by more than the issue's acceptance bounds (2 mm, 0.2°), counted as ``exceeds``.

Each sweep axis (pixel noise, FK noise, number of poses, rotation span) is varied with the others at
their defaults; every method sees the same trials (same seeds), so the methods are compared pairwise.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Final

import cv2
import numpy as np
import numpy.typing as npt

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.handeye_opencv import opencv_eye_to_hand
from calib.handeye_refine import refine_eye_to_hand
from calib.handeye_solve import solve_eye_to_hand
from calib.rotations import pose_difference, rigid, rotation_exp
from pilworld.geometry import invert_transform

__all__ = [
    "AXES",
    "DEFAULT_VALUES",
    "HEAD_CAMERA",
    "IN_HAND_DEFAULTS",
    "IN_HAND_METHODS",
    "IN_HAND_VALUES",
    "SWEEP_BOARD",
    "THRESHOLD_DEG",
    "THRESHOLD_MM",
    "T_BASE_BOARD",
    "T_TCP_CAM",
    "WRIST_CAMERA",
    "EyeInHandTrial",
    "HandEyeTrial",
    "MethodStats",
    "SweepConditions",
    "SweepResult",
    "TrialOutcome",
    "available_methods",
    "count_points",
    "make_in_hand_trial",
    "make_trial",
    "opencv_methods_available",
    "run_in_hand_sweep",
    "run_sweep",
    "solve_in_hand_trial",
    "solve_trial",
    "sweep_points",
]

FloatArray = npt.NDArray[np.float64]

#: The issue's hand-eye acceptance bounds on ``T_cam_base``.
THRESHOLD_MM: Final = 2.0
THRESHOLD_DEG: Final = 0.2

#: The simulated rig's head camera (configs/rig/sim_dual_ur5e.yaml: eye, target, 46° fovy) at 1024x1024,
#: with mild barrel distortion. Its ``T_cam_base`` is the ground truth of every trial.
HEAD_CAMERA: Final = replace(
    CameraModel.look_at(eye=[-0.12, 0.0, 1.0], target=[0.04, 0.0, 0.0], up=[0.0, 0.0, 1.0], fovy_deg=46.0,
                        width=1024, height=1024),
    dist=np.array([-0.05, 0.02, 0.0003, -0.0002, 0.0]),
)  # fmt: skip
#: The A4 board of configs/board/charuco_7x5_a4.yaml (built here: the package does not read configs/).
SWEEP_BOARD: Final = ChArUcoBoard(7, 5, 0.035, 0.026, "DICT_5X5_100", name="charuco_7x5_a4")
#: Board frame → gripper frame: the board held 12 cm off the gripper axis, slightly turned.
T_GRIPPER_BOARD: Final = rigid(rotation_exp([0.1, -0.2, 0.3]), [-0.12, -0.08, 0.05])

#: Sweep axes: name → (field of :class:`SweepConditions`, unit).
AXES: Final = {
    "pixel_noise": ("pixel_noise_px", "px"),
    "fk_noise": ("fk_noise_deg", "deg"),
    "poses": ("poses", "count"),
    "rotation_span": ("rotation_span_deg", "deg"),
}
_OURS: Final = ("park_martin", "shah", "refined")
_OPENCV: Final = ("TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS", "SHAH", "LI")


@dataclass(frozen=True)
class SweepConditions:
    """One point of the sweep; validated on construction (``ValueError`` naming the field)."""

    pixel_noise_px: float = 0.3  #: σ of the corner noise per coordinate, pixels
    #: σ of the FK rotation error per axis, degrees (translation: see fk_lever_m). 0.02° ≈ 0.17 mm per axis:
    #: a kinematically calibrated UR-class arm.
    fk_noise_deg: float = 0.02
    poses: int = 10  #: gripper poses per calibration
    rotation_span_deg: float = 40.0  #: largest rotation between two gripper orientations, degrees
    fk_lever_m: float = 0.5  #: FK translation σ = σ_rad · this, metres per radian
    depth_m: float = 0.75  #: board centre distance along the optical axis, metres
    offset_m: float = 0.12  #: board centre offset range (±) along each camera axis, metres

    def __post_init__(self) -> None:
        for name in ("pixel_noise_px", "fk_noise_deg", "rotation_span_deg", "fk_lever_m", "offset_m"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name}: expected a finite number >= 0, got {value!r}")
        if not self.rotation_span_deg <= 120.0:
            raise ValueError(
                f"rotation_span_deg: at most 120° (the board must stay visible), got {self.rotation_span_deg}"
            )
        if isinstance(self.poses, bool) or not isinstance(self.poses, int) or not 2 <= self.poses <= 200:
            raise ValueError(f"poses: expected an integer in 2..200, got {self.poses!r}")
        if not (math.isfinite(self.depth_m) and 0.2 <= self.depth_m <= 5.0):
            raise ValueError(f"depth_m: expected metres in [0.2, 5], got {self.depth_m!r}")


@dataclass(frozen=True, eq=False)
class HandEyeTrial:
    """One synthetic calibration: what the solvers get and the truth they should return."""

    T_base_gripper: FloatArray  #: ``(N, 4, 4)`` FK poses handed to the solvers (with FK noise)
    T_base_gripper_true: FloatArray  #: ``(N, 4, 4)`` the exact gripper poses
    T_cam_board: FloatArray  #: ``(N, 4, 4)`` solvePnP board poses from the noisy corners
    board_points: FloatArray  #: ``(n, 3)`` board-frame corners, metres (all visible in every pose)
    image_points: FloatArray  #: ``(N, n, 2)`` noisy detected pixels
    camera: CameraModel  #: the true camera; ``camera.T_cam_base`` is the answer
    T_gripper_board: FloatArray  #: ``(4, 4)`` the true board mount


def _pnp(P: FloatArray, uv: FloatArray, camera: CameraModel) -> FloatArray:
    ok, rvec, tvec = cv2.solvePnP(P, uv, camera.K, camera.dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:  # pragma: no cover - IPPE always succeeds on >= 4 coplanar points
        raise ValueError("solvePnP failed on a synthetic view")
    rvec, tvec = cv2.solvePnPRefineLM(P, uv, camera.K, camera.dist, rvec, tvec)
    return rigid(cv2.Rodrigues(rvec)[0], tvec)


def _unit(rng: np.random.Generator) -> FloatArray:
    v = rng.normal(size=3)
    out: FloatArray = v / np.linalg.norm(v)
    return out


def make_trial(
    conditions: SweepConditions,
    seed: int,
    camera: CameraModel = HEAD_CAMERA,
    board: ChArUcoBoard = SWEEP_BOARD,
    T_gripper_board: FloatArray = T_GRIPPER_BOARD,
) -> HandEyeTrial:
    """The synthetic calibration of trial ``seed`` under ``conditions`` (see the module docstring)."""
    rng = np.random.default_rng(seed)
    P = board.corner_points()
    w_m, h_m = board.size_m
    centre_b = np.array([w_m / 2.0, h_m / 2.0, 0.0])
    half = math.radians(conditions.rotation_span_deg) / 2.0
    first_axis = _unit(rng)
    T_base_cam = invert_transform(camera.T_cam_base)
    T_board_gripper = invert_transform(T_gripper_board)
    G_true, C, imgs = [], [], []
    for i in range(conditions.poses):
        for _ in range(1000):
            # Poses 0 and 1 at ±span/2 about one axis: the span is reached exactly.
            w = (1.0 - 2.0 * i) * half * first_axis if i < 2 else rng.uniform(0.3, 1.0) * half * _unit(rng)
            R = rotation_exp(w)  # frontal (board axes = camera axes) tilted about the board centre
            centre_c = np.array([0.0, 0.0, conditions.depth_m]) + rng.uniform(-1.0, 1.0, 3) * conditions.offset_m
            T_cam_board = rigid(R, centre_c - R @ centre_b)
            proj = camera.with_pose(T_cam_board).project_detailed(P)
            margin = 4.0
            uv = proj.uv
            if (
                proj.visible.all()
                and (uv >= margin).all()
                and (uv[:, 0] <= camera.width - 1 - margin).all()
                and (uv[:, 1] <= camera.height - 1 - margin).all()
            ):
                break
        else:  # pragma: no cover - the defaults always fit
            raise ValueError(f"make_trial: the board does not fit the image at depth {conditions.depth_m} m")
        noisy = uv + rng.normal(0.0, conditions.pixel_noise_px, uv.shape)
        G_true.append(T_base_cam @ T_cam_board @ T_board_gripper)
        C.append(_pnp(P, noisy, camera))
        imgs.append(noisy)
    sigma = math.radians(conditions.fk_noise_deg)
    G_meas = [
        g @ rigid(rotation_exp(rng.normal(0.0, sigma, 3)), rng.normal(0.0, sigma * conditions.fk_lever_m, 3))
        for g in G_true
    ]
    return HandEyeTrial(
        T_base_gripper=np.asarray(G_meas),
        T_base_gripper_true=np.asarray(G_true),
        T_cam_board=np.asarray(C),
        board_points=P,
        image_points=np.asarray(imgs),
        camera=camera,
        T_gripper_board=np.asarray(T_gripper_board, dtype=np.float64),
    )


@contextmanager
def _quiet_opencv() -> Iterator[None]:
    log = getattr(getattr(cv2, "utils", None), "logging", None)
    if log is None:  # pragma: no cover - every 4.x/5.x wheel has cv2.utils.logging
        yield
        return
    level = log.getLogLevel()
    log.setLogLevel(log.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        log.setLogLevel(level)


def opencv_methods_available() -> list[str]:
    """OpenCV hand-eye methods the installed cv2 exposes to Python (none on the 5.0 wheels)."""
    names: list[str] = []
    if hasattr(cv2, "calibrateHandEye"):
        names += _OPENCV[:5]
    if hasattr(cv2, "calibrateRobotWorldHandEye"):
        names += _OPENCV[5:]
    return names


def available_methods() -> list[str]:
    """Method names of the sweep: ours, then ``opencv_<name>`` for every OpenCV method present."""
    return [*_OURS, *(f"opencv_{n.lower()}" for n in opencv_methods_available())]


@dataclass(frozen=True)
class TrialOutcome:
    """One method on one trial: the error of its ``T_cam_base`` or why it refused."""

    method: str
    trans_mm: float  #: NaN if refused
    rot_deg: float  #: NaN if refused
    refused: str | None  #: the exception's type and message, None if the method returned a pose
    seconds: float


def solve_trial(trial: HandEyeTrial, methods: Sequence[str] | None = None) -> dict[str, TrialOutcome]:
    """Run every method (default :func:`available_methods`) on ``trial``; errors against the true pose."""
    wanted = list(methods) if methods is not None else available_methods()
    unknown = [m for m in wanted if m not in available_methods()]
    if unknown:
        raise ValueError(f"methods: unknown or unavailable {unknown}; available: {', '.join(available_methods())}")
    truth = trial.camera.T_cam_base
    out: dict[str, TrialOutcome] = {}

    def record(name: str, fn: Callable[[], FloatArray]) -> None:
        t0 = time.perf_counter()
        try:
            T = fn()
        except (ValueError, cv2.error, np.linalg.LinAlgError) as exc:  # DegenerateMotionError is a ValueError
            out[name] = TrialOutcome(name, math.nan, math.nan, f"{type(exc).__name__}: {exc}", time.perf_counter() - t0)
            return
        if not np.all(np.isfinite(T)):
            out[name] = TrialOutcome(name, math.nan, math.nan, "non-finite result", time.perf_counter() - t0)
            return
        dt, dr = pose_difference(T, truth)
        out[name] = TrialOutcome(name, 1e3 * dt, dr, None, time.perf_counter() - t0)

    G, C = trial.T_base_gripper, trial.T_cam_board
    if "park_martin" in wanted:
        record("park_martin", lambda: solve_eye_to_hand(G, C, method="park").T_cam_base)
    shah_cache: list[Any] = []

    def shah() -> FloatArray:
        shah_cache.append(solve_eye_to_hand(G, C, method="shah"))
        T: FloatArray = shah_cache[-1].T_cam_base
        return T

    if "shah" in wanted or "refined" in wanted:
        record("shah", shah)

    def refined() -> FloatArray:
        start = shah_cache[-1] if shah_cache else solve_eye_to_hand(G, C, method="shah")
        n = trial.image_points.shape[0]
        result = refine_eye_to_hand(
            start.T_cam_base,
            start.T_gripper_board,
            G,
            [trial.board_points] * n,
            list(trial.image_points),
            trial.camera.K,
            trial.camera.dist,
        )
        T: FloatArray = result.T_cam_base
        return T

    if "refined" in wanted:
        record("refined", refined)
    if "shah" not in wanted:
        out.pop("shah", None)
    cv_wanted = [m for m in wanted if m.startswith("opencv_")]
    if cv_wanted:
        t0 = time.perf_counter()
        try:
            with _quiet_opencv():  # TSAI logs "not enough informative motions" to stderr, then returns I
                estimates = opencv_eye_to_hand(G, C)
            error: str | None = None
        except (ValueError, cv2.error) as exc:  # pragma: no cover - opencv_eye_to_hand catches cv2 errors
            estimates, error = {}, f"{type(exc).__name__}: {exc}"
        each = (time.perf_counter() - t0) / len(opencv_methods_available())
        for name in cv_wanted:
            est = estimates.get(name.removeprefix("opencv_").upper())
            if est is None:
                out[name] = TrialOutcome(name, math.nan, math.nan, error or "cv2 raised or returned non-finite", each)
            else:
                dt, dr = pose_difference(est.T_cam_base, truth)
                out[name] = TrialOutcome(name, 1e3 * dt, dr, None, each)
    return {m: out[m] for m in wanted}


@dataclass(frozen=True)
class MethodStats:
    """One method at one value of one sweep axis, over ``trials`` seeds."""

    value: float  #: the axis value (pixels, degrees or a pose count)
    trials: int
    refused: int  #: trials where the method raised or returned a non-finite pose
    exceeds: int  #: accepted trials with an error above THRESHOLD_MM or THRESHOLD_DEG
    #: median and 90th percentile over the accepted trials; None if every trial was refused
    trans_mm_median: float | None
    trans_mm_p90: float | None
    rot_deg_median: float | None
    rot_deg_p90: float | None
    refusal: str | None = None  #: the first refusal message, shortened (None if none)


def _stats(value: float, outcomes: Sequence[TrialOutcome]) -> MethodStats:
    ok = [o for o in outcomes if o.refused is None]
    refusals = [o.refused for o in outcomes if o.refused is not None]
    t = np.array([o.trans_mm for o in ok])
    r = np.array([o.rot_deg for o in ok])

    def q(a: FloatArray, p: float) -> float | None:
        return float(np.percentile(a, p)) if a.size else None

    return MethodStats(
        value=float(value),
        trials=len(outcomes),
        refused=len(refusals),
        exceeds=int(np.sum((t > THRESHOLD_MM) | (r > THRESHOLD_DEG))),
        trans_mm_median=q(t, 50),
        trans_mm_p90=q(t, 90),
        rot_deg_median=q(r, 50),
        rot_deg_p90=q(r, 90),
        refusal=refusals[0][:160] if refusals else None,
    )


#: Default axis values (the issue's sweep). Spans 2° (refused by our check: <= 5°) and 6° (just accepted).
DEFAULT_VALUES: Final[dict[str, tuple[float, ...]]] = {
    "pixel_noise": (0.0, 0.1, 0.3, 0.5, 1.0, 2.0),
    "fk_noise": (0.0, 0.02, 0.05, 0.1, 0.2, 0.5),
    "poses": (3, 4, 6, 10, 15, 25),
    "rotation_span": (2.0, 6.0, 10.0, 20.0, 40.0, 80.0),
}


@dataclass(frozen=True, eq=False)
class SweepResult:
    """The whole sweep: ``axes[axis][method]`` is a list of :class:`MethodStats`, one per axis value."""

    defaults: SweepConditions
    trials: int
    seed: int
    methods: tuple[str, ...]
    opencv_version: str
    opencv_methods_available: tuple[str, ...]
    axes: dict[str, dict[str, list[MethodStats]]]
    seconds: float
    method_ms_median: dict[str, float] = field(default_factory=dict)  #: median solve time per trial

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN-free: missing figures are None)."""
        return {
            "defaults": asdict(self.defaults),
            "trials": self.trials,
            "seed": self.seed,
            "methods": list(self.methods),
            "opencv_version": self.opencv_version,
            "opencv_methods_available": list(self.opencv_methods_available),
            "thresholds": {"trans_mm": THRESHOLD_MM, "rot_deg": THRESHOLD_DEG},
            "units": {axis: unit for axis, (_, unit) in AXES.items()},
            "axes": {
                axis: {m: [asdict(s) for s in stats] for m, stats in per.items()} for axis, per in self.axes.items()
            },
            "method_ms_median": self.method_ms_median,
            "seconds": self.seconds,
        }


def sweep_points(
    defaults: SweepConditions, values: Mapping[str, Sequence[float]] | None = None
) -> Iterator[tuple[str, float, SweepConditions]]:
    """``(axis, value, conditions)`` for every point of the sweep, the other axes at ``defaults``."""
    for axis, vals in (values if values is not None else DEFAULT_VALUES).items():
        if axis not in AXES:
            raise ValueError(f"sweep axis: unknown {axis!r}; choose from {', '.join(AXES)}")
        name = AXES[axis][0]
        for v in vals:
            yield axis, float(v), _with_value(defaults, name, v)


def _with_value(c: SweepConditions, name: str, v: float) -> SweepConditions:
    if name == "poses":
        return replace(c, poses=int(v))
    if name == "pixel_noise_px":
        return replace(c, pixel_noise_px=float(v))
    if name == "fk_noise_deg":
        return replace(c, fk_noise_deg=float(v))
    return replace(c, rotation_span_deg=float(v))


def run_sweep(
    trials: int = 20,
    *,
    defaults: SweepConditions | None = None,
    values: Mapping[str, Sequence[float]] | None = None,
    methods: Sequence[str] | None = None,
    seed: int = 0,
    progress: Callable[[int], object] | None = None,
) -> SweepResult:
    """The stability sweep (see the module docstring): ``trials`` seeds per axis value, every method.

    Trial ``k`` of every point uses seed ``seed + k``: the same board poses and noise draws wherever the
    conditions allow, so neighbouring values and the methods are compared on equal footing.
    ``progress(n)`` is called after every ``n`` finished trials (for a progress bar).
    """
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 1:
        raise ValueError(f"trials: expected an integer >= 1, got {trials!r}")
    base = defaults if defaults is not None else SweepConditions()
    names = list(methods) if methods is not None else available_methods()
    t_start = time.perf_counter()
    axes: dict[str, dict[str, list[MethodStats]]] = {}
    times: dict[str, list[float]] = {m: [] for m in names}
    for axis, value, cond in sweep_points(base, values):
        per_method: dict[str, list[TrialOutcome]] = {m: [] for m in names}
        for k in range(trials):
            for m, outcome in solve_trial(make_trial(cond, seed + k), names).items():
                per_method[m].append(outcome)
                times[m].append(outcome.seconds)
            if progress is not None:
                progress(1)
        for m in names:
            axes.setdefault(axis, {}).setdefault(m, []).append(_stats(value, per_method[m]))
    return SweepResult(
        defaults=base,
        trials=trials,
        seed=seed,
        methods=tuple(names),
        opencv_version=cv2.__version__,
        opencv_methods_available=tuple(opencv_methods_available()),
        axes=axes,
        seconds=time.perf_counter() - t_start,
        method_ms_median={m: 1e3 * float(np.median(t)) for m, t in times.items() if t},
    )


def count_points(values: Mapping[str, Sequence[float]] | None = None) -> int:
    """Number of sweep points (axis values) in ``values`` (default :data:`DEFAULT_VALUES`)."""
    return sum(len(v) for v in (values if values is not None else DEFAULT_VALUES).values())


# ---------------------------------------------------------------------- eye-in-hand (wrist cameras)

#: A wrist camera like the simulated rig's (80° vertical field of view) at 1024x1024, mild distortion.
WRIST_CAMERA: Final = CameraModel(
    K=np.array([[610.2, 0.0, 511.5], [0.0, 610.2, 511.5], [0.0, 0.0, 1.0]]),
    dist=np.array([-0.04, 0.015, 0.0002, -0.0001, 0.0]),
    T_cam_base=np.eye(4),
    width=1024,
    height=1024,
    name="wrist",
)
#: Camera frame → TCP frame: the simulated rig's wrist mount (beside the palm, tilted towards the fingers).
T_TCP_CAM: Final = rigid(rotation_exp([0.0, 0.0, math.pi / 2]) @ rotation_exp([-0.35, 0.0, 0.0]), [0.075, 0.0, -0.08])
#: Board frame → base frame: the board flat on the table (board z, into the board, points down).
T_BASE_BOARD: Final = rigid(np.diag([1.0, -1.0, -1.0]), [0.35, 0.15, 0.0])
#: Defaults of the eye-in-hand sweep: the camera 0.38 m from the board centre, ±5 cm offsets.
IN_HAND_DEFAULTS: Final = SweepConditions(depth_m=0.38, offset_m=0.05)
#: The eye-in-hand sweep: a few values per axis (spans 2° and 6°: refused and just accepted).
IN_HAND_VALUES: Final[dict[str, tuple[float, ...]]] = {
    "pixel_noise": (0.0, 0.3, 1.0),
    "fk_noise": (0.0, 0.02, 0.05),
    "poses": (3, 10, 20),
    "rotation_span": (2.0, 6.0, 40.0),
}
IN_HAND_METHODS: Final = ("park_martin", "shah", "refined")


@dataclass(frozen=True, eq=False)
class EyeInHandTrial:
    """One synthetic wrist-camera calibration: what the solvers get and the truth they should return."""

    T_base_tcp: FloatArray  #: ``(N, 4, 4)`` FK poses handed to the solvers (with FK noise)
    T_base_tcp_true: FloatArray  #: ``(N, 4, 4)`` the exact TCP poses
    T_cam_board: FloatArray  #: ``(N, 4, 4)`` solvePnP board poses from the noisy corners
    board_points: FloatArray  #: ``(n, 3)`` board-frame corners, metres
    image_points: FloatArray  #: ``(N, n, 2)`` noisy detected pixels
    camera: CameraModel  #: the true intrinsics (its ``T_cam_base`` is unused)
    T_tcp_cam: FloatArray  #: the answer
    T_base_board: FloatArray  #: where the board lies


def make_in_hand_trial(
    conditions: SweepConditions,
    seed: int,
    camera: CameraModel = WRIST_CAMERA,
    board: ChArUcoBoard = SWEEP_BOARD,
    T_tcp_cam: FloatArray = T_TCP_CAM,
    T_base_board: FloatArray = T_BASE_BOARD,
) -> EyeInHandTrial:
    """Trial ``seed``: the camera looks at the fixed board from ``depth_m``, tilted like :func:`make_trial`'s board.

    The camera starts frontal above the board centre (camera axes = board axes), offset by up to
    ``offset_m`` per axis, and is tilted about the board centre by rotation vectors of at most ``span/2``
    (the first two ``±span/2`` about one axis). FK noise is applied to the TCP poses as in :func:`make_trial`.
    """
    rng = np.random.default_rng(seed)
    P = board.corner_points()
    w_m, h_m = board.size_m
    centre_b = np.array([w_m / 2.0, h_m / 2.0, 0.0])
    half = math.radians(conditions.rotation_span_deg) / 2.0
    first_axis = _unit(rng)
    T_cam_tcp = invert_transform(T_tcp_cam)
    G_true, C, imgs = [], [], []
    for i in range(conditions.poses):
        for _ in range(1000):
            w = (1.0 - 2.0 * i) * half * first_axis if i < 2 else rng.uniform(0.3, 1.0) * half * _unit(rng)
            R = rotation_exp(w)
            centre_c = np.array([0.0, 0.0, conditions.depth_m]) + rng.uniform(-1.0, 1.0, 3) * conditions.offset_m
            T_cam_board = rigid(R, centre_c - R @ centre_b)
            proj = camera.with_pose(T_cam_board).project_detailed(P)
            uv, margin = proj.uv, 4.0
            if (
                proj.visible.all()
                and (uv >= margin).all()
                and (uv[:, 0] <= camera.width - 1 - margin).all()
                and (uv[:, 1] <= camera.height - 1 - margin).all()
            ):
                break
        else:  # pragma: no cover - the defaults always fit
            raise ValueError(f"make_in_hand_trial: the board does not fit the image at depth {conditions.depth_m} m")
        noisy = uv + rng.normal(0.0, conditions.pixel_noise_px, uv.shape)
        # T_base_tcp · T_tcp_cam · T_cam_board = T_base_board
        G_true.append(T_base_board @ invert_transform(T_cam_board) @ T_cam_tcp)
        C.append(_pnp(P, noisy, camera))
        imgs.append(noisy)
    sigma = math.radians(conditions.fk_noise_deg)
    G_meas = [
        g @ rigid(rotation_exp(rng.normal(0.0, sigma, 3)), rng.normal(0.0, sigma * conditions.fk_lever_m, 3))
        for g in G_true
    ]
    return EyeInHandTrial(
        T_base_tcp=np.asarray(G_meas),
        T_base_tcp_true=np.asarray(G_true),
        T_cam_board=np.asarray(C),
        board_points=P,
        image_points=np.asarray(imgs),
        camera=camera,
        T_tcp_cam=np.asarray(T_tcp_cam, dtype=np.float64),
        T_base_board=np.asarray(T_base_board, dtype=np.float64),
    )


def solve_in_hand_trial(trial: EyeInHandTrial, methods: Sequence[str] = IN_HAND_METHODS) -> dict[str, TrialOutcome]:
    """Run the eye-in-hand methods on ``trial``; errors of ``T_tcp_cam`` against the truth."""
    from calib.handeye_refine import refine_eye_in_hand
    from calib.handeye_solve import solve_eye_in_hand

    unknown = [m for m in methods if m not in IN_HAND_METHODS]
    if unknown:
        raise ValueError(f"methods: unknown {unknown}; available: {', '.join(IN_HAND_METHODS)}")
    G, C = trial.T_base_tcp, trial.T_cam_board
    out: dict[str, TrialOutcome] = {}
    shah_cache: list[Any] = []

    def record(name: str, fn: Callable[[], FloatArray]) -> None:
        t0 = time.perf_counter()
        try:
            T = fn()
        except (ValueError, np.linalg.LinAlgError) as exc:
            out[name] = TrialOutcome(name, math.nan, math.nan, f"{type(exc).__name__}: {exc}", time.perf_counter() - t0)
            return
        dt, dr = pose_difference(T, trial.T_tcp_cam)
        out[name] = TrialOutcome(name, 1e3 * dt, dr, None, time.perf_counter() - t0)

    def shah() -> FloatArray:
        shah_cache.append(solve_eye_in_hand(G, C, method="shah"))
        T: FloatArray = shah_cache[-1].T_tcp_cam
        return T

    def refined() -> FloatArray:
        start = shah_cache[-1] if shah_cache else solve_eye_in_hand(G, C, method="shah")
        n = trial.image_points.shape[0]
        result = refine_eye_in_hand(
            start.T_tcp_cam,
            start.T_base_board,
            G,
            [trial.board_points] * n,
            list(trial.image_points),
            trial.camera.K,
            trial.camera.dist,
        )
        T: FloatArray = result.T_tcp_cam
        return T

    if "park_martin" in methods:
        record("park_martin", lambda: solve_eye_in_hand(G, C, method="park").T_tcp_cam)
    if "shah" in methods or "refined" in methods:
        record("shah", shah)
    if "refined" in methods:
        record("refined", refined)
    return {m: out[m] for m in methods}


def run_in_hand_sweep(
    trials: int = 10,
    *,
    defaults: SweepConditions = IN_HAND_DEFAULTS,
    values: Mapping[str, Sequence[float]] | None = None,
    methods: Sequence[str] = IN_HAND_METHODS,
    seed: int = 0,
    progress: Callable[[int], object] | None = None,
) -> SweepResult:
    """The eye-in-hand stability sweep: error of ``T_tcp_cam`` per method against noise, poses and span.

    Same protocol as :func:`run_sweep` (each axis varied with the others at ``defaults``, trial ``k`` seeded
    ``seed + k``, refusals counted apart), on :func:`make_in_hand_trial` scenes, without OpenCV's methods.
    """
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 1:
        raise ValueError(f"trials: expected an integer >= 1, got {trials!r}")
    t_start = time.perf_counter()
    axes: dict[str, dict[str, list[MethodStats]]] = {}
    times: dict[str, list[float]] = {m: [] for m in methods}
    for axis, value, cond in sweep_points(defaults, values if values is not None else IN_HAND_VALUES):
        per_method: dict[str, list[TrialOutcome]] = {m: [] for m in methods}
        for k in range(trials):
            for m, outcome in solve_in_hand_trial(make_in_hand_trial(cond, seed + k), methods).items():
                per_method[m].append(outcome)
                times[m].append(outcome.seconds)
            if progress is not None:
                progress(1)
        for m in methods:
            axes.setdefault(axis, {}).setdefault(m, []).append(_stats(value, per_method[m]))
    return SweepResult(
        defaults=defaults,
        trials=trials,
        seed=seed,
        methods=tuple(methods),
        opencv_version=cv2.__version__,
        opencv_methods_available=(),
        axes=axes,
        seconds=time.perf_counter() - t_start,
        method_ms_median={m: 1e3 * float(np.median(t)) for m, t in times.items() if t},
    )
