"""Outcome-only evaluation: one draw of a grasp's success probability.

A draw needs the outcome (held along the reference trajectory or not) and the grasp type (the
links in contact once the hand has closed), not μs probes, margins or grasp tests: `sample`
runs placement, approach, closing, release and the trajectory with the probes off, under a
draw's friction, mass and closing-effort scales (shared/specs/uncertainty.py); the object's
dynamics are put back afterwards, so the evaluator's next result does not depend on it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import pybullet as p
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import Outcome, PhaseTimes
from graspscape.workers.sim.bullet import get_dynamics_info
from graspscape.workers.sim.table import closing_outcome, start_outcome


@dataclass(frozen=True)
class Sample:
    """The outcome of one draw: held or not, and the links in contact after closing."""

    outcome: Outcome
    links: tuple[str, ...]
    seconds: float

    @property
    def held(self) -> bool:
        return self.outcome is Outcome.HELD


def sample(evaluator, pose: Pose, *, friction_scale: float = 1.0, mass_scale: float = 1.0,
           effort_scale: float = 1.0) -> Sample:
    """Simulates one start pose, outcome only (module doc)."""
    started = time.perf_counter()
    scene, cid = evaluator.scene, evaluator.client
    body = scene.object_body
    dyn = get_dynamics_info(cid, body)
    friction, mass = float(dyn.lateral_friction), float(dyn.mass)
    inertia = [float(x) for x in dyn.local_inertia_diagonal]
    try:
        evaluator._reset()
        if effort_scale != 1.0:
            hand = scene.hand
            hand.reset_open(evaluator.spread, hand.effort * effort_scale, hand.hold_factor)
        if friction_scale != 1.0 or mass_scale != 1.0:
            p.changeDynamics(body, -1, lateralFriction=friction * friction_scale,
                             mass=mass * mass_scale,
                             localInertiaDiagonal=[x * mass_scale for x in inertia],
                             physicsClientId=cid)
            # On a table the object's weight is applied as a force (table.py): scaled too.
            scene.object_weight_n = getattr(scene, "object_weight_n", 0.0) * mass_scale
        start = evaluator._start_pose(pose)
        if start is None:
            return Sample(Outcome.INFEASIBLE, (), time.perf_counter() - started)
        if (blocked := start_outcome(scene)) is not None:
            return Sample(blocked, (), time.perf_counter() - started)
        position, rotation, target, _ = start
        phases = PhaseTimes()
        failed = evaluator.policy.synthesize(scene, position, rotation, target,
                                             evaluator.settings, phases)
        failed = closing_outcome(scene) or failed
        if failed is not None:
            return Sample(failed, (), time.perf_counter() - started)
        links = tuple(sorted({scene.hand.link_names[c.link_index_a]
                              for c in scene.contacts()}))
        held, _, _ = evaluator._run_trajectory(phases, probes=False)
        outcome = Outcome.HELD if held else Outcome.DROPPED
        return Sample(outcome, links, time.perf_counter() - started)
    finally:
        if friction_scale != 1.0 or mass_scale != 1.0:
            p.changeDynamics(body, -1, lateralFriction=friction, mass=mass,
                             localInertiaDiagonal=inertia, physicsClientId=cid)
