"""Mesh uploads: read the file and run the one object validation on it at POST time.

The check is shared/specs/object_checks.check_object, the same the workers run when they
prepare the object, so an upload every worker would refuse fails here, once, with the
message naming the problem and what to do; its warnings are returned and stored.
"""

from __future__ import annotations

import io

import trimesh
from graspscape.services.coordinator.errors import InvalidInput, UnsupportedMediaType
from graspscape.shared.specs.object_checks import ObjectReport, check_name, check_object
from graspscape.shared.specs.objects import ObjectSpec
from pydantic import BaseModel

MESH_FORMATS = ("obj", "stl", "ply", "glb", "off")


class MeshInfo(BaseModel):
    vertices: int
    faces: int
    watertight: bool
    volume_m3: float
    extents_m: tuple[float, float, float]
    bodies: int | None = None  # separate bodies far apart (None: stored before it was counted)


def mesh_format(filename: str | None) -> str:
    suffix = (filename or "").rsplit(".", 1)[-1].lower() if "." in (filename or "") else ""
    if suffix not in MESH_FORMATS:
        raise UnsupportedMediaType(
            f"mesh file {filename!r} has an unsupported format; use one of "
            + ", ".join(f".{f}" for f in MESH_FORMATS)
        )
    return suffix


def refuse(report: ObjectReport, loc: tuple[str, ...]) -> None:
    """422 with every error of the validation, each saying what to do."""
    if report.errors:
        raise InvalidInput("; ".join(e.message for e in report.errors), loc=loc)


def validate_mesh(
    data: bytes, fmt: str, spec: ObjectSpec, label: str
) -> tuple[MeshInfo, list[str]]:
    """The upload's mesh facts and warnings, or InvalidInput naming every problem."""
    loc = ("body", "file")
    if not data:
        raise InvalidInput("mesh file is empty", loc=loc)
    try:
        mesh = trimesh.load(io.BytesIO(data), file_type=fmt, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for malformed files
        raise InvalidInput(f"mesh could not be read as .{fmt}: {exc}", loc=loc) from exc
    if not isinstance(mesh, trimesh.Trimesh):
        raise InvalidInput("mesh has no faces", loc=loc)
    # Loaded unprocessed so NaNs are seen; scaled to metres as the worker will see it.
    mesh.apply_scale(spec.metres_per_unit)
    report = check_object(mesh, spec, label=label)
    refuse(report, loc)
    assert report.extents_m is not None and report.volume_m3 is not None
    info = MeshInfo(
        vertices=report.vertices or 0,
        faces=report.faces or 0,
        watertight=bool(report.watertight),
        volume_m3=report.volume_m3,
        extents_m=report.extents_m,
        bodies=report.bodies,
    )
    return info, report.warning_messages()


def validate_name(spec: ObjectSpec) -> list[str]:
    """A named object's warnings, or InvalidInput when the name does not exist or its size
    at `scale` is out of bounds."""
    report = check_name(spec)
    refuse(report, ("body", "name"))
    return report.warning_messages()
