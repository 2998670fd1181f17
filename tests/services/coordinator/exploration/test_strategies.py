"""The exploration strategies through the real store (SQLite and PostgreSQL): the grid stores
exactly the dense grid, the random sample is seeded, in range and within its budget, and the
adaptive strategy stays the default. Evaluations come from the oracle: these tests are about
decisions, not physics."""

from __future__ import annotations

import math

import pytest
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.exploration.strategies.random import random_poses
from graspscape.services.coordinator.store.models import (
    ExplorationRow,
    PosePlanRow,
    TileRow,
)
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy import func, select

from tests.factories import explore_with_oracle

GRID = {"dtheta": math.radians(45), "r_min": 0.0, "r_max": 0.02, "dr": 0.01,
        "attitudes": {"rolls": 2}}
# A smaller one where the number of rolls does not matter (the default-strategy check runs
# two whole adaptive explorations).
SMALL_GRID = {**GRID, "dtheta": math.radians(60), "attitudes": {"rolls": 1}}


def _spec(object_id: int, strategy: dict | None = None, levels: int = 1,
          grid: dict = GRID) -> ExplorationSpec:
    extra = {} if strategy is None else {"strategy": strategy}
    return ExplorationSpec(object_id=object_id, grid=grid, refinement={"levels": levels},
                           **extra)


def _explore(sessions, spec: ExplorationSpec) -> tuple[int, list[str], list[str]]:
    return explore_with_oracle(sessions, spec)


def test_grid_stores_exactly_the_dense_grid(sessions, named_object) -> None:
    spec = _spec(named_object("sphere"), {"name": "grid"}, levels=1)
    eid, evaluated, stored = _explore(sessions, spec)
    lattice = Lattice(spec.grid.model_copy(update={"azimuth_multiple": 1}), 1)
    dense = sorted(
        lattice.pose(Point(K, J, i, a)).key()
        for K, J in lattice.cells(1)
        for i in range(lattice.n_r * 2 + 1)
        for a in range(len(lattice.attitudes))
    )
    assert stored == dense
    assert sorted(evaluated) == dense  # each pose once, nothing inferred
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        assert (row.status, row.poses_done, row.poses_total) == ("done", len(dense), len(dense))
        assert not s.scalar(select(func.count()).select_from(PosePlanRow)
                            .where(PosePlanRow.exploration_id == eid))


@pytest.mark.parametrize("rounds", [1, 3])
def test_random_is_seeded_in_range_and_within_its_budget(sessions, named_object,
                                                         rounds: int) -> None:
    object_id = named_object("sphere")
    strategy = {"name": "random", "poses": 250, "seed": 7, "rounds": rounds}
    eid, evaluated, stored = _explore(sessions, _spec(object_id, strategy, levels=0))
    spec = _spec(object_id, strategy, levels=0)
    sample = random_poses(spec, spec.strategy)
    assert len(stored) == len(evaluated) == 250
    assert stored == sorted(p.key() for p in sample)
    attitudes = {tuple(round(x, 9) for x in a) for a in spec.grid.attitudes.attitudes()}
    for pose in sample:
        assert 0.0 <= pose.theta <= math.pi and 0.0 <= pose.phi < 2 * math.pi
        assert spec.grid.r_min <= pose.r <= spec.grid.r_max
        assert tuple(round(x, 9) for x in (pose.roll, pose.pitch, pose.yaw)) in attitudes
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        assert (row.status, row.poses_done, row.poses_total) == ("done", 250, 250)
        assert sorted(set(s.scalars(select(TileRow.round)
                                    .where(TileRow.exploration_id == eid)))) == list(range(rounds))
    # The same seed draws the same sample again, another seed another one.
    again = random_poses(spec, spec.strategy)
    assert [p.key() for p in again] == [p.key() for p in sample]
    other = spec.strategy.model_copy(update={"seed": 8})
    assert {p.key() for p in random_poses(spec, other)}.isdisjoint(stored)


@pytest.mark.slow  # two whole adaptive explorations per database
def test_adaptive_is_the_default_and_old_specs_parse_as_adaptive(sessions, named_object) -> None:
    object_id = named_object("sphere")
    spec = _spec(object_id, levels=1, grid=SMALL_GRID)
    assert spec.strategy.name == "adaptive"
    stored = spec.model_dump(mode="json")
    stored.pop("strategy")  # a spec stored before strategies existed
    assert ExplorationSpec.model_validate(stored) == spec
    _, evaluated_default, default = _explore(sessions, spec)
    _, evaluated_named, named = _explore(sessions, _spec(object_id, {"name": "adaptive"}, 1,
                                                                SMALL_GRID))
    assert default == named and sorted(evaluated_default) == sorted(evaluated_named)
