"""/manifolds and /manifolds/{label} copy the stored summaries' text into their answer (no
decoding on the read path, issue 21): the same documents as the summaries decoded and
validated, on both databases; migration 0012 fills the volume column of existing rows."""

from __future__ import annotations

import json
import math
from collections.abc import Hashable

from graspscape.services.coordinator import db
from graspscape.services.coordinator.api import answers
from graspscape.services.coordinator.api.manifolds import BestOut, ManifoldList
from graspscape.services.coordinator.api.pages import CursorPage
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.exploration.schemas import PoseOut
from graspscape.services.coordinator.manifolds.grouping import label_name
from graspscape.services.coordinator.manifolds.service import ensure_manifolds
from graspscape.services.coordinator.manifolds.summary import ManifoldSummary
from graspscape.services.coordinator.manifolds.table import table_document
from graspscape.services.coordinator.state import Bounded, of
from graspscape.services.coordinator.store.models import ExplorationRow, ManifoldRow
from graspscape.services.coordinator.store.queue import lease_tiles
from pydantic import TypeAdapter
from sqlalchemy import create_engine, select, text

from tests.factories import oracle_result

GRID = {"dtheta": math.radians(30), "r_min": 0.0, "r_max": 0.02, "dr": 0.01,
        "attitudes": {"rolls": 2}}


def test_manifold_reads_are_the_stored_summaries(client, object_id, sessions) -> None:
    """One exploration (the default suite's budget) for: the answers kept per map version
    (`_kept_per_version`), /best's evidence samples (`_evidence_samples`), and the lists."""
    eid = _kept_per_version(client, object_id, sessions)
    _evidence_samples(sessions, eid)
    listed = client.get(f"/explorations/{eid}/manifolds")
    assert listed.status_code == 200 and listed.headers["content-type"] == "application/json"
    got = ManifoldList.model_validate(listed.json())
    with sessions() as s:
        # The last manifold made dust, in its row and its summary: the dust line is written
        # from the columns, and must be what the summaries say.
        row = s.scalars(select(ManifoldRow).where(ManifoldRow.exploration_id == eid)
                        .order_by(ManifoldRow.label.desc())).first()
        row.large = False
        row.summary = {**row.summary, "large": False}
        s.commit()
        document = table_document(s, eid)
        expected = ManifoldList.model_validate({k: v for k, v in document.items() if k != "table"})
    # Edited by hand, behind the map's version (every real write moves it): the answers kept
    # for the version are the unedited ones, so forget them (api/answers.py).
    answers.clear(of(client.app))
    assert len(got.manifolds) >= 2 and got.final
    listed = client.get(f"/explorations/{eid}/manifolds").json()
    assert listed == json.loads(expected.model_dump_json())
    assert listed["dust"]["manifolds"] == 1
    for m in expected.manifolds:
        one = client.get(f"/explorations/{eid}/manifolds/{label_name(m.label)}")
        assert one.status_code == 200
        assert ManifoldSummary.model_validate(one.json()) == m
    assert client.get(f"/explorations/{eid}/manifolds/ZZ").status_code == 404
    assert client.get("/explorations/999999/manifolds").status_code == 404
    assert client.get("/explorations/999999/manifolds/A").status_code == 404


def _kept_per_version(client, object_id, sessions) -> int:  # type: ignore[no-untyped-def]
    """/best, /manifolds and /manifolds/A are kept per map version (api/answers.py): the
    same bytes while no pose arrives, the new map's answer once results are ingested (the
    version moves with them), and a kept answer is what computing it again gives. Returns the
    exploration, every tile ingested."""
    eid = client.post("/explorations", json={
        "object_id": object_id, "gripper": "robotiq_3f", "grid": GRID,
        "strategy": {"name": "grid"}, "refinement": {"levels": 0}}).json()["id"]
    paths = [f"/explorations/{eid}/best?limit=3&rank=mu_s", f"/explorations/{eid}/manifolds",
             f"/explorations/{eid}/manifolds/A"]

    def read() -> list[bytes]:
        answered = [client.get(p) for p in paths]
        assert [r.status_code for r in answered] == [200, 200, 200]
        return [r.content for r in answered]

    with sessions() as s:
        tiles = lease_tiles(s, worker_id="w", n=1000, lease_seconds=60)
        assert len(tiles) >= 2
        half = len(tiles) // 2
        for t in tiles[:half]:
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
        # Fewer poses than the keeper's REFRESH_MIN_POSES: the running table is refreshed by
        # a writer here (reads serve what is stored, never refresh).
        assert s.get(ExplorationRow, eid).manifolds_poses_done is None
        ensure_manifolds(s, eid)
    first = read()
    # Written as FastAPI writes the response model (what the routes answered before they
    # returned bytes): validated and dumped again, the same bytes.
    adapter = TypeAdapter(BestOut)
    assert adapter.dump_json(adapter.validate_json(first[0])) == first[0]
    page = client.get(f"/explorations/{eid}/poses", params={"limit": 5}).content
    pages = TypeAdapter(CursorPage[PoseOut])
    assert pages.dump_json(pages.validate_json(page)) == page
    assert read() == first  # kept
    answers.clear(of(client.app))
    assert read() == first  # and what computing it again gives
    with sessions() as s:
        for t in tiles[half:]:
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
    after = read()
    listed = [json.loads(after[1]), json.loads(first[1])]
    assert listed[0]["final"] and not listed[1]["final"]
    assert (sum(m["pose_count"] for m in listed[0]["manifolds"])
            > sum(m["pose_count"] for m in listed[1]["manifolds"]))
    answers.clear(of(client.app))
    assert read() == after
    return eid


def test_migration_0012_fills_the_volume_from_the_summary(tmp_path) -> None:
    url = f"sqlite:///{tmp_path / 'm.db'}"
    db.upgrade(url, "0011")
    engine = create_engine(url)
    with engine.begin() as c:
        c.execute(text("INSERT INTO objects (id, kind, name, properties, created_at) "
                       "VALUES (1, 'named', 'sphere', '{}', '2026-01-01')"))
        c.execute(text("INSERT INTO explorations (id, object_id, spec, status, tiles_total, "
                       "poses_total, poses_done, viable_count, created_at, updated_at) VALUES "
                       "(1, 1, '{}', 'done', 0, 0, 0, 0, '2026-01-01', '2026-01-01')"))
        c.execute(text("INSERT INTO manifolds (id, exploration_id, label, size, summary, "
                       "created_at) VALUES (1, 1, 0, 3, '{\"volume_cm3\": 12.5}', "
                       "'2026-01-01')"))
    db.upgrade(url, "head")
    with engine.begin() as c:
        assert c.execute(text("SELECT volume_cm3 FROM manifolds")).scalar() == 12.5
    engine.dispose()


def _evidence_samples(sessions, eid: int) -> None:  # type: ignore[no-untyped-def]
    """/best's evidence reads its neighbourhoods by key (manifolds/best._samples_by_key): the
    samples load_samples finds for those points, the grasp left out."""
    import dataclasses

    from graspscape.services.coordinator.exploration.samples import lattice_of, load_samples
    from graspscape.services.coordinator.exploration.specs import spec_of
    from graspscape.services.coordinator.manifolds.best import _samples_by_key
    from graspscape.services.coordinator.store.models import ExplorationRow

    with sessions() as s:
        lattice = lattice_of(spec_of(s.get(ExplorationRow, eid)))
        every = load_samples(s, eid, lattice)
        assert len(every) > 20 and any(x.grasp for x in every.values())
        points = sorted(every)[::3]
        by_key = _samples_by_key(s, eid, {lattice.pose(p).key(): p for p in points})
    assert by_key == {p: dataclasses.replace(every[p], grasp=None) for p in points}


def test_kept_answers_are_bounded_by_count_and_bytes() -> None:
    """Least recently used out, beyond the state's count or bytes (state.Bounded); an answer
    is computed once while kept."""
    kept: Bounded[Hashable, bytes] = Bounded(3, max_bytes=100, size=len)
    calls: list[int] = []

    def body(i: int, size: int = 30) -> bytes:
        calls.append(i)
        return bytes([i]) * size

    for i in range(4):
        assert answers.answer(i, lambda i=i: body(i), kept) == bytes([i]) * 30
    assert answers.answer(3, lambda: body(99), kept) == bytes([3]) * 30  # kept: not computed
    assert calls == [0, 1, 2, 3]
    assert answers.answer(0, lambda: body(0), kept) and calls[-1] == 0  # out by count
    assert answers.answer(9, lambda: body(9, 90), kept) == bytes([9]) * 90  # answered, alone
    assert answers.answer(3, lambda: body(3), kept) and calls[-1] == 3  # out by bytes
    assert len(kept) == 1
