"""The MuJoCo model of one evaluation: the gripper (the same URDF the pybullet Hand loads, a
TOML spec's generated one or a vendor's rewritten one) with a free joint on its palm, and the
object as one body of the same convex parts pybullet collides with.

What differs from pybullet, and how the model makes the two comparable (docs/design/simulation.md,
"MuJoCo"):
- Friction: MuJoCo combines two geoms' frictions by their maximum, pybullet multiplies them.
  Every hand and object geom gets the product pybullet uses (object × the hand link's 0.5), so
  each hand-object pair has the coefficient it has in pybullet.
- Only hand-object pairs collide (contype/conaffinity), as in pybullet, which loads the URDF
  without self-collision.
- Joint limits and contacts use a stiff `solref` (time constant 4.2 ms, 2·dt at the default
  step: MuJoCo's floor): the default 0.02 s is far too soft for 1e-5 kg·m² phalanges driven
  at 1.5 N·m.
- One `general` actuator per finger joint; the Hand (mj/hand.py) switches it between a
  force-capped velocity servo and a force-capped position servo, as pybullet's motors are.
- Couplings (URDF <mimic>, linkages) are joint equality constraints q_f = offset + ratio·q_d.
- Mesh geoms collide as their convex hull in MuJoCo: the object is one geom per convex part.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np
from graspscape.workers.sim.gripper.model import HandModel
from graspscape.workers.sim.objects import PreparedObject

HAND_LINK_FRICTION = 0.5  # pybullet's default lateral friction of a URDF link
HAND_GROUP, OBJECT_GROUP = 1, 2
PALM = "palm"
OBJECT = "object"
# Joint damping and armature keep the light phalanges' explicit part of the integration well
# conditioned; pybullet's URDF joints have none, and the values are small against the motors.
ARMATURE = 1e-4
SOLREF_TIMECONST_S = 1.0 / 240.0  # 2 × the default MuJoCo step (240 Hz × 2 substeps)


@dataclass(frozen=True)
class World:
    model: mujoco.MjModel
    palm_body: int
    object_body: int
    palm_dofs: slice  # the free joint's 6 velocity coordinates
    object_qpos: slice  # the object's free joint position (7) coordinates
    object_dofs: slice
    palm_qpos: slice
    fixture: int  # the weld equality that holds the object until release
    grip_weld: int  # the weld of the object to the palm (calibration only)
    joint_ids: dict[str, int]  # hand joint name -> joint id
    actuator_of: dict[str, int]  # finger / spread joint name -> its actuator id
    link_names: dict[int, str]  # body id -> link name ("palm" for the palm)
    link_index: dict[int, int]  # body id -> the pybullet-style link index (-1: palm)
    geom_link: np.ndarray  # geom id -> pybullet-style link index (or -2: not the hand)
    # finger joint name -> (s, g) of the actuator that drives it, where that actuator is not the
    # joint's own (an MJCF's tendon): its length moves s per unit of the fingers' common
    # closing, and a unit of its force is g on this joint (mj/mjcf.py).
    transmission: dict[str, tuple[float, float]] = field(default_factory=dict)


def add_object(spec: mujoco.MjSpec, prepared: PreparedObject, offset: np.ndarray,
                friction: float, solref: list[float]) -> None:
    body = spec.worldbody.add_body(name=OBJECT, pos=offset.tolist())
    body.add_freejoint(name="object_free")
    body.mass = prepared.mass_kg
    body.inertia = list(prepared.inertia_diag)  # pybullet's diagonal (objects/spawn.py)
    body.ipos = [0.0, 0.0, 0.0]
    body.explicitinertial = True
    for i, part in enumerate(prepared.collision_parts):
        spec.add_mesh(name=f"part{i}", uservert=np.asarray(part, float).ravel().tolist())
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"part{i}", mass=0.0,
                      contype=OBJECT_GROUP, conaffinity=HAND_GROUP,
                      friction=[friction, 0.0, 0.0], solref=solref, condim=3)
    spec.add_equality(type=mujoco.mjtEq.mjEQ_WELD, name1=OBJECT, objtype=mujoco.mjtObj.mjOBJ_BODY,
                      name="fixture", data=[0.0] * 10 + [1.0, 0.0],  # anchor 0, torquescale 1
                      solref=solref)
    # The estimator's anchor (mj/calibration.py): the object welded to the palm, off until used.
    spec.add_equality(type=mujoco.mjtEq.mjEQ_WELD, name1=PALM, name2=OBJECT,
                      objtype=mujoco.mjtObj.mjOBJ_BODY, name="grip_weld", active=False,
                      data=[0.0] * 10 + [1.0, 0.0], solref=solref)


def set_options(spec: mujoco.MjSpec, dt: float) -> None:
    spec.option.timestep = dt
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.gravity = [0.0, 0.0, 0.0]
    spec.option.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
    spec.option.impratio = 1.0


def contact_solref(dt: float) -> list[float]:
    """A time constant in seconds, not in steps: at the default step (2.08 ms) it is MuJoCo's
    floor 2·dt; a finer step keeps the same contact model instead of a stiffer one, so a
    finer-step reference measures the integration alone."""
    return [max(SOLREF_TIMECONST_S, 2.0 * dt), 1.0]


def set_up_hand(spec: mujoco.MjSpec, friction: float, solref: list[float], *,
                keep_visual: bool = False) -> None:
    """The free joint on the palm, the hand's weight carried, and every hand geom colliding
    with the object only, with pybullet's pair friction (module docstring). `keep_visual`:
    geoms that collide with nothing (an MJCF's visual ones, which may carry mass) stay so."""
    spec.body(PALM).add_freejoint(name="palm_free")
    for body in spec.bodies:
        if body.name == "world":
            continue
        body.gravcomp = 1.0  # the arm carries the hand's weight (scene.py, "The arm's drive")
        for geom in body.geoms:
            if keep_visual and geom.contype == 0 and geom.conaffinity == 0:
                continue
            geom.contype, geom.conaffinity = HAND_GROUP, OBJECT_GROUP
            geom.friction = [friction, 0.0, 0.0]
            geom.solref = solref
            geom.condim = 3


def build_world(prepared: PreparedObject, hand: HandModel, dt: float, offset: np.ndarray,
                ) -> World:
    spec = mujoco.MjSpec.from_file(str(hand.urdf))
    spec.compiler.discardvisual = True
    set_options(spec, dt)
    friction = prepared.friction * HAND_LINK_FRICTION
    solref = contact_solref(dt)
    set_up_hand(spec, friction, solref)
    finger_joints = [j.name for j in spec.joints if j.name != "palm_free"]
    for j in spec.joints:
        if j.name != "palm_free":
            j.solref_limit = solref
            j.armature = ARMATURE
    driven = {name for f in hand.fingers for name in f.joints}
    driven |= {f.spread_joint for f in hand.fingers if f.spread_joint}
    for name in finger_joints:
        if name in driven:
            spec.add_actuator(name=f"act_{name}", target=name,
                              trntype=mujoco.mjtTrn.mjTRN_JOINT,
                              gaintype=mujoco.mjtGain.mjGAIN_FIXED,
                              biastype=mujoco.mjtBias.mjBIAS_AFFINE,
                              forcelimited=True, forcerange=[-1.0, 1.0])
    for c in hand.couplings:
        spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1=c.follower, name2=c.driver,
                          data=[c.offset, c.ratio, 0, 0, 0] + [0.0] * 7, solref=solref)
    add_object(spec, prepared, offset, friction, solref)
    model = spec.compile()
    return index_world(model)


def index_world(model: mujoco.MjModel, names: dict[str, str] | None = None,
                actuator_of: dict[str, int] | None = None,
                transmission: dict[str, tuple[float, float]] | None = None,
                prefix: str = "") -> World:
    """The World of a compiled model. `names`: joint name -> the Graspscape name of the link
    it moves (an MJCF's; a rewritten URDF's bodies already have theirs); `actuator_of`: finger
    joint -> actuator, where the actuator is not on the joint itself; `prefix`: what an
    attached MJCF's joint names begin with (dropped: joints go by the vendor's names)."""
    palm = model.body(PALM).id
    obj = model.body(OBJECT).id
    palm_joint = model.joint("palm_free")
    obj_joint = model.joint("object_free")
    joint_ids = {model.joint(j).name.removeprefix(prefix): j for j in range(model.njnt)
                 if model.joint(j).name not in ("palm_free", "object_free")}
    if actuator_of is None:
        actuator_of = {model.joint(int(model.actuator_trnid[a, 0])).name: a
                       for a in range(model.nu)}
    link_names = {palm: "palm"}
    link_index = {palm: -1}
    # pybullet's link index is its joint index in URDF order; the body of joint k is link k.
    for k, j in enumerate(sorted(joint_ids.values())):
        body = int(model.jnt_bodyid[j])
        name = model.joint(j).name.removeprefix(prefix)
        link_names[body] = (names or {}).get(name, model.body(body).name)
        link_index[body] = k
    geom_link = np.full(model.ngeom, -2, dtype=int)
    for g in range(model.ngeom):
        body = int(model.geom_bodyid[g])
        while body not in link_index and body != 0:  # a rigid part: its moving ancestor's link
            body = int(model.body_parentid[body])
        if body in link_index:
            geom_link[g] = link_index[body]
    qa, da = int(palm_joint.qposadr[0]), int(palm_joint.dofadr[0])
    qo, do = int(obj_joint.qposadr[0]), int(obj_joint.dofadr[0])
    return World(model=model, palm_body=palm, object_body=obj, palm_dofs=slice(da, da + 6),
                 object_qpos=slice(qo, qo + 7), object_dofs=slice(do, do + 6),
                 palm_qpos=slice(qa, qa + 7), fixture=model.equality("fixture").id,
                 grip_weld=model.equality("grip_weld").id,
                 joint_ids=joint_ids, actuator_of=actuator_of, link_names=link_names,
                 link_index=link_index, geom_link=geom_link,
                 transmission=dict(transmission or {}))


def urdf_dir(work_dir: Path) -> Path:
    return work_dir / "urdf"
