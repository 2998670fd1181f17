"""P(success) bounds and the sequential rule, on simulated Bernoulli arms and a synthetic map."""

from __future__ import annotations

import math

import numpy as np
from graspscape.services.coordinator.mapspace import success
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.uncertainty import UncertaintyModel, draws, perturbed


def test_clopper_pearson_values() -> None:
    # 8/8 and 30/30 one-sided 95 %: the figures of the literature (0.688, 0.905)
    assert math.isclose(success.lower_bound(8, 8, 0.05), 0.05 ** (1 / 8))
    assert abs(success.lower_bound(30, 30, 0.05) - 0.9050) < 1e-3
    assert success.lower_bound(0, 10, 0.05) == 0.0
    assert success.upper_bound(10, 10, 0.05) == 1.0
    assert abs(success.upper_bound(0, 30, 0.05) - (1 - 0.05 ** (1 / 30))) < 1e-9


def test_coverage_under_optional_stopping() -> None:
    """10,000 runs per arm, each stopped by the real rule (certified, refuted or the last
    look): the final lower and upper bounds each cover P in ≥ 95 % of runs, and an arm at or
    below the level is certified in ≤ 5 % of runs."""
    p = np.array([0.3, 0.6, 0.8, 0.85, 0.88, 0.9, 0.91, 0.93, 0.95, 0.97, 0.99])
    got = success.simulate_coverage(p, 10_000, np.random.default_rng(20261205))
    assert (got["lower_covers"] >= 0.95).all(), got["lower_covers"]
    assert (got["upper_covers"] >= 0.95).all(), got["upper_covers"]
    assert (got["certified"][p <= 0.9] <= 0.05).all()
    assert got["certified"][p == 0.99][0] > 0.9  # and it does certify clear cases
    assert got["mean_draws"][0] <= 13  # a clear loser stops at its first look


def test_naive_peeking_would_over_claim() -> None:
    """The same looks with the full α at every look (no spending) certify a P = 0.9 arm more
    often than 5 %: the test above can fail."""
    rng = np.random.default_rng(7)
    x = rng.random((10_000, 96)) < 0.9
    counts = np.cumsum(x, axis=1)
    claimed = np.zeros(10_000, dtype=bool)
    for m in range(10, 97):
        claimed |= success.lower_bound(counts[:, m - 1], m, 0.05) >= 0.9
    assert claimed.mean() > 0.05


def test_estimate_matches_the_rule() -> None:
    e = success.estimate([True] * 48)
    assert e.certified and e.done and e.lower > 0.9 and (e.k, e.n) == (48, 48)
    e = success.estimate([True] * 30)  # 30/30 alone does not certify under the rule
    assert not e.certified and not e.done
    e = success.estimate([False] * 6 + [True] * 6)
    assert e.refuted and e.done and not e.certified
    assert success.next_look(0) == 12 and success.next_look(48) == 96
    assert success.next_look(96) is None


def _synthetic_held(centre: Pose, radius_deg: float):
    """A synthetic map: a draw holds (with the centre's grasp type) where its approach
    direction lies within `radius_deg` of the centre's: a held region of that size."""
    def u(p: Pose) -> np.ndarray:
        st = math.sin(p.theta)
        return np.array([st * math.cos(p.phi), st * math.sin(p.phi), math.cos(p.theta)])
    c = u(centre)
    return lambda p: math.degrees(math.acos(min(1.0, float(u(p) @ c)))) <= radius_deg


def _run(centre: Pose, held, model: UncertaintyModel) -> success.Estimate:
    outcomes: list[bool] = []
    while True:
        e = success.estimate(outcomes)
        target = success.next_look(len(outcomes))
        if e.done or target is None:
            return e
        new = draws(centre.key(), model, target - len(outcomes), start=len(outcomes))
        outcomes += [held(perturbed(centre, d, 0.05)) for d in new]


def test_lone_held_pose_never_certified_region_certified() -> None:
    lab, field = UncertaintyModel(preset="lab"), UncertaintyModel(preset="field")
    for i in range(20):
        centre = Pose(theta=0.3 + 0.1 * i, phi=0.2 * i, r=0.01, roll=0.0, pitch=0.0, yaw=0.0)
        lone = _synthetic_held(centre, 0.5)  # held only within 0.5° of its direction
        for model in (lab, field):
            assert not _run(centre, lone, model).certified
        large = _synthetic_held(centre, 40.0)  # deep inside a large uniform held region
        for model in (lab, field):
            e = _run(centre, large, model)
            assert e.certified and e.n == 48 and e.k == 48


def test_race_spends_on_the_contenders() -> None:
    est = [success.estimate([True] * 24), success.estimate([True] * 12 + [False] * 12),
           success.estimate([True] * 23 + [False])]
    chosen = success.race(est)
    assert chosen == [0, 2]  # the leader and its challenger; the clear loser gets nothing
    done = [success.estimate([True] * 48), success.estimate([False] * 12)]
    assert success.race(done) == []
