"""Progress answers an ETA only when it can be estimated: none before 10 poses came in the
throughput window, and the rate over the part of the window since its first pose."""

from __future__ import annotations

from datetime import timedelta

import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator.exploration.service import progress
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from tests.services.coordinator.api.test_explorations import submit, work


def test_no_eta_until_it_can_be_estimated(client: TestClient, object_id: int,
                                           sessions: sessionmaker[Session]) -> None:
    """A few poses measure start-up, not a rate: no ETA below 10 in the window; then the rate
    is over the time since the window's first pose (the whole window read 21 min for a 17 s
    run)."""
    eid = submit(client, object_id)["id"]
    stored = work(sessions, 1)
    assert 0 < len(stored) < 10
    assert client.get(f"/explorations/{eid}").json()["progress"]["eta_s"] is None
    while len(stored) < 10:
        stored += work(sessions, 1)
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        first = min(s.scalars(select(PoseRow.created_at).where(PoseRow.exploration_id == eid)))
        later = progress(s, row=row, window_s=60.0, now=first + timedelta(seconds=20))
        assert later.throughput_poses_per_s == pytest.approx(len(stored) / 20.0, rel=0.05)
        assert later.eta_s == pytest.approx((row.poses_total - row.poses_done)
                                            / later.throughput_poses_per_s)
