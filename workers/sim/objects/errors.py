"""Errors raised while turning an object description into geometry or a pybullet body.

Every bad input is caught here, before pybullet sees it: pybullet can crash or hang on
degenerate meshes, so each check raises an ObjectError subclass whose message names the
problem and the object.
"""

from __future__ import annotations

from collections.abc import Sequence

from graspscape.shared.specs.object_checks import ObjectIssue


class ObjectError(ValueError):
    """Base class: the object cannot be prepared; the message says why."""


class UnknownObject(ObjectError):
    """A name that is neither a built-in, a pybullet_data entry nor a YCB folder."""


class UnreadableMesh(ObjectError):
    """The file is missing, of an unsupported type, or cannot be parsed."""


class EmptyMesh(ObjectError):
    """The mesh has no vertices or no faces."""


class NonFiniteVertices(ObjectError):
    """Some vertex coordinates are NaN or infinite."""


class ZeroVolume(ObjectError):
    """The mesh is flat or encloses no volume (a sheet, a line, a point)."""


class NotWatertight(ObjectError):
    """The mesh has holes, so its volume, centre of mass and inertia are undefined."""


class TooManyFaces(ObjectError):
    """The mesh exceeds the configured face limit (decomposition and collision get too slow)."""


class WrongSize(ObjectError):
    """Too small or too large for the gripper: a mesh in other units than metres."""


class MassMissing(ObjectError):
    """A mesh file gives no mass, and mass_kg was not given."""


_BY_CODE: dict[str, type[ObjectError]] = {
    "empty": EmptyMesh,
    "non_finite": NonFiniteVertices,
    "too_many_faces": TooManyFaces,
    "degenerate": ZeroVolume,
    "too_small": WrongSize,
    "too_large": WrongSize,
    "flat": ZeroVolume,
    "zero_volume": ZeroVolume,
    "not_watertight": NotWatertight,
    "mass_missing": MassMissing,
    "unknown_name": UnknownObject,
}


def raise_first(errors: Sequence[ObjectIssue]) -> None:
    """Raise the first error of a validation (shared/specs/object_checks.py) as its class."""
    if errors:
        raise _BY_CODE.get(errors[0].code, ObjectError)(errors[0].message)
