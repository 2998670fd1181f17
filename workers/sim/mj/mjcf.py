"""A gripper from a vendor's MJCF (`MjcfGripperSpec`: MuJoCo Menagerie's Robotiq 2F-85 and
Franka hand are shipped) in the MuJoCo world, beside the URDF path of world.py.

What loading does (docs/design/simulation.md, "MJCF grippers"):
- the description's base body and its subtree are attached (MjSpec attach, prefix `hand/`)
  under the world's `palm` body at the inverse of the palm frame, so the palm body's frame is
  the gripper frame, as the rewritten URDF's base is; the vendor's visual-only geoms stay
  visual (their mass counts), and every other hand geom gets world.py's contact settings
  (hand-object pairs only, pybullet's pair friction, the stiff solref);
- a finger joint that closes toward smaller values is turned around (axis, range, spring
  reference negated), so every finger joint closes as its value grows;
- the MJCF's own couplings stay as they are: the 2F-85's four-bar linkages are its `connect`
  equalities, its two drivers are tied by a joint equality and share one tendon actuator, its
  spring links are joint springs; the Franka fingers are tied by a joint equality and share a
  tendon actuator. Those under-actuated joints are `passive` in the description: they count
  for their finger's digit, the closing sequence never commands them;
- the description's actuator is kept with its transmission (a tendon or a joint), and the
  closing sequence (mj/hand.py) rewrites its gains per command as it does a joint's own
  actuator, through the transmission's factors (world.World.transmission).
The vendor's joint damping, armature and limit softness are kept: they are part of the model.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
from graspscape.shared.specs.gripper import AnyGripperSpec, MjcfGripperSpec
from graspscape.shared.specs.gripper_frames import palm_in_base_link
from graspscape.workers.sim.gripper.model import HandModel, hand_model
from graspscape.workers.sim.gripper.urdf_import import (
    GripperFileError,
    JointLayout,
    resolve_inside,
)
from graspscape.workers.sim.mj.world import (
    HAND_LINK_FRICTION,
    PALM,
    World,
    add_object,
    build_world,
    contact_solref,
    index_world,
    set_options,
    set_up_hand,
)
from graspscape.workers.sim.objects import PreparedObject

PREFIX = "hand/"
MOVING = (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE)


def load_world(prepared: PreparedObject, gripper: AnyGripperSpec, dt: float,
               offset: np.ndarray, work_dir: Path) -> tuple[World, HandModel]:
    """The world of one evaluation and the hand's layout, for any gripper description."""
    if isinstance(gripper, MjcfGripperSpec):
        return build_mjcf_world(prepared, gripper, dt, offset)
    model = hand_model(gripper, work_dir / "urdf")
    return build_world(prepared, model, dt, offset), model


def _vendor_spec(gripper: MjcfGripperSpec) -> mujoco.MjSpec:
    path = resolve_inside(Path(gripper.folder), gripper.mjcf)
    try:
        return mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:
        raise GripperFileError(f"{gripper.mjcf}: MuJoCo cannot read it ({exc})") from None


def _subtree_joints(body: mujoco.MjsBody) -> list[mujoco.MjsJoint]:
    out = list(body.joints)
    for child in body.bodies:
        out += _subtree_joints(child)
    return out


def _check_joints(gripper: MjcfGripperSpec, base: mujoco.MjsBody) -> dict[str, int]:
    """Each named joint's closing sign; refuses a missing joint or a moving one left unnamed."""
    joints = {j.name: j for j in _subtree_joints(base)}
    sign = {j.joint: j.closing for f in gripper.fingers for j in f.joints}
    sign |= {name: 1 for f in gripper.fingers for name in f.passive}
    for name in sign:
        if name not in joints or joints[name].type not in MOVING:
            raise GripperFileError(f"joint {name!r} is not a hinge or slide joint under "
                                   f"{gripper.base_body!r} in {gripper.mjcf}")
    free = sorted(n for n, j in joints.items() if j.type in MOVING and n not in sign)
    if free:
        raise GripperFileError(f"joints {', '.join(free)} move but are in no finger of the "
                               "description: name them (a finger joint or a passive one)")
    for name, s in sign.items():
        if s == -1:  # closing-positive, as the Hand's sequencing assumes
            j = joints[name]
            j.axis = -np.asarray(j.axis)
            j.range = [-j.range[1], -j.range[0]]
            j.ref, j.springref = -j.ref, -j.springref
    return sign


def _layout(gripper: MjcfGripperSpec, ranges: dict[str, tuple[float, float]],
            sign: dict[str, int]) -> tuple[tuple[JointLayout, ...], dict[str, str]]:
    """The fingers for the Hand (vendor joint names, closing-positive values) and each joint's
    link name (`<finger>_<k>`: its closing joints, then its passive ones)."""
    fingers, names = [], {}
    for f in gripper.fingers:
        joints = [j.joint for j in f.joints]
        for k, name in enumerate(joints + list(f.passive), start=1):
            names[name] = f"{f.name}_{k}"
        opens = tuple(sign[j.joint] * j.open for j in f.joints)
        for j, q in zip(f.joints, opens, strict=True):
            low, high = ranges[j.joint]
            if not low - 1e-9 <= q <= high + 1e-9:
                raise GripperFileError(f"joint {j.joint!r}: open value {j.open} is outside "
                                       "its range")
        fingers.append(JointLayout(
            finger=f.name, spread_joint=None, spread_sign=1.0, joints=tuple(joints),
            open_values=opens, uppers=tuple(ranges[j][1] for j in joints),
            shares=tuple(j.torque_share for j in f.joints)))
    return tuple(fingers), names


def _transmission(model: mujoco.MjModel, actuator: int, joints: list[str],
                  ) -> dict[str, tuple[float, float]]:
    """(s, g) per finger joint of the closing actuator (world.World.transmission): a tendon's
    length moves Σ coef per unit of the fingers' common closing, and pushes coef on each."""
    gear = float(model.actuator_gear[actuator, 0])
    target = int(model.actuator_trnid[actuator, 0])
    if model.actuator_trntype[actuator] == mujoco.mjtTrn.mjTRN_JOINT:
        coef = {model.joint(target).name.removeprefix(PREFIX): 1.0}
    elif model.actuator_trntype[actuator] == mujoco.mjtTrn.mjTRN_TENDON:
        a, n = int(model.tendon_adr[target]), int(model.tendon_num[target])
        coef = {model.joint(int(model.wrap_objid[w])).name.removeprefix(PREFIX):
                float(model.wrap_prm[w]) for w in range(a, a + n)
                if model.wrap_type[w] == mujoco.mjtWrap.mjWRAP_JOINT}
    else:
        raise GripperFileError("the closing actuator must act on a joint or a fixed tendon")
    missing = [j for j in joints if coef.get(j, 0.0) == 0.0]
    if missing:
        raise GripperFileError(f"the closing actuator does not move {', '.join(missing)}")
    s = gear * sum(coef.values())
    return {j: (s, gear * coef[j]) for j in joints}


def build_mjcf_world(prepared: PreparedObject, gripper: MjcfGripperSpec, dt: float,
                     offset: np.ndarray) -> tuple[World, HandModel]:
    vendor = _vendor_spec(gripper)
    base = vendor.body(gripper.base_body)
    if base is None:
        raise GripperFileError(f"base body {gripper.base_body!r} is not in {gripper.mjcf}")
    sign = _check_joints(gripper, base)
    ranges = {j.name: tuple(j.range) for j in _subtree_joints(base)}
    fingers, names = _layout(gripper, ranges, sign)
    if vendor.actuator(gripper.actuator) is None:
        raise GripperFileError(f"actuator {gripper.actuator!r} is not in {gripper.mjcf}")
    base.pos, base.quat = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]
    spec = mujoco.MjSpec()
    set_options(spec, dt)
    for field in ("cone", "impratio", "integrator", "timestep"):  # no attach conflicts
        setattr(vendor.option, field, getattr(spec.option, field))
    vendor.option.gravity = spec.option.gravity
    to_base = np.linalg.inv(palm_in_base_link(gripper))
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, to_base[:3, :3].ravel())
    frame = spec.worldbody.add_body(name=PALM).add_frame(pos=to_base[:3, 3], quat=quat)
    frame.attach_body(base, PREFIX, "")
    friction = prepared.friction * HAND_LINK_FRICTION
    solref = contact_solref(dt)
    set_up_hand(spec, friction, solref, keep_visual=True)
    act = spec.actuator(PREFIX + gripper.actuator)
    act.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE  # targets in joint units (mj/hand.py)
    act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
    act.gaintype, act.biastype = mujoco.mjtGain.mjGAIN_FIXED, mujoco.mjtBias.mjBIAS_AFFINE
    act.dyntype = mujoco.mjtDyn.mjDYN_NONE
    add_object(spec, prepared, offset, friction, solref)
    model = spec.compile()
    closing = [j for f in fingers for j in f.joints]
    a = model.actuator(PREFIX + gripper.actuator).id
    world = index_world(model, names=names, actuator_of=dict.fromkeys(closing, a),
                        transmission=_transmission(model, a, closing), prefix=PREFIX)
    vendor_names = {names[j]: j for j in names}
    passive = {f.name: tuple(f.passive) for f in gripper.fingers}
    return world, HandModel(Path(gripper.folder) / gripper.mjcf, 0, fingers, (), vendor_names,
                            passive)
