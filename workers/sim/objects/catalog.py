"""Where objects come from: names and files resolved to source geometry (no pybullet).

Naming scheme: a bare name is a built-in ('mug'), 'pb:<name>' a mesh shipped in pybullet's
data package, 'ycb:<Folder>' a folder of the YCB set (model.urdf + collision_vhacd.obj), and
ObjectSpec.mesh_path a user mesh file. Everything here is in the source frame (metres,
scaled); prepare.py moves it to the centre-of-mass frame.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pybullet_data
import trimesh
from graspscape.shared.specs.object_names import (
    known_names,
    unknown_name_message,
    ycb_folder,
    ycb_root,
)
from graspscape.shared.specs.objects import ObjectSpec

from .builtins import BUILTINS, DEFAULT_FRICTION, GENERATOR_VERSION, builtin_shape
from .errors import UnknownObject
from .meshio import (
    DEFAULT_MAX_FACES,
    check_basic,
    close_planar_holes,
    hull_mesh,
    load_mesh_file,
    read_obj_groups,
)
from .urdf import UrdfObject, read_urdf

__all__ = ["SourceObject", "describe", "list_builtin_objects", "resolve", "ycb_root"]

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
# frictions are demo placeholders, so masses are plausible guesses, documented in
# docs/howto/add-object.md.
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


@dataclass(frozen=True)
class SourceObject:
    """Geometry and physics of one object in its source frame, before COM centring."""

    name: str
    mesh: trimesh.Trimesh  # unprocessed; watertight is checked where mass_source == "mesh"
    parts: list[np.ndarray] | None  # convex vertex sets, or None: decompose `mesh`
    visual: trimesh.Trimesh | None  # None: show `mesh`
    mass_source: MassSource
    mass_kg: float | None  # None only for a mesh file without mass_kg, which validation refuses
    friction: float
    inertia_diag: tuple[float, float, float] | None
    content_hash: str
    convex: bool = False
    parts_kind: Literal["builtin", "predecomposed"] = "predecomposed"


def list_builtin_objects() -> list[str]:
    """Names accepted by ObjectSpec.name: built-ins, then 'pb:' and 'ycb:' entries."""
    return known_names()


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
            "mass_kg": urdf.mass_kg, "friction": urdf.friction, "folder": str(urdf.path.parent),
        }
    raise UnknownObject(unknown_name_message(name))


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
        return _urdf_source(_ycb_urdf(name), spec, name, max_faces)
    raise UnknownObject(unknown_name_message(name))


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
    scale = spec.metres_per_unit
    content = _hash(f"builtin:{info.name}:v{GENERATOR_VERSION}".encode(), repr(scale).encode())
    return SourceObject(
        name=info.name,
        mesh=_scaled(shape.mesh, scale),
        parts=[p * scale for p in shape.parts],
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
    scale = e.scale * spec.metres_per_unit
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


def _ycb_urdf(name: str) -> UrdfObject:
    folder = ycb_folder(name)
    if folder is None:
        raise UnknownObject(unknown_name_message(name))
    return read_urdf(folder / "model.urdf", name)


def _urdf_source(u: UrdfObject, spec: ObjectSpec, name: str, max_faces: int) -> SourceObject:
    """A URDF's object: its collision hulls, mass, friction and mesh scales and origins."""
    col_path, col_t = u.collision
    scale_t = np.diag([spec.metres_per_unit] * 3 + [1.0])
    parts = []
    for p in read_obj_groups(col_path, name):
        homog = np.c_[p, np.ones(len(p))]
        parts.append((homog @ (scale_t @ col_t).T)[:, :3])
    mesh = _hulls_mesh(parts)
    check_basic(mesh, name, max_faces)
    chunks = [u.path.read_bytes(), col_path.read_bytes()]
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
        content_hash=_hash(*chunks, repr(spec.metres_per_unit).encode()),
    )


def _user_mesh(spec: ObjectSpec, max_faces: int) -> SourceObject:
    path = Path(spec.mesh_path or "")
    label = path.name or "mesh"
    if path.suffix.lower() == ".urdf":
        # The same object as its 'ycb:' name, when it is a YCB folder's model.urdf.
        name = path.parent.name if path.name == "model.urdf" else path.stem
        return _urdf_source(read_urdf(path, label), spec, name, max_faces)
    scale = spec.metres_per_unit
    mesh = _scaled(load_mesh_file(path, label, max_faces), scale)
    return SourceObject(
        name=path.stem, mesh=mesh, parts=None, visual=None, mass_source="mesh",
        mass_kg=spec.mass_kg,
        friction=spec.friction if spec.friction is not None else DEFAULT_FRICTION,
        inertia_diag=spec.inertia_diag,
        content_hash=_hash(path.read_bytes(), path.suffix.lower().encode(), repr(scale).encode()),
    )
