"""The live MuJoCo simulation an evaluation acts on: the methods of workers/sim/scene.py's
Scene (what the policies, the start pose and the metrics call), on an MjModel and MjData.

The arm's drive. pybullet's drive is a fixed constraint with a force cap (G_c's approach
pushes with at most f_c through it). MuJoCo's equality constraints have no force cap, so the
drive here is a force-capped 6-D PD on the palm's free joint: generalized force
M₆(ω²·e − 2ω·v), e the pose error, M₆ the palm block of the mass matrix at the open hand
(so ω is the drive's bandwidth whatever the hand weighs), the force clipped to the cap and the
torque to the same number in N·m (pybullet caps every row of a constraint with one maxForce).
The hand's own weight is compensated (`gravcomp`), as a stiff pybullet drive carries it.
"""

from __future__ import annotations

from typing import NamedTuple

import mujoco
import numpy as np
from graspscape.workers.sim.geometry import quat_from_matrix, rotation_vector
from graspscape.workers.sim.mj.hand import MjHand
from graspscape.workers.sim.mj.world import World

DRIVE_MAX_FORCE_N = 2000.0
CONTACT_DISTANCE_M = 1e-4
DRIVE_BANDWIDTH_RAD_S = 2 * np.pi * 25.0


class MjContact(NamedTuple):
    """The fields of bullet.ContactPoint the metrics read (A: the hand, B: the object)."""

    link_index_a: int
    position_on_b: tuple[float, float, float]
    contact_normal_on_b: tuple[float, float, float]  # from the object toward the hand
    contact_distance: float
    normal_force: float


class MjScene:
    def __init__(self, world: World, data: mujoco.MjData, hand: MjHand, offset: np.ndarray,
                 dt: float) -> None:
        self.world, self.data, self.hand = world, data, hand
        self.model = world.model
        self.offset, self.dt = offset, dt
        self.object_body = world.object_body
        self._target = (np.zeros(3), np.eye(3))
        self._cap = DRIVE_MAX_FORCE_N
        self._gains = np.eye(6)

    def calibrate_drive(self) -> None:
        """The palm block of the mass matrix at the present (open) configuration."""
        m, d = self.model, self.data
        mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        s = self.world.palm_dofs
        self._gains = full[s, s].copy()

    # --- the drive ---------------------------------------------------------------------
    def drive_to(self, position: np.ndarray, rotation: np.ndarray,
                 max_force: float = DRIVE_MAX_FORCE_N) -> None:
        self._target = (np.asarray(position, float), np.asarray(rotation, float))
        self._cap = max_force

    def drive_to_quat(self, position: list[float], quaternion: list[float],
                      max_force: float = DRIVE_MAX_FORCE_N) -> None:
        x, y, z, w = quaternion
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, np.array([w, x, y, z]))
        self.drive_to(np.array(position), rot.reshape(3, 3), max_force)

    def _drive_force(self) -> np.ndarray:
        d, b = self.data, self.world.palm_body
        pos, rot = d.xpos[b], d.xmat[b].reshape(3, 3)
        target_pos, target_rot = self._target
        v = d.qvel[self.world.palm_dofs]
        # Free joint: linear dofs in world axes, angular dofs in the body's axes.
        err = np.concatenate([target_pos - pos, rot.T @ rotation_vector(target_rot @ rot.T)])
        w = DRIVE_BANDWIDTH_RAD_S
        force = self._gains @ (w * w * err - 2.0 * w * v)
        for part in (slice(0, 3), slice(3, 6)):
            norm = float(np.linalg.norm(force[part]))
            if norm > self._cap:
                force[part] *= self._cap / norm
        return force

    def step(self) -> None:
        self.data.qfrc_applied[self.world.palm_dofs] = self._drive_force()
        mujoco.mj_step(self.model, self.data)

    # --- gravity and the fixture -------------------------------------------------------
    def set_gravity(self, g: float) -> None:
        self.model.opt.gravity[:] = (0.0, 0.0, -g)

    def hold_object(self, held: bool) -> None:
        self.data.eq_active[self.world.fixture] = 1 if held else 0

    # --- contacts ----------------------------------------------------------------------
    def _hand_contacts(self) -> list[tuple[int, int, int]]:
        """(contact index, hand link index, sign) of the hand-object contacts touching."""
        d, link = self.data, self.world.geom_link
        found = []
        for i in range(d.ncon):
            c = d.contact[i]
            if c.dist > CONTACT_DISTANCE_M:
                continue
            a, b = link[c.geom1], link[c.geom2]
            if a != -2 and b == -2:
                found.append((i, int(a), 1))
            elif b != -2 and a == -2:
                found.append((i, int(b), -1))
        return found

    def in_contact(self) -> bool:
        return bool(self._hand_contacts())

    def palm_in_contact(self) -> bool:
        return any(link == -1 for _, link, _ in self._hand_contacts())

    def touching_links(self) -> frozenset[int]:
        return frozenset(link for _, link, _ in self._hand_contacts())

    def contacts(self) -> list[MjContact]:
        out, force = [], np.zeros(6)
        for i, link, sign in self._hand_contacts():
            c = self.data.contact[i]
            mujoco.mj_contactForce(self.model, self.data, i, force)
            # MuJoCo's frame normal points from geom1 to geom2; "on B" points to the hand.
            normal = -sign * np.array(c.frame[:3])
            out.append(MjContact(link, tuple(c.pos), tuple(normal), float(c.dist),
                                 float(force[0])))
        return out

    def pair_friction(self, link: int) -> float:
        del link  # every hand-object pair has the same coefficient (world.py)
        return float(self.model.geom_friction[self.world.geom_link == -2][0, 0])

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]:
        b = self.object_body
        return self.data.xpos[b].copy(), self.data.xmat[b].reshape(3, 3).copy()

    # --- placement (start_pose.py) -----------------------------------------------------
    def place_hand(self, position: np.ndarray, rotation: np.ndarray) -> None:
        d, w = self.data, self.world
        x, y, z, qw = quat_from_matrix(rotation)
        d.qpos[w.palm_qpos] = [*position, qw, x, y, z]
        d.qvel[w.palm_dofs] = 0.0
        self.drive_to(position, rotation)
        mujoco.mj_forward(self.model, d)

    def penetrating(self, tolerance: float) -> bool:
        d, link = self.data, self.world.geom_link
        for i in range(d.ncon):
            c = d.contact[i]
            if c.dist < -tolerance and (link[c.geom1] == -2) != (link[c.geom2] == -2):
                return True
        return False
