"""Sequential certification of P(success) in the adaptive strategy's rounds (pure functions).

Per large manifold, the robust map chooses the candidates: its best `count` members by the
robust order (robust before uncertain, fragile, futile; then q_δ, μs — high s_δ and q_δ, deep
in the manifold). Each candidate's draws are the poses of its seeded sequence under the
exploration's uncertainty model (shared/specs/uncertainty.py): draw i of the centre's key,
the start moved by the draw's pose error. A draw succeeds when it is stored held with the
centre's grasp type (the digits in contact). Each round, the race (mapspace/success.py:
LUCB over anytime-valid Clopper–Pearson bounds) names the candidates to sample, and each is
planned up to its next look; the round after reads what was stored.

A draw is evaluated outcome only (workers/sim/samples.py), at its start pose, under its
friction, mass and effort scales, in each engine the model lists; it succeeds where it held
with the centre's grasp type in every one of them (mapspace/draws.success_of).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from graspscape.services.coordinator.exploration.lattice import Point
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.robust import RobustScore
from graspscape.services.coordinator.manifolds.summary import robust_order
from graspscape.services.coordinator.mapspace import success
from graspscape.services.coordinator.mapspace.draws import (  # noqa: F401  (the race's vocabulary)
    draw_poses,
    outcomes,
    scales_of,
    success_of,
)
from graspscape.shared.specs.pose import Pose


def candidates(members: Sequence[Point], samples: Mapping[Point, StoredPose],
               scores: Mapping[Point, RobustScore], count: int) -> list[Point]:
    """The manifold's best `count` viable members by the robust order."""
    scored = [p for p in members if p in scores and samples[p].viable]
    return sorted(scored, key=lambda p: robust_order(samples[p], scores[p]))[:count]


@dataclass(frozen=True)
class Candidate:
    point: Point
    sequence: tuple[Pose, ...]  # the first `success.LOOKS[-1]` draws' start poses
    estimate: success.Estimate


def assess(points: Sequence[Point], samples: Mapping[Point, StoredPose],
           sequence: Callable[[Point], Sequence[Pose]], stored: Mapping[str, StoredPose],
           *, level: float, engines: Sequence[str] | None = None) -> list[Candidate]:
    """Each candidate's estimate from its stored draws (successes in each of `engines`)."""
    out = []
    for p in points:
        seq = tuple(sequence(p))
        done = outcomes(samples[p], seq, stored, engines)
        out.append(Candidate(p, seq, success.estimate(done, level=level)))
    return out


def race_round(cands: Sequence[Candidate]) -> list[tuple[Point, list[Pose]]]:
    """The draws one round plans for a manifold: the race's chosen candidates, each up to its
    next look (the draws not stored yet)."""
    return [(p, [q for _, q in drawn]) for p, drawn in race_draws(cands)]


def race_draws(cands: Sequence[Candidate]) -> list[tuple[Point, list[tuple[int, Pose]]]]:
    """`race_round` with each draw's index in its centre's sequence (its scales' seed)."""
    out = []
    for i in success.race([c.estimate for c in cands]):
        c = cands[i]
        target = success.next_look(c.estimate.n)
        if target is not None:
            out.append((c.point, list(enumerate(c.sequence))[c.estimate.n:target]))
    return out


def best(cands: Sequence[Candidate]) -> Candidate | None:
    """The manifold's pick by P(success): the highest lower bound, then k/n, with draws."""
    drawn = [c for c in cands if c.estimate.n]
    return max(drawn, key=lambda c: (c.estimate.lower, c.estimate.p), default=None)
