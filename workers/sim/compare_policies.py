"""Compare the policies G_c (baseline) and G_s (haptic) on the same pose grid (paper Table 2).

For each object both policies evaluate the same grid of initial poses. Reported per object:
v_c and v_s, the volume (cm³) of the viable set, i.e. of the gripper reference-point (palm
centre) positions whose pose is held along the trajectory; the best μs, μg, μf, μm of each
policy over its viable poses; and containment, the share of G_c-viable poses that G_s also
holds. v is the volume of the whole viable set, not per behavioral manifold (the grouping of
viable poses by grasp type is the coordinator's explorations': docs/design/exploration.md).

Volume: a pose (θ, φ, r) stands for the cell θ ± Δθ/2, φ ± Δφ/2, r ± Δr/2. Its reference point
lies on the ray (θ, φ) from the object's centre of mass at distance ρ(r) (placement.py), so
the cell is the spherical-shell sector Δφ·(cos θ₁ − cos θ₂)·(ρ₂³ − ρ₁³)/3 with ρ₁, ρ₂ the
distances at the cell's two gap bounds along the centre ray: the integral of ρ² sin θ dθ dφ dρ
over the cell. One attitude (roll 0: the two-finger side up, as in the paper's Fig. 3 maps).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

from graspscape.shared import cli_args
from graspscape.shared.specs.gripper import GripperSpec, load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import PoseResult
from graspscape.shared.specs.sim import SimSettings
from pydantic import BaseModel, ConfigDict, Field

# pybullet, trimesh and numpy are imported where used: `graspscape --help` imports this module
# to register the subcommand and must stay instant.

BUILTIN_OBJECTS = ("sphere", "cube", "can", "dumbbell", "mug", "spiked_ball")
POLICIES = ("baseline", "haptic")


class PoseGrid(BaseModel):
    """Cell centres: θ and φ split their ranges evenly; gaps are cells of `gap_step_m`
    from 0 up to `max_gap_m`."""

    model_config = ConfigDict(frozen=True)

    theta_cells: int = Field(ge=1, le=180)
    phi_cells: int = Field(ge=1, le=360)
    gap_step_m: float = Field(gt=0.0, le=0.1)
    max_gap_m: float = Field(gt=0.0, le=0.5)
    roll: float = 0.0

    @property
    def d_theta(self) -> float:
        return math.pi / self.theta_cells

    @property
    def d_phi(self) -> float:
        return 2 * math.pi / self.phi_cells

    def gaps(self) -> list[float]:
        n = round(self.max_gap_m / self.gap_step_m)
        return [(k + 0.5) * self.gap_step_m for k in range(n)]

    def poses(self) -> list[Pose]:
        return [Pose(theta=(i + 0.5) * self.d_theta, phi=j * self.d_phi, r=r, roll=self.roll)
                for i in range(self.theta_cells) for j in range(self.phi_cells)
                for r in self.gaps()]


# small: 72 poses an object and policy (a few minutes for all built-ins on one core);
# paper: 1 cm gap cells and 15° cells, 576 poses (about 8× as long).
GRIDS = {
    "small": PoseGrid(theta_cells=6, phi_cells=6, gap_step_m=0.02, max_gap_m=0.04),
    "paper": PoseGrid(theta_cells=12, phi_cells=12, gap_step_m=0.01, max_gap_m=0.04),
}


def cell_volume_cm3(mesh, grid: PoseGrid, pose: Pose) -> float:
    import numpy as np
    from graspscape.shared.specs.placement import direction, point_at_gap

    u = direction(pose.theta, pose.phi)
    rho1 = float(np.linalg.norm(point_at_gap(mesh, u, max(pose.r - grid.gap_step_m / 2, 0.0))))
    rho2 = float(np.linalg.norm(point_at_gap(mesh, u, pose.r + grid.gap_step_m / 2)))
    t1, t2 = pose.theta - grid.d_theta / 2, pose.theta + grid.d_theta / 2
    volume = grid.d_phi * (math.cos(t1) - math.cos(t2)) * (rho2**3 - rho1**3) / 3.0
    return volume * 1e6


class PolicySummary(BaseModel):
    policy: str
    viable_poses: int
    volume_cm3: float
    best_mu_s: float | None = None
    best_mu_s_pose: str | None = None
    best_mu_g: float | None = None
    best_mu_f: float | None = None
    best_mu_m: float | None = None
    outcomes: dict[str, int] = Field(description="poses per outcome (held, dropped, ...)")
    mean_eval_time_s: float
    min_closing_effort: float | None = Field(
        default=None, description="of the best-μs pose, N·m (with --min-effort)")
    effort_evaluations: int | None = None


class ObjectComparison(BaseModel):
    object: str
    grid: str
    poses: int
    baseline: PolicySummary
    haptic: PolicySummary
    contained_share: float | None = Field(
        description="share of G_c-viable poses that G_s also holds; None if G_c holds none")
    lost_by_haptic: int = Field(description="G_c-viable poses that G_s does not hold")
    gained_by_haptic: int = Field(description="G_s-viable poses that G_c does not hold")
    volume_gain: float | None = Field(description="v_s / v_c − 1")


def _best(results: list[PoseResult], field: str) -> float | None:
    values = [getattr(r, field) for r in results if r.viable and getattr(r, field) is not None]
    return max(values) if values else None


def _summary(policy: str, results: list[PoseResult], volumes: list[float]) -> PolicySummary:
    import numpy as np

    viable = [r for r in results if r.viable]
    best = max(viable, key=lambda r: r.mu_s, default=None)
    return PolicySummary(
        policy=policy, viable_poses=len(viable),
        volume_cm3=float(sum(v for v, r in zip(volumes, results, strict=True) if r.viable)),
        best_mu_s=best.mu_s if best else None, best_mu_s_pose=best.pose_key if best else None,
        best_mu_g=_best(results, "mu_g"), best_mu_f=_best(results, "mu_f"),
        best_mu_m=_best(results, "mu_m"),
        outcomes={o: sum(r.outcome.value == o for r in results)
                  for o in sorted({r.outcome.value for r in results})},
        mean_eval_time_s=float(np.mean([r.eval_time_s for r in results])),
    )


def compare_object(name: str, grid_name: str = "small", *, gripper: GripperSpec | None = None,
                   settings: SimSettings | None = None, min_effort: bool = False,
                   effort_floor: float = 0.02, effort_tolerance: float = 0.02,
                   cache_dir: Path | None = None, log=None) -> ObjectComparison:
    from graspscape.workers.sim.effort import search_closing_effort
    from graspscape.workers.sim.evaluate import Evaluator, default_cache_dir
    from graspscape.workers.sim.objects import prepare_object

    grid = GRIDS[grid_name]
    cache = cache_dir or default_cache_dir()
    spec = gripper or load_gripper("robotiq_3f")
    base = settings or SimSettings()
    prepared = prepare_object(ObjectSpec(name=name), cache / "objects")
    poses = grid.poses()
    volumes = [cell_volume_cm3(prepared.mesh, grid, pose) for pose in poses]
    results: dict[str, list[PoseResult]] = {}
    summaries: dict[str, PolicySummary] = {}
    for policy in POLICIES:
        started = time.perf_counter()
        policy_settings = base.model_copy(update={"policy_name": policy})
        with Evaluator(prepared, spec, policy_settings, work_dir=cache) as evaluator:
            results[policy] = [evaluator.evaluate(pose) for pose in poses]
            summary = _summary(policy, results[policy], volumes)
            if min_effort and summary.best_mu_s_pose is not None:
                best = next(r for r in results[policy] if r.pose_key == summary.best_mu_s_pose)
                # Searched below the torque the grasp was found with (known to hold there):
                # above it holding need not be monotone (a stronger closing forms other grasps).
                hi = policy_settings.policy.closing_effort or spec.closing_effort
                found = search_closing_effort(evaluator, best.pose, effort_floor, hi,
                                              effort_tolerance)
                summary = summary.model_copy(update={
                    "min_closing_effort": found.min_closing_effort,
                    "effort_evaluations": found.evaluations})
        summaries[policy] = summary
        if log:
            log(f"{name:12s} {policy:8s} viable {summary.viable_poses}/{len(poses)} "
                f"v = {summary.volume_cm3:.1f} cm³ ({time.perf_counter() - started:.1f} s)")
    c_viable = {r.pose_key for r in results["baseline"] if r.viable}
    s_viable = {r.pose_key for r in results["haptic"] if r.viable}
    v_c, v_s = summaries["baseline"].volume_cm3, summaries["haptic"].volume_cm3
    return ObjectComparison(
        object=name, grid=grid_name, poses=len(poses),
        baseline=summaries["baseline"], haptic=summaries["haptic"],
        contained_share=len(c_viable & s_viable) / len(c_viable) if c_viable else None,
        lost_by_haptic=len(c_viable - s_viable), gained_by_haptic=len(s_viable - c_viable),
        volume_gain=v_s / v_c - 1.0 if v_c > 0 else None,
    )


class HandleSweep(BaseModel):
    """Both policies on poses facing the built-in mug's handle (+x)."""

    poses: int
    held_c: int
    held_s: int
    handle_c: int = Field(description="G_c held with a contact on the handle")
    handle_s: int = Field(description="G_s held with a contact on the handle")
    handle_s_where_c_not_viable: int
    held_s_where_c_dropped: int


def on_mug_handle(result: PoseResult) -> bool:
    """Held, with a contact on the handle: past the body's 4 cm radius on +x, within the
    handle tube's width in y."""
    return result.viable and any(
        c.position_object[0] > 0.045 and abs(c.position_object[1]) < 0.012
        for c in result.signature.contacts)


def mug_handle_poses() -> list[Pose]:
    rolls = (math.pi / 4, -math.pi / 4, 3 * math.pi / 4)
    return [Pose(theta=t, phi=f, r=r, roll=a) for t in (1.7, 1.85, 2.0)
            for f in (-0.3, -0.15, 0.0, 0.15, 0.3) for a in rolls for r in (0.01, 0.02)]


def mug_handle_sweep(cache_dir: Path | None = None) -> HandleSweep:
    from graspscape.workers.sim.evaluate import Evaluator, default_cache_dir
    from graspscape.workers.sim.objects import prepare_object

    cache = cache_dir or default_cache_dir()
    prepared = prepare_object(ObjectSpec(name="mug"), cache / "objects")
    poses = mug_handle_poses()
    out: dict[str, list[PoseResult]] = {}
    for policy in POLICIES:
        with Evaluator(prepared, load_gripper("robotiq_3f"), SimSettings(policy_name=policy),
                       work_dir=cache) as evaluator:
            out[policy] = [evaluator.evaluate(pose) for pose in poses]
    pairs = list(zip(out["baseline"], out["haptic"], strict=True))
    return HandleSweep(
        poses=len(poses), held_c=sum(c.viable for c, _ in pairs),
        held_s=sum(s.viable for _, s in pairs),
        handle_c=sum(on_mug_handle(c) for c, _ in pairs),
        handle_s=sum(on_mug_handle(s) for _, s in pairs),
        handle_s_where_c_not_viable=sum(on_mug_handle(s) and not c.viable for c, s in pairs),
        held_s_where_c_dropped=sum(s.viable and c.outcome.value == "dropped" for c, s in pairs),
    )


def _fmt(value: float | None, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def markdown_table(rows: list[ObjectComparison]) -> str:
    lines = ["| object | v_c (cm³) | v_s (cm³) | v_s/v_c − 1 | G_c ⊆ G_s | lost / gained "
             "| best μs c / s | best μg c / s | best μf c / s | best μm c / s "
             "| min τ c / s (N·m) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        c, s = r.baseline, r.haptic
        gain = "–" if r.volume_gain is None else f"{100 * r.volume_gain:+.0f} %"
        share = "–" if r.contained_share is None else f"{100 * r.contained_share:.0f} %"
        lines.append(
            f"| {r.object} | {c.volume_cm3:.1f} | {s.volume_cm3:.1f} | {gain} | {share} "
            f"| {r.lost_by_haptic} / {r.gained_by_haptic} "
            f"| {_fmt(c.best_mu_s)} / {_fmt(s.best_mu_s)} "
            f"| {_fmt(c.best_mu_g)} / {_fmt(s.best_mu_g)} "
            f"| {_fmt(c.best_mu_f, 3)} / {_fmt(s.best_mu_f, 3)} "
            f"| {_fmt(c.best_mu_m)} / {_fmt(s.best_mu_m)} "
            f"| {_fmt(c.min_closing_effort)} / {_fmt(s.min_closing_effort)} |")
    return "\n".join(lines)


def _run(args: argparse.Namespace) -> int:
    import sys

    settings = (SimSettings.model_validate_json(args.settings.read_text())
                if args.settings else SimSettings())
    rows = []
    for name in args.objects or args.objects_flag or BUILTIN_OBJECTS:
        rows.append(compare_object(name, args.grid, gripper=load_gripper(args.gripper),
                                   settings=settings, min_effort=args.min_effort,
                                   log=lambda msg: print(msg, file=sys.stderr, flush=True)))
    print(markdown_table(rows))
    if args.json:
        args.json.write_text(json.dumps([r.model_dump(mode="json") for r in rows], indent=2))
    return 0


def register_compare(subparsers: argparse._SubParsersAction) -> None:
    cp = subparsers.add_parser(
        "compare-policies",
        help="run G_c and G_s over the same pose grid; viable-set volumes, best μ, containment")
    cp.add_argument("objects", nargs="*", metavar="object",
                    help="object names (default: every built-in)")
    cli_args.add_hidden_alias(cp, "--objects", "objects_flag", nargs="+")
    cp.add_argument("--grid", choices=sorted(GRIDS), default="small",
                    help="which pose grid (default small)")
    cli_args.add_gripper(cp, default="robotiq_3f")
    cp.add_argument("--settings", type=Path, help="JSON file of SimSettings overrides")
    cp.add_argument("--min-effort", action="store_true",
                    help="also bisect the minimum closing effort of each best-μs pose")
    cp.add_argument("--json", type=Path, help="also write the rows as JSON here")
    cp.set_defaults(handler=_run)
