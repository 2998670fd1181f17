"""The adaptive exploration at the store's edge: plan the coarse pass, react to results.

`after_ingest` runs inside the ingest transaction, after the poses are inserted and the
exploration's counters updated. That UPDATE holds the exploration row's lock until commit, so
ingests of one exploration run this step one at a time, and each sees every result committed
before it: a pair of neighbours is always judged by whichever of its two results arrives last.
Decisions come from `refine` (pure); this module only loads what they read and stores what
they decide: inferred poses, planned poses (unique per exploration: never evaluated twice),
and the tiles holding them. When no tile is open any more, a round of local search is planned,
or, after the last round, the manifolds are computed for good.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from datetime import datetime
from typing import Any

from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.exploration.refine import (
    Inference,
    Proposal,
    border_proposals,
    local_maxima,
    lookup_points,
    normal_decisions,
    search_proposals,
)
from graspscape.services.coordinator.exploration.tiling import TilePlan, coarse_tiles, group_tiles
from graspscape.services.coordinator.manifolds.behaviour import Sample
from graspscape.services.coordinator.store.dialect import insert_for
from graspscape.services.coordinator.store.models import (
    TERMINAL_TILE_STATES,
    ExplorationRow,
    ExplorationStatus,
    PosePlanRow,
    PoseRow,
    TileRow,
    TileState,
)
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import PoseResult
from sqlalchemy import func, insert, select, update
from sqlalchemy.orm import Session

log = logging.getLogger("graspscape.coordinator.adaptive")

SEARCH_LEVEL_BASE = 100  # tile level of local-search round k: 100 + k (leased after refinement)
_KEY_CHUNK = 500
_SPECS: dict[int, tuple[str, ExplorationSpec]] = {}


def spec_of(row_spec: dict[str, Any], exploration_id: int) -> ExplorationSpec:
    """The stored spec, parsed once per process (validation resolves gripper and policy)."""
    import json

    text = json.dumps(row_spec, sort_keys=True)
    cached = _SPECS.get(exploration_id)
    if cached is None or cached[0] != text:
        cached = (text, ExplorationSpec.model_validate(row_spec))
        _SPECS[exploration_id] = cached
    return cached[1]


def lattice_of(spec: ExplorationSpec) -> Lattice:
    return Lattice(spec.grid, spec.refinement.levels)


# --- the coarse pass -------------------------------------------------------------------------
def plan_coarse(spec: ExplorationSpec, *, target_poses: int) -> list[TilePlan]:
    """Level-0 tiles. With normal reuse only the two r ends of each normal are evaluated
    first; the levels between are inferred or bisected as the ends come in."""
    if not spec.shortcuts.normal_reuse or len(spec.grid.r_levels()) <= 2:
        return coarse_tiles(spec.grid, target_poses=target_poses)
    lattice = lattice_of(spec)
    top = lattice.n_r * lattice.scale(0)
    ends = [lattice.pose(p) for p in lattice.coarse_points() if p.I in (0, top)]
    return group_tiles(ends, target_poses=target_poses)


# --- loading ---------------------------------------------------------------------------------
_SAMPLE_COLUMNS = (
    PoseRow.pose_key,
    PoseRow.theta,
    PoseRow.phi,
    PoseRow.r,
    PoseRow.roll,
    PoseRow.pitch,
    PoseRow.yaw,
    PoseRow.viable,
    PoseRow.outcome,
    PoseRow.mu_s,
    PoseRow.effort_max_nm,
    PoseRow.signature,
    PoseRow.grasp,
    PoseRow.worker_id,
)


def _point_or_none(lattice: Lattice, pose: Pose) -> Point | None:
    try:
        p = lattice.point(pose)
        return p if lattice.pose(p).key() == pose.key() else None
    except ValueError:
        return None


def load_samples(
    session: Session, exploration_id: int, lattice: Lattice, keys: Iterable[str] | None = None
) -> dict[Point, Sample]:
    """Stored poses of an exploration (all, or those with the given keys) by lattice point."""
    out: dict[Point, Sample] = {}
    base = select(*_SAMPLE_COLUMNS).where(PoseRow.exploration_id == exploration_id)
    if keys is None:
        batches = [session.execute(base).all()]
    else:
        wanted = sorted(set(keys))
        batches = [
            session.execute(base.where(PoseRow.pose_key.in_(wanted[i : i + _KEY_CHUNK]))).all()
            for i in range(0, len(wanted), _KEY_CHUNK)
        ]
    for rows in batches:
        for row in rows:
            sample = Sample.from_row(row)
            pose = Pose(theta=row.theta, phi=row.phi, r=row.r, roll=row.roll, pitch=row.pitch,
                        yaw=row.yaw)
            p = _point_or_none(lattice, pose)
            if p is not None:
                out[p] = sample
    return out


# --- storing ---------------------------------------------------------------------------------
def _plan(session: Session, exploration_id: int, proposals: Sequence[Proposal], lattice: Lattice,
          now: datetime) -> list[Proposal]:
    """Insert plans; return those that were new (another ingest may have planned some)."""
    by_key: dict[str, Proposal] = {}
    for prop in sorted(proposals, key=lambda q: (q.level, q.point)):
        by_key.setdefault(lattice.pose(prop.point).key(), prop)
    if not by_key:
        return []
    table = PosePlanRow.__table__
    rows = [
        {"exploration_id": exploration_id, "pose_key": k, "level": prop.level,
         "reason": prop.reason, "created_at": now}
        for k, prop in by_key.items()
    ]
    stmt = (
        insert_for(session, table)
        .on_conflict_do_nothing(index_elements=[table.c.exploration_id, table.c.pose_key])
        .returning(table.c.pose_key)
    )
    new = {k for (k,) in session.connection().execute(stmt, rows)}
    return [prop for k, prop in by_key.items() if k in new]


def _enqueue(session: Session, exploration_id: int, props: list[Proposal], lattice: Lattice,
             level_of: dict[str, int], now: datetime, target_poses: int) -> int:
    by_level: dict[int, list[Pose]] = {}
    for prop in props:
        level = level_of.get(prop.reason, prop.level)
        by_level.setdefault(level, []).append(lattice.pose(prop.point))
    added = 0
    for level, poses in sorted(by_level.items()):
        last = session.scalar(
            select(func.max(TileRow.index)).where(
                TileRow.exploration_id == exploration_id, TileRow.level == level
            )
        )
        first = 0 if last is None else last + 1
        tiles = group_tiles(poses, target_poses=target_poses, first_index=first)
        session.execute(
            insert(TileRow),
            [
                {
                    "exploration_id": exploration_id, "level": level, "index": t.index,
                    "cells": [list(c) for c in t.cells], "r_levels": t.r_levels,
                    "attitudes": [list(a) for a in t.attitudes], "n_poses": t.n_poses,
                    "state": TileState.QUEUED, "lease_epoch": 0, "attempts": 0,
                    "updated_at": now,
                }
                for t in tiles
            ],
        )
        added += len(tiles)
    session.execute(
        update(ExplorationRow)
        .where(ExplorationRow.id == exploration_id)
        .values(
            tiles_total=ExplorationRow.tiles_total + added,
            # Normal-reuse levels are coarse poses, already counted at submission.
            poses_total=ExplorationRow.poses_total
            + sum(1 for prop in props if prop.reason != "normal"),
            status=ExplorationStatus.RUNNING,
            finished_at=None,
            updated_at=now,
        )
        .execution_options(synchronize_session=False)
    )
    return added


def _store_inferred(session: Session, exploration_id: int, inferences: list[Inference],
                    samples: dict[Point, Sample], lattice: Lattice, now: datetime) -> int:
    """Copies of the source results under the inferred poses' keys (worker 'shortcut:…')."""
    if not inferences:
        return 0
    src_keys = sorted({samples[i.source].key for i in inferences})
    src_rows = {
        row.pose_key: row
        for row in session.execute(
            select(PoseRow).where(PoseRow.exploration_id == exploration_id,
                                  PoseRow.pose_key.in_(src_keys))
        ).scalars()
    }
    rows = []
    for inf in inferences:
        src = src_rows[samples[inf.source].key]
        pose = lattice.pose(inf.point)
        rows.append({
            "exploration_id": exploration_id, "tile_id": src.tile_id, "pose_key": pose.key(),
            "theta": pose.theta, "phi": pose.phi, "r": pose.r, "roll": pose.roll,
            "pitch": pose.pitch, "yaw": pose.yaw, "outcome": src.outcome, "viable": src.viable,
            "mu_s": src.mu_s, "effective_r": None, "effort_max_nm": src.effort_max_nm,
            "contacts_per_link": src.contacts_per_link, "signature": src.signature,
            "grasp": src.grasp, "worker_id": f"shortcut:{inf.reason}", "eval_time_s": 0.0,
            "created_at": now,
        })
    table = PoseRow.__table__
    stmt = (
        insert_for(session, table)
        .on_conflict_do_nothing(index_elements=[table.c.exploration_id, table.c.pose_key])
        .returning(table.c.viable)
    )
    returned = [bool(v) for (v,) in session.connection().execute(stmt, rows)]
    if returned:
        session.execute(
            update(ExplorationRow)
            .where(ExplorationRow.id == exploration_id)
            .values(poses_done=ExplorationRow.poses_done + len(returned),
                    viable_count=ExplorationRow.viable_count + sum(returned))
            .execution_options(synchronize_session=False)
        )
    for inf in inferences:  # the decisions that follow read the inferred results too
        src = samples[inf.source]
        pose = lattice.pose(inf.point)
        samples[inf.point] = Sample(**{**src.__dict__, "key": pose.key(), "r": pose.r,
                                       "source": f"shortcut:{inf.reason}"})
    return len(returned)


# --- the hook --------------------------------------------------------------------------------
def after_ingest(
    session: Session,
    *,
    exploration_id: int,
    results: Sequence[PoseResult],
    tile_moved: bool,
    now: datetime,
    target_poses: int = 100,
) -> None:
    """React to a stored batch: refine borders, apply shortcuts, search, finish manifolds."""
    row = session.execute(
        select(ExplorationRow.spec, ExplorationRow.status)
        .where(ExplorationRow.id == exploration_id)
    ).one_or_none()
    if row is None or row.status == ExplorationStatus.CANCELLED:
        return
    spec = spec_of(row.spec, exploration_id)
    lattice = lattice_of(spec)
    new_points = sorted(
        p for p in (_point_or_none(lattice, r.pose) for r in results) if p is not None
    )
    if new_points:
        wanted: set[Point] = set(new_points)
        for p in new_points:
            wanted |= lookup_points(lattice, p)
        samples = load_samples(session, exploration_id, lattice,
                               [lattice.pose(q).key() for q in wanted])
        proposals: list[Proposal] = []
        todo = [p for p in new_points if p in samples]
        mu_step = spec.refinement.mu_step_max
        if spec.shortcuts.normal_reuse:
            inferences: list[Inference] = []
            for p in todo:
                props, infs = normal_decisions(lattice, p, samples.get, mu_step)
                proposals += props
                inferences += [i for i in infs if i.point not in samples]
            inferences = sorted({i.point: i for i in inferences}.values(), key=lambda i: i.point)
            # Inferred points neighbour others; their own lookups may need more rows.
            extra = set()
            for inf in inferences:
                extra |= lookup_points(lattice, inf.point)
            extra -= set(samples)
            samples.update(load_samples(session, exploration_id, lattice,
                                        [lattice.pose(q).key() for q in extra]))
            _store_inferred(session, exploration_id, inferences, samples, lattice, now)
            todo += [i.point for i in inferences]
        for p in todo:
            proposals += border_proposals(lattice, p, samples.get, mu_step)
        proposals = [q for q in proposals if q.point not in samples]
        budget = spec.refinement.max_poses - (
            session.scalar(select(func.count()).select_from(PosePlanRow)
                           .where(PosePlanRow.exploration_id == exploration_id)) or 0
        )
        refine = [q for q in proposals if q.reason == "refine"]
        keep = [q for q in proposals if q.reason != "refine"] + sorted(
            refine, key=lambda q: (q.level, q.point))[: max(0, budget)]
        fresh = _plan(session, exploration_id, keep, lattice, now)
        if fresh:
            _enqueue(session, exploration_id, fresh, lattice, {"normal": 0}, now, target_poses)
    if lattice.depth == 0:
        # A coarse-only exploration: its manifolds are computed on request (manifolds.service
        # `ensure_manifolds`), not on every ingest.
        return
    if tile_moved and not _open_tiles(session, exploration_id):
        _quiescent(session, exploration_id, spec, lattice, now, target_poses)
    elif tile_moved:
        from graspscape.services.coordinator.manifolds.service import maybe_refresh

        maybe_refresh(session, exploration_id, spec, lattice)


def _open_tiles(session: Session, exploration_id: int) -> bool:
    return bool(
        session.scalar(
            select(func.count()).select_from(TileRow).where(
                TileRow.exploration_id == exploration_id,
                TileRow.state.not_in(TERMINAL_TILE_STATES),
            )
        )
    )


def _quiescent(session: Session, exploration_id: int, spec: ExplorationSpec, lattice: Lattice,
               now: datetime, target_poses: int) -> None:
    """Nothing open: the next local-search round, or the final manifolds."""
    from graspscape.services.coordinator.manifolds.service import refresh_manifolds

    rounds_done = session.scalar(
        select(func.count(func.distinct(TileRow.level))).where(
            TileRow.exploration_id == exploration_id, TileRow.level >= SEARCH_LEVEL_BASE
        )
    ) or 0
    samples = load_samples(session, exploration_id, lattice)
    if rounds_done < spec.refinement.local_search_rounds:
        from graspscape.services.coordinator.manifolds.grouping import components

        proposals: list[Proposal] = []
        for comp in components(lattice, samples):
            maxima = local_maxima(lattice, comp, samples.get,
                                  top=spec.refinement.local_search_starts)
            proposals += search_proposals(lattice, maxima, samples.get)
        fresh = _plan(session, exploration_id, proposals, lattice, now)
        if fresh:
            _enqueue(session, exploration_id, fresh, lattice,
                     {"search": SEARCH_LEVEL_BASE + rounds_done}, now, target_poses)
            refresh_manifolds(session, exploration_id, spec, lattice, samples=samples, final=False)
            return
    refresh_manifolds(session, exploration_id, spec, lattice, samples=samples, final=True)
