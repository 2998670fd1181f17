"""The μs estimator's calibration: what it reads on an object welded to the palm.

A rigid grasp has S = G − I = 0 and μs = 1 by definition, so a weld is the estimator's anchor.
`weld_reading` places the open hand at a pose, welds the object to the palm where it is (every
collision between hand and object switched off, so nothing but the weld acts), releases it
under gravity and probes each instant the evaluator's trajectory would, driving the hand along
the reference path in between. Used by the tests and by benchmarks/bench_metric_stability.py.
"""

from __future__ import annotations

import pybullet as p
from graspscape.shared.specs.pose import Pose
from graspscape.workers.sim.bullet import get_pose
from graspscape.workers.sim.sensitivity import ProbeContext, probe_instant
from graspscape.workers.sim.trajectory import reference_pose

WELD_MAX_FORCE_N = 1e5
# Approaches from above, the sides and below, both roll references (the mug's first one is
# infeasible: the open hand would stand in it).
CALIBRATION_POSES = tuple(
    Pose(theta=t, phi=f, r=0.02, roll=roll) for t, f, roll in
    [(0.3, 0.0, 0.0), (1.57, 0.0, 0.0), (1.57, 1.0, 1.57), (2.0, 3.14, 0.0), (1.0, 4.0, 0.8),
     (1.3, 2.2, 0.0), (2.6, 5.5, 1.0)])
# The objects the issue names: the built-ins and a 3 cm ball (the sphere at 0.375 scale).
CALIBRATION_OBJECTS = (("sphere", 1.0), ("cube", 1.0), ("can", 1.0), ("mug", 1.0),
                       ("sphere", 0.375))


def weld_reading(evaluator, pose: Pose) -> list[float]:
    """Per-instant qualities 1 − σ_max(S) of the welded object; [] where the pose is
    infeasible (the open hand cannot be placed). The evaluator's next evaluation starts from
    its pristine state as always; the weld and the collision filter are undone here."""
    evaluator._reset()
    start = evaluator._start_pose(pose)
    if start is None:
        return []
    evaluator._place(start[0], start[1])
    scene = evaluator.scene
    cid, hand, obj = scene.client, scene.hand.body, scene.object_body
    relative_pos, relative_orn = p.multiplyTransforms(
        *p.invertTransform(*get_pose(cid, hand)), *get_pose(cid, obj))
    weld = p.createConstraint(hand, -1, obj, -1, p.JOINT_FIXED, [0, 0, 0], relative_pos,
                              [0, 0, 0], relative_orn, physicsClientId=cid)
    p.changeConstraint(weld, maxForce=WELD_MAX_FORCE_N, physicsClientId=cid)
    for link in scene.hand.link_names:
        p.setCollisionFilterPair(hand, obj, link, -1, 0, physicsClientId=cid)
    try:
        p.changeConstraint(scene.fixture_constraint, maxForce=0.0, physicsClientId=cid)
        spec, metric = evaluator.settings.trajectory, evaluator.settings.metric
        p.setGravity(0, 0, -spec.gravity_m_s2, physicsClientId=cid)
        start_pos, start_rot = scene.hand.frame_pose()
        pivot = scene.object_pose()[0]

        def target(step: int):
            return reference_pose(spec, start_pos, start_rot, pivot, step * scene.dt)

        ctx = ProbeContext(client=cid, hand_body=hand, object_body=obj, drive=scene.drive_to,
                           contact_free_state=evaluator.pristine, target=target)
        n_steps = max(1, round(spec.duration_s / scene.dt))
        instants = {min(n_steps - 1, int((k + 0.5) * n_steps / metric.instants))
                    for k in range(metric.instants)}
        qualities = []
        for step in range(n_steps):
            if step in instants:
                qualities.append(probe_instant(ctx, step, scene.dt, metric, evaluator.length))
            scene.drive_to(*target(step + 1))
            scene.step()
        return qualities
    finally:
        p.removeConstraint(weld, physicsClientId=cid)
        for link in scene.hand.link_names:
            p.setCollisionFilterPair(hand, obj, link, -1, 1, physicsClientId=cid)
