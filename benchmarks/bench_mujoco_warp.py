"""The GPU path's first figure: MuJoCo Warp stepping many grasps at once (docs/design/simulation.md,
"Batched evaluation on a GPU").

Not an evaluation yet: the mug's model (the MuJoCo engine's, workers/sim/mj/world.py) with N
worlds, each at the start pose of another pose of bench_eval_pose's grid (placed on the CPU,
as the evaluator places it), every finger closing as G_c's first phalanges do (the motor
commands at the start of closing are the same in every world), stepped for the closing cap.
It reports world-steps per second on the GPU against mj_step on one CPU core, the ceiling a
batched evaluator could reach. Needs `mujoco_warp` and a CUDA device; without them it says so
and writes nothing.

    .venv/bin/python benchmarks/bench_mujoco_warp.py --worlds 1024,4096
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time

import mujoco
import numpy as np
from graspscape.shared.specs.gripper import load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.engine import make_evaluator
from graspscape.workers.sim.evaluate import default_cache_dir
from graspscape.workers.sim.objects import prepare_object

try:
    from benchmarks._results import write_results
    from benchmarks.bench_eval_pose import pose_grid
except ModuleNotFoundError:  # run as a script from the repo root
    from _results import write_results
    from bench_eval_pose import pose_grid


def start_states(obj: str, n: int) -> tuple[mujoco.MjModel, np.ndarray, np.ndarray]:
    """The model with closing's motor commands, and n start states (qpos, ctrl rows)."""
    prepared = prepare_object(ObjectSpec(name=obj), default_cache_dir() / "objects")
    ev = make_evaluator(prepared, load_gripper("robotiq_3f"), SimSettings(engine="mujoco"),
                        work_dir=default_cache_dir())
    poses = pose_grid()
    qpos, ctrl = [], []
    for k in range(n):
        ev._reset()
        start = ev._start_pose(poses[k % len(poses)])
        if start is None:
            continue
        ev.scene.place_hand(start[0], start[1])
        ev.scene.hand.begin_closing(ev.settings.policy.closing_speed)
        qpos.append(ev.data.qpos.copy())
        ctrl.append(ev.data.ctrl.copy())
    reps = -(-n // len(qpos))
    return ev.world.model, np.tile(qpos, (reps, 1))[:n], np.tile(ctrl, (reps, 1))[:n]


def cpu_rate(model: mujoco.MjModel, qpos: np.ndarray, ctrl: np.ndarray, steps: int) -> float:
    data = mujoco.MjData(model)
    data.qpos[:], data.ctrl[:] = qpos[0], ctrl[0]
    started = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(model, data)
    return steps / (time.perf_counter() - started)


def gpu_rate(model: mujoco.MjModel, qpos: np.ndarray, ctrl: np.ndarray, steps: int) -> float:
    import mujoco_warp as mjw
    import warp as wp

    data = mujoco.MjData(model)
    m = mjw.put_model(model)
    d = mjw.put_data(model, data, nworld=len(qpos))
    wp.copy(d.qpos, wp.array(qpos.astype(np.float32)))
    wp.copy(d.ctrl, wp.array(ctrl.astype(np.float32)))
    mjw.step(m, d)  # compile the kernels outside the timing
    wp.synchronize()
    started = time.perf_counter()
    for _ in range(steps):
        mjw.step(m, d)
    wp.synchronize()
    return len(qpos) * steps / (time.perf_counter() - started)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--object", default="pb:mug")
    parser.add_argument("--worlds", default="1024,4096")
    args = parser.parse_args()
    if importlib.util.find_spec("mujoco_warp") is None:
        print("mujoco_warp is not installed: nothing measured", file=sys.stderr)
        return
    import warp as wp

    if not wp.get_cuda_device_count():
        print("no CUDA device: nothing measured", file=sys.stderr)
        return
    load = os.getloadavg()
    steps = round(SimSettings().policy.closing_cap_s * SimSettings().physics.rate_hz * 2)
    figures: dict[str, float] = {"steps": steps}
    for n in (int(k) for k in args.worlds.split(",")):
        model, qpos, ctrl = start_states(args.object, n)
        figures.setdefault("cpu_steps_per_s", cpu_rate(model, qpos, ctrl, steps))
        figures[f"gpu_world_steps_per_s_{n}_worlds"] = gpu_rate(model, qpos, ctrl, steps)
        figures[f"gpu_over_one_core_{n}_worlds"] = (
            figures[f"gpu_world_steps_per_s_{n}_worlds"] / figures["cpu_steps_per_s"])
    write_results("mujoco_warp", figures, {"object": args.object, "load_average": list(load)})


if __name__ == "__main__":
    main()
