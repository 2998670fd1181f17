"""Objects to grasp: names and mesh files -> COM-frame geometry and pybullet bodies.

prepare_object is pure (no physics client) and caches convex decompositions on disk;
spawn_object turns its result into a body in a given client. See docs/howto/add-object.md.
"""

from .catalog import describe, list_builtin_objects
from .errors import (
    EmptyMesh,
    MassMissing,
    NonFiniteVertices,
    NotWatertight,
    ObjectError,
    TooManyFaces,
    UnknownObject,
    UnreadableMesh,
    WrongSize,
    ZeroVolume,
)
from .prepare import PreparedObject, prepare_object
from .spawn import forget_client, source_axes_orientation, spawn_object
from .validate import inspect_object

__all__ = [
    "EmptyMesh",
    "MassMissing",
    "NonFiniteVertices",
    "NotWatertight",
    "ObjectError",
    "PreparedObject",
    "TooManyFaces",
    "UnknownObject",
    "UnreadableMesh",
    "WrongSize",
    "ZeroVolume",
    "describe",
    "forget_client",
    "inspect_object",
    "list_builtin_objects",
    "prepare_object",
    "source_axes_orientation",
    "spawn_object",
]
