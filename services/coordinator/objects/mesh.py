"""Light mesh validation for uploads: does it load, and is it a solid we can grasp?

The workers do the full pybullet preparation (collision shapes, inertia); the coordinator
only refuses what can never work, early and with a message naming the problem, so a bad
upload fails at POST time instead of on every worker.
"""

from __future__ import annotations

import io
import math

import numpy as np
import trimesh
from graspscape.services.coordinator.errors import InvalidInput, UnsupportedMediaType
from pydantic import BaseModel
from scipy.spatial import ConvexHull, QhullError

MESH_FORMATS = ("obj", "stl", "ply", "glb", "off")
# A grasped object larger than this is surely in millimetres, not metres.
MAX_EXTENT_M = 5.0


def _invalid(message: str) -> InvalidInput:
    return InvalidInput(message, loc=("body", "file"))


class MeshInfo(BaseModel):
    vertices: int
    faces: int
    watertight: bool
    volume_m3: float
    extents_m: tuple[float, float, float]


def mesh_format(filename: str | None) -> str:
    suffix = (filename or "").rsplit(".", 1)[-1].lower() if "." in (filename or "") else ""
    if suffix not in MESH_FORMATS:
        raise UnsupportedMediaType(
            f"mesh file {filename!r} has an unsupported format; use one of "
            + ", ".join(f".{f}" for f in MESH_FORMATS)
        )
    return suffix


def validate_mesh(data: bytes, fmt: str, *, scale: float = 1.0) -> MeshInfo:
    if not data:
        raise _invalid("mesh file is empty")
    try:
        mesh = trimesh.load(io.BytesIO(data), file_type=fmt, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for malformed files
        raise _invalid(f"mesh could not be read as .{fmt}: {exc}") from exc
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise _invalid("mesh has no faces")
    vertices = np.asarray(mesh.vertices, dtype=float)
    if not np.isfinite(vertices).all():
        raise _invalid("mesh has non-finite vertex coordinates (NaN or infinity)")
    # Loaded unprocessed so NaNs are seen above; STL repeats vertices per face, merge them so
    # a closed surface reads as watertight.
    mesh.merge_vertices()
    extents = tuple(float(e) * scale for e in mesh.extents)
    if min(extents) <= 1e-9:
        raise _invalid("mesh is flat: zero extent along one axis, so zero volume")
    if max(extents) > MAX_EXTENT_M:
        raise _invalid(
            f"mesh is {max(extents):.3g} m across at scale {scale}; meshes are in metres "
            "(set 'scale', e.g. 0.001 for millimetres)"
        )
    if mesh.is_watertight:
        volume = abs(float(mesh.volume))
    else:
        # An open mesh has no enclosed volume; its convex hull tells a solid from a flat sheet.
        try:
            volume = float(ConvexHull(vertices).volume)
        except QhullError:
            volume = 0.0
    volume *= scale**3
    if not math.isfinite(volume) or volume <= 1e-15:
        raise _invalid("mesh has zero volume")
    return MeshInfo(
        vertices=len(mesh.vertices),
        faces=len(mesh.faces),
        watertight=bool(mesh.is_watertight),
        volume_m3=volume,
        extents_m=extents,  # type: ignore[arg-type]
    )
