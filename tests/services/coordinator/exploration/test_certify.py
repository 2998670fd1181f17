"""Certification of the adaptive strategy's best grasps (exploration/certify.py).

Pure: the jitters of a stated pose error are deterministic, near their centre and extend
with K; a plan completes the robust best's N_δ first, jitters it only once that is known,
and keeps to its budget. Through the real store and scheduler (SQLite and PostgreSQL) with an
oracle as the evaluator: a lone held pose among drops is never claimed robust, a pose inside
a large uniform held region is, and the same spec gives the same certification plan."""

from __future__ import annotations

import math

import pytest
from graspscape.services.coordinator.exploration import certify, racing
from graspscape.services.coordinator.exploration.accounting import exploration_budget
from graspscape.services.coordinator.exploration.certify_store import (
    certification_plans,
    certified_bests,
    robust_summary,
)
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.best import (
    Rank,
    best_poses,
    robust_evidence,
)
from graspscape.services.coordinator.manifolds.robust import (
    RobustLabel,
    neighbourhood,
    robust_scores,
)
from graspscape.services.coordinator.mapspace import success
from graspscape.services.coordinator.objects.service import create_named
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow
from graspscape.services.local.explore_lines import robust_lines
from graspscape.services.local.run import run_local
from graspscape.shared.specs.exploration import (
    CertificationSpec,
    ExplorationSpec,
    PoseGridSpec,
)
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import Outcome, PoseResult
from sqlalchemy import select

from tests.factories import oracle_result

GRID = PoseGridSpec(dtheta=0.6, r_min=0.0, r_max=0.02, dr=0.01)
LATTICE = Lattice(GRID, 1)
# A coarse point (θ = 2π/5, r = 0) that the "lone" oracle holds alone.
LONE = Point(LATTICE.scale(0) * 2, 0, 0, 0)
# Certification with room for N_δ and the jitters on a ~100-pose exploration (the pure plan
# tests, jitters without a race).
CERT = CertificationSpec(share=0.5, candidates=1, pose_error_mm=2.0, pose_error_deg=2.0,
                         jitters=4)
# Through the store: the race's draws, with room for one candidate's 48 draws (the least
# that certifies P ≥ 0.9 under the sequential rule).
RACE = CertificationSpec(share=0.5, core_share=0.0, candidates=1)
FIRST = success.LOOKS[0]


# --- pure ----------------------------------------------------------------------------------
def test_jitters_are_deterministic_near_their_centre_and_extend_with_k() -> None:
    centre = Pose(theta=1.0, phi=2.0, r=0.005, roll=0.5)
    a = certify.jitters(centre, radius_m=0.05, sigma_pos_m=0.002,
                        sigma_ang_rad=math.radians(2), k=8)
    b = certify.jitters(centre, radius_m=0.05, sigma_pos_m=0.002,
                        sigma_ang_rad=math.radians(2), k=12)
    assert len(a) == 8 and a == b[:8]
    assert len({p.key() for p in b}) == 12 and centre.key() not in {p.key() for p in b}
    for p in b:
        # 5 σ: 10 mm over a reach of 55 mm is at most ~0.18 rad of direction.
        u = (math.sin(p.theta) * math.cos(p.phi), math.sin(p.theta) * math.sin(p.phi),
             math.cos(p.theta))
        c = (math.sin(1.0) * math.cos(2.0), math.sin(1.0) * math.sin(2.0), math.cos(1.0))
        assert math.acos(min(1.0, sum(x * y for x, y in zip(u, c, strict=True)))) < 0.2
        assert 0.0 <= p.r <= 0.015
        assert abs(math.remainder(p.roll - 0.5, 2 * math.pi)) < math.radians(10)
        assert abs(p.pitch) < math.radians(10) and abs(p.yaw) < math.radians(10)
    other = certify.jitters(centre.model_copy(update={"phi": 2.1}), radius_m=0.05,
                            sigma_pos_m=0.002, sigma_ang_rad=math.radians(2), k=8)
    assert {p.key() for p in other}.isdisjoint(p.key() for p in a)
    assert certify.jitters(centre, radius_m=0.05, sigma_pos_m=0.0, sigma_ang_rad=0.0,
                           k=8) == []


def _held(p: Point, mu: float = 0.5) -> StoredPose:
    pose = LATTICE.pose(p)
    return StoredPose(key=pose.key(), theta=pose.theta, phi=pose.phi, r=pose.r, roll=pose.roll,
                      pitch=pose.pitch, yaw=pose.yaw, viable=True, outcome="held", mu_s=mu,
                      digits=frozenset({"A", "B", "C"}))


def _plan(samples, manifolds, budget: int, taken: set[str] = frozenset()
          ) -> list[certify.Work]:
    return certify.plan(LATTICE, samples, manifolds, robust_scores(LATTICE, samples), CERT,
                        budget_left=budget, taken=set(taken), radius_m=lambda p: 0.05)


def _drop(samples, points) -> None:
    for q in points:
        pose = LATTICE.pose(q)
        samples[q] = StoredPose(key=pose.key(), theta=pose.theta, phi=pose.phi, r=pose.r,
                                roll=pose.roll, pitch=pose.pitch, yaw=pose.yaw, viable=False,
                                outcome="no_grasp", mu_s=0.0)


def test_plan_completes_the_robust_best_first_then_jitters_it_within_budget() -> None:
    samples = {LONE: _held(LONE, 0.9)}
    manifolds = [certify.Manifold(0, (LONE,))]
    hood = neighbourhood(LATTICE, LONE)
    work = _plan(samples, manifolds, 100)
    # Its neighbours, all of them, and no jitter while they are unknown.
    assert [w.point for w in work] == hood and {w.centre for w in work} == {LONE}
    assert [w.point for w in _plan(samples, manifolds, 3)] == hood[:3]
    # Once N_δ is known (here: all dropped), the K jitters; a smaller budget takes the first
    # ones, and a later round the rest.
    _drop(samples, hood)
    work = _plan(samples, manifolds, 100)
    assert [w.point for w in work] == [None] * CERT.jitters
    first = _plan(samples, manifolds, 3)
    assert [w.pose for w in first] == [w.pose for w in work[:3]]
    rest = _plan(samples, manifolds, 100, {w.pose.key() for w in first})
    assert [w.pose for w in rest] == [w.pose for w in work[3:]]
    # And the claim: every neighbour known, none held: not robust, whatever the jitters say.
    score = robust_scores(LATTICE, samples, [LONE])[LONE]
    ev = certify.evidence(LATTICE, samples, LONE, score, [samples[LONE]] * 4,
                          jitters_asked=True)
    assert (ev.known, ev.held, ev.jitters_held, ev.certified) == (len(hood), 0, 4, False)


def test_plan_shares_the_budget_returned_grasps_first_overall_best_first() -> None:
    # Two one-pose manifolds on opposite sides; manifold 1 holds the better grasp.
    other = Point(LATTICE.scale(0) * 2, LATTICE.m(LATTICE.scale(0) * 2) // 2, 0, 0)
    samples = {LONE: _held(LONE, 0.5), other: _held(other, 0.9)}
    manifolds = [certify.Manifold(0, (LONE,)), certify.Manifold(1, (other,))]
    work = _plan(samples, manifolds, 3)
    # ceil(3 / 2) = 2 for the overall best's manifold, the 1 left for the other.
    assert [(w.label, w.centre) for w in work] == [(1, other), (1, other), (0, LONE)]
    assert [w.point for w in work] == neighbourhood(LATTICE, other)[:2] + \
        neighbourhood(LATTICE, LONE)[:1]
    # Candidates' neighbourhoods only after every returned grasp's (here the candidate is
    # the robust best itself, so nothing more): the budget is not a quota to fill.
    assert len(_plan(samples, manifolds, 1000)) == \
        len(neighbourhood(LATTICE, other)) + len(neighbourhood(LATTICE, LONE))


def test_budget_is_a_share_of_the_other_planned_poses() -> None:
    assert certify.budget(CertificationSpec(), 1000) == 350  # ≤ 40 % more evaluations
    assert certify.budget(CertificationSpec(share=0.0), 1000) == 0
    assert certify.budget(CertificationSpec(share=0.5), 7) == 3
    assert certify.centre_id_of(certify.reason_for(12345)) == 12345
    assert certify.centre_id_of("search") is None


def _fine_points(lattice: Lattice) -> list[Point]:
    n_i = (lattice.n_r << lattice.depth) + 1
    return [Point(K, J, i, a) for K, J in lattice.cells(lattice.depth) for i in range(n_i)
            for a in range(len(lattice.attitudes))]


def test_claims_complete_n_delta_deep_inside_and_grow_as_a_block() -> None:
    # A cap θ < 1.3 held (manifold 0), dropped elsewhere; stored: the coarse points only, the
    # finest ones carry the interpolated labels. A claim needs p and its whole N_δ stored and
    # in the manifold: none yet.
    fine = _fine_points(LATTICE)
    label_at = {p: 0 if LATTICE.pose(p).theta < 1.3 else -1 for p in fine}
    samples = {}
    for p in fine:
        if LATTICE.birth(p) == 0:
            if label_at[p] == 0:
                samples[p] = _held(p)
            else:
                _drop(samples, [p])
    manifolds = [certify.Manifold(0, tuple(sorted(p for p in samples if label_at[p] == 0)))]
    hood = {p: neighbourhood(LATTICE, p) for p in fine}
    first = certify.claims(LATTICE, samples, label_at, manifolds, room=8, taken=set())
    assert first and len(first) <= 8 and all(w.claim and w.label == 0 for w in first)
    points = [w.point for w in first]
    assert len(set(points)) == len(points) and not set(points) & set(samples)
    # Each centre is completed whole: it and its N_δ are then all known, and in the cap.
    centres = {w.centre for w in first}
    known = set(samples) | set(points)
    assert all({c, *hood[c]} <= known for c in centres)
    assert all(label_at[q] == 0 for c in centres for q in (c, *hood[c]))
    # The cheapest first, then the deepest: near the pole, far from the cap's rim (ring 4 of
    # the finest rings, θ = 1.2; ring 5 drops).
    assert all(c.ring <= 2 for c in centres), centres
    # With more room the claims grow as a block: a second centre next to the first costs
    # fewer evaluations than the first.
    more = certify.claims(LATTICE, samples, label_at, manifolds, room=40, taken=set())
    per_centre: dict[Point, int] = {}
    for w in more:
        per_centre[w.centre] = per_centre.get(w.centre, 0) + 1
    costs = list(per_centre.values())
    assert len(costs) >= 2 and min(costs[1:]) < costs[0]
    # Completed as planned (all held), the claimed poses are a robust core of the cap.
    for w in more:
        samples[w.point] = _held(w.point)
    in_cap = {p for p in samples if label_at[p] == 0}
    core = {p for p in in_cap if all(q in in_cap for q in hood[p])}
    assert {w.centre for w in more} <= core


def test_claims_skip_a_pose_whose_stored_neighbour_disagrees_and_keep_to_their_room() -> None:
    fine = _fine_points(LATTICE)
    label_at = {p: 0 for p in fine}
    samples = {p: _held(p) for p in fine if LATTICE.birth(p) == 0}
    manifolds = [certify.Manifold(0, tuple(sorted(samples)))]
    # One coarse point dropped: no centre whose N_δ ∪ {p} holds it is ever completed.
    bad = Point(LATTICE.scale(0) * 2, 0, 2, 0)
    _drop(samples, [bad])
    label_at[bad] = -1
    work = certify.claims(LATTICE, samples, label_at, manifolds, room=30, taken=set())
    assert 0 < len(work) <= 30
    assert all(bad != w.centre and bad not in neighbourhood(LATTICE, w.centre) for w in work)
    assert certify.claims(LATTICE, samples, label_at, manifolds, room=0, taken=set()) == []
    # A pose planned already (by key) is not planned again.
    taken = {work[0].pose.key()}
    again = certify.claims(LATTICE, samples, label_at, manifolds, room=30, taken=taken)
    assert work[0].pose.key() not in {w.pose.key() for w in again}


# --- through the store and the scheduler -----------------------------------------------
def _dropped(pose: Pose) -> PoseResult:
    return PoseResult(pose=pose, pose_key=pose.key(), outcome=Outcome.NO_GRASP, viable=False,
                      mu_s=0.0)


def _lone(pose: Pose) -> PoseResult:
    """Held at LONE only (to the key), dropped everywhere else."""
    if pose.key() != LATTICE.pose(LONE).key():
        return _dropped(pose)
    return oracle_result(pose).model_copy(update={"mu_s": 0.9})


def _cap(pose: Pose) -> PoseResult:
    """One grasp type of one quality held over the cap θ < 1.1 (the oracle's contacts and
    joints: they slide with the approach), dropped elsewhere except at LONE."""
    if pose.theta >= 1.1 and pose.key() != LATTICE.pose(LONE).key():
        return _dropped(pose)
    held = oracle_result(pose.model_copy(update={"phi": 0.1, "r": 0.0}))
    return held.model_copy(update={"pose": pose, "pose_key": pose.key(), "mu_s": 0.6})


def _explore(sessions, object_id: int, oracle, *, workers: int = 2, seed: int = 1,
             search_rounds: int = 3) -> int:
    spec = ExplorationSpec(object_id=object_id, grid=GRID, certification=RACE,
                           refinement={"levels": 1, "local_search_rounds": search_rounds})

    def evaluate(poses, match=None):  # type: ignore[no-untyped-def]
        return [oracle(p) for p in poses]

    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=20, max_poses=10**6).id
    run_local(sessions, evaluate, workers=workers, seed=seed, split=2)
    return eid


def _plan_of(sessions, eid: int) -> list[tuple[str, str]]:
    """(pose key, key of the pose it certifies) of every certification plan."""
    with sessions() as s:
        plans = certification_plans(s, eid)
        key_of = dict(s.execute(select(PoseRow.id, PoseRow.pose_key)
                                .where(PoseRow.id.in_(set(plans.values()) - {None}))).all())
    return sorted((k, "core" if c is None else key_of[c]) for k, c in plans.items())


def _sphere(sessions) -> int:
    with sessions() as s:
        return create_named(s, name="sphere", properties={}, shared_dir=None)[0].id


# SQLite only, to stay in the default suite (~1.5 s); the slow test below runs the same
# machinery on both databases.
def test_a_lone_held_pose_is_never_certified(sqlite_sessions) -> None:
    sessions = sqlite_sessions
    eid = _explore(sessions, _sphere(sessions), _lone)
    lone_key = LATTICE.pose(LONE).key()
    with sessions() as s:
        assert s.get(ExplorationRow, eid).status == "done"
        bests = certified_bests(s, eid)
        jitters = list(s.scalars(select(PoseRow).where(PoseRow.exploration_id == eid,
                                                       PoseRow.certifies == lone_key)))
        budget = exploration_budget(s, eid)
        # /best's ranking (rank=robust, the default): its top pose is not labelled robust.
        top = best_poses(s, eid, rank=Rank.ROBUST, limit=10)
        top_evidence = robust_evidence(s, eid, top)
        printed = robust_lines(robust_summary(s, eid))
    # It is the only grasp, so the only (large) manifold's candidate: its first look of draws
    # all dropped, so the upper bound fell below the level and the race stopped.
    assert [b.key for b in bests] == [lone_key]
    (best,) = bests
    assert best.neighbours == len(neighbourhood(LATTICE, LONE))
    assert (best.known, best.held) == (best.neighbours, 0)
    assert len(jitters) == FIRST and not any(j.viable for j in jitters)
    assert (best.jitters, best.jitters_held, best.p_success) == (FIRST, 0, 0.0)
    assert best.lower == 0.0 and best.upper is not None and best.upper < RACE.level
    assert not best.certified and best.robust_label != "robust"
    assert [r.pose_key for r in top] == [lone_key]  # the draws all dropped
    assert top_evidence[0].score.label != RobustLabel.ROBUST
    assert (top_evidence[0].certifying, top_evidence[0].certifying_held) == (FIRST, 0)
    # `graspscape explore` prints it so.
    assert "A: " in printed and f"P(success) 0/{FIRST} = 0.00, 95 % bounds [0.00, " \
        f"{best.upper:.2f}]; not certified: P < 0.9 at 95 %" in printed
    # Border refinement had evaluated its neighbours already: the certification's own
    # evaluations are the draws, and the budget counts them.
    plan = _plan_of(sessions, eid)
    assert {c for _, c in plan} == {lone_key}
    assert budget.certification_evaluations == len(plan) == FIRST


@pytest.mark.slow  # two whole explorations per database
def test_a_pose_inside_a_large_held_region_is_certified_and_the_plan_repeats(
        client, sessions, monkeypatch) -> None:
    object_id = _sphere(sessions)
    # No local search: certification follows refinement, which leaves the inside alone.
    eid = _explore(sessions, object_id, _cap, search_rounds=0)
    with sessions() as s:
        bests = certified_bests(s, eid)
    # One large manifold (the cap); LONE is dust and never returned.
    assert len(bests) == 1 and bests[0].key != LATTICE.pose(LONE).key()
    (best,) = bests
    # 48 straight successes: the sequential rule's lower bound clears 0.9 at its third look.
    assert best.certified and best.lower is not None and best.lower >= RACE.level
    assert best.jitters == best.jitters_held == success.LOOKS[2]
    # GET /best (rank=robust) answers the same grasp, with the same evidence.
    answer = client.get(f"/explorations/{eid}/best?rank=robust").json()["poses"][0]
    assert answer["pose_key"] == best.key
    assert answer["evidence"]["certifying"] == answer["evidence"]["certifying_held"] == \
        success.LOOKS[2]
    # GET /best (rank=p_success, the default): the certified grasp first, with k, n, bounds.
    default = client.get(f"/explorations/{eid}/best").json()
    assert default["rank"] == "p_success" and default["level"] == RACE.level
    first = default["poses"][0]
    assert first["pose_key"] == best.key
    assert (first["success"]["k"], first["success"]["n"]) == (success.LOOKS[2],) * 2
    assert first["success"]["certified"] and first["success"]["lower"] == best.lower
    # The manifold table carries the same grasp and numbers for its one large manifold.
    table = client.get(f"/explorations/{eid}/manifolds").json()["success"]
    assert list(table) == ["A"] and table["A"]["pose_key"] == best.key
    assert table["A"]["success"] == first["success"]
    row = client.get(f"/explorations/{eid}/export/manifolds.json").json()["table"][0]
    assert (row["p_success_best"], row["p_success_k"], row["certified"]) == (
        best.key, success.LOOKS[2], True)
    plan = _plan_of(sessions, eid)
    assert sum(1 for _, c in plan if c == best.key) == success.LOOKS[2]
    # Same spec, other worker count and report order: the same certification plan.
    again = _explore(sessions, object_id, _cap, workers=3, seed=7, search_rounds=0)
    assert _plan_of(sessions, again) == plan
    # A pick the map no longer ranks first (a later round can change the robust order) keeps
    # its draws: drawn members stay candidates. Here the order puts every other member first.
    real = racing.candidates

    def others_first(members, samples, scores, count):  # type: ignore[no-untyped-def]
        ranked = real(members, samples, scores, len(members))
        return [p for p in ranked if samples[p].key != best.key][:count]

    monkeypatch.setattr(racing, "candidates", others_first)
    with sessions() as s:
        (moved,) = certified_bests(s, eid)
    assert moved.key == best.key and moved.jitters == success.LOOKS[2] and moved.certified


def test_a_race_s_look_is_planned_whole_or_not_at_all() -> None:
    # Two candidates' draws up to their next look (12 each) and room for 20: the second look
    # would be cut to 8 draws, a count the sequential rule has no bound for, so it waits.
    works = [certify.Work(Pose(theta=0.5 + 0.01 * i, phi=0.1 * c, r=0.02), None, c, 0)
             for c in (1, 2) for i in range(success.LOOKS[0])]
    taken = certify._take(works, 20, set(), whole_groups=True)
    assert [w.centre for w in taken] == [1] * success.LOOKS[0]
    # Without looks (N_δ members), as many as fit.
    assert len(certify._take(works, 20, set(), whole_groups=False)) == 20
    # What was planned before is not planned again, and does not count against the room.
    seen = {w.pose.key() for w in works[:6]}
    assert len(certify._take(works, 18, seen, whole_groups=True)) == 18
