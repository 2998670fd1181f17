"""Refreshes that write only what changed (manifolds/live.py) leave the store as a whole
rewrite does: manifold rows, each pose's manifold and robust score, on both databases; and
the running map notices a store it did not write."""

from __future__ import annotations

import math

from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds import service
from graspscape.services.coordinator.store.models import ExplorationRow, ManifoldRow, PoseRow
from graspscape.services.coordinator.store.queue import lease_tiles
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy import select

from tests.factories import oracle_result


def stored(s, eid: int) -> tuple:  # type: ignore[no-untyped-def]
    labels = dict(s.execute(select(ManifoldRow.id, ManifoldRow.label)
                            .where(ManifoldRow.exploration_id == eid)).all())
    rows = s.execute(select(ManifoldRow.label, ManifoldRow.size, ManifoldRow.best_pose_key,
                            ManifoldRow.summary, ManifoldRow.volume_cm3, ManifoldRow.large,
                            ManifoldRow.robust_best_key, ManifoldRow.signature)
                     .where(ManifoldRow.exploration_id == eid)
                     .order_by(ManifoldRow.label)).all()
    poses = s.execute(select(PoseRow.pose_key, PoseRow.manifold_id, PoseRow.robust_s,
                             PoseRow.robust_q, PoseRow.robust_label)
                      .where(PoseRow.exploration_id == eid).order_by(PoseRow.pose_key)).all()
    return ([tuple(r) for r in rows],
            [(k, labels.get(m), rs, rq, rl) for k, m, rs, rq, rl in poses])


def test_refreshes_tile_by_tile_store_the_whole_rewrite(sessions, named_object) -> None:
    spec = ExplorationSpec(object_id=named_object("sphere"), gripper="robotiq_3f",
                           strategy={"name": "grid"}, refinement={"levels": 0},
                           grid={"dtheta": math.radians(45), "r_min": 0.0, "r_max": 0.02,
                                 "dr": 0.01, "attitudes": {"rolls": 2}})
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=16, max_poses=10**6).id
        tiles = []
        while leased := lease_tiles(s, worker_id="w", n=50, lease_seconds=60):
            tiles += leased
        assert len(tiles) >= 8
        for n, t in enumerate(tiles):
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
            if n % 3 == 0:
                s.commit()
                continue  # some tiles arrive between refreshes
            if n % 4 == 0:
                service.compute_map(s, eid)  # computed, written by the next refresh
            service.refresh_manifolds(s, eid)
            s.commit()
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        incremental = stored(s, eid)
        service.MAPS.clear()  # a restarted process: read everything, write it whole
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        assert stored(s, eid) == incremental
        assert len(incremental[0]) >= 2 and all(p[4] is not None for p in incremental[1])


def test_a_table_written_by_another_process_is_written_whole(sessions, named_object) -> None:
    spec = ExplorationSpec(object_id=named_object("sphere"), gripper="robotiq_3f",
                           strategy={"name": "grid"}, refinement={"levels": 0},
                           grid={"dtheta": math.radians(45), "r_min": 0.0, "r_max": 0.01,
                                 "dr": 0.01})
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=10, max_poses=10**6).id
        tiles = lease_tiles(s, worker_id="w", n=50, lease_seconds=60)
        for t in tiles[:-1]:
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
        service.refresh_manifolds(s, eid)
        s.commit()
        # Someone else emptied the table (a migration, another coordinator).
        s.execute(ManifoldRow.__table__.delete().where(ManifoldRow.exploration_id == eid))
        s.get(ExplorationRow, eid).manifolds_poses_done = None
        s.commit()
        t = tiles[-1]
        ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                       results=[oracle_result(p) for p in t.poses()])
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        after = stored(s, eid)
        service.MAPS.clear()
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        assert stored(s, eid) == after
        assert all(m is not None for k, m, *_ in after[1]
                   if s.scalar(select(PoseRow.viable).where(PoseRow.pose_key == k,
                                                            PoseRow.exploration_id == eid)))
