"""OpenCV's camera lens-distortion model, vectorised in float64 numpy.

The model is the one of ``cv::projectPoints`` (OpenCV calib3d, "Detailed Description" of the
"Camera Calibration and 3D Reconstruction" module). It acts on *normalized image coordinates*
``(x', y') = (X_c / Z_c, Y_c / Z_c)`` of a point ``(X_c, Y_c, Z_c)`` in the camera frame (OpenCV
convention: x right, y down, z forward) and returns distorted normalized coordinates; the camera
matrix ``K`` is applied afterwards (see :mod:`calib.camera_model`). With ``r² = x'² + y'²``::

    x'' = x' (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)
          + 2 p1 x'y' + p2 (r² + 2 x'²) + s1 r² + s2 r⁴
    y'' = y' (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)
          + p1 (r² + 2 y'²) + 2 p2 x'y' + s3 r² + s4 r⁴

followed by the tilted-sensor ("Scheimpflug") model: ``s [x''', y''', 1]ᵀ = M(τx, τy) [x'', y'', 1]ᵀ``
with ``M`` built exactly as OpenCV's ``computeTiltProjectionMatrix`` (see
:func:`tilt_projection_matrix`).

Coefficients come in OpenCV order and OpenCV's allowed counts (``cv::projectPoints``: "distCoeffs --
Input vector of distortion coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, τx,
τy]]]]) of 4, 5, 8, 12 or 14 elements. If the vector is empty, the zero distortion coefficients are
assumed."); missing trailing coefficients are zero.

Polynomial/rational fits are only trustworthy inside the field of view they were calibrated on:
beyond it the radial mapping ``r ↦ r · radial(r)`` usually turns around, so points far outside the
view "fold back" into the image. :func:`max_monotonic_radius` gives the normalized radius where that
happens, and :class:`calib.camera_model.CameraModel` treats rays beyond it as not visible.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
import numpy.typing as npt
from numpy.polynomial import polynomial as npoly

__all__ = [
    "VALID_COEFFICIENT_COUNTS",
    "DistortionModel",
    "as_distortion_coefficients",
    "distort_normalized",
    "max_monotonic_radius",
    "tilt_projection_matrix",
    "undistort_normalized",
]

FloatArray = npt.NDArray[np.float64]

#: Coefficient counts accepted by OpenCV (``cv::projectPoints``); 0 means no distortion.
VALID_COEFFICIENT_COUNTS: Final[tuple[int, ...]] = (0, 4, 5, 8, 12, 14)

_ORDER: Final = "(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, τx, τy]]]])"

# A complex root of the monotonicity polynomial whose imaginary part is this small relative to its
# modulus is treated as real: the derivative of the radial mapping then comes within round-off of zero
# there, so the fit is at the edge of folding back and we stop trusting it (conservative).
_REAL_ROOT_RTOL: Final = 1e-7


def _const(value: float) -> FloatArray:
    """A read-only 0-d float64 array (cheaper than a Python float as a numpy operand)."""
    arr = np.array(value, dtype=np.float64)
    arr.flags.writeable = False
    return arr


_ONE: Final = _const(1.0)


def as_distortion_coefficients(dist: npt.ArrayLike | None, name: str = "dist") -> FloatArray:
    """Validate OpenCV distortion coefficients and return them as a new 1-D float64 array.

    Accepts 0, 4, 5, 8, 12 or 14 finite numbers, as a flat sequence or in the ``(1, n)`` / ``(n, 1)``
    layout that ``cv2.calibrateCamera`` returns. ``None`` means no distortion. Raises ``ValueError``
    naming ``name`` otherwise.
    """
    if dist is None:
        return np.zeros(0, dtype=np.float64)
    try:
        arr = np.array(dist, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"{name}: expected a sequence of {_counts_text()} numbers {_ORDER}, got {_short(dist)}"
        ) from exc
    if arr.ndim == 2 and 1 in arr.shape:
        arr = arr.reshape(-1)
    if arr.ndim != 1:
        raise ValueError(
            f"{name}: expected a flat sequence of {_counts_text()} OpenCV distortion coefficients "
            f"{_ORDER}, got an array of shape {arr.shape}"
        )
    if arr.size not in VALID_COEFFICIENT_COUNTS:
        raise ValueError(
            f"{name}: expected {_counts_text()} OpenCV distortion coefficients {_ORDER}, got {arr.size}: {arr.tolist()}"
        )
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}: distortion coefficients must be finite, got {arr.tolist()}")
    return arr


def tilt_projection_matrix(tau_x: float, tau_y: float) -> FloatArray:
    """The 3x3 tilted-sensor matrix of OpenCV's ``computeTiltProjectionMatrix`` (angles in radians).

    OpenCV (calib3d, ``distortion_model.hpp``) builds ``R = R_y(τy) R_x(τx)`` with
    ``R_x = [[1, 0, 0], [0, cos τx, sin τx], [0, -sin τx, cos τx]]`` and
    ``R_y = [[cos τy, 0, -sin τy], [0, 1, 0], [sin τy, 0, cos τy]]``, then the projection back onto the
    sensor ``P = [[R22, 0, -R02], [0, R22, -R12], [0, 0, 1]]`` and returns ``P @ R``. Applied to
    ``[x'', y'', 1]`` it gives homogeneous tilted coordinates (divide by the last component).
    """
    ctx, stx = math.cos(tau_x), math.sin(tau_x)
    cty, sty = math.cos(tau_y), math.sin(tau_y)
    rot_x = np.array([[1.0, 0.0, 0.0], [0.0, ctx, stx], [0.0, -stx, ctx]])
    rot_y = np.array([[cty, 0.0, -sty], [0.0, 1.0, 0.0], [sty, 0.0, cty]])
    rot_xy = rot_y @ rot_x
    proj_z = np.array(
        [
            [rot_xy[2, 2], 0.0, -rot_xy[0, 2]],
            [0.0, rot_xy[2, 2], -rot_xy[1, 2]],
            [0.0, 0.0, 1.0],
        ]
    )
    out: FloatArray = proj_z @ rot_xy
    return out


def _monotonic_radius(k1: float, k2: float, k3: float, k4: float, k5: float, k6: float) -> float:
    """Smallest r > 0 where ``g(r) = r N(r²) / D(r²)`` stops increasing, or +inf if it never does.

    With ``s = r²``, ``N(s) = 1 + k1 s + k2 s² + k3 s³`` and ``D(s) = 1 + k4 s + k5 s² + k6 s³``:
    ``g'(r) = [(N + 2 s N') D - 2 s N D'] / D²``. The numerator ``P(s)`` is a polynomial (degree <= 6)
    with ``P(0) = 1 > 0`` and ``D(0) = 1 > 0``, so ``g`` increases until the first positive root of
    ``P`` (the fit turns around) or of ``D`` (the rational model has a pole and jumps). Solving for
    the roots is exact up to round-off and has no search range, unlike sampling ``g``.
    """
    num = np.array([1.0, k1, k2, k3])
    den = np.array([1.0, k4, k5, k6])
    two_s = np.array([0.0, 2.0])
    p = npoly.polysub(
        npoly.polymul(npoly.polyadd(num, npoly.polymul(two_s, npoly.polyder(num))), den),
        npoly.polymul(two_s, npoly.polymul(num, npoly.polyder(den))),
    )
    s_min = math.inf
    for poly in (p, den):
        roots = npoly.polyroots(npoly.polytrim(poly))  # drop zero top coefficients: true degree
        for root in np.atleast_1d(roots):
            re, im = float(np.real(root)), float(np.imag(root))
            if re > 0.0 and abs(im) <= _REAL_ROOT_RTOL * abs(root):
                s_min = min(s_min, re)
    return math.sqrt(s_min)


class DistortionModel:
    """Validated OpenCV distortion coefficients with everything needed to apply them precomputed.

    Build it once (e.g. per camera) and call :meth:`distort_xy` in hot loops: the terms whose
    coefficients are all zero are skipped. Treat instances as immutable.
    """

    __slots__ = (
        "_core",
        "_k",
        "_kz",
        "_max_radius",
        "_radial",
        "_rational",
        "_tangential",
        "_thin_prism",
        "_tilt",
        "_tilt_inv",
        "_tilt_rows",
        "coefficients",
    )

    coefficients: FloatArray
    """The coefficients as given (read-only float64, 0/4/5/8/12/14 entries, OpenCV order)."""

    def __init__(self, dist: npt.ArrayLike | None = None) -> None:
        coeffs = as_distortion_coefficients(dist)
        coeffs.flags.writeable = False
        self.coefficients = coeffs
        padded = np.zeros(14, dtype=np.float64)
        padded[: coeffs.size] = coeffs
        # OpenCV order: k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4 τx τy.
        k: tuple[float, ...] = tuple(float(c) for c in padded)
        self._k = k
        self._radial = any(k[i] != 0.0 for i in (0, 1, 4))
        self._rational = any(k[i] != 0.0 for i in (5, 6, 7))
        self._tangential = k[2] != 0.0 or k[3] != 0.0
        self._thin_prism = any(c != 0.0 for c in k[8:12])
        self._tilt = k[12] != 0.0 or k[13] != 0.0
        m = tilt_projection_matrix(k[12], k[13])
        self._core = self._radial or self._rational or self._tangential or self._thin_prism
        self._kz: tuple[FloatArray, ...] = tuple(_const(c) for c in k)
        self._tilt_rows: tuple[FloatArray, ...] = tuple(_const(c) for c in m.reshape(-1))
        self._tilt_inv: FloatArray = np.asarray(np.linalg.inv(m), dtype=np.float64)
        self._max_radius = -1.0  # computed lazily: root finding costs ~50 µs and few callers need it

    @property
    def is_identity(self) -> bool:
        """True if all coefficients are zero (the model is the identity)."""
        return not (self._radial or self._rational or self._tangential or self._thin_prism or self._tilt)

    @property
    def has_tilt(self) -> bool:
        """True if the tilted-sensor angles τx, τy are not both zero."""
        return self._tilt

    @property
    def max_monotonic_radius(self) -> float:
        """Normalized radius where ``r ↦ r · radial(r)`` stops increasing (+inf if never); see module doc."""
        if self._max_radius < 0.0:
            k = self._k
            self._max_radius = _monotonic_radius(k[0], k[1], k[4], k[5], k[6], k[7])
        return self._max_radius

    def distort_xy(
        self, x: FloatArray, y: FloatArray, r2: FloatArray | None = None
    ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        """Distort normalized coordinates given as two equally shaped float64 arrays.

        ``r2`` may pass ``x² + y²`` if the caller has it already. Returns ``(x_d, y_d, w)``: the
        distorted normalized coordinates and, if the tilt model is active, its homogeneous denominator
        ``w`` *before* OpenCV's zero guard (``w <= 0`` means the tilted projection flipped; callers may
        treat such points as invalid), else ``None``. The returned arrays may be the inputs themselves
        when the model is the identity; do not modify them in place.
        """
        # Coefficients as 0-d arrays: numpy multiplies those into arrays ~40 % faster than Python floats,
        # which matters for the ~30-point batches of the render loop.
        k = self._kz
        if self._core:
            if r2 is None:
                r2 = x * x + y * y
            if self._radial or self._rational:
                # Horner form of OpenCV's cdist = 1 + k1 r² + k2 r⁴ + k3 r⁶ and 1 / icdist2.
                if self._radial:
                    radial = _ONE + r2 * (k[0] + r2 * (k[1] + r2 * k[4]))
                    if self._rational:
                        radial = radial / (_ONE + r2 * (k[5] + r2 * (k[6] + r2 * k[7])))
                else:
                    radial = _ONE / (_ONE + r2 * (k[5] + r2 * (k[6] + r2 * k[7])))
                xd = x * radial
                yd = y * radial
            else:
                xd, yd = x, y
            if self._tangential:
                xy2 = x * y
                xy2 = xy2 + xy2  # OpenCV's a1 = 2 x'y'
                xx = x * x
                yy = y * y
                xd = xd + (k[2] * xy2 + k[3] * (r2 + xx + xx))  # p1 a1 + p2 (r² + 2x'²)
                yd = yd + (k[2] * (r2 + yy + yy) + k[3] * xy2)  # p1 (r² + 2y'²) + p2 a1
            if self._thin_prism:
                r4 = r2 * r2
                xd = xd + (k[8] * r2 + k[9] * r4)
                yd = yd + (k[10] * r2 + k[11] * r4)
        else:
            xd, yd = x, y
        if not self._tilt:
            return xd, yd, None
        m = self._tilt_rows
        w = m[6] * xd + m[7] * yd + m[8]
        # OpenCV: "double invProj = vecTilt(2) ? 1./vecTilt(2) : 1;"
        inv_proj = _ONE / np.where(w != 0.0, w, _ONE)
        xt = (m[0] * xd + m[1] * yd + m[2]) * inv_proj
        yt = (m[3] * xd + m[4] * yd + m[5]) * inv_proj
        return xt, yt, w

    def distort(self, xy: npt.ArrayLike) -> FloatArray:
        """Distort normalized coordinates ``xy`` ``(..., 2)`` -> distorted normalized ``(..., 2)``."""
        pts = _as_xy(xy, "xy")
        xd, yd, _ = self.distort_xy(pts[..., 0], pts[..., 1])
        return np.stack([xd, yd], axis=-1)

    def _jacobian_core(
        self, x: FloatArray, y: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """Core (untilted) distortion and its 2x2 Jacobian: ``(xd, yd, dxd/dx, dxd/dy, dyd/dx, dyd/dy)``."""
        k = self._k
        s = x * x + y * y
        num = 1.0 + s * (k[0] + s * (k[1] + s * k[4]))
        dnum = k[0] + s * (2.0 * k[1] + s * 3.0 * k[4])
        den = 1.0 + s * (k[5] + s * (k[6] + s * k[7]))
        dden = k[5] + s * (2.0 * k[6] + s * 3.0 * k[7])
        c = num / den
        dc = (dnum * den - num * dden) / (den * den)  # d(radial)/d(r²)
        xd = x * c + 2.0 * k[2] * x * y + k[3] * (s + 2.0 * x * x) + k[8] * s + k[9] * s * s
        yd = y * c + k[2] * (s + 2.0 * y * y) + 2.0 * k[3] * x * y + k[10] * s + k[11] * s * s
        # d(r²)/dx = 2x, d(r²)/dy = 2y.
        jxx = c + 2.0 * x * x * dc + 2.0 * k[2] * y + 6.0 * k[3] * x + 2.0 * x * (k[8] + 2.0 * k[9] * s)
        jxy = 2.0 * x * y * dc + 2.0 * k[2] * x + 2.0 * k[3] * y + 2.0 * y * (k[8] + 2.0 * k[9] * s)
        jyx = 2.0 * x * y * dc + 2.0 * k[2] * x + 2.0 * k[3] * y + 2.0 * x * (k[10] + 2.0 * k[11] * s)
        jyy = c + 2.0 * y * y * dc + 6.0 * k[2] * y + 2.0 * k[3] * x + 2.0 * y * (k[10] + 2.0 * k[11] * s)
        return xd, yd, jxx, jxy, jyx, jyy

    def undistort(self, xy_d: npt.ArrayLike, iterations: int = 20, tol: float = 1e-12) -> FloatArray:
        """Invert :meth:`distort`: distorted normalized ``(..., 2)`` -> undistorted normalized ``(..., 2)``.

        The tilt is inverted exactly (as ``cv::undistortPoints`` does, with the inverse tilt matrix);
        the rest is solved by Newton's method with the analytic Jacobian, starting from the distorted
        point. OpenCV's fixed-point iteration converges only linearly and stalls for strong distortion;
        Newton converges quadratically wherever the mapping is locally invertible.

        Points for which no solution with residual ``<= tol`` (normalized units; 1e-12 is ~1e-9 px
        for focal lengths up to 1000 px) is found within ``iterations`` steps, or whose solution lies
        at or beyond :attr:`max_monotonic_radius` (there the inverse is not unique), come back as NaN.
        """
        if iterations < 1:
            raise ValueError(f"iterations must be >= 1, got {iterations}")
        pts = _as_xy(xy_d, "xy_d")
        shape = pts.shape
        flat = pts.reshape(-1, 2)
        xt, yt = flat[:, 0], flat[:, 1]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            if self._tilt:
                inv = self._tilt_inv
                w = inv[2, 0] * xt + inv[2, 1] * yt + inv[2, 2]
                inv_proj = 1.0 / np.where(w != 0.0, w, 1.0)  # as cv::undistortPoints
                xd = (inv[0, 0] * xt + inv[0, 1] * yt + inv[0, 2]) * inv_proj
                yd = (inv[1, 0] * xt + inv[1, 1] * yt + inv[1, 2]) * inv_proj
            else:
                xd, yd = xt, yt
            x, y = xd.copy(), yd.copy()
            if not self.is_identity and flat.shape[0] > 0:
                for _ in range(iterations):
                    fx, fy, jxx, jxy, jyx, jyy = self._jacobian_core(x, y)
                    ex, ey = fx - xd, fy - yd
                    det = jxx * jyy - jxy * jyx
                    dx = (jyy * ex - jxy * ey) / det
                    dy = (jxx * ey - jyx * ex) / det
                    x = x - dx
                    y = y - dy
                    step = np.maximum(np.abs(dx), np.abs(dy))
                    if (step <= 1e-15 * (1.0 + np.abs(x) + np.abs(y))).all():
                        break
                fx, fy, *_ = self._jacobian_core(x, y)
                resid = np.maximum(np.abs(fx - xd), np.abs(fy - yd))
                bad = ~(resid <= tol)
                r_max = self.max_monotonic_radius
                if math.isfinite(r_max):
                    bad |= ~(x * x + y * y < r_max * r_max)
                x = np.where(bad, np.nan, x)
                y = np.where(bad, np.nan, y)
        return np.stack([x, y], axis=-1).reshape(shape)


def _counts_text() -> str:
    return ", ".join(str(n) for n in VALID_COEFFICIENT_COUNTS[:-1]) + f" or {VALID_COEFFICIENT_COUNTS[-1]}"


def _short(value: object, limit: int = 120) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _as_xy(xy: npt.ArrayLike, name: str) -> FloatArray:
    try:
        arr = np.asarray(xy, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected a real array of shape (..., 2), got {_short(xy)}") from exc
    if arr.ndim == 0 or arr.shape[-1] != 2:
        raise ValueError(f"{name}: expected shape (..., 2), got shape {arr.shape}")
    return arr


def distort_normalized(xy: npt.ArrayLike, dist: npt.ArrayLike) -> FloatArray:
    """Apply OpenCV distortion ``dist`` to normalized coordinates ``xy`` ``(..., 2)`` -> ``(..., 2)``.

    ``xy`` are undistorted normalized image coordinates ``(X_c/Z_c, Y_c/Z_c)`` in the camera frame;
    the result is what OpenCV multiplies by ``fx, fy`` and offsets by ``cx, cy``. ``dist`` has 0, 4,
    5, 8, 12 or 14 coefficients in OpenCV order. For repeated calls build a :class:`DistortionModel`.
    """
    return DistortionModel(dist).distort(xy)


def undistort_normalized(
    xy_d: npt.ArrayLike, dist: npt.ArrayLike, iterations: int = 20, tol: float = 1e-12
) -> FloatArray:
    """Invert :func:`distort_normalized` ``(..., 2) -> (..., 2)``; see :meth:`DistortionModel.undistort`."""
    return DistortionModel(dist).undistort(xy_d, iterations=iterations, tol=tol)


def max_monotonic_radius(dist: npt.ArrayLike) -> float:
    """Normalized radius beyond which ``r ↦ r · radial(r)`` stops increasing, or +inf if it never does.

    ``radial(r) = (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)``. The first positive
    zero of the derivative, or the first pole of the rational term, is found analytically (no search
    range); rays with ``r = sqrt(x'² + y'²) >= max_monotonic_radius`` map to pixels that the fit
    cannot be trusted for and that may coincide with pixels of rays inside the field of view.
    Tangential, thin-prism and tilt terms are not considered: in calibrated lenses they are orders of
    magnitude smaller than the radial term.
    """
    return DistortionModel(dist).max_monotonic_radius
