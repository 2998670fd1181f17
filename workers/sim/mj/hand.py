"""The gripper in MuJoCo: the pybullet Hand's under-actuated closing sequence (begin_closing,
update_closing, settle: workers/sim/gripper/hand.py) on MuJoCo actuators.

Only the motor commands and the joint reads are engine-specific, so this class inherits the
sequence and replaces those. A pybullet motor is a solver row with a force cap; here each
finger joint has one `general` actuator whose gain, bias (affine: MuJoCo ignores a bias that
is not) and force range are rewritten per command:
- velocity motor (target q̇*, cap F): force = kv·(q̇* − q̇) clipped to ±F, kv = F / 6 rad/s.
  With kv this soft a phalanx closing at the policy's 6 rad/s from rest gets exactly F and is
  never clipped on its way, while a blocked one (target PUSH_VELOCITY) is clipped at F. A
  stiffer kv closed at cap/kv instead: the implicit-fast integrator keeps −kv·q̇ in the step's
  implicit part even while the force is clipped (measured: 1 rad/s against 6 at kv = 10·F).
- position motor (target q*, cap F): force = kp·(q* − q) − kd·q̇ clipped to ±F, kp = F / 0.05
  rad (the full cap 0.05 rad off target), kd = 0.1·F s. The spring is explicit: stable on the
  1e-5 kg·m² distal links only because the implicit damping adds dt·kd ≫ I to the step.
An explicit per-joint torque that reaches the target velocity in one step (what pybullet's row
does) was tried and oscillated: the phalanges' inertia coupling makes one joint's deadbeat
torque overshoot its neighbours'.
"""

from __future__ import annotations

import mujoco
import numpy as np
from graspscape.shared.specs.gripper import AnyGripperSpec
from graspscape.workers.sim.gripper.hand import FingerJoints, Hand
from graspscape.workers.sim.gripper.model import HandModel
from graspscape.workers.sim.mj.world import World

VELOCITY, POSITION = 0, 1
VELOCITY_BAND = 6.0  # rad/s (or m/s): kv = F / this
POSITION_BAND = 0.05  # rad (or m): kp = F / this
KD_PER_FORCE = 0.1  # s


class MjHand(Hand):
    """Hand with MuJoCo underneath: same attributes the policies read (fingers, finger_joints,
    link_names, mass, effort, hold_factor, couplings, movable)."""

    def __init__(self, world: World, data: mujoco.MjData, spec: AnyGripperSpec,
                 model: HandModel) -> None:
        self.world, self.data, self.spec, self.model = world, data, spec, model
        m = world.model
        # Link indices as the Scene reports them (world.link_index), joints by those indices.
        self.link_names = {world.link_index[b]: name for b, name in world.link_names.items()}
        by_name = {name: world.link_index[int(m.jnt_bodyid[j])]
                   for name, j in world.joint_ids.items()}
        self.joint_by_name = by_name
        self.movable = sorted(by_name.values())
        self._qpos = {by_name[n]: int(m.jnt_qposadr[j]) for n, j in world.joint_ids.items()}
        self._dof = {by_name[n]: int(m.jnt_dofadr[j]) for n, j in world.joint_ids.items()}
        self._act = {by_name[n]: a for n, a in world.actuator_of.items()}
        self.fingers = [FingerJoints(
            name=f.finger,
            spread_joint=by_name[f.spread_joint] if f.spread_joint else None,
            spread_sign=f.spread_sign, joints=[by_name[n] for n in f.joints],
            open_values=list(f.open_values), uppers=list(f.uppers), shares=list(f.shares),
            passive=[by_name[n] for n in (model.passive or {}).get(f.finger, ())],
        ) for f in model.fingers]
        self.finger_joints = [j for f in self.fingers for j in f.joints]
        self.couplings = [(by_name[c.follower], by_name[c.driver], c.ratio, c.offset)
                          for c in model.couplings]
        self.mass = float(m.body_subtreemass[world.palm_body])  # rigid parts included
        # (s, g) of a joint driven through a shared actuator (world.transmission).
        self._trn = {by_name[n]: sg for n, sg in world.transmission.items()}
        self.base_inertial_offset = np.array(m.body_ipos[world.palm_body])
        self.effort = spec.closing_effort
        self.hold_factor = 3.0
        self.commands: dict[int, tuple[int, float, float]] = {}

    # --- poses -------------------------------------------------------------------------
    def frame_pose(self) -> tuple[np.ndarray, np.ndarray]:
        b = self.world.palm_body
        return self.data.xpos[b].copy(), self.data.xmat[b].reshape(3, 3).copy()

    # --- joints ------------------------------------------------------------------------
    def set_joint(self, joint: int, q: float) -> None:
        self.data.qpos[self._qpos[joint]] = q
        self.data.qvel[self._dof[joint]] = 0.0

    def reset_open(self, spread: float, effort: float, hold_factor: float) -> None:
        self.effort, self.hold_factor = effort, hold_factor
        for finger in self.fingers:
            for j, q in zip(finger.joints, finger.open_values, strict=True):
                self.set_joint(j, q)
            finger.active = 0
            finger.last = list(finger.open_values)
            if finger.spread_joint is not None:
                angle = finger.spread_sign * spread
                self.set_joint(finger.spread_joint, angle)
                self._command(finger.spread_joint, POSITION, angle, 10 * effort)
        for follower, driver, ratio, offset in self.couplings:
            self.set_joint(follower, ratio * self.data.qpos[self._qpos[driver]] + offset)
        self._hold(self.finger_joints, [q for f in self.fingers for q in f.open_values])

    def _command(self, joint: int, mode: int, target: float, force: float) -> None:
        self.commands[joint] = (mode, float(target), float(force))
        self._apply(joint, mode, target, force)

    def _apply(self, joint: int, mode: int, target: float, force: float) -> None:
        act = self._act.get(joint)
        if act is None:
            return
        m = self.world.model
        # A shared actuator (an MJCF's tendon) works in its own units: the fingers' common
        # target times s, the joint's force over g (world.transmission); the gains below then
        # reach the cap at the same joint error as a joint's own actuator does.
        s, g = self._trn.get(joint, (1.0, 1.0))
        force, target = force / g, target * s
        m.actuator_forcerange[act] = (-force, force)
        m.actuator_biasprm[act, :3] = 0.0
        if mode == VELOCITY:
            kv = force / (VELOCITY_BAND * s)
            m.actuator_gainprm[act, 0] = kv
            m.actuator_biasprm[act, 2] = -kv
        else:
            kp = force / (POSITION_BAND * s)
            m.actuator_gainprm[act, 0] = kp
            m.actuator_biasprm[act, 1] = -kp
            m.actuator_biasprm[act, 2] = -KD_PER_FORCE * force / s
        self.data.ctrl[act] = target

    def hold_positions(self, joints: list[int], targets: list[float], force: float) -> None:
        for j, q in zip(joints, targets, strict=True):
            self._command(j, POSITION, q, force)

    def _velocity(self, joint: int, target: float, force: float) -> None:
        self._command(joint, VELOCITY, target, force)

    def reissue(self, effort: float | None = None) -> None:
        """Applies the recorded commands again (the model holds them, but a restored mjData
        copy holds the controls of its own time, and an earlier `effort` may have scaled
        them); with `effort`, every finger joint's force is scaled by effort / the closing
        effort, as Hand.reissue does. The record itself is not changed."""
        scale = 1.0 if effort is None else effort / self.effort
        fingers = set(self.finger_joints)
        for joint, (mode, target, force) in self.commands.items():
            self._apply(joint, mode, target, force * scale if joint in fingers else force)

    def finger_angles(self, finger: FingerJoints) -> list[float]:
        return [float(self.data.qpos[self._qpos[j]]) for j in finger.joints]

    def joint_angles(self) -> dict[str, float]:
        """By the Graspscape link name each joint moves (a URDF's joint name less `_joint`;
        an MJCF's `<finger>_<k>`, mj/mjcf.py)."""
        return {self.link_names[j]: float(self.data.qpos[self._qpos[j]])
                for j in sorted(self.joint_by_name.values())}

    def max_finger_torque(self) -> float:
        forces = [abs(self.data.actuator_force[self._act[j]]) * self._trn.get(j, (1.0, 1.0))[1]
                  for j in self.finger_joints if j in self._act]
        return float(max(forces)) if forces else 0.0
