"""Grippers from URDFs (issue 23): does the Robotiq 3F written as a URDF in the vendor's frames
behave as the TOML model of boxes does, and what does each shipped gripper cost?

1. Both Robotiq 3F models on the same 50-pose mug grid with G_c (workers/sim/gripper/compare.py):
   the share of poses with the same outcome, and of poses both hold with the same digits.
2. Each shipped gripper: preparing it cold (URDF rewrite, collision meshes decomposed), and one
   evaluation on the sphere from the side (held or not, seconds).

    .venv/bin/python benchmarks/bench_grippers.py        # writes results/grippers.json
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from pathlib import Path

from graspscape.shared.specs.gripper import list_grippers, load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.workers.sim.evaluate import Evaluator, default_cache_dir
from graspscape.workers.sim.gripper.compare import compare, grid_50
from graspscape.workers.sim.gripper.model import hand_model
from graspscape.workers.sim.objects import prepare_object

try:
    from benchmarks._results import write_results
except ModuleNotFoundError:  # run as a script from the repo root
    from _results import write_results


def main() -> None:
    load_before = os.getloadavg()[0]
    cache = default_cache_dir()
    figures: dict[str, float] = {}
    started = time.perf_counter()
    agreement = compare(load_gripper("robotiq_3f"), load_gripper("robotiq_3f_urdf"), "mug",
                        grid_50(), cache)
    figures["robotiq_mug_grid_poses"] = agreement.poses
    figures["robotiq_mug_same_outcome_share"] = agreement.outcome_share
    figures["robotiq_mug_viable_toml"] = agreement.viable_a
    figures["robotiq_mug_viable_urdf"] = agreement.viable_b
    figures["robotiq_mug_both_viable"] = agreement.both_viable
    figures["robotiq_mug_same_digits_when_both_viable"] = agreement.same_digits_when_both_viable
    figures["robotiq_mug_mean_eval_s_toml"] = sum(r.eval_s_a for r in agreement.rows) / 50
    figures["robotiq_mug_mean_eval_s_urdf"] = sum(r.eval_s_b for r in agreement.rows) / 50
    figures["robotiq_mug_wall_s"] = time.perf_counter() - started

    sphere = prepare_object(ObjectSpec(name="sphere"), cache / "objects")
    side = Pose(theta=math.pi / 2, phi=0.0, r=0.02)
    for name in list_grippers():
        spec = load_gripper(name)
        with tempfile.TemporaryDirectory() as cold:
            t0 = time.perf_counter()
            hand_model(spec, Path(cold))
            figures[f"{name}_prepare_cold_s"] = time.perf_counter() - t0
        with Evaluator(sphere, spec, work_dir=cache) as evaluator:
            result = evaluator.evaluate(side)
        figures[f"{name}_sphere_side_held"] = float(result.viable)
        figures[f"{name}_sphere_side_eval_s"] = result.eval_time_s
    figures["load_avg_1min"] = max(load_before, os.getloadavg()[0])
    write_results("grippers", figures, {"rows": [r.model_dump(mode="json")
                                                 for r in agreement.rows]})


if __name__ == "__main__":
    main()
