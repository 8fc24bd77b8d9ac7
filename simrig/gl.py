"""Headless OpenGL for MuJoCo rendering, chosen before ``mujoco`` is imported.

MuJoCo picks its GL backend from ``MUJOCO_GL`` at import time. The simulated rig runs on servers and CI
machines without a display, so we default to EGL (Mesa renders on the CPU where there is no GPU) and
leave any value the user set alone (``osmesa`` or ``glfw`` work too). When no backend works, the
error names the packages that fix it rather than a bare ``GLError``.
"""

from __future__ import annotations

import os
from typing import Any

DEFAULT_BACKEND = "egl"
FIX_HINT = (
    "install a headless OpenGL: on Debian/Ubuntu `apt-get install -y libegl1 libegl-mesa0 libgl1-mesa-dri` "
    "(EGL; scripts/bootstrap.sh does this when run as root) or `libosmesa6` and set MUJOCO_GL=osmesa"
)


class SimRenderError(RuntimeError):
    """The simulator could not create an OpenGL context for rendering."""


def configure_gl() -> str:
    """Set ``MUJOCO_GL`` (and PyOpenGL's platform to match) unless the user chose; returns the backend."""
    backend = os.environ.setdefault("MUJOCO_GL", DEFAULT_BACKEND)
    if backend in ("egl", "osmesa"):
        os.environ.setdefault("PYOPENGL_PLATFORM", backend)
    return backend


configure_gl()

import mujoco  # noqa: E402  (must follow configure_gl)

__all__ = ["DEFAULT_BACKEND", "FIX_HINT", "SimRenderError", "configure_gl", "make_renderer", "mujoco"]


def make_renderer(model: Any, width: int, height: int) -> Any:
    """A ``mujoco.Renderer`` of ``width``×``height``, or :class:`SimRenderError` naming the fix."""
    try:
        return mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:  # mujoco raises several types (FatalError, RuntimeError, ImportError)
        backend = os.environ.get("MUJOCO_GL", "")
        raise SimRenderError(
            f"cannot render with MUJOCO_GL={backend!r} ({type(exc).__name__}: {exc}); {FIX_HINT}"
        ) from exc
