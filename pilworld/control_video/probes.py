"""Stability probes of Γ⁺: the render built from a slightly wrong rig, and how far it moves.

A world model conditioned on Γ⁺ sees the robot where the rig's calibration and robot model put it. On a
real rig both are wrong by a little: the head camera's extrinsics by millimetres and a fraction of a
degree, each wrist camera's mount (``T_cam_tcp``) likewise, the link radii and colours of the model by
up to ±20 %. The stability bench renders with such errors and measures where methods break; this module
builds the wrong rigs and measures how much the render itself moves:

* :func:`perturb_transform` — a rigid error of exactly the given size, in a random direction;
* :func:`perturbed_cameras` — the rig's cameras with head extrinsics and wrist mount errors;
* :func:`mismatched_robot` — the robot model with scaled link radii and other colours;
* :func:`perturbed_gamma_plus` — Γ⁺ built from both (the head error moves render and markers together);
* :func:`shifted_principal_point` — a camera whose principal point is off by some pixels (an intrinsics error);
* :func:`perturbed_rig` — the rig config as a wrong calibration describes it (its calibration files
  rewritten with the errors), for whatever reads the rig's geometry (world model v2 binds it);
* :func:`render_sensitivity` — per perturbation, the IoU of the perturbed robot mask against the nominal
  one in every view and the pixel shift of the TCPs in the head view (a JSON-able summary).

Perturbations are named by keyword (``head_translation_m``, ``head_rotation_deg``,
``wrist_translation_m``, ``wrist_rotation_deg``, ``radius_scale``, ``rgba``, ``seed``); all zero (scale
one, no colour) reproduces the nominal render bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from calib.camera_model import CameraModel
from pilworld.config.rig import RigConfig
from pilworld.control_video.cameras import RigCameras, ViewCamera
from pilworld.control_video.gamma_plus import GammaPlus
from pilworld.control_video.robot_model import RobotModel
from pilworld.control_video.robot_render import Backend, make_robot_renderer
from pilworld.control_video.style import ControlVideoStyle
from pilworld.control_video.styles import Style
from pilworld.geometry import invert_transform, is_rigid_transform, matrix_to_pose
from pilworld.types import HEAD_VIEW, STATE_DIM, ChunkSpec

F64 = NDArray[np.float64]
RADIUS_SCALE_RANGE = (0.5, 2.0)  # link radii off by more than a factor of two is not a calibration error


def _size(value: object, name: str, upper: float = math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise ValueError(f"{name}: expected a number, got {value!r}")
    x = float(value)
    if not math.isfinite(x) or x < 0 or x > upper:
        allowed = "a finite number >= 0" if upper == math.inf else f"a number in [0, {upper:g}]"
        raise ValueError(f"{name}: expected {allowed}, got {value!r}")
    return x


def _unit(rng: np.random.Generator) -> F64:
    while True:  # a Gaussian draw, normalised: uniform on the sphere
        v = rng.normal(size=3)
        n = float(np.linalg.norm(v))
        if n > 1e-9:
            out: F64 = v / n
            return out


def _rotation(axis: F64, angle: float) -> F64:
    """Rodrigues: the rotation by ``angle`` rad about the unit ``axis`` (exactly I for angle 0)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    out: F64 = np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)
    return out


def perturb_transform(
    T: NDArray[np.floating], translation_m: float, rotation_deg: float, rng: np.random.Generator
) -> F64:
    """``E · T``: ``T`` (4, 4) with a rigid error ``E`` of exactly the given size.

    ``E`` translates by ``translation_m`` along a random direction and rotates by ``rotation_deg`` about a
    random axis (both uniform on the sphere, drawn from ``rng`` whatever the sizes, so a seed gives the
    same direction at every size). For a camera's ``T_cam_x`` (x frame → camera) this moves the camera's
    centre in frame x by exactly ``translation_m`` and turns it by exactly ``rotation_deg`` about it.
    Zero sizes return ``T`` unchanged (a copy).
    """
    M = np.asarray(T, dtype=np.float64)
    if M.shape != (4, 4) or not is_rigid_transform(M):
        raise ValueError(f"T: expected a finite rigid transform (4, 4), got shape {M.shape}")
    t = _size(translation_m, "translation_m")
    a = _size(rotation_deg, "rotation_deg", 180.0)
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    direction, axis = _unit(rng), _unit(rng)
    if t == 0.0 and a == 0.0:
        return M.copy()
    E = np.eye(4)
    E[:3, :3] = _rotation(axis, math.radians(a))
    E[:3, 3] = t * direction
    out: F64 = E @ M
    return out


@dataclass(frozen=True)
class Perturbation:
    """One probe's errors (see the module docstring); :meth:`from_dict` validates a bench's dict."""

    head_translation_m: float = 0.0  # head camera centre moved by this much (rig frame)
    head_rotation_deg: float = 0.0  # head camera turned by this much about its centre
    wrist_translation_m: float = 0.0  # each wrist camera's mount moved by this much (TCP frame)
    wrist_rotation_deg: float = 0.0  # each wrist camera turned by this much on its mount
    radius_scale: float = 1.0  # round geoms' radii × this
    rgba: tuple[float, float, float, float] | None = None  # every robot geom's colour, or the model's
    seed: int = 0  # directions and axes of the camera errors

    def __post_init__(self) -> None:
        for name in ("head_translation_m", "wrist_translation_m"):
            object.__setattr__(self, name, _size(getattr(self, name), name))
        for name in ("head_rotation_deg", "wrist_rotation_deg"):
            object.__setattr__(self, name, _size(getattr(self, name), name, 180.0))
        s = self.radius_scale
        lo, hi = RADIUS_SCALE_RANGE
        if isinstance(s, bool) or not isinstance(s, int | float | np.floating | np.integer) or not lo <= s <= hi:
            raise ValueError(f"radius_scale: expected a factor in [{lo:g}, {hi:g}], got {s!r}")
        object.__setattr__(self, "radius_scale", float(s))
        if self.rgba is not None:
            c = np.asarray(self.rgba, dtype=np.float64) if _numeric(self.rgba) else None
            if c is None or c.shape != (4,) or not np.all(np.isfinite(c)) or np.any((c < 0) | (c > 1)):
                raise ValueError(f"rgba: expected four numbers in [0, 1], got {self.rgba!r}")
            object.__setattr__(self, "rgba", tuple(float(x) for x in c))
        if isinstance(self.seed, bool) or not isinstance(self.seed, int | np.integer) or self.seed < 0:
            raise ValueError(f"seed: expected an integer >= 0, got {self.seed!r}")
        object.__setattr__(self, "seed", int(self.seed))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Perturbation:
        if not isinstance(data, Mapping):
            raise ValueError(f"perturbation: expected a dict of {[f.name for f in fields(cls)]}, got {data!r}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(str(k) for k in data if k not in known)
        if unknown:
            raise ValueError(f"perturbation: unknown key(s) {unknown}; expected some of {sorted(known)}")
        return cls(**data)

    @property
    def moves_cameras(self) -> bool:
        return any(
            getattr(self, n) != 0.0
            for n in ("head_translation_m", "head_rotation_deg", "wrist_translation_m", "wrist_rotation_deg")
        )

    @property
    def changes_robot(self) -> bool:
        return self.radius_scale != 1.0 or self.rgba is not None

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["rgba"] = None if self.rgba is None else list(self.rgba)
        return out


def _numeric(value: object) -> bool:
    try:
        np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return True


def perturbed_cameras(
    rig: RigConfig,
    *,
    head_translation_m: float = 0.0,
    head_rotation_deg: float = 0.0,
    wrist_translation_m: float = 0.0,
    wrist_rotation_deg: float = 0.0,
    seed: int = 0,
) -> RigCameras:
    """``rig``'s cameras with a head extrinsics error (on ``T_cam_rig``) and a wrist mount error (on each
    wrist camera's ``T_cam_tcp``, its own direction per camera).

    View i's directions come from ``numpy.random.default_rng([seed, i])``: the head's draw does not
    depend on the wrist sizes, nor one wrist's on the other's.
    """
    p = Perturbation(
        head_translation_m=head_translation_m,
        head_rotation_deg=head_rotation_deg,
        wrist_translation_m=wrist_translation_m,
        wrist_rotation_deg=wrist_rotation_deg,
        seed=seed,
    )
    return _cameras(RigCameras.from_rig(rig), p)


def _cameras(base: RigCameras, p: Perturbation) -> RigCameras:
    if not p.moves_cameras:
        return base
    views = []
    for i, v in enumerate(base.views):
        rng = np.random.default_rng([p.seed, i])
        if v.moves:
            T = perturb_transform(v.model.T_cam_base, p.wrist_translation_m, p.wrist_rotation_deg, rng)
        else:
            T = perturb_transform(v.model.T_cam_base, p.head_translation_m, p.head_rotation_deg, rng)
        views.append(ViewCamera(v.name, v.model.with_pose(T), v.arm))
    return RigCameras(base.kinematics, tuple(views))


def shifted_principal_point(camera: CameraModel, shift_px: float) -> CameraModel:
    """``camera`` with its principal point moved ``shift_px`` pixels diagonally (``shift_px / √2`` along
    each image axis): every projection moves by ``shift_px`` pixels. Zero returns an equal camera."""
    d = _size(shift_px, "shift_px") / math.sqrt(2.0)
    K = np.array(camera.K, dtype=np.float64)
    K[0, 2] += d
    K[1, 2] += d
    return replace(camera, K=K)


def perturbed_rig(
    rig: RigConfig,
    folder: str | Path,
    *,
    principal_shift_px: float = 0.0,
    head_translation_m: float = 0.0,
    head_rotation_deg: float = 0.0,
    wrist_translation_m: float = 0.0,
    wrist_rotation_deg: float = 0.0,
    seed: int = 0,
) -> RigConfig:
    """``rig`` as a wrong calibration describes it: a rig config whose cameras carry the errors.

    The head camera (principal point moved ``principal_shift_px`` px diagonally, extrinsics as
    :func:`perturbed_cameras` moves them) is written to ``folder/cam_high.yaml`` as the calibration file
    a real rig's ``head_camera.file`` points to; a wrist camera with a mount error gets its
    ``pose_in_tcp`` moved by the same error (and its calibration file rewritten, if it has one). Whatever
    reads the rig's geometry — Γ, Γ⁺, world model v2's layers and tracked objects — then sees the same
    wrong cameras. Arms, robot model and image size are ``rig``'s (see :func:`mismatched_robot` for a
    wrong robot model). The head camera goes through the file even without an error, so all zeros
    reproduce ``rig``'s cameras bit for bit along the same path. ``folder`` must outlive the rig's use.
    """
    shift = _size(principal_shift_px, "principal_shift_px")
    cams = perturbed_cameras(
        rig,
        head_translation_m=head_translation_m,
        head_rotation_deg=head_rotation_deg,
        wrist_translation_m=wrist_translation_m,
        wrist_rotation_deg=wrist_rotation_deg,
        seed=seed,
    )
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    data = rig.model_dump()
    head_file = root / f"{HEAD_VIEW}.yaml"
    shifted_principal_point(cams.view(HEAD_VIEW).model, shift).to_yaml(head_file)
    data["head_camera"] = {"file": str(head_file)}
    for view in cams.views:
        if view.arm is None:
            continue
        nominal = rig.wrist_camera_model(view.name).T_cam_base  # T_cam_tcp
        if np.array_equal(view.model.T_cam_base, nominal):
            continue
        error = view.model.T_cam_base @ invert_transform(nominal)  # the mount error, on the camera side
        cfg = data["wrist_cameras"][view.name]
        mount = rig.wrist_cameras[view.name].pose_in_tcp.matrix()  # T_tcp_cam of the designed mount
        xyz, rpy = matrix_to_pose(invert_transform(error @ invert_transform(mount)))
        cfg["pose_in_tcp"] = {"xyz": tuple(float(x) for x in xyz), "rpy": tuple(float(x) for x in rpy)}
        if cfg.get("file") is not None:
            wrist_file = root / f"{view.name}.yaml"
            view.model.to_yaml(wrist_file)
            cfg["file"] = str(wrist_file)
    return RigConfig.model_validate(data)


def mismatched_robot(
    rig: RigConfig, *, radius_scale: float = 1.0, rgba: tuple[float, float, float, float] | None = None
) -> RobotModel:
    """``rig``'s robot model with its round links' radii × ``radius_scale`` (in [0.5, 2]) and, if given,
    every robot geom coloured ``rgba`` (four numbers in [0, 1]); part ids are unchanged."""
    p = Perturbation(radius_scale=radius_scale, rgba=rgba)
    return _robot(RobotModel.from_rig(rig), p)


def _robot(base: RobotModel, p: Perturbation) -> RobotModel:
    return base.scaled(p.radius_scale, p.rgba) if p.changes_robot else base


def perturbed_gamma_plus(
    rig: RigConfig,
    style: str | Style = "render",
    *,
    spec: ChunkSpec | None = None,
    backend: Backend = "analytic",
    marker_style: ControlVideoStyle | None = None,
    head_translation_m: float = 0.0,
    head_rotation_deg: float = 0.0,
    wrist_translation_m: float = 0.0,
    wrist_rotation_deg: float = 0.0,
    radius_scale: float = 1.0,
    rgba: tuple[float, float, float, float] | None = None,
    seed: int = 0,
) -> GammaPlus:
    """Γ⁺ of ``rig`` in ``style`` with the given errors (see :func:`perturbed_cameras`,
    :func:`mismatched_robot`). Γ's markers are drawn through the perturbed head camera too, so a head
    error moves render, markers and prior alike — as a wrong calibration would."""
    p = Perturbation(
        head_translation_m=head_translation_m,
        head_rotation_deg=head_rotation_deg,
        wrist_translation_m=wrist_translation_m,
        wrist_rotation_deg=wrist_rotation_deg,
        radius_scale=radius_scale,
        rgba=rgba,
        seed=seed,
    )
    return GammaPlus(
        rig,
        style,
        spec=spec,
        backend=backend,
        robot=_robot(RobotModel.from_rig(rig), p),
        cameras=_cameras(RigCameras.from_rig(rig), p),
        marker_style=marker_style,
    )


def _stride_actions(chunks: NDArray[np.floating], spec: ChunkSpec) -> F64:
    arr = np.asarray(chunks, dtype=np.float64)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[-1] != STATE_DIM:
        raise ValueError(
            f"chunks: expected a chunk (H, {STATE_DIM}) or a batch (B, H, {STATE_DIM}), got shape {arr.shape}"
        )
    if arr.shape[1] < spec.executed_steps:
        raise ValueError(f"chunks: {arr.shape[1]} steps, but K·Δ = {spec.executed_steps} are needed")
    if not np.all(np.isfinite(arr)):
        raise ValueError("chunks: contains non-finite values")
    out: F64 = arr[:, spec.stride_indices()].reshape(-1, STATE_DIM)
    return out


def _mean_or_none(values: NDArray[np.floating]) -> float | None:
    return float(np.mean(values)) if values.size else None


def render_sensitivity(
    rig: RigConfig,
    chunks: NDArray[np.floating],
    perturbations: Sequence[Mapping[str, Any]],
    backend: Backend = "analytic",
    *,
    spec: ChunkSpec | None = None,
) -> list[dict[str, Any]]:
    """How far each perturbation moves the robot render over the stride-aligned actions of ``chunks``.

    ``chunks``: one (H, 14) or a batch (B, H, 14); ``perturbations``: dicts of :class:`Perturbation`'s
    keys. Per perturbation (JSON-able, in order):

    * ``iou``: view → mean over frames of the IoU of the perturbed robot mask with the nominal one
      (frames where neither shows the robot are left out; None if that is every frame);
    * ``area_ratio``: view → perturbed robot pixels / nominal robot pixels over all frames (None if the
      nominal render is empty);
    * ``tcp_shift_px`` / ``tcp_shift_px_max``: mean / largest pixel distance between both TCPs' projections
      through the nominal and the perturbed head camera (points visible in both; None if none is);
    * ``perturbation``: the validated perturbation, ``frames``: the number of joint vectors rendered.
    """
    spec = spec or ChunkSpec()
    probes = [Perturbation.from_dict(d) for d in perturbations]
    q = _stride_actions(chunks, spec)
    robot = RobotModel.from_rig(rig)
    cameras = RigCameras.from_rig(rig)
    nominal = _render_parts(make_robot_renderer(rig, backend, robot=robot, cameras=cameras), q)
    tcp = rig.kinematics.gripper_points(q).reshape(-1, 3)  # (N·2, 3) rig frame
    head = next((v.model for v in cameras.views if v.name == HEAD_VIEW), None)
    out: list[dict[str, Any]] = []
    for p in probes:
        cams = _cameras(cameras, p)
        parts = _render_parts(make_robot_renderer(rig, backend, robot=_robot(robot, p), cameras=cams), q)
        iou: dict[str, float | None] = {}
        area: dict[str, float | None] = {}
        for view, ref in nominal.items():
            a, b = ref > 0, parts[view] > 0
            union = (a | b).sum(axis=(1, 2))
            inter = (a & b).sum(axis=(1, 2))
            seen = union > 0
            iou[view] = _mean_or_none(inter[seen] / union[seen])
            n_ref = int(a.sum())
            area[view] = float(b.sum()) / n_ref if n_ref else None
        shift: float | None = None
        shift_max: float | None = None
        if head is not None:
            uv0, vis0 = head.project(tcp)
            uv1, vis1 = cams.view(HEAD_VIEW).model.project(tcp)
            both = vis0 & vis1
            d = np.linalg.norm(uv1[both] - uv0[both], axis=-1)
            shift = _mean_or_none(d)
            shift_max = float(d.max()) if d.size else None
        out.append(
            {
                "perturbation": p.to_json(),
                "frames": int(q.shape[0]),
                "iou": iou,
                "area_ratio": area,
                "tcp_shift_px": shift,
                "tcp_shift_px_max": shift_max,
            }
        )
    return out


def _render_parts(renderer: Any, q: F64) -> dict[str, NDArray[np.uint8]]:
    try:
        parts: dict[str, NDArray[np.uint8]] = renderer.render(q, depth=False, shaded=False).parts
        return parts
    finally:
        close = getattr(renderer, "close", None)
        if close is not None:
            close()
