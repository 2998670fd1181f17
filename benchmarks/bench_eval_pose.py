"""Cost and fidelity of one pose evaluation on one core (issue: simulation core).

Evaluates a fixed grid of poses around the mug with the production settings and with a
reference at 240 Hz and 50 solver iterations (all else equal), and reports evaluations per
second, the cost of a held grasp, steps and time by phase, and the share of outcomes (viable
or not, and the same grasp type) on which both agree.

    .venv/bin/python benchmarks/bench_eval_pose.py            # writes results/eval_pose.json
    .venv/bin/python benchmarks/bench_eval_pose.py --scaling-only --procs 1,2,4,8,16
                                                  # 16-core scaling: eval_pose_scaling.json
    .venv/bin/python benchmarks/bench_eval_pose.py --engine pybullet,mujoco
        # both engines on the grid, alternating: eval_pose_engines.json (eval_pose_engines.py)
    .venv/bin/python benchmarks/bench_eval_pose.py --against REV --rounds 2
        # also the grid on the code at git revision REV and on this tree, alternating, each in
        # a process of its own: the results must be identical (every field but timings), and
        # the CPU figures of both come from one run, on one machine load
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pybullet as p
from graspscape.shared.specs.gripper import load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import PoseResult
from graspscape.shared.specs.sim import PhysicsSettings, SimSettings
from graspscape.workers.sim.evaluate import Evaluator, default_cache_dir
from graspscape.workers.sim.objects import prepare_object
from graspscape.workers.sim.signature import same_grasp_type

try:
    from benchmarks._results import write_results
except ModuleNotFoundError:  # run as a script from the repo root
    from _results import write_results


def pose_grid() -> list[Pose]:
    thetas = [0.3, 0.8, 1.3, 1.8, 2.4]
    phis = [k * math.pi / 3 for k in range(6)]
    rolls = [0.0, math.pi / 2]
    return [Pose(theta=t, phi=f, r=0.02, roll=a) for t in thetas for f in phis for a in rolls]


class StepClock:
    """Time spent inside pybullet.stepSimulation (wall and CPU), while installed: the engine's
    share of an evaluation, and the floor a zero-cost Python side would reach."""

    def __init__(self) -> None:
        self.wall_s = self.cpu_s = 0.0
        self.steps = 0
        self._step = p.stepSimulation

    def __enter__(self) -> StepClock:
        step = self._step

        def timed(*args, **kwargs):  # type: ignore[no-untyped-def]
            wall, cpu = time.perf_counter(), time.process_time()
            step(*args, **kwargs)
            self.cpu_s += time.process_time() - cpu
            self.wall_s += time.perf_counter() - wall
            self.steps += 1

        p.stepSimulation = timed  # every caller looks it up on the module at each call
        return self

    def __exit__(self, *exc: object) -> None:
        p.stepSimulation = self._step


def run(obj: ObjectSpec, settings: SimSettings, poses: list[Pose],
        world_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
        engine: dict | None = None,
        clock: dict[str, float] | None = None) -> tuple[list[PoseResult], float]:
    """The grid's results and their wall time on one warm evaluator. `engine`: pybullet
    engine parameters beyond SimSettings (set once: they outlive restoreState). `clock`:
    filled with the CPU time of the grid and the wall and CPU time inside stepSimulation."""
    prepared = prepare_object(obj, default_cache_dir() / "objects")
    with Evaluator(prepared, load_gripper("robotiq_3f"), settings,
                   work_dir=default_cache_dir(), world_offset=world_offset) as evaluator:
        if engine:
            p.setPhysicsEngineParameter(physicsClientId=evaluator.client, **engine)
        evaluator.evaluate(poses[0])  # warm caches outside the timing
        with StepClock() as steps:
            started, cpu = time.perf_counter(), time.process_time()
            results = [evaluator.evaluate(pose) for pose in poses]
            wall = time.perf_counter() - started
        if clock is not None:
            clock.update(cpu_s=time.process_time() - cpu, step_wall_s=steps.wall_s,
                         step_cpu_s=steps.cpu_s, steps=steps.steps)
        return results, wall


def _grid_in_process(obj_name: str, out) -> None:  # type: ignore[no-untyped-def]
    """One process of the scaling run: the grid on a warm evaluator, its wall time to `out`."""
    _, wall = run(ObjectSpec(name=obj_name), SimSettings(), pose_grid())
    out.put(wall)


def scaling(obj_name: str, procs: list[int]) -> dict[str, float]:
    """k processes at once, each evaluating the whole grid: evaluations/s of all together and
    the speed-up over one process (issue 21 item 6; meaningful on a machine with ≥ k cores)."""
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    n = len(pose_grid())
    figures: dict[str, float] = {}
    for k in procs:
        out = ctx.Queue()
        workers = [ctx.Process(target=_grid_in_process, args=(obj_name, out)) for _ in range(k)]
        for w in workers:
            w.start()
        walls = [out.get() for _ in workers]
        for w in workers:
            w.join()
        # Throughput while all k ran: k grids in the slowest one's time.
        figures[f"scaling_evals_per_s_{k}_procs"] = k * n / max(walls)
        print(f"{k} processes: {figures[f'scaling_evals_per_s_{k}_procs']:.2f} evals/s",
              flush=True)
    base = figures[f"scaling_evals_per_s_{procs[0]}_procs"] / procs[0]
    for k in procs:
        figures[f"scaling_speedup_{k}_procs"] = figures[f"scaling_evals_per_s_{k}_procs"] / base
    return figures


# pybullet's own profiler (STATE_LOGGING_PROFILE_TIMINGS): the scopes one step is split into.
STEP_SCOPES = {
    "step": "internalSingleStepSimulation",
    "collision": "performDiscreteCollisionDetection",
    "solver_setup": "solveGroupCacheFriendlySetup",
    "solver_iterations": "solveGroupCacheFriendlyIterations",
}


def step_split(obj: ObjectSpec, settings: SimSettings, poses: list[Pose]) -> dict[str, float]:
    """Seconds in each STEP_SCOPES scope while evaluating `poses`, from pybullet's profiler."""
    prepared = prepare_object(obj, default_cache_dir() / "objects")
    with tempfile.TemporaryDirectory() as tmp, Evaluator(
            prepared, load_gripper("robotiq_3f"), settings,
            work_dir=default_cache_dir()) as evaluator:
        log = p.startStateLogging(p.STATE_LOGGING_PROFILE_TIMINGS, f"{tmp}/timings",
                                  physicsClientId=evaluator.client)
        for pose in poses:
            evaluator.evaluate(pose)
        p.stopStateLogging(log, physicsClientId=evaluator.client)
        events = json.loads(next(Path(tmp).glob("timings*")).read_text())["traceEvents"]
    wanted = {v: k for k, v in STEP_SCOPES.items()}
    seconds = dict.fromkeys(STEP_SCOPES, 0.0)
    opened: dict[str, float] = {}
    for event in events:  # names carry a running number: "solveGroup123"
        name = event["name"]
        scope = wanted.get(name.rstrip("0123456789"))
        if scope is None:
            continue
        if event["ph"] == "B":
            opened[name] = event["ts"]
        elif event["ph"] == "E" and name in opened:
            seconds[scope] += (event["ts"] - opened.pop(name)) * 1e-6
    return seconds


def against(rev: str, rounds: int, obj_name: str) -> tuple[dict[str, float], dict]:
    """The grid on the code at git revision `rev` ("before") and on this tree ("after"),
    `rounds` times each, alternating (before, after, then after, before, ...), each in a fresh
    process (eval_pose_tree.py): whether every result is identical but its timings, and each
    tree's CPU figures summed over its rounds."""
    repo = Path(__file__).resolve().parents[1]
    child = Path(__file__).with_name("eval_pose_tree.py")
    runs: dict[str, list[dict]] = {"before": [], "after": []}
    with tempfile.TemporaryDirectory() as tmp:
        before = Path(tmp)
        # The whole tree: the code finds its configs (grippers) next to its packages.
        archive = subprocess.run(["git", "-C", str(repo), "archive", rev], check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(before)], input=archive, check=True)
        trees = [("before", before), ("after", repo)]
        for k in range(rounds):
            for name, tree in trees if k % 2 == 0 else trees[::-1]:
                out = subprocess.run([sys.executable, str(child), str(tree), obj_name],
                                     check=True, capture_output=True, text=True).stdout
                runs[name].append(json.loads(out.splitlines()[-1]))
                print(f"round {k}, {name}: {runs[name][-1]['cpu_s']:.2f} CPU-s", flush=True)
    first = runs["before"][0]["results"]
    figures: dict[str, float] = {
        "against_rounds": rounds,
        "against_identical_results": float(all(
            r["results"] == first for r in runs["before"] + runs["after"])),
        "against_poses_differing": sum(
            a != b for a, b in zip(first, runs["after"][0]["results"], strict=True)),
    }
    n = len(first) * rounds
    for name, tree_runs in runs.items():
        cpu = sum(r["cpu_s"] for r in tree_runs)
        step = sum(r["step_cpu_s"] for r in tree_runs)
        figures[f"{name}_evals_per_cpu_s"] = n / cpu
        figures[f"{name}_step_share_of_evaluation_cpu"] = step / cpu
        figures[f"{name}_engine_floor_evals_per_cpu_s"] = n / step
        figures[f"{name}_outside_step_cpu_ms_per_eval"] = 1000 * (cpu - step) / n
    figures["against_cpu_saved_share"] = (
        1 - figures["before_evals_per_cpu_s"] / figures["after_evals_per_cpu_s"])
    head = subprocess.run(["git", "-C", str(repo), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True).stdout.strip()
    return figures, {"against": rev, "after": f"working tree at {head}"}


def agree(a: PoseResult, b: PoseResult) -> bool:
    if a.viable != b.viable:
        return False
    return not a.viable or same_grasp_type(a.signature, b.signature)


def share_agreeing(a: list[PoseResult], b: list[PoseResult]) -> float:
    return float(np.mean([agree(x, y) for x, y in zip(a, b, strict=True)]))


def with_iterations(settings: SimSettings, iterations: int) -> SimSettings:
    physics = settings.physics.model_copy(update={"solver_iterations": iterations})
    return settings.model_copy(update={"physics": physics})


def engines_side_by_side(args: argparse.Namespace, load_before: tuple) -> None:
    """--engine: the engines on the grid, alternating (eval_pose_engines.py)."""
    try:
        from benchmarks.eval_pose_engines import side_by_side
    except ModuleNotFoundError:
        from eval_pose_engines import side_by_side
    figures = side_by_side(ObjectSpec(name=args.object), pose_grid(),
                           args.engine.split(","), args.rounds, converge=args.converge)
    extra = {"object": args.object, "load_average_start": list(load_before),
             "load_average_end": list(os.getloadavg())}
    if not args.no_write:
        write_results("eval_pose_engines", figures, extra)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--object", default="pb:mug")
    parser.add_argument("--no-write", action="store_true")
    parser.add_argument("--rate-hz", type=float, help="production physics rate (default: the "
                        "SimSettings default)")
    parser.add_argument("--iterations", type=int, help="production solver iterations")
    parser.add_argument("--procs", help="also the scaling run: 1,2,4,8,16 processes at once, "
                        "each evaluating the grid (issue 21 item 6)")
    parser.add_argument("--scaling-only", action="store_true",
                        help="only the scaling run (--procs), written to eval_pose_scaling.json")
    parser.add_argument("--against", metavar="REV", help="also the grid on the code at git "
                        "revision REV and on this tree, alternating: identical results? CPU?")
    parser.add_argument("--rounds", type=int, default=2, help="runs of each tree (--against)")
    parser.add_argument("--engine", help="engines side by side, e.g. pybullet,mujoco: written "
                        "to eval_pose_engines.json (eval_pose_engines.py)")
    parser.add_argument("--converge", action="store_true", help="with --engine: each engine "
                        "also at a quarter of its step, against its own finer references")
    args = parser.parse_args()
    load_before = os.getloadavg()
    if args.engine:
        engines_side_by_side(args, load_before)
        return
    if args.scaling_only:
        figures = scaling(args.object, [int(k) for k in (args.procs or "1,2").split(",")])
        write_results("eval_pose_scaling", figures, {"object": args.object,
                                                     "cpu_count": os.cpu_count()})
        return
    obj = ObjectSpec(name=args.object)
    poses = pose_grid()
    production = SimSettings()
    if args.rate_hz or args.iterations:
        physics = production.physics.model_copy(update={
            k: v for k, v in (("rate_hz", args.rate_hz), ("solver_iterations", args.iterations))
            if v is not None})
        production = production.model_copy(update={"physics": physics})
    reference = production.model_copy(
        update={"physics": PhysicsSettings(rate_hz=240.0, solver_iterations=50)})
    clock: dict[str, float] = {}
    prod, prod_wall = run(obj, production, poses, clock=clock)
    ref, ref_wall = (prod, prod_wall) if production == reference else run(obj, reference, poses)
    # The reference's own repeatability: the same grid with the object (and so every pose)
    # moved 1 µm in the world, which changes nothing physical but the floating-point
    # rounding; then the same grid at a slightly different setting.
    moved, _ = run(obj, reference, poses, world_offset=(1e-6, 0.0, 0.0))
    neighbour, _ = run(obj, with_iterations(reference, 60), poses)
    faster, faster_wall = run(obj, with_iterations(reference, 15), poses)

    split = step_split(obj, reference, poses[:12])
    held = [r for r in prod if r.viable]
    phase = {k: float(np.sum([getattr(r.phases, k) for r in prod])) for k in
             ("reset_s", "approach_s", "closing_s", "trajectory_s", "sensitivity_s",
              "approach_steps", "closing_steps", "trajectory_steps", "sensitivity_steps")}
    agreement = share_agreeing(prod, ref)
    both = [(a, b) for a, b in zip(prod, ref, strict=True) if a.viable and b.viable]
    figures = {
        "poses": len(poses),
        "evals_per_s_per_core": len(poses) / prod_wall,
        # The same run's CPU time (less sensitive to a shared machine's other load), the time
        # inside stepSimulation, and the rate if nothing but the engine took time.
        "evals_per_cpu_s": len(poses) / clock["cpu_s"],
        "step_share_of_evaluation_cpu": clock["step_cpu_s"] / clock["cpu_s"],
        "engine_floor_evals_per_cpu_s": len(poses) / clock["step_cpu_s"],
        "engine_floor_evals_per_s_per_core": len(poses) / clock["step_wall_s"],
        "steps": clock["steps"],
        "reference_evals_per_s_per_core": len(poses) / ref_wall,
        "held_grasp_ms": 1000 * float(np.mean([r.eval_time_s for r in held])) if held else 0.0,
        "held_share": len(held) / len(poses),
        "reference_held_share": sum(r.viable for r in ref) / len(poses),
        "production_is_reference": float(production == reference),
        "agreement_with_reference_share": float(agreement),
        "agreement_reference_vs_moved_1um_share": share_agreeing(ref, moved),
        "agreement_reference_vs_60_iterations_share": share_agreeing(ref, neighbour),
        "agreement_15_iterations_vs_reference_share": share_agreeing(faster, ref),
        "evals_per_s_per_core_15_iterations": len(poses) / faster_wall,
        "mean_abs_mu_s_difference_where_both_held": float(
            np.mean([abs(a.mu_s - b.mu_s) for a, b in both])) if both else 0.0,
        **{f"step_time_share_{k}": v / split["step"] for k, v in split.items() if k != "step"},
        "rate_hz": production.physics.rate_hz,
        "solver_iterations": production.physics.solver_iterations,
        **{f"{k}_total" if k.endswith("steps") else f"{k.removesuffix('_s')}_total_s": v
           for k, v in phase.items()},
    }
    outcomes: dict[str, int] = {}
    for r in prod:
        outcomes[r.outcome.value] = outcomes.get(r.outcome.value, 0) + 1
    print("outcomes:", outcomes)
    if args.procs:
        figures.update(scaling(args.object, [int(k) for k in args.procs.split(",")]))
    extra: dict = {"object": args.object, "outcomes": outcomes}
    if args.against:
        compared, trees = against(args.against, args.rounds, args.object)
        figures.update(compared)
        extra.update(trees)
    # The machine's load (1, 5, 15 min) as the run began and ended: other processes share
    # the cores, and wall-clock figures move with them (CPU figures much less).
    extra["load_average_start"] = list(load_before)
    extra["load_average_end"] = list(os.getloadavg())
    if not args.no_write:
        write_results("eval_pose", figures, extra)
    else:
        print(figures)


if __name__ == "__main__":
    main()
