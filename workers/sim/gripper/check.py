"""`graspscape gripper check`: loads a gripper, looks at it and tries it, and says what it
inferred and what looks wrong (docs/howto/add-gripper.md).

In free air (a client of its own, the hand fixed at the origin, no gravity): the open and the
closed hand are rendered from two sides; the reach (how far the open hand's links stand past
the palm surface), the opening (the gap between the closest links of two fingers) and the mass
are measured; every joint's travel while closing is recorded. Then the hand closes on the
built-in sphere and cube from three start poses each (the evaluation every exploration runs).

Problems looked for: a joint that never moves while the hand closes in free air, a finger
whose links never reach the palm's axis (in the plane it closes in: it cannot hold anything
centred on the palm),
links that interpenetrate in the open hand (parent and child links, which meet at their
joint, excepted), a joint that closes past its limits, a declared reach that is not the
measured one, nothing held on the sphere.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pybullet as p
from graspscape.shared.specs.gripper import AnyGripperSpec, GripperSpec
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.bullet import get_closest_points, get_joint_info
from graspscape.workers.sim.geometry import quat_from_matrix
from graspscape.workers.sim.gripper.check_explain import why_no_hold, zero_quality_warnings
from graspscape.workers.sim.gripper.hand import Hand
from graspscape.workers.sim.objects import prepare_object
from graspscape.workers.sim.render import render_scene
from pydantic import BaseModel, Field

FREE_CLOSING_CAP_S = 3.0
STALL_TOLERANCE = 1e-4  # rad or m per check interval: a finger this slow has halted
CHECK_EVERY_STEPS = 24
MOVED_AT_LEAST = 0.02  # rad (revolute) or m / 10 (prismatic: 2 mm)
AXIS_REACH_M = 0.005  # a finger's links must come this close to the palm's axis
INTERPENETRATION_M = 0.001
LIMIT_SLACK = 0.02  # rad or m a joint may stand past its limit (pybullet's limits are soft)
REACH_TOLERANCE_M = 0.005
TRY_POSES = (
    ("side", Pose(theta=math.pi / 2, phi=0.0, r=0.02)),
    ("side, rolled 90°", Pose(theta=math.pi / 2, phi=0.0, r=0.02, roll=math.pi / 2)),
    ("top", Pose(theta=0.0, phi=0.0, r=0.02)),
)


class JointTravel(BaseModel):
    joint: str
    vendor: str
    open: float
    closed: float
    moved: bool


class Trial(BaseModel):
    object: str
    start: str
    outcome: str
    viable: bool
    mu_s: float
    links_in_contact: list[str]


class CheckReport(BaseModel):
    gripper: str
    kind: str = Field(description="toml (boxes) or urdf")
    mass_kg: float
    digits: dict[str, list[str]] = Field(description="digit → its links")
    vendor_names: dict[str, str] = Field(default_factory=dict)
    reach_m: float = Field(description="measured: farthest link point past the palm surface")
    declared_reach_m: float
    opening_m: float = Field(description="open hand: the gap between two fingers' links (the "
                             "widest pair's)")
    closed_gap_m: float = Field(description="free-air closed hand: the same gap")
    joints: list[JointTravel]
    trials: list[Trial]
    pictures: list[str]
    problems: list[str]
    warnings: list[str] = Field(default_factory=list, description="not faults, but worth a "
                                "look: held grasps with μs ≈ 0")


def _digit(link: str) -> str:
    return link.split("_", 1)[0]


def _fixed_hand(client: int, spec: AnyGripperSpec, cache: Path) -> Hand:
    hand = Hand(client, spec, cache / "urdf")
    com, orn = hand.com_pose_for(np.zeros(3), np.eye(3))
    p.resetBasePositionAndOrientation(hand.body, com, orn, physicsClientId=client)
    p.createConstraint(hand.body, -1, -1, -1, p.JOINT_FIXED, [0, 0, 0],
                       (-hand.base_inertial_offset).tolist(), [0, 0, 0],
                       physicsClientId=client)
    p.setGravity(0, 0, 0, physicsClientId=client)
    return hand


def _gap(client: int, hand: Hand) -> float:
    """Per pair of fingers the smallest distance between their links; the largest of these
    over the pairs (a three-finger hand's opening is between the lone finger and the pair)."""
    pairs: dict[tuple[str, str], float] = {}
    links = {j: _digit(n) for j, n in hand.link_names.items() if j >= 0}
    for a, da in links.items():
        for b, db in links.items():
            if a < b and da != db:
                points = p.getClosestPoints(hand.body, hand.body, 1.0, linkIndexA=a,
                                            linkIndexB=b, physicsClientId=client)
                key = (min(da, db), max(da, db))
                pairs[key] = min([pairs.get(key, math.inf)] + [pt[8] for pt in points])
    return max(pairs.values(), default=math.inf)


def _axis_slabs(client: int, hand: Hand) -> dict[str, int]:
    """Per finger, a thin plane through the palm's axis along the direction the finger cannot
    move in (its first joint's axis if revolute; across its stroke and the palm normal if
    prismatic): the finger reaches the axis where it reaches that plane. A digit whose plane is
    undefined (a joint turning about the palm normal, a stroke along it) is left out."""
    slabs: dict[str, int] = {}
    for finger in hand.fingers:
        joint = finger.joints[0]
        info = get_joint_info(client, hand.body, joint)
        state = p.getLinkState(hand.body, joint, computeForwardKinematics=1,
                               physicsClientId=client)
        axis = np.reshape(p.getMatrixFromQuaternion(state[5]), (3, 3)) @ np.array(
            info.joint_axis)
        z = np.array([0.0, 0.0, 1.0])
        along = axis if info.joint_type == p.JOINT_REVOLUTE else np.cross(z, axis)
        along = along - z * float(along @ z)
        if np.linalg.norm(along) < 1e-6:
            continue
        along /= np.linalg.norm(along)
        rot = np.column_stack([np.cross(along, z), along, z])
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[1e-4, 0.5, 0.5],
                                       physicsClientId=client)
        body = p.createMultiBody(0, shape, basePosition=[0, 0, 0.5],
                                 baseOrientation=quat_from_matrix(rot), physicsClientId=client)
        p.setCollisionFilterGroupMask(body, -1, 0, 0, physicsClientId=client)
        slabs[finger.name] = body
    return slabs


def _axis_distances(client: int, hand: Hand, slabs: dict[str, int]) -> dict[str, float]:
    out: dict[str, float] = {}
    for j, name in hand.link_names.items():
        digit = _digit(name)
        if j < 0 or name.endswith("_spread") or digit not in slabs:
            continue
        points = get_closest_points(client, hand.body, slabs[digit], 1.0, link_a=j)
        d = min((pt.contact_distance for pt in points), default=math.inf)
        out[digit] = min(out.get(digit, math.inf), d)
    return out


def _reach(client: int, hand: Hand) -> float:
    return max(p.getAABB(hand.body, j, physicsClientId=client)[1][2]
               for j in hand.link_names if j >= 0)


def _interpenetrating(client: int, hand: Hand) -> list[str]:
    parent = {j: get_joint_info(client, hand.body, j).parent_index for j in hand.link_names
              if j >= 0}
    found = []
    links = sorted(hand.link_names)
    for i, a in enumerate(links):
        for b in links[i + 1:]:
            if parent.get(b) == a or parent.get(a) == b:
                continue
            points = p.getClosestPoints(hand.body, hand.body, 0.0, linkIndexA=a, linkIndexB=b,
                                        physicsClientId=client)
            depth = min((pt[8] for pt in points), default=0.0)
            if depth < -INTERPENETRATION_M:
                found.append(f"links {hand.link_names[a]} and {hand.link_names[b]} "
                             f"interpenetrate by {-depth * 1000:.1f} mm in the open hand")
    return found


def _pictures(client: int, out_dir: Path, state: str) -> list[str]:
    target = np.array([0.0, 0.0, 0.05])
    return [str(render_scene(client, target, out_dir / f"{state}_{side}.png", distance=0.4,
                             yaw=yaw, pitch=-20.0))
            for side, yaw in (("front", 0.0), ("side", 90.0))]


def _free_air(spec: AnyGripperSpec, cache: Path, out_dir: Path | None) -> dict:
    client = p.connect(p.DIRECT)
    try:
        hand = _fixed_hand(client, spec, cache)
        settings = SimSettings()
        p.setPhysicsEngineParameter(fixedTimeStep=settings.physics.dt,
                                    numSolverIterations=settings.physics.solver_iterations,
                                    physicsClientId=client)
        hand.reset_open(0.0, spec.closing_effort, settings.policy.hold_effort_factor)
        p.performCollisionDetection(physicsClientId=client)
        movable = [(name, hand.joint_by_name[f"{name}_joint"]) for name in hand.joint_angles()]
        opened = hand.joint_angles()
        found = {
            "reach": _reach(client, hand),
            "opening": _gap(client, hand),
            "problems": _interpenetrating(client, hand),
            "pictures": _pictures(client, out_dir, "open") if out_dir else [],
        }
        axis = _axis_slabs(client, hand)  # after the pictures: the renderer would draw them
        nearest = _axis_distances(client, hand, axis)
        hand.begin_closing(settings.policy.closing_speed)
        steps = round(FREE_CLOSING_CAP_S / settings.physics.dt)
        for step in range(1, steps + 1):
            p.stepSimulation(physicsClientId=client)
            if step % CHECK_EVERY_STEPS == 0:
                for digit, d in _axis_distances(client, hand, axis).items():
                    nearest[digit] = min(nearest[digit], d)
                if hand.update_closing(STALL_TOLERANCE):
                    break
        closed = hand.joint_angles()
        for body in axis.values():
            p.removeBody(body, physicsClientId=client)
        found["closed_gap"] = _gap(client, hand)
        if out_dir:
            found["pictures"] += _pictures(client, out_dir, "closed")
        vendor = hand.model.vendor_names or {}
        travel = []
        for name, j in movable:
            info = get_joint_info(client, hand.body, j)
            prismatic = info.joint_type == p.JOINT_PRISMATIC
            moved = abs(closed[name] - opened[name]) >= (
                MOVED_AT_LEAST / 10 if prismatic else MOVED_AT_LEAST)
            travel.append(JointTravel(joint=name, vendor=vendor.get(f"{name}_joint", name),
                                      open=opened[name], closed=closed[name], moved=moved))
            lower, upper = info.joint_lower_limit, info.joint_upper_limit
            if lower < upper and not lower - LIMIT_SLACK <= closed[name] <= upper + LIMIT_SLACK:
                found["problems"].append(
                    f"joint {name} ({vendor.get(f'{name}_joint', name)}) closed to "
                    f"{closed[name]:+.3f}, past its limits [{lower:+.3f}, {upper:+.3f}]")
            if not moved and not name.endswith("_spread"):
                found["problems"].append(
                    f"joint {name} ({vendor.get(f'{name}_joint', name)}) never moved while "
                    "the hand closed in free air")
        for digit, d in sorted(nearest.items()):
            if d > AXIS_REACH_M:
                found["problems"].append(
                    f"finger {digit} never comes within {AXIS_REACH_M * 1000:.0f} mm of the "
                    f"palm's axis (closest {d * 1000:.0f} mm): it cannot hold what the palm "
                    "faces")
        digits: dict[str, list[str]] = {}
        for j, name in sorted(hand.link_names.items()):
            digits.setdefault(_digit(name) if j >= 0 else "palm", []).append(name)
        found.update(travel=travel, mass=hand.mass, digits=digits, vendor=vendor)
        return found
    finally:
        p.disconnect(client)


def _trials(spec: AnyGripperSpec, cache: Path, out_dir: Path | None) -> list[Trial]:
    from graspscape.workers.sim.evaluate import Evaluator  # evaluate imports the hand

    trials = []
    for name in ("sphere", "cube"):
        prepared = prepare_object(ObjectSpec(name=name), cache / "objects")
        with Evaluator(prepared, spec, SimSettings(), work_dir=cache) as evaluator:
            for k, (label, pose) in enumerate(TRY_POSES):
                picture = out_dir / f"{name}_{k}.png" if out_dir else None
                result = evaluator.evaluate(pose, picture=picture)
                trials.append(Trial(object=name, start=label, outcome=str(result.outcome.value),
                                    viable=result.viable, mu_s=result.mu_s,
                                    links_in_contact=sorted(result.contacts_per_link or {})))
    return trials


def check_problems(found: dict, trials: list[Trial], declared_reach: float) -> list[str]:
    """The check's problems, in either engine: the free-air findings, a declared reach off
    the measured one, and a hand that held the sphere from no start (with why)."""
    problems = list(found["problems"])
    if abs(found["reach"] - declared_reach) > REACH_TOLERANCE_M:
        problems.append(f"declared reach {declared_reach * 1000:.0f} mm, measured "
                        f"{found['reach'] * 1000:.0f} mm: set reach_m = {found['reach']:.3f}")
    if not any(t.viable for t in trials if t.object == "sphere"):
        why = why_no_hold("sphere", trials, found["travel"], found["digits"])
        problems.append("held the sphere from none of the start poses tried"
                        + (": " + "; ".join(why) if why else ""))
    return problems


def check_gripper(spec: AnyGripperSpec, cache: Path, out_dir: Path | None = None
                  ) -> CheckReport:
    found = _free_air(spec, cache, out_dir)
    trials = _trials(spec, cache, out_dir)
    declared = spec.reach()
    problems = check_problems(found, trials, declared)
    if out_dir:
        found["pictures"] += [str(p_) for p_ in sorted(out_dir.glob("sphere_*.png"))
                              + sorted(out_dir.glob("cube_*.png"))]
    return CheckReport(
        gripper=spec.name, kind="toml" if isinstance(spec, GripperSpec) else "urdf",
        mass_kg=found["mass"], digits=found["digits"], vendor_names=found["vendor"],
        reach_m=found["reach"], declared_reach_m=declared, opening_m=found["opening"],
        closed_gap_m=found["closed_gap"], joints=found["travel"], trials=trials,
        pictures=found["pictures"], problems=problems, warnings=zero_quality_warnings(trials))
