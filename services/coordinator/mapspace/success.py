"""P(success) of a grasp under a stated uncertainty model: bounds, a sequential rule, racing.

Pure statistics (numpy/scipy), no store, no simulation. A *draw* is one simulated grasp from a
start pose perturbed by the uncertainty model (shared/specs/uncertainty.py); it succeeds when
the grasp holds along the reference trajectory with the centre's grasp type. k successes of n
draws estimate the pose's success probability P.

**Bounds: Clopper–Pearson (exact).** The one-sided lower bound at level α is the α quantile of
Beta(k, n − k + 1), the upper bound the 1 − α quantile of Beta(k + 1, n − k). Chosen over
Wilson because good grasps live at P near 1, where Wilson's interval is liberal for small n
(its coverage dips below nominal) and a certification must never over-claim; Clopper–Pearson
never covers less than its nominal level, at the price of a few more draws. Wald's interval is
not used (8/8 gives it zero width).

**Sequential rule (honest under optional stopping).** Draws are taken in planned looks
`LOOKS` = 12, 24, 48, 96 draws (cumulative). At look j the bounds are computed at level
α_j = α / len(LOOKS) per side (Bonferroni α-spending over the planned looks), and the reported
bound is the best one so far (the running max of lower bounds, min of upper bounds). By the
union bound the chance that the lower bound ever exceeds P, at any look, is ≤ Σ α_j = α, so
the lower bound is a valid 1 − α bound whenever sampling stops — whatever rule decided to stop
(certified, refuted, budget spent, a racing decision). The same holds for the upper bound; each
is a one-sided 95 % bound, so [lower, upper] together is a 90 % interval. Sampling a candidate
stops when its lower bound reaches the level (certified), its upper bound falls below it
(refuted: it cannot be certified), the last look is reached, or its budget is spent. A stop
between looks (the budget ran out mid-look) uses the bound of the last completed look.

What it costs: with α = 0.05 and 4 looks, 48 straight successes give a lower bound of 0.913,
so certifying P ≥ 0.9 takes ≥ 48 draws (a fixed-n test would take 29 but loses its meaning
once it is looked at early).

**Racing (LUCB).** Within one manifold, candidates race for a shared budget as a best-arm
identification (Kalyanakrishnan et al. 2012): the leader is the candidate with the highest
lower bound (then point estimate), the challenger the other with the highest upper bound;
both are sampled to their next look, until the leader's lower bound clears the challenger's
upper bound, or the leader is decided against the level and no challenger can still beat it.
Candidates whose upper bound is below the leader's lower bound are dropped. Racing only decides
*which* candidates get draws; each candidate's bounds stay valid by the rule above.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import beta

# Cumulative draws at each planned look.
LOOKS: tuple[int, ...] = (12, 24, 48, 96)
CONFIDENCE = 0.95
LEVEL = 0.9


def lower_bound(k: int | np.ndarray, n: int | np.ndarray, alpha: float) -> np.ndarray | float:
    """One-sided Clopper–Pearson lower bound at level α (0 where k = 0 or n = 0)."""
    k, n = np.asarray(k, dtype=float), np.asarray(n, dtype=float)
    with np.errstate(invalid="ignore"):
        out = np.where(k > 0, beta.ppf(alpha, np.maximum(k, 1), n - k + 1), 0.0)
    return out if out.ndim else float(out)


def upper_bound(k: int | np.ndarray, n: int | np.ndarray, alpha: float) -> np.ndarray | float:
    """One-sided Clopper–Pearson upper bound at level α (1 where k = n)."""
    k, n = np.asarray(k, dtype=float), np.asarray(n, dtype=float)
    with np.errstate(invalid="ignore"):
        out = np.where(k < n, beta.ppf(1 - alpha, k + 1, np.maximum(n - k, 1)), 1.0)
    return out if out.ndim else float(out)


def look_alpha(confidence: float = CONFIDENCE, looks: Sequence[int] = LOOKS) -> float:
    """α_j: each side's error spent at one look."""
    return (1.0 - confidence) / len(looks)


@dataclass(frozen=True)
class Estimate:
    """What the draws of one candidate say about its P(success)."""

    k: int  # successes (held with the centre's grasp type)
    n: int  # draws
    p: float  # k / n (0 where n = 0)
    lower: float  # anytime-valid one-sided lower bound (module doc)
    upper: float  # anytime-valid one-sided upper bound
    certified: bool  # lower ≥ level
    refuted: bool  # upper < level: it cannot be certified under this model
    done: bool  # no more draws wanted: certified, refuted or at the last look


def estimate(outcomes: Sequence[bool], *, level: float = LEVEL,
             confidence: float = CONFIDENCE, looks: Sequence[int] = LOOKS) -> Estimate:
    """The bounds of a sequence of draws, read at every completed look in order (the draws'
    order matters: draw i is the i-th of the pose's seeded sequence)."""
    a = look_alpha(confidence, looks)
    lo, hi = 0.0, 1.0
    x = np.asarray(outcomes, dtype=bool)
    for m in looks:
        if m > len(x):
            break
        k = int(x[:m].sum())
        lo, hi = max(lo, lower_bound(k, m, a)), min(hi, upper_bound(k, m, a))
    n, k = len(x), int(x.sum())
    return Estimate(k=k, n=n, p=k / n if n else 0.0, lower=float(lo), upper=float(hi),
                    certified=lo >= level, refuted=hi < level and lo < level,
                    done=lo >= level or hi < level or n >= looks[-1])


def next_look(n: int, looks: Sequence[int] = LOOKS) -> int | None:
    """The draws a candidate with n draws should have after its next look (None: none left)."""
    return next((m for m in looks if m > n), None)


def race(estimates: Sequence[Estimate], *, looks: Sequence[int] = LOOKS) -> list[int]:
    """One LUCB step over a manifold's candidates: the indices to sample to their next look
    (empty: the race is decided). The leader is the undone-or-not candidate with the highest
    lower bound (then p, then the lower index); the challenger the other live candidate with
    the highest upper bound. A candidate is live while it is not `done` and its upper bound is
    above the leader's lower bound."""
    if not estimates:
        return []
    leader = max(range(len(estimates)),
                 key=lambda i: (estimates[i].lower, estimates[i].p, -i))
    lead = estimates[leader]
    live = [i for i, e in enumerate(estimates)
            if i != leader and not e.done and e.upper > lead.lower
            and next_look(e.n, looks) is not None]
    out: list[int] = []
    if not lead.done and next_look(lead.n, looks) is not None:
        out.append(leader)
    if live:
        challenger = max(live, key=lambda i: (estimates[i].upper, estimates[i].p, -i))
        out.append(challenger)
    return out


def simulate_coverage(p: np.ndarray, runs: int, rng: np.random.Generator, *,
                      level: float = LEVEL, confidence: float = CONFIDENCE,
                      looks: Sequence[int] = LOOKS) -> dict[str, np.ndarray]:
    """The sequential rule on simulated Bernoulli arms (vectorised): `runs` runs of each arm of
    success probability p[i], each stopped by the real rule (`estimate`'s looks). Returns per
    arm the share of runs whose final lower bound ≤ p, whose upper bound ≥ p, that were
    certified, and the mean draws at the stop."""
    a = look_alpha(confidence, looks)
    arms = len(p)
    x = rng.random((arms, runs, looks[-1])) < p[:, None, None]
    counts = np.cumsum(x, axis=2)
    lo = np.zeros((arms, runs))
    hi = np.ones((arms, runs))
    n = np.zeros((arms, runs), dtype=int)
    active = np.ones((arms, runs), dtype=bool)
    for m in looks:
        k = counts[:, :, m - 1]
        lo = np.where(active, np.maximum(lo, lower_bound(k, m, a)), lo)
        hi = np.where(active, np.minimum(hi, upper_bound(k, m, a)), hi)
        n = np.where(active, m, n)
        active &= (lo < level) & (hi >= level)
    return {
        "lower_covers": (lo <= p[:, None]).mean(axis=1),
        "upper_covers": (hi >= p[:, None]).mean(axis=1),
        "certified": (lo >= level).mean(axis=1),
        "mean_draws": n.mean(axis=1),
    }
