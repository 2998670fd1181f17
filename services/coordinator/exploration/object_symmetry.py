"""The symmetries of an exploration's object and the lattice orbits they make, cached.

Detecting symmetries samples the mesh (a fraction of a second); orbits enumerate the
lattice. Both are kept on the coordinator's state (state.py): the scheduler asks for them on
every batch of an exploration with the symmetry shortcut.
"""

from __future__ import annotations

from graspscape.services.coordinator.exploration import symmetry
from graspscape.services.coordinator.exploration.samples import lattice_of
from graspscape.services.coordinator.exploration.symmetry import Orbits
from graspscape.services.coordinator.objects.geometry import object_mesh
from graspscape.services.coordinator.state import current
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.gripper import load_gripper
from sqlalchemy.orm import Session


def object_symmetries(session: Session, spec: ExplorationSpec) -> list[symmetry.Symmetry]:
    """The symmetries of the exploration's object that the task keeps: rotations about z and
    vertical mirrors (mirrors only for a mirror-symmetric gripper); none where the mesh is
    unavailable."""
    mesh = object_mesh(session, spec.object_id)
    if mesh is None:
        return []
    # object_mesh caches one mesh per object spec; keyed by identity, the entry keeps the
    # mesh alive so its id is never reused for another object.
    detected = current().symmetries
    found = detected.get(id(mesh))
    if found is None:
        found = detected.put(id(mesh), (mesh, symmetry.detect(mesh)))
    return symmetry.task_symmetries(found[1], load_gripper(spec.gripper))


def resolve_grid(session: Session, spec: ExplorationSpec) -> ExplorationSpec:
    """The spec with its lattice's azimuth multiple decided (`PoseGridSpec.azimuth_multiple`):
    as given, else the object's symmetry order when the symmetry shortcut is on, else 1."""
    if spec.grid.azimuth_multiple is not None:
        return spec
    multiple = 1
    if spec.shortcuts.symmetry:
        multiple = symmetry.azimuth_multiple(object_symmetries(session, spec))
    grid = spec.grid.model_copy(update={"azimuth_multiple": multiple})
    return spec.model_copy(update={"grid": grid})


def symmetry_orbits(session: Session | None, spec: ExplorationSpec) -> Orbits | None:
    """The orbits of the exploration's lattice under the object's symmetries (shortcut 3),
    or None when the shortcut is off or the object has no usable symmetry."""
    if session is None or not spec.shortcuts.symmetry:
        return None
    found = tuple(object_symmetries(session, spec))
    if not found:
        return None
    orbits = current().orbits
    key = (spec.model_dump_json(), found)
    kept = orbits.get(key)
    if kept is None:
        kept = orbits.put(key, symmetry.Orbits(lattice_of(spec), list(found)))
    result: Orbits = kept
    return result


def hand_mirror(spec: ExplorationSpec) -> symmetry.HandMirror | None:
    """How the gripper's own links map under a mirror (None: it is not mirror-symmetric)."""
    return symmetry.hand_mirror(load_gripper(spec.gripper))
