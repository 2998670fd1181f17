"""An ACRONYM-style HDF5 (NVlabs/acronym: `grasps/transforms` N×4×4,
`grasps/qualities/flex/object_in_gripper`, `object/file`, `object/scale`, `object/mass`,
`gripper/type`), one row per stored pose, with this project's qualities beside ACRONYM's
success flag and the object's mesh in the frame of the transforms. Datasets grow chunk by
chunk, so the export holds one chunk of poses in memory.
"""

from __future__ import annotations

import math
from typing import Any, BinaryIO

import h5py
import numpy as np
from graspscape.services.coordinator.datasets.rows import (
    QUALITIES,
    SUCCESS_QUALITIES,
    Chunk,
    dataset_source,
    exploration_mesh,
    pose_chunks,
)
from sqlalchemy.orm import Session

_TEXT = h5py.string_dtype()


# Every per-pose dataset: its shape after the pose axis and its type.
_LAYOUT: dict[str, tuple[tuple[int, ...], Any]] = {
    "grasps/transforms": ((4, 4), np.float64),
    "grasps/qualities/flex/object_in_gripper": ((), np.int8),
    **{f"grasps/qualities/{q}": ((), np.float64) for q in (*QUALITIES, *SUCCESS_QUALITIES)},
    "grasps/from_grasp": ((), np.int8),
    "grasps/outcome": ((), _TEXT),
    "grasps/pose_key": ((), _TEXT),
    "grasps/pose": ((6,), np.float64),
}


def _columns(chunk: Chunk) -> dict[str, Any]:
    return {
        "grasps/transforms": chunk.transforms,
        "grasps/qualities/flex/object_in_gripper": chunk.success,
        **{f"grasps/qualities/{q}": chunk.qualities[q]
           for q in (*QUALITIES, *SUCCESS_QUALITIES)},
        "grasps/from_grasp": chunk.from_grasp,
        "grasps/outcome": chunk.outcomes,
        "grasps/pose_key": chunk.pose_keys,
        "grasps/pose": chunk.poses,
    }


def write_acronym(session: Session, exploration_id: int, out: BinaryIO,
                  object_file: str | None = None) -> int:
    """Writes the exploration's poses to `out` (a seekable binary file); returns the rows."""
    source = dataset_source(session, exploration_id, object_file)
    mesh = exploration_mesh(session, exploration_id)
    n = 0
    with h5py.File(out, "w") as file:
        file.attrs["exploration_id"] = exploration_id
        file.attrs["frame"] = ("transforms: the gripper frame (palm surface centre, z the palm "
                               "normal) in the object's centre-of-mass frame, metres")
        obj = source.object
        file["object/file"] = obj.file
        file["object/scale"] = obj.scale
        file["object/mass"] = math.nan if obj.mass_kg is None else obj.mass_kg
        file["object/friction"] = math.nan if obj.friction is None else obj.friction
        file["object/source"] = obj.source
        file["object/source_scale"] = obj.source_scale
        if mesh is not None:
            file["object/mesh/vertices"] = np.asarray(mesh.vertices, dtype=float)
            file["object/mesh/faces"] = np.asarray(mesh.faces, dtype=np.int64)
        if source.resting_pose is not None:  # on a table: the object frame in the table's
            table = source.resting_pose
            file["table/object_in_table"] = np.asarray(table["object_in_table"], dtype=float)
            file["table/probability"] = table["probability"]
            file["table/friction"] = table["friction"]
        file["gripper/type"] = source.gripper
        file["gripper/name"] = source.gripper
        datasets = {name: file.create_dataset(name, shape=(0, *shape), dtype=dtype,
                                              maxshape=(None, *shape), chunks=(1024, *shape))
                    for name, (shape, dtype) in _LAYOUT.items()}
        for chunk in pose_chunks(session, exploration_id, mesh):
            added = len(chunk.pose_keys)
            for name, values in _columns(chunk).items():
                datasets[name].resize(n + added, axis=0)
                datasets[name][n:] = values
            n += added
    return n
