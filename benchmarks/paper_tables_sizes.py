"""The grids and budgets of the paper-tables harness (benchmarks/paper_tables.py)."""

from __future__ import annotations

from dataclasses import dataclass

from graspscape.workers.sim import compare_policies
from graspscape.workers.sim.compare_policies import PoseGrid

SIMPLE = ("sphere", "cube", "can", "dumbbell")
DEFAULT_YCB = ("ycb:YcbTennisBall", "ycb:YcbBanana")
ROLLS = (1, 2, 4, 8)
# The 12 YCB objects of ../shared/objects, cheapest first: the mean simulation time per pose
# of the atlas run (results/atlas.json, 60° grid, load 10-20). A run cut short by the clock
# (`--objects cheapest`) then has done as many objects as the time allowed.
YCB_BY_COST = (
    "ycb:YcbCrackerBox", "ycb:YcbChipsCan", "ycb:YcbTomatoSoupCan", "ycb:YcbMustardBottle",
    "ycb:YcbFoamBrick", "ycb:YcbGelatinBox", "ycb:YcbBanana", "ycb:YcbPowerDrill",
    "ycb:YcbPottedMeatCan", "ycb:YcbTennisBall", "ycb:YcbHammer", "ycb:YcbStrawberry",
)


@dataclass(frozen=True)
class Size:
    """The grids and budgets of one run of the harness. The Table 3 baselines (PPO, CMA-ES,
    random) get no budget of their own: each is run once per roll count with as many
    evaluations as the adaptive exploration at that roll count spent on that object."""

    dtheta_deg: float  # adaptive coarse grid
    r_min: float
    r_max: float
    dr: float
    levels: int  # adaptive refinement levels
    refine_max: int  # adaptive refinement pose budget
    search_rounds: int  # adaptive local search rounds
    ppo_batch: int  # poses per PPO rollout (and per round of random search)
    ppo_seeds: int
    table2_grid: PoseGrid
    effort_tolerance_nm: float
    rolls: tuple[int, ...] = ROLLS
    simple: tuple[str, ...] = SIMPLE


SIZES = {
    # The harness's own test: one object, a handful of poses per run (seconds).
    "tiny": Size(dtheta_deg=90, r_min=0.01, r_max=0.01, dr=0.01, levels=0, refine_max=0,
                 search_rounds=0, ppo_batch=4, ppo_seeds=3,
                 table2_grid=PoseGrid(theta_cells=2, phi_cells=2, gap_step_m=0.02,
                                      max_gap_m=0.02),
                 effort_tolerance_nm=0.5, rolls=(1, 2), simple=()),
    # 90° grid of directions (6 per roll) at one start gap, one round of local search.
    "small": Size(dtheta_deg=90, r_min=0.01, r_max=0.01, dr=0.01, levels=0, refine_max=0,
                  search_rounds=1, ppo_batch=8, ppo_seeds=3,
                  table2_grid=PoseGrid(theta_cells=2, phi_cells=2, gap_step_m=0.02,
                                       max_gap_m=0.02),
                  effort_tolerance_nm=0.1),
    # Twice the directions, two start gaps, one refinement level.
    "medium": Size(dtheta_deg=60, r_min=0.005, r_max=0.02, dr=0.015, levels=1, refine_max=24,
                   search_rounds=1, ppo_batch=16, ppo_seeds=3,
                   table2_grid=PoseGrid(theta_cells=3, phi_cells=3, gap_step_m=0.02,
                                        max_gap_m=0.02),
                   effort_tolerance_nm=0.1),
    "full": Size(dtheta_deg=30, r_min=0.0, r_max=0.03, dr=0.01, levels=1, refine_max=5000,
                 search_rounds=3, ppo_batch=64, ppo_seeds=3,
                 table2_grid=compare_policies.GRIDS["paper"], effort_tolerance_nm=0.02),
}


def all_ycb() -> tuple[str, ...]:
    """Every YCB object beside the checkout (shared/specs/object_names.py)."""
    from graspscape.shared.specs.object_names import ycb_names

    return tuple(ycb_names())


def cheapest_first(names: tuple[str, ...]) -> tuple[str, ...]:
    """`names` in YCB_BY_COST's order, any not in it last (alphabetically)."""
    rank = {n: i for i, n in enumerate(YCB_BY_COST)}
    return tuple(sorted(names, key=lambda n: (rank.get(n, len(rank)), n)))
