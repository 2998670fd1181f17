"""The shape-informed haptic grasp synthesis policy G_s (paper Sec. III-D, Alg. 1).

Proximity sensor model: every gripper link (the palm, each phalanx and each link of a joint
coupled to another, a parallel jaw's second finger) reads its distance to the nearest object
surface (the engine's closest-point query per link: `scene.link_distances`), saturated at the
sensing range and optionally perturbed by seeded Gaussian noise. The policy acts through the
scene's methods only, so it runs in either engine.

Step 1, digit alignment: the base holds still while the finger joints θ move along the damped
pseudo-inverse of Ĵ_s = ∂d̂/∂θ, d̂_i = d_i − d_b (link distance minus the palm's), asking for
d̂ → 0: links closer than the palm open away, links further away close in (the paper's Fig. 5).
Done when max d̂_i ≤ Δd_s (Alg. 1's loop condition: no link lags behind the palm by more than
the tolerance; links already closer than the palm pass, since the open hand's fingers reach
past the palm and often sit at their opening limit). If the worst offset stops improving (or
the iteration limit is reached) no reachable joint configuration meets the tolerance: the pose
is non-viable (outcome no_grasp, μs = 0).

Step 2, grasp closure: base pose and joints move together along the pseudo-inverse of
J_s = ∂[d_b, d_1 … d_n]/∂[η_r, θ_g], asking every distance to shrink by the same step (so the
hand closes in homogeneously, keeping the shape it took in step 1) until every link touches or
the hand is blocked by the contacts it made. Then, as in G_c, the base holds and the closing
torque τ_c drives the fingers until their motion halts (the hand's under-actuated closing);
also when every link reads within d_c without touching yet (closing makes the contact).

Both iterations are closed loops on the live simulation: each update is sent to the base drive
(force-capped like G_c's approach) and the joint position motors, the physics runs a few steps,
and the next Jacobian is estimated at the pose actually reached. Jacobians are finite
differences of the sensor model: a probe teleports one joint (or the base: the scene's
`teleport_joint`, `teleport_frame`), reads the distances and puts the exact state back (the
scene's `probing_joints`, `probing_base`), so probing never changes what the simulation does
next (a test checks it bit for bit).
Probe readings are noise-free: the Jacobian stands for the local surface model a real
controller would fit; the noise enters the readings that set the targets.
"""

from __future__ import annotations

import time
import zlib
from dataclasses import dataclass

import numpy as np
from graspscape.shared.specs.haptic import HapticPolicySettings
from graspscape.shared.specs.results import Outcome, PhaseTimes
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.policies.closing import close_fingers
from graspscape.workers.sim.policies.registry import register_policy
from scipy.spatial.transform import Rotation


class ProximitySensors:
    """Distance of each sensing link to the object; index 0 is the palm (link −1)."""

    def __init__(self, scene, settings: HapticPolicySettings, seed: int) -> None:
        self.scene = scene
        self.hand = scene.hand
        self.range = settings.sensing_range_m
        self.noise = settings.noise_std_m
        self.rng = np.random.default_rng(seed)
        # The actuated fingers' links and those of joints coupled to them (a parallel jaw's
        # second finger): unsensed, a follower finger is left where it happens to be, and a
        # coupled hand closes on one finger's contact with the object off-centre.
        followers = [follower for follower, *_ in self.hand.couplings]
        self.links = [-1] + [j for f in self.hand.fingers for j in f.joints] + followers
        self.index = {link: i for i, link in enumerate(self.links)}

    def exact(self, links: list[int] | None = None) -> np.ndarray:
        return self.scene.link_distances(links or self.links, self.range)

    def read(self) -> np.ndarray:
        distances = self.exact()
        if self.noise > 0.0:
            distances = distances + self.rng.normal(0.0, self.noise, distances.shape)
        return np.minimum(distances, self.range)


def _followers(hand, joint: int, q: float) -> list[tuple[int, float]]:
    """Each joint coupled to `joint` (through its followers too) and its value for q: the gear
    constraints move them only while the physics steps, so a probe sets them itself."""
    out: list[tuple[int, float]] = []
    for follower, driver, ratio, offset in hand.couplings:
        if driver == joint:
            value = ratio * q + offset
            out += [(follower, value), *_followers(hand, follower, value)]
    return out


def _moved_links(sensors: ProximitySensors, joints: set[int]) -> list[int]:
    """Sensing links that move with any of `joints`: those with one of them up their chain."""
    moved = []
    for link in sensors.links[1:]:
        chain = link
        while chain >= 0 and chain not in joints:
            chain = sensors.scene.parent_link(chain)
        if chain >= 0:
            moved.append(link)
    return moved


def joint_jacobian(sensors: ProximitySensors, joints: list[int], step: float) -> np.ndarray:
    """∂d/∂θ (rows: sensing links, columns: joints) by forward differences; a probe moves the
    joints coupled to the probed one with it, as the gear would."""
    scene, hand = sensors.scene, sensors.hand
    jac = np.zeros((len(sensors.links), len(joints)))
    uppers = scene.joint_limits(joints)[:, 1]
    angles = scene.joint_positions(joints)
    with scene.probing_joints() as put_back:
        base = sensors.exact()
        for col, joint in enumerate(joints):
            q = angles[col]
            # Step inward unless that leaves the joint range (then outward): the model stays
            # valid.
            h = step if q + step <= uppers[col] else -step
            probed = [(joint, q + h), *_followers(hand, joint, q + h)]
            for moved_joint, value in probed:
                scene.teleport_joint(moved_joint, value)
            links = _moved_links(sensors, {j for j, _ in probed})
            probe = sensors.exact(links)
            for link, value in zip(links, probe, strict=True):
                row = sensors.index[link]
                jac[row, col] = (value - base[row]) / h
            put_back()
    return jac


def base_jacobian(sensors: ProximitySensors, step_m: float, step_rad: float) -> np.ndarray:
    """∂d/∂η_r: world translations of the gripper frame, then rotations about world axes
    through the palm centre (rows: sensing links)."""
    scene, hand = sensors.scene, sensors.hand
    with scene.probing_base():
        base = sensors.exact()
        frame_pos, frame_rot = hand.frame_pose()
        jac = np.zeros((len(sensors.links), 6))
        for col in range(6):
            axis = np.zeros(3)
            axis[col % 3] = 1.0
            if col < 3:
                pos, rot, h = frame_pos + axis * step_m, frame_rot, step_m
            else:
                turn = Rotation.from_rotvec(axis * step_rad).as_matrix()
                pos, rot, h = frame_pos, turn @ frame_rot, step_rad
            scene.teleport_frame(pos, rot)
            jac[:, col] = (sensors.exact() - base) / h
    return jac


def damped_pinv_step(jac: np.ndarray, wanted: np.ndarray, damping: float) -> np.ndarray:
    """Δx = Jᵀ(JJᵀ + λ²I)⁻¹ Δd: the pseudo-inverse step, damped so that near-singular
    directions (a link that no joint can move, a saturated reading) do not blow it up."""
    rows = jac.shape[0]
    return jac.T @ np.linalg.solve(jac @ jac.T + damping**2 * np.eye(rows), wanted)


def _clip_norm(v: np.ndarray, limit: float) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v * (limit / n) if n > limit else v


# Step 2 asks each link to close in by its excess over d_c, so the readings converge onto d_c
# from above: a WSG-50 stopped with its palm a fraction of a nanometre short of the band, at
# a fixed point, for 60 iterations. A link this close to the band's edge is in it.
BAND_SLACK_M = 1e-6


@register_policy("haptic")
class HapticPolicy:

    def synthesize(self, scene, position: np.ndarray, rotation: np.ndarray, target: np.ndarray,
                   sim: SimSettings, phases: PhaseTimes) -> Outcome | None:
        cfg = sim.haptic
        hand = scene.hand
        # Same inputs, same noise: the seed comes from the settings and the start pose.
        key = np.round(np.concatenate([position, rotation.ravel()]), 9).tobytes()
        sensors = ProximitySensors(scene, cfg, zlib.crc32(key) ^ cfg.noise_seed)
        joints = list(hand.finger_joints)
        run = _Run(scene, sensors, joints, scene.joint_limits(joints), phases)
        t0 = time.perf_counter()
        # --- step 1: digit alignment (base still, joints only) --------------------------
        scene.drive_to(position, rotation)
        if not _align(run, cfg):
            phases.approach_s = time.perf_counter() - t0
            return Outcome.NO_GRASP
        # --- step 2: grasp closure (base pose and joints together) ----------------------
        closed_in = _close_in(run, cfg)
        phases.approach_s = time.perf_counter() - t0
        if not (closed_in or scene.in_contact()):
            return Outcome.NO_CONTACT

        # --- hold: the base stays, the closing torque τ_c closes the fingers (as G_c) --------
        # Phalanges not yet closing are held where step 2 left them, stiff as in G_c.
        run.command_joints(run.angles(), hand.hold_factor * hand.effort)
        return close_fingers(scene, sim.policy, phases)


@dataclass
class _Run:
    """What both steps of the policy act through: the scene, the sensors and the joints."""

    scene: object
    sensors: ProximitySensors
    joints: list[int]
    limits: np.ndarray
    phases: PhaseTimes

    def angles(self) -> np.ndarray:
        return self.scene.joint_positions(self.joints)  # type: ignore[attr-defined]

    def command_joints(self, values: np.ndarray, force: float) -> None:
        self.scene.hand.hold_positions(self.joints, values.tolist(), force)  # type: ignore[attr-defined]

    def step_joints(self, dq: np.ndarray, force: float) -> None:
        """Joints to their present angles + dq within their limits, pushing with `force`."""
        self.command_joints(np.clip(self.angles() + dq, self.limits[:, 0], self.limits[:, 1]),
                            force)

    def run(self, steps: int) -> None:
        for _ in range(steps):
            self.scene.step()  # type: ignore[attr-defined]
            self.phases.approach_steps += 1


def _align(run: _Run, cfg: HapticPolicySettings) -> bool:
    """Step 1, digit alignment: the joints move (base still) until no link is further from the
    object than the palm by more than the tolerance; False where that is out of reach."""
    hand = run.scene.hand  # type: ignore[attr-defined]
    hold = hand.hold_factor * hand.effort
    best, best_at = np.inf, 0
    for iteration in range(cfg.alignment_max_iterations):
        offsets = (d := run.sensors.read())[1:] - d[0]
        # Alg. 1's condition: no link further from the object than the palm by more than
        # Δd_s. Links closer than the palm (the open fingers reach past it) pass: they are
        # steered away where their joint range allows, but at the opening limit they can't.
        worst = float(np.max(offsets))
        if worst <= cfg.alignment_tolerance_m:
            return True
        if worst < best - cfg.alignment_stall_m:
            best, best_at = worst, iteration
        elif iteration - best_at >= cfg.stall_window:
            return False  # no joint configuration gets closer: the tolerance is out of reach
        # The palm does not move in step 1, so ∂d̂/∂θ is the links' rows of ∂d/∂θ.
        jac = joint_jacobian(run.sensors, run.joints, cfg.jacobian_joint_step_rad)[1:]
        dq = damped_pinv_step(jac, -offsets, cfg.damping)
        run.step_joints(np.clip(dq, -cfg.max_joint_step_rad, cfg.max_joint_step_rad), hold)
        run.run(cfg.steps_per_iteration)
    return False


def _close_in(run: _Run, cfg: HapticPolicySettings) -> bool:
    """Step 2, grasp closure: base pose and joints move together until every link touches
    (True) or the contacts made block the progress or the iterations run out (False)."""
    scene, sensors = run.scene, run.sensors
    hand = scene.hand  # type: ignore[attr-defined]
    progress: list[float] = []
    for _ in range(cfg.closure_max_iterations):
        excess = np.maximum(sensors.read() - cfg.closure_contact_m, 0.0)
        if (excess <= BAND_SLACK_M).all():
            return True  # every link touches
        progress.append(float(excess.sum()))
        if (len(progress) > cfg.stall_window and scene.in_contact()  # type: ignore[attr-defined]
                and progress[-cfg.stall_window - 1] - progress[-1] < cfg.closure_step_m):
            return False  # blocked by the contacts made: the grasp has emerged
        jac = np.hstack([base_jacobian(sensors, cfg.jacobian_base_step_m,
                                       cfg.jacobian_base_step_rad),
                         joint_jacobian(sensors, run.joints, cfg.jacobian_joint_step_rad)])
        dx = damped_pinv_step(jac, -np.minimum(excess, cfg.closure_step_m), cfg.damping)
        shift = _clip_norm(dx[:3], cfg.max_base_step_m)
        turn = _clip_norm(dx[3:6], cfg.max_base_step_rad)
        frame_pos, frame_rot = hand.frame_pose()
        goal_rot = Rotation.from_rotvec(turn).as_matrix() @ frame_rot
        scene.drive_to(frame_pos + shift, goal_rot,  # type: ignore[attr-defined]
                       max_force=cfg.base_force_n)
        # Joints push with at most the closing effort, as G_c's fingers do.
        run.step_joints(np.clip(dx[6:], -cfg.max_joint_step_rad, cfg.max_joint_step_rad),
                        hand.effort)
        run.run(cfg.steps_per_iteration)
    return False
