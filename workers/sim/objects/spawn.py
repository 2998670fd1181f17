"""Create a pybullet body from a PreparedObject; the body frame is the object's COM frame.

Inertia: pybullet takes principal moments in an inertial frame, and when that frame is
rotated (baseInertialFrameOrientation), getBasePositionAndOrientation reports the rotated
frame, not the object's. To keep "body pose = object pose" for every caller, the inertial
frame is the object frame and pybullet gets the diagonal of the mesh inertia tensor; the
products of inertia it drops are reported as PreparedObject.inertia_offdiag_ratio (0 for the
symmetric built-ins, ~2 % for the mug).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pybullet as p
import trimesh

from .errors import ObjectError
from .prepare import PreparedObject

# (client, content hash, collision file) -> (collision shape, visual shape). Shape ids die
# with resetSimulation/disconnect: call forget_client then (client ids are reused).
_SHAPES: dict[tuple[int, str, str], tuple[int, int]] = {}


def forget_client(client_id: int) -> None:
    """Drop cached shape ids of a client after resetSimulation or disconnect."""
    for key in [k for k in _SHAPES if k[0] == client_id]:
        del _SHAPES[key]


def _shapes(client_id: int, prepared: PreparedObject, rgba: Sequence[float]) -> tuple[int, int]:
    key = (client_id, prepared.content_hash, str(prepared.collision_path))
    if key not in _SHAPES:
        # A multi-object OBJ becomes a compound with one convex hull per object: the
        # concavities between the parts (a handle hole, a mug's cavity) are kept.
        col = p.createCollisionShape(
            p.GEOM_MESH, fileName=str(prepared.collision_path), physicsClientId=client_id
        )
        vis = p.createVisualShape(
            p.GEOM_MESH, fileName=str(prepared.visual_path), rgbaColor=list(rgba),
            physicsClientId=client_id,
        )
        if col < 0 or vis < 0:
            raise ObjectError(f"{prepared.name}: pybullet refused the collision or visual mesh")
        _SHAPES[key] = (col, vis)
    return _SHAPES[key]


def spawn_object(
    client_id: int,
    prepared: PreparedObject,
    position: Sequence[float] = (0.0, 0.0, 0.0),
    orientation: Sequence[float] = (0.0, 0.0, 0.0, 1.0),
    rgba: Sequence[float] = (0.85, 0.45, 0.2, 1.0),
) -> int:
    """Create the dynamic body with mass, inertia and friction; returns its body id.

    Rolling and spinning friction stay at pybullet's default 0: they are contact-patch
    approximations that would add an unmeasured resistance to the object turning in the grasp.
    """
    body = -1
    for attempt in range(2):
        col, vis = _shapes(client_id, prepared, rgba)
        try:
            body = p.createMultiBody(
                baseMass=prepared.mass_kg,
                baseCollisionShapeIndex=col,
                baseVisualShapeIndex=vis,
                basePosition=list(position),
                baseOrientation=list(orientation),
                baseInertialFramePosition=[0.0, 0.0, 0.0],
                baseInertialFrameOrientation=[0.0, 0.0, 0.0, 1.0],
                physicsClientId=client_id,
            )
        except p.error:
            body = -1
        if body >= 0 or attempt == 1:
            break
        forget_client(client_id)  # cached ids from a reset or reconnected client: rebuild
    if body < 0:
        raise ObjectError(f"{prepared.name}: pybullet could not create the body")
    # createMultiBody derives inertia from the compound's bounding box; set the mesh's.
    p.changeDynamics(
        body, -1,
        localInertiaDiagonal=list(prepared.inertia_diag),
        lateralFriction=prepared.friction,
        physicsClientId=client_id,
    )
    return body


def source_axes_orientation(prepared: PreparedObject) -> tuple[float, float, float, float]:
    """Body orientation (x, y, z, w) that lines the source file's axes up with the world's.

    Identity unless prepare turned the frame onto principal axes; use it to show, say, a YCB
    drill standing as its file has it.
    """
    rot = np.eye(4)
    rot[:3, :3] = np.asarray(prepared.object_from_source)[:3, :3].T
    w, x, y, z = trimesh.transformations.quaternion_from_matrix(rot)
    return (float(x), float(y), float(z), float(w))
