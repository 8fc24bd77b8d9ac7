"""Batched forward kinematics of Universal Robots arms from their classic DH tables.

Frames: index 0 is the UR base frame (see :mod:`pilworld.kinematics.ur_dh`), index ``i`` the DH frame
of link ``i`` and index 6 the tool flange. An optional ``tcp`` transform ``T_flange_tcp`` maps the
flange to a tool centre point (gripper fingertips, camera, ...).

All functions take joint vectors ``q`` of shape ``(..., 6)`` in radians with arbitrary leading batch
dimensions and are fully vectorised over the batch (the only Python loop runs over the six joints),
so 1e5 configurations take a few tens of milliseconds. Inputs may be float32 (e.g. from a policy) but
are computed in float64: a float32 chain is only good to ~0.1 mm at a 1 m reach.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from pilworld.geometry import FloatArray, as_finite_array, is_rigid_transform
from pilworld.kinematics.ur_dh import DHParams, dh_params

__all__ = ["UrArm", "fk", "fk_flange", "fk_frames", "joint_transforms"]


def _resolve(dh: DHParams | str) -> DHParams:
    # Accepting a model name keeps call sites short (fk(q, "ur5e")) without a second API.
    return dh_params(dh) if isinstance(dh, str) else dh


def _validate_q(q: npt.ArrayLike) -> FloatArray:
    """``q`` as float64 ``(..., 6)`` joint angles in radians; ValueError naming ``q`` otherwise."""
    return as_finite_array(q, "q", (6,))


def _validate_tcp(tcp: npt.ArrayLike | None) -> FloatArray | None:
    """``tcp`` as a float64 ``(4, 4)`` rigid transform, or None."""
    if tcp is None:
        return None
    arr = np.asarray(tcp, dtype=np.float64)
    if arr.shape != (4, 4):
        raise ValueError(f"tcp must be a single (4, 4) flange->TCP transform; got shape {arr.shape}")
    # A scaled or sheared TCP would silently distort every pose, so insist on a rigid motion.
    if not is_rigid_transform(arr):
        raise ValueError(f"tcp must be a finite rigid transform (orthonormal R, det +1, last row 0 0 0 1); got\n{arr}")
    return arr


def joint_transforms(q: npt.ArrayLike, dh: DHParams | str) -> FloatArray:
    """The six DH link transforms ``T_{i-1,i}`` for joints ``q`` ``(..., 6)`` -> ``(..., 6, 4, 4)``.

    ``T_i = Rz(q_i) @ Tz(d_i) @ Tx(a_i) @ Rx(alpha_i)``, written out in closed form.
    """
    params = _resolve(dh)
    theta = _validate_q(q)
    d, a, alpha = params.d_array, params.a_array, params.alpha_array
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)  # (6,), broadcast against the batch
    out = np.zeros((*theta.shape, 4, 4), dtype=np.float64)
    out[..., 0, 0] = ct
    out[..., 0, 1] = -st * ca
    out[..., 0, 2] = st * sa
    out[..., 0, 3] = a * ct
    out[..., 1, 0] = st
    out[..., 1, 1] = ct * ca
    out[..., 1, 2] = -ct * sa
    out[..., 1, 3] = a * st
    out[..., 2, 1] = sa
    out[..., 2, 2] = ca
    out[..., 2, 3] = d
    out[..., 3, 3] = 1.0
    return out


def fk_frames(q: npt.ArrayLike, dh: DHParams | str) -> FloatArray:
    """Base-frame poses of all DH frames, ``(..., 7, 4, 4)``: index 0 is identity, 6 the flange."""
    links = joint_transforms(q, dh)
    frames = np.empty((*links.shape[:-3], 7, 4, 4), dtype=np.float64)
    frames[..., 0, :, :] = np.eye(4)
    for i in range(6):
        frames[..., i + 1, :, :] = frames[..., i, :, :] @ links[..., i, :, :]
    return frames


def fk_flange(q: npt.ArrayLike, dh: DHParams | str) -> FloatArray:
    """Flange pose in the base frame, ``T_base_flange`` ``(..., 4, 4)``, for joints ``q`` ``(..., 6)``."""
    links = joint_transforms(q, dh)
    pose = links[..., 0, :, :]
    for i in range(1, 6):
        pose = pose @ links[..., i, :, :]
    return pose


def fk(q: npt.ArrayLike, dh: DHParams | str, tcp: npt.ArrayLike | None = None) -> FloatArray:
    """TCP pose in the base frame ``(..., 4, 4)``: ``T_base_flange(q) @ tcp``.

    Args:
        q: joint angles ``(..., 6)`` [rad].
        dh: DH table or model name (e.g. ``"ur5e"``).
        tcp: optional ``(4, 4)`` rigid ``T_flange_tcp``; None means the flange itself.
    """
    tcp_arr = _validate_tcp(tcp)
    pose = fk_flange(q, dh)
    return pose if tcp_arr is None else pose @ tcp_arr


def _identity() -> FloatArray:
    return np.eye(4, dtype=np.float64)


@dataclass(frozen=True, eq=False)  # eq=False: dataclass __eq__ on an ndarray field is ambiguous
class UrArm:
    """A UR arm model: its DH table plus a fixed flange->TCP transform ``tcp`` ``(4, 4)``."""

    dh: DHParams
    tcp: FloatArray = field(default_factory=_identity)

    def __post_init__(self) -> None:
        tcp = _validate_tcp(self.tcp)
        assert tcp is not None  # the field is never None; narrows the type for mypy
        tcp = tcp.copy()
        tcp.flags.writeable = False  # the arm is frozen; so is its TCP
        object.__setattr__(self, "tcp", tcp)

    @classmethod
    def from_model(cls, name: str, tcp: npt.ArrayLike | None = None) -> UrArm:
        """Build from a model name (``"ur5e"``, ``"UR10"``, ...) and an optional ``(4, 4)`` TCP."""
        return cls(dh_params(name), _identity() if tcp is None else np.asarray(tcp, dtype=np.float64))

    def fk(self, q: npt.ArrayLike) -> FloatArray:
        """TCP pose ``T_base_tcp`` ``(..., 4, 4)`` for joints ``q`` ``(..., 6)``."""
        return fk_flange(q, self.dh) @ self.tcp

    def frames(self, q: npt.ArrayLike) -> FloatArray:
        """All DH frames in the base frame ``(..., 7, 4, 4)`` (flange last, TCP not included)."""
        return fk_frames(q, self.dh)

    def tcp_position(self, q: npt.ArrayLike) -> FloatArray:
        """TCP position in the base frame ``(..., 3)`` [m] for joints ``q`` ``(..., 6)``."""
        return self.fk(q)[..., :3, 3]
