"""The dataset exports by file name, one table for the REST routes and `graspscape map export`:
what writes each and its media type. `object.obj` is the object's mesh in the frame of the
transforms, the file the other two name in `object/file`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import BinaryIO

from graspscape.services.coordinator.datasets.acronym import write_acronym
from graspscape.services.coordinator.datasets.graspgen import write_graspgen
from graspscape.services.coordinator.datasets.rows import exploration_mesh
from graspscape.services.coordinator.errors import Conflict
from sqlalchemy.orm import Session

# (session, exploration id, out, object_file=None) -> rows; object_file: the name of the mesh
# written beside the dataset, which its `object.file` names.
Writer = Callable[..., int]


def write_object_mesh(session: Session, exploration_id: int, out: BinaryIO,
                      object_file: str | None = None) -> int:
    """The object's mesh in its centre-of-mass frame as OBJ; returns its faces."""
    mesh = exploration_mesh(session, exploration_id)
    if mesh is None:
        raise Conflict(f"exploration {exploration_id}: the object's mesh is unavailable here "
                       "(a coordinator without the workers' object preparation)")
    out.write(mesh.export(file_type="obj").encode())
    return len(mesh.faces)


@dataclass(frozen=True)
class DatasetFormat:
    write: Writer
    media_type: str
    summary: str


FORMATS: dict[str, DatasetFormat] = {
    "graspgen.json": DatasetFormat(
        write_graspgen, "application/json",
        "GraspGen's grasp dataset JSON: 4×4 gripper transforms in the object frame, success"),
    "acronym.h5": DatasetFormat(
        write_acronym, "application/x-hdf5",
        "ACRONYM-style HDF5: transforms, success, qualities, object and gripper"),
    "object.obj": DatasetFormat(
        write_object_mesh, "model/obj",
        "The object's mesh in the frame of the dataset transforms (centre of mass), OBJ"),
}
