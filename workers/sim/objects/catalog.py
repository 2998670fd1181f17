"""Where objects come from: names and files resolved to source geometry (no pybullet).

Naming scheme: a bare name is a built-in ('mug'), 'pb:<name>' a mesh shipped in pybullet's
data package, 'ycb:<Folder>' a folder of the YCB set (model.urdf + collision_vhacd.obj), and
ObjectSpec.mesh_path a user mesh file. Everything here is in the source frame (metres,
scaled); prepare.py moves it to the centre-of-mass frame.
"""

from __future__ import annotations

import hashlib
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pybullet_data
import trimesh
from graspscape.shared.specs.objects import ObjectSpec

from .builtins import BUILTINS, DEFAULT_FRICTION, GENERATOR_VERSION, builtin_shape
from .errors import ObjectError, UnknownObject, UnreadableMesh
from .meshio import (
    DEFAULT_MAX_FACES,
    check_basic,
    close_planar_holes,
    hull_mesh,
    load_mesh_file,
    read_obj_groups,
)

MassSource = Literal["mesh", "parts"]


@dataclass(frozen=True)
class PbEntry:
    visual: str  # relative to pybullet_data
    collision: str | None  # a ready decomposition, or None: decompose the visual mesh
    scale: float
    mass_kg: float
    description: str
    close_holes: bool = False


# Scales bring each mesh to hand size (~10 cm); pybullet_data's own URDF masses and
# frictions are demo placeholders, so masses are plausible guesses, documented in docs/objects.md.
PB_ENTRIES: dict[str, PbEntry] = {
    "mug": PbEntry(
        "objects/mug.obj", None, 1.0, 0.3,
        "pybullet_data mug, ~8 x 12 x 10 cm, handle on +y; its shipped URDF collides as a "
        "convex hull, so the visual mesh is decomposed instead", close_holes=True,
    ),
    "bunny": PbEntry("bunny.obj", None, 0.05, 0.15, "Stanford bunny scaled to ~10 cm"),
    "duck": PbEntry("duck.obj", "duck_vhacd.obj", 0.06, 0.1, "rubber duck scaled to ~10 cm"),
    "teddy": PbEntry(
        "teddy2_VHACD_CHs.obj", "teddy2_VHACD_CHs.obj", 0.1, 0.1, "teddy bear, ~9 cm"
    ),
}


def ycb_root() -> Path:
    """YCB folder: $GRASPSCAPE_YCB_DIR, else ../shared/objects/ycb next to the repository."""
    env = os.environ.get("GRASPSCAPE_YCB_DIR")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[3].parent / "shared" / "objects" / "ycb"


@dataclass(frozen=True)
class SourceObject:
    """Geometry and physics of one object in its source frame, before COM centring."""

    name: str
    mesh: trimesh.Trimesh  # unprocessed; watertight is checked where mass_source == "mesh"
    parts: list[np.ndarray] | None  # convex vertex sets, or None: decompose `mesh`
    visual: trimesh.Trimesh | None  # None: show `mesh`
    mass_source: MassSource
    mass_kg: float
    friction: float
    inertia_diag: tuple[float, float, float] | None
    content_hash: str
    convex: bool = False
    parts_kind: Literal["builtin", "predecomposed"] = "predecomposed"


def list_builtin_objects() -> list[str]:
    """Names accepted by ObjectSpec.name: built-ins, then 'pb:' and 'ycb:' entries."""
    names = list(BUILTINS)
    names += [f"pb:{k}" for k in PB_ENTRIES]
    root = ycb_root()
    if root.is_dir():
        names += sorted(f"ycb:{d.name}" for d in root.iterdir() if (d / "model.urdf").is_file())
    return names


def describe(name: str) -> dict[str, Any]:
    """Mass, friction, dimensions and a sentence for docs and the CLI."""
    if name in BUILTINS:
        info = BUILTINS[name]
        return {
            "name": name, "kind": "builtin", "description": info.description,
            "mass_kg": info.mass_kg, "friction": info.friction,
            "dimensions_m": dict(info.dimensions_m), "convex": info.convex,
        }
    if name.startswith("pb:") and name[3:] in PB_ENTRIES:
        e = PB_ENTRIES[name[3:]]
        return {
            "name": name, "kind": "pybullet_data", "description": e.description,
            "mass_kg": e.mass_kg, "friction": DEFAULT_FRICTION, "file": e.visual,
            "scale": e.scale,
        }
    if name.startswith("ycb:"):
        urdf = _ycb_urdf(name)
        return {
            "name": name, "kind": "ycb", "description": f"YCB object {name[4:]}",
            "mass_kg": urdf.mass_kg, "friction": urdf.friction, "folder": str(urdf.folder),
        }
    raise UnknownObject(_unknown_message(name))


def resolve(spec: ObjectSpec, max_faces: int = DEFAULT_MAX_FACES) -> SourceObject:
    """Turn a spec into source geometry, raising ObjectError subclasses for bad input."""
    if spec.mesh_path is not None:
        return _user_mesh(spec, max_faces)
    assert spec.name is not None  # the spec validator guarantees one source
    name = spec.name
    if name in BUILTINS:
        return _builtin(spec)
    if name.startswith("pb:") and name[3:] in PB_ENTRIES:
        return _pybullet_data(spec, max_faces)
    if name.startswith("ycb:"):
        return _ycb(spec, max_faces)
    raise UnknownObject(_unknown_message(name))


def _unknown_message(name: str) -> str:
    return f"unknown object '{name}'; known: {', '.join(list_builtin_objects())}"


def _hash(*chunks: bytes) -> str:
    h = hashlib.sha256()
    for c in chunks:
        h.update(len(c).to_bytes(8, "little"))  # length-prefixed: no ambiguous concatenation
        h.update(c)
    return h.hexdigest()


def _scaled(mesh: trimesh.Trimesh, scale: float) -> trimesh.Trimesh:
    out = mesh.copy()
    out.apply_scale(scale)
    return out


def _builtin(spec: ObjectSpec) -> SourceObject:
    info = BUILTINS[spec.name or ""]
    shape = builtin_shape(info.name)
    # Generated geometry: hash the generator identity, not float output that could differ
    # in the last bit between platforms.
    content = _hash(f"builtin:{info.name}:v{GENERATOR_VERSION}".encode(), repr(spec.scale).encode())
    return SourceObject(
        name=info.name,
        mesh=_scaled(shape.mesh, spec.scale),
        parts=[p * spec.scale for p in shape.parts],
        visual=None,
        mass_source="mesh",
        mass_kg=spec.mass_kg or info.mass_kg,
        friction=spec.friction if spec.friction is not None else info.friction,
        inertia_diag=spec.inertia_diag,
        content_hash=content,
        convex=info.convex,
        parts_kind="builtin",
    )


def _pybullet_data(spec: ObjectSpec, max_faces: int) -> SourceObject:
    key = (spec.name or "")[3:]
    e = PB_ENTRIES[key]
    root = Path(pybullet_data.getDataPath())
    scale = e.scale * spec.scale
    vis_path = root / e.visual
    visual = _scaled(load_mesh_file(vis_path, spec.name or key, max_faces), scale)
    chunks = [vis_path.read_bytes()]
    parts = None
    if e.collision is not None:
        col_path = root / e.collision
        chunks.append(col_path.read_bytes())
        parts = [p * scale for p in read_obj_groups(col_path, spec.name or key)]
        mesh = _hulls_mesh(parts)
        mass_source: MassSource = "parts"
    else:
        mesh = close_planar_holes(visual) if e.close_holes else visual
        mass_source = "mesh"
    return SourceObject(
        name=spec.name or key, mesh=mesh, parts=parts, visual=visual, mass_source=mass_source,
        mass_kg=spec.mass_kg or e.mass_kg,
        friction=spec.friction if spec.friction is not None else DEFAULT_FRICTION,
        inertia_diag=spec.inertia_diag,
        content_hash=_hash(*chunks, repr(scale).encode()),
    )


def _hulls_mesh(parts: list[np.ndarray]) -> trimesh.Trimesh:
    """One mesh made of the closed hulls: what collides, so what geometry queries should see."""
    return trimesh.util.concatenate([hull_mesh(p) for p in parts])


@dataclass(frozen=True)
class _YcbUrdf:
    folder: Path
    mass_kg: float
    friction: float
    collision: tuple[Path, np.ndarray]  # file, 4x4 transform (scale then origin)
    visual: tuple[Path, np.ndarray] | None


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


def _ycb_urdf(name: str) -> _YcbUrdf:
    folder = ycb_root() / name[4:]
    urdf = folder / "model.urdf"
    if not name[4:] or "/" in name[4:] or not urdf.is_file():
        raise UnknownObject(_unknown_message(name))
    try:
        link = ET.parse(urdf).getroot().find("link")
        assert link is not None
        mass = float(link.find("inertial/mass").get("value"))  # type: ignore[union-attr]
        fric = link.find("contact/lateral_friction")
        friction = DEFAULT_FRICTION if fric is None else float(fric.get("value", DEFAULT_FRICTION))
        collision = _geometry(link, "collision", folder)
        assert collision is not None
    except (ET.ParseError, AssertionError, AttributeError, TypeError, ValueError) as exc:
        raise UnreadableMesh(f"{name}: cannot read {urdf}: {exc!r}") from exc
    visual = _geometry(link, "visual", folder)
    if visual is not None and not visual[0].is_file():
        visual = None  # some YCB folders ship without their textured mesh: show the hulls
    return _YcbUrdf(folder, mass, friction, collision, visual)


def _ycb(spec: ObjectSpec, max_faces: int) -> SourceObject:
    name = spec.name or ""
    u = _ycb_urdf(name)
    col_path, col_t = u.collision
    scale_t = np.diag([spec.scale] * 3 + [1.0])
    parts = []
    for p in read_obj_groups(col_path, name):
        homog = np.c_[p, np.ones(len(p))]
        parts.append((homog @ (scale_t @ col_t).T)[:, :3])
    mesh = _hulls_mesh(parts)
    check_basic(mesh, name, max_faces)
    chunks = [(u.folder / "model.urdf").read_bytes(), col_path.read_bytes()]
    visual = None
    if u.visual is not None:
        vis_path, vis_t = u.visual
        visual = load_mesh_file(vis_path, name, max_faces)
        visual.apply_transform(scale_t @ vis_t)
        chunks.append(vis_path.read_bytes())
    return SourceObject(
        name=name, mesh=mesh, parts=parts, visual=visual, mass_source="parts",
        mass_kg=spec.mass_kg or u.mass_kg,
        friction=spec.friction if spec.friction is not None else u.friction,
        inertia_diag=spec.inertia_diag,
        content_hash=_hash(*chunks, repr(spec.scale).encode()),
    )


def _user_mesh(spec: ObjectSpec, max_faces: int) -> SourceObject:
    path = Path(spec.mesh_path or "")
    label = path.name or "mesh"
    mesh = _scaled(load_mesh_file(path, label, max_faces), spec.scale)
    if spec.mass_kg is None:
        raise ObjectError(f"{label}: a mesh file needs mass_kg")
    return SourceObject(
        name=path.stem, mesh=mesh, parts=None, visual=None, mass_source="mesh",
        mass_kg=spec.mass_kg,
        friction=spec.friction if spec.friction is not None else DEFAULT_FRICTION,
        inertia_diag=spec.inertia_diag,
        content_hash=_hash(
            path.read_bytes(), path.suffix.lower().encode(), repr(spec.scale).encode()
        ),
    )
