"""One budget accounting for every explorer (adaptive, grid, random, cmaes), from stored rows.

What an exploration spent and what it got, counted the same way whatever strategy produced
the poses, so that explorers can be compared on one table (issue 20's Table 3): evaluations,
wall time, best quality, grasp types, grasps, misses and the times to the first grasp and to
within 5 % of the final best. `account` is a pure function of the pose rows and the time of
the first lease; `exploration_budget` reads them from the store for
`GET /explorations/{id}/budget`.

Counting rules:
- an *evaluation* is a pose a worker simulated: every stored pose except the coordinator's
  copies (shortcuts 1 and 3, `worker_id` "shortcut:…"); a pose of shortcut 2 is one (the
  worker synthesized its grasp);
- *grasps* are the viable stored poses, copies included (they are poses of the map);
  *misses* are evaluations without a viable grasp (error outcomes too);
- a *grasp type* is the set of digits in contact in the stored signature
  (`manifolds/behaviour.py` digits: fingers and palm). The behaviour test of the manifolds also
  compares contact positions and closures, but only between lattice neighbours; off-lattice
  poses (random, cmaes) have none, so the digit set is the notion every explorer shares;
- *certification evaluations* are the evaluations the adaptive strategy planned to certify
  its best grasps (exploration/certify.py: missing neighbours N_δ and jitters of the stated
  pose error); they are evaluations like any other, and counted again on their own;
- times are from the first lease (`explorations.started_at`) to the ingest time of the pose
  (`poses.created_at`, one per batch); "within 5 %" is the first viable pose with
  μs ≥ 0.95 × the final best μs.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from datetime import datetime
from typing import Any

from graspscape.services.coordinator.exploration.certify_store import certification_plans
from graspscape.services.coordinator.exploration.service import get_exploration
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.best import DEFAULT_RANK, LOWER_IS_BETTER
from graspscape.services.coordinator.store.models import ManifoldRow, PoseRow
from pydantic import BaseModel, Field
from sqlalchemy import func, select
from sqlalchemy.orm import Session

NEAR_BEST = 0.95  # "within 5 % of the final best"


class BudgetAccount(BaseModel):
    """What an exploration spent and found (exploration/accounting.py)."""

    evaluations: int = Field(description="poses simulated by a worker (coordinator copies of "
                             "shortcuts 1 and 3 excluded)")
    certification_evaluations: int = Field(
        default=0, description="of the evaluations, those planned to certify the best grasps "
        "(neighbours N_δ and jitters of the stated pose error; adaptive only)")
    poses_stored: int = Field(description="every stored pose, copies included")
    wall_time_s: float | None = Field(
        description="first lease to the last stored result; null before any")
    best_mu_s: float | None = Field(description="best μs of a viable pose")
    rank_metric: str = Field(description="the point rank metric of /best (rank=point)")
    best_rank: float | None = Field(
        description="its best value over the viable poses where stored; null where none has it")
    best_robust_q: float | None = Field(
        default=None, description="best robust quality q_δ of a viable pose (the default rank "
        "of /best); null where the robust map is not computed (off-lattice explorers)")
    large_manifolds: int | None = Field(
        default=None, description="manifolds of at least 1 % of the viable volume in the "
        "exploration's table; null where it has none stored (off-lattice explorers)")
    grasp_types: int = Field(description="distinct sets of digits in contact among viable "
                             "poses")
    grasps: int = Field(description="viable poses found ('# of grasps')")
    misses: int = Field(description="evaluations with no viable grasp")
    time_to_first_grasp_s: float | None = Field(
        description="first lease to the first viable pose stored")
    time_to_near_best_s: float | None = Field(
        description="first lease to the first viable pose within 5 % of the final best μs")


class ExplorationBudget(BudgetAccount):
    exploration_id: int
    strategy: str = Field(description="the spec's strategy name")
    status: str


def _seconds(start: datetime | None, end: datetime | None) -> float | None:
    if start is None or end is None:
        return None
    return max(0.0, (end - start).total_seconds())


def account(rows: Iterable[Any], started_at: datetime | None,
            certification: Collection[str] = frozenset()) -> BudgetAccount:
    """The accounting of stored pose rows (PoseRow or anything with its attributes);
    `started_at`: the exploration's first lease; `certification`: the keys of the poses
    planned for certification."""
    rows = list(rows)
    evaluated = [r for r in rows if not (r.worker_id or "").startswith("shortcut:")]
    viable = [r for r in rows if r.viable]
    best_mu = max((float(r.mu_s) for r in viable), default=None)
    ranked = [float(v) for r in viable
              if (v := getattr(r, DEFAULT_RANK.value)) is not None]
    best_rank = (min if DEFAULT_RANK in LOWER_IS_BETTER else max)(ranked, default=None)
    first = min((r.created_at for r in viable), default=None)
    near = min((r.created_at for r in viable
                if best_mu is not None and float(r.mu_s) >= NEAR_BEST * best_mu), default=None)
    return BudgetAccount(
        evaluations=len(evaluated),
        certification_evaluations=sum(1 for r in evaluated if r.pose_key in certification),
        poses_stored=len(rows),
        wall_time_s=_seconds(started_at, max((r.created_at for r in rows), default=None)),
        best_mu_s=best_mu,
        rank_metric=DEFAULT_RANK.value,
        best_rank=best_rank,
        best_robust_q=max((float(r.robust_q) for r in viable
                           if getattr(r, "robust_q", None) is not None), default=None),
        grasp_types=len({StoredPose.from_row(r).digits for r in viable}),
        grasps=len(viable),
        misses=sum(1 for r in evaluated if not r.viable),
        time_to_first_grasp_s=_seconds(started_at, first),
        time_to_near_best_s=_seconds(started_at, near),
    )


def exploration_budget(session: Session, exploration_id: int) -> ExplorationBudget:
    """The accounting of one stored exploration. NotFound if there is none."""
    row = get_exploration(session, exploration_id=exploration_id)
    poses = session.scalars(select(PoseRow).where(PoseRow.exploration_id == exploration_id))
    figures = account(poses, row.started_at, set(certification_plans(session, exploration_id)))
    large = session.scalar(select(func.count()).select_from(ManifoldRow).where(
        ManifoldRow.exploration_id == exploration_id, ManifoldRow.large.is_(True)))
    any_manifold = session.scalar(select(func.count()).select_from(ManifoldRow).where(
        ManifoldRow.exploration_id == exploration_id))
    figures.large_manifolds = large if any_manifold else None
    return ExplorationBudget(exploration_id=row.id,
                             strategy=str(row.spec.get("strategy", {}).get("name", "adaptive")),
                             status=row.status, **figures.model_dump())
