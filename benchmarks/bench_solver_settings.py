"""How fragile the reference evaluation is: speed and agreement of nearby physics settings.

The simulation core's target is 20 evaluations/s per core with ≥ 95 % of the mug grid's
outcomes (viable or not, same grasp type) agreeing with the reference at 240 Hz and 50 solver
iterations. This runs the grid of `bench_eval_pose.py` once at the reference and once per
nearby setting — fewer or more iterations, other rates, an early-exit residual threshold,
pybullet's other constraint solvers — and reports each one's evaluations/s and its agreement
with the reference, beside the reference's own agreement with itself with the object moved
1 µm (floating-point rounding only).

    .venv/bin/python benchmarks/bench_solver_settings.py     # writes results/solver_settings.json
"""

from __future__ import annotations

import argparse

import numpy as np
import pybullet as p
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import PoseResult
from graspscape.shared.specs.sim import PhysicsSettings, SimSettings

try:
    from benchmarks._results import write_results
    from benchmarks.bench_eval_pose import pose_grid, run, share_agreeing
except ModuleNotFoundError:  # run as a script from the repo root
    from _results import write_results
    from bench_eval_pose import pose_grid, run, share_agreeing

# name → (rate Hz, solver iterations, extra pybullet engine parameters, world offset x in m)
SETTINGS: dict[str, tuple[float, int, dict, float]] = {
    "moved_1um": (240.0, 50, {}, 1e-6),
    "iterations_30": (240.0, 30, {}, 0.0),
    "iterations_40": (240.0, 40, {}, 0.0),
    "iterations_60": (240.0, 60, {}, 0.0),
    "rate_200hz": (200.0, 50, {}, 0.0),
    "rate_160hz": (160.0, 50, {}, 0.0),
    "rate_120hz": (120.0, 50, {}, 0.0),
    "residual_threshold_1e-4": (240.0, 50, {"solverResidualThreshold": 1e-4}, 0.0),
    "residual_threshold_1e-2": (240.0, 50, {"solverResidualThreshold": 1e-2}, 0.0),
    "dantzig_50": (240.0, 50, {"constraintSolverType": p.CONSTRAINT_SOLVER_LCP_DANTZIG}, 0.0),
    "dantzig_10": (240.0, 10, {"constraintSolverType": p.CONSTRAINT_SOLVER_LCP_DANTZIG}, 0.0),
}


def run_setting(obj: ObjectSpec, poses: list[Pose], rate_hz: float, iterations: int,
                engine: dict, offset_x: float) -> tuple[list[PoseResult], float]:
    """The grid's results and evaluations/s with these settings."""
    settings = SimSettings(physics=PhysicsSettings(rate_hz=rate_hz, solver_iterations=iterations))
    results, wall = run(obj, settings, poses, (offset_x, 0.0, 0.0), engine)
    return results, len(poses) / wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--object", default="pb:mug")
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args()
    obj = ObjectSpec(name=args.object)
    poses = pose_grid()
    reference, reference_rate = run_setting(obj, poses, 240.0, 50, {}, 0.0)
    figures: dict[str, float] = {
        "poses": len(poses),
        "reference_evals_per_s_per_core": reference_rate,
        "reference_held_share": float(np.mean([r.viable for r in reference])),
    }
    for name, (rate_hz, iterations, engine, offset_x) in SETTINGS.items():
        results, rate = run_setting(obj, poses, rate_hz, iterations, engine, offset_x)
        both = [(a.mu_s, b.mu_s) for a, b in zip(reference, results, strict=True)
                if a.viable and b.viable]
        figures[f"{name}.agreement_with_reference_share"] = share_agreeing(reference, results)
        figures[f"{name}.evals_per_s_per_core"] = rate
        figures[f"{name}.speedup_over_reference"] = rate / reference_rate
        figures[f"{name}.held_share"] = float(np.mean([r.viable for r in results]))
        figures[f"{name}.mean_abs_mu_s_difference_where_both_held"] = float(
            np.mean([abs(a - b) for a, b in both])) if both else 0.0
        print(name, {k.split(".", 1)[1]: round(v, 3) for k, v in figures.items()
                     if k.startswith(name + ".")}, flush=True)
    if args.no_write:
        print(figures)
    else:
        write_results("solver_settings", figures, {"object": args.object})


if __name__ == "__main__":
    main()
