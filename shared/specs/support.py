"""What the object rests on while the hand reaches it: nothing (the paper's free-floating
object) or a table (a horizontal plane under the object at one of its stable resting poses).

`SupportSpec` is what a user submits (`ExplorationSpec.support`); `TableScene` is what a worker
simulates (`SimSettings.table`): the plane's friction, the resting pose of this exploration and
the tolerances that tell a grasp that knocked the object over or dragged it. The coordinator
turns one submitted `plane` into one exploration per chosen resting pose
(`shared/specs/resting.py`, docs/concepts/support.md).
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from scipy.spatial.transform import Rotation

SupportKind = Literal["none", "plane"]
SUPPORT_KINDS: tuple[str, ...] = ("none", "plane")

# 0.5: a dry wooden or laminate tabletop against plastic or ceramic (handbook values 0.3–0.6),
# and the object's own default friction in pybullet's product rule. Lower makes a pushed object
# slide rather than tip; the spec states it so that a map says which table it was made on.
DEFAULT_TABLE_FRICTION = 0.5


class RestingPose(BaseModel):
    """One stable resting pose: the object frame (centre of mass, object axes) in the table
    frame (origin on the plane under the centre of mass, z up), and how likely the object
    comes to rest so when dropped at random (trimesh's `compute_stable_poses`)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    index: int = Field(ge=0, le=1000, description="rank among the object's resting poses, "
                       "most probable first")
    probability: float = Field(ge=0.0, le=1.0)
    position: tuple[float, float, float] = Field(
        description="the centre of mass in the table frame, m (x = y = 0, z its height)")
    quaternion: tuple[float, float, float, float] = Field(
        description="the object axes in the table frame, x, y, z, w")

    def rotation(self) -> np.ndarray:
        """3×3: columns are the object's axes in the table frame."""
        return Rotation.from_quat(self.quaternion).as_matrix()

    def matrix(self) -> list[list[float]]:
        """4×4: a table-frame point = this @ an object-frame point."""
        out = np.eye(4)
        out[:3, :3] = self.rotation()
        out[:3, 3] = self.position
        return out.tolist()

    def up(self) -> np.ndarray:
        """The table's up direction in the object frame."""
        return self.rotation().T @ np.array([0.0, 0.0, 1.0])


class TableScene(BaseModel):
    """The table as a worker simulates it: a static plane under the object at `resting`,
    the object free on it (gravity on) while the hand approaches and closes."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    friction: float = Field(default=DEFAULT_TABLE_FRICTION, gt=0.0, le=3.0,
                            description="the plane's lateral friction (pybullet multiplies "
                            "it with the object's)")
    resting: RestingPose
    # Before lift-off the object only has to stay put: a grasp that moved it more than this
    # (dragged it) or turned it more than this (tipped it) is not a grasp of the object at
    # rest. 2 cm and 15° pass a hand that centres a sphere or squares a box while closing.
    moved_tolerance_m: float = Field(default=0.02, gt=0.0, le=0.5)
    turned_tolerance_rad: float = Field(default=math.radians(15.0), gt=0.0, le=math.pi)
    # A slow lift-off (3 cm in 0.5 s: at most 0.7 m/s²) lets the object settle in the hand
    # before the task: after a brisk one (2 cm in 0.2 s) a swinging mug read μs < 0 at the
    # task's first probe instant where the same grasp of the free mug read 0.84.
    lift_off_m: float = Field(
        default=0.03, ge=0.0, le=0.5,
        description="the first phase of the reference trajectory: straight up by this much "
        "before the task starts, so μs and the margins are measured clear of the table")
    lift_off_s: float = Field(default=0.5, gt=0.0, le=5.0)


class SupportSpec(BaseModel):
    """`ExplorationSpec.support`: nothing under the object, or a plane; for a plane, the
    resting poses explored (each its own exploration of one group)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    kind: SupportKind = Field(
        default="none", description="'none': the free-floating object; 'plane': the object at "
        "rest on a table, one exploration per chosen stable resting pose")
    friction: float = Field(default=DEFAULT_TABLE_FRICTION, gt=0.0, le=3.0,
                            description="the table's lateral friction")
    min_probability: float = Field(
        default=0.05, ge=0.0, le=1.0,
        description="resting poses at least this probable are explored (the most probable "
        "one always)")
    max_poses: int = Field(default=4, ge=1, le=16,
                           description="at most this many resting poses, most probable first")
    resting: RestingPose | None = Field(
        default=None, description="set by the coordinator on each exploration of the group: "
        "its resting pose")
    seed_exploration: int | None = Field(
        default=None, ge=1, le=2**31 - 1,
        description="a free-object exploration of the same object, gripper, grid and "
        "refinement levels: each exploration on the table evaluates only its viable poses, "
        "once (starts whose palm is under the table are skipped; the rest are simulated "
        "again on the table, not copied); None: the whole grid as the strategy plans it")


def resting_document(spec_json: dict) -> dict | None:
    """What an export states about the table, from a stored spec's JSON: the resting pose
    (the object frame in the table frame, 4×4, and as position + quaternion), its rank and
    probability, and the table's friction; None for a free object."""
    support = SupportSpec.model_validate(spec_json.get("support") or {})
    if support.resting is None:
        return None
    resting = support.resting
    return {"object_in_table": resting.matrix(), "position": list(resting.position),
            "quaternion_xyzw": list(resting.quaternion), "index": resting.index,
            "probability": resting.probability, "friction": support.friction}


def table_scene(support: SupportSpec) -> TableScene | None:
    """The table the workers simulate for a support with its resting pose set."""
    if support.kind != "plane" or support.resting is None:
        return None
    return TableScene(friction=support.friction, resting=support.resting)


def support_problem(support: SupportSpec, table: TableScene | None, engine: str) -> str | None:
    """Why an exploration's support and its workers' table disagree (None: they agree)."""
    if support.kind == "plane" and engine != "pybullet":
        return ("support 'plane' is simulated on pybullet only; set settings.engine to "
                "'pybullet' or support.kind to 'none'")
    if support.seed_exploration is not None and support.kind != "plane":
        return "support.seed_exploration needs support.kind 'plane'"
    if support.resting is None:
        if table is not None:
            return ("settings.table is set by the coordinator from support; submit "
                    "support.kind 'plane' instead")
        return None
    if support.kind != "plane":
        return "support.resting needs support.kind 'plane'"
    if table != table_scene(support):
        return "settings.table must be the support's table at its resting pose"
    return None
