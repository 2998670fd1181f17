"""Outcome-only evaluation: one draw of a grasp's success probability.

A draw needs the outcome (held along the reference trajectory or not) and the grasp type (the
links in contact once the hand has closed), not μs probes, margins or grasp tests: `sample`
runs placement, approach, closing, release and the trajectory with the probes off, under a
draw's scales (shared/specs/uncertainty.py):

- friction × s: the hand-object pair's friction coefficient (the object's in pybullet, which
  multiplies the two bodies'; every geom's in MuJoCo, which takes their maximum);
- mass × s: the object's mass and its inertia with it (the same shape, denser);
- effort × s: the hand's closing torque (or force) cap, and the holding torque of the joints
  not yet closing with it.

The scene's `scaled_object` (scene.py, mj/scene.py) owns the engine's part and puts the
object's dynamics back afterwards, so the evaluator's next result does not depend on a draw.
`sample_result` is what a worker runs for a pose of a tile of draws (wire TileSample): the
draw in each engine it names, as one PoseResult whose `sample` record keeps each engine's
outcome and links and says which fields it leaves out.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import (
    DrawScales,
    EngineOutcome,
    Outcome,
    PhaseTimes,
    PoseResult,
    SampleRecord,
)
from graspscape.shared.specs.sim import SimSettings
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
    """Simulates one start pose, outcome only (module doc), in either engine's evaluator."""
    started = time.perf_counter()
    scene = evaluator.scene
    with scene.scaled_object(friction_scale, mass_scale):
        evaluator._reset()
        # On a table the object's weight is a force on it alone (table.py): scaled with it.
        scene.object_weight_n = getattr(scene, "object_weight_n", 0.0) * mass_scale
        if effort_scale != 1.0:
            policy = evaluator.settings.policy
            effort = policy.closing_effort or evaluator.gripper.closing_effort
            scene.hand.reset_open(evaluator.spread, effort * effort_scale,
                                  policy.hold_effort_factor)
        start = evaluator._start_pose(pose)
        if start is None:
            return Sample(Outcome.INFEASIBLE, (), time.perf_counter() - started)
        position, rotation, target, _ = start
        if (blocked := start_outcome(scene)) is not None:
            return Sample(blocked, (), time.perf_counter() - started)
        phases = PhaseTimes()
        failed = evaluator.policy.synthesize(scene, position, rotation, target,
                                             evaluator.run_settings, phases)
        failed = closing_outcome(scene) or failed
        if failed is not None:
            return Sample(failed, (), time.perf_counter() - started)
        links = tuple(sorted({scene.hand.link_names[c.link_index_a]
                              for c in scene.contacts()}))
        held, _, _ = evaluator._run_trajectory(phases, probes=False)
        outcome = Outcome.HELD if held else Outcome.DROPPED
        return Sample(outcome, links, time.perf_counter() - started)


def sample_result(pose: Pose, *, obj: ObjectSpec, gripper: str, settings: SimSettings,
                  engines: list[str], scales: DrawScales | None = None,
                  cache_dir: Path | None = None) -> PoseResult:
    """One draw of a tile of draws: `sample` in each of `engines` (this process's evaluator
    for the object, gripper and settings with that engine). Its outcome is held only where
    every engine held; otherwise the first engine's outcome that was not held."""
    from graspscape.workers.sim.evaluate import _evaluator

    scales = scales or DrawScales()
    started = time.perf_counter()
    per_engine: dict[str, EngineOutcome] = {}
    for engine in engines:
        ev = _evaluator(obj, gripper, settings.model_copy(update={"engine": engine}),
                        cache_dir)
        got = sample(ev, pose, friction_scale=scales.friction, mass_scale=scales.mass,
                     effort_scale=scales.effort)
        per_engine[engine] = EngineOutcome(outcome=got.outcome, links=got.links)
    outcome = next((e.outcome for e in per_engine.values() if e.outcome is not Outcome.HELD),
                   Outcome.HELD)
    return PoseResult(pose=pose, pose_key=pose.key(), outcome=outcome,
                      viable=outcome is Outcome.HELD, mu_s=0.0,
                      eval_time_s=time.perf_counter() - started,
                      sample=SampleRecord(scales=scales, engines=per_engine))


def tile_draw(pose: Pose, tile, obj: ObjectSpec, cache_dir: Path | None) -> PoseResult:
    """`sample_result` of a pose of a leased tile of draws (wire TileLease with `sample`)."""
    return sample_result(pose, obj=obj, gripper=tile.gripper, settings=tile.settings,
                         engines=list(tile.sample.engines),
                         scales=tile.sample.scales.get(pose.key()), cache_dir=cache_dir)
