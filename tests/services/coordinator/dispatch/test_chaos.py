"""Chaos as a test: during one exploration the coordinator is killed -9 three times and the
workers five times (a simulation process, or the whole `graspscape worker`), on SQLite and
on PostgreSQL; each comes back, and the exploration ends `done` with every planned pose
stored exactly once and the counters agreeing (tests/services/coordinator/dispatch/chaos.py).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sqlalchemy.orm import Session, sessionmaker

from tests.services.coordinator.dispatch.chaos import PLAN, chaos

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]


def test_coordinator_and_workers_killed_several_times_each_lose_and_double_nothing(
    any_url: str, any_sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    result = chaos(any_url, any_sessions, tmp_path)
    print("chaos:", json.dumps({key: result[key] for key in ("status", "elapsed_s", "kills")}
                               | {"tally": result["tally"]}))  # shown with -s
    assert [kill["what"] for kill in result["kills"]] == list(PLAN), result["kills"]
    assert PLAN.count("coordinator") >= 3 and len(PLAN) - PLAN.count("coordinator") >= 5
    tally = result["tally"]
    assert result["complete"], result
    assert tally["stored_rows"] == tally["unique_keys"] == tally["planned"] > 300
    assert tally["tile_states"] == {"done": tally["tile_states"]["done"]}
