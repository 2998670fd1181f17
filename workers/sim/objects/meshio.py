"""Reading, checking and writing meshes (pure trimesh/numpy, no pybullet).

Meshes are loaded unprocessed first so that NaN coordinates are seen before trimesh's
processing silently drops or merges them; only then are vertices merged.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import trimesh

from .errors import (
    EmptyMesh,
    NonFiniteVertices,
    NotWatertight,
    TooManyFaces,
    UnreadableMesh,
    ZeroVolume,
)

DEFAULT_MAX_FACES = 200_000
MESH_SUFFIXES = (".obj", ".stl", ".ply", ".glb", ".gltf", ".off")
# Below this size (m) along any axis a mesh is a sheet for our purposes.
_MIN_EXTENT_M = 1e-5
_MIN_VOLUME_M3 = 1e-12


def load_mesh_file(path: Path, label: str, max_faces: int = DEFAULT_MAX_FACES) -> trimesh.Trimesh:
    """Load one file as a single unprocessed Trimesh (scenes are concatenated)."""
    if not path.is_file():
        raise UnreadableMesh(f"{label}: mesh file not found: {path}")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise UnreadableMesh(
            f"{label}: unsupported mesh type '{path.suffix}' (use one of {MESH_SUFFIXES})"
        )
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise UnreadableMesh(f"{label}: cannot parse {path.name}: {exc}") from exc
    if not isinstance(mesh, trimesh.Trimesh):
        raise UnreadableMesh(f"{label}: {path.name} holds no triangle mesh")
    check_basic(mesh, label, max_faces)
    return mesh


def check_basic(mesh: trimesh.Trimesh, label: str, max_faces: int = DEFAULT_MAX_FACES) -> None:
    """Checks that need no volume: non-empty, finite, within the face limit, not flat."""
    if len(mesh.vertices) == 0 or len(mesh.faces) == 0:
        raise EmptyMesh(f"{label}: mesh is empty (no vertices or no faces)")
    if not np.all(np.isfinite(mesh.vertices)):
        bad = int((~np.isfinite(mesh.vertices)).any(axis=1).sum())
        raise NonFiniteVertices(f"{label}: {bad} vertices have NaN or infinite coordinates")
    if len(mesh.faces) > max_faces:
        raise TooManyFaces(
            f"{label}: {len(mesh.faces)} faces exceed the limit of {max_faces}; simplify it"
        )
    extents = mesh.vertices.max(axis=0) - mesh.vertices.min(axis=0)
    if float(extents.min()) < _MIN_EXTENT_M:
        raise ZeroVolume(f"{label}: mesh is flat (extents {np.round(extents, 6).tolist()} m)")


def close_planar_holes(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Cap every boundary loop with a fan around its centroid.

    Used only for sources we vouch for (pybullet_data's mug, whose handle ends are open
    where they sink into the wall); user meshes must arrive watertight.
    """
    edges = mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.sort(edges, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    boundary = edges[counts[inverse.ravel()] == 1]
    if len(boundary) == 0:
        return mesh
    nxt = {int(a): int(b) for a, b in boundary}
    vertices = [mesh.vertices]
    faces = [mesh.faces]
    n_vert = len(mesh.vertices)
    while nxt:
        start = next(iter(nxt))
        loop = [start]
        while True:
            v = nxt.pop(loop[-1], None)
            if v is None or v == start:
                break
            loop.append(v)
        centre = mesh.vertices[loop].mean(axis=0)
        vertices.append(centre[None, :])
        # The boundary edge a->b belongs to a face; the cap triangle must run b->a.
        faces.append(
            np.array([[loop[(i + 1) % len(loop)], loop[i], n_vert] for i in range(len(loop))])
        )
        n_vert += 1
    return trimesh.Trimesh(np.vstack(vertices), np.vstack(faces), process=True)


def solid_mesh(mesh: trimesh.Trimesh, label: str) -> trimesh.Trimesh:
    """Merge vertices and require a closed, positive-volume mesh (for COM and inertia)."""
    solid = trimesh.Trimesh(mesh.vertices, mesh.faces, process=True)
    if not solid.is_watertight:
        raise NotWatertight(
            f"{label}: mesh is not watertight (has holes or open edges), so its volume, "
            "centre of mass and inertia are undefined; close it or give a watertight mesh"
        )
    if solid.volume < 0:
        solid.invert()  # inside-out winding: the shape is fine, the normals point in
    if solid.volume < _MIN_VOLUME_M3:
        raise ZeroVolume(f"{label}: mesh encloses no volume ({solid.volume:.3g} m³)")
    return solid


def read_obj_groups(path: Path, label: str) -> list[np.ndarray]:
    """Vertex arrays of each 'o'/'g' group of an OBJ: one convex hull each, as pybullet reads it."""
    groups: list[list[int]] = []
    verts: list[list[float]] = []
    current: list[int] | None = None
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError as exc:
        raise UnreadableMesh(f"{label}: cannot read {path}: {exc}") from exc
    for line in lines:
        if line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:4]])
        elif line.startswith(("o ", "g ")):
            current = []
            groups.append(current)
        elif line.startswith("f "):
            if current is None:
                current = []
                groups.append(current)
            for tok in line.split()[1:]:
                idx = int(tok.split("/")[0])
                current.append(idx - 1 if idx > 0 else len(verts) + idx)
    all_v = np.asarray(verts, dtype=float)
    parts = [all_v[np.unique(g)] for g in groups if len(g) >= 4]
    if not parts:
        raise EmptyMesh(f"{label}: {path.name} has no faces")
    return parts


def hull_mesh(points: np.ndarray) -> trimesh.Trimesh:
    """Closed convex hull of a point set (each collision part, as pybullet sees it)."""
    return trimesh.convex.convex_hull(points)


def write_parts_obj(parts: Sequence[np.ndarray], path: Path) -> None:
    """Write convex parts as one OBJ, one 'o' group per hull; atomic for concurrent workers."""
    lines: list[str] = []
    offset = 1
    for i, pts in enumerate(parts):
        hull = hull_mesh(pts)
        lines.append(f"o hull_{i}")
        lines.extend(f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in hull.vertices)
        lines.extend(f"f {a + offset} {b + offset} {c + offset}" for a, b, c in hull.faces)
        offset += len(hull.vertices)
    atomic_write(path, ("\n".join(lines) + "\n").encode())


def write_mesh_obj(mesh: trimesh.Trimesh, path: Path) -> None:
    """Write a mesh as OBJ (no normals or textures; pybullet's visual shape needs geometry only)."""
    text = trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_texture=False)
    atomic_write(path, text.encode())


def atomic_write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
    os.replace(tmp, path)
