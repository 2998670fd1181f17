"""Errors raised while turning an object description into geometry or a pybullet body.

Every bad input is caught here, before pybullet sees it: pybullet can crash or hang on
degenerate meshes, so each check raises an ObjectError subclass whose message names the
problem and the object.
"""

from __future__ import annotations


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
