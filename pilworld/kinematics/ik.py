"""Closed-form inverse kinematics of Universal Robots arms (classic DH tables of :mod:`.ur_dh`).

Method: the standard 8-solution analytic IK of the UR family, as derived by K. P. Hawkins, "Analytic
Inverse Kinematics for the Universal Robots UR-5/UR-10 Arms" (Georgia Tech, 2013) and implemented in
the ROS ``ur_kinematics`` package, written here directly in the base frame:

* the wrist-2 centre ``p5 = p - d6 z6`` lies at distance ``d4`` from the plane of the shoulder, elbow
  and wrist-1 axes, which fixes ``q1`` up to the shoulder left/right branch;
* ``z1 . z6 = cos q5`` gives ``q5`` up to the wrist up/down branch, and ``z1`` expressed in the flange
  frame, ``(s5 c6, -s5 s6, c5)``, gives ``q6``;
* what remains is a planar 2R arm (``a2``, ``a3``) reaching the wrist-1 centre: ``q3`` up to the
  elbow branch by the law of cosines, then ``q2``, and ``q4 = (q2 + q3 + q4) - q2 - q3``;
* at the wrist singularity ``sin q5 = 0`` Hawkins leaves ``q6`` free; here it is chosen deterministically
  (0, or the seed's) but moved, if needed, to where the elbow can still reach (:func:`_singular_q6`).

Using closed forms instead of iterating from a seed is what makes the answer global (every branch,
no local minima) and fast enough for a scripted policy. :func:`ik_nearest` then resolves branches and
``2 pi`` multiples against a seed and the joint limits, and polishes with damped Newton steps so the
result is exact to ~1e-12 even after rounding in the closed form.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Final

import numpy as np
import numpy.typing as npt

from pilworld.geometry import FloatArray, as_finite_array, invert_transform
from pilworld.kinematics.ur_dh import DHParams, dh_params

__all__ = ["IK_JOINT_WEIGHTS", "IKError", "ik_all", "ik_nearest", "ik_solve"]

# Joint-space metric of ik_nearest: moving the base, shoulder or elbow swings the whole arm (more mass,
# a much larger swept volume, more collision risk) than moving a wrist joint, so they cost more.
IK_JOINT_WEIGHTS: Final[tuple[float, ...]] = (3.0, 3.0, 2.0, 1.0, 1.0, 1.0)

_TWO_PI: Final = 2.0 * math.pi
_RIGID_TOL: Final = 1e-6  # same tolerance as geometry.is_rigid_transform
_REACH_TOL: Final = 1e-10  # acos arguments this far beyond +-1 are rounding, not unreachable targets
_SINGULAR_S5: Final = 1e-10  # |sin q5| below this: axes 2, 3, 4, 6 parallel, q6 is not fixed by the pose
_DUPLICATE_TOL: Final = 1e-9  # solutions closer than this (rad, per joint) are reported once
_POLISH_TOL: Final = 1e-12  # stop Newton once position [m] and rotation [rad] errors are below this
_DAMPING_SQ: Final = 1e-12  # DLS damping: negligible when regular, bounded steps at singularities


class IKError(ValueError):
    """No joint solution: the target is out of reach or every solution violates the joint limits."""


@lru_cache(maxsize=64)
def _ur_lengths(dh: DHParams) -> tuple[float, float, float, float, float, float]:
    """``(d1, a2, a3, d4, d5, d6)``; checks once per table that the closed form applies to it."""
    ur_alpha = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
    twists_ok = all(abs(x - y) <= 1e-12 for x, y in zip(dh.alpha, ur_alpha, strict=True))
    zeros_ok = not any((dh.a[0], dh.a[3], dh.a[4], dh.a[5], dh.d[1], dh.d[2])) and all((dh.a[1], dh.a[2], dh.d[4]))
    if not (twists_ok and zeros_ok):
        raise ValueError(f"dh must have the Universal Robots DH structure for closed-form IK; got {dh!r}")
    return dh.d[0], dh.a[1], dh.a[2], dh.d[3], dh.d[4], dh.d[5]


def _rigid(T: npt.ArrayLike, name: str) -> FloatArray:
    """``T`` as a finite float64 ``(4, 4)`` rigid transform; a rotation off by rounding is re-orthonormalised."""
    arr = as_finite_array(T, name, (4, 4))
    if arr.shape != (4, 4):
        raise ValueError(f"{name} must be a single (4, 4) transform; got shape {arr.shape}")
    R = arr[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > _RIGID_TOL or np.linalg.det(R) <= 0 or np.abs(arr[3] - (0.0, 0.0, 0.0, 1.0)).max() > _RIGID_TOL:
        raise ValueError(f"{name} must be a rigid transform (orthonormal R, det +1, last row 0 0 0 1); got\n{arr}")
    if err > 1e-13:
        # An exact solution only exists for an exact rotation: use the nearest one (polar decomposition).
        u, _, vt = np.linalg.svd(R)
        arr = arr.copy()
        arr[:3, :3] = u @ vt
    return arr


def _flange_target(T_base_tcp: npt.ArrayLike, T_flange_tcp: npt.ArrayLike | None) -> FloatArray:
    T = _rigid(T_base_tcp, "T_base_tcp")
    return T if T_flange_tcp is None else T @ invert_transform(_rigid(T_flange_tcp, "T_flange_tcp"))


def _wrap(q: FloatArray) -> FloatArray:
    """Angles wrapped to ``(-pi, pi]``."""
    return np.pi - np.mod(np.pi - q, _TWO_PI)


def _singular_q6(
    T: FloatArray, p5: FloatArray, c1: FloatArray, s1: FloatArray, lengths: tuple[float, ...], preferred: float
) -> FloatArray:
    """``q6`` per shoulder branch ``(2,)`` for a singular wrist: ``preferred`` if the elbow can reach, else the nearest.

    With ``z6 = +-z1`` the elbow, wrist-1 and wrist-3 axes are all parallel to the shoulder axis, so the
    pose fixes only a one-parameter family: choosing ``q6`` places the wrist-1 centre ``p4 = p5 + d5 e``
    with ``e = s6 x6 + c6 y6`` on a circle around ``p5`` in the arm plane, and ``q2, q3, q4`` follow. That
    ``p4`` must stay in the annulus the 2R arm ``a2, a3`` reaches, i.e. ``sin(q6 + g)`` in ``[lo, hi]``.
    """
    d1, a2, a3, d5 = lengths
    # Arm-plane coordinates (along x1 = (c1, s1, 0) and base z) of p5 (from the shoulder) and of x6, y6.
    wu, wv = p5[0] * c1 + p5[1] * s1, np.full(2, p5[2] - d1)
    w_x = wu * (T[0, 0] * c1 + T[1, 0] * s1) + wv * T[2, 0]
    w_y = wu * (T[0, 1] * c1 + T[1, 1] * s1) + wv * T[2, 1]
    g, w2 = np.arctan2(w_y, w_x), wu * wu + wv * wv
    scale = 2.0 * d5 * np.maximum(np.sqrt(w2), 1e-15)
    lo = ((abs(a2) - abs(a3)) ** 2 - w2 - d5 * d5) / scale
    hi = ((abs(a2) + abs(a3)) ** 2 - w2 - d5 * d5) / scale
    theta = preferred + g
    sin_theta = np.sin(theta)
    # Keep `preferred` where the elbow reaches; else take the nearer angle whose sine is the violated bound
    # (elbow exactly straight or folded). A bound beyond +-1 means unreachable: _analytic's c3 check drops it.
    bound = np.clip(np.where(sin_theta < lo, lo, hi), -1.0, 1.0)
    options = np.stack([np.arcsin(bound), np.pi - np.arcsin(bound)])
    nearest = options[np.argmin(np.abs(_wrap(options - theta)), axis=0), np.arange(2)]
    return np.where((sin_theta >= lo) & (sin_theta <= hi), preferred, _wrap(nearest - g))


def _analytic(T: FloatArray, dh: DHParams, q6_singular: float) -> FloatArray:
    """All distinct closed-form solutions ``(N, 6)``, ``N <= 8``, of the flange target ``T``."""
    d1, a2, a3, d4, d5, d6 = _ur_lengths(dh)
    x6, y6, z6, p = T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3]
    p5 = p - d6 * z6
    r = math.hypot(p5[0], p5[1])
    if r <= abs(d4) * (1.0 - _REACH_TOL):  # wrist centre inside the cylinder the shoulder offset sweeps
        return np.empty((0, 6), dtype=np.float64)
    phi = math.acos(max(-1.0, min(d4 / r, 1.0)))
    q1 = math.atan2(p5[1], p5[0]) + math.pi / 2 + np.array([phi, -phi])  # shoulder branch, (2,)
    c1, s1 = np.cos(q1), np.sin(q1)
    # z1 = (s1, -c1, 0) is the common direction of the shoulder, elbow and wrist-1 axes.
    # z1 in flange coordinates is (s5 c6, -s5 s6, c5); atan2 keeps q5 accurate near 0 where acos is not.
    xz, yz = (x6[0] * s1 - x6[1] * c1)[:, None], (y6[0] * s1 - y6[1] * c1)[:, None]
    q5 = np.arctan2(np.hypot(xz, yz), (z6[0] * s1 - z6[1] * c1)[:, None]) * np.array([1.0, -1.0])  # (2, 2)
    c5, s5 = np.cos(q5), np.sin(q5)
    singular = np.abs(s5) < _SINGULAR_S5
    sign = np.where(singular, 0.0, np.sign(s5))  # multiply by sign(s5) instead of dividing by s5
    q6 = np.arctan2(-yz * sign, xz * sign)
    if singular.any():
        q6 = np.where(singular, _singular_q6(T, p5, c1, s1, (d1, a2, a3, d5), q6_singular)[:, None], q6)
    c6, s6 = np.cos(q6), np.sin(q6)
    # Wrist-1 frame axes from the flange axes: x4 = c5 c6 x6 - c5 s6 y6 - s5 z6, z4 = -s6 x6 - c6 y6.
    x4 = (c5 * c6)[..., None] * x6 - (c5 * s6)[..., None] * y6 - s5[..., None] * z6
    p4 = p5 + d5 * (s6[..., None] * x6 + c6[..., None] * y6)  # wrist-1 centre, (2, 2, 3)
    c1b, s1b = c1[:, None], s1[:, None]
    q234 = np.arctan2(x4[..., 2], x4[..., 0] * c1b + x4[..., 1] * s1b)  # y1 is the base z axis
    px, py = p4[..., 0] * c1b + p4[..., 1] * s1b, p4[..., 2] - d1  # wrist-1 centre in the arm plane
    c3 = (px * px + py * py - a2 * a2 - a3 * a3) / (2.0 * a2 * a3)
    reach = np.abs(c3) <= 1.0 + _REACH_TOL
    q3 = np.arccos(np.clip(c3, -1.0, 1.0))[..., None] * np.array([1.0, -1.0])  # elbow branch, (2, 2, 2)
    q2 = np.arctan2(py, px)[..., None] - np.arctan2(a3 * np.sin(q3), a2 + a3 * np.cos(q3))
    q4 = q234[..., None] - q2 - q3
    grid = np.empty((2, 2, 2, 6))
    grid[..., 0], grid[..., 1], grid[..., 2], grid[..., 3] = q1[:, None, None], q2, q3, q4
    grid[..., 4], grid[..., 5] = q5[..., None], q6[..., None]
    sols = _wrap(grid[reach].reshape(-1, 6))  # reach is per (q1, q5) branch; both elbows share it
    if len(sols) < 2:
        return sols
    # Branches coincide at the workspace boundary and at wrist singularities; report each pose once.
    diff = np.abs(_wrap(sols[:, None, :] - sols[None, :, :])).max(axis=-1)
    keep = ~np.any(np.tril(diff < _DUPLICATE_TOL, k=-1), axis=1)
    return np.ascontiguousarray(sols[keep])


def ik_all(T_base_tcp: npt.ArrayLike, dh: DHParams | str, T_flange_tcp: npt.ArrayLike | None = None) -> FloatArray:
    """Every joint solution ``(N, 6)`` [rad], ``0 <= N <= 8``, wrapped to ``(-pi, pi]``, of a TCP pose.

    Args:
        T_base_tcp: target ``(4, 4)`` rigid transform of the TCP in the UR base frame.
        dh: DH table or model name (``"ur5e"``, ...) of an arm with the UR structure.
        T_flange_tcp: optional ``(4, 4)`` flange->TCP transform; None means the target is the flange.

    An unreachable target gives a ``(0, 6)`` array. At a wrist singularity (``sin q5 = 0``) the pose
    fixes only a one-parameter family of solutions; ``q6 = 0`` is returned when the elbow can reach with
    it, otherwise the ``q6`` nearest to 0 it can reach (see :func:`_singular_q6`). Joint limits are not
    applied here (every solution also has ``2 pi``-shifted twins); use :func:`ik_nearest` for that.
    """
    params = dh_params(dh) if isinstance(dh, str) else dh
    return _analytic(_flange_target(T_base_tcp, T_flange_tcp), params, 0.0)


def _fk_jacobian(q: FloatArray, dh: DHParams) -> tuple[FloatArray, FloatArray]:
    """Flange pose ``(4, 4)`` and base-frame geometric Jacobian ``(6, 6)`` ([v; w] rows) at ``q``."""
    T = np.eye(4)
    axes, origins = np.empty((6, 3)), np.empty((6, 3))
    for i in range(6):  # same products as fk.joint_transforms, so both agree to the last bit
        ct, st = math.cos(q[i]), math.sin(q[i])
        ca, sa = math.cos(dh.alpha[i]), math.sin(dh.alpha[i])
        axes[i], origins[i] = T[:3, 2], T[:3, 3]
        link = [[ct, -st * ca, st * sa, dh.a[i] * ct], [st, ct * ca, -ct * sa, dh.a[i] * st], [0.0, sa, ca, dh.d[i]]]
        T = T @ np.array([*link, [0.0, 0.0, 0.0, 1.0]])
    J = np.empty((6, 6))
    lever = T[:3, 3] - origins
    J[:3] = (axes[:, [1, 2, 0]] * lever[:, [2, 0, 1]] - axes[:, [2, 0, 1]] * lever[:, [1, 2, 0]]).T  # z_i x (p - o_i)
    J[3:] = axes.T
    return T, J


def _pose_error(T: FloatArray, target: FloatArray) -> FloatArray:
    """6-D error ``[dp; dw]`` taking ``T`` to ``target``; ``dw`` is the small-angle rotation vector."""
    M = target[:3, :3] @ T[:3, :3].T
    dw = 0.5 * np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])
    return np.concatenate([target[:3, 3] - T[:3, 3], dw])


def _polish(q: FloatArray, target: FloatArray, dh: DHParams, lower: FloatArray, upper: FloatArray) -> FloatArray:
    """Up to 3 damped-least-squares Newton steps on the full pose error; never returns a worse ``q``."""
    T, J = _fk_jacobian(q, dh)
    err = _pose_error(T, target)
    best = float(np.abs(err).max())
    for _ in range(3):
        if best < _POLISH_TOL:
            break
        step = J.T @ np.linalg.solve(J @ J.T + _DAMPING_SQ * np.eye(6), err)
        q_new = np.clip(q + step, lower, upper)
        T, J = _fk_jacobian(q_new, dh)
        err = _pose_error(T, target)
        if float(np.abs(err).max()) >= best:
            break
        q, best = q_new, float(np.abs(err).max())
    return q


def _nearest(
    T_base_tcp: npt.ArrayLike,
    dh: DHParams | str,
    q_seed: npt.ArrayLike,
    T_flange_tcp: npt.ArrayLike | None,
    lower: npt.ArrayLike | None,
    upper: npt.ArrayLike | None,
    weights: npt.ArrayLike | None,
) -> tuple[FloatArray | None, int]:
    """``(q or None, number of solutions ignoring limits)`` for :func:`ik_nearest`."""
    params = dh_params(dh) if isinstance(dh, str) else dh
    target = _flange_target(T_base_tcp, T_flange_tcp)
    seed = as_finite_array(q_seed, "q_seed", (6,))
    lo = params.lower_limits if lower is None else as_finite_array(lower, "lower", (6,))
    hi = params.upper_limits if upper is None else as_finite_array(upper, "upper", (6,))
    w = np.asarray(IK_JOINT_WEIGHTS) if weights is None else as_finite_array(weights, "weights", (6,))
    for name, arr in (("q_seed", seed), ("lower", lo), ("upper", hi), ("weights", w)):
        if arr.shape != (6,):
            raise ValueError(f"{name} must have shape (6,); got {arr.shape}")
    if np.any(lo > hi) or np.any(w <= 0):
        raise ValueError(f"need lower <= upper and weights > 0; got lower={lo}, upper={hi}, weights={w}")
    # At a wrist singularity prefer q6 where the seed has it: the rest of the family then stays nearby.
    sols = _analytic(target, params, float(_wrap(seed[5:6])[0]))
    if len(sols) == 0:
        return None, 0
    # The weighted distance is separable per joint, so the best 2 pi multiple of each joint is the one
    # nearest the seed, clipped to the multiples that stay inside the limits.
    k_lo, k_hi = np.ceil((lo - sols) / _TWO_PI), np.floor((hi - sols) / _TWO_PI)
    cand = sols + _TWO_PI * np.clip(np.round((seed - sols) / _TWO_PI), k_lo, k_hi)
    cost = np.where(np.all(k_lo <= k_hi, axis=1), (w * (cand - seed) ** 2).sum(axis=1), np.inf)
    best = int(np.argmin(cost))
    if not np.isfinite(cost[best]):
        return None, len(sols)
    return _polish(np.clip(cand[best], lo, hi), target, params, lo, hi), len(sols)


def ik_nearest(
    T_base_tcp: npt.ArrayLike,
    dh: DHParams | str,
    q_seed: npt.ArrayLike,
    T_flange_tcp: npt.ArrayLike | None = None,
    lower: npt.ArrayLike | None = None,
    upper: npt.ArrayLike | None = None,
    *,
    weights: npt.ArrayLike | None = None,
) -> FloatArray | None:
    """The solution ``(6,)`` [rad] within ``[lower, upper]`` closest to ``q_seed``, or None if there is none.

    Candidates are all closed-form solutions and their ``2 pi``-shifted equivalents; "closest" is the
    weighted squared distance ``sum w_j (q_j - seed_j)^2`` with ``weights`` defaulting to
    :data:`IK_JOINT_WEIGHTS` (base and shoulder cost 3x, elbow 2x a wrist joint). Limits default to
    the DH table's. The winner is polished with damped Newton steps, so it reproduces the target to
    ~1e-12 m / rad (for a target whose rotation was exact; see :func:`ik_all` for the arguments).
    """
    return _nearest(T_base_tcp, dh, q_seed, T_flange_tcp, lower, upper, weights)[0]


def ik_solve(
    T_base_tcp: npt.ArrayLike,
    dh: DHParams | str,
    q_seed: npt.ArrayLike,
    T_flange_tcp: npt.ArrayLike | None = None,
    lower: npt.ArrayLike | None = None,
    upper: npt.ArrayLike | None = None,
    *,
    weights: npt.ArrayLike | None = None,
) -> FloatArray:
    """Like :func:`ik_nearest` but raises :class:`IKError` (naming the target and why) instead of returning None."""
    q, n_solutions = _nearest(T_base_tcp, dh, q_seed, T_flange_tcp, lower, upper, weights)
    if q is not None:
        return q
    xyz = np.asarray(T_base_tcp, dtype=np.float64)[:3, 3]
    where = f"target TCP position {np.array2string(xyz, precision=4)} m (base frame)"
    name = dh if isinstance(dh, str) else dh.name
    if n_solutions == 0:
        raise IKError(f"{where} is unreachable for {name}: outside the workspace or at its singular core")
    raise IKError(f"{where} is reachable for {name} by {n_solutions} solution(s), but none is within the joint limits")
