"""The worker's and the CLI's side of the one object validation (shared/specs/object_checks).

`check_source` runs the shared check on a resolved object exactly as the coordinator runs it
on an upload; `inspect_object` resolves a spec and checks it without decomposing anything,
so the CLI can print the warnings and refuse a bad object before it simulates.
"""

from __future__ import annotations

from graspscape.shared.specs.object_checks import ObjectReport, check_object
from graspscape.shared.specs.objects import ObjectSpec

from .catalog import SourceObject, resolve
from .meshio import DEFAULT_MAX_FACES


def check_source(
    src: SourceObject, spec: ObjectSpec, max_faces: int = DEFAULT_MAX_FACES
) -> ObjectReport:
    """Validate a resolved object; its mass comes from the volume only for solid meshes."""
    return check_object(
        src.mesh, spec, label=src.name, needs_volume=src.mass_source == "mesh",
        max_faces=max_faces,
    )


def inspect_object(spec: ObjectSpec, max_faces: int = DEFAULT_MAX_FACES) -> ObjectReport:
    """Resolve and validate. A file that cannot be read or a name that does not exist
    raises its ObjectError; everything else is in the report."""
    return check_source(resolve(spec, max_faces), spec, max_faces)
