"""The robust map: robust success and quality of a pose over its pose-error neighbourhood (pure).

A behavioral map with structure at every scale (fractal-like borders, issue 18) cannot be
trusted pose by pose: a robot lands somewhere within its pose error of the pose it aimed at.
This module scores every pose by what happens around it, on the lattice itself:

- N_δ(p), the neighbourhood (`neighbourhood`): the finest-level lattice neighbours of p —
  its *position* neighbours at the same attitude (the next r level in and out, the next
  azimuth either way on its ring, the points of the rings just above and below whose cells
  overlap p's: `Lattice.neighbours` at the finest level) and its *attitude* neighbours at the
  same position (the next roll either way, the tilt variants: `Lattice.attitude_neighbours`).
  These are the poses one finest step δ away along one axis of the pose space, the poses a
  robot whose pose error is about one step may reach instead of p. Diagonal combinations
  (another position *and* another attitude) are two steps away and left out.
  With `coarser=c` it is the ball of 2^c such steps in that graph (a position step and an
  attitude step each count one): every pose within an error of 2^c·δ, diagonals included —
  "one coarser step" is coarser=1, an error of about 2δ.
- Target grasp type of p: p's own grasp type (the set of digits in contact, the notion every
  explorer shares: exploration/accounting.py) when p holds; else the most common grasp type
  among the held known members of N_δ(p) (ties: the smaller sorted digit tuple); none if no
  known member holds.
- Robust success s_δ(p): the share of the KNOWN members of N_δ(p) ∪ {p} held with the target
  type. Robust quality q_δ(p): the mean over the same known members of μs, 0 for a drop or
  another grasp type — the grasp function smoothed by the pose-error kernel (Johns,
  Leutenegger & Davison 2016; Weisz & Allen 2012; Dex-Net's robust metrics).
- Bounds: s_low counts every unknown member (not stored) as a failure, s_high as a success,
  both over the whole N_δ(p) ∪ {p}. Known members include shortcut-inferred poses (they are
  poses of the map).
- Label (Rubert, Kappler, Bohg & Morales 2018): robust s ≥ ROBUST_MIN, futile s ≤ FUTILE_MAX,
  fragile between. The label is given only where the unknown members cannot change it: the
  label of s_low and that of s_high agree; otherwise `uncertain`.
- Robust core of a manifold (`robust_core`): its members whose whole N_δ is stored and in the
  same manifold.
- Large manifold (`large_manifolds`): volume ≥ 1 % of the viable volume; the rest is dust,
  counted and shown as one entry (`dust`).
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum

from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.mapspace.lattice import Lattice, Point

ROBUST_MIN = 0.9
FUTILE_MAX = 0.1
LARGE_SHARE = 0.01  # of the viable volume: a manifold this large is "large", else dust


class RobustLabel(StrEnum):
    ROBUST = "robust"  # s ≥ ROBUST_MIN over the neighbourhood
    FRAGILE = "fragile"  # between
    FUTILE = "futile"  # s ≤ FUTILE_MAX
    UNCERTAIN = "uncertain"  # the unknown neighbours could change the label


def label_of_share(s: float) -> RobustLabel:
    """The label a known share s gives (no unknowns)."""
    if s >= ROBUST_MIN - 1e-12:
        return RobustLabel.ROBUST
    if s <= FUTILE_MAX + 1e-12:
        return RobustLabel.FUTILE
    return RobustLabel.FRAGILE


def _position_ball(lattice: Lattice, p: Point, hops: int) -> dict[Point, int]:
    """Positions (at attitude 0) within `hops` finest position steps of p's, with distances."""
    start = Point(p.ring, p.azimuth, p.r_index, 0)
    dist = {start: 0}
    queue = deque([start])
    while queue:
        x = queue.popleft()
        if dist[x] == hops:
            continue
        for _, y in lattice.neighbours(x, lattice.depth):
            if y not in dist:
                dist[y] = dist[x] + 1
                queue.append(y)
    return dist


def _attitude_ball(lattice: Lattice, attitude: int, hops: int) -> dict[int, int]:
    """Attitudes within `hops` attitude steps of `attitude`, with distances."""
    dist = {attitude: 0}
    queue = deque([attitude])
    while queue:
        a = queue.popleft()
        if dist[a] == hops:
            continue
        for q in lattice.attitude_neighbours(Point(0, 0, 0, a)):
            if q.attitude not in dist:
                dist[q.attitude] = dist[a] + 1
                queue.append(q.attitude)
    return dist


class Neighbourhoods:
    """N_δ of many points (`neighbourhood` for each, unsorted): the position and attitude
    balls are computed once each (position neighbours do not depend on the attitude, attitude
    neighbours not on the position). Keep one per lattice and δ where many points are asked."""

    def __init__(self, lattice: Lattice, coarser: int = 0) -> None:
        if coarser < 0:
            raise ValueError("coarser must be ≥ 0")
        self.lattice = lattice
        self.hops = 1 << coarser
        self._pos: dict[tuple[int, int, int], list[tuple[int, int, int, int]]] = {}
        self._att: dict[int, list[tuple[int, ...]]] = {}

    def __call__(self, p: Point) -> list[Point]:
        # Every position x of the ball (sorted, with its distance dx) with every attitude a of
        # the attitude ball (sorted) where dx + da ≤ hops, p itself left out. Per attitude,
        # the attitudes allowed at each dx are listed once (`_att`, in sorted order), so this
        # is one flat comprehension making the same points in the same order.
        ring, azimuth, r_index, attitude = p
        pos = self._pos.get((ring, azimuth, r_index))
        if pos is None:
            pos = [(*x[:3], dx)
                   for x, dx in sorted(_position_ball(self.lattice, p, self.hops).items())]
            self._pos[(ring, azimuth, r_index)] = pos
        att = self._att.get(attitude)
        if att is None:
            ball = sorted(_attitude_ball(self.lattice, attitude, self.hops).items())
            att = [tuple(a for a, da in ball if dx + da <= self.hops and (dx or da))
                   for dx in range(self.hops + 1)]
            self._att[attitude] = att
        new = tuple.__new__
        return [new(Point, (K, J, i, a)) for K, J, i, dx in pos for a in att[dx]]


def neighbourhood(lattice: Lattice, p: Point, *, coarser: int = 0) -> list[Point]:
    """N_δ(p) without p, sorted (module docstring): the finest-level position neighbours at
    p's attitude and the attitude neighbours at p's position; with `coarser=c`, every point
    within 2^c such steps."""
    return sorted(Neighbourhoods(lattice, coarser)(p))


@dataclass(frozen=True)
class RobustScore:
    """Robust success and quality of one pose over N_δ(p) ∪ {p} (module docstring)."""

    s: float  # share of the known members held with the target type
    q: float  # mean μs of the known members, 0 for drops and other types
    s_low: float  # unknown members counted as failures
    s_high: float  # unknown members counted as successes
    label: RobustLabel
    known: int  # members of N_δ(p) ∪ {p} stored
    total: int  # members of N_δ(p) ∪ {p}
    target: tuple[str, ...] | None = None  # the target grasp type (sorted digits), if any


def target_type(sample: StoredPose, neighbours: Iterable[StoredPose]) -> frozenset[str] | None:
    """p's own grasp type if p holds, else the most common type among held neighbours."""
    if sample.viable:
        return sample.digits
    counts = Counter(n.digits for n in neighbours if n.viable)
    if not counts:
        return None
    return min(counts, key=lambda d: (-counts[d], sorted(d)))


def score(sample: StoredPose, members: Sequence[StoredPose | None]) -> RobustScore:
    """The robust score of a pose from its own sample and those of N_δ (None: not stored)."""
    known = [m for m in members if m is not None]
    target = target_type(sample, known)
    group = [sample, *known]
    held = [m for m in group if m.viable and target is not None and m.digits == target]
    total = 1 + len(members)
    unknown = total - len(group)
    n_held = len(held)
    s = n_held / len(group)
    q = sum(m.mu_s for m in held) / len(group)
    s_low = n_held / total
    s_high = (n_held + unknown) / total
    lo, hi = label_of_share(s_low), label_of_share(s_high)
    return RobustScore(
        s=s, q=q, s_low=s_low, s_high=s_high,
        label=lo if lo == hi else RobustLabel.UNCERTAIN,
        known=len(group), total=total,
        target=tuple(sorted(target)) if target is not None else None,
    )


def robust_scores(
    lattice: Lattice,
    samples: Mapping[Point, StoredPose],
    points: Iterable[Point] | None = None,
    *,
    coarser: int = 0,
    hood: Neighbourhoods | None = None,
) -> dict[Point, RobustScore]:
    """The robust score of each of `points` (every stored sample when None) that is stored
    (`hood`: neighbourhoods already computed for this lattice and `coarser`, to reuse)."""
    hood = hood or Neighbourhoods(lattice, coarser)
    out = {}
    for p in sorted(samples) if points is None else points:
        sample = samples.get(p)
        if sample is None:
            continue
        out[p] = score(sample, [samples.get(q) for q in hood(p)])
    return out


def robust_core(
    lattice: Lattice,
    samples: Mapping[Point, StoredPose],
    members: Iterable[Point],
    *,
    coarser: int = 0,
    hood: Neighbourhoods | None = None,
) -> set[Point]:
    """The members of one manifold whose whole N_δ is stored and in the same manifold."""
    hood = hood or Neighbourhoods(lattice, coarser)
    inside = set(members)
    return {p for p in inside if all(q in inside and q in samples for q in hood(p))}


def coarser_for_error(lattice: Lattice, pose_error_mm: float | None,
                      pose_error_deg: float | None) -> int:
    """Which δ a stated pose error asks for: the finest step (0) when the error is within one
    finest step on both counts — the position error against the finest r step, the angular
    error against the finest angular step between approach directions — else one coarser
    step (1). Never more: beyond 2δ the neighbourhood is still that of 2δ (the caller says
    so with `error_within`)."""
    ratio = error_in_steps(lattice, pose_error_mm, pose_error_deg)
    return 0 if ratio <= 1.0 + 1e-9 else 1


def error_in_steps(lattice: Lattice, pose_error_mm: float | None,
                   pose_error_deg: float | None) -> float:
    """The larger of the two errors in finest steps (0 where neither is stated)."""
    step_mm = lattice.dr(lattice.depth) * 1000.0
    step_deg = math.degrees(lattice.dtheta(lattice.depth))
    ratios = [0.0]
    if pose_error_mm is not None and step_mm > 0:
        ratios.append(pose_error_mm / step_mm)
    if pose_error_deg is not None:
        ratios.append(pose_error_deg / step_deg)
    return max(ratios)


def large_manifolds(
    volumes: Sequence[float], viable_volume: float, share: float = LARGE_SHARE
) -> list[int]:
    """Indices of the manifolds whose volume is at least `share` of the viable volume."""
    floor = share * viable_volume
    return [i for i, v in enumerate(volumes) if v >= floor - 1e-15]


@dataclass(frozen=True)
class Dust:
    """The manifolds under `share` of the viable volume, as one entry of the table."""

    indices: list[int]
    count: int
    volume: float


def dust(volumes: Sequence[float], viable_volume: float, share: float = LARGE_SHARE) -> Dust:
    """The complement of `large_manifolds`: which, how many and their total volume."""
    large = set(large_manifolds(volumes, viable_volume, share))
    small = [i for i in range(len(volumes)) if i not in large]
    return Dust(small, len(small), float(sum(volumes[i] for i in small)))
