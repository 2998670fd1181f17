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
from types import SimpleNamespace
from typing import Any

from graspscape.services.coordinator.exploration import symmetry
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
from graspscape.services.coordinator.exploration.symmetry import Orbits
from graspscape.services.coordinator.exploration.tiling import TilePlan, coarse_tiles, group_tiles
from graspscape.services.coordinator.manifolds.behaviour import Sample
from graspscape.services.coordinator.store.dialect import insert_for
from graspscape.services.coordinator.store.models import (
    POSE_METRIC_COLUMNS,
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
from sqlalchemy import bindparam, func, insert, select, update
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
def plan_coarse(
    spec: ExplorationSpec, *, target_poses: int, session: Session | None = None
) -> list[TilePlan]:
    """Level-0 tiles. With normal reuse only the two r ends of each normal are evaluated
    first; the levels between are inferred or bisected as the ends come in. With symmetry,
    only one pose of each orbit is evaluated; the others are mirrored from it."""
    normal = spec.shortcuts.normal_reuse and len(spec.grid.r_levels()) > 2
    orbits = symmetry_orbits(session, spec) if session is not None else None
    if not normal and orbits is None:
        return coarse_tiles(spec.grid, target_poses=target_poses)
    lattice = lattice_of(spec)
    top = lattice.n_r * lattice.scale(0)
    points = [p for p in lattice.coarse_points() if not normal or p.I in (0, top)]
    if orbits is not None:
        points = [p for p in points if orbits.representative(p) == p]
    return group_tiles([lattice.pose(p) for p in points], target_poses=target_poses)


_DETECTED: dict[int, tuple[Any, list[symmetry.Symmetry]]] = {}
_ORBITS: dict[tuple[str, tuple[symmetry.Symmetry, ...]], Orbits] = {}


def object_symmetries(session: Session, spec: ExplorationSpec) -> list[symmetry.Symmetry]:
    """The symmetries of the exploration's object that the task keeps: rotations about z and
    vertical mirrors (mirrors only for a mirror-symmetric gripper); none where the mesh is
    unavailable."""
    from graspscape.services.coordinator.manifolds.service import object_mesh
    from graspscape.shared.specs.gripper import load_gripper

    mesh = object_mesh(session, spec.object_id)
    if mesh is None:
        return []
    # object_mesh caches one mesh per object spec; keyed by identity, the entry keeps the
    # mesh alive so its id is never reused for another object.
    if id(mesh) not in _DETECTED:
        _DETECTED[id(mesh)] = (mesh, symmetry.detect(mesh))
    return symmetry.task_symmetries(_DETECTED[id(mesh)][1], load_gripper(spec.gripper))


def resolve_grid(session: Session, spec: ExplorationSpec) -> ExplorationSpec:
    """The spec with its lattice's azimuth multiple decided (`PoseGridSpec.azimuth_multiple`):
    as given, else the object's symmetry order when the symmetry shortcut is on, else 1."""
    if spec.grid.azimuth_multiple is not None:
        return spec
    multiple = 1
    if spec.shortcuts.symmetry:
        multiple = symmetry.azimuth_multiple(object_symmetries(session, spec))
    grid = spec.grid.model_copy(update={"azimuth_multiple": multiple})
    return spec.model_copy(update={"grid": grid})


def symmetry_orbits(session: Session | None, spec: ExplorationSpec) -> Orbits | None:
    """The orbits of the exploration's lattice under the object's symmetries (shortcut 3),
    or None when the shortcut is off or the object has no usable symmetry."""
    if session is None or not spec.shortcuts.symmetry:
        return None
    found = tuple(object_symmetries(session, spec))
    if not found:
        return None
    key = (spec.model_dump_json(), found)
    if key not in _ORBITS:
        _ORBITS[key] = symmetry.Orbits(lattice_of(spec), list(found))
    return _ORBITS[key]


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
    PoseRow.inferred_from,
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
                    samples: dict[Point, Sample], lattice: Lattice, now: datetime,
                    paths: dict[Point, tuple[symmetry.Symmetry, ...]] | None = None,
                    hand: symmetry.HandMirror | None = None) -> int:
    """Copies of the source results under the inferred poses' keys (worker 'shortcut:…');
    with `paths`, each copy is mirrored along its point's chain of symmetries."""
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
        row = {
            "exploration_id": exploration_id, "tile_id": src.tile_id, "pose_key": pose.key(),
            "theta": pose.theta, "phi": pose.phi, "r": pose.r, "roll": pose.roll,
            "pitch": pose.pitch, "yaw": pose.yaw, "outcome": src.outcome, "viable": src.viable,
            "mu_s": src.mu_s, "effective_r": None, "effort_max_nm": src.effort_max_nm,
            "contacts_per_link": src.contacts_per_link, "signature": src.signature,
            "grasp": src.grasp, "worker_id": f"shortcut:{inf.reason}", "eval_time_s": 0.0,
            "created_at": now,
            # The source's grasp metrics and margins, like its μs (none changes under a mirror).
            **{name: getattr(src, name) for name in POSE_METRIC_COLUMNS},
        }
        for sym in (paths or {}).get(inf.point, ()):
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
        # Coarse poses were counted in poses_total at submission; finer ones were not.
        finer = sum(1 for inf in inferences
                    if lattice.birth(inf.point) > 0 and lattice.pose(inf.point).key() in returned)
        session.execute(
            update(ExplorationRow)
            .where(ExplorationRow.id == exploration_id)
            .values(poses_done=ExplorationRow.poses_done + len(returned),
                    poses_total=ExplorationRow.poses_total + finer,
                    viable_count=ExplorationRow.viable_count
                    + sum(1 for v in returned.values() if v))
            .execution_options(synchronize_session=False)
        )
    for inf, row in zip(inferences, rows, strict=True):  # later decisions read them too
        samples[inf.point] = Sample.from_row(SimpleNamespace(**row))
    return len(returned)


# --- the hook --------------------------------------------------------------------------------
_STATE = select(ExplorationRow.status, ExplorationRow.created_at).where(
    ExplorationRow.id == bindparam("id")
)
_SPEC = select(ExplorationRow.spec).where(ExplorationRow.id == bindparam("id"))
# Specs never change after submission: the hook reads one per exploration, not per batch (a
# spec is a JSON document to load and validate). Keyed with the creation time, as
# dispatch.catalog is: SQLite may give a deleted exploration's id to a new one.
_SPECS_AT: dict[tuple[int, datetime], ExplorationSpec] = {}
_MAX_SPECS_AT = 256


def _spec_at(session: Session, exploration_id: int, created_at: datetime) -> ExplorationSpec:
    key = (exploration_id, created_at)
    spec = _SPECS_AT.get(key)
    if spec is None:
        spec = spec_of(session.scalar(_SPEC, {"id": exploration_id}), exploration_id)
        if len(_SPECS_AT) >= _MAX_SPECS_AT:
            _SPECS_AT.clear()
        _SPECS_AT[key] = spec
    return spec


def after_ingest(
    session: Session,
    *,
    exploration_id: int,
    results: Sequence[PoseResult],
    tile_moved: bool,
    now: datetime,
    target_poses: int = 100,
    status: str | None = None,
    created_at: datetime | None = None,
) -> None:
    """React to a stored batch: refine borders, apply shortcuts, search, finish manifolds.

    `status`, `created_at`: the exploration's, when the caller has read them in this
    transaction already (the ingest's counter update returns them)."""
    if status is None or created_at is None:
        row = session.connection().execute(_STATE, {"id": exploration_id}).one_or_none()
        if row is None:
            return
        status, created_at = row.status, row.created_at
    if status == ExplorationStatus.CANCELLED:
        return
    spec = _spec_at(session, exploration_id, created_at)
    lattice = lattice_of(spec)
    if lattice.depth == 0 and not (spec.shortcuts.normal_reuse or spec.shortcuts.symmetry):
        # Coarse pass only, no shortcuts: no batch can lead to more work, and the manifolds
        # are computed on request; ingest stays at the store's own speed.
        return
    orbits = symmetry_orbits(session, spec)
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
            extra -= wanted
            wanted |= extra
            samples.update(load_samples(session, exploration_id, lattice,
                                        [lattice.pose(q).key() for q in extra]))
            _store_inferred(session, exploration_id, inferences, samples, lattice, now)
            todo += [i.point for i in inferences]
        if orbits is not None:
            # Every image's neighbours must be at hand: a pair missed now is missed for good.
            extra = set()
            for p in todo:
                for q in orbits.orbit(p):
                    extra |= {q} | lookup_points(lattice, q)
            extra -= wanted
            wanted |= extra
            samples.update(load_samples(session, exploration_id, lattice,
                                        [lattice.pose(q).key() for q in extra]))
            todo += _mirror(session, exploration_id, todo, orbits, samples, lattice, spec, now)
        for p in todo:
            proposals += border_proposals(lattice, p, samples.get, mu_step)
        proposals = _canonical(proposals, orbits, lattice)
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


def _canonical(proposals: list[Proposal], orbits: Orbits | None, lattice: Lattice
               ) -> list[Proposal]:
    """With symmetry, each proposal becomes its orbit's representative (evaluated once,
    mirrored onto the rest when it arrives)."""
    if orbits is None:
        return proposals
    out = []
    for prop in proposals:
        rep = orbits.representative(prop.point)
        out.append(Proposal(rep, lattice.birth(rep) if prop.reason != "search" else prop.level,
                            prop.reason))
    return out


def _mirror(session: Session, exploration_id: int, points: list[Point], orbits: Orbits,
            samples: dict[Point, Sample], lattice: Lattice, spec: ExplorationSpec,
            now: datetime) -> list[Point]:
    """Shortcut 3: copy each new result onto the rest of its orbit; returns the new points."""
    from graspscape.shared.specs.gripper import load_gripper

    hand = symmetry.hand_mirror(load_gripper(spec.gripper))
    todo: dict[Point, Inference] = {}
    paths: dict[Point, tuple[symmetry.Symmetry, ...]] = {}
    for p in points:
        for q, path in orbits.orbit(p).items():
            if q != p and q not in samples and q not in todo:
                todo[q] = Inference(q, p, "symmetry")
                paths[q] = path
    inferences = sorted(todo.values(), key=lambda i: i.point)
    _store_inferred(session, exploration_id, inferences, samples, lattice, now, paths, hand)
    return [i.point for i in inferences]


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
        proposals = _canonical(proposals, symmetry_orbits(session, spec), lattice)
        proposals = [q for q in proposals if q.point not in samples]
        fresh = _plan(session, exploration_id, proposals, lattice, now)
        if fresh:
            _enqueue(session, exploration_id, fresh, lattice,
                     {"search": SEARCH_LEVEL_BASE + rounds_done}, now, target_poses)
            refresh_manifolds(session, exploration_id, spec, lattice, samples=samples, final=False)
            return
    refresh_manifolds(session, exploration_id, spec, lattice, samples=samples, final=True)
