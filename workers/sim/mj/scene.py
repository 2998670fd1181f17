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

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import NamedTuple

import mujoco
import numpy as np
from graspscape.workers.sim.geometry import quat_from_matrix
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
    # No support table in MuJoCo (a plane is refused when the evaluator is made): the table's
    # hooks (table.start_outcome, closing_outcome, the weight as a force) find none.
    table_body: int | None = None
    watch = None
    object_weight_n: float = 0.0

    def __init__(self, world: World, data: mujoco.MjData, hand: MjHand, offset: np.ndarray,
                 dt: float) -> None:
        self.world, self.data, self.hand = world, data, hand
        self.model = world.model
        self.offset, self.dt = offset, dt
        self.object_body = world.object_body
        self._target_pos, self._target_quat = np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        self._cap = DRIVE_MAX_FORCE_N
        self._gains = np.eye(6)
        self._coupling = np.zeros((3, 3))
        self._err = np.zeros(6)
        self._w2, self._2w = DRIVE_BANDWIDTH_RAD_S**2, 2.0 * DRIVE_BANDWIDTH_RAD_S
        self._link = world.geom_link
        colliding = (self.model.geom_contype != 0) | (self.model.geom_conaffinity != 0)
        self._object_geoms = np.flatnonzero(colliding & (world.geom_link == -2)
                                            & (self.model.geom_bodyid == world.object_body))
        self._link_geoms = {link: np.flatnonzero(colliding & (world.geom_link == link))
                            for link in set(world.link_index.values())}
        self._joint_of = {hand.joint_by_name[name]: j for name, j in world.joint_ids.items()}

    def calibrate_drive(self) -> None:
        """The palm block of the mass matrix at the present (open) configuration."""
        m, d = self.model, self.data
        mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        s = self.world.palm_dofs
        self._gains = full[s, s].copy()
        # The free joint's linear coordinates are in the world's axes, its angular ones in the
        # palm's: the block coupling them turns with the palm (−m·R·[c]×, c the centre of mass
        # in the palm's frame). Kept here unturned, turned by the palm's rotation each step;
        # left fixed, it pushed a hand whose centre of mass lies 5 cm behind the palm (the
        # 2F-85) into a growing spin once it was turned 90° from where this ran.
        self._coupling = d.xmat[self.world.palm_body].reshape(3, 3).T @ self._gains[:3, 3:]

    # --- the drive ---------------------------------------------------------------------
    def drive_to(self, position: np.ndarray, rotation: np.ndarray,
                 max_force: float = DRIVE_MAX_FORCE_N) -> None:
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rotation, dtype=float).ravel())
        self._set_target(np.asarray(position, float), quat, max_force)

    def drive_to_quat(self, position: list[float], quaternion: list[float],
                      max_force: float = DRIVE_MAX_FORCE_N) -> None:
        """`drive_to` with a quaternion (x, y, z, w, as ReferencePath.drive gives it)."""
        x, y, z, w = quaternion
        self._set_target(np.array(position, float), np.array([w, x, y, z]), max_force)

    def _set_target(self, position: np.ndarray, quat: np.ndarray, max_force: float) -> None:
        self._target_pos, self._target_quat, self._cap = position, quat, max_force

    def _drive_force(self) -> np.ndarray:
        d, b = self.data, self.world.palm_body
        err = self._err
        err[:3] = self._target_pos - d.xpos[b]
        # The turn from the palm's orientation to the target's, in the palm's axes (the free
        # joint's angular dofs are in the body's axes).
        mujoco.mju_subQuat(err[3:], self._target_quat, d.xquat[b])
        accel = self._w2 * err - self._2w * d.qvel[self.world.palm_dofs]
        turned = d.xmat[b].reshape(3, 3) @ self._coupling  # this step's −m·R·[c]×
        gains = self._gains
        force = np.concatenate([gains[:3, :3] @ accel[:3] + turned @ accel[3:],
                                turned.T @ accel[:3] + gains[3:, 3:] @ accel[3:]])
        lin, ang = float(np.dot(force[:3], force[:3])), float(np.dot(force[3:], force[3:]))
        cap2 = self._cap * self._cap
        if lin > cap2:
            force[:3] *= self._cap / np.sqrt(lin)
        if ang > cap2:
            force[3:] *= self._cap / np.sqrt(ang)
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
        d = self.data
        if d.ncon == 0:
            return []
        links = self._link[d.contact.geom]  # (ncon, 2): a link, or -2 for the object
        close = d.contact.dist <= CONTACT_DISTANCE_M
        first = close & (links[:, 0] != -2) & (links[:, 1] == -2)
        second = close & (links[:, 1] != -2) & (links[:, 0] == -2)
        return ([(int(i), int(links[i, 0]), 1) for i in np.flatnonzero(first)]
                + [(int(i), int(links[i, 1]), -1) for i in np.flatnonzero(second)])

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
        d = self.data
        if d.ncon == 0:
            return False
        hand = self._link[d.contact.geom] != -2
        return bool(np.any((d.contact.dist < -tolerance) & (hand[:, 0] != hand[:, 1])))

    @contextmanager
    def scaled_object(self, friction: float, mass: float) -> Iterator[None]:
        """The hand-object pairs' friction coefficient and the object's mass (its inertia with
        it) × these while the block runs, put back after. MuJoCo combines two geoms'
        frictions by their maximum, so every geom's is scaled (world.py: only hand-object
        pairs collide, each with the product pybullet uses)."""
        if friction == 1.0 and mass == 1.0:
            yield
            return
        model, b = self.model, self.object_body
        mu = model.geom_friction[:, 0].copy()
        m, inertia = float(model.body_mass[b]), model.body_inertia[b].copy()
        model.geom_friction[:, 0] = mu * friction
        model.body_mass[b], model.body_inertia[b] = m * mass, inertia * mass
        try:
            yield
        finally:
            model.geom_friction[:, 0] = mu
            model.body_mass[b], model.body_inertia[b] = m, inertia

    # --- probes: the haptic policy's proximity sensors and finite differences -------------
    def link_distances(self, links: list[int], max_distance: float) -> np.ndarray:
        """Each link's distance to the object (the least over their geoms' pairs,
        mj_geomDistance on the positions now), `max_distance` beyond it."""
        m, d = self.model, self.data
        mujoco.mj_kinematics(m, d)
        out = np.full(len(links), float(max_distance))
        for i, link in enumerate(links):
            for g in self._link_geoms.get(link, ()):
                for o in self._object_geoms:
                    out[i] = min(out[i], mujoco.mj_geomDistance(m, d, int(g), int(o),
                                                                max_distance, None))
        return out

    def joint_limits(self, joints: list[int]) -> np.ndarray:
        return np.array([self.model.jnt_range[self._joint_of[j]] for j in joints])

    def joint_positions(self, joints: list[int]) -> np.ndarray:
        return np.array([self.data.qpos[self.model.jnt_qposadr[self._joint_of[j]]]
                         for j in joints])

    def parent_link(self, link: int) -> int:
        """The link `link` hangs on (−1: the palm), past any rigid bodies between."""
        body = int(self.model.jnt_bodyid[self._joint_of[link]])
        index = self.world.link_index
        body = int(self.model.body_parentid[body])
        while body not in index and body != 0:
            body = int(self.model.body_parentid[body])
        return index.get(body, -1)

    @contextmanager
    def _probing(self) -> Iterator[Callable[[], None]]:
        """Yields `put_back`, which copies the whole mjData of entry back (its derived fields
        too: after mj_step they lag the positions by a step, and the drive reads them);
        called on leaving too."""
        saved = mujoco.MjData(self.model)
        mujoco.mj_copyData(saved, self.model, self.data)

        def put_back() -> None:
            mujoco.mj_copyData(self.data, self.model, saved)

        try:
            yield put_back
        finally:
            put_back()

    def probing_joints(self):
        return self._probing()

    @contextmanager
    def probing_base(self) -> Iterator[None]:
        with self._probing():
            yield

    def teleport_joint(self, joint: int, q: float) -> None:
        self.hand.set_joint(joint, q)

    def teleport_frame(self, position: np.ndarray, rotation: np.ndarray) -> None:
        x, y, z, w = quat_from_matrix(rotation)
        self.data.qpos[self.world.palm_qpos] = [*position, w, x, y, z]
