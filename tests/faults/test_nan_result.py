"""A non-finite value in one pose of a real worker loop never hangs an exploration: with the
worker's check the pose is stored as `error` and the rest of the exploration is stored; a
worker without the check is stopped by the coordinator, which counts each refused batch as
an attempt and fails the tile at max_attempts (`incomplete`, the reason on /failures). Either
way it ends within twice the lease time, with one log line per refused batch."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.faults.nan_run import nan_run

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]


def test_a_nan_in_one_pose_is_stored_as_that_pose_s_error(tmp_path: Path) -> None:
    result = nan_run(tmp_path, checked=True)
    assert result["status"] == "done", result
    assert result["ended_s"] < 2 * result["lease_s"], result["timeline"]
    outcome = result["poisoned_outcome"]
    assert outcome["outcome"] == "error" and outcome["effort_max_nm"] == 0.0
    assert "non-finite result values: effort_max_nm=nan" in outcome["error"]
    tally = result["tally"]  # every planned pose stored once, the poisoned one as its error
    assert tally["stored_rows"] == tally["unique_keys"] == tally["planned"]
    assert tally["missing"] == tally["foreign"] == 0
    assert set(result["leases_per_tile"].values()) == {1}  # nothing went round
    assert result["refused_batches_in_log"] == 0 and result["coordinator_tracebacks"] == 0
    assert result["second_complete"], result["second_exploration"]


def test_a_nan_sent_by_a_worker_without_the_check_fails_its_tile_not_the_run(
    tmp_path: Path,
) -> None:
    result = nan_run(tmp_path, checked=False)
    assert result["status"] == "incomplete", result
    assert result["ended_s"] < 2 * result["lease_s"], result["timeline"]
    leases = result["leases_per_tile"]
    assert sorted(leases.values())[-1] == result["max_attempts"]  # the poisoned tile alone
    assert sum(n == result["max_attempts"] for n in leases.values()) == 1
    assert set(leases.values()) <= {1, result["max_attempts"]}
    (reason,) = result["failed_tiles_reasons"]
    assert "batch refused" in reason and "effort_max_nm" in reason
    # One line per refused batch, no traceback; the worker dropped each for good.
    assert result["refused_batches_in_log"] == result["max_attempts"]
    assert result["coordinator_tracebacks"] == 0
    assert result["worker_dropped_batches"] == result["max_attempts"]
    tally = result["tally"]  # every other pose stored once
    assert tally["foreign"] == 0 and tally["stored_rows"] == tally["unique_keys"]
    assert tally["missing"] == 3  # the failed tile's poses
    assert result["second_complete"], result["second_exploration"]
