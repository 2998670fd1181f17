"""Paged /poses reads only the columns it returns (issue 21): its bytes are those of the page
built from the full ORM rows, as the route did before, on both databases."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient
from graspscape.services.coordinator.api.pages import CursorPage
from graspscape.services.coordinator.api.responses import encoded
from graspscape.services.coordinator.exploration.schemas import PoseOut
from graspscape.services.coordinator.store.models import PoseRow
from sqlalchemy import func, select, update
from sqlalchemy.orm import Session, sessionmaker

from tests.services.coordinator.api.test_explorations import submit, work


def _orm_page(sessions: sessionmaker[Session], eid: int, limit: int, cursor: int | None,
              **where: Any) -> bytes:
    """The page as the route built it from ORM rows (select(PoseRow), every column)."""
    query = select(PoseRow).where(PoseRow.exploration_id == eid)
    if cursor is not None:
        query = query.where(PoseRow.id > cursor)
    for name, value in where.items():
        query = query.where(getattr(PoseRow, name) == value)
    with sessions() as s:
        rows = list(s.scalars(query.order_by(PoseRow.id).limit(limit + 1)))
        next_cursor = rows[limit - 1].id if len(rows) > limit else None
        return encoded(CursorPage[PoseOut](items=rows[:limit], limit=limit,
                                           next_cursor=next_cursor))


def test_a_page_has_the_bytes_of_the_orm_rows_page(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    eid = submit(client, object_id)["id"]
    results = work(sessions, 3)
    with sessions() as s:  # the optional columns too: some rows with values, the rest null
        first = s.scalar(select(func.min(PoseRow.id)).where(PoseRow.exploration_id == eid))
        s.execute(update(PoseRow).where(PoseRow.id <= first + 3).values(
            robust_s=0.75, robust_q=0.5, robust_label="fragile", mu_g=0.125, certifies="k",
            error="a message with \"quotes\" and ü", torque_margin_ratio=1e-5))
        s.commit()
    pages, cursor = 0, None
    while True:
        params: dict[str, Any] = {"limit": 5}
        if cursor is not None:
            params["cursor"] = cursor
        response = client.get(f"/explorations/{eid}/poses", params=params)
        assert response.status_code == 200
        assert response.content == _orm_page(sessions, eid, 5, cursor)
        pages += 1
        cursor = response.json()["next_cursor"]
        if cursor is None:
            break
    assert pages == -(-len(results) // 5)
    viable = client.get(f"/explorations/{eid}/poses", params={"viable": "true", "limit": 1000})
    assert viable.content == _orm_page(sessions, eid, 1000, None, viable=True)
    assert len(viable.json()["items"]) == sum(r.viable for r in results) > 0

