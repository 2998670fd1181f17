"""A tile whose poses cannot be expanded (a cell out of Pose's range, as the south pole at
π + 1 ulp once was) is reported failed with the reason; the process goes on. Before, the
process crashed, the tile came back "lost" three times and failed with no word of why."""

from __future__ import annotations

import math
from datetime import UTC, datetime

from graspscape.shared.specs.sim import SimSettings
from graspscape.shared.wire.messages import ObjectRef, ResultBatch, TileLease
from graspscape.workers.runtime.config import WorkerConfig
from graspscape.workers.runtime.process import WorkerProcess


def test_a_tile_beyond_the_pole_is_reported_failed_not_a_crash() -> None:
    tile = TileLease(
        tile_id=7, exploration_id=1, level=0, index=12, lease_epoch=2,
        lease_expires_at=datetime(2030, 1, 1, tzinfo=UTC),
        cells=[(math.nextafter(math.pi, 4.0), 0.0)], r_levels=[0.01],
        attitudes=[(0.0, 0.0, 0.0)], object=ObjectRef(object_id=1, name="sphere"),
        gripper="robotiq_3f", settings=SimSettings(),
    )
    worker = WorkerProcess(WorkerConfig(name="t", procs=1, instant=True), 0)
    delivered: list[ResultBatch] = []
    worker._deliver = lambda batch: delivered.append(batch)  # type: ignore[method-assign]
    worker._work(tile)
    (report,) = delivered
    assert (report.tile_id, report.lease_epoch, report.results) == (7, 2, [])
    assert not report.final and not report.release
    assert report.error.startswith("the tile's poses are invalid:")
    assert "theta" in report.error
    assert worker.pending is None and worker.tiles_done == 0
