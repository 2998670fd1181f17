"""The stored exploration spec, parsed once per coordinator (its state's `specs`: state.py):
the one cache every reader shares.

A spec never changes after submission, and parsing one (a JSON document validated into
ExplorationSpec, the gripper name checked against the configs) costs more than the work of a
small batch, so the scheduler, the dispatcher's lease replies and the manifold map all read
it through here. Entries are keyed by (exploration id, creation time): SQLite may give a
deleted exploration's id to a new one (before migration 0006), which must not inherit the old
spec.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from graspscape.services.coordinator.errors import NotFound
from graspscape.services.coordinator.state import current
from graspscape.services.coordinator.store.models import ExplorationRow
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy import bindparam, select
from sqlalchemy.orm import Session

_ROW = select(ExplorationRow.spec, ExplorationRow.created_at).where(
    ExplorationRow.id == bindparam("id"))
_SPEC = select(ExplorationRow.spec).where(ExplorationRow.id == bindparam("id"))


def _cached(exploration_id: int, created_at: datetime, spec_json: Any | None,
            session: Session | None) -> ExplorationSpec:
    cache = current().specs  # thread-safe: the dispatcher reads specs from its handler threads
    key = (exploration_id, created_at)
    spec = cache.get(key)
    if spec is not None:
        return spec
    if spec_json is None and session is not None:
        spec_json = session.scalar(_SPEC, {"id": exploration_id})
    if spec_json is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    spec = ExplorationSpec.model_validate(spec_json, context={"stored": True})
    return cache.put(key, spec)


def spec_of(row: ExplorationRow) -> ExplorationSpec:
    """The spec of an exploration row at hand."""
    return _cached(row.id, row.created_at, row.spec, None)


def stored_spec(session: Session, exploration_id: int,
                created_at: datetime | None = None) -> ExplorationSpec:
    """The spec of an exploration by id; `created_at` when the caller has read it already
    (then a cached spec costs no query). NotFound if there is no such exploration."""
    if created_at is not None:
        return _cached(exploration_id, created_at, None, session)
    row = session.execute(_ROW, {"id": exploration_id}).one_or_none()
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    return _cached(exploration_id, row.created_at, row.spec, None)
