"""Every baseline explorer (random, cmaes, ppo) on the real sphere in pybullet, through the
store: with a small budget it finds a held grasp, and it is repeatable with its seed (the
same stored poses and outcomes through another interleaving of workers)."""

from __future__ import annotations

import importlib.util
import math
from concurrent.futures import ProcessPoolExecutor

import pytest
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.store.models import PoseRow
from graspscape.services.local.run import pybullet_evaluator, run_local
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.objects import ObjectSpec
from sqlalchemy import select

GRID = {"dtheta": math.radians(45), "r_min": 0.005, "r_max": 0.02, "dr": 0.005}
BUDGET = 24

_RL = all(importlib.util.find_spec(m) is not None
          for m in ("torch", "stable_baselines3", "gymnasium"))


def _explore(sessions, spec: ExplorationSpec, evaluate, workers: int, seed: int
             ) -> list[tuple[str, str, bool]]:
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=8, max_poses=10**6).id
    run_local(sessions, evaluate, workers=workers, seed=seed, split=2)
    with sessions() as s:
        rows = s.execute(select(PoseRow.pose_key, PoseRow.outcome, PoseRow.viable)
                         .where(PoseRow.exploration_id == eid))
        return sorted(tuple(row) for row in rows)


@pytest.mark.slow  # two physics explorations of 24 poses per explorer and database
@pytest.mark.parametrize("strategy", [
    {"name": "random", "poses": BUDGET, "seed": 1, "rounds": 3},
    {"name": "cmaes", "poses": BUDGET, "seed": 1, "popsize": 8},
    pytest.param({"name": "ppo", "poses": BUDGET, "seed": 1, "batch": 8},
                 marks=pytest.mark.skipif(not _RL, reason="the optional extra rl is missing")),
])
def test_explorer_finds_a_held_grasp_on_the_sphere_and_repeats_with_its_seed(
        sessions, named_object, strategy: dict) -> None:
    spec = ExplorationSpec(object_id=named_object("sphere"), grid=GRID, strategy=strategy)
    # The cache only saves simulating a pose twice: an evaluation is a pure function of the
    # pose, object, gripper and settings (tests/workers/sim check that).
    cache: dict = {}
    with ProcessPoolExecutor(2) as pool:
        evaluate = pybullet_evaluator(ObjectSpec(name="sphere"), pool=pool, cache=cache)
        first = _explore(sessions, spec, evaluate, workers=2, seed=1)
        again = _explore(sessions, spec, evaluate, workers=3, seed=7)
    assert len(first) == BUDGET
    held = [row for row in first if row[2]]
    assert held, "no held grasp in the budget"
    assert all(outcome == "held" for _, outcome, _ in held)
    assert again == first
