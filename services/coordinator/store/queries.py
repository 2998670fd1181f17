"""Read queries of the map routes that walk an index instead of scanning the exploration.

`best_pose_ids` is what `/best` runs. A `Ranking` is read as a few passes, each one index range
already in the answer's order, and the walk stops once `limit` poses are found: for a grouped
ranking (the robust label: robust, uncertain, fragile, futile, then unlabelled) one group at a
time; within a group, the poses that have the ranking value (value, then μs, then key), then
those without it (μs, then key). Passes rather than one `ORDER BY CASE … , value DESC NULLS
LAST` because neither a CASE nor NULLS LAST can be read off a plain index (SQLite has no NULLS
LAST in an index, PostgreSQL's DESC index puts NULLs first): this way one plain index per
ranking serves both backends (migration 0011; `store/models.py` lists them). The walk reads
only id, θ and φ (no JSON column is decoded); the full rows of the winners are loaded at the
end. An approach cone is checked on those light rows as they stream in index order, so a
query stops as soon as `limit` poses pass (worst case, a cone no pose lies in, it reads every
viable pose's id, θ and φ).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from graspscape.services.coordinator.store.models import PoseRow
from sqlalchemy import ColumnElement, select, true
from sqlalchemy.orm import Session

_CONE_BATCH = 256


def approach_vector(theta: float, phi: float) -> tuple[float, float, float]:
    """Direction the gripper moves in to approach (from its start toward the object)."""
    st = math.sin(theta)
    return (-st * math.cos(phi), -st * math.sin(phi), -math.cos(theta))


@dataclass(frozen=True)
class Ranking:
    """An order of /best: `group` values in `group_order` (which names every value the column
    takes; NULL after),
    then `value` (highest first, or lowest if `lower_is_better`; NULL after), then μs highest
    first, then the pose key. `value=None`: μs alone."""

    value: str | None = None
    lower_is_better: bool = False
    group: str | None = None
    group_order: tuple[str, ...] = ()


MU_S = Ranking()


def _passes(ranking: Ranking) -> Iterator[tuple[list[Any], list[Any]]]:
    """(conditions, order) of each pass, in the order the answer takes them."""
    mu_s_order = [PoseRow.mu_s.desc(), PoseRow.pose_key]
    groups: list[list[Any]] = [[]]
    if ranking.group is not None:
        column = getattr(PoseRow, ranking.group)
        groups = [[column == value] for value in ranking.group_order]
        groups.append([column.is_(None)])
    for where in groups:
        if ranking.value is None:
            yield where, mu_s_order
            continue
        value = getattr(PoseRow, ranking.value)
        first = value.asc() if ranking.lower_is_better else value.desc()
        yield [*where, value.is_not(None)], [first, *mu_s_order]
        # Every value here is NULL, so ordering by it changes nothing, but it keeps the ORDER BY
        # the index's own: PostgreSQL does not count `IS NULL` as an equality that fixes the
        # first key, and sorted the rows instead of reading them in index order.
        yield [*where, value.is_(None)], [first, *mu_s_order]


def best_pose_ids(
    session: Session,
    exploration_id: int,
    *,
    ranking: Ranking = MU_S,
    manifold_id: int | None = None,
    cone_axis: Sequence[float] | None = None,
    cone_half_angle: float | None = None,
    max_effort_nm: float | None = None,
    limit: int = 1,
    pose_keys: Collection[str] | None = None,
) -> list[int]:
    """Ids of the best viable poses, best first (see the module docstring for the order);
    only those among `pose_keys` where given."""
    # `viable = true`, not a bare `viable`: SQLite uses an index column only in a comparison.
    # A draw of a success probability is evidence about its centre, evaluated outcome only
    # (no μs, effort or margins): never a grasp to return.
    where: list[ColumnElement[bool]] = [PoseRow.exploration_id == exploration_id,
                                        PoseRow.viable == true(), PoseRow.sample.is_(None)]
    if manifold_id is not None:
        where.append(PoseRow.manifold_id == manifold_id)
    if max_effort_nm is not None:
        where.append(PoseRow.effort_max_nm <= max_effort_nm)
    if pose_keys is not None:
        where.append(PoseRow.pose_key.in_(sorted(pose_keys)))
    axis = None
    if cone_axis is not None:
        norm = math.sqrt(sum(c * c for c in cone_axis)) or 1.0
        axis = tuple(c / norm for c in cone_axis)
    cos_max = math.cos(cone_half_angle) if cone_half_angle is not None else -1.0
    ids: list[int] = []
    for extra, order in _passes(ranking):
        query = select(PoseRow.id, PoseRow.theta, PoseRow.phi).where(*where, *extra)
        query = query.order_by(*order)
        if axis is None:
            ids.extend(row[0] for row in session.execute(query.limit(limit - len(ids))))
        else:
            rows = session.execute(query.execution_options(yield_per=_CONE_BATCH))
            for pose_id, theta, phi in rows:
                v = approach_vector(theta, phi)
                if sum(a * b for a, b in zip(axis, v, strict=True)) >= cos_max - 1e-12:
                    ids.append(pose_id)
                    if len(ids) >= limit:
                        break
            rows.close()
        if len(ids) >= limit:
            break
    return ids


def rows_by_id(session: Session, ids: Sequence[int]) -> list[PoseRow]:
    """The full rows of `ids`, in that order."""
    if not ids:
        return []
    found = {row.id: row for row in session.scalars(select(PoseRow).where(PoseRow.id.in_(ids)))}
    return [found[i] for i in ids if i in found]


def best_pose_rows(session: Session, exploration_id: int, **options: Any) -> list[PoseRow]:
    """`best_pose_ids`' poses as full rows, best first."""
    return rows_by_id(session, best_pose_ids(session, exploration_id, **options))
