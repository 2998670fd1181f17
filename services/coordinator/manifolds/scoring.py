"""How good an explored robust map is, against the dense map of the same lattice (issue 18).

Pure: both maps are given as a manifold label per finest lattice point (−1: not viable) and
the samples each holds (the dense map every point; an explored run the poses it evaluated or
inferred through a shortcut), with the volume weight of every finest point. Robust success,
quality, labels and cores come from manifolds/robust.py. The scores:

- T1 robust cores: recall of the dense core (the union of every dense manifold's robust core)
  by the poses the run *claims* as core — a pose and its whole N_δ held by the run (evaluated
  or inferred) and in one run manifold — and the share of the claimed volume outside the dense
  core.
- T2 best robust grasp: the run's pick p̂ is the robust best it returns (`summary.robust_order`:
  robust before uncertain before fragile, then the highest q_δ over the known members, as
  `/best` ranks), scored on the dense grid: regret
  max q_δ − q_δ(p̂), membership of the dense top 5 % by q_δ (over every finest point, ties
  included), s_δ(p̂). Per large dense manifold the same within it, the run's pick taken from
  the run manifold matched to it (none matched: not found, regret counted as the manifold's
  best q_δ).
- T3 large manifolds: a dense manifold is found when the run manifold matched to it (one to
  one, greedily by overlap, largest first) covers at least half of its volume; the volume error
  of a found manifold is |V_run − V_dense| / V_dense, and the total viable volume's likewise.
- T4 honest marker: of the run's poses with a label other than uncertain, the share (by volume)
  whose label differs from the dense label; labelled coverage, the labelled volume the dense
  map says is viable over the dense viable volume; the Brier score of the run's s_δ against
  the dense s_δ over the run's scored poses.
- Diagnostics: the differing-pair shares of the dense samples per lattice level and the
  uncertainty exponent α = log2(share_coarse / share_fine) between levels (1 for a smooth
  border); the dense core share of the viable volume (the ceiling for T1); manifold IoU after
  a mode filter over N_δ ∪ {p} on both maps (and without it).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass

from graspscape.services.coordinator.manifolds.behaviour import StoredPose, differs
from graspscape.services.coordinator.manifolds.robust import (
    ROBUST_MIN,
    Neighbourhoods,
    RobustLabel,
    RobustScore,
    large_manifolds,
    score,
)
from graspscape.services.coordinator.manifolds.summary import robust_order
from graspscape.services.coordinator.mapspace.lattice import Lattice, Point

TOP_SHARE = 0.05  # T2: the dense top 5 % by q_δ
FOUND_COVER = 0.5  # T3: a matched run manifold covering this share of a dense one finds it
LARGE_SHARES = (0.05, 0.01)  # T3: "large" at ≥ 5 % and ≥ 1 % of the viable volume


@dataclass(frozen=True)
class MapLabels:
    """One map over the finest lattice: a manifold label for every finest point (−1: not
    viable) and the samples the map holds."""

    labels: Mapping[Point, int]
    samples: Mapping[Point, StoredPose]


@dataclass(frozen=True)
class CoreScores:  # T1
    dense_core_volume_share: float  # of the dense viable volume: the ceiling for T1
    recall: float | None  # None: the dense map has no core
    claimed_false_share: float | None  # None: the run claims no core
    claimed_volume_share: float  # of the dense viable volume


@dataclass(frozen=True)
class BestScores:  # T2
    regret: float | None  # None: the run scored no pose
    in_top: bool
    s_dense: float | None
    large_manifolds: int
    large_found: int  # with a matched run manifold to pick from
    large_regret_median: float | None
    large_regret_max: float | None
    large_passing: int  # regret ≤ 0.05, in the manifold's top 5 %, s_δ ≥ 0.9


@dataclass(frozen=True)
class ManifoldScores:  # T3
    large_5pct: int
    found_5pct: int
    large_1pct: int
    found_1pct: int
    volume_error_median: float | None  # over found manifolds ≥ 1 %
    volume_error_max: float | None
    viable_volume_error: float


@dataclass(frozen=True)
class MarkerScores:  # T4
    labelled_error: float | None
    labelled_coverage: float
    coverage_target: float  # max(0.5, dense core share + 0.10)
    brier: float | None


@dataclass(frozen=True)
class Diagnostics:
    differing_shares: dict[int, float]  # level → share of differing neighbour pairs
    alphas: dict[int, float]  # level → α between level − 1 and level
    iou: float
    iou_mode_filtered: float


@dataclass(frozen=True)
class RunScores:
    t1: CoreScores
    t2: BestScores
    t3: ManifoldScores
    t4: MarkerScores
    diagnostics: Diagnostics

    def figures(self, prefix: str = "") -> dict[str, float | int | bool | None]:
        """Flat figures ("t1.recall", ...) for a results file."""
        out: dict[str, float | int | bool | None] = {}
        for group, values in asdict(self).items():
            for key, value in values.items():
                if isinstance(value, dict):
                    for level, v in value.items():
                        out[f"{prefix}{group}.{key}.level{level}"] = _round(v)
                else:
                    out[f"{prefix}{group}.{key}"] = _round(value)
        return out


def _round(v):
    return round(v, 4) if isinstance(v, float) else v


def _total(points: Iterable[Point], weights: Mapping[Point, float]) -> float:
    return float(sum(weights[p] for p in points))


def _members(labels: Mapping[Point, int]) -> dict[int, list[Point]]:
    out: dict[int, list[Point]] = {}
    for p, label in labels.items():
        if label >= 0:
            out.setdefault(label, []).append(p)
    return out


class _Hood:
    """N_δ of every point asked, computed once (a score asks each point's several times)."""

    def __init__(self, lattice: Lattice, coarser: int) -> None:
        self._of = Neighbourhoods(lattice, coarser)
        self._known: dict[Point, list[Point]] = {}

    def __call__(self, p: Point) -> list[Point]:
        out = self._known.get(p)
        if out is None:
            out = self._known[p] = self._of(p)
        return out


def _scores(hood: _Hood, samples: Mapping[Point, StoredPose]) -> dict[Point, RobustScore]:
    """robust.robust_scores over every stored sample, with a shared neighbourhood cache."""
    return {p: score(s, [samples.get(q) for q in hood(p)]) for p, s in samples.items()}


def _core(hood: _Hood, m: MapLabels) -> set[Point]:
    """The union of robust.robust_core over the map's manifolds, counting only held samples:
    a point and its whole N_δ stored in the map and in one manifold."""
    return {p for p, label in m.labels.items() if label >= 0 and p in m.samples
            and all(m.labels.get(q, -1) == label and q in m.samples for q in hood(p))}


def core_points(lattice: Lattice, m: MapLabels, *, coarser: int = 0) -> set[Point]:
    """The union of the robust cores of a map's manifolds (`_core`)."""
    return _core(_Hood(lattice, coarser), m)


def match_manifolds(dense: Mapping[Point, int], run: Mapping[Point, int],
                    weights: Mapping[Point, float]) -> dict[int, tuple[int, float]]:
    """Dense label → (run label, overlap volume), one to one, greedily by overlap."""
    overlap: Counter[tuple[int, int]] = Counter()
    for p, d in dense.items():
        a = run.get(p, -1)
        if d >= 0 and a >= 0:
            overlap[(d, a)] += weights[p]
    matched: dict[int, tuple[int, float]] = {}
    used: set[int] = set()
    for (d, a), w in sorted(overlap.items(), key=lambda kv: (-kv[1], kv[0])):
        if d not in matched and a not in used:
            matched[d] = (a, w)
            used.add(a)
    return matched


def manifold_iou(dense: Mapping[Point, int], run: Mapping[Point, int],
                 weights: Mapping[Point, float]) -> float:
    """Volume where both maps are viable and in matched manifolds, over the volume where
    either is viable."""
    matched = {d: a for d, (a, _) in match_manifolds(dense, run, weights).items()}
    either = agree = 0.0
    for p, d in dense.items():
        a = run.get(p, -1)
        if d >= 0 or a >= 0:
            either += weights[p]
            if d >= 0 and a >= 0 and matched.get(d) == a:
                agree += weights[p]
    return agree / either if either > 0 else 1.0


def mode_filter(lattice: Lattice, labels: Mapping[Point, int], *, coarser: int = 0,
                hood: _Hood | None = None) -> dict[Point, int]:
    """Each point's label replaced by the most common label over N_δ(p) ∪ {p} (ties: p's own
    if it is among the most common, else the smallest)."""
    hood = hood or _Hood(lattice, coarser)
    out = {}
    for p, own in labels.items():
        counts = Counter(labels[q] for q in hood(p) if q in labels)
        counts[own] += 1
        top = max(counts.values())
        tied = [label for label, c in counts.items() if c == top]
        out[p] = own if own in tied else min(tied)
    return out


def differing_shares(lattice: Lattice, samples: Mapping[Point, StoredPose]) -> dict[int, float]:
    """Per level L: the share of level-L neighbour pairs (both sampled, both existing at L)
    that differ in viability or grasp type (behaviour.differs). A smooth border halves it
    from one level to the next."""
    shares = {}
    for level in range(lattice.depth + 1):
        seen: set[tuple[Point, Point]] = set()
        differ = 0
        for p, a in samples.items():
            if lattice.birth(p) > level:
                continue
            for _, q in lattice.neighbours(p, level):
                b = samples.get(q)
                pair = (p, q) if p < q else (q, p)
                if b is None or pair in seen:
                    continue
                seen.add(pair)
                differ += differs(a, b)
        shares[level] = differ / len(seen) if seen else 0.0
    return shares


def alphas(shares: Mapping[int, float]) -> dict[int, float]:
    """α = log2(share at level L − 1 / share at level L), where both are positive."""
    return {level: math.log2(shares[level - 1] / shares[level]) for level in sorted(shares)
            if level - 1 in shares and shares[level] > 0 and shares[level - 1] > 0}


def _pick(scores: Mapping[Point, RobustScore], samples: Mapping[Point, StoredPose],
          among: Iterable[Point]) -> Point | None:
    """The robust best the run returns among `among`: first by `summary.robust_order` (robust,
    uncertain, fragile, futile; then q_δ over the known members, μs, key), as `/best` and the
    manifold table rank."""
    pool = [p for p in among if p in scores]
    return min(pool, key=lambda p: robust_order(samples[p], scores[p])) if pool else None


def _top_threshold(values: list[float]) -> float:
    """The q a pose needs to be in the top TOP_SHARE of `values` (ties included)."""
    ordered = sorted(values, reverse=True)
    return ordered[max(0, math.ceil(TOP_SHARE * len(ordered)) - 1)]


def score_run(lattice: Lattice, weights: Mapping[Point, float], dense: MapLabels,
              run: MapLabels, *, coarser: int = 0, max_regret: float = 0.05) -> RunScores:
    """T1–T4 and the diagnostics of `run` against `dense` (module docstring). `weights`: the
    volume of every finest point; `dense.samples` must hold every finest point."""
    points = list(dense.labels)
    viable = [p for p in points if dense.labels[p] >= 0]
    viable_volume = _total(viable, weights)
    hood = _Hood(lattice, coarser)
    dense_scores = _scores(hood, dense.samples)
    run_scores = _scores(hood, run.samples)

    t1 = _core_scores(hood, dense, run, weights, viable_volume)
    q_dense = {p: dense_scores[p].q for p in points}  # T2
    pick = _pick(run_scores, run.samples, run_scores)
    best_q = max(q_dense.values(), default=0.0)
    threshold = _top_threshold(list(q_dense.values()))
    dense_members = _members(dense.labels)
    run_members = _members(run.labels)
    volumes = {label: _total(ms, weights) for label, ms in dense_members.items()}
    order = sorted(volumes)
    large = [order[i] for i in large_manifolds([volumes[k] for k in order], viable_volume)]
    matched = match_manifolds(dense.labels, run.labels, weights)
    regrets, passing, found = [], 0, 0
    for label in large:
        members = dense_members[label]
        best_here = max(q_dense[p] for p in members)
        a = matched.get(label)
        chosen = None if a is None else _pick(run_scores, run.samples, run_members[a[0]])
        if chosen is None:
            regrets.append(best_here)
            continue
        found += 1
        regret = best_here - q_dense[chosen]
        regrets.append(regret)
        top_here = _top_threshold([q_dense[p] for p in members])
        passing += (regret <= max_regret + 1e-12 and q_dense[chosen] >= top_here - 1e-12
                    and dense_scores[chosen].s >= ROBUST_MIN - 1e-12)
    regrets.sort()
    t2 = BestScores(
        regret=None if pick is None else best_q - q_dense[pick],
        in_top=pick is not None and q_dense[pick] >= threshold - 1e-12,
        s_dense=None if pick is None else dense_scores[pick].s,
        large_manifolds=len(large), large_found=found,
        large_regret_median=_median(regrets), large_regret_max=regrets[-1] if regrets else None,
        large_passing=passing,
    )

    run_volumes = {label: _total(ms, weights) for label, ms in run_members.items()}
    t3 = _manifold_scores(order, volumes, run_volumes, matched, viable_volume)
    # T4
    labelled = [p for p, s in run_scores.items() if s.label is not RobustLabel.UNCERTAIN]
    labelled_volume = _total(labelled, weights)
    wrong = _total((p for p in labelled if run_scores[p].label is not dense_scores[p].label),
                   weights)
    scored_volume = _total(run_scores, weights)
    t4 = MarkerScores(
        labelled_error=wrong / labelled_volume if labelled_volume else None,
        labelled_coverage=(_total((p for p in labelled if dense.labels[p] >= 0), weights)
                           / viable_volume if viable_volume else 0.0),
        coverage_target=max(0.5, t1.dense_core_volume_share + 0.10),
        brier=(sum(weights[p] * (s.s - dense_scores[p].s) ** 2 for p, s in run_scores.items())
               / scored_volume if scored_volume else None),
    )

    shares = differing_shares(lattice, dense.samples)
    diagnostics = Diagnostics(
        differing_shares=shares, alphas=alphas(shares),
        iou=manifold_iou(dense.labels, run.labels, weights),
        iou_mode_filtered=manifold_iou(mode_filter(lattice, dense.labels, hood=hood),
                                       mode_filter(lattice, run.labels, hood=hood), weights),
    )
    return RunScores(t1=t1, t2=t2, t3=t3, t4=t4, diagnostics=diagnostics)


def _core_scores(hood: _Hood, dense: MapLabels, run: MapLabels,
                 weights: Mapping[Point, float], viable_volume: float) -> CoreScores:
    """T1: the dense map's robust core against the core `run` claims, by volume."""
    dense_core = _core(hood, dense)
    claimed = _core(hood, run)
    core_volume = _total(dense_core, weights)
    claimed_volume = _total(claimed, weights)
    return CoreScores(
        dense_core_volume_share=core_volume / viable_volume if viable_volume else 0.0,
        recall=_total(claimed & dense_core, weights) / core_volume if core_volume else None,
        claimed_false_share=(_total(claimed - dense_core, weights) / claimed_volume
                             if claimed_volume else None),
        claimed_volume_share=claimed_volume / viable_volume if viable_volume else 0.0,
    )


def _manifold_scores(order: list[int], volumes: Mapping[int, float],
                     run_volumes: Mapping[int, float], matched: Mapping[int, tuple[int, float]],
                     viable_volume: float) -> ManifoldScores:
    """T3: the large dense manifolds `run` found (matched, covering enough) and their volumes."""
    counts = {}
    errors: list[float] = []
    for share in LARGE_SHARES:
        big = [k for k in order if volumes[k] >= share * viable_volume - 1e-15]
        hits = [k for k in big if k in matched and matched[k][1] >= FOUND_COVER * volumes[k]]
        counts[share] = (len(big), len(hits))
        if share == LARGE_SHARES[-1]:
            errors = sorted(abs(run_volumes[matched[k][0]] - volumes[k]) / volumes[k]
                            for k in hits)
    run_viable = sum(run_volumes.values())
    return ManifoldScores(
        large_5pct=counts[0.05][0], found_5pct=counts[0.05][1],
        large_1pct=counts[0.01][0], found_1pct=counts[0.01][1],
        volume_error_median=_median(errors), volume_error_max=errors[-1] if errors else None,
        viable_volume_error=(abs(run_viable - viable_volume) / viable_volume
                             if viable_volume else 0.0),
    )


def _median(values: list[float]) -> float | None:
    if not values:
        return None
    ordered = sorted(values)
    mid = len(ordered) // 2
    return ordered[mid] if len(ordered) % 2 else 0.5 * (ordered[mid - 1] + ordered[mid])
