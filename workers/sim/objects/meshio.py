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
from graspscape.shared.specs.object_checks import MAX_FACES, mesh_errors

from .errors import EmptyMesh, UnreadableMesh, raise_first

DEFAULT_MAX_FACES = MAX_FACES  # one limit for the coordinator's upload check and the worker
MESH_SUFFIXES = (".obj", ".stl", ".ply", ".glb", ".gltf", ".off")


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
    """Checks that hold at any scale: non-empty, finite, within the face limit."""
    raise_first(mesh_errors(mesh, label, max_faces))


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


def solid_mesh(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Merged vertices, outward winding: the closed mesh (validated by check_object) whose
    volume, centre of mass and inertia are computed."""
    solid = trimesh.Trimesh(mesh.vertices, mesh.faces, process=True)
    if solid.volume < 0:
        solid.invert()  # inside-out winding: the shape is fine, the normals point in
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
