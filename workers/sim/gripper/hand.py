"""The gripper as a pybullet body, and the under-actuated closing of its fingers.

Under-actuation, approximated: each finger has one actuator. Its phalanges close in sequence:
a phalanx that is not yet closing is held at its angle by a stiff position motor (the locked
linkage); the first phalanx closes under a force-capped velocity motor (so it pushes with the
finger's closing effort once blocked, and never overshoots a limit, which pure torque control
does on such light links); when a closing phalanx halts (blocked by the object, or at its
limit), the next one starts closing too, and the blocked ones keep pushing with their full
share of the effort (`settle`). A finger whose phalanges have all halted is done. See
docs/design/simulation.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pybullet as p
from graspscape.shared.specs.gripper import AnyGripperSpec
from graspscape.workers.sim.bullet import (
    get_dynamics_info,
    get_joint_info,
    get_joint_positions,
    get_joint_states,
    get_num_joints,
    get_pose,
    matrix_from_quat,
)
from graspscape.workers.sim.geometry import quat_from_matrix
from graspscape.workers.sim.gripper.model import (
    add_couplings,
    hand_model,
    load_body,
    reset_couplings,
)

# The velocity target of a blocked phalanx: beyond what any link reaches within one step, so its
# motor row saturates at the force cap in the solver's first iteration and the phalanx pushes
# with exactly its share of τ_c. With the closing speed as target, the row gains only about
# speed × the link's effective inertia per iteration: a 0.05 kg distal link needs ≈100
# iterations to reach its cap, so at 50 the finger pushed with a fraction of τ_c that depended
# on the iteration count (docs/design/simulation.md, "Blocked phalanges push").
PUSH_VELOCITY = 1000.0
LIMIT_MARGIN = 1e-3  # rad (or m): a phalanx this close to its upper limit is at it


@dataclass
class FingerJoints:
    name: str
    spread_joint: int | None
    spread_sign: float
    joints: list[int]
    open_values: list[float]
    uppers: list[float]
    shares: list[float]
    active: int = 0  # how many phalanges are closing
    last: list[float] = field(default_factory=list)
    # Links the finger's linkage moves without a command of its own (an MJCF's passive joints,
    # mj/mjcf.py): beyond every phalanx, so one touching the object blocks them all.
    passive: list[int] = field(default_factory=list)


class Hand:
    def __init__(self, client: int, spec: AnyGripperSpec, urdf_dir: Path) -> None:
        self.client = client
        self.spec = spec
        # A TOML spec of boxes or a vendor's URDF, both in the same conventions (model.py).
        self.model = hand_model(spec, urdf_dir)
        self.body = load_body(client, self.model)
        self.link_names: dict[int, str] = {-1: "palm"}
        joint_by_name: dict[str, int] = {}
        infos = [get_joint_info(client, self.body, j)
                 for j in range(get_num_joints(client, self.body))]
        for j, info in enumerate(infos):
            self.link_names[j] = info.link_name.decode()
            joint_by_name[info.joint_name.decode()] = j
        self.joint_by_name = joint_by_name
        self.movable = [j for j in joint_by_name.values()
                        if infos[j].joint_type != p.JOINT_FIXED]
        self.fingers: list[FingerJoints] = []
        for finger in self.model.fingers:
            self.fingers.append(FingerJoints(
                name=finger.finger,
                spread_joint=joint_by_name[finger.spread_joint] if finger.spread_joint else None,
                spread_sign=finger.spread_sign,
                joints=[joint_by_name[name] for name in finger.joints],
                open_values=list(finger.open_values),
                uppers=list(finger.uppers),
                shares=list(finger.shares),
            ))
        self.finger_joints = [j for f in self.fingers for j in f.joints]
        self.mass = sum(get_dynamics_info(client, self.body, link).mass
                        for link in self.link_names)
        # pybullet reports the base pose as the palm's centre-of-mass frame; the gripper frame
        # (palm surface centre) sits at this offset from it.
        self.base_inertial_offset = np.array(
            get_dynamics_info(client, self.body).local_inertial_pos)
        # The trap: default velocity motors lock every joint until switched off.
        p.setJointMotorControlArray(self.body, self.movable, p.VELOCITY_CONTROL,
                                    forces=[0.0] * len(self.movable), physicsClientId=client)
        # Joints that mimic others follow them through gear constraints, motors off.
        self.couplings = add_couplings(client, self.body, self.model.couplings, joint_by_name)
        self.effort = spec.closing_effort
        self.hold_factor = 3.0
        # The last motor command of each finger and spread joint: (mode, target, force).
        # pybullet's saved states hold no motor settings; `reissue` puts these back.
        self.commands: dict[int, tuple[int, float, float]] = {}

    # --- poses -------------------------------------------------------------------------
    def com_pose_for(self, frame_pos: np.ndarray, frame_rot: np.ndarray) -> tuple[list, list]:
        """The base COM pose that puts the gripper frame (palm surface centre) at a pose."""
        com = frame_pos + frame_rot @ self.base_inertial_offset
        return com.tolist(), quat_from_matrix(frame_rot)

    def frame_pose(self) -> tuple[np.ndarray, np.ndarray]:
        pos, orn = get_pose(self.client, self.body)
        rot = matrix_from_quat(orn)
        return np.array(pos) - rot @ self.base_inertial_offset, rot

    # --- joints ------------------------------------------------------------------------
    def reset_open(self, spread: float, effort: float, hold_factor: float) -> None:
        self.effort, self.hold_factor = effort, hold_factor
        cid = self.client
        for finger in self.fingers:
            for j, q in zip(finger.joints, finger.open_values, strict=True):
                p.resetJointState(self.body, j, q, 0.0, physicsClientId=cid)
            finger.active = 0
            finger.last = list(finger.open_values)
            if finger.spread_joint is not None:
                angle = finger.spread_sign * spread
                p.resetJointState(self.body, finger.spread_joint, angle, 0.0, physicsClientId=cid)
                p.setJointMotorControl2(self.body, finger.spread_joint, p.POSITION_CONTROL,
                                        targetPosition=angle, force=10 * effort,
                                        physicsClientId=cid)
                self.commands[finger.spread_joint] = (p.POSITION_CONTROL, angle, 10 * effort)
        reset_couplings(cid, self.body, self.couplings)
        self._hold(self.finger_joints, [q for f in self.fingers for q in f.open_values])

    def _hold(self, joints: list[int], targets: list[float]) -> None:
        self.hold_positions(joints, targets, self.hold_factor * self.effort)

    def hold_positions(self, joints: list[int], targets: list[float], force: float) -> None:
        """Position motors on `joints` (a policy's joint targets), each capped at `force`."""
        if joints:
            p.setJointMotorControlArray(self.body, joints, p.POSITION_CONTROL,
                                        targetPositions=targets, forces=[force] * len(joints),
                                        physicsClientId=self.client)
            for j, q in zip(joints, targets, strict=True):
                self.commands[j] = (p.POSITION_CONTROL, float(q), force)

    def _velocity(self, joint: int, target: float, force: float) -> None:
        p.setJointMotorControl2(self.body, joint, p.VELOCITY_CONTROL, targetVelocity=target,
                                force=force, physicsClientId=self.client)
        self.commands[joint] = (p.VELOCITY_CONTROL, target, force)

    def _close(self, finger: FingerJoints, k: int, speed: float) -> None:
        self._velocity(finger.joints[k], speed, self.effort * finger.shares[k])

    def reissue(self, effort: float | None = None) -> None:
        """Sends the last motor commands again (after a restoreState, which keeps none).
        With `effort`, every finger joint's force is scaled by effort / the closing effort the
        commands were made with (each phalanx pushes with its share of `effort`, a held one
        holds with hold_factor × `effort`); the spread joints keep theirs."""
        scale = 1.0 if effort is None else effort / self.effort
        fingers = set(self.finger_joints)
        for joint, (mode, target, force) in self.commands.items():
            if joint in fingers:
                force *= scale
            if mode == p.POSITION_CONTROL:
                p.setJointMotorControl2(self.body, joint, mode, targetPosition=target,
                                        force=force, physicsClientId=self.client)
            else:
                p.setJointMotorControl2(self.body, joint, mode, targetVelocity=target,
                                        force=force, physicsClientId=self.client)

    def _settle(self, finger: FingerJoints, k: int, angle: float, touching: frozenset[int], *,
                stop_free: bool) -> None:
        """A halted phalanx: at its upper limit, it holds still there (the stop takes the
        effort; pushed on, pybullet's limit yields); blocked by the object (it or a phalanx
        beyond it touches), it pushes with its full share of the effort. Otherwise it is
        free: with `stop_free` it holds still, else its closing motor stays on (pushed, it
        would swing on at full effort)."""
        if angle >= finger.uppers[k] - LIMIT_MARGIN:
            target = 0.0
        elif touching.intersection(finger.joints[k:] + finger.passive):
            target = PUSH_VELOCITY
        elif stop_free:
            target = 0.0
        else:
            return
        self._velocity(finger.joints[k], target, self.effort * finger.shares[k])

    def settle(self, touching: frozenset[int]) -> None:
        """The end of closing: the grasp is formed. Every phalanx that closed pushes on the
        object with exactly its share of τ_c, or holds still where it is (see `_settle`),
        through the trajectory. `touching`: the links touching the object."""
        for finger in self.fingers:
            angles = self.finger_angles(finger)
            for k in range(finger.active):
                self._settle(finger, k, angles[k], touching, stop_free=True)

    def begin_closing(self, speed: float) -> None:
        self.speed = speed
        for finger in self.fingers:
            finger.active = 1
            finger.last = self.finger_angles(finger)
            self._close(finger, 0, speed)

    def finger_angles(self, finger: FingerJoints) -> list[float]:
        return get_joint_positions(self.client, self.body, finger.joints)

    def update_closing(self, stall_tolerance: float,
                       touching: frozenset[int] = frozenset()) -> bool:
        """Advances each finger's closing sequence; True once every phalanx has halted.
        `touching`: the links touching the object (a halted phalanx among or before them is
        blocked by it)."""
        all_done = True
        for finger in self.fingers:
            angles = self.finger_angles(finger)
            moved = [abs(a - b) for a, b in zip(angles, finger.last, strict=True)]
            finger.last = angles
            k = finger.active - 1
            halted = moved[k] < stall_tolerance or angles[k] >= finger.uppers[k] - LIMIT_MARGIN
            if halted:
                self._settle(finger, k, angles[k], touching, stop_free=False)
            if halted and finger.active < len(finger.joints):
                self._close(finger, finger.active, self.speed)
                finger.active += 1
                all_done = False
            elif (finger.active < len(finger.joints)
                  or max(moved[: finger.active]) >= stall_tolerance):
                all_done = False
        return all_done

    def joint_angles(self) -> dict[str, float]:
        joints = sorted(self.joint_by_name.items(), key=lambda kv: kv[1])
        movable = [(name, j) for name, j in joints if j in self.movable]
        angles = get_joint_positions(self.client, self.body, [j for _, j in movable])
        return {name.removesuffix("_joint"): float(q)
                for (name, _), q in zip(movable, angles, strict=True)}

    def max_finger_torque(self) -> float:
        states = get_joint_states(self.client, self.body, self.finger_joints)
        return max(abs(s.applied_joint_motor_torque) for s in states)

