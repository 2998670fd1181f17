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
large manifolds in each round (`plan`); and

3. core claims (`claims`): the missing members of N_δ ∪ {p} around poses deep inside large
   manifolds, so that the robust core is claimed where it is (a claim needs p and its whole
   N_δ known and in one manifold, manifolds/robust.robust_core), with `core_share` of the
   budget at least (certify_store.certification_round splits it).

Each certification round is planned at a quiescent point from every stored result, so the plan
is a function of the stored results and the spec (docs/design/exploration.md, "Determinism"); a
round whose robust best changed (its neighbours dropped) certifies the new one in the next round,
until nothing is left to do or the budget is spent.

A robust claim (`Evidence.certified`) needs the centre held, every member of N_δ known
(evaluated or shortcut-inferred), the robust label over N_δ ∪ {p} (s_δ ≥ 0.9), and, where
jitters were asked for, at least one evaluated and ≥ 90 % of them held with the centre's
grasp type.
"""

from __future__ import annotations

import hashlib
import heapq
import math
import random
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.robust import (
    ROBUST_MIN,
    Neighbourhoods,
    RobustLabel,
    RobustScore,
    neighbourhood,
)
from graspscape.services.coordinator.manifolds.summary import robust_order
from graspscape.shared.specs.exploration import CertificationSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import DrawScales

# The plan reason of a certification evaluation: "cert:<id of the centre's pose row>". The
# reason column is what a plan row has room for (16 characters; ids below 10¹¹), and it ties
# every certification evaluation to the grasp it certifies, across coordinator restarts.
REASON_PREFIX = "cert:"
# The plan reason of a core-claim evaluation: it serves a claim about the poses around it, not
# one pose row (its centre may not be stored yet).
CLAIM_REASON = f"{REASON_PREFIX}core"
# Certification rounds after local search at most: each waits for the round before it, and
# each one more certifies only robust bests that the round before disqualified.
MAX_ROUNDS = 8


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
    claim: bool = False  # a core claim's evaluation (`claims`), not a returned grasp's
    scales: DrawScales | None = None  # a race's draw: its friction, mass and effort scales


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
    race: Callable[[Manifold], list[Work]] | None = None,
) -> list[Work]:
    """One certification round over the large `manifolds` (the map's `large` flag: ≥ 1 % of
    the viable volume, manifolds/robust.large_manifolds).

    `budget_left`: what the whole certification may still cost; `taken`: pose keys planned
    or stored already. Two passes, each over the manifolds in order — the one holding the
    overall robust best first, then by label (largest first) — and each giving a manifold
    an even share of what is left (rounded up) among the manifolds still to come:
    1. the returned grasps: with `race` (exploration/racing.py), the draws of the uncertainty
       model its race plans for the manifold's candidates; without, the missing N_δ of each
       robust best, or, once that is wholly known, its K jitters (those not planned yet);
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
        if race is not None:
            return race(m)
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
            works = wanted(m, bests[m.label])  # type: ignore[arg-type]
            whole = race is not None and wanted is returned
            taken_now = _take(works, room, seen, whole_groups=whole)
            out += taken_now
            left -= len(taken_now)
    return out


def _take(works: Sequence[Work], room: int, seen: set[str], *,
          whole_groups: bool) -> list[Work]:
    """The works not seen yet, at most `room`. With `whole_groups` a centre's works are taken
    all or none: a race's draws for a candidate run up to its next look, and a look cut short
    gives a count the sequential rule has no bound for (n = 11 of a look at 12 reads [0, 1])."""
    groups: dict[Point | None, list[Work]] = {}
    fresh: set[str] = set()
    for w in works:
        key = w.pose.key()
        if key not in seen and key not in fresh:
            fresh.add(key)
            groups.setdefault(w.centre if whole_groups else None, []).append(w)
    out: list[Work] = []
    for group in groups.values():
        if whole_groups and len(group) > room:
            continue
        for w in group[:room]:
            seen.add(w.pose.key())
            out.append(w)
        room -= min(room, len(group))
    return out


def depths(hood: Callable[[Point], Iterable[Point]], label_at: Mapping[Point, int],
           inside: set[int]) -> dict[Point, int]:
    """Steps of N_δ from each point labelled with one of `inside` to the nearest point of
    another label (−1, not viable, included): 1 where a member of its own N_δ differs. Points
    of a manifold with no such point anywhere get none (the caller ranks them deepest)."""
    out: dict[Point, int] = {}
    queue: deque[Point] = deque()
    for p, label in label_at.items():
        if label in inside and any(label_at.get(q, -1) != label for q in hood(p)):
            out[p] = 1
            queue.append(p)
    while queue:
        p = queue.popleft()
        for q in hood(p):
            if q not in out and label_at.get(q, -1) == label_at[p]:
                out[q] = out[p] + 1
                queue.append(q)
    return out


def claims(lattice: Lattice, samples: Mapping[Point, StoredPose], label_at: Mapping[Point, int],
           manifolds: Sequence[Manifold], *, room: int, taken: set[str],
           start_below: int | None = None) -> list[Work]:
    """Core claims (pass 3): evaluations that complete N_δ ∪ {p} around poses deep inside the
    large `manifolds`, at most `room` of them; a new candidate is started only while fewer
    than `start_below` (default `room`) are planned, so a round can keep part of the room for
    the next one without leaving a candidate too dear for its half.

    `label_at`: the map's label of every finest point (−1: not viable), the interpolated one
    where a point is not stored. A candidate p lies in a large manifold and every member of
    N_δ ∪ {p} carries its label, stored or interpolated: no evaluated neighbour disagrees.
    Candidates are taken greedily, cheapest first — the fewest members still unknown and not
    yet planned, so a claim next to one already planned costs one or two evaluations and the
    claims grow as blocks — then the deepest (`depths`: the farthest from any other label,
    where the interpolated map is least likely wrong), then the larger manifold. A candidate
    is completed whole or not at all: a part of N_δ claims nothing. Whether the claim holds
    is for the results to say: a member that lands elsewhere breaks it, and the next round
    plans from the new map."""
    if room <= 0:
        return []
    large = {m.label: i for i, m in enumerate(manifolds)}  # manifolds come largest first
    hood = Neighbourhoods(lattice)
    deep = depths(hood, label_at, set(large))
    seen = set(taken)
    planned: set[Point] = set()

    def need(p: Point) -> list[Point]:
        return [q for q in (p, *sorted(hood(p))) if q not in samples and q not in planned]

    heap = []
    for p, label in label_at.items():
        if label not in large or (p in deep and deep[p] < 2):
            continue  # a member of N_δ ∪ {p} carries another label
        todo = need(p)
        if todo:
            heap.append((len(todo), -deep.get(p, 1 << 20), large[label], p))
    heapq.heapify(heap)
    out: list[Work] = []
    start_below = room if start_below is None else min(room, start_below)
    while heap and room > 0 and len(out) < start_below:
        cost, depth, rank, p = heapq.heappop(heap)
        todo = need(p)
        if len(todo) < cost:  # members planned since it was ranked: rank it again
            if todo:
                heapq.heappush(heap, (len(todo), depth, rank, p))
            continue
        if len(todo) > room:
            continue
        for q in todo:
            planned.add(q)
            key = lattice.pose(q).key()
            if key not in seen:
                seen.add(key)
                out.append(Work(lattice.pose(q), q, p, label_at[p], claim=True))
                room -= 1
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
