"""`worker --instant` on a tile of draws: a made-up draw shaped as a real one (outcome only, a
`sample` record per engine of the lease, under the lease's scales for that pose), so the store
ingests what real workers send; a full tile still gets made-up full results."""

from __future__ import annotations

import math
from datetime import UTC, datetime

from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import DrawScales, Outcome
from graspscape.shared.specs.sim import SimSettings
from graspscape.shared.wire.codec import decode_as, encode
from graspscape.shared.wire.messages import ObjectRef, ResultBatch, TileLease, TileSample
from graspscape.workers.runtime.config import WorkerConfig
from graspscape.workers.runtime.instant import instant_result
from graspscape.workers.runtime.process import WorkerProcess
from graspscape.workers.sim.samples import sample_result

SIDE = Pose(theta=1.5707963, phi=0.0, r=0.01)


def _fields(result) -> set[str]:  # type: ignore[no-untyped-def]
    return set(result.model_dump(exclude_defaults=True))


def test_an_instant_draw_is_shaped_as_a_real_one(tmp_path) -> None:
    scales = DrawScales(friction=0.8, mass=1.1)
    lease = TileSample(engines=["pybullet"], scales={SIDE.key(): scales})
    made_up = instant_result(SIDE, lease)
    real = sample_result(SIDE, obj=ObjectSpec(name="sphere"), gripper="robotiq_3f",
                         settings=SimSettings(), engines=["pybullet"], scales=scales,
                         cache_dir=tmp_path)
    assert _fields(made_up) - {"eval_time_s"} == _fields(real) - {"eval_time_s"}
    assert made_up.sample is not None and real.sample is not None
    assert made_up.sample.scales == scales and made_up.sample.absent == real.sample.absent
    assert list(made_up.sample.engines) == ["pybullet"]
    assert made_up.signature is None and made_up.mu_s == 0.0


def test_instant_draws_name_each_engine_and_default_scales() -> None:
    other = Pose(theta=1.0, phi=0.5, r=0.02)
    lease = TileSample(engines=["pybullet", "mujoco"], scales={SIDE.key(): DrawScales()})
    draw = instant_result(other, lease)
    assert draw.sample is not None and draw.sample.scales == DrawScales()
    assert [e.outcome for e in draw.sample.engines.values()] == [Outcome.HELD] * 2
    assert draw.outcome is Outcome.HELD and draw.viable


def test_a_full_tile_still_gets_full_made_up_results() -> None:
    full = instant_result(SIDE)
    assert full.sample is None and full.signature is not None and full.grasp is not None


def test_an_instant_worker_sends_draws_for_a_leased_tile_of_draws() -> None:
    tile = TileLease(
        tile_id=3, exploration_id=1, level=0, index=0, lease_epoch=1,
        lease_expires_at=datetime(2030, 1, 1, tzinfo=UTC),
        cells=[(math.pi / 2, 0.0), (math.pi / 2, 1.0)], r_levels=[0.01],
        attitudes=[(0.0, 0.0, 0.0)], object=ObjectRef(object_id=1, name="sphere"),
        gripper="robotiq_3f", settings=SimSettings(),
        sample=TileSample(engines=["pybullet", "mujoco"]))
    worker = WorkerProcess(WorkerConfig(name="t", procs=1, instant=True), 0)
    batch = worker._evaluate_tile(tile, tile.poses())
    assert batch is not None
    results = decode_as(encode(batch), ResultBatch).results
    assert len(results) == 2 and all(r.signature is None for r in results)
    assert all(r.sample is not None and set(r.sample.engines) == {"pybullet", "mujoco"}
               for r in results)
