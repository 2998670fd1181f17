"""Does the torque margin separate held grasps? Share at its ceiling, before and after.

The torque margin ratio 1 − τ_min/τ_c is bisected over [lo · τ_c, τ_c] in `margin_trials`
trajectories (workers/sim/robustness.py): a grasp that holds at the floor reads 1 − lo, the
ceiling (0.98 by default). Per object, random start poses (seeded) are evaluated once; on the
held ones the margin is measured under each setting (floor, trials). Figures: the share of
held poses at the ceiling and the number of distinct values, per setting, and the CPU time
per margin.
"""

from __future__ import annotations

import argparse
import math
import os
import random
import tempfile
import time
from pathlib import Path

from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.evaluate import _evaluator

from benchmarks._results import write_results

SETTINGS = {"default": (0.02, 6), "floor_0.001_trials_10": (0.001, 10),
            "floor_0.0001_trials_14": (0.0001, 14)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", nargs="+", default=["mug", "ycb:YcbTomatoSoupCan"])
    parser.add_argument("--poses", type=int, default=60)
    args = parser.parse_args()
    os.environ.setdefault("GRASPSCAPE_YCB_DIR", "/work/shared/objects/ycb")
    load = os.getloadavg()
    figures: dict[str, float] = {}
    for name in args.objects:
        ev = _evaluator(ObjectSpec(name=name), "robotiq_3f", SimSettings(),
                        Path(tempfile.gettempdir()) / "gs-i32-cal")
        rng = random.Random(11)
        poses = [Pose(theta=math.acos(rng.uniform(-1, 1)), phi=rng.uniform(0, 2 * math.pi),
                      r=rng.choice((0.01, 0.02)), roll=0.0, pitch=0.0, yaw=0.0)
                 for _ in range(args.poses)]
        held = [q for q in poses if ev.evaluate(q).viable]
        figures[f"{name}.held_poses"] = len(held)
        for label, (lo, trials) in SETTINGS.items():
            settings = RobustnessSettings(tests=("torque_margin",), torque_lo_fraction=lo,
                                          margin_trials=trials)
            t = time.process_time()
            ratios = [ev.robustness(q, settings)[1].torque_margin_ratio for q in held]
            cpu = time.process_time() - t
            got = [x for x in ratios if x is not None]
            ceiling = 1.0 - lo
            figures[f"{name}.{label}.ceiling_share"] = round(
                sum(x >= ceiling - 1e-9 for x in got) / max(1, len(got)), 3)
            figures[f"{name}.{label}.distinct_values"] = len({round(x, 6) for x in got})
            figures[f"{name}.{label}.cpu_ms_per_pose"] = round(1000 * cpu / max(1, len(held)))
            print(name, label, {k: v for k, v in figures.items() if label in k and name in k},
                  flush=True)
    write_results("torque_saturation", figures, extra={
        "settings": {k: {"torque_lo_fraction": lo, "margin_trials": n}
                     for k, (lo, n) in SETTINGS.items()},
        "load_average_start": load, "load_average_end": os.getloadavg()})


if __name__ == "__main__":
    main()
