"""Meshes of the object-validation findings (issue #19, finding 6), made with trimesh.

Shared by the worker's preparation tests and the REST upload tests, so both sides are shown
the very same bad objects.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pybullet_data
import trimesh

RAW_BUNNY = Path(pybullet_data.getDataPath()) / "bunny.obj"  # about 2 m across as shipped


def two_bodies() -> trimesh.Trimesh:
    """Two 5 cm cubes 30 cm apart: one mesh, two bodies."""
    a = trimesh.creation.box(extents=(0.05, 0.05, 0.05))
    b = a.copy()
    b.apply_translation((0.35, 0.0, 0.0))
    return trimesh.util.concatenate([a, b])


def open_tube() -> trimesh.Trimesh:
    """A 6 cm × 10 cm cylinder with its end caps cut off: open at both ends."""
    can = trimesh.creation.cylinder(radius=0.03, height=0.1, sections=32)
    side = np.abs(can.face_normals[:, 2]) < 0.5
    return trimesh.Trimesh(can.vertices, can.faces[side], process=False)


def box(size_m: float) -> trimesh.Trimesh:
    """A closed cube `size_m` across (10 km, 1 µm, ...)."""
    return trimesh.creation.box(extents=(size_m, size_m, size_m))


def bunny_in_mm() -> bytes:
    """The Stanford bunny as a 10 cm object written in millimetres (about 100 units)."""
    bunny = trimesh.load(RAW_BUNNY, force="mesh")
    bunny.apply_scale(0.05 * 1000.0)
    return obj_bytes(bunny)


def obj_bytes(mesh: trimesh.Trimesh) -> bytes:
    return trimesh.exchange.obj.export_obj(mesh, include_normals=False).encode()


def stl_bytes(mesh: trimesh.Trimesh) -> bytes:
    return mesh.export(file_type="stl")
