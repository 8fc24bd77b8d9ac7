"""The head-camera projection model shared by the control video and the simulator.

A :class:`CameraModel` is OpenCV's camera model (``cv::projectPoints``) plus the camera pose and the
image size, so that both branches of PiL-World draw 3-D points at the same pixels:

* **Frames.** ``T_cam_base`` (4x4, metres) maps points expressed in the base frame -- for the
  dual-arm rig the *rig frame* -- into the camera frame: ``p_cam = T_cam_base @ p_base``. The camera
  frame is OpenCV's: x right, y down, z forward along the optical axis.
* **Projection.** With ``(x', y') = (X_c / Z_c, Y_c / Z_c)`` distorted to ``(x'', y'')`` by
  :mod:`calib.distortion`, the pixel is ``[u, v, 1]ᵀ = K [x'', y'', 1]ᵀ`` with
  ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]``. OpenCV's own calibration never estimates the skew
  ``s = K[0, 1]`` (it is always 0 there, and ``cv2.projectPoints`` ignores it); a non-zero skew is
  honoured here as the matrix product says, i.e. ``u = fx x'' + s y'' + cx``.
* **Pixel convention.** OpenCV's: integer pixel coordinates are pixel *centres*, so the image covers
  ``-0.5 <= u < width - 0.5`` and ``-0.5 <= v < height - 0.5`` and its centre is
  ``((width - 1) / 2, (height - 1) / 2)``.
* **Visibility.** A point is visible if it is in front of the camera (``Z_c > NEAR_Z``), its ray lies
  inside the distortion model's monotonic radius (beyond it polynomial fits fold back and would put
  the point at a wrong pixel, see :func:`calib.distortion.max_monotonic_radius`), and its pixel lies
  inside the image.
* **Back-projection.** :meth:`CameraModel.unproject` inverts the projection to unit camera-frame rays
  (same pixel convention, distortion removed to ~1e-9 px) and :meth:`CameraModel.backproject_to_plane`
  intersects them with a horizontal base-frame plane ``Z = z``: what image-only scripted policies need
  to turn a detected pixel into a point on (or above) the table, which is ``z = 0`` in the rig frame.

YAML file format (``to_yaml`` / ``from_yaml``; the same keys in ``to_dict`` / ``from_dict``)::

    format: pilworld.camera_model/v1      # required, exactly this string
    name: cam_high                        # optional, default "cam_high"
    image_size: {width: 640, height: 480} # pixels, integers > 0
    K: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]   # OpenCV camera matrix; K[0][1] is the (rare) skew
    dist: [k1, k2, p1, p2, k3]  # 0, 4, 5, 8, 12 or 14 OpenCV coefficients
                                # (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, τx, τy]]]])
    T_cam_base: [[r00, r01, r02, tx], [r10, r11, r12, ty], [r20, r21, r22, tz], [0, 0, 0, 1]]
                # maps base(rig)-frame points into the camera frame (metres); must be rigid

Every key except ``name`` is required and unknown keys are rejected (they are usually typos). Floats
are written with ``repr`` precision, so a write/read round trip is exact.
"""

from __future__ import annotations

import errno
import math
import numbers
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Final, cast

import numpy as np
import numpy.typing as npt
import yaml

from calib.distortion import DistortionModel, as_distortion_coefficients
from pilworld.geometry import as_finite_array

__all__ = ["FORMAT", "NEAR_Z", "RIGID_ATOL", "CameraModel", "Projection"]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

#: Value of the ``format`` key of camera model files.
FORMAT: Final = "pilworld.camera_model/v1"

#: Near limit in metres: points with camera-frame depth ``Z_c <= NEAR_Z`` are "not in front". 1 µm is
#: far below any real working distance, yet keeps ``1 / Z_c`` (and thus pixel values) finite.
NEAR_Z: Final = 1e-6

#: Absolute tolerance for ``T_cam_base`` being rigid (``RᵀR = I``, ``det R = 1``, last row
#: ``[0, 0, 0, 1]``): loose enough for matrices printed with ~9 digits, tight enough to catch scale.
RIGID_ATOL: Final = 1e-6

# Rays beyond the monotonic radius are pulled back radially to this fraction of it before distorting
# (see CameraModel._project_flat): strictly inside, so that a pole of the rational model is never hit.
_CLAMP_FRACTION: Final = 1.0 - 1e-9


def _const(value: float) -> FloatArray:
    """A read-only 0-d float64 array."""
    arr = np.array(value, dtype=np.float64)
    arr.flags.writeable = False
    return arr


_NEAR: Final = _const(NEAR_Z)
_MINUS_HALF: Final = _const(-0.5)

_KEYS: Final = ("format", "name", "image_size", "K", "dist", "T_cam_base")
_REQUIRED: Final = ("format", "image_size", "K", "dist", "T_cam_base")


@dataclass(frozen=True, eq=False)
class Projection:
    """Everything :meth:`CameraModel.project_detailed` knows about each point; ``...`` = input batch shape.

    ``uv`` is always finite (for input coordinates below ~1e30 m). For visible points it is the OpenCV
    pixel. For points in front of the camera but outside the valid (monotonic) field of view, the ray is
    pulled back radially onto the edge of that field of view, distorted there, and the distorted offset
    pushed out again by the same factor: a finite stand-in that keeps the direction of the point and
    grows with its angle instead of folding back. Points not in front are first moved onto the near
    plane ``Z_c = NEAR_Z`` (keeping ``X_c``, ``Y_c``) and then treated the same way.
    """

    uv: FloatArray  #: ``(..., 2)`` float64 pixel coordinates (u right, v down; integers are pixel centres)
    depth: FloatArray  #: ``(...)`` float64 ``Z_c`` in metres (camera frame; negative = behind)
    in_front: BoolArray  #: ``(...)`` ``Z_c > NEAR_Z``
    #: ``(...)`` in front and inside the distortion model's monotonic radius (and, for a tilted sensor,
    #: on the side where the tilt homography does not flip the image)
    in_valid_fov: BoolArray
    in_image: BoolArray  #: ``(...)`` ``uv`` inside ``[-0.5, width - 0.5) x [-0.5, height - 0.5)``
    visible: BoolArray  #: ``(...)`` ``in_valid_fov & in_image``


@dataclass(frozen=True, eq=False)
class CameraModel:
    """An OpenCV camera (intrinsics, distortion), its pose in the base (rig) frame and its image size.

    Fields accept anything array-like and are stored as read-only float64 copies:

    * ``K``: ``(3, 3)`` camera matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``, ``fx, fy > 0``, pixels.
    * ``dist``: ``(n,)`` OpenCV distortion coefficients, ``n`` in 0, 4, 5, 8, 12, 14 (``(1, n)`` as
      returned by ``cv2.calibrateCamera`` is flattened).
    * ``T_cam_base``: ``(4, 4)`` rigid transform mapping base(rig)-frame points into the camera frame
      (OpenCV axes: x right, y down, z forward), metres.
    * ``width``, ``height``: image size in pixels (integers > 0); ``name``: the camera key.

    Invalid values raise ``ValueError`` naming the field, the value and what is allowed. Instances are
    immutable and hashable; equality is exact. See the module docstring for conventions.
    """

    K: FloatArray
    dist: FloatArray
    T_cam_base: FloatArray
    width: int
    height: int
    name: str = "cam_high"

    # Derived, precomputed once so that project() does no validation or conversion of its own state.
    _R_T: FloatArray = field(init=False, repr=False)  # R_cam_base transposed, C-contiguous (3, 3)
    _t: FloatArray = field(init=False, repr=False)  # t_cam_base (3,)
    _distortion: DistortionModel = field(init=False, repr=False)
    _r2_max: FloatArray | None = field(init=False, repr=False)  # squared monotonic radius, None if inf
    _r2_clamp: FloatArray = field(init=False, repr=False)
    # 0-d arrays: cheaper numpy operands than Python floats (see calib.distortion.DistortionModel).
    _intrinsics: tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray] = field(init=False, repr=False)
    _has_skew: bool = field(init=False, repr=False)
    _hi: tuple[FloatArray, FloatArray] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        K = _float_matrix(self.K, "K", 3, 3)
        fx, fy = float(K[0, 0]), float(K[1, 1])
        if not fx > 0.0:
            raise ValueError(f"field 'K': fx = K[0][0] must be > 0, got {fx!r} in K = {K.tolist()}")
        if not fy > 0.0:
            raise ValueError(f"field 'K': fy = K[1][1] must be > 0, got {fy!r} in K = {K.tolist()}")
        if K[1, 0] != 0.0 or K[2, 0] != 0.0 or K[2, 1] != 0.0 or K[2, 2] != 1.0:
            raise ValueError(
                "field 'K': expected the OpenCV layout [[fx, s, cx], [0, fy, cy], [0, 0, 1]] "
                f"(K[1][0] = 0 and last row exactly [0, 0, 1]), got {K.tolist()}"
            )
        distortion = DistortionModel(as_distortion_coefficients(self.dist, name="field 'dist'"))
        T = _float_matrix(self.T_cam_base, "T_cam_base", 4, 4)
        _check_rigid(T)
        width = _positive_int(self.width, "width")
        height = _positive_int(self.height, "height")
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"field 'name': expected a non-empty string, got {self.name!r}")

        K.flags.writeable = False
        T.flags.writeable = False
        set_ = object.__setattr__  # the dataclass is frozen; this is its documented escape hatch
        set_(self, "K", K)
        set_(self, "dist", distortion.coefficients)
        set_(self, "T_cam_base", T)
        set_(self, "width", width)
        set_(self, "height", height)
        R_T = np.ascontiguousarray(T[:3, :3].T)
        t = T[:3, 3].copy()
        R_T.flags.writeable = False
        t.flags.writeable = False
        set_(self, "_R_T", R_T)
        set_(self, "_t", t)
        set_(self, "_distortion", distortion)
        r_max = distortion.max_monotonic_radius
        set_(self, "_r2_max", None if math.isinf(r_max) else _const(r_max * r_max))
        set_(self, "_r2_clamp", _const((r_max * _CLAMP_FRACTION) ** 2))
        set_(self, "_intrinsics", tuple(_const(float(c)) for c in (fx, K[0, 1], K[0, 2], fy, K[1, 2])))
        set_(self, "_has_skew", bool(K[0, 1] != 0.0))
        set_(self, "_hi", (_const(width - 0.5), _const(height - 0.5)))

    # ------------------------------------------------------------------ identity

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CameraModel):
            return NotImplemented
        return (
            self.name == other.name
            and self.width == other.width
            and self.height == other.height
            and np.array_equal(self.K, other.K)
            and self.dist.shape == other.dist.shape
            and np.array_equal(self.dist, other.dist)
            and np.array_equal(self.T_cam_base, other.T_cam_base)
        )

    def __hash__(self) -> int:
        # "+ 0.0" maps -0.0 to 0.0 so that equal models (array_equal treats them as equal) hash equally.
        return hash(
            (
                self.name,
                self.width,
                self.height,
                (self.K + 0.0).tobytes(),
                (self.dist + 0.0).tobytes(),
                (self.T_cam_base + 0.0).tobytes(),
            )
        )

    # ------------------------------------------------------------------ properties

    @property
    def max_valid_radius(self) -> float:
        """Normalized image radius ``sqrt(x'² + y'²)`` of the valid field of view (+inf if unlimited)."""
        return self._distortion.max_monotonic_radius

    # ------------------------------------------------------------------ projection

    def points_to_camera(self, points: npt.ArrayLike) -> FloatArray:
        """Base(rig)-frame points ``(..., 3)`` in metres -> camera-frame points ``(..., 3)``."""
        flat, batch = _flat_points(points)
        pc: FloatArray = flat @ self._R_T + self._t
        return pc.reshape(*batch, 3)

    def camera_center_in_base(self) -> FloatArray:
        """Optical centre of the camera in the base (rig) frame, ``(3,)`` metres: ``-Rᵀ t``."""
        center: FloatArray = -(self._R_T @ self._t)
        return center

    def project(self, points: npt.ArrayLike) -> tuple[FloatArray, BoolArray]:
        """Project base(rig)-frame points ``(..., 3)`` (metres) to pixels.

        Returns ``(uv, visible)``: ``uv`` ``(..., 2)`` float64 pixel coordinates (always finite; only
        meaningful where ``visible``) and ``visible`` ``(...)`` bool. See :class:`Projection` for what
        ``uv`` holds for points that are not visible and :meth:`project_detailed` for the reasons.
        Raises ``ValueError`` if ``points`` is not ``(..., 3)`` or contains NaN/inf.
        """
        flat, batch = _flat_points(points)
        uv, _, _, _, _, visible = self._project_flat(flat)
        return uv.reshape(*batch, 2), visible.reshape(batch)

    def project_detailed(self, points: npt.ArrayLike) -> Projection:
        """Like :meth:`project` but also returns depth and each visibility condition separately."""
        flat, batch = _flat_points(points)
        uv, depth, in_front, in_fov, in_image, visible = self._project_flat(flat)
        return Projection(
            uv=uv.reshape(*batch, 2),
            depth=depth.reshape(batch),
            in_front=in_front.reshape(batch),
            in_valid_fov=in_fov.reshape(batch),
            in_image=in_image.reshape(batch),
            visible=visible.reshape(batch),
        )

    def _project_flat(
        self, pts: FloatArray
    ) -> tuple[FloatArray, FloatArray, BoolArray, BoolArray, BoolArray, BoolArray]:
        """The projection of ``(N, 3)`` validated points; returns uv, depth and the masks (see Projection).

        Hot path (all points in front and inside the valid field of view): one matmul, no copies of the
        model's arrays, and only the distortion terms whose coefficients are non-zero.
        """
        pc = pts @ self._R_T
        pc += self._t
        x, y, z = pc[:, 0], pc[:, 1], pc[:, 2]
        in_front = z > _NEAR
        # Never divide by ~0 or by a negative depth (which would mirror the point): points not in front
        # are moved onto the near plane. They are not visible; this only keeps uv finite and warning-free.
        # For points in front, max(z, NEAR_Z) is z exactly.
        zs = np.maximum(z, _NEAR)
        xn = x / zs
        yn = y / zs
        distortion = self._distortion
        r2_max = self._r2_max
        if r2_max is None:  # the radial mapping never turns around
            in_fov = in_front
            xd, yd, w = distortion.distort_xy(xn, yn)
        else:
            r2 = xn * xn + yn * yn
            inside = r2 < r2_max
            in_fov = in_front & inside
            if inside.all():
                xd, yd, w = distortion.distort_xy(xn, yn, r2)
            else:
                # Beyond the monotonic radius the fit folds back; pull the ray radially onto the edge of
                # the valid field of view, distort there and push the result out again by the same
                # factor, so uv stays finite, keeps the ray's direction and moves away with its angle.
                scale = np.where(inside, 1.0, np.sqrt(r2 / self._r2_clamp))
                xd, yd, w = distortion.distort_xy(xn / scale, yn / scale)
                xd = xd * scale
                yd = yd * scale
        if w is not None:
            # The tilted-sensor homography flips the image where its denominator is <= 0.
            in_fov = in_fov & (w > 0.0)
        fx, skew, cx, fy, cy = self._intrinsics
        uv = np.empty((pts.shape[0], 2), dtype=np.float64)
        u, v = uv[:, 0], uv[:, 1]
        if self._has_skew:
            np.multiply(yd, skew, out=u)
            u += fx * xd
        else:
            np.multiply(xd, fx, out=u)
        u += cx
        np.multiply(yd, fy, out=v)
        v += cy
        # OpenCV's pixel-centre convention: pixel i covers [i - 0.5, i + 0.5).
        u_hi, v_hi = self._hi
        in_image = (u >= _MINUS_HALF) & (u < u_hi) & (v >= _MINUS_HALF) & (v < v_hi)
        visible = in_fov & in_image
        return uv, z, in_front, in_fov, in_image, visible

    # ------------------------------------------------------------------ back-projection

    def unproject(self, uv: npt.ArrayLike) -> FloatArray:
        """Pixels ``uv`` ``(..., 2)`` -> unit ray directions ``(..., 3)`` in the camera frame (float64).

        The inverse of :meth:`project` on its valid field of view, with the same pixel convention
        (integer coordinates are pixel centres): ``y'' = (v - cy) / fy``, ``x'' = (u - cx - s y'') / fx``
        (the skew undone as :meth:`project` applies it), then the distortion removed by
        :meth:`calib.distortion.DistortionModel.undistort` -- the exact inverse of the tilt followed by
        Newton's method on the analytic Jacobian to a residual of 1e-12 in normalized coordinates
        (~1e-9 px). That is the same model :meth:`project` applies, so the round trip is exact to
        round-off; ``cv2.undistortPointsIter`` would ignore the skew and its fixed-point iteration
        converges only linearly (it stalls on strong rational fits). Without distortion there is no
        iteration at all. Rays are ``(x', y', 1) / |(x', y', 1)|``, so their z component is > 0.

        Pixels outside the image are allowed (they have rays too). Pixels that no ray inside the valid
        field of view maps to (the undistorted ray would lie at or beyond :attr:`max_valid_radius`, or
        on the side that a tilted sensor flips) come back as NaN rays, and so do the rare pixels where
        Newton's method does not converge (seen only next to a pole of a rational 8-coefficient fit,
        ~1.4 normalized units off-centre, far outside any image): a ray is either right or NaN. Raises
        ``ValueError`` naming ``uv`` if it is not ``(..., 2)`` or contains NaN/inf.
        """
        p = as_finite_array(uv, "uv", (2,))
        batch = p.shape[:-1]
        flat = p.reshape(-1, 2)
        fx, skew, cx, fy, cy = self._intrinsics
        yd = (flat[:, 1] - cy) / fy
        xd = flat[:, 0] - cx
        if self._has_skew:
            xd -= skew * yd
        xd /= fx
        distortion = self._distortion
        if distortion.is_identity:
            x, y = xd, yd
        else:
            und = distortion.undistort(np.stack([xd, yd], axis=-1))
            x, y = und[:, 0], und[:, 1]
            if distortion.has_tilt:
                # undistort inverts the tilt homography exactly, also where it flips the image; project()
                # treats such rays as outside the valid field of view, so they have no pixel to invert.
                with np.errstate(invalid="ignore"):
                    _, _, w = distortion.distort_xy(x, y)
                    flipped = ~(w > 0.0) if w is not None else np.zeros(x.shape, dtype=np.bool_)
                x = np.where(flipped, np.nan, x)
                y = np.where(flipped, np.nan, y)
        rays = np.empty((flat.shape[0], 3), dtype=np.float64)
        inv_norm = 1.0 / np.sqrt(x * x + y * y + 1.0)
        np.multiply(x, inv_norm, out=rays[:, 0])
        np.multiply(y, inv_norm, out=rays[:, 1])
        rays[:, 2] = inv_norm
        return rays.reshape(*batch, 3)

    def backproject_to_plane(self, uv: npt.ArrayLike, z: npt.ArrayLike = 0.0) -> tuple[FloatArray, BoolArray]:
        """Intersect the rays of pixels ``uv`` ``(..., 2)`` with the horizontal base-frame plane ``Z = z``.

        ``z`` (metres, base/rig frame; the table surface is ``z = 0``) is a scalar or an array that
        broadcasts to the batch shape ``(...)`` of ``uv``, e.g. one plane height per pixel. Returns
        ``(points, valid)``: ``points`` ``(..., 3)`` float64 base-frame intersections (metres) and
        ``valid`` ``(...)`` bool. ``valid`` is False -- and the point NaN -- where the pixel has no ray
        (see :meth:`unproject`), where the ray is parallel to the plane, or where the intersection is not
        in front of the camera (camera-frame depth ``<= NEAR_Z``, the same limit :meth:`project` uses),
        so ``project(points[valid])`` gives back ``uv[valid]``. Nearly parallel rays are valid and
        their intersections correspondingly far away. Raises ``ValueError`` naming ``uv`` or ``z`` for
        bad shapes or NaN/inf.
        """
        rays = self.unproject(uv)
        batch = rays.shape[:-1]
        z_arr = as_finite_array(z, "z")
        try:
            z_flat = np.broadcast_to(z_arr, batch).reshape(-1)
        except ValueError as exc:
            raise ValueError(
                f"z must be a scalar or broadcast to the batch shape {batch} of uv; got shape {z_arr.shape}"
            ) from exc
        rays_flat = rays.reshape(-1, 3)
        # Base-frame directions d_b = Rᵀ d_c; with row vectors d_bᵀ = d_cᵀ R = d_cᵀ (Rᵀ)ᵀ.
        dirs = rays_flat @ self._R_T.T
        center = self.camera_center_in_base()
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (z_flat - center[2]) / dirs[:, 2]  # distance along the unit ray
            # t * ray_z is the camera-frame depth of the hit (NaN rays and 0 / 0 compare False).
            valid = np.isfinite(t) & (t * rays_flat[:, 2] > _NEAR)
        points = center + np.where(valid, t, np.nan)[:, None] * dirs
        points[:, 2] = np.where(valid, z_flat, np.nan)  # exactly on the plane, not centre + round-off
        return points.reshape(*batch, 3), valid.reshape(batch)

    # ------------------------------------------------------------------ derived models

    def with_pose(self, T_cam_base: npt.ArrayLike) -> CameraModel:
        """The same camera at another pose (``T_cam_base`` 4x4, base(rig) frame -> camera frame)."""
        # __post_init__ converts and validates; the cast only tells mypy that it will.
        return replace(self, T_cam_base=cast(FloatArray, T_cam_base))

    def resized(self, width: int, height: int) -> CameraModel:
        """The same camera for an image resampled to ``width x height`` (the full frame, no crop).

        With the pixel-centre convention a pixel edge at ``-0.5`` stays at ``-0.5``, so
        ``u' = (u + 0.5) sx - 0.5`` with ``sx = width' / width``: ``fx' = sx fx``, ``s' = sx s``,
        ``cx' = (cx + 0.5) sx - 0.5``, and likewise for y. Distortion acts on normalized coordinates
        and is unchanged.
        """
        new_w = _positive_int(width, "width")
        new_h = _positive_int(height, "height")
        sx, sy = new_w / self.width, new_h / self.height
        A = np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5], [0.0, 0.0, 1.0]])
        return replace(self, K=A @ self.K, width=new_w, height=new_h)

    @classmethod
    def look_at(
        cls,
        eye: npt.ArrayLike,
        target: npt.ArrayLike,
        up: npt.ArrayLike,
        fovy_deg: float,
        width: int,
        height: int,
        name: str = "cam_high",
    ) -> CameraModel:
        """An undistorted pinhole camera at ``eye`` looking at ``target`` (base-frame points, metres).

        ``up`` (base-frame direction, any length) appears upwards in the image, i.e. towards smaller
        ``v``. ``fovy_deg`` is the vertical field of view spanning the full image height (edge to edge,
        as MuJoCo's ``fovy``): ``fy = height / (2 tan(fovy / 2))``. Pixels are square and the principal
        point is the image centre ``((width - 1) / 2, (height - 1) / 2)``. Raises ``ValueError`` if
        ``eye == target``, ``up`` is zero or parallel to the viewing direction, or ``fovy_deg`` is not
        in (0, 180).
        """
        eye_v = _vector3(eye, "eye")
        target_v = _vector3(target, "target")
        up_v = _vector3(up, "up")
        fwd = target_v - eye_v
        dist = float(np.linalg.norm(fwd))
        if not dist > 1e-12:
            raise ValueError(f"look_at: eye {eye_v.tolist()} and target {target_v.tolist()} coincide")
        fwd /= dist
        up_norm = float(np.linalg.norm(up_v))
        right = np.cross(fwd, up_v)
        right_norm = float(np.linalg.norm(right))
        if not right_norm > 1e-9 * up_norm:
            raise ValueError(
                f"look_at: up {up_v.tolist()} must be non-zero and not parallel to the viewing direction "
                f"{fwd.tolist()} (from eye to target)"
            )
        right /= right_norm
        # Unit length because fwd and right are orthonormal; rows (right, down, fwd) then have det +1.
        down = np.cross(fwd, right)
        fovy = float(fovy_deg)
        if not 0.0 < fovy < 180.0:
            raise ValueError(f"look_at: fovy_deg must be in (0, 180), got {fovy_deg!r}")
        w = _positive_int(width, "width")
        h = _positive_int(height, "height")
        f = h / (2.0 * math.tan(math.radians(fovy) / 2.0))
        K = np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
        T = np.eye(4)
        T[:3, :3] = np.stack([right, down, fwd])  # rows: camera axes expressed in the base frame
        T[:3, 3] = -T[:3, :3] @ eye_v
        return cls(K=K, dist=np.zeros(0), T_cam_base=T, width=w, height=h, name=name)

    # ------------------------------------------------------------------ serialisation

    def to_dict(self) -> dict[str, Any]:
        """The YAML mapping of this model (plain Python types; see the module docstring)."""
        return {
            "format": FORMAT,
            "name": self.name,
            "image_size": {"width": self.width, "height": self.height},
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "T_cam_base": self.T_cam_base.tolist(),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str = "<dict>") -> CameraModel:
        """Build a model from the mapping of :meth:`to_dict`; errors name ``source`` and the field."""
        if not isinstance(d, Mapping):
            raise ValueError(f"{source}: expected a mapping with keys {', '.join(_KEYS)}, got {type(d).__name__}")
        unknown = [str(k) for k in d if k not in _KEYS]
        if unknown:
            raise ValueError(
                f"{source}: unknown field(s) {', '.join(repr(k) for k in unknown)}; allowed: {', '.join(_KEYS)}"
            )
        for key in _REQUIRED:
            if key not in d:
                raise ValueError(f"{source}: field {key!r}: missing (required: {', '.join(_REQUIRED)})")
        if d["format"] != FORMAT:
            raise ValueError(f"{source}: field 'format': expected {FORMAT!r}, got {d['format']!r}")
        size = d["image_size"]
        if not isinstance(size, Mapping) or set(size) != {"width", "height"}:
            raise ValueError(f"{source}: field 'image_size': expected {{width: <int>, height: <int>}}, got {size!r}")
        raw_dist = d["dist"]
        if not isinstance(raw_dist, Sequence | np.ndarray) or isinstance(raw_dist, str):
            raise ValueError(
                f"{source}: field 'dist': expected a list of 0, 4, 5, 8, 12 or 14 numbers, got {raw_dist!r}"
            )
        try:
            return cls(
                K=_parse_matrix(d["K"], 3, 3, "K"),
                dist=np.array([_parse_number(c, "dist") for c in raw_dist], dtype=np.float64),
                T_cam_base=_parse_matrix(d["T_cam_base"], 4, 4, "T_cam_base"),
                width=size["width"],
                height=size["height"],
                name=d.get("name", "cam_high"),
            )
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from exc

    def to_yaml(self, path: str | Path) -> None:
        """Write the model to ``path`` (YAML, see the module docstring) via a temporary file + rename."""
        path = Path(path)
        text = (
            f"# PiL-World camera model ({FORMAT}); conventions: calib/camera_model.py.\n"
            "# K, dist: OpenCV (cv::projectPoints); integer pixel coordinates are pixel centres.\n"
            "# T_cam_base maps base(rig)-frame points (metres) into the camera frame (x right, y down,"
            " z forward).\n"
        ) + yaml.safe_dump(self.to_dict(), sort_keys=False, default_flow_style=None, allow_unicode=True)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(path)  # atomic on POSIX: a reader never sees a half-written calibration

    @classmethod
    def from_yaml(cls, path: str | Path) -> CameraModel:
        """Load a model written by :meth:`to_yaml` (or by hand).

        Raises ``FileNotFoundError`` (with the path) if the file does not exist and ``ValueError``
        naming the file and the offending field if it is not a valid camera model.
        """
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise FileNotFoundError(errno.ENOENT, "camera model file not found", str(path)) from None
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ValueError(f"{path}: not valid YAML: {exc}") from exc
        if data is None:
            raise ValueError(f"{path}: file is empty; expected a camera model ({FORMAT})")
        return cls.from_dict(data, source=str(path))


# ---------------------------------------------------------------------- helpers


def _short(value: object, limit: int = 160) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _flat_points(points: npt.ArrayLike) -> tuple[FloatArray, tuple[int, ...]]:
    """``points`` as float64 ``(N, 3)`` (a view when possible) and its batch shape; cheap checks only."""
    p = as_finite_array(points, "points", (3,))  # base-frame xyz in metres
    return p.reshape(-1, 3), p.shape[:-1]


def _float_matrix(value: object, name: str, rows: int, cols: int) -> FloatArray:
    """A new float64 ``(rows, cols)`` array of finite numbers, else ``ValueError`` naming field ``name``."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"field {name!r}: expected a {rows}x{cols} matrix of numbers, got {_short(value)}") from exc
    if arr.shape != (rows, cols):
        raise ValueError(f"field {name!r}: expected a {rows}x{cols} matrix, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"field {name!r}: entries must be finite, got {arr.tolist()}")
    return arr


def _check_rigid(T: FloatArray) -> None:
    R = T[:3, :3]
    orth_err = float(np.abs(R.T @ R - np.eye(3)).max())
    det = float(np.linalg.det(R))
    bottom_err = float(np.abs(T[3] - np.array([0.0, 0.0, 0.0, 1.0])).max())
    if orth_err > RIGID_ATOL or abs(det - 1.0) > RIGID_ATOL or bottom_err > RIGID_ATOL:
        raise ValueError(
            f"field 'T_cam_base': expected a rigid transform (rotation block R with RᵀR = I and "
            f"det R = +1, last row [0, 0, 0, 1], all within {RIGID_ATOL:g}); got max|RᵀR - I| = "
            f"{orth_err:.3g}, det R = {det:.9g}, last row {T[3].tolist()} in {T.tolist()}"
        )


def _positive_int(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value <= 0:
        raise ValueError(f"field {name!r}: expected an integer > 0 (pixels), got {value!r}")
    return int(value)


def _vector3(value: npt.ArrayLike, name: str) -> FloatArray:
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"look_at: {name} must be a 3-vector of numbers, got {_short(value)}") from exc
    if arr.shape != (3,) or not np.isfinite(arr).all():
        raise ValueError(f"look_at: {name} must be a finite 3-vector, got {_short(value)}")
    return arr


def _parse_number(value: object, name: str) -> float:
    """A YAML scalar as float. Bools are rejected (YAML 1.1 reads ``yes``/``on`` as true)."""
    if isinstance(value, bool):
        raise ValueError(f"field {name!r}: expected a number, got {value!r}")
    if isinstance(value, numbers.Real):
        return float(value)
    if isinstance(value, str):
        # PyYAML implements YAML 1.1, whose float pattern needs a dot: "1e-5" loads as a *string*.
        try:
            return float(value)
        except ValueError:
            pass
    raise ValueError(f"field {name!r}: expected a number, got {value!r}")


def _parse_matrix(value: object, rows: int, cols: int, name: str) -> FloatArray:
    """A YAML list of ``rows`` lists of ``cols`` numbers as float64 ``(rows, cols)``."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, list | tuple) or not all(isinstance(r, list | tuple) for r in value):
        raise ValueError(
            f"field {name!r}: expected a {rows}x{cols} matrix (a list of {rows} lists of {cols} numbers), "
            f"got {_short(value)}"
        )
    lengths = sorted({len(r) for r in value})
    if len(lengths) > 1:
        raise ValueError(
            f"field {name!r}: expected a {rows}x{cols} matrix, got rows of different lengths {[len(r) for r in value]}"
        )
    shape = (len(value), lengths[0] if lengths else 0)
    if shape != (rows, cols):
        raise ValueError(f"field {name!r}: expected a {rows}x{cols} matrix, got shape {shape}")
    return np.array([[_parse_number(x, name) for x in row] for row in value], dtype=np.float64)
