"""The ppo strategy: through the real store (SQLite and PostgreSQL) with the oracle as the
evaluator, it is seeded and repeatable, spends its budget in rollouts of `batch` poses and
finds held grasps; it learns (slow); resuming equals replaying; its reward is the paper's;
without the optional extra a submission is refused saying how to install it. Its gymnasium
environment runs under stable-baselines3's own `learn`."""

from __future__ import annotations

import importlib.util
import math
import sys

import numpy as np
import pytest
from graspscape.services.coordinator.errors import InvalidInput
from graspscape.services.coordinator.exploration.strategies.ppo import PpoStrategy, rollout
from graspscape.services.coordinator.exploration.strategies.ppo_env import (
    action_pose,
    make_env,
    reward,
)
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow, TileRow
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy import select

from tests.factories import explore_with_oracle, oracle_result

GRID = {"dtheta": math.radians(45), "r_min": 0.005, "r_max": 0.02, "dr": 0.005,
        "attitudes": {"rolls": 4}}
ORACLE_BEST_MU_S = 0.8  # test_cmaes.py: θ → 0, φ = π/2, r ≤ 0.012

# Tests that run PPO need the optional extra `rl` (CI installs it: .ci/run).
needs_rl = pytest.mark.skipif(
    any(importlib.util.find_spec(m) is None
        for m in ("torch", "stable_baselines3", "gymnasium")),
    reason="the optional extra rl is not installed (README, 'Set up')")


def _spec(object_id: int, **strategy) -> ExplorationSpec:
    return ExplorationSpec(object_id=object_id, grid=GRID, strategy={"name": "ppo", **strategy})


def _rows(sessions, eid: int) -> list[PoseRow]:
    with sessions() as s:
        return list(s.scalars(select(PoseRow).where(PoseRow.exploration_id == eid)))


# SQLite only (the store is the same code on both; the physics test of every explorer runs on
# both databases). Slow: importing torch and stable-baselines3 alone costs 4-5 s of CPU, the
# default run's whole allowance; the default run keeps the tests below that need neither.
@needs_rl
@pytest.mark.slow
@pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)
def test_ppo_is_seeded_repeatable_in_rollouts_and_finds_held_grasps(sessions,
                                                                    named_object) -> None:
    object_id = named_object("sphere")
    spec = _spec(object_id, poses=40, seed=3, batch=16, epochs=2, objective="mu_s")
    eid, evaluated, stored = explore_with_oracle(sessions, spec)
    assert len(stored) == len(evaluated) == 40  # each pose once, the budget spent exactly
    rows = _rows(sessions, eid)
    assert any(r.viable for r in rows)
    for row in rows:
        assert GRID["r_min"] <= row.r <= GRID["r_max"] and row.pitch == row.yaw == 0.0
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        assert (row.status, row.poses_done, row.poses_total) == ("done", 40, 40)
        per_round: dict[int, int] = {}
        for pose_row in rows:
            k = s.get(TileRow, pose_row.tile_id).round
            per_round[k] = per_round.get(k, 0) + 1
    # Two rollouts of 16, trained on; the third cut to the 8 poses left of the budget.
    assert per_round == {0: 16, 1: 16, 2: 8}
    # The same seed through other interleavings gives the same run.
    _, _, again = explore_with_oracle(sessions, spec, workers=3, seed=9)
    assert again == stored
    # Another seed samples other poses from the start.
    other = _spec(object_id, poses=40, seed=4, batch=16, epochs=2, objective="mu_s")
    _, first = rollout(other, 0, lambda key: 0.0)
    assert {p.key() for p in first}.isdisjoint(stored)


@needs_rl
@pytest.mark.slow  # torch's import alone is seconds
def test_resuming_the_kept_search_equals_replaying_from_the_seed() -> None:
    spec = ExplorationSpec(object_id=1, grid=GRID,
                           strategy={"name": "ppo", "poses": 10_000, "seed": 4, "batch": 4,
                                     "epochs": 1})
    rng = np.random.default_rng(0)
    stored: dict[str, float] = {}
    for g in range(3):
        k, poses = rollout(spec, g, lambda key: stored.get(key, 0.0), cache_key="t")
        fresh = rollout(spec, g, lambda key: stored.get(key, 0.0))
        assert (k, [p.key() for p in poses]) == (fresh[0], [p.key() for p in fresh[1]])
        stored.update((p.key(), float(rng.uniform())) for p in poses)
    # A stored reward other than the one the kept search was told: replayed, not resumed.
    stored[next(iter(stored))] += 0.5
    _, poses = rollout(spec, 3, lambda key: stored.get(key, 0.0), cache_key="t")
    _, fresh = rollout(spec, 3, lambda key: stored.get(key, 0.0))
    assert [p.key() for p in poses] == [p.key() for p in fresh]


def test_reward_is_quality_less_weighted_effort_and_zero_without_a_grasp() -> None:
    assert reward(True, 0.8, 2.0, w_s=1.0, w_f=0.05) == pytest.approx(0.7)
    assert reward(False, 0.8, 2.0, w_s=1.0, w_f=0.05) == 0.0
    assert reward(True, 0.5, None, w_s=2.0, w_f=1.0) == pytest.approx(1.0)


def test_action_zero_is_the_middle_of_the_r_range_and_the_roll_turn() -> None:
    spec = ExplorationSpec(object_id=1, grid=GRID, strategy={"name": "ppo"})
    pose = action_pose(np.array([0.0, 0.0, 1.0, 0.0, 0.0]), spec)
    assert pose.theta == pytest.approx(0.0) and pose.r == pytest.approx(0.0125)
    assert pose.roll == pytest.approx(math.pi)
    low = action_pose(np.array([0.0, 0.0, -1.0, -1.0, -1.0]), spec)
    assert low.theta == pytest.approx(math.pi) and low.r == pytest.approx(0.005)


def test_without_the_rl_extra_a_submission_is_refused_saying_how_to_install(monkeypatch
                                                                            ) -> None:
    # An entry of None in sys.modules makes `import stable_baselines3` raise ImportError, as
    # in an environment without the extra.
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)
    spec = ExplorationSpec(object_id=1, grid=GRID, strategy={"name": "ppo"})
    with pytest.raises(InvalidInput, match=r"pip install -e '\.\[rl\]'") as refused:
        PpoStrategy(spec)
    assert refused.value.loc == ("body", "strategy")
    assert "download.pytorch.org/whl/cpu" in refused.value.message


@needs_rl
@pytest.mark.slow  # a whole search to its budget, on both databases
def test_ppo_learns_towards_the_oracles_best(sessions, named_object) -> None:
    spec = _spec(named_object("sphere"), poses=384, seed=0, batch=32, objective="mu_s",
                 w_f=0.0)
    eid, _, _ = explore_with_oracle(sessions, spec)
    rows = _rows(sessions, eid)
    best = max(rows, key=lambda r: r.mu_s if r.viable else 0.0)
    assert best.viable and 0.9 * ORACLE_BEST_MU_S <= best.mu_s <= ORACLE_BEST_MU_S
    # It learns: the last rollouts are better on average than the first ones.
    ordered = sorted(rows, key=lambda r: r.tile_id)
    q = [r.mu_s if r.viable else 0.0 for r in ordered]
    assert np.mean(q[-96:]) > np.mean(q[:96]) + 0.05


@needs_rl
@pytest.mark.slow  # stable-baselines3's own training loop, 20 rollouts
def test_the_environment_runs_under_stable_baselines3_learn() -> None:
    import torch
    from stable_baselines3 import PPO

    # One thread, as the strategy runs it: on a loaded machine torch's thread pool spins.
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    spec = ExplorationSpec(object_id=1, grid=GRID, strategy={"name": "ppo"})

    def evaluate(pose):
        result = oracle_result(pose)
        return result.viable, result.mu_s, result.effort_max_nm

    env = make_env(spec, evaluate, w_s=1.0, w_f=0.0)
    model = PPO("MlpPolicy", env, n_steps=32, batch_size=8, learning_rate=3e-3, seed=0,
                device="cpu", policy_kwargs={"net_arch": [32]})
    try:
        model.learn(total_timesteps=640)
    finally:
        torch.set_num_threads(threads)
    rewards = [reward(*evaluate(p), w_s=1.0, w_f=0.0) for p in env.unwrapped.poses]
    assert len(rewards) == 640
    assert np.mean(rewards[-160:]) > np.mean(rewards[:160])
