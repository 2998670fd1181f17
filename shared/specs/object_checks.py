"""The one validation of an object: a mesh in metres and its ObjectSpec -> errors and warnings.

Run at upload by the coordinator, by the CLI before it simulates and by the worker's
preparation, so an object is refused (or warned about) in the same words everywhere, at the
door rather than on every worker. Pure: trimesh and numpy only, no pybullet. Every message
says what is wrong and what to do. The limits and why: docs/howto/add-object.md, "Validation".
"""

from __future__ import annotations

import functools
from typing import Literal

import numpy as np
import trimesh
from pydantic import BaseModel, Field
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .gripper import GripperSpec, list_grippers, load_gripper
from .object_names import (
    NAMED_SIZE_M,
    unknown_name_message,
    ycb_folder,
    ycb_root,
)
from .objects import ObjectSpec

# The worker's decomposition and collision get too slow beyond this; both sides use it.
MAX_FACES = 200_000
# Smaller than a millimetre across is a mesh in the wrong units, not a graspable object.
MIN_SIZE_M = 1e-3
# Thinner than this along an axis is a sheet: no volume to grasp.
FLAT_EXTENT_M = 1e-5
MIN_VOLUME_M3 = 1e-12
# Larger than this many times the gripper's reach is refused (surely the wrong units) ...
REFUSE_REACH_FACTOR = 10.0
# ... and larger than this many times is warned: most poses cannot close around it.
WARN_REACH_FACTOR = 4.0
# Bodies farther apart than this share of the largest body's size are warned about.
GAP_FACTOR = 0.5
# Beyond this many separate pieces the pairwise gap test is skipped (a triangle soup).
_MAX_PIECES = 2000

IssueCode = Literal[
    "empty", "non_finite", "too_many_faces", "degenerate", "too_small", "too_large", "flat",
    "not_watertight", "zero_volume", "mass_missing", "unknown_name",
    "disconnected", "large", "unchecked_name",
]


class ObjectIssue(BaseModel):
    code: IssueCode
    message: str


class ObjectReport(BaseModel):
    """What the validation found. `errors` refuse the object; `warnings` are shown and kept."""

    errors: list[ObjectIssue] = Field(default_factory=list)
    warnings: list[ObjectIssue] = Field(default_factory=list)
    vertices: int | None = None
    faces: int | None = None
    extents_m: tuple[float, float, float] | None = None
    watertight: bool | None = None
    volume_m3: float | None = None
    bodies: int | None = Field(default=None, description="separate bodies (pieces far apart)")

    @property
    def ok(self) -> bool:
        return not self.errors

    def warning_messages(self) -> list[str]:
        return [w.message for w in self.warnings]


@functools.cache
def gripper_reach_m() -> float:
    """The longest reach of the shipped grippers of boxes (TOML specs): the object must suit at
    least one of them. Grippers from URDFs (docs/howto/add-gripper.md) leave the limits where they
    were: pybullet's WSG-50 with its 15 cm finger boxes would loosen them by half."""
    specs = [load_gripper(name) for name in list_grippers()]
    return max(spec.reach() for spec in specs if isinstance(spec, GripperSpec))


def _issue(code: IssueCode, message: str) -> ObjectIssue:
    return ObjectIssue(code=code, message=message)


def _scale_note(spec: ObjectSpec) -> str:
    units = f" in {spec.units}" if spec.units else ""
    return f"at scale {spec.scale:g}{units}"


def mesh_errors(mesh: trimesh.Trimesh, label: str, max_faces: int = MAX_FACES) -> list[ObjectIssue]:
    """What makes any mesh unusable, whatever its scale: empty, non-finite, too many faces."""
    if len(mesh.vertices) == 0 or len(mesh.faces) == 0:
        return [_issue("empty", f"{label}: mesh is empty (no vertices or no faces); give a "
                       "file with a triangle mesh")]
    vertices = np.asarray(mesh.vertices, dtype=float)
    if not np.all(np.isfinite(vertices)):
        bad = int((~np.isfinite(vertices)).any(axis=1).sum())
        return [_issue("non_finite", f"{label}: {bad} vertices have NaN or infinite "
                       "(non-finite) coordinates; repair or re-export the mesh")]
    if len(mesh.faces) > max_faces:
        return [_issue("too_many_faces", f"{label}: {len(mesh.faces)} faces exceed the limit "
                       f"of {max_faces}; simplify it (decimate) below {max_faces} faces")]
    return []


def degenerate_error(mesh: trimesh.Trimesh, label: str) -> ObjectIssue | None:
    """A mesh whose triangles have no area (each one's corners coincide or lie on a line):
    there is no surface, whatever its vertices span. Named as such; measured by its size it
    read as "too large" or "flat"."""
    vertices = np.asarray(mesh.vertices, dtype=float)
    corners = vertices[np.asarray(mesh.faces)]
    doubled = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                      corners[:, 2] - corners[:, 0]), axis=1)
    span = float((vertices.max(axis=0) - vertices.min(axis=0)).max())
    # Relative to the mesh's span: a micrometre mesh's true triangles are tiny, not zero.
    if span > 0 and float(doubled.max()) > 1e-12 * span * span:
        return None
    return _issue("degenerate", (
        f"{label}: mesh is degenerate: none of its {len(doubled)} triangles has an area "
        "(their corners coincide or lie on one line), so it has no surface to grasp; give a "
        "triangle mesh of a solid"))


def size_issues(size_m: float, label: str, spec: ObjectSpec) -> ObjectReport:
    """Errors or a warning for an object `size_m` across (its largest extent, in metres)."""
    report = ObjectReport()
    reach = gripper_reach_m()
    where = _scale_note(spec)
    if size_m < MIN_SIZE_M:
        report.errors.append(_issue("too_small", (
            f"{label}: object is too small: {size_m:.3g} m across {where}, under the "
            f"{MIN_SIZE_M * 1000:g} mm minimum; the file is in other units than metres: "
            "give its units ('mm', 'cm') or a scale that makes it metres")))
    elif size_m > REFUSE_REACH_FACTOR * reach:
        report.errors.append(_issue("too_large", (
            f"{label}: object is too large: {size_m:.3g} m across {where}; the gripper "
            f"reaches {reach:.3g} m and nothing over {REFUSE_REACH_FACTOR * reach:.3g} m "
            "is accepted; meshes are in metres: give the file's units ('mm', 'cm') or a "
            "scale (e.g. 0.001 for millimetres)")))
    elif size_m > WARN_REACH_FACTOR * reach:
        report.warnings.append(_issue("large", (
            f"{label}: object is {size_m:.3g} m across {where}, more than "
            f"{WARN_REACH_FACTOR:g} times the gripper's reach ({reach:.3g} m): most poses "
            "will not close around it; check its units or scale")))
    return report


def _pieces(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Bounding boxes (lo, hi) of the vertex-connected pieces of a mesh."""
    edges = mesh.edges_unique
    n = len(mesh.vertices)
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    count, labels = connected_components(graph, directed=False)
    order = np.argsort(labels, kind="stable")
    starts = np.searchsorted(labels[order], np.arange(count))
    verts = np.asarray(mesh.vertices)[order]
    return np.minimum.reduceat(verts, starts), np.maximum.reduceat(verts, starts)


def _bodies(mesh: trimesh.Trimesh, label: str) -> tuple[int, ObjectIssue | None]:
    """How many bodies the pieces form when pieces closer than GAP_FACTOR × the largest
    piece are joined, and a warning when that is more than one."""
    lo, hi = _pieces(mesh)
    if len(lo) == 1:
        return 1, None
    if len(lo) > _MAX_PIECES:
        return len(lo), _issue("disconnected", (
            f"{label}: mesh is {len(lo)} separate pieces; they are simulated as one rigid "
            "object; check that this is one object, or merge the pieces"))
    size = float((hi - lo).max(axis=1).max())
    # Axis-aligned box gaps: never larger than the true gap, so no false warning.
    sep = np.maximum(0.0, np.maximum(lo[None, :, :] - hi[:, None, :],
                                     lo[:, None, :] - hi[None, :, :]))
    gaps = np.linalg.norm(sep, axis=2)
    near = coo_matrix(gaps <= GAP_FACTOR * size)
    count, labels = connected_components(near, directed=False)
    if count == 1:
        return 1, None
    apart = gaps[labels[:, None] != labels[None, :]]
    return count, _issue("disconnected", (
        f"{label}: mesh is {count} bodies up to {float(apart.max()):.3g} m apart (the "
        f"largest piece is {size:.3g} m across); they are simulated as one rigid object "
        "whose centre of mass may lie in the empty space between them: check that this is "
        "one object, or give the bodies as separate meshes"))


def check_object(
    mesh: trimesh.Trimesh,
    spec: ObjectSpec,
    *,
    label: str,
    needs_volume: bool = True,
    max_faces: int = MAX_FACES,
) -> ObjectReport:
    """Validate one object. `mesh`: its surface in metres (every scale applied), unprocessed
    so that NaN coordinates are still there. `needs_volume`: its mass properties come from
    the enclosed volume (user meshes, built-ins), so it must be watertight."""
    report = _check_geometry(mesh, spec, label, needs_volume, max_faces)
    if spec.mesh_path is not None and spec.mass_kg is None and not _carries_mass(spec):
        report.errors.append(_issue("mass_missing", (
            f"{label}: a mesh file carries no mass: give mass_kg (kg; e.g. --mass 0.2)")))
    return report


def _check_geometry(
    mesh: trimesh.Trimesh, spec: ObjectSpec, label: str, needs_volume: bool, max_faces: int
) -> ObjectReport:
    report = ObjectReport()
    basic = mesh_errors(mesh, label, max_faces)
    if basic:
        report.errors.extend(basic)
        return report
    degenerate = degenerate_error(mesh, label)
    if degenerate is not None:  # before its size: the size of no surface says nothing
        report.errors.append(degenerate)
        return report
    # From the raw vertices: merging them first would collapse a micrometre mesh to a point.
    vertices = np.asarray(mesh.vertices, dtype=float)
    extents = vertices.max(axis=0) - vertices.min(axis=0)
    report.extents_m = tuple(float(e) for e in extents)  # type: ignore[assignment]
    size = size_issues(float(extents.max()), label, spec)
    report.warnings.extend(size.warnings)
    if size.errors:
        report.errors.extend(size.errors)
        return report
    if float(extents.min()) < FLAT_EXTENT_M:
        report.errors.append(_issue("flat", (
            f"{label}: mesh is flat (extents {np.round(extents, 6).tolist()} m), so it has "
            "no volume to grasp; give a solid (closed) mesh")))
        return report
    # STL repeats vertices per face: merged, a closed surface reads as watertight.
    solid = trimesh.Trimesh(mesh.vertices, mesh.faces, process=True)
    report.vertices, report.faces = len(solid.vertices), len(solid.faces)
    report.watertight = bool(solid.is_watertight)
    if needs_volume:
        if not report.watertight:
            report.errors.append(_issue("not_watertight", (
                f"{label}: mesh is not watertight ({_open_edges(solid)} open edges), so its "
                "volume, centre of mass and inertia are undefined; close its holes or give "
                "a watertight mesh")))
            return report
        report.volume_m3 = abs(float(solid.volume))
        if report.volume_m3 < MIN_VOLUME_M3:
            report.errors.append(_issue("zero_volume", (
                f"{label}: mesh encloses no volume ({report.volume_m3:.3g} m³): it is a "
                "sheet or folded onto itself; give a solid (closed) mesh")))
            return report
    report.bodies, apart = _bodies(solid, label)
    if apart is not None:
        report.warnings.append(apart)
    return report


def _open_edges(mesh: trimesh.Trimesh) -> int:
    key = np.sort(mesh.edges, axis=1)
    _, counts = np.unique(key, axis=0, return_counts=True)
    return int((counts == 1).sum())


def _carries_mass(spec: ObjectSpec) -> bool:
    return (spec.mesh_path or "").lower().endswith(".urdf")


def check_name(spec: ObjectSpec) -> ObjectReport:
    """A named object: does the name exist here, and does its size at `scale` suit the
    gripper? Its geometry is vouched for (docs/howto/add-object.md); a worker checks it again."""
    name = spec.name or ""
    report = ObjectReport()
    if name in NAMED_SIZE_M:  # the built-ins and pybullet_data entries
        return size_issues(NAMED_SIZE_M[name] * spec.scale, name, spec)
    if name.startswith("ycb:"):
        if ycb_folder(name) is not None:
            return report  # its size: the worker's check, which reads the URDF's geometry
        if not ycb_root().is_dir():
            report.warnings.append(_issue("unchecked_name", (
                f"{name}: no YCB folder on this machine ({ycb_root()}) to check the name "
                "against; the workers resolve it (set GRASPSCAPE_YCB_DIR here to check it "
                "at upload)")))
            return report
    report.errors.append(_issue("unknown_name", unknown_name_message(name)))
    return report
