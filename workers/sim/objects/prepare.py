"""Prepare an object: source geometry -> centre-of-mass frame, mass properties, collision parts.

Pure and cacheable (no physics client): the result can be built once per worker and spawned
into any number of pybullet clients. The object frame is the source frame translated so the
centre of mass is the origin. Axes are kept (a mug stays upright) unless the mesh's products
of inertia are too large to drop (more than INERTIA_ALIGN_THRESHOLD of the tensor's norm):
then the frame turns to the principal axes nearest the source axes, so that pybullet, which
only takes a diagonal inertia, gets the exact tensor without a rotated inertial frame (a
rotated one would make getBasePositionAndOrientation report a frame other than the object's).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh
from graspscape.shared.specs.objects import ObjectSpec

from .catalog import SourceObject, resolve
from .decompose import params_key, vhacd_parts
from .errors import ObjectError, raise_first
from .meshio import DEFAULT_MAX_FACES, hull_mesh, solid_mesh, write_mesh_obj, write_parts_obj
from .validate import check_source

# Bump when the preparation changes what lands in the cache.
PREP_VERSION = 1
# Relative Frobenius norm of the products of inertia above which the frame is rotated. Set in
# the gap between the shipped objects' values (teddy 0.021, strawberry 0.050) so that float
# noise cannot flip a shipped object's frame between machines.
INERTIA_ALIGN_THRESHOLD = 0.03

Decomposition = Literal["convex", "builtin", "predecomposed", "vhacd"]


@dataclass(frozen=True, eq=False)
class PreparedObject:
    """Everything a worker needs about one object, all in the object (COM) frame."""

    name: str
    content_hash: str  # sha256 of source bytes + scale: same object, same hash, any machine
    mesh: trimesh.Trimesh  # closed surface for geometry queries, COM at the origin
    collision_parts: tuple[np.ndarray, ...]  # convex vertex sets (each collides as its hull)
    collision_path: Path  # the same parts as a multi-object OBJ (pybullet loads it as a compound)
    visual_path: Path  # what TinyRenderer draws
    mass_kg: float
    inertia_diag: tuple[float, float, float]  # kg·m², about the COM along the object axes
    inertia_tensor: np.ndarray  # full 3x3 about the COM, object axes (from the mesh)
    principal_moments: tuple[float, float, float]
    principal_axes: np.ndarray  # 3x3, columns = principal directions in object axes
    inertia_dropped: float  # |offdiag| / |I| (Frobenius) in the object frame: what pybullet misses
    friction: float
    bounding_radius: float  # farthest surface point from the COM, m
    extents: tuple[float, float, float]  # axis-aligned size, m
    com_in_source: tuple[float, float, float]  # object origin in the source file's frame
    object_from_source: np.ndarray  # 4x4: object-frame point = T @ source point (scaled source)
    decomposition: Decomposition
    decomposition_cached: bool  # True when the hulls came from the on-disk cache
    prepare_seconds: float = field(default=0.0)
    warnings: tuple[str, ...] = ()  # what the validation warned about (docs/howto/add-object.md)


def prepare_object(
    spec: ObjectSpec, cache_dir: Path, max_faces: int = DEFAULT_MAX_FACES
) -> PreparedObject:
    """Resolve, validate, centre, decompose (cached) and describe one object."""
    t0 = time.perf_counter()
    src = resolve(spec, max_faces)
    report = check_source(src, spec, max_faces)
    raise_first(report.errors)
    assert src.mass_kg is not None  # a missing mass is one of the errors raised above
    if src.mass_source == "mesh":
        solid = solid_mesh(src.mesh)
    else:
        solid = trimesh.Trimesh(src.mesh.vertices, src.mesh.faces, process=False)
        if solid.volume <= 0:
            raise ObjectError(f"{src.name}: its collision hulls enclose no volume")
    com = np.asarray(solid.center_mass, dtype=float)
    # trimesh integrates at density 1; inertia scales linearly with density = m / V.
    tensor_src = np.asarray(solid.moment_inertia, dtype=float) * (src.mass_kg / solid.volume)
    rot = np.eye(3) if _dropped(tensor_src) <= INERTIA_ALIGN_THRESHOLD else _principal(tensor_src)
    transform = np.eye(4)
    transform[:3, :3] = rot
    transform[:3, 3] = -rot @ com
    tensor = rot @ tensor_src @ rot.T
    moments, axes = np.linalg.eigh(tensor)

    mesh = solid.copy()
    mesh.apply_transform(transform)
    entry = Path(cache_dir) / f"v{PREP_VERSION}-{src.content_hash[:32]}"
    parts, kind, cached = _collision_parts(src, mesh, transform, entry)
    collision_path = entry / f"collision-{kind}.obj"
    if kind == "vhacd":
        collision_path = entry / f"collision-vhacd-{params_key()}.obj"
    elif not collision_path.is_file():
        write_parts_obj(parts, collision_path)
    visual_path = entry / "visual.obj"
    if not visual_path.is_file():
        visual = src.visual.copy() if src.visual is not None else solid.copy()
        visual.apply_transform(transform)
        write_mesh_obj(visual, visual_path)

    if src.inertia_diag is not None:
        diag = tuple(float(v) for v in src.inertia_diag)
    else:
        diag = tuple(float(v) for v in np.diag(tensor))
    return PreparedObject(
        name=src.name,
        content_hash=src.content_hash,
        mesh=mesh,
        collision_parts=tuple(parts),
        collision_path=collision_path,
        visual_path=visual_path,
        mass_kg=float(src.mass_kg),
        inertia_diag=diag,  # type: ignore[arg-type]
        inertia_tensor=tensor,
        principal_moments=tuple(float(v) for v in moments),  # type: ignore[arg-type]
        principal_axes=axes,
        inertia_dropped=_dropped(tensor),
        friction=float(src.friction),
        bounding_radius=float(np.linalg.norm(mesh.vertices, axis=1).max()),
        extents=tuple(float(v) for v in mesh.extents),  # type: ignore[arg-type]
        com_in_source=tuple(float(v) for v in com),  # type: ignore[arg-type]
        object_from_source=transform,
        decomposition=kind,
        decomposition_cached=cached,
        prepare_seconds=time.perf_counter() - t0,
        warnings=tuple(report.warning_messages()),
    )


def _collision_parts(
    src: SourceObject, mesh: trimesh.Trimesh, transform: np.ndarray, entry: Path
) -> tuple[list[np.ndarray], Decomposition, bool]:
    """Convex parts in the COM frame, and how they were obtained."""
    if src.parts is not None:
        kind: Decomposition = "convex" if src.convex else src.parts_kind
        moved = [trimesh.transform_points(np.asarray(p, dtype=float), transform) for p in src.parts]
        return moved, kind, False
    if _is_convex(mesh):
        return [np.asarray(mesh.vertices)], "convex", False
    out = entry / f"collision-vhacd-{params_key()}.obj"
    cached = out.is_file()
    return vhacd_parts(mesh, out, src.name), "vhacd", cached


def _is_convex(mesh: trimesh.Trimesh) -> bool:
    # Volume ratio against the hull, tolerant of tessellation noise (is_convex is exact).
    return bool(mesh.volume / hull_mesh(mesh.vertices).volume > 0.999)


def _dropped(tensor: np.ndarray) -> float:
    off = tensor - np.diag(np.diag(tensor))
    return float(np.linalg.norm(off) / np.linalg.norm(tensor))


def _principal(tensor: np.ndarray) -> np.ndarray:
    """Rotation (rows = new axes in source coordinates) onto the principal axes that are
    closest to the source axes: the smallest turn that makes the tensor diagonal."""
    _, vecs = np.linalg.eigh(tensor)
    best = max(
        itertools.permutations(range(3)),
        key=lambda perm: float(np.abs(np.diag(vecs[:, list(perm)])).sum()),
    )
    m = vecs[:, list(best)]
    m = m * np.where(np.diag(m) < 0, -1.0, 1.0)  # each new axis points along its source axis
    if np.linalg.det(m) < 0:
        weakest = int(np.argmin(np.abs(np.diag(m))))
        m[:, weakest] *= -1.0
    return m.T
