"""Mesh objects of a task file: an OBJ or STL file read with trimesh, checked, split into convex parts.

MuJoCo collides each mesh geom as its convex hull, so a mesh is split into its connected parts (a mug's body
and handle modelled as two closed shells) and every part becomes one geom; a part that is not convex
collides as its hull (documented in docs/tasks.md). The mesh is centred on its bounding box (the body
origin, as for the primitives) and must be closed, at most :data:`MAX_EXTENT` across and at most
:data:`MAX_FACES` triangles, so a task file cannot ask for something the simulator cannot handle.
"""

from __future__ import annotations

import functools
import io
from dataclasses import dataclass

import numpy as np

MAX_EXTENT = 0.3  # m: larger than anything a parallel gripper on this rig can carry
MAX_FACES = 20_000
MAX_PARTS = 16
MIN_EXTENT = 0.005


class MeshError(ValueError):
    """A mesh file that cannot be an object (unreadable, open, too large, too many parts)."""


@dataclass(frozen=True)
class MeshPart:
    stl: bytes  # binary STL of the part, centred like the whole mesh
    volume: float  # of its convex hull [m³]


@dataclass(frozen=True)
class MeshParts:
    parts: tuple[MeshPart, ...]
    bounds: tuple[tuple[float, float, float], tuple[float, float, float]]  # after centring [m]
    radius: float  # largest horizontal distance of a vertex from the z axis
    base_radius: float  # the same for vertices within 2 mm of the bottom


@functools.lru_cache(maxsize=32)
def load_mesh_parts(path: str, scale: float = 1.0) -> MeshParts:
    """Read ``path`` (OBJ/STL), scale to metres, centre on its bounding box, split into closed parts."""
    import trimesh

    try:
        loaded = trimesh.load(path, force="mesh", process=True)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise MeshError(f"cannot read mesh {path}: {exc}") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise MeshError(f"mesh {path} holds no triangles")
    mesh = loaded.copy()
    if len(mesh.faces) > MAX_FACES:
        raise MeshError(f"mesh {path} has {len(mesh.faces)} triangles (at most {MAX_FACES}); simplify it")
    mesh.apply_scale(scale)  # type: ignore[no-untyped-call]
    extent = mesh.extents
    if float(np.max(extent)) > MAX_EXTENT:
        raise MeshError(
            f"mesh {path} is {float(np.max(extent)):.3f} m across after scale {scale} (at most {MAX_EXTENT} m): "
            "check 'scale' (file units → metres)"
        )
    if float(np.min(extent)) < MIN_EXTENT:
        raise MeshError(f"mesh {path} is flat ({float(np.min(extent)) * 1000:.1f} mm thick, at least 5 mm)")
    if not mesh.is_watertight:
        raise MeshError(f"mesh {path} is not closed (it has open edges); an object must be a closed surface")
    mesh.apply_translation(-mesh.bounds.mean(axis=0))
    pieces = mesh.split(only_watertight=False)
    if len(pieces) > MAX_PARTS:
        raise MeshError(f"mesh {path} has {len(pieces)} separate parts (at most {MAX_PARTS})")
    parts = []
    for piece in pieces:
        buf = io.BytesIO()
        piece.export(buf, file_type="stl")
        parts.append(MeshPart(stl=buf.getvalue(), volume=float(piece.convex_hull.volume)))
    v = np.asarray(mesh.vertices)
    r = np.hypot(v[:, 0], v[:, 1])
    low = v[:, 2] < float(v[:, 2].min()) + 0.002
    lo, hi = mesh.bounds
    return MeshParts(
        parts=tuple(parts),
        bounds=((float(lo[0]), float(lo[1]), float(lo[2])), (float(hi[0]), float(hi[1]), float(hi[2]))),
        radius=float(r.max()),
        base_radius=float(r[low].max()) if bool(low.any()) else 0.0,
    )
