"""Tables 1 and 2 of the paper-tables harness (benchmarks/paper_tables.py).

Table 1 (per object): over every pose the object's Table 3 runs evaluated, the best held grasp
by each of μs, μg, μf, μm and by the torque margin ratio (/best's rank), then its minimum
closing effort: the least closing torque at which the same pose still holds along the
reference trajectory, by bisection (workers/sim/effort.py), as the paper reduced efforts
"until we reach grasp failure".

Table 2 (per object): both policies, G_c (baseline) and G_s (haptic), on one pose grid
(workers/sim/compare_policies.compare_object): viable-set volumes v_c and v_s (cm³), the
share of G_c-viable poses that G_s also holds (the paper's containment claim), the best μs,
μg, μf, μm of each.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Executor
from typing import Any

from graspscape.services.coordinator.store.models import PoseRow
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim import compare_policies
from graspscape.workers.sim.compare_policies import PoseGrid, compare_object

# Table 1's metrics (pose columns; larger is better for each).
TABLE1_METRICS = ("mu_s", "mu_g", "mu_f", "mu_m", "torque_margin_ratio")
# The bisection's lower bound, N·m: a grasp that still holds there is reported as ≤ it.
EFFORT_FLOOR_NM = 0.02


def _min_effort(args: tuple[str, Pose, SimSettings, float]) -> tuple[float | None, int]:
    from graspscape.shared.specs.gripper import load_gripper
    from graspscape.workers.sim.effort import search_closing_effort
    from graspscape.workers.sim.evaluate import Evaluator, default_cache_dir
    from graspscape.workers.sim.objects import prepare_object

    name, pose, settings, tolerance = args
    cache = default_cache_dir()
    gripper = load_gripper("robotiq_3f")
    prepared = prepare_object(ObjectSpec(name=name), cache / "objects")
    # Holding only: the bisection needs no margins.
    plain = settings.model_copy(update={"robustness": SimSettings().robustness})
    # Searched below the torque the grasp was found with (it held there): above it holding
    # need not be monotone (a stronger closing forms other grasps).
    hi = plain.policy.closing_effort or gripper.closing_effort
    with Evaluator(prepared, gripper, plain, work_dir=cache) as evaluator:
        found = search_closing_effort(evaluator, pose, EFFORT_FLOOR_NM, hi, tolerance)
    return found.min_closing_effort, found.evaluations


def table1_object(name: str, rows: Sequence[PoseRow], settings: SimSettings,
                  tolerance_nm: float, pool: Executor) -> dict[str, Any]:
    held = [r for r in rows if r.viable]
    best: dict[str, PoseRow] = {}
    for metric in TABLE1_METRICS:
        candidates = [r for r in held if getattr(r, metric) is not None]
        if candidates:
            best[metric] = max(candidates, key=lambda r, m=metric: (getattr(r, m), r.pose_key))
    poses = {r.pose_key: Pose(theta=r.theta, phi=r.phi, r=r.r, roll=r.roll, pitch=r.pitch,
                              yaw=r.yaw) for r in best.values()}
    keys = sorted(poses)
    found = dict(zip(keys, pool.map(_min_effort, [(name, poses[k], settings, tolerance_nm)
                                                  for k in keys]), strict=True))
    out: dict[str, Any] = {"held_poses": len(held)}
    for metric, row in best.items():
        effort, evaluations = found[row.pose_key]
        out[metric] = {"pose": row.pose_key, "value": round(float(getattr(row, metric)), 4),
                       "min_closing_effort_nm": effort,
                       "holds_at_floor": effort is not None and effort <= EFFORT_FLOOR_NM,
                       "bisection_evaluations": evaluations}
    return out


def _compare(args: tuple[str, str]) -> dict[str, Any]:
    name, grid_name = args
    return compare_object(name, grid_name).model_dump(mode="json")


def table2(names: Sequence[str], grid: PoseGrid, pool: Executor) -> list[dict[str, Any]]:
    # compare_object names its grid; this harness's grid is registered under its own name
    # in every process that runs it (the pool's workers: init_worker).
    grid_name = register_grid(grid)
    return list(pool.map(_compare, [(n, grid_name) for n in names]))


def register_grid(grid: PoseGrid) -> str:
    name = (f"paper_tables_{grid.theta_cells}x{grid.phi_cells}_{grid.gap_step_m}"
            f"_{grid.max_gap_m}")
    compare_policies.GRIDS.setdefault(name, grid)
    return name


def init_worker(grids: list[PoseGrid]) -> None:
    for grid in grids:
        register_grid(grid)
