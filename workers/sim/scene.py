"""The live simulation an evaluation acts on: the client, the hand, the object and the two
constraints (the arm's drive on the hand, the fixture that holds the object until release).
Policies and the robustness tests drive it through these methods."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
import pybullet as p
from graspscape.workers.sim.bullet import (
    ContactPoint,
    get_closest_points,
    get_contact_points,
    get_dynamics_info,
    get_joint_info,
    get_joint_positions,
    get_joint_state,
    get_pose,
    matrix_from_quat,
    saved_state,
    touching_link_indices,
)
from graspscape.workers.sim.geometry import quat_from_matrix
from graspscape.workers.sim.gripper.hand import Hand
from graspscape.workers.sim.table import TableWatch

DRIVE_MAX_FORCE_N = 2000.0
CONTACT_DISTANCE_M = 1e-4


@dataclass
class Scene:
    """The live simulation an evaluation acts on; policies drive it through these methods."""

    client: int
    hand: Hand
    object_body: int
    drive_constraint: int
    fixture_constraint: int
    offset: np.ndarray
    dt: float
    # On a table (workers/sim/table.py): the table body, the object's resting rotation in the
    # world (the pose space stays the object's frame) and its weight, applied to it alone
    # while the hand approaches and closes (0: none applied).
    table_body: int | None = None
    rest_rotation: np.ndarray | None = None
    object_weight_n: float = 0.0
    # While the weight is applied: the watch that tells a knocked object (table.TableWatch).
    watch: TableWatch | None = None
    # The last rotation drive_to converted, as bytes, and its quaternion: the approach drives
    # to one rotation every step, which needs converting once.
    _last_rotation: tuple[bytes, list[float]] = field(default=(b"", []), init=False,
                                                      repr=False)
    _probed: set[int] = field(default_factory=set, init=False, repr=False)

    def drive_to(self, position: np.ndarray, rotation: np.ndarray,
                 max_force: float = DRIVE_MAX_FORCE_N) -> None:
        key = rotation.tobytes()
        if key != self._last_rotation[0]:
            self._last_rotation = (key, quat_from_matrix(rotation))
        p.changeConstraint(self.drive_constraint, jointChildPivot=position.tolist(),
                           jointChildFrameOrientation=self._last_rotation[1],
                           maxForce=max_force, physicsClientId=self.client)

    def drive_to_quat(self, position: list[float], quaternion: list[float],
                      max_force: float = DRIVE_MAX_FORCE_N) -> None:
        """`drive_to` with the position and rotation already converted (ReferencePath.drive):
        the same constraint change, without the conversion."""
        p.changeConstraint(self.drive_constraint, jointChildPivot=position,
                           jointChildFrameOrientation=quaternion,
                           maxForce=max_force, physicsClientId=self.client)

    def step(self) -> None:
        if self.object_weight_n:
            if self.watch is not None:
                self.watch.look(self)
            # An external force lasts one step: applied again before every step.
            position = p.getBasePositionAndOrientation(self.object_body,
                                                       physicsClientId=self.client)[0]
            p.applyExternalForce(self.object_body, -1, [0.0, 0.0, -self.object_weight_n],
                                 position, p.WORLD_FRAME, physicsClientId=self.client)
        p.stepSimulation(physicsClientId=self.client)

    def in_contact(self) -> bool:
        return bool(self._touching())

    def hand_on_table(self) -> bool:
        """Whether the hand touches the table (never without one)."""
        if self.table_body is None:
            return False
        return bool(get_contact_points(self.client, self.hand.body, self.table_body))

    def palm_in_contact(self) -> bool:
        return -1 in self._touching()

    def touching_links(self) -> frozenset[int]:
        """Indices of the hand's links that touch the object (the palm is -1)."""
        return frozenset(self._touching())

    def _touching(self) -> list[int]:
        """The hand's link of each of `contacts()`, read without building their records."""
        return touching_link_indices(self.client, self.hand.body, self.object_body,
                                     CONTACT_DISTANCE_M)

    def contacts(self) -> list[ContactPoint]:
        """The hand's contact points with the object (A: the hand, B: the object)."""
        # pybullet also reports pairs still apart by up to its breaking threshold; only
        # touching pairs are contacts here.
        points = get_contact_points(self.client, self.hand.body, self.object_body)
        return [c for c in points if c.contact_distance <= CONTACT_DISTANCE_M]

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]:
        pos, orn = get_pose(self.client, self.object_body)
        return np.array(pos), matrix_from_quat(orn)

    def pair_friction(self, link: int) -> float:
        """The friction coefficient of the hand's `link` against the object: pybullet
        combines the two bodies' lateral frictions by multiplying them."""
        obj_mu = get_dynamics_info(self.client, self.object_body).lateral_friction
        return obj_mu * get_dynamics_info(self.client, self.hand.body, link).lateral_friction

    def place_hand(self, position: np.ndarray, rotation: np.ndarray) -> None:
        """The open hand at rest with its gripper frame at (position, rotation)."""
        hand, client = self.hand, self.client
        com, orn = hand.com_pose_for(position, rotation)
        p.resetBasePositionAndOrientation(hand.body, com, orn, physicsClientId=client)
        p.resetBaseVelocity(hand.body, [0, 0, 0], [0, 0, 0], physicsClientId=client)
        self.drive_to(position, rotation)
        # Contact queries report the last collision pass; refresh it for the new placement.
        p.performCollisionDetection(physicsClientId=client)

    def penetrating(self, tolerance: float) -> bool:
        """Whether the hand interpenetrates the object deeper than `tolerance`."""
        points = get_closest_points(self.client, self.hand.body, self.object_body, 0.0)
        return any(pt.contact_distance < -tolerance for pt in points)

    @contextmanager
    def scaled_object(self, friction: float, mass: float) -> Iterator[None]:
        """The object's friction coefficient and mass (its inertia with it) × these while
        the block runs, put back after. pybullet multiplies two bodies' frictions, so the
        hand-object pair's coefficient scales as the object's does."""
        if friction == 1.0 and mass == 1.0:
            yield
            return
        cid, body = self.client, self.object_body
        dyn = get_dynamics_info(cid, body)
        mu, m = float(dyn.lateral_friction), float(dyn.mass)
        inertia = [float(x) for x in dyn.local_inertia_diagonal]
        p.changeDynamics(body, -1, lateralFriction=mu * friction, mass=m * mass,
                         localInertiaDiagonal=[x * mass for x in inertia], physicsClientId=cid)
        try:
            yield
        finally:
            p.changeDynamics(body, -1, lateralFriction=mu, mass=m,
                             localInertiaDiagonal=inertia, physicsClientId=cid)

    # --- probes: the haptic policy's proximity sensors and finite differences -------------
    def link_distances(self, links: list[int], max_distance: float) -> np.ndarray:
        """Each link's distance to the object (closest points), `max_distance` beyond it."""
        out = []
        for link in links:
            points = get_closest_points(self.client, self.hand.body, self.object_body,
                                        max_distance, link_a=link)
            out.append(min((pt.contact_distance for pt in points), default=max_distance))
        return np.array(out)

    def joint_limits(self, joints: list[int]) -> np.ndarray:
        infos = [get_joint_info(self.client, self.hand.body, j) for j in joints]
        return np.array([(i.joint_lower_limit, i.joint_upper_limit) for i in infos])

    def joint_positions(self, joints: list[int]) -> np.ndarray:
        return np.array(get_joint_positions(self.client, self.hand.body, joints))

    def parent_link(self, link: int) -> int:
        """The link `link` hangs on (−1: the palm)."""
        return get_joint_info(self.client, self.hand.body, link).parent_index

    @contextmanager
    def probing_joints(self) -> Iterator[Callable[[], None]]:
        """Yields `put_back`, which returns every joint `teleport_joint` moved to its exact
        position and velocity at entry (resetJointState restores them bit for bit: a test
        checks the rollout is unchanged); called on leaving too."""
        body, cid = self.hand.body, self.client
        saved = {j: get_joint_state(cid, body, j) for j in self.hand.movable}

        def put_back() -> None:
            for j in self._probed:
                p.resetJointState(body, j, saved[j].joint_position, saved[j].joint_velocity,
                                  physicsClientId=cid)
            self._probed.clear()

        try:
            yield put_back
        finally:
            put_back()

    def teleport_joint(self, joint: int, q: float) -> None:
        p.resetJointState(self.hand.body, joint, q, 0.0, physicsClientId=self.client)
        self._probed.add(joint)

    @contextmanager
    def probing_base(self) -> Iterator[None]:
        """The whole state back on leaving: putting the base back with
        resetBasePositionAndOrientation is off by ~1e-13 (pybullet converts between the link
        and inertial frames), enough to change a later contact-rich rollout (~1 ms)."""
        with saved_state(self.client):
            yield

    def teleport_frame(self, position: np.ndarray, rotation: np.ndarray) -> None:
        com, orn = self.hand.com_pose_for(position, rotation)
        p.resetBasePositionAndOrientation(self.hand.body, com, orn, physicsClientId=self.client)
