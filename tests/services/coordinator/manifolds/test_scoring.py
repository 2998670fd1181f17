"""Scores of an explored robust map against the dense one (manifolds/scoring.py), on hand-made
label fields over a real lattice where T1–T4 are known: a smooth disc, a checkerboard of two
grasp types, random speckle inside a disc; and a run that holds only some of the poses."""

from __future__ import annotations

import math
import random

import pytest
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.robust import Neighbourhoods
from graspscape.services.coordinator.manifolds.scoring import (
    MapLabels,
    manifold_iou,
    mode_filter,
    score_run,
)
from graspscape.shared.specs.exploration import AttitudeSpec, PoseGridSpec

from tests.factories import PINCH, POWER, lattice_pose

# A 60° grid refined once (small, so the tests stay fast): the finest step is 30°, 5 r
# levels, 2 rolls.
LATTICE = Lattice(
    PoseGridSpec(dtheta=math.radians(60), r_min=0.0, r_max=0.02, dr=0.01,
                 attitudes=AttitudeSpec(rolls=2)),
    depth=1,
)
POINTS = [Point(K, J, i, a) for K, J in LATTICE.cells(1) for i in range(5) for a in range(2)]
WEIGHTS = {p: 1.0 for p in POINTS}  # every finest point one unit of volume
HOOD = Neighbourhoods(LATTICE)
DISC = {p for p in POINTS if LATTICE.direction(p)[2] > math.cos(math.radians(50))}


def pose(p: Point, digits: frozenset[str] | None, mu: float = 0.5) -> StoredPose:
    return lattice_pose(LATTICE, p, digits, mu)


def disc_map(held: set[Point]) -> MapLabels:
    return MapLabels(labels={p: 0 if p in held else -1 for p in POINTS},
                     samples={p: pose(p, POWER if p in held else None) for p in POINTS})


def test_a_run_that_holds_every_pose_of_a_smooth_disc_scores_perfectly() -> None:
    dense = disc_map(DISC)
    scores = score_run(LATTICE, WEIGHTS, dense, dense)
    core = {p for p in DISC if all(q in DISC for q in HOOD(p))}
    assert scores.t1.dense_core_volume_share == pytest.approx(len(core) / len(DISC))
    assert (scores.t1.recall, scores.t1.claimed_false_share) == (1.0, 0.0)
    # The best robust grasp: q_δ = 0.5 on the core, the most there is; s_δ = 1.
    assert (scores.t2.regret, scores.t2.in_top, scores.t2.s_dense) == (0.0, True, 1.0)
    assert (scores.t2.large_manifolds, scores.t2.large_found, scores.t2.large_passing) == (1, 1, 1)
    assert (scores.t3.large_5pct, scores.t3.found_5pct, scores.t3.volume_error_max,
            scores.t3.viable_volume_error) == (1, 1, 0.0, 0.0)
    assert (scores.t4.labelled_error, scores.t4.labelled_coverage, scores.t4.brier) == (
        0.0, 1.0, 0.0)
    assert scores.t4.coverage_target == pytest.approx(
        max(0.5, len(core) / len(DISC) + 0.1))
    assert (scores.diagnostics.iou, scores.diagnostics.iou_mode_filtered) == (1.0, 1.0)
    # A smooth border: the share of differing neighbour pairs falls as the step halves.
    shares = scores.diagnostics.differing_shares
    assert shares[1] < shares[0] and scores.diagnostics.alphas[1] > 0.5


def test_a_run_without_the_finest_poses_claims_no_core_and_labels_nothing_wrong() -> None:
    # It holds the 30° poses only (its map labels every point right, as if interpolated):
    # no N_δ is held whole, so it claims no core; the unknown neighbours leave most labels
    # uncertain, and the ones it gives are right (the dense s lies within its bounds).
    dense = disc_map(DISC)
    coarse = {p: s for p, s in dense.samples.items() if LATTICE.birth(p) == 0}
    run = MapLabels(labels=dense.labels, samples=coarse)
    scores = score_run(LATTICE, WEIGHTS, dense, run)
    assert (scores.t1.recall, scores.t1.claimed_false_share) == (0.0, None)
    assert scores.t4.labelled_error in (None, 0.0)
    assert scores.t4.labelled_coverage < scores.t4.coverage_target
    assert (scores.t3.found_1pct, scores.t3.viable_volume_error) == (1, 0.0)


def test_a_checkerboard_of_two_types_has_no_core_and_differs_only_at_the_finest_step() -> None:
    # The type flips with the finest r step and the roll: 30° neighbours (two finest r steps
    # apart, same roll) agree, every 15° r pair differs — no border a coarse pass could see.
    def kind(p: Point) -> frozenset[str]:
        return POWER if (p.r_index + p.attitude) % 2 == 0 else PINCH

    dense = MapLabels(labels={p: (p.r_index + p.attitude) % 2 for p in POINTS},
                      samples={p: pose(p, kind(p)) for p in POINTS})
    scores = score_run(LATTICE, WEIGHTS, dense, dense)
    assert scores.t1.dense_core_volume_share == 0.0 and scores.t1.recall is None
    assert scores.t1.claimed_false_share is None
    assert scores.t4.coverage_target == 0.5
    assert scores.t2.s_dense is not None and scores.t2.s_dense < 0.9  # nothing robust to find
    assert (scores.t4.labelled_error, scores.t4.brier) == (0.0, 0.0)
    shares = scores.diagnostics.differing_shares
    r_pairs = sum(1 for p in POINTS for kind_, q in LATTICE.neighbours(p, 1)
                  if q.r_index != p.r_index and p < q)
    all_pairs = sum(1 for p in POINTS for _, q in LATTICE.neighbours(p, 1) if p < q)
    assert shares[0] == 0.0 and shares[1] == pytest.approx(r_pairs / all_pairs)
    assert scores.diagnostics.alphas == {}


def test_speckle_in_a_disc_missed_by_the_run_shrinks_no_core_and_counts_as_volume_error() -> None:
    rng = random.Random(3)
    disc = sorted(DISC)
    specks = set(rng.sample(disc, len(disc) // 10))
    held = DISC - specks
    dense = disc_map(held)
    # The run never evaluated the specks and its map fills them in as the disc.
    run = MapLabels(labels={p: 0 if p in DISC else -1 for p in POINTS},
                    samples={p: s for p, s in dense.samples.items() if p not in specks})
    scores = score_run(LATTICE, WEIGHTS, dense, run)
    core = {p for p in held if all(q in held for q in HOOD(p))}
    assert scores.t1.dense_core_volume_share == pytest.approx(len(core) / len(held))
    # Claimed: held poses whose N_δ it holds whole — exactly the dense core.
    assert (scores.t1.recall, scores.t1.claimed_false_share) == (1.0, 0.0)
    assert scores.t3.viable_volume_error == pytest.approx(len(specks) / len(held))
    assert scores.t3.volume_error_max == pytest.approx(len(specks) / len(held))
    assert scores.t4.labelled_error == 0.0  # omitting poses never mislabels: bounds
    assert scores.t4.brier > 0.0  # but its s_δ next to a speck is too high
    assert scores.t2.regret == 0.0 and scores.t2.s_dense == 1.0
    assert scores.diagnostics.iou == pytest.approx(len(held) / len(DISC))
    # A mode filter over N_δ fills isolated specks in: the filtered maps agree more.
    assert scores.diagnostics.iou_mode_filtered > scores.diagnostics.iou


def test_a_run_that_splits_a_manifold_finds_the_larger_part_only() -> None:
    dense = disc_map(DISC)
    half = {p for p in DISC if p.attitude == 0}
    run = MapLabels(labels={p: (0 if p in half else 1) if p in DISC else -1 for p in POINTS},
                    samples=dense.samples)
    scores = score_run(LATTICE, WEIGHTS, dense, run)
    # One dense manifold, matched to one run half that covers exactly half of it: found; its
    # volume is off by half.
    assert (scores.t3.large_1pct, scores.t3.found_1pct) == (1, 1)
    assert scores.t3.volume_error_max == pytest.approx(0.5)
    assert scores.t3.viable_volume_error == 0.0
    assert manifold_iou(dense.labels, run.labels, WEIGHTS) == pytest.approx(0.5)
    filtered = mode_filter(LATTICE, run.labels)
    assert set(filtered) == set(POINTS)
