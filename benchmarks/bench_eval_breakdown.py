"""Where an evaluation's CPU goes besides stepSimulation (issue 21 item 5: what stands between
today and stepSimulation ≥ 90 % of an evaluation).

Runs bench_eval_pose's 60-pose mug grid on one warm evaluator with process-time clocks around
each phase (placement, approach, closing, static metrics, trajectory, μs probes; exclusive:
a phase's time excludes the phases it calls) and around stepSimulation, so each phase's CPU
splits into time inside the engine's step and time outside it; and, across phases, the CPU of
the other pybullet calls (saveState, restoreState, collision passes, constraint changes, state
and contact reads). The clocks cost ≈ 1 µs a call each, which lands outside the step: the
figures are an upper bound on the non-step share by about 1 %.

    .venv/bin/python benchmarks/bench_eval_breakdown.py    # writes results/eval_breakdown.json
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable
from typing import Any

import pybullet as p
from graspscape.shared.specs.gripper import load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim import evaluate
from graspscape.workers.sim.objects import prepare_object
from graspscape.workers.sim.policies import baseline

try:
    from benchmarks._results import write_results
    from benchmarks.bench_eval_pose import pose_grid
except ModuleNotFoundError:  # run as a script from the repo root
    from _results import write_results
    from bench_eval_pose import pose_grid

# pybullet calls other than stepSimulation that an evaluation makes in numbers.
ENGINE_CALLS = ("saveState", "restoreState", "performCollisionDetection", "changeConstraint",
                "getJointStates", "getContactPoints", "getClosestPoints",
                "getBasePositionAndOrientation")


class Clocks:
    """Exclusive process time per phase, and stepSimulation's time per phase."""

    def __init__(self) -> None:
        self.total: dict[str, float] = {}
        self.step: dict[str, float] = {}
        self.calls: dict[str, float] = {}
        self.current = "rest"
        self._undo: list[Callable[[], None]] = []

    def _patch(self, owner: Any, name: str, wrapper: Callable) -> None:
        original = getattr(owner, name)
        setattr(owner, name, wrapper(original))
        self._undo.append(lambda: setattr(owner, name, original))

    def phase(self, owner: Any, name: str, label: str) -> None:
        def wrapper(fn: Callable) -> Callable:
            def timed(*args: Any, **kwargs: Any) -> Any:
                outer, self.current = self.current, label
                started = time.process_time()
                try:
                    return fn(*args, **kwargs)
                finally:
                    spent = time.process_time() - started
                    self.current = outer
                    self.total[label] = self.total.get(label, 0.0) + spent
                    self.total[outer] = self.total.get(outer, 0.0) - spent
            return timed
        self._patch(owner, name, wrapper)

    def engine_call(self, name: str) -> None:
        def wrapper(fn: Callable) -> Callable:
            def timed(*args: Any, **kwargs: Any) -> Any:
                started = time.process_time()
                try:
                    return fn(*args, **kwargs)
                finally:
                    self.calls[name] = self.calls.get(name, 0.0) + time.process_time() - started
            return timed
        self._patch(p, name, wrapper)

    def stepping(self) -> None:
        def wrapper(fn: Callable) -> Callable:
            def timed(*args: Any, **kwargs: Any) -> Any:
                started = time.process_time()
                fn(*args, **kwargs)
                spent = time.process_time() - started
                self.step[self.current] = self.step.get(self.current, 0.0) + spent
            return timed
        self._patch(p, "stepSimulation", wrapper)

    def undo(self) -> None:
        for undo in reversed(self._undo):
            undo()


def breakdown(obj: ObjectSpec, settings: SimSettings) -> dict[str, float]:
    poses = pose_grid()
    prepared = prepare_object(obj, evaluate.default_cache_dir() / "objects")
    clocks = Clocks()
    # Callers look these names up at each call: evaluate's imports, the policy class, and
    # pybullet's module functions (every caller writes p.<name>).
    clocks.phase(evaluate, "start_pose", "placement")
    clocks.phase(baseline.BaselinePolicy, "synthesize", "approach")
    clocks.phase(baseline, "close_fingers", "closing")
    clocks.phase(evaluate, "scene_metrics", "static_metrics")
    clocks.phase(evaluate, "probe_instant", "probes")
    clocks.phase(evaluate.Evaluator, "_run_trajectory", "trajectory")
    clocks.stepping()
    for name in ENGINE_CALLS:
        clocks.engine_call(name)
    try:
        with evaluate.Evaluator(prepared, load_gripper("robotiq_3f"), settings,
                                work_dir=evaluate.default_cache_dir()) as evaluator:
            evaluator.evaluate(poses[0])  # warm caches outside the clocks
            for table in (clocks.total, clocks.step, clocks.calls):
                table.clear()
            started = time.process_time()
            for pose in poses:
                evaluator.evaluate(pose)
            cpu = time.process_time() - started
    finally:
        clocks.undo()
    step = sum(clocks.step.values())
    figures = {"poses": len(poses), "cpu_s": cpu, "step_cpu_s": step,
               "step_share_of_evaluation_cpu": step / cpu}
    clocks.total["rest"] = cpu - sum(v for k, v in clocks.total.items() if k != "rest")
    for label, spent in clocks.total.items():
        outside = spent - clocks.step.get(label, 0.0)
        figures[f"{label}_cpu_s"] = spent
        figures[f"{label}_outside_step_share"] = outside / cpu
    for name, spent in clocks.calls.items():
        figures[f"engine_{name}_share"] = spent / cpu
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--object", default="pb:mug")
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args()
    load = os.getloadavg()
    figures = breakdown(ObjectSpec(name=args.object), SimSettings())
    extra = {"object": args.object, "load_average_start": list(load),
             "load_average_end": list(os.getloadavg())}
    if args.no_write:
        print(figures)
    else:
        write_results("eval_breakdown", figures, extra)


if __name__ == "__main__":
    main()
