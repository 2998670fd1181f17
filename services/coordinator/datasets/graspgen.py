"""GraspGen's grasp dataset layout (NVlabs/GraspGen, docs/GRIPPER_DESCRIPTION.md): one JSON per
object, `object.file`, `object.scale`, `grasps.transforms` (4×4, the gripper's base frame in
the object frame) and `grasps.object_in_gripper` (success mask); `graspscape.p_success_lower`
holds the 95 % lower bound of P(success) where the certification drew around a pose (null
elsewhere). Written in one pass: the
transforms are streamed chunk by chunk, the per-pose flags (one byte each) kept until the end.
"""

from __future__ import annotations

import json
from typing import BinaryIO

from graspscape.services.coordinator.datasets.rows import (
    dataset_source,
    exploration_mesh,
    pose_chunks,
)
from sqlalchemy.orm import Session


def _flags(values: bytearray) -> str:
    return "[" + ",".join("true" if v else "false" for v in values) + "]"


def write_graspgen(session: Session, exploration_id: int, out: BinaryIO,
                   object_file: str | None = None) -> int:
    """Writes the exploration's poses to `out`; returns the number of rows."""
    source = dataset_source(session, exploration_id, object_file)
    mesh = exploration_mesh(session, exploration_id)
    head = {
        "object": {"file": source.object.file, "scale": source.object.scale,
                   "source": source.object.source, "source_scale": source.object.source_scale,
                   "mass": source.object.mass_kg},
        "gripper": {"name": source.gripper},
    }
    if source.resting_pose is not None:  # on a table: where the object rests
        head["table"] = source.resting_pose
    out.write(json.dumps(head)[:-1].encode() + b', "grasps": {"transforms": [')
    success, from_grasp = bytearray(), bytearray()
    lower: list[float | None] = []
    first = True
    for chunk in pose_chunks(session, exploration_id, mesh):
        body = json.dumps(chunk.transforms.tolist())[1:-1]
        out.write((body if first else ", " + body).encode())
        first = False
        success.extend(chunk.success.tolist())
        from_grasp.extend(chunk.from_grasp.tolist())
        lower += [None if x != x else x for x in chunk.qualities["p_success_lower"].tolist()]
    out.write(f'], "object_in_gripper": {_flags(success)}}}, "graspscape": '
              f'{{"exploration_id": {exploration_id}, "poses": {len(success)}, '
              f'"transform_from_grasp": {_flags(from_grasp)}, '
              f'"p_success_lower": {json.dumps(lower)}}}}}'.encode())
    return len(success)
