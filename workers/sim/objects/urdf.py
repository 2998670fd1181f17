"""Reading a one-link URDF (a YCB folder's model.urdf, or any such file given by path).

The file's mass, contact friction and each mesh's `<origin>` and `<mesh scale>` are what
the object is, so `ycb:<Folder>` and the path of that folder's model.urdf give the same
object. Pure XML and numpy; no pybullet.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from .builtins import DEFAULT_FRICTION
from .errors import UnreadableMesh


@dataclass(frozen=True)
class UrdfObject:
    path: Path
    mass_kg: float
    friction: float
    collision: tuple[Path, np.ndarray]  # file, 4x4 transform (scale then origin)
    visual: tuple[Path, np.ndarray] | None  # None: the folder lacks it, show the hulls


def _origin_transform(elem: ET.Element | None) -> np.ndarray:
    if elem is None:
        return np.eye(4)
    xyz = [float(v) for v in elem.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in elem.get("rpy", "0 0 0").split()]
    t = trimesh.transformations.euler_matrix(*rpy, axes="sxyz")  # URDF: fixed-axis r, p, y
    t[:3, 3] = xyz
    return t


def _geometry(link: ET.Element, tag: str, folder: Path) -> tuple[Path, np.ndarray] | None:
    node = link.find(tag)
    mesh = node.find("geometry/mesh") if node is not None else None
    if node is None or mesh is None:
        return None
    path = folder / mesh.get("filename", "")
    scale = np.diag([*(float(v) for v in mesh.get("scale", "1 1 1").split()), 1.0])
    return path, _origin_transform(node.find("origin")) @ scale


def _inside(mesh: Path, urdf: Path, label: str) -> None:
    """A URDF's meshes are files of its own folder: a path leading out of it (`..`, an
    absolute path, a link) is refused, as an upload of a URDF is, rather than followed."""
    folder = urdf.parent.resolve()
    if not mesh.resolve().is_relative_to(folder):
        raise UnreadableMesh(
            f"{label}: the URDF's mesh {mesh} points outside its folder {folder}; put the "
            "mesh files beside the URDF")


def read_urdf(path: Path, label: str) -> UrdfObject:
    """Mass, friction and mesh geometry of the URDF's first link."""
    if not path.is_file():
        raise UnreadableMesh(f"{label}: URDF file not found: {path}")
    try:
        link = ET.parse(path).getroot().find("link")
        assert link is not None, "no <link>"
        mass = float(link.find("inertial/mass").get("value"))  # type: ignore[union-attr]
        fric = link.find("contact/lateral_friction")
        friction = DEFAULT_FRICTION if fric is None else float(fric.get("value", DEFAULT_FRICTION))
        collision = _geometry(link, "collision", path.parent)
        assert collision is not None, "no <collision><geometry><mesh>"
    except (ET.ParseError, AssertionError, AttributeError, TypeError, ValueError) as exc:
        raise UnreadableMesh(
            f"{label}: cannot read {path}: {exc!r}; give a URDF whose first link has an "
            "<inertial><mass> and a <collision> mesh"
        ) from exc
    _inside(collision[0], path, label)
    visual = _geometry(link, "visual", path.parent)
    if visual is not None:
        _inside(visual[0], path, label)
    if visual is not None and not visual[0].is_file():
        visual = None  # some YCB folders ship without their textured mesh: show the hulls
    return UrdfObject(path, mass, friction, collision, visual)
