"""bench_eval_pose.py --engine pybullet,mujoco: the two engines side by side in one run
(split from bench_eval_pose.py, which calls it).

On the same pose grid, each engine at its chosen settings (pybullet: 240 Hz, 50 iterations;
MuJoCo: the same rate × 2 substeps, a 2.08 ms step) and at a finer time step (pybullet
480 Hz; MuJoCo 4 substeps, 1.04 ms): evaluations per second on one core (the best round's
wall clock), evaluations per CPU-second (all rounds; and at the finer step), steps
per evaluation, the share of CPU inside the engine's step (pybullet.stepSimulation,
mujoco.mj_step), and each engine's agreement with its own finer reference (the same viability
and, where held, the same grasp type). The engines alternate (pybullet, MuJoCo, MuJoCo,
pybullet, ...) so both see the same machine load. With `--converge`, each engine also runs at a
quarter of its step (pybullet 960 Hz; MuJoCo 8 substeps, 0.52 ms): the chosen step's
agreement with it and the half step's, on viability and grasp type and on viability alone.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import mujoco
import numpy as np
import pybullet as p
from graspscape.shared.specs.gripper import load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import PoseResult
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.engine import make_evaluator
from graspscape.workers.sim.evaluate import default_cache_dir
from graspscape.workers.sim.objects import prepare_object
from graspscape.workers.sim.signature import same_grasp_type


class Clock:
    """CPU time inside one module-level step function while installed."""

    def __init__(self, module: object, name: str) -> None:
        self.module, self.name = module, name
        self.cpu_s, self.steps = 0.0, 0
        self._step: Callable = getattr(module, name)

    def __enter__(self) -> Clock:
        step = self._step

        def timed(*args, **kwargs):  # type: ignore[no-untyped-def]
            cpu = time.process_time()
            step(*args, **kwargs)
            self.cpu_s += time.process_time() - cpu
            self.steps += 1

        setattr(self.module, self.name, timed)
        return self

    def __exit__(self, *exc: object) -> None:
        setattr(self.module, self.name, self._step)


def settings_for(engine: str, fine: bool, finer: int = 2) -> SimSettings:
    """The chosen settings, or (`fine`) the step divided by `finer`."""
    base = SimSettings(engine=engine)
    if not fine:
        return base
    if engine == "pybullet":
        physics = base.physics.model_copy(update={"rate_hz": base.physics.rate_hz * finer})
    else:
        physics = base.physics.model_copy(
            update={"mujoco_substeps": base.physics.mujoco_substeps * finer})
    return base.model_copy(update={"physics": physics})


def run(obj: ObjectSpec, settings: SimSettings, poses: list[Pose]) -> tuple[list, dict]:
    prepared = prepare_object(obj, default_cache_dir() / "objects")
    evaluator = make_evaluator(prepared, load_gripper("robotiq_3f"), settings,
                               work_dir=default_cache_dir())
    try:
        evaluator.evaluate(poses[0])  # warm caches outside the timing
        module, name = (p, "stepSimulation") if settings.engine == "pybullet" else (
            mujoco, "mj_step")
        with Clock(module, name) as clock:
            wall, cpu = time.perf_counter(), time.process_time()
            results = [evaluator.evaluate(pose) for pose in poses]
            timing = {"wall_s": time.perf_counter() - wall, "cpu_s": time.process_time() - cpu,
                      "step_cpu_s": clock.cpu_s, "steps": clock.steps}
    finally:
        evaluator.close()
    return results, timing


def agree(a: PoseResult, b: PoseResult) -> bool:
    if a.viable != b.viable:
        return False
    return not a.viable or same_grasp_type(a.signature, b.signature)


def share(a: list[PoseResult], b: list[PoseResult], outcome_only: bool = False) -> float:
    """The share of poses on which two runs agree (or only on viability)."""
    return float(np.mean([x.viable == y.viable if outcome_only else agree(x, y)
                          for x, y in zip(a, b, strict=True)]))


def convergence(obj: ObjectSpec, poses: list[Pose], engine: str, chosen: list[PoseResult],
                fine: list[PoseResult]) -> dict[str, float]:
    """Each engine against its own step ÷ 4 as well as ÷ 2: the chosen step's agreement with
    both references (viable and grasp type; viability alone), and the ÷ 2 step's with the ÷ 4
    one, which says whether the outcomes settle as the step shrinks."""
    finest, timing = run(obj, settings_for(engine, fine=True, finer=4), poses)
    print(f"{engine} step ÷ 4: {timing['wall_s']:.1f} s", flush=True)
    return {
        f"same_outcome_with_finer_step_{engine}": share(chosen, fine, True),
        f"agreement_with_step_quarter_{engine}": share(chosen, finest),
        f"same_outcome_with_step_quarter_{engine}": share(chosen, finest, True),
        f"agreement_half_step_with_quarter_{engine}": share(fine, finest),
        f"same_outcome_half_step_with_quarter_{engine}": share(fine, finest, True),
    }


def side_by_side(obj: ObjectSpec, poses: list[Pose], engines: list[str],
                 rounds: int = 2, converge: bool = False) -> dict[str, float]:
    timings: dict[str, list[dict]] = {e: [] for e in engines}
    results: dict[str, list[PoseResult]] = {}
    for k in range(rounds):
        for engine in engines if k % 2 == 0 else engines[::-1]:
            got, timing = run(obj, settings_for(engine, fine=False), poses)
            results[engine] = got
            timings[engine].append(timing)
            print(f"round {k} {engine}: {timing['wall_s']:.1f} s", flush=True)
    n = len(poses)
    figures: dict[str, float] = {"poses": n, "rounds": rounds}
    for engine in engines:
        ts = timings[engine]
        # Wall clock: the best round, as the other processes of a shared machine only ever
        # slow a round down; CPU time: all rounds.
        wall, cpu = min(t["wall_s"] for t in ts), sum(t["cpu_s"] for t in ts)
        step_cpu, steps = sum(t["step_cpu_s"] for t in ts), sum(t["steps"] for t in ts)
        fine, fine_timing = run(obj, settings_for(engine, fine=True), poses)
        figures.update({
            f"evals_per_s_per_core_{engine}": n / wall,
            f"evals_per_cpu_s_half_step_{engine}": n / fine_timing["cpu_s"],
            f"evals_per_cpu_s_{engine}": rounds * n / cpu,
            f"steps_per_eval_{engine}": steps / (rounds * n),
            f"step_share_of_cpu_{engine}": step_cpu / cpu,
            f"held_share_{engine}": float(np.mean([r.viable for r in results[engine]])),
            f"agreement_with_finer_step_{engine}": float(np.mean(
                [agree(a, b) for a, b in zip(results[engine], fine, strict=True)])),
        })
        if converge:
            figures.update(convergence(obj, poses, engine, results[engine], fine))
    if {"pybullet", "mujoco"} <= set(engines):
        figures["mujoco_speedup"] = (figures["evals_per_s_per_core_mujoco"]
                                     / figures["evals_per_s_per_core_pybullet"])
        figures["mujoco_speedup_cpu"] = (figures["evals_per_cpu_s_mujoco"]
                                         / figures["evals_per_cpu_s_pybullet"])
        # MuJoCo at half its step (where it agrees with its own finer reference) against
        # pybullet at its chosen settings.
        figures["mujoco_half_step_speedup_cpu"] = (figures["evals_per_cpu_s_half_step_mujoco"]
                                                   / figures["evals_per_cpu_s_pybullet"])
        figures["agreement_between_engines"] = float(np.mean(
            [agree(a, b) for a, b in zip(results["pybullet"], results["mujoco"], strict=True)]))
    return figures
