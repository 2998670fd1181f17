"""Storing what a strategy decides: planned poses, the tiles holding them, inferred results.

A pose is planned once per exploration (pose_plans is unique on the pose key), so a pose two
batches both propose is evaluated once; only newly planned poses get tiles. Inferred results
(shortcuts) are copies of stored results under other poses' keys.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from datetime import datetime
from typing import Any

from graspscape.services.coordinator.exploration import symmetry
from graspscape.services.coordinator.exploration.strategies.base import Planned
from graspscape.services.coordinator.exploration.tiling import group_tiles
from graspscape.services.coordinator.store import explorations, tiles
from graspscape.services.coordinator.store.dialect import insert_for
from graspscape.services.coordinator.store.models import (
    POSE_METRIC_COLUMNS,
    PosePlanRow,
    PoseRow,
    TileRow,
)
from graspscape.shared.specs.pose import Pose, tile_poses
from graspscape.shared.specs.results import DrawScales
from graspscape.shared.wire.messages import TileSample
from sqlalchemy import func, select
from sqlalchemy.orm import Session


def plan(session: Session, exploration_id: int, planned: Sequence[Planned], now: datetime
         ) -> list[Planned]:
    """Insert plans (the first of each pose key, in the given order); return those that were
    new (another batch may have planned some)."""
    by_key: dict[str, Planned] = {}
    for item in planned:
        by_key.setdefault(item.pose.key(), item)
    if not by_key:
        return []
    table = PosePlanRow.__table__
    rows = [
        {"exploration_id": exploration_id, "pose_key": k, "level": item.plan_level,
         "reason": item.reason, "created_at": now}
        for k, item in by_key.items()
    ]
    stmt = (
        insert_for(session, table)
        .on_conflict_do_nothing(index_elements=[table.c.exploration_id, table.c.pose_key])
        .returning(table.c.pose_key)
    )
    new = {k for (k,) in session.connection().execute(stmt, rows)}
    return [item for k, item in by_key.items() if k in new]


def enqueue(session: Session, exploration_id: int, planned: Sequence[Planned], now: datetime,
            target_poses: int) -> int:
    """Tiles for planned poses, per (round, tile level) after its last tile; the exploration
    runs again (it may have finished with its last tile). Returns the number of tiles."""
    # Draws share tiles only with draws for the same engines (a tile of draws is evaluated
    # outcome only, each pose under its own scales).
    by_level: dict[tuple[int, int, tuple[str, ...]], list[Planned]] = {}
    for item in planned:
        by_level.setdefault((item.round, item.tile_level, item.draw_engines or ()),
                            []).append(item)
    added = 0
    for (round_, level, engines), items in sorted(by_level.items()):
        last = session.scalar(
            select(func.max(TileRow.index)).where(
                TileRow.exploration_id == exploration_id, TileRow.round == round_,
                TileRow.level == level,
            )
        )
        first = 0 if last is None else last + 1
        grouped = group_tiles([item.pose for item in items], target_poses=target_poses,
                              first_index=first)
        if engines:
            scales = {item.pose.key(): item.draw_scales for item in items
                      if item.draw_scales is not None and item.draw_scales != DrawScales()}
            grouped = [replace(t, sample=TileSample(engines=list(engines), scales={
                k: scales[k] for k in (q.key() for q in tile_poses(t.cells, t.r_levels,
                                                                    t.attitudes))
                if k in scales})) for t in grouped]
        added += tiles.add_tiles(
            session, exploration_id=exploration_id, round=round_, level=level, now=now,
            tiles=grouped)
    explorations.count_planned(session, exploration_id, tiles_added=added,
                               poses_counted=sum(1 for item in planned if item.counted), now=now)
    return added


def schedule(session: Session, exploration_id: int, planned: Sequence[Planned], now: datetime,
             target_poses: int) -> list[Planned]:
    """Plan, and queue tiles for what was newly planned; returns that."""
    fresh = plan(session, exploration_id, planned, now)
    if fresh:
        enqueue(session, exploration_id, fresh, now, target_poses)
    return fresh


def store_inferred(session: Session, exploration_id: int,
                   copies: Sequence[tuple[Pose, str, str, bool]], now: datetime,
                   paths: Sequence[tuple[symmetry.Symmetry, ...]] | None = None,
                   hand: symmetry.HandMirror | None = None) -> list[dict[str, Any]]:
    """Copies of stored results under other poses' keys (worker 'shortcut:<reason>').

    `copies`: (pose, source pose key, reason, counted) each; `counted`: whether the pose adds
    to poses_total (coarse poses were counted at submission, finer ones were not). With
    `paths`, each copy is mirrored along its chain of symmetries. Returns the rows as built
    (stored or already there), in the order of `copies`."""
    if not copies:
        return []
    src_keys = sorted({source for _, source, _, _ in copies})
    src_rows = {
        row.pose_key: row
        for row in session.execute(
            select(PoseRow).where(PoseRow.exploration_id == exploration_id,
                                  PoseRow.pose_key.in_(src_keys))
        ).scalars()
    }
    rows = []
    for i, (pose, source, reason, _) in enumerate(copies):
        src = src_rows[source]
        row = {
            "exploration_id": exploration_id, "tile_id": src.tile_id, "pose_key": pose.key(),
            "theta": pose.theta, "phi": pose.phi, "r": pose.r, "roll": pose.roll,
            "pitch": pose.pitch, "yaw": pose.yaw, "outcome": src.outcome, "viable": src.viable,
            "mu_s": src.mu_s, "effective_r": None, "effort_max_nm": src.effort_max_nm,
            "contacts_per_link": src.contacts_per_link, "signature": src.signature,
            "grasp": src.grasp, "worker_id": f"shortcut:{reason}", "eval_time_s": 0.0,
            "created_at": now,
            # The source's grasp metrics and margins, like its μs (none changes under a mirror).
            **{name: getattr(src, name) for name in POSE_METRIC_COLUMNS},
        }
        for sym in (paths[i] if paths is not None else ()):
            row = symmetry.mirror_result(row, sym, hand)
        rows.append(row)
    table = PoseRow.__table__
    stmt = (
        insert_for(session, table)
        .on_conflict_do_nothing(index_elements=[table.c.exploration_id, table.c.pose_key])
        .returning(table.c.pose_key, table.c.viable)
    )
    returned = dict(session.connection().execute(stmt, rows).all())
    if returned:
        counted = sum(1 for pose, _, _, c in copies if c and pose.key() in returned)
        explorations.count_copies(session, exploration_id, stored=len(returned), counted=counted,
                                  viable=sum(1 for v in returned.values() if v))
    return rows
