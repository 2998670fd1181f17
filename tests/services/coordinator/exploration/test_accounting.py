"""The budget accounting: the known figures of hand-made rows, and the same counting for
every explorer through the real store and `GET /explorations/{id}/budget` (SQLite and
PostgreSQL), checked against what the evaluator itself saw."""

from __future__ import annotations

import importlib.util
import math
from datetime import datetime, timedelta

import pytest
from graspscape.services.coordinator.exploration.accounting import account
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.store.models import PoseRow
from graspscape.services.local.run import run_local
from graspscape.shared.specs.exploration import ExplorationSpec

from tests.factories import oracle_result

T0 = datetime(2026, 12, 1, 12, 0, 0)


def _row(at_s: float, *, viable: bool, mu_s: float = 0.0, links: tuple[str, ...] = (),
         ratio: float | None = None, worker: str = "w1", outcome: str | None = None,
         inferred_from: str | None = None, robust_q: float | None = None) -> PoseRow:
    signature = {"links_in_contact": list(links), "contacts": [], "joint_angles": {}}
    return PoseRow(
        pose_key=f"k{at_s}{worker}{mu_s}", theta=1.0, phi=1.0, r=0.01, roll=0.0, pitch=0.0,
        yaw=0.0, outcome=outcome or ("held" if viable else "no_grasp"), viable=viable,
        mu_s=mu_s, effort_max_nm=1.0, signature=signature if viable else None,
        torque_margin_ratio=ratio, robust_q=robust_q, worker_id=worker,
        inferred_from=inferred_from,
        eval_time_s=0.1, created_at=T0 + timedelta(seconds=at_s))


def test_account_of_hand_made_rows_gives_the_known_figures() -> None:
    rows = [
        _row(1, viable=False),  # a miss
        _row(2, viable=True, mu_s=0.5, links=("A_3", "B_3", "C_3"), ratio=0.3),  # first grasp
        # A symmetry copy: a grasp of the map, not an evaluation.
        _row(2, viable=True, mu_s=0.5, links=("A_3", "B_3", "C_3"), worker="shortcut:symmetry"),
        # Shortcut 2 (the worker synthesized it): an evaluation; within 5 % of the best 0.8.
        _row(5, viable=True, mu_s=0.79, links=("A_2", "B_spread", "palm"), ratio=0.6,
             inferred_from="k2w10.5"),
        # The best μs, no margin; its robust quality is the best stored one.
        _row(9, viable=True, mu_s=0.8, links=("A_1", "B_3", "C_2"), robust_q=0.42),
        _row(12, viable=False, outcome="error"),  # a miss too; the last result
    ]
    # Two poses planned for certification: the evaluated one counts, the copy does not.
    got = account(rows, T0, {rows[4].pose_key, rows[2].pose_key})
    assert got.model_dump() == {
        "evaluations": 5, "certification_evaluations": 1, "poses_stored": 6,
        "wall_time_s": 12.0, "best_mu_s": 0.8,
        "rank_metric": "torque_margin_ratio", "best_rank": 0.6,
        "best_robust_q": 0.42, "large_manifolds": None,  # the latter is read from the store
        "grasp_types": 2,  # {A, B, C} and {A, B, palm}
        "grasps": 4, "misses": 2, "time_to_first_grasp_s": 2.0, "time_to_near_best_s": 5.0,
    }


def test_account_of_nothing_and_of_misses_only() -> None:
    empty = account([], None)
    assert (empty.evaluations, empty.grasps, empty.wall_time_s, empty.best_mu_s,
            empty.time_to_first_grasp_s) == (0, 0, None, None, None)
    misses = account([_row(3, viable=False), _row(4, viable=False)], T0)
    assert (misses.evaluations, misses.misses, misses.grasps, misses.wall_time_s,
            misses.best_mu_s, misses.best_rank, misses.grasp_types,
            misses.time_to_near_best_s) == (2, 2, 0, 4.0, None, None, 0, None)


GRID = {"dtheta": math.radians(60), "r_min": 0.0, "r_max": 0.02, "dr": 0.01}


@pytest.mark.slow  # five whole explorations on both databases
@pytest.mark.parametrize("strategy", [
    {"name": "adaptive"},
    {"name": "grid"},
    {"name": "random", "poses": 60, "seed": 2, "rounds": 2},
    {"name": "cmaes", "poses": 60, "seed": 2},
    pytest.param({"name": "ppo", "poses": 60, "seed": 2, "batch": 16},
                 marks=pytest.mark.skipif(
                     importlib.util.find_spec("stable_baselines3") is None,
                     reason="the optional extra rl is not installed")),
])
def test_every_explorer_is_counted_the_same_way(client, sessions, object_id,
                                                strategy: dict) -> None:
    # Certification with room to do something on this small grid (only adaptive certifies).
    spec = ExplorationSpec(object_id=object_id, grid=GRID, refinement={"levels": 1},
                           shortcuts={"symmetry": strategy["name"] == "adaptive"},
                           certification={"share": 0.5}, strategy=strategy)
    seen = []

    def evaluate(poses, match=None):
        results = [oracle_result(p) for p in poses]
        seen.extend(results)
        return results

    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=20, max_poses=10**6).id
    run_local(sessions, evaluate, workers=2, seed=3, split=2)
    response = client.get(f"/explorations/{eid}/budget")
    assert response.status_code == 200, response.text
    got = response.json()
    assert (got["exploration_id"], got["strategy"], got["status"]) == \
        (eid, strategy["name"], "done")
    viable = [r for r in seen if r.viable]
    assert got["evaluations"] == len(seen)
    assert got["misses"] == len(seen) - len(viable)
    assert got["best_mu_s"] == pytest.approx(max(r.mu_s for r in viable))
    assert got["best_rank"] is None  # the oracle measures no torque margin
    assert got["grasp_types"] == 1  # the oracle's grasps all touch with A, B and C
    # Only the adaptive strategy certifies; its certification evaluations are evaluations.
    cert = got["certification_evaluations"]
    assert (cert > 0) == (strategy["name"] == "adaptive")
    assert cert <= 0.5 * (got["poses_stored"] - cert)  # of the planned poses
    if strategy["name"] == "adaptive":  # the symmetry shortcut's copies are grasps, not work
        assert got["poses_stored"] > got["evaluations"]
        assert got["grasps"] > len(viable)
        # The lattice explorer has a robust map: its best q_δ and its large manifolds.
        assert 0.0 < got["best_robust_q"] <= got["best_mu_s"]
        assert got["large_manifolds"] >= 1
    else:
        assert got["poses_stored"] == got["evaluations"]
        assert got["grasps"] == len(viable)
    assert 0.0 <= got["time_to_first_grasp_s"] <= got["time_to_near_best_s"] \
        <= got["wall_time_s"]


def test_budget_of_an_unknown_exploration_is_404(client) -> None:
    assert client.get("/explorations/999/budget").status_code == 404
