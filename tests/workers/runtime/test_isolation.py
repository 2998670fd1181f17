"""A pose whose evaluation raises is reported with outcome `error` and its message, and the
tile goes on; a tile whose every pose raises is reported failed instead (the fault is the
tile's). Real worker loop code, instant evaluations, one injected fault."""

from __future__ import annotations

import math
from datetime import UTC, datetime

from graspscape.shared.specs.results import Outcome, nonfinite_fields
from graspscape.shared.specs.sim import SimSettings
from graspscape.shared.wire.codec import decode_as, encode
from graspscape.shared.wire.messages import ObjectRef, ResultBatch, TileLease
from graspscape.workers.runtime.config import WorkerConfig
from graspscape.workers.runtime.isolation import SYSTEMATIC_AFTER
from graspscape.workers.runtime.process import WorkerProcess


def _tile() -> TileLease:
    return TileLease(
        tile_id=3, exploration_id=1, level=0, index=0, lease_epoch=1,
        lease_expires_at=datetime(2030, 1, 1, tzinfo=UTC),
        cells=[(math.pi / 2, 0.0), (math.pi / 2, 1.0), (math.pi / 2, 2.0)],
        r_levels=[0.0, 0.01], attitudes=[(0.0, 0.0, 0.0)],
        object=ObjectRef(object_id=1, name="sphere"), gripper="robotiq_3f",
        settings=SimSettings(),
    )


def _worker(raises) -> tuple[WorkerProcess, list[ResultBatch]]:
    worker = WorkerProcess(WorkerConfig(name="t", procs=1, instant=True), 0)
    delivered: list[ResultBatch] = []
    worker._deliver = lambda batch: delivered.append(batch)  # type: ignore[method-assign]
    evaluate = worker._evaluate

    def faulty(tile, obj, pose, donors=None):  # type: ignore[no-untyped-def]
        if raises(pose):
            raise FloatingPointError(f"solver diverged at {pose.key()}")
        return evaluate(tile, obj, pose, donors)

    worker._evaluate = faulty  # type: ignore[method-assign]
    return worker, delivered


def test_one_failing_pose_is_stored_as_an_error_and_the_tile_completes() -> None:
    tile = _tile()
    bad = tile.poses()[2].key()
    worker, delivered = _worker(lambda pose: pose.key() == bad)
    batch = worker._evaluate_tile(tile, tile.poses())
    assert batch is not None and batch.final and not delivered
    assert [r.pose_key for r in batch.results] == [p.key() for p in tile.poses()]
    (error,) = [r for r in batch.results if r.outcome == Outcome.ERROR]
    assert error.pose_key == bad and not error.viable
    assert error.error == f"FloatingPointError: solver diverged at {bad}"
    assert all(r.outcome == Outcome.HELD for r in batch.results if r.pose_key != bad)


def test_a_tile_whose_every_pose_raises_is_reported_failed_with_the_reason() -> None:
    tile = _tile()
    worker, delivered = _worker(lambda pose: True)
    assert worker._evaluate_tile(tile, tile.poses()) is None
    (report,) = delivered
    assert report.results == [] and not report.final and not report.release
    assert report.error.startswith(f"the first {SYSTEMATIC_AFTER} poses all raised")
    assert "FloatingPointError: solver diverged" in report.error


def test_errors_after_a_good_start_stay_per_pose() -> None:
    tile = _tile()
    first = tile.poses()[0].key()
    worker, delivered = _worker(lambda pose: pose.key() != first)
    batch = worker._evaluate_tile(tile, tile.poses())
    assert batch is not None and batch.final and not delivered
    assert sum(r.outcome == Outcome.ERROR for r in batch.results) == len(tile.poses()) - 1


def test_a_result_with_a_non_finite_number_is_sent_as_that_pose_s_error() -> None:
    # A blown-up simulation returns NaN or ∞ somewhere in a result built without validation
    # (model_copy): the pose goes out as `error` naming the values, the rest as they were.
    tile = _tile()
    bad = tile.poses()[1].key()
    worker, delivered = _worker(lambda pose: False)
    evaluate = worker._evaluate

    def blown_up(tile, obj, pose, donors=None):  # type: ignore[no-untyped-def]
        result = evaluate(tile, obj, pose, donors)
        if pose.key() != bad:
            return result
        joints = {**result.grasp.joint_angles, "joint_1": float("inf")}
        return result.model_copy(update={
            "effort_max_nm": float("nan"),
            "grasp": result.grasp.model_copy(update={"joint_angles": joints})})

    worker._evaluate = blown_up  # type: ignore[method-assign]
    batch = worker._evaluate_tile(tile, tile.poses())
    assert batch is not None and batch.final and not delivered
    (error,) = [r for r in batch.results if r.outcome == Outcome.ERROR]
    assert error.pose_key == bad and not error.viable and error.grasp is None
    assert error.error == ("ValueError: non-finite result values: effort_max_nm=nan, "
                           "grasp.joint_angles.joint_1=inf")
    # Every number of the batch is finite now: it encodes without a `null`, and decodes.
    assert not nonfinite_fields(batch)
    assert isinstance(decode_as(encode(batch), ResultBatch), ResultBatch)
