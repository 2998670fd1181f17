"""The schema comes from the migrations, and the models do not drift from them."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from datetime import UTC, datetime

import psycopg
import pytest
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from graspscape.services.coordinator import db
from graspscape.services.coordinator.store.models import Base
from sqlalchemy import Engine, inspect

from tests.conftest import PG_URL


def test_schema_is_at_head(engine: Engine) -> None:
    assert db.current_revision(engine) == db.head_revision() is not None


def test_models_and_migrations_do_not_drift(engine: Engine) -> None:
    with engine.connect() as connection:
        context = MigrationContext.configure(connection, opts={"compare_type": True})
        diff = compare_metadata(context, Base.metadata)
    assert diff == []


def test_every_model_table_exists(engine: Engine) -> None:
    assert set(Base.metadata.tables) <= set(inspect(engine).get_table_names())


def test_downgrade_and_upgrade_round_trip(tmp_path) -> None:
    url = f"sqlite:///{tmp_path / 'rt.db'}"
    db.upgrade(url)
    from alembic import command

    command.downgrade(db.alembic_config(url), "base")
    engine = db.make_engine(url)
    assert set(inspect(engine).get_table_names()) <= {"alembic_version"}
    engine.dispose()
    db.upgrade(url)
    engine = db.make_engine(url)
    assert set(Base.metadata.tables) <= set(inspect(engine).get_table_names())
    engine.dispose()


def test_0006_gives_sqlite_autoincrement_and_keeps_every_row(tmp_path) -> None:
    """The rebuild of explorations and tiles (AUTOINCREMENT) on a database with data: with
    foreign keys enforced, dropping the old explorations table would have deleted every
    tile, pose and manifold by cascade."""
    from alembic import command
    from graspscape.services.coordinator.exploration.scheduler import ingest_results
    from graspscape.services.coordinator.exploration.service import create_exploration
    from graspscape.services.coordinator.objects.service import create_named
    from graspscape.services.coordinator.store.models import PoseRow
    from graspscape.services.coordinator.store.queue import lease_tiles
    from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec
    from sqlalchemy import inspect, text

    from tests.factories import fake_results

    url = f"sqlite:///{tmp_path / 'old.db'}"
    # The data is made by today's code, then the schema taken back to 0005 with it.
    db.upgrade(url)
    engine = db.make_engine(url)
    sessions = db.make_sessionmaker(engine)
    spec = {"grid": PoseGridSpec(dtheta=1.0, r_max=0.02)}
    with sessions() as session:
        object_id = create_named(session, name="sphere", properties={}, shared_dir=None)[0].id
        for _ in range(2):
            create_exploration(session, spec=ExplorationSpec(object_id=object_id, **spec),
                               tile_target_poses=10, max_poses=10**6)
        for t in lease_tiles(session, worker_id="w", n=4, lease_seconds=60):
            ingest_results(session, tile_id=t.tile_id, lease_epoch=t.lease_epoch,
                           worker_id="w", results=fake_results(t.poses()))

    def snapshot(pose_columns: list[str]) -> dict[str, object]:
        with engine.connect() as c:
            return {
                table: c.execute(text(f"SELECT {columns} FROM {table} ORDER BY id")).all()
                for table, columns in (
                    # the columns of 0005 (0008 adds the manifolds' refresh state)
                    ("explorations", "id, object_id, spec, status, tiles_total, poses_total, "
                                     "poses_done, viable_count, created_at, updated_at, "
                                     "started_at, finished_at"),
                    # the columns of 0005, as that schema has them (0009 adds `error`,
                    # 0010 the robust map's, later ones the qualities of pose_columns.py)
                    ("poses", ", ".join(pose_columns)),
                    ("objects", "*"),
                    # the columns of 0005 (0007 adds `round`)
                    ("tiles", 'id, exploration_id, level, "index", cells, r_levels, attitudes, '
                              "n_poses, state, lease_owner, lease_expires_at, lease_epoch, "
                              "attempts, last_error, updated_at, done_at"),
                )
            }

    engine.dispose()
    command.downgrade(db.alembic_config(url), "0005")
    engine = db.make_engine(url)
    at_0005 = [c["name"] for c in inspect(engine).get_columns("poses")]
    assert {"error", "robust_s", "certifies"}.isdisjoint(at_0005)
    assert set(at_0005) < {c.name for c in PoseRow.__table__.columns}
    before = snapshot(at_0005)
    assert before["poses"] and all(p.tile_id is not None for p in before["poses"])
    engine.dispose()
    db.upgrade(url)
    engine = db.make_engine(url)
    sessions = db.make_sessionmaker(engine)
    assert snapshot(at_0005) == before  # every row, id and reference kept
    with engine.connect() as c:
        for table in ("explorations", "tiles"):
            sql = c.execute(text("SELECT sql FROM sqlite_master WHERE name = :t"),
                            {"t": table}).scalar_one()
            assert "AUTOINCREMENT" in sql, sql
        assert c.execute(text("PRAGMA foreign_key_check")).all() == []
        assert c.execute(text("PRAGMA foreign_keys")).scalar_one() == 1
    with sessions() as session:  # the newest id is not handed out again
        from graspscape.services.coordinator.exploration.service import delete_exploration

        newest = max(row.id for row in before["explorations"])
        delete_exploration(session, exploration_id=newest)
        again = create_exploration(session, spec=ExplorationSpec(object_id=object_id, **spec),
                                   tile_target_poses=10, max_poses=10**6)
        assert again.id == newest + 1
    with engine.connect() as c:
        context = MigrationContext.configure(c, opts={"compare_type": True})
        assert compare_metadata(context, Base.metadata) == []
    engine.dispose()
    command.downgrade(db.alembic_config(url), "0005")
    engine = db.make_engine(url)
    with engine.connect() as c:
        sql = c.execute(text("SELECT sql FROM sqlite_master WHERE name = 'tiles'")).scalar_one()
        assert "AUTOINCREMENT" not in sql
        assert c.execute(text("SELECT count(*) FROM poses")).scalar_one() == len(before["poses"])
    engine.dispose()


@pytest.fixture(params=["sqlite", "postgresql"])
def empty_url(request: pytest.FixtureRequest, tmp_path) -> Iterator[str]:
    """A database with no schema yet (the test migrates it), on either backend."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'empty.db'}"
        return
    schema = f"gs_test_{uuid.uuid4().hex[:12]}"
    conninfo = PG_URL.replace("postgresql+psycopg://", "postgresql://")
    with psycopg.connect(conninfo, autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    try:
        yield f"{PG_URL}?options=-csearch_path%3D{schema}"
    finally:
        with psycopg.connect(conninfo, autocommit=True) as conn:
            conn.execute(f'DROP SCHEMA "{schema}" CASCADE')


def test_0007_stores_the_search_round_explicitly_and_back(empty_url: str) -> None:
    """Tiles of local search round k were stored at level 100 + k: 0007 gives them round k
    and the exploration's finest level, keeping every other tile; the downgrade restores
    the old levels. On both backends (the depth is read from the stored spec's JSON)."""
    from alembic import command
    from sqlalchemy import MetaData, insert, text

    db.upgrade(empty_url, "0006")
    engine = db.make_engine(empty_url)
    old = MetaData()
    old.reflect(engine)
    now = datetime(2026, 12, 1, tzinfo=UTC)
    levels = [(0, 0), (0, 1), (2, 0), (100, 0), (100, 1), (101, 0)]  # (level, index)
    with engine.begin() as c:
        c.execute(insert(old.tables["objects"]).values(
            id=1, kind="named", name="sphere", properties={}, created_at=now))
        c.execute(insert(old.tables["explorations"]).values(
            id=1, object_id=1, spec={"object_id": 1, "refinement": {"levels": 2}},
            status="running", tiles_total=6, poses_total=6, poses_done=0, viable_count=0,
            created_at=now, updated_at=now))
        c.execute(insert(old.tables["tiles"]), [
            {"exploration_id": 1, "level": level, "index": index, "cells": [], "r_levels": [],
             "attitudes": [], "n_poses": 0, "state": "queued", "lease_epoch": 0,
             "attempts": 0, "updated_at": now}
            for level, index in levels])
    engine.dispose()
    db.upgrade(empty_url)
    engine = db.make_engine(empty_url)
    with engine.connect() as c:
        assert c.execute(text('SELECT round, level, "index" FROM tiles ORDER BY id')).all() == [
            (0, 0, 0), (0, 0, 1), (0, 2, 0), (1, 2, 0), (1, 2, 1), (2, 2, 0)]
        context = MigrationContext.configure(c, opts={"compare_type": True})
        assert compare_metadata(context, Base.metadata) == []
        if engine.dialect.name == "sqlite":
            sql = c.execute(text("SELECT sql FROM sqlite_master WHERE name = 'tiles'")
                            ).scalar_one()
            assert "AUTOINCREMENT" in sql
    engine.dispose()
    command.downgrade(db.alembic_config(empty_url), "0006")
    engine = db.make_engine(empty_url)
    with engine.connect() as c:
        assert c.execute(text('SELECT level, "index" FROM tiles ORDER BY id')).all() == levels
    engine.dispose()


def test_0010_adds_the_robust_map_columns_and_back(empty_url: str) -> None:
    """0010 adds the robust map's columns (NULL, `large` false) to existing poses and
    manifolds, clears the exploration's refresh mark so that the next read recomputes them,
    and its downgrade drops them keeping every row. On both backends."""
    from alembic import command
    from sqlalchemy import MetaData, insert, text

    db.upgrade(empty_url, "0009")
    engine = db.make_engine(empty_url)
    old = MetaData()
    old.reflect(engine)
    now = datetime(2026, 12, 1, tzinfo=UTC)
    with engine.begin() as c:
        c.execute(insert(old.tables["objects"]).values(
            id=1, kind="named", name="sphere", properties={}, created_at=now))
        c.execute(insert(old.tables["explorations"]).values(
            id=1, object_id=1, spec={"object_id": 1}, status="done", tiles_total=1,
            poses_total=1, poses_done=1, viable_count=1, created_at=now, updated_at=now,
            manifolds_poses_done=1, manifolds_final=True))
        c.execute(insert(old.tables["manifolds"]).values(
            id=1, exploration_id=1, label=0, size=1, best_pose_key="k", best_mu_s=0.5,
            created_at=now))
        c.execute(insert(old.tables["poses"]).values(
            id=1, exploration_id=1, pose_key="k", theta=1.0, phi=0.0, r=0.0, roll=0.0,
            pitch=0.0, yaw=0.0, outcome="held", viable=True, mu_s=0.5, effort_max_nm=1.0,
            manifold_id=1, eval_time_s=0.1, created_at=now))
    engine.dispose()
    db.upgrade(empty_url, "0010")
    engine = db.make_engine(empty_url)
    with engine.connect() as c:
        assert c.execute(text(
            "SELECT pose_key, manifold_id, robust_s, robust_q, robust_label, certifies "
            "FROM poses")).all() == [("k", 1, None, None, None, None)]
        assert c.execute(text(
            "SELECT best_pose_key, core_volume_cm3, robust_best_key, robust_best_q, large "
            "FROM manifolds")).all() == [("k", None, None, None, False)]
        assert c.execute(text(
            "SELECT manifolds_poses_done, manifolds_final FROM explorations")).one() == (
            None, True)
        indexes = {i["name"] for i in inspect(c).get_indexes("poses")}
        assert "ix_poses_exploration_id_certifies" in indexes
    engine.dispose()
    command.downgrade(db.alembic_config(empty_url), "0009")
    engine = db.make_engine(empty_url)
    with engine.connect() as c:
        pose_cols = {col["name"] for col in inspect(c).get_columns("poses")}
        manifold_cols = {col["name"] for col in inspect(c).get_columns("manifolds")}
        assert not pose_cols & {"robust_s", "robust_q", "robust_label", "certifies"}
        assert not manifold_cols & {"core_volume_cm3", "robust_best_key", "robust_best_q",
                                    "large"}
        assert c.execute(text("SELECT pose_key, manifold_id FROM poses")).all() == [("k", 1)]
        assert c.execute(text("SELECT count(*) FROM manifolds")).scalar_one() == 1
    engine.dispose()
