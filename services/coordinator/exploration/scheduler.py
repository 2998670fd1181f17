"""The exploration scheduler: record a batch of results and ask the strategy what comes next.

One transaction per batch: the store takes the batch (store/ingest.py: lease check,
idempotent insert, the tile finished, then the counters), then the exploration's strategy
(`ExplorationSpec.strategy`, exploration/strategies/) decides from what is stored now which
poses to evaluate next, and they are planned and queued (exploration/planning.py), all
before the commit. The counter update takes the exploration row's lock, held to the commit,
so the batches of one exploration reach their strategy one at a time, each seeing every
result committed before it. After the commit, outside that transaction, the manifold
keeper (manifolds/keeper.py) brings the exploration's manifold table up to date where it is
due, for every strategy. The dispatcher and the in-process run both report through
`ingest_results`; a submission gets its first tiles from `initial_tiles`.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from datetime import datetime
from typing import Literal

from graspscape.services.coordinator.exploration.planning import schedule
from graspscape.services.coordinator.exploration.specs import stored_spec
from graspscape.services.coordinator.exploration.strategies.base import Batch, Stage
from graspscape.services.coordinator.exploration.strategies.registry import strategy_for
from graspscape.services.coordinator.exploration.tiling import TilePlan
from graspscape.services.coordinator.manifolds.keeper import Keeper, current_keeper
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.ingest import IngestReport, StoredBatch, store_batch
from graspscape.services.coordinator.store.models import (
    TERMINAL_TILE_STATES,
    ExplorationStatus,
    TileRow,
)
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.results import PoseResult
from sqlalchemy import func, select
from sqlalchemy.orm import Session

log = logging.getLogger("graspscape.coordinator.scheduler")

# Tiles of later work, as the scheduler queues them (the coordinator's tile size setting
# applies to the first tiles of a submission).
TARGET_POSES = 100


def initial_tiles(session: Session, spec: ExplorationSpec, *, target_poses: int
                  ) -> tuple[int, list[TilePlan]]:
    """What a submission starts with: the poses its strategy plans in all (for progress)
    and its first tiles."""
    strategy = strategy_for(spec)
    # The work first: a strategy may count its poses as it plans them (strategies/seeded.py).
    work = strategy.initial_work(session, target_poses=target_poses)
    return strategy.planned_poses(), work


def ingest_results(
    session: Session,
    *,
    tile_id: int,
    lease_epoch: int,
    worker_id: str,
    results: Sequence[PoseResult],
    final: bool = True,
    now: datetime | None = None,
    keeper: Keeper | Literal["current"] | None = "current",
) -> IngestReport:
    """Store a batch of results of one tile (store/ingest.store_batch: with `final`, the tile
    is finished once every pose of it is stored), let the strategy react, commit; then the
    `keeper`'s turn, in a transaction of its own ("current": the coordinator's keeper,
    `keeper.current_keeper`; None: the table is left as it is).

    Raises what store_batch raises (NotFound, NotLeaseHolder, InvalidInput); a refused batch
    stores nothing."""
    now = now or utcnow()

    def quiet(exploration_id: int, created_at: datetime) -> bool:
        # after_batch would do nothing (the strategy does not react): the store may commit
        # with the counter update, one round trip less under the exploration's row lock.
        return not strategy_for(stored_spec(session, exploration_id, created_at)).reacts

    stored = store_batch(session, tile_id=tile_id, lease_epoch=lease_epoch, worker_id=worker_id,
                         results=results, final=final, now=now, quiet=quiet)
    if not stored.committed:
        after_batch(session, stored, results, now)
    session.commit()  # nothing left to commit when the store did
    if keeper is not None and stored.exploration_status is not None:
        if keeper == "current":
            keeper = current_keeper()
        try:
            keeper.keep(session, stored.exploration_id)
        except Exception:  # the batch is committed: its Ack must not wait on the table
            # (the lease sweep's catch_up refreshes it later)
            log.exception("exploration %s: the manifold table was not refreshed",
                          stored.exploration_id)
            session.rollback()
    return stored.report


def after_batch(session: Session, stored: StoredBatch, results: Sequence[PoseResult],
                now: datetime, target_poses: int = TARGET_POSES) -> None:
    """The strategy's turn after a stored batch, in its transaction (the caller commits)."""
    if stored.exploration_status is None or stored.exploration_created_at is None:
        return  # nothing new stored, no tile moved
    if stored.exploration_status == ExplorationStatus.CANCELLED:
        return
    spec = stored_spec(session, stored.exploration_id, stored.exploration_created_at)
    strategy = strategy_for(spec)
    if not strategy.reacts:
        return
    batch = Batch(session=session, exploration_id=stored.exploration_id, spec=spec,
                  results=results, tile_moved=stored.report.tile_moved, now=now,
                  target_poses=target_poses)
    schedule(session, batch.exploration_id, strategy.after_batch(batch), now, target_poses)
    if not strategy.has_rounds or not batch.tile_moved:
        return
    if _open_tiles(session, batch.exploration_id):
        strategy.progress(batch, Stage.RUNNING)
        return
    fresh = schedule(session, batch.exploration_id, strategy.next_round(batch), now,
                     target_poses)
    strategy.progress(batch, Stage.NEW_ROUND if fresh else Stage.FINISHED)


def _open_tiles(session: Session, exploration_id: int) -> bool:
    return bool(
        session.scalar(
            select(func.count()).select_from(TileRow).where(
                TileRow.exploration_id == exploration_id,
                TileRow.state.not_in(TERMINAL_TILE_STATES),
            )
        )
    )
