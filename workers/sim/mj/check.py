"""`graspscape gripper check --engine mujoco`: the gripper check (gripper/check.py) in the MuJoCo
engine, for any gripper description and the only one for an MJCF gripper.

In free air (the hand parked far from the object, held by the arm's drive, no gravity) it
measures the mass, the reach (the farthest colliding point past the palm surface), the
opening and the free-air closed gap (the smallest distance between two fingers' colliding
geoms), and every joint's travel while the hand closes; then it closes the hand on the
built-in sphere and cube from the same three starts as the pybullet check. Problems looked
for: a commanded joint that never moves, a joint that closes past its range, a declared reach
that is not the measured one, nothing held on the sphere. No pictures are drawn: pybullet's
renderer draws a MuJoCo grasp only for a gripper it can load (mj/picture.py).
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
from graspscape.shared.specs.gripper import AnyGripperSpec, GripperSpec, MjcfGripperSpec
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.gripper.check import (
    FREE_CLOSING_CAP_S,
    LIMIT_SLACK,
    MOVED_AT_LEAST,
    STALL_TOLERANCE,
    TRY_POSES,
    CheckReport,
    JointTravel,
    Trial,
    check_problems,
)
from graspscape.workers.sim.gripper.check_explain import zero_quality_warnings
from graspscape.workers.sim.mj.evaluate import MjEvaluator
from graspscape.workers.sim.objects import prepare_object

MUJOCO = SimSettings(engine="mujoco")
FAR_M = 1.0  # distances beyond this are not measured


def _colliding(ev: MjEvaluator) -> dict[int, int]:
    """Hand geom → its link index, for the geoms that can touch the object."""
    m, link = ev.world.model, ev.world.geom_link
    return {g: int(link[g]) for g in range(m.ngeom)
            if link[g] != -2 and (m.geom_contype[g] or m.geom_conaffinity[g])}


def _points(m: mujoco.MjModel, d: mujoco.MjData, g: int) -> np.ndarray:
    """World points bounding a geom: a mesh's vertices, a box's corners, else its centre ±
    its bounding radius along each axis."""
    rot, pos = d.geom_xmat[g].reshape(3, 3), d.geom_xpos[g]
    if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
        mesh = int(m.geom_dataid[g])
        a, n = int(m.mesh_vertadr[mesh]), int(m.mesh_vertnum[mesh])
        local = m.mesh_vert[a:a + n]
    elif m.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
        local = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        local = local * m.geom_size[g]
    else:
        local = np.vstack([np.eye(3), -np.eye(3)]) * m.geom_rbound[g]
    return local @ rot.T + pos


def _reach(ev: MjEvaluator, geoms: dict[int, int]) -> float:
    m, d = ev.world.model, ev.data
    pos, rot = ev.scene.hand.frame_pose()
    fingers = [g for g, link in geoms.items() if link >= 0]
    return max(float(((_points(m, d, g) - pos) @ rot[:, 2]).max()) for g in fingers)


def _gap(ev: MjEvaluator, geoms: dict[int, int]) -> float:
    """Per pair of fingers the smallest distance between their geoms; the largest over the
    pairs (as the pybullet check's opening)."""
    m, d, names = ev.world.model, ev.data, ev.scene.hand.link_names
    digit = {g: names[link].split("_", 1)[0] for g, link in geoms.items() if link >= 0}
    pairs: dict[tuple[str, str], float] = {}
    for a, da in digit.items():
        for b, db in digit.items():
            if a < b and da != db:
                key = (min(da, db), max(da, db))
                dist = mujoco.mj_geomDistance(m, d, a, b, FAR_M, None)
                pairs[key] = min(pairs.get(key, np.inf), dist)
    return float(max(pairs.values(), default=np.inf))


def _travel(ev: MjEvaluator, opened: dict[str, float], closed: dict[str, float],
            vendor: dict[str, str], problems: list[str]) -> list[JointTravel]:
    """Each joint's travel, by the link it moves (hand.joint_angles' keys)."""
    m, hand = ev.world.model, ev.scene.hand
    joint_of = {hand.link_names[link]: ev.world.joint_ids[name]
                for name, link in hand.joint_by_name.items()}
    commanded = {hand.link_names[j] for j in hand.finger_joints}
    travel = []
    for name, q_open in opened.items():
        j = joint_of[name]
        prismatic = m.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE
        moved = abs(closed[name] - q_open) >= (MOVED_AT_LEAST / 10 if prismatic
                                              else MOVED_AT_LEAST)
        label = vendor.get(name, name)
        travel.append(JointTravel(joint=name, vendor=label, open=q_open, closed=closed[name],
                                  moved=moved))
        lower, upper = m.jnt_range[j]
        if m.jnt_limited[j] and not lower - LIMIT_SLACK <= closed[name] <= upper + LIMIT_SLACK:
            problems.append(f"joint {name} ({label}) closed to {closed[name]:+.3f}, past its "
                            f"range [{lower:+.3f}, {upper:+.3f}]")
        if not moved and name in commanded:
            problems.append(f"joint {name} ({label}) never moved while the hand closed in "
                            "free air")
    return travel


def _free_air(spec: AnyGripperSpec, cache: Path) -> dict:
    prepared = prepare_object(ObjectSpec(name="sphere"), cache / "objects")
    with MjEvaluator(prepared, spec, MUJOCO, work_dir=cache) as ev:
        ev._reset()  # parked 2 m above the object, open
        hand, scene = ev.scene.hand, ev.scene
        geoms = _colliding(ev)
        mujoco.mj_forward(ev.world.model, ev.data)
        opened = hand.joint_angles()
        found: dict = {"reach": _reach(ev, geoms), "opening": _gap(ev, geoms), "problems": []}
        hand.begin_closing(MUJOCO.policy.closing_speed)
        check = ev.run_settings.policy.check_every_steps
        for step in range(1, round(FREE_CLOSING_CAP_S / scene.dt) + 1):
            scene.step()
            if step % check == 0 and hand.update_closing(STALL_TOLERANCE):
                break
        found["closed_gap"] = _gap(ev, geoms)
        vendor = hand.model.vendor_names or {}
        found["travel"] = _travel(ev, opened, hand.joint_angles(), vendor, found["problems"])
        digits: dict[str, list[str]] = {}
        for j, name in sorted(hand.link_names.items()):
            digits.setdefault(name.split("_", 1)[0] if j >= 0 else "palm", []).append(name)
        found.update(mass=hand.mass, digits=digits, vendor=hand.model.vendor_names or {})
        return found


def _trials(spec: AnyGripperSpec, cache: Path) -> list[Trial]:
    trials = []
    for name in ("sphere", "cube"):
        prepared = prepare_object(ObjectSpec(name=name), cache / "objects")
        with MjEvaluator(prepared, spec, MUJOCO, work_dir=cache) as evaluator:
            for label, pose in TRY_POSES:
                result = evaluator.evaluate(pose)
                trials.append(Trial(object=name, start=label, outcome=str(result.outcome.value),
                                    viable=result.viable, mu_s=result.mu_s,
                                    links_in_contact=sorted(result.contacts_per_link or {})))
    return trials


def check_gripper_mujoco(spec: AnyGripperSpec, cache: Path) -> CheckReport:
    found = _free_air(spec, cache)
    trials = _trials(spec, cache)
    declared = spec.reach()
    problems = check_problems(found, trials, declared)
    kind = ("toml" if isinstance(spec, GripperSpec)
            else "mjcf" if isinstance(spec, MjcfGripperSpec) else "urdf")
    return CheckReport(
        gripper=spec.name, kind=kind, mass_kg=found["mass"], digits=found["digits"],
        vendor_names=found["vendor"], reach_m=found["reach"], declared_reach_m=declared,
        opening_m=found["opening"], closed_gap_m=found["closed_gap"], joints=found["travel"],
        trials=trials, pictures=[], problems=problems,
        warnings=zero_quality_warnings(trials))
