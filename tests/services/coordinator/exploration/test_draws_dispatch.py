"""The certification's draws as dispatched work, on a real small exploration of the sphere
(pybullet, and MuJoCo where named): a round of the race queues its draws as tiles of draws
(outcome only, each pose's scales); the evaluation stores them as draw records with no μs,
whose outcome and grasp type are a full evaluation's of the same start pose; under a model
listing both engines every draw is simulated in both, and /best can ask for grasps
confirmed in both; draws are never returned as grasps."""

from __future__ import annotations

import importlib.util
import math

import pytest
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.mapspace.pose import digit
from graspscape.services.coordinator.store.models import PoseRow, TileRow
from graspscape.services.local.run import drawer, pybullet_evaluator, run_local
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.workers.sim.evaluate import evaluate_pose
from sqlalchemy import select

GRID = {"dtheta": math.radians(60), "r_min": 0.01, "r_max": 0.02, "dr": 0.01}
CERT = {"share": 0.5, "core_share": 0.0, "candidates": 1}
SPHERE = ObjectSpec(name="sphere")
_MUJOCO = importlib.util.find_spec("mujoco") is not None


def _explore(sessions, object_id: int, uncertainty: dict) -> tuple[int, ExplorationSpec]:
    spec = ExplorationSpec(object_id=object_id, grid=GRID, certification=CERT,
                           refinement={"levels": 1, "local_search_rounds": 0},
                           uncertainty=uncertainty)
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=20, max_poses=10**6).id
    run_local(sessions, pybullet_evaluator(SPHERE, settings=spec.settings),
              draw=drawer(SPHERE, settings=spec.settings), engines=("pybullet", "mujoco"))
    return eid, spec


def _draws(sessions, eid: int) -> list[PoseRow]:
    with sessions() as s:
        rows = list(s.scalars(select(PoseRow).where(PoseRow.exploration_id == eid,
                                                    PoseRow.certifies.is_not(None))))
        s.expunge_all()
        return rows


@pytest.mark.slow  # a ~100-pose exploration and its draws, then 6 full evaluations
def test_draws_are_evaluated_outcome_only_and_agree_with_full_evaluations(
        sessions, named_object, client) -> None:
    eid, spec = _explore(sessions, named_object("sphere"), {"preset": "lab"})
    rows = _draws(sessions, eid)
    assert len(rows) >= 12  # the race's first look at least
    with sessions() as s:
        tiles = list(s.scalars(select(TileRow).where(TileRow.exploration_id == eid,
                                                     TileRow.sample.is_not(None))))
    assert tiles and all(t.needs_engines == "pybullet" for t in tiles)
    assert sum(t.n_poses for t in tiles) == len(rows)
    for row in rows:  # the worker took the outcome-only path: no μs, no grasp record
        assert row.sample is not None and "mu_s" in row.sample["absent"]
        assert row.mu_s == 0.0 and row.signature is None and row.grasp is None
        assert list(row.sample["engines"]) == ["pybullet"]
    # The poses export names them draws (their μs of 0 is no measurement); /best skips them.
    table = client.get(f"/explorations/{eid}/export/poses.csv").text.splitlines()
    source = {line.split(",")[0]: line for line in table[1:]}
    assert all(",draw," in source[row.pose_key] for row in rows)
    best = client.get(f"/explorations/{eid}/best?rank=mu_s&limit=100").json()["poses"]
    assert not {p["pose_key"] for p in best} & {row.pose_key for row in rows}
    for row in rows[:6]:
        pose = Pose(theta=row.theta, phi=row.phi, r=row.r, roll=row.roll, pitch=row.pitch,
                    yaw=row.yaw)
        full = evaluate_pose(pose, obj=SPHERE, settings=spec.settings)
        drawn = row.sample["engines"]["pybullet"]
        assert drawn["outcome"] == full.outcome.value == row.outcome
        if full.signature is not None:
            assert {digit(x) for x in drawn["links"]} == {
                digit(x) for x in full.signature.links_in_contact}


@pytest.mark.slow  # the same exploration with every draw simulated in both engines
@pytest.mark.skipif(not _MUJOCO, reason="mujoco is not installed")
def test_draws_in_both_engines_and_best_asks_for_grasps_confirmed_in_both(
        sessions, named_object, client) -> None:
    eid, _ = _explore(sessions, named_object("sphere"),
                      {"preset": "lab", "engines": ["pybullet", "mujoco"]})
    rows = _draws(sessions, eid)
    assert len(rows) >= 12
    for row in rows:
        assert sorted(row.sample["engines"]) == ["mujoco", "pybullet"]
        both_held = all(e["outcome"] == "held" for e in row.sample["engines"].values())
        assert row.viable == both_held
    answer = client.get(f"/explorations/{eid}/best?engines=pybullet,mujoco&limit=5")
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert body["engines"] == ["mujoco", "pybullet"] and body["rank"] == "p_success"
    assert body["poses"], "no grasp of the sphere confirmed in both engines"
    for pose in body["poses"]:
        assert pose["success"]["engines"] == ["pybullet", "mujoco"]
        assert pose["success"]["n"] >= 12
