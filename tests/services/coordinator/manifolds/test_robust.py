"""The robust map on hand-made label fields over a real lattice (manifolds/robust.py): a smooth
disc, a checkerboard, random speckle inside a disc, and unknown neighbours."""

from __future__ import annotations

import math
import random

import pytest
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.robust import (
    Neighbourhoods,
    RobustLabel,
    dust,
    large_manifolds,
    neighbourhood,
    robust_core,
    robust_scores,
)
from graspscape.shared.specs.exploration import AttitudeSpec, PoseGridSpec

from tests.factories import PINCH, POWER, lattice_pose

# A 30° grid refined once: the finest step is 15°, 5 r levels, 2 rolls.
LATTICE = Lattice(
    PoseGridSpec(dtheta=math.radians(30), r_min=0.0, r_max=0.02, dr=0.01,
                 attitudes=AttitudeSpec(rolls=2)),
    depth=1,
)


def finest_points(lattice: Lattice) -> list[Point]:
    n_i = (lattice.n_r << lattice.depth) + 1
    return [Point(K, J, i, a) for K, J in lattice.cells(lattice.depth)
            for i in range(n_i) for a in range(len(lattice.attitudes))]


POINTS = finest_points(LATTICE)
hood = Neighbourhoods(LATTICE)  # N_δ(p) of many points, as robust_scores computes it


def pose(p: Point, digits: frozenset[str] | None, mu: float = 0.5) -> StoredPose:
    return lattice_pose(LATTICE, p, digits, mu)


DISC = {p for p in POINTS if LATTICE.direction(p)[2] > math.cos(math.radians(50))}


def in_disc(p: Point) -> bool:
    """Within 50° of the +z axis."""
    return p in DISC


def expected_label(s: float) -> RobustLabel:
    return (RobustLabel.ROBUST if s >= 0.9 else RobustLabel.FUTILE if s <= 0.1
            else RobustLabel.FRAGILE)


def test_the_neighbourhood_is_the_finest_position_and_attitude_neighbours() -> None:
    p = Point(5, 3, 1, 1)  # a finest-only ring (5 of 12) and r level (1 of 0…4)
    assert LATTICE.birth(p) == 1 and LATTICE.m(5) > 8
    expected = {q for _, q in LATTICE.neighbours(p, 1)} | set(LATTICE.attitude_neighbours(p))
    got = neighbourhood(LATTICE, p)
    assert set(got) == expected and len(got) == len(expected)
    # The next r level in and out, the next azimuth either way, the other roll: all there.
    assert {p.at_r(0), p.at_r(2), Point(5, 2, 1, 1), Point(5, 4, 1, 1),
            Point(5, 3, 1, 0)} <= set(got)
    assert p not in got
    # One coarser step: every point within two steps, the one-step neighbourhood included,
    # diagonals (another r and another roll) too.
    wide = set(neighbourhood(LATTICE, p, coarser=1))
    assert set(got) < wide and p not in wide
    assert {p.at_r(3), Point(5, 3, 0, 0), Point(5, 1, 1, 1), Point(5, 5, 1, 1)} <= wide
    # Neighbourhoods are symmetric.
    for q in got:
        assert p in neighbourhood(LATTICE, q)


def test_a_smooth_disc_is_robust_inside_futile_outside_fragile_on_a_band() -> None:
    samples = {p: pose(p, POWER if in_disc(p) else None) for p in POINTS}
    scores = robust_scores(LATTICE, samples)
    assert set(scores) == set(POINTS)
    counts = {label: 0 for label in RobustLabel}
    for p, sc in scores.items():
        group = [p, *hood(p)]
        inside = sum(in_disc(q) for q in group)
        # One grasp type everywhere: s is the disc's share of N_δ ∪ {p}, whether p holds or not.
        assert sc.s == pytest.approx(inside / len(group))
        assert sc.q == pytest.approx(0.5 * inside / len(group))
        assert sc.s_low == sc.s == sc.s_high and sc.known == sc.total == len(group)
        assert sc.label == expected_label(inside / len(group))
        # N_δ ∪ {p} has 7–11 members here: one pose off the type is robust (s ≥ 0.9) only
        # where there are 10 or 11.
        if inside == len(group) - 1:
            assert (sc.label == RobustLabel.ROBUST) == (len(group) >= 10)
        counts[sc.label] += 1
    assert counts[RobustLabel.UNCERTAIN] == 0
    assert min(counts[RobustLabel.ROBUST], counts[RobustLabel.FUTILE],
               counts[RobustLabel.FRAGILE]) > 0
    # The core of the disc's manifold: the poses whose whole N_δ lies in the disc — robust
    # ones, but not every robust one (a single neighbour outside leaves s ≥ 0.9 on 10-sets).
    disc = {p for p in POINTS if in_disc(p)}
    core = robust_core(LATTICE, samples, disc)
    assert core == {p for p in disc if all(in_disc(q) for q in hood(p))}
    robust = {p for p, sc in scores.items() if sc.label == RobustLabel.ROBUST}
    assert core <= robust and len(core) > 50


def test_a_checkerboard_of_two_grasp_types_has_no_robust_pose_and_no_core() -> None:
    # The type flips with the r level and the roll: every pose has unlike neighbours.
    def kind(p: Point) -> frozenset[str]:
        return POWER if (p.r_index + p.attitude) % 2 == 0 else PINCH

    samples = {p: pose(p, kind(p)) for p in POINTS}
    scores = robust_scores(LATTICE, samples)
    for p, sc in scores.items():
        group = [p, *hood(p)]
        same = sum(kind(q) == kind(p) for q in group)
        assert sc.s == pytest.approx(same / len(group))
        assert sc.target == tuple(sorted(kind(p)))
        assert sc.label == RobustLabel.FRAGILE  # every pose holds, none robustly
    for k in (POWER, PINCH):
        members = {p for p in POINTS if kind(p) == k}
        assert robust_core(LATTICE, samples, members) == set()


def test_speckle_inside_a_disc_breaks_robustness_around_every_dropped_pose() -> None:
    rng = random.Random(7)
    disc = [p for p in POINTS if in_disc(p)]
    dropped = set(rng.sample(disc, len(disc) // 10))
    held = {p for p in disc if p not in dropped}
    samples = {p: pose(p, POWER if p in held else None) for p in POINTS}
    scores = robust_scores(LATTICE, samples)
    for p, sc in scores.items():
        group = [p, *hood(p)]
        n_held = sum(q in held for q in group)
        assert sc.s == pytest.approx(n_held / len(group))
        assert sc.label == expected_label(n_held / len(group))
        if sum(q in dropped for q in group) >= 2:
            assert sc.label != RobustLabel.ROBUST
    # A dropped pose surrounded by held ones is not robust either, and held poses next to a
    # speck are not in the core.
    core = robust_core(LATTICE, samples, held)
    assert core == {p for p in held if all(q in held for q in hood(p))}
    assert all(scores[p].label == RobustLabel.ROBUST for p in core)
    smooth_core = robust_core(LATTICE, {p: pose(p, POWER if p in disc else None)
                                        for p in POINTS}, set(disc))
    assert core < smooth_core


def test_a_lone_held_pose_among_drops_is_never_robust() -> None:
    lone = Point(6, 6, 2, 1)
    samples = {p: pose(p, POWER if p == lone else None) for p in POINTS}
    sc = robust_scores(LATTICE, samples, [lone])[lone]
    n = len(neighbourhood(LATTICE, lone)) + 1
    assert sc.s == pytest.approx(1 / n) and sc.label == expected_label(1 / n)
    assert sc.label != RobustLabel.ROBUST
    assert robust_core(LATTICE, samples, {lone}) == set()
    # Its neighbours target the lone pose's type and fail it almost everywhere.
    for q in neighbourhood(LATTICE, lone):
        other = robust_scores(LATTICE, samples, [q])[q]
        assert other.target == tuple(sorted(POWER)) and other.label != RobustLabel.ROBUST


def test_unknown_neighbours_bound_s_and_the_label_is_uncertain_when_they_could_change_it() -> None:
    p = Point(6, 6, 2, 1)
    hood = neighbourhood(LATTICE, p)
    n = len(hood) + 1
    full = {q: pose(q, POWER) for q in [p, *hood]}
    # Two neighbours unknown, the rest held: s = 1, s_low = (n − 2)/n < 0.9 → uncertain.
    missing = dict(full)
    del missing[hood[0]], missing[hood[1]]
    sc = robust_scores(LATTICE, missing, [p])[p]
    assert (sc.s, sc.s_high) == (1.0, 1.0)
    assert sc.s_low == pytest.approx((n - 2) / n)
    assert (sc.known, sc.total) == (n - 2, n)
    assert sc.label == RobustLabel.UNCERTAIN
    # One unknown where N_δ ∪ {p} has 10 members: 9 of 10 held whatever it is → robust.
    assert n == 10
    del full[hood[0]]
    assert robust_scores(LATTICE, full, [p])[p].label == RobustLabel.ROBUST
    full[hood[0]] = pose(hood[0], POWER)
    # Every neighbour unknown, p dropped: futile only if the unknowns could not hold.
    alone = {p: pose(p, None)}
    sc = robust_scores(LATTICE, alone, [p])[p]
    assert sc.s == 0.0 and sc.target is None and sc.label == RobustLabel.UNCERTAIN
    assert sc.s_high == pytest.approx((n - 1) / n)
    # The core needs the whole neighbourhood stored.
    assert p not in robust_core(LATTICE, missing, set(missing))
    assert p in robust_core(LATTICE, full, set(full))
    # Points not stored are not scored.
    assert robust_scores(LATTICE, missing, [hood[0]]) == {}


def test_large_manifolds_and_dust_split_at_one_percent_of_the_viable_volume() -> None:
    volumes = [50.0, 30.0, 1.0, 0.99, 0.5, 0.0]
    viable = 100.0
    assert large_manifolds(volumes, viable) == [0, 1, 2]
    d = dust(volumes, viable)
    assert (d.indices, d.count) == ([3, 4, 5], 3) and d.volume == pytest.approx(1.49)
    assert large_manifolds(volumes, viable, share=0.05) == [0, 1]


def test_the_manifold_table_carries_core_robust_best_and_dust() -> None:
    """build_map on a cap within 130° of +z (20° grid) and a lone held pose at the south pole:
    the cap is large, with its core and its robust best (the first by `robust_order`); the
    lone pose is dust (0.9 % of the viable volume), shown as one line of the table."""
    import numpy as np
    from graspscape.services.coordinator.manifolds.summary import (
        build_map,
        robust_order,
        table_rows,
        table_text,
    )

    lattice = Lattice(PoseGridSpec(dtheta=math.radians(20), r_min=0.01, r_max=0.01), 0)
    points = finest_points(lattice)
    cap = {p for p in points if lattice.direction(p)[2] > math.cos(math.radians(130))}
    south = Point(lattice.n_rings, 0, 0, 0)

    def mu(p: Point) -> float:
        return 0.99 if p == south else round(0.5 + 0.3 * lattice.direction(p)[2], 9)

    samples = {p: pose(p, POWER if p in cap or p == south else None, mu(p)) for p in points}
    mmap, _, label_of = build_map(lattice, samples, lambda d: np.full(len(d), 0.05))
    disc, lone = mmap.manifolds
    assert {label_of[p] for p in cap} == {0} and label_of[south] == 1
    assert disc.large and not lone.large
    assert lone.volume_cm3 < 0.01 * mmap.viable_volume_cm3 < disc.volume_cm3
    core = robust_core(lattice, samples, cap)
    assert disc.core_count == len(core) and 0 < disc.core_volume_cm3 < disc.volume_cm3
    scores = robust_scores(lattice, samples)
    top = min(cap, key=lambda p: robust_order(samples[p], scores[p]))
    assert scores[top].label == RobustLabel.ROBUST
    assert disc.robust_best.key == samples[top].key and disc.robust_best.robust_label == "robust"
    assert disc.robust_best.q == pytest.approx(scores[top].q)
    assert lone.best.mu_s == 0.99 and lone.robust_best.robust_label != "robust"
    assert mmap.robust[samples[south].key] == scores[south]
    rows = table_rows(mmap)
    assert [r["label"] for r in rows] == ["A", "dust"]
    assert rows[0]["robust_best"] == disc.robust_best.key
    assert (rows[1]["manifolds"], rows[1]["poses"]) == (1, 1)
    assert rows[1]["volume_cm3"] == lone.volume_cm3
    text = table_text(mmap.manifolds).splitlines()
    assert len(text) == 2 and text[0].startswith("A: ") and text[1].startswith("dust: 1 ")
    assert f"robust best {disc.robust_best.key} (s 1.00" in text[0]


def test_an_uncertain_pose_that_cannot_be_robust_ranks_after_a_known_fragile_one() -> None:
    """The robust ranking: an uncertain pose goes before a fragile one only while its unknown
    neighbours could still make it robust (s_high ≥ 0.9); one whose bound is lower is no
    better than what is known, however high the q_δ of its few known neighbours."""
    from graspscape.services.coordinator.manifolds.robust import RobustScore
    from graspscape.services.coordinator.manifolds.summary import robust_order

    a, b, c = (pose(p, POWER, 0.9) for p in POINTS[:3])
    fragile = RobustScore(s=0.5, q=0.43, s_low=0.5, s_high=0.5,
                          label=RobustLabel.FRAGILE, known=9, total=9)
    hopeless = RobustScore(s=0.6, q=0.8, s_low=0.33, s_high=0.67,
                           label=RobustLabel.UNCERTAIN, known=5, total=9)
    hopeful = RobustScore(s=1.0, q=0.5, s_low=0.56, s_high=1.0,
                          label=RobustLabel.UNCERTAIN, known=5, total=9)
    futile = RobustScore(s=0.0, q=0.0, s_low=0.0, s_high=0.0,
                         label=RobustLabel.FUTILE, known=9, total=9)
    ranked = sorted([(a, hopeless), (b, fragile), (c, hopeful), (c, futile)],
                    key=lambda e: robust_order(*e))
    assert [sc for _, sc in ranked] == [hopeful, fragile, hopeless, futile]
