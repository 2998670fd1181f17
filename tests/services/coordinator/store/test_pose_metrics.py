"""Static grasp metrics and robustness margins: stored by the ingest (wire → store), served by
the API and the exports, and ranked by /best — on both databases."""

from __future__ import annotations

import csv
import io
from typing import Any

import pyarrow.parquet as pq
import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.manifolds import best
from graspscape.services.coordinator.manifolds.export import COLUMNS
from graspscape.services.coordinator.store.models import (
    GRASP_METRIC_COLUMNS,
    POSE_METRIC_COLUMNS,
    PoseRow,
)
from graspscape.services.coordinator.store.queue import lease_tiles
from graspscape.shared.specs.results import Outcome, PoseResult, RobustnessReport
from graspscape.shared.wire.codec import decode_as, encode
from graspscape.shared.wire.messages import ResultBatch
from sqlalchemy import select
from sqlalchemy.orm import Session

from tests.factories import fake_results, make_exploration

# Five held poses (by index in the tile): μs, static metrics, and the robustness report.
HELD: list[tuple[float, tuple[float | None, ...], dict[str, float | None] | None]] = [
    (0.9, (None, None, None), None),  # no metrics, no tests: last by any margin
    (0.5, (0.11, 0.021, 1.5), {"torque_margin_nm": 0.8, "torque_margin_ratio": 0.2,
                               "friction_margin": 0.3, "gravity_test_share": 0.5,
                               "force_test_share": 1.0, "tug_force_n": 12.5,
                               "shake_survival_s": 2.0}),
    (0.4, (0.12, 0.031, 2.5), {"torque_margin_ratio": 0.8, "friction_margin": 0.1}),
    (0.6, (0.13, 0.011, 0.5), {"torque_margin_ratio": 0.8, "friction_margin": 0.5}),
    (0.3, (None, None, None), {"torque_margin_ratio": None, "friction_margin": 0.05}),
]

SESSION_KEY = "5e55" * 8  # a worker session's key (any 32 hex digits)


def _results(poses: list[Any]) -> list[PoseResult]:
    """The tile's results: HELD for its first poses, the others never touched the object."""
    assert len(poses) >= len(HELD)
    out = []
    for i, base in enumerate(fake_results(poses, seed=3)):
        if i < len(HELD):
            mu_s, (mu_g, mu_f, mu_m), report = HELD[i]
            out.append(base.model_copy(update={
                "outcome": Outcome.HELD, "viable": True, "mu_s": mu_s,
                "mu_g": mu_g, "mu_f": mu_f, "mu_m": mu_m,
                "robustness": RobustnessReport(**report) if report is not None else None,
            }))
        else:
            out.append(base.model_copy(update={
                "outcome": Outcome.NO_CONTACT, "viable": False, "mu_s": 0.0,
                "signature": None, "grasp": None, "contacts_per_link": {}}))
    return out


def _expected(result: PoseResult) -> dict[str, float | None]:
    report = result.robustness.model_dump() if result.robustness is not None else {}
    static = {name: getattr(result, name) for name in GRASP_METRIC_COLUMNS}
    return {name: static.get(name, report.get(name)) for name in POSE_METRIC_COLUMNS}


@pytest.fixture
def stored(session: Session) -> tuple[int, list[PoseResult]]:
    """One tile's results sent as a worker does: encoded, decoded, then ingested."""
    eid = make_exploration(session)
    leased = lease_tiles(session, worker_id="w1", n=4, lease_seconds=60)
    tile = max(leased, key=lambda t: len(t.poses()))  # not a pole's three poses
    batch = ResultBatch(session_key=SESSION_KEY,
                        worker_id="w1", tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                        results=_results(tile.poses()))
    received = decode_as(encode(batch), ResultBatch)
    assert isinstance(received, ResultBatch) and received.results == batch.results
    ingest_results(session, tile_id=received.tile_id, lease_epoch=received.lease_epoch,
                   worker_id=received.worker_id, results=received.results)
    return eid, batch.results


def test_metrics_and_margins_are_stored_and_null_when_absent(
    session: Session, stored: tuple[int, list[PoseResult]]
) -> None:
    eid, results = stored
    session.expire_all()
    rows = {r.pose_key: r for r in session.scalars(
        select(PoseRow).where(PoseRow.exploration_id == eid))}
    for result in results:
        row = rows[result.pose_key]
        assert {name: getattr(row, name) for name in POSE_METRIC_COLUMNS} == _expected(result)
    assert rows[results[-1].pose_key].torque_margin_ratio is None  # not held: NULL everywhere


def test_a_batch_without_reports_stores_its_static_metrics(session: Session) -> None:
    # No report in the batch: the robustness columns are left out of the insert (NULL).
    make_exploration(session)
    (tile,) = lease_tiles(session, worker_id="w1", n=1, lease_seconds=60)
    results = [r.model_copy(update={"mu_g": 0.1 * i, "mu_f": None, "mu_m": 2.0})
               for i, r in enumerate(fake_results(tile.poses(), seed=5))]
    ingest_results(session, tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                   worker_id="w1", results=results)
    session.expire_all()
    rows = {r.pose_key: r for r in session.scalars(select(PoseRow))}
    assert len(rows) == len(results)
    for result in results:
        row = rows[result.pose_key]
        assert {name: getattr(row, name) for name in POSE_METRIC_COLUMNS} == _expected(result)
        assert (row.mu_g, row.mu_m, row.shake_survival_s) == (result.mu_g, 2.0, None)


def test_api_and_exports_serve_the_values(
    client: TestClient, stored: tuple[int, list[PoseResult]]
) -> None:
    eid, results = stored
    expected = {r.pose_key: _expected(r) for r in results}
    items = client.get(f"/explorations/{eid}/poses", params={"limit": 1000}).json()["items"]
    assert {p["pose_key"]: {n: p[n] for n in POSE_METRIC_COLUMNS} for p in items} == expected

    assert set(POSE_METRIC_COLUMNS) <= set(COLUMNS)
    response = client.get(f"/explorations/{eid}/export/poses.csv")
    assert response.status_code == 200
    rows = list(csv.DictReader(io.StringIO(response.text)))
    assert {r["pose_key"]: {n: float(r[n]) if r[n] else None for n in POSE_METRIC_COLUMNS}
            for r in rows} == expected

    response = client.get(f"/explorations/{eid}/export/poses.parquet")
    assert response.status_code == 200
    table = pq.read_table(io.BytesIO(response.content)).to_pylist()
    assert {r["pose_key"]: {n: r[n] for n in POSE_METRIC_COLUMNS} for r in table} == expected


def _best(client: TestClient, eid: int, **params: Any) -> list[dict[str, Any]]:
    response = client.get(f"/explorations/{eid}/best", params={"limit": 100, **params})
    assert response.status_code == 200, response.text
    return response.json()["poses"]


def test_best_ranks_by_the_chosen_metric_with_missing_values_last(
    client: TestClient, stored: tuple[int, list[PoseResult]]
) -> None:
    eid, results = stored
    key = [r.pose_key for r in results]

    def order(**params: Any) -> list[str]:
        return [p["pose_key"] for p in _best(client, eid, **params)]

    by_mu_s = [key[0], key[3], key[1], key[2], key[4]]
    assert order(rank="mu_s") == by_mu_s
    # Highest first; the tie at 0.8 by μs; no value (pose 0 despite its μs of 0.9) last.
    by_torque_margin = [key[3], key[2], key[1], key[0], key[4]]
    assert order(rank="torque_margin_ratio") == by_torque_margin
    assert best.DEFAULT_RANK == "torque_margin_ratio"
    assert order(rank="point") == by_torque_margin
    ratios = [p["torque_margin_ratio"] for p in _best(client, eid, rank="torque_margin_ratio")]
    assert ratios == [0.8, 0.8, 0.2, None, None]
    # Lower is better: the grasp that holds with the least friction first.
    assert order(rank="friction_margin") == [key[4], key[2], key[1], key[3], key[0]]
    assert order(rank="friction_margin", limit=2) == [key[4], key[2]]
    assert order(rank="mu_f") == [key[2], key[1], key[3], key[0], key[4]]
    assert order(rank="tug_force_n") == [key[1], key[0], key[3], key[2], key[4]]
    for rank in best.Rank:
        assert sorted(order(rank=rank.value)) == sorted(by_mu_s)


def test_best_refuses_an_unknown_rank(
    client: TestClient, stored: tuple[int, list[PoseResult]]
) -> None:
    eid, _ = stored
    response = client.get(f"/explorations/{eid}/best", params={"rank": "mu_x"})
    assert response.status_code == 422
    assert response.json()["detail"][0]["loc"] == ["query", "rank"]
