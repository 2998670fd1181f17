"""What the Hand loads for a gripper spec: a URDF file, the flags to load it with, each
finger's joints in closing order, and the joints coupled to others (URDF <mimic>, linkages).

A TOML spec of boxes gets its URDF generated (urdf.py); a URDF gripper gets its vendor's file
rewritten (urdf_import.py). Either way the Hand sees the same conventions: base frame = gripper
frame, finger joints close as their values grow, links named `<finger>_<k>`.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path

import pybullet as p
from graspscape.shared.specs.gripper import AnyGripperSpec, GripperSpec, MjcfGripperSpec
from graspscape.workers.sim.gripper.urdf import write_gripper_urdf
from graspscape.workers.sim.gripper.urdf_import import (
    Coupling,
    GripperFileError,
    JointLayout,
    prepare_urdf,
)
from graspscape.workers.sim.objects.decompose import _quiet_stdout

# The gear constraints' force cap: far above any closing effort, so a follower keeps its ratio.
COUPLING_MAX_FORCE = 1000.0
# The gear is a velocity constraint; this position correction keeps q_f = ratio·q_d + offset
# when the driver stops at its limit (with none, a PR2 finger made to mimic the other ran on
# at the closing speed once the driver stopped; at 0.2 it settled 0.05 rad off, at 0.5 0.02).
COUPLING_ERP = 0.5


@dataclass(frozen=True)
class HandModel:
    urdf: Path
    flags: int
    fingers: tuple[JointLayout, ...]
    couplings: tuple[Coupling, ...] = ()
    vendor_names: dict[str, str] | None = None
    passive: dict[str, tuple[str, ...]] | None = None  # finger -> joints no command moves


def _box_layout(spec: GripperSpec) -> tuple[JointLayout, ...]:
    return tuple(JointLayout(
        finger=f.name,
        spread_joint=f"{f.name}_spread_joint" if f.spread is not None else None,
        spread_sign=f.spread_sign,
        joints=tuple(f"{f.name}_{ph.name}_joint" for ph in f.phalanges),
        open_values=tuple(ph.open for ph in f.phalanges),
        uppers=tuple(ph.upper for ph in f.phalanges),
        shares=tuple(ph.torque_share for ph in f.phalanges),
    ) for f in spec.fingers)


def hand_model(spec: AnyGripperSpec, directory: Path) -> HandModel:
    if isinstance(spec, MjcfGripperSpec):
        raise GripperFileError(
            f"gripper {spec.name!r} is described by an MJCF ({spec.mjcf}), which only the "
            "MuJoCo engine loads: run it with --engine mujoco")
    if isinstance(spec, GripperSpec):
        return HandModel(write_gripper_urdf(spec, directory), p.URDF_USE_INERTIA_FROM_FILE,
                         _box_layout(spec))
    prepared = prepare_urdf(spec, directory)
    # Fixed links (fingertip pads, flanges) merge into the link they hang on: contacts on
    # them count for that link, and the palm's for the palm.
    flags = p.URDF_MERGE_FIXED_LINKS
    if spec.inertia == "file":
        flags |= p.URDF_USE_INERTIA_FROM_FILE
    return HandModel(prepared.path, flags, prepared.fingers, prepared.couplings,
                     prepared.vendor_names)


def load_body(client: int, model: HandModel) -> int:
    # pybullet prints every merged link to fd 1 from C.
    quiet = _quiet_stdout() if model.flags & p.URDF_MERGE_FIXED_LINKS else contextlib.nullcontext()
    with quiet:
        return p.loadURDF(str(model.urdf), basePosition=[0, 0, 5], useFixedBase=False,
                          flags=model.flags, physicsClientId=client)


def add_couplings(client: int, body: int, couplings: tuple[Coupling, ...],
                  joint_by_name: dict[str, int]) -> list[tuple[int, int, float, float]]:
    """Gear constraints follower ↔ driver; returns (follower, driver, ratio, offset) indices."""
    made = []
    for c in couplings:
        follower, driver = joint_by_name[c.follower], joint_by_name[c.driver]
        gear = p.createConstraint(body, driver, body, follower, p.JOINT_GEAR, [0, 0, 1],
                                  [0, 0, 0], [0, 0, 0], physicsClientId=client)
        # pybullet's gear keeps ratio_g · q̇_driver + q̇_follower = 0, so ratio_g = −ratio, and
        # with erp it pulls q_follower toward ratio · q_driver − relativePositionTarget.
        p.changeConstraint(gear, gearRatio=-c.ratio, maxForce=COUPLING_MAX_FORCE,
                           erp=COUPLING_ERP, relativePositionTarget=-c.offset,
                           physicsClientId=client)
        made.append((follower, driver, c.ratio, c.offset))
    return made


def reset_couplings(client: int, body: int, made: list[tuple[int, int, float, float]]) -> None:
    """Puts each follower where its driver says (after the drivers were reset)."""
    for follower, driver, ratio, offset in made:
        q = p.getJointState(body, driver, physicsClientId=client)[0]
        p.resetJointState(body, follower, ratio * q + offset, 0.0, physicsClientId=client)
