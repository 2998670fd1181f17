"""The manifold table as it is exported — REST's `export/manifolds.json`, `graspscape map
export`, the atlas — built once here so that every copy says the same: the summaries, the dust
as one line, and beside each large manifold's scores its best grasp by P(success) (the first
answer of /best?manifold=L under rank=p_success) with its k of n draws, bounds and claim."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from graspscape.services.coordinator.manifolds import best as ranking
from graspscape.services.coordinator.manifolds import p_success
from graspscape.services.coordinator.manifolds.grouping import label_name
from graspscape.services.coordinator.manifolds.p_success import SuccessOut
from graspscape.services.coordinator.manifolds.service import is_final, stored_manifolds
from graspscape.services.coordinator.manifolds.summary import dust_line, table_rows_of
from graspscape.services.coordinator.store.models import ExplorationRow
from graspscape.shared.specs.support import resting_document
from pydantic import BaseModel, Field
from sqlalchemy.orm import Session


class ManifoldSuccess(BaseModel):
    """A large manifold's best grasp by P(success): what /best?manifold=L answers first."""

    pose_key: str
    success: SuccessOut | None = Field(description="its P(success) under the exploration's "
                                       "uncertainty model; null where nothing was drawn")


def manifold_successes(session: Session, exploration_id: int,
                       labels: Iterable[int]) -> dict[str, ManifoldSuccess]:
    """The first answer of /best?manifold=L (rank p_success) of each label, with P(success):
    the exploration's estimates read once for every label."""
    est = p_success.estimates(session, exploration_id)
    out = {}
    for number in labels:
        rows = ranking.best_by_p_success(session, exploration_id, est, label=number, limit=1)
        if rows:
            key = rows[0].pose_key
            out[label_name(number)] = ManifoldSuccess(pose_key=key, success=est.get(key))
    return out


def _with_success(rows: list[dict[str, Any]],
                  success: dict[str, ManifoldSuccess]) -> list[dict[str, Any]]:
    for row in rows:
        if row["label"] == "dust":
            continue
        chance = success.get(row["label"])
        e = chance.success if chance is not None else None
        row.update(p_success_best=chance.pose_key if chance else None,
                   p_success_k=e.k if e else None, p_success_n=e.n if e else None,
                   p_success_lower=round(e.lower, 4) if e else None,
                   p_success_upper=round(e.upper, 4) if e else None,
                   certified=e.certified if e else False)
    return rows


def table_document(session: Session, exploration_id: int) -> dict[str, Any]:
    """The exported manifold table as JSON-ready data."""
    items = stored_manifolds(session, exploration_id)
    success = manifold_successes(session, exploration_id, [m.label for m in items if m.large])
    return {"exploration_id": exploration_id, "final": is_final(session, exploration_id),
            "manifolds": [m.model_dump(mode="json") for m in items],
            "dust": dust_line(items),
            "success": {k: v.model_dump(mode="json") for k, v in success.items()},
            "table": _with_success(table_rows_of(items), success),
            **_resting(session, exploration_id)}


def _resting(session: Session, exploration_id: int) -> dict[str, Any]:
    """On a table, `resting_pose` (support.resting_document); nothing for a free object, so
    its table reads as it always did."""
    row = session.get(ExplorationRow, exploration_id)
    found = None if row is None else resting_document(row.spec)
    return {} if found is None else {"resting_pose": found}
