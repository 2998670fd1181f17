"""Certification of the adaptive strategy's best grasps: what to evaluate, and what it proves.

Pure functions, no store (the strategy's hook is exploration/certify_store.py). After border
refinement and local search the map says which grasp looks best, but a pose's robust
quality q_δ and success share s_δ (manifolds/robust.py) are read over the neighbours N_δ the
exploration happened to evaluate: a lone held pose among unevaluated neighbours looks as good
as the middle of a large held region. Certification evaluates, per large manifold,

1. the missing members of N_δ of its current robust best (as /best ranks it) and of its
   best `candidates` poses by point quality (μs), and
2. once the robust best's N_δ is wholly known, K jitters of the user's stated pose error
   (σ_pos, σ_ang) around it: off-lattice poses drawn deterministically from the centre's key,

within a budget of `share` × the exploration's other planned poses, shared evenly among the
large manifolds in each round (`plan`). Each certification round is planned at a quiescent
point from every stored result, so the plan is a function of the stored results and the
spec (docs/exploration.md, "Determinism"); a round whose robust best changed (its neighbours
dropped) certifies the new one in the next round, until nothing is left to do or the budget
is spent.

A robust claim (`Evidence.certified`) needs the centre held, every member of N_δ known
(evaluated or shortcut-inferred), the robust label over N_δ ∪ {p} (s_δ ≥ 0.9), and, where
jitters were asked for, at least one evaluated and ≥ 90 % of them held with the centre's
grasp type.
"""

from __future__ import annotations

import hashlib
import math
import random
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.robust import (
    ROBUST_MIN,
    RobustLabel,
    RobustScore,
    neighbourhood,
)
from graspscape.services.coordinator.manifolds.summary import robust_order
from graspscape.shared.specs.exploration import CertificationSpec
from graspscape.shared.specs.pose import Pose

# The plan reason of a certification evaluation: "cert:<id of the centre's pose row>". The
# reason column is what a plan row has room for (16 characters; ids below 10¹¹), and it ties
# every certification evaluation to the grasp it certifies, across coordinator restarts.
REASON_PREFIX = "cert:"
# Certification rounds after local search at most: each waits for the round before it, and
# each one more certifies only robust bests that the round before disqualified.
MAX_ROUNDS = 4


def reason_for(centre_id: int) -> str:
    return f"{REASON_PREFIX}{centre_id}"


def centre_id_of(reason: str | None) -> int | None:
    """The centre's pose row id of a certification plan reason, else None."""
    if not reason or not reason.startswith(REASON_PREFIX):
        return None
    tail = reason[len(REASON_PREFIX):]
    return int(tail) if tail.isdigit() else None


@dataclass(frozen=True)
class Manifold:
    """One large manifold as certification sees it: its label and viable members."""

    label: int
    members: tuple[Point, ...]


@dataclass(frozen=True)
class Work:
    """One certification evaluation: a lattice member of N_δ (`point` set) or a jitter
    (`point` None), serving the certification of `centre` in manifold `label`."""

    pose: Pose
    point: Point | None
    centre: Point
    label: int


def robust_best(members: Iterable[Point], samples: Mapping[Point, StoredPose],
                scores: Mapping[Point, RobustScore]) -> Point | None:
    """The manifold's robust best as the map and /best rank it (manifolds/summary.py
    `robust_order`: robust before uncertain, fragile, futile; then by q_δ, μs, key)."""
    scored = [p for p in members if p in scores and samples[p].viable]
    if not scored:
        return None
    return min(scored, key=lambda p: robust_order(samples[p], scores[p]))


def point_best(members: Iterable[Point], samples: Mapping[Point, StoredPose], top: int
               ) -> list[Point]:
    """The `top` viable members by μs (ties: the smaller pose key)."""
    viable = [p for p in members if samples[p].viable]
    return sorted(viable, key=lambda p: (-samples[p].mu_s, samples[p].key))[:top]


def missing_neighbours(lattice: Lattice, samples: Mapping[Point, StoredPose], p: Point
                       ) -> list[Point]:
    return sorted(q for q in neighbourhood(lattice, p) if q not in samples)


def _seed(key: str, sigma_pos_m: float, sigma_ang_rad: float) -> int:
    text = f"{key}|{sigma_pos_m!r}|{sigma_ang_rad!r}".encode()
    return int.from_bytes(hashlib.sha256(text).digest()[:8], "big")


def jitters(pose: Pose, *, radius_m: float, sigma_pos_m: float, sigma_ang_rad: float,
            k: int) -> list[Pose]:
    """K poses of the stated error around `pose`, the same for the same pose and error (the
    first K of one sequence seeded by the pose key, so a larger K extends a smaller one).

    A position error e ~ N(0, σ_pos² I) of the gripper's start moves it along the approach
    line (r changes by e·u, reflected at 0: the hand cannot start inside the object) and
    across it (the approach direction turns to the point R·u + e_t, R the object's surface
    radius along u plus r); an attitude error w ~ N(0, σ_ang² I) adds to roll, pitch and yaw
    (pitch and yaw clipped to their ranges)."""
    if k <= 0 or (sigma_pos_m <= 0 and sigma_ang_rad <= 0):
        return []
    rng = random.Random(_seed(pose.key(), sigma_pos_m, sigma_ang_rad))
    st = math.sin(pose.theta)
    u = (st * math.cos(pose.phi), st * math.sin(pose.phi), math.cos(pose.theta))
    reach = radius_m + pose.r
    out = []
    for _ in range(k):
        e = [rng.gauss(0.0, sigma_pos_m) for _ in range(3)]
        w = [rng.gauss(0.0, sigma_ang_rad) for _ in range(3)]
        along = sum(a * b for a, b in zip(e, u, strict=True))
        v = [reach * u[i] + e[i] - along * u[i] for i in range(3)]
        norm = math.sqrt(sum(c * c for c in v))
        theta = math.acos(max(-1.0, min(1.0, v[2] / norm)))
        phi = math.atan2(v[1], v[0]) % (2 * math.pi)
        out.append(Pose(
            theta=theta, phi=phi, r=min(1.0, abs(pose.r + along)),
            roll=(pose.roll + w[0]) % (2 * math.pi),
            pitch=max(-math.pi, min(math.pi, pose.pitch + w[1])),
            yaw=max(-math.pi / 2, min(math.pi / 2, pose.yaw + w[2])),
        ))
    return out


def budget(spec: CertificationSpec, other_planned: int) -> int:
    """The whole certification's budget: `share` of the exploration's other planned poses."""
    return math.floor(spec.share * other_planned + 1e-9)


def plan(
    lattice: Lattice,
    samples: Mapping[Point, StoredPose],
    manifolds: Sequence[Manifold],
    scores: Mapping[Point, RobustScore],
    spec: CertificationSpec,
    *,
    budget_left: int,
    taken: set[str],
    radius_m: Callable[[Point], float],
) -> list[Work]:
    """One certification round over the large `manifolds` (the map's `large` flag: ≥ 1 % of
    the viable volume, manifolds/robust.large_manifolds).

    `budget_left`: what the whole certification may still cost; `taken`: pose keys planned
    or stored already. Two passes, each over the manifolds in order — the one holding the
    overall robust best first, then by label (largest first) — and each giving a manifold
    an even share of what is left (rounded up) among the manifolds still to come:
    1. the returned grasps: the missing N_δ of each robust best, or, once that is wholly
       known, its K jitters (those not planned yet);
    2. the missing N_δ of each manifold's point-best candidates, in order."""
    left = budget_left
    bests = {m.label: robust_best(m.members, samples, scores) for m in manifolds}
    ranked = [b for b in bests.values() if b is not None]
    if not ranked or left <= 0:
        return []
    top = min(ranked, key=lambda p: robust_order(samples[p], scores[p]))
    order = sorted((m for m in manifolds if bests[m.label] is not None),
                   key=lambda m: (bests[m.label] != top, m.label))
    seen = set(taken)
    out: list[Work] = []

    def returned(m: Manifold, best: Point) -> list[Work]:
        missing = missing_neighbours(lattice, samples, best)
        if missing:
            return [Work(lattice.pose(q), q, best, m.label) for q in missing]
        shaken = jitters(lattice.pose(best), radius_m=radius_m(best),
                         sigma_pos_m=spec.pose_error_mm / 1000,
                         sigma_ang_rad=math.radians(spec.pose_error_deg), k=spec.jitters)
        return [Work(pose, None, best, m.label) for pose in shaken]

    def candidates(m: Manifold, best: Point) -> list[Work]:
        return [Work(lattice.pose(q), q, p, m.label)
                for p in point_best(m.members, samples, spec.candidates) if p != best
                for q in missing_neighbours(lattice, samples, p)]

    for wanted in (returned, candidates):
        for i, m in enumerate(order):
            room = -(-left // (len(order) - i))  # ceil: the first ones get the remainder
            for w in wanted(m, bests[m.label]):  # type: ignore[arg-type]
                if room <= 0:
                    break
                if w.pose.key() not in seen:
                    seen.add(w.pose.key())
                    out.append(w)
                    room -= 1
                    left -= 1
    return out


@dataclass(frozen=True)
class Evidence:
    """What backs (or refutes) a robust claim about one pose."""

    neighbours: int  # |N_δ|
    known: int  # members of N_δ stored (evaluated or shortcut-inferred)
    evaluated: int  # of those, simulated for this pose's own key (no coordinator copy)
    held: int  # known members held with the pose's grasp type
    jitters: int  # stored jitters of the stated pose error around it
    jitters_held: int  # of those, held with its grasp type
    s: float | None  # s_δ over the known N_δ ∪ {p}
    label: str | None  # the robust label
    certified: bool  # the claim: robust, and backed by evaluated neighbours (module doc)


def evidence(lattice: Lattice, samples: Mapping[Point, StoredPose], p: Point,
             score: RobustScore | None, shaken: Sequence[StoredPose], *, jitters_asked: bool
             ) -> Evidence:
    centre = samples.get(p)
    members = neighbourhood(lattice, p)
    known = [samples[q] for q in members if q in samples]

    def holds(b: StoredPose) -> bool:  # held with the centre's grasp type (robust.py's test)
        return centre is not None and centre.viable and b.viable and b.digits == centre.digits

    held = sum(1 for b in known if holds(b))
    jitters_held = sum(1 for b in shaken if holds(b))
    complete = centre is not None and centre.viable and len(known) == len(members)
    robust = score is not None and score.label == RobustLabel.ROBUST
    jitter_ok = not jitters_asked or (bool(shaken) and jitters_held >= ROBUST_MIN * len(shaken))
    return Evidence(
        neighbours=len(members), known=len(known),
        evaluated=sum(1 for b in known if not b.source.startswith("shortcut:")
                      or b.source == "shortcut:configuration"),
        held=held, jitters=len(shaken), jitters_held=jitters_held,
        s=None if score is None else score.s,
        label=None if score is None else str(score.label),
        certified=complete and robust and jitter_ok,
    )
