"""Behavioral manifolds from stored samples: components, labels, volumes, summaries (pure).

A manifold is a connected set of viable poses in the multi-resolution lattice whose
neighbouring members show the same behaviour (`behaviour.same_behaviour`). Neighbours are
taken at the finest resolution available: two level-L neighbours whose level-L+1 midpoint was
evaluated are linked only through that midpoint, so a thin border found by refinement really
separates them. Attitude neighbours (adjacent rolls, tilt variants) link poses at one position.

Volumes are measured on the finest lattice: every finest point takes the label of the nearest
known pose (its own sample where one exists), and a point covers the shell cell
Ω_cell × [ρ − Δr/2, ρ + Δr/2] of gripper reference-point positions, ρ = ρ_surface(u) + r.
A position counts once per manifold however many attitudes reach it.
"""

from __future__ import annotations

import math
import string
from collections import Counter
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from functools import partial

import numpy as np
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds.behaviour import StoredPose, same_behaviour
from scipy.spatial import cKDTree

NON_VIABLE = -1
FALLBACK_RADIUS = 0.05  # m, surface radius where no mesh is at hand
MIN_POSES = 3  # components smaller than this (or than MIN_SHARE of the viable poses) are specks
MIN_SHARE = 0.02
SPECK_TOLERANCE_RAD = 0.35  # 1.4 × the joint tolerance of `same_behaviour`


def label_name(label: int) -> str:
    """0 → A, 25 → Z, 26 → AA, …"""
    letters = string.ascii_uppercase
    name = ""
    label += 1
    while label:
        label, rem = divmod(label - 1, 26)
        name = letters[rem] + name
    return name


class _UnionFind:
    def __init__(self) -> None:
        self.parent: dict[Point, Point] = {}

    def find(self, x: Point) -> Point:
        self.parent.setdefault(x, x)
        while self.parent[x] != x:
            self.parent[x] = self.parent[self.parent[x]]
            x = self.parent[x]
        return x

    def union(self, a: Point, b: Point) -> None:
        ra, rb = self.find(a), self.find(b)
        if ra != rb:
            lo, hi = sorted((ra, rb))
            self.parent[hi] = lo


def components(lattice: Lattice, samples: Mapping[Point, StoredPose]) -> list[list[Point]]:
    """Connected same-behaviour sets of viable points, each sorted, in a canonical order."""
    uf = _UnionFind()
    for p in sorted(samples):
        a = samples[p]
        if not a.viable:
            continue
        uf.find(p)
        links = []
        for level in range(lattice.birth(p), lattice.depth + 1):
            for _, q in lattice.neighbours(p, level):
                mid = lattice.midpoint(p, q, level)
                if mid is None or mid not in samples:
                    links.append(q)
        links += lattice.attitude_neighbours(p)
        for q in links:
            b = samples.get(q)
            if b is not None and b.viable and same_behaviour(a, b):
                uf.union(p, q)
    groups: dict[Point, list[Point]] = {}
    for p in sorted(samples):
        if samples[p].viable:
            groups.setdefault(uf.find(p), []).append(p)
    return _merge_specks(lattice, samples, sorted(groups.values(), key=lambda g: g[0]))


def _merge_specks(
    lattice: Lattice,
    samples: Mapping[Point, StoredPose],
    comps: list[list[Point]],
    owner_of: Callable[[Point], int | None] | None = None,
    neighbours_of: Callable[[Point], Iterable[Point]] | None = None,
    near: Callable[[Point, Point], bool] | None = None,
) -> list[list[Point]]:
    """Fold specks (fewer than max(MIN_POSES, MIN_SHARE of the viable poses) members) into
    the larger neighbouring component they nearly match most often (same digits, joints
    within SPECK_TOLERANCE_RAD): a lone pose whose fingers closed a little differently is
    noise, not a behaviour. A speck with no such neighbour stays on its own.

    `owner_of(q)` is the index into `comps` of q's component (None: not viable); a caller
    that keeps the components (manifolds/incremental.py) passes its own instead of the
    index built here over every point, and may pass its caches of p's lattice neighbours at
    all its levels (`neighbours_of`) and of the tolerance test (`near`). Components not
    merged are returned as given (the same list objects, already sorted)."""
    n_viable = sum(len(c) for c in comps)
    small = max(MIN_POSES, math.ceil(MIN_SHARE * n_viable))
    if owner_of is None:
        owner_of = {p: i for i, c in enumerate(comps) for p in c}.get
    if neighbours_of is None:
        neighbours_of = partial(speck_neighbours, lattice)
    if near is None:
        def near(p: Point, q: Point) -> bool:
            return same_behaviour(samples[p], samples[q], SPECK_TOLERANCE_RAD)
    merged: dict[int, int] = {}
    for i, comp in enumerate(comps):
        if len(comp) >= small:
            continue
        votes: Counter[int] = Counter()
        for p in comp:
            for q in neighbours_of(p):
                j = owner_of(q)
                if j is not None and j != i and len(comps[j]) >= small and near(p, q):
                    votes[j] += 1
        if votes:
            merged[i] = min(votes, key=lambda j: (-votes[j], j))
    if not merged:  # the usual case: every component as it is, in its order
        return comps
    out: dict[int, list[Point]] = {}
    for i, comp in enumerate(comps):
        out.setdefault(merged.get(i, i), []).extend(comp)
    return sorted((sorted(c) for c in out.values()), key=lambda g: g[0])


def speck_neighbours(lattice: Lattice, p: Point) -> list[Point]:
    """p's lattice neighbours at every level from its birth (a speck's vote goes to their
    components), with repeats as the levels give them."""
    return [q for level in range(lattice.birth(p), lattice.depth + 1)
            for _, q in lattice.neighbours(p, level)]


def surface_radii(mesh: object | None, directions: np.ndarray, fallback: float) -> np.ndarray:
    """Distance from the centre of mass to the outermost surface point along each direction."""
    if mesh is None:
        return np.full(len(directions), fallback)
    origins = np.zeros_like(directions)
    locations, index_ray, _ = mesh.ray.intersects_location(origins, directions)  # type: ignore[attr-defined]
    out = np.full(len(directions), fallback)
    if len(locations):
        dist = np.linalg.norm(locations, axis=1)
        best = np.zeros(len(directions))
        np.maximum.at(best, index_ray, dist)
        out = np.where(best > 0, best, fallback)
    return out


@dataclass(frozen=True)
class FineLabels:
    """The finest lattice with one label per point (NON_VIABLE or a component index)."""

    points: list[Point]
    labels: np.ndarray
    weights: np.ndarray  # m³ of reference-point positions each point stands for
    position_ids: np.ndarray  # points sharing a position (all attitudes) share an id


def _embed(lattice: Lattice, pts: list[Point]) -> np.ndarray:
    # One coarse r step weighs as much as one coarse angular step.
    scale = lattice.dtheta(0) / lattice.grid.dr if lattice.grid.dr > 0 else 0.0
    out = np.empty((len(pts), 4))
    for i, p in enumerate(pts):
        x, y, z = lattice.direction(p)
        out[i] = (x, y, z, p.r_index * lattice.dr(lattice.depth) * scale)
    return out


def fine_labels(
    lattice: Lattice,
    samples: Mapping[Point, StoredPose],
    label_of: Mapping[Point, int],
    radius: Callable[[np.ndarray], np.ndarray],
) -> FineLabels:
    """Label every finest-lattice point by its nearest known pose of the same attitude."""
    cells = lattice.cells(lattice.depth)
    n_i = (lattice.n_r << lattice.depth) + 1
    n_a = len(lattice.attitudes)
    dirs = np.array([lattice.direction(Point(K, J, 0, 0)) for K, J in cells])
    rho_s = radius(dirs)
    d = lattice.depth
    dr = lattice.dr(d)
    r0 = lattice.grid.r_min
    r_top = lattice.grid.r_min + lattice.n_r * lattice.grid.dr
    points: list[Point] = []
    weights = []
    pos_ids = []
    for c, (K, J) in enumerate(cells):
        omega = lattice.cell_area(K, d)
        for i in range(n_i):
            r = r0 + i * dr
            lo, hi = max(r0, r - dr / 2), min(r_top, r + dr / 2)
            if hi <= lo:  # a single r level: a shell of one Δr
                lo, hi = r - lattice.grid.dr / 2, r + lattice.grid.dr / 2
            vol = omega * ((rho_s[c] + hi) ** 3 - (rho_s[c] + lo) ** 3) / 3
            for a in range(n_a):
                points.append(Point(K, J, i, a))
                weights.append(vol)
                pos_ids.append(c * n_i + i)
    labels = np.full(len(points), NON_VIABLE)
    by_att: dict[int, list[Point]] = {}
    for p in samples:
        by_att.setdefault(p.attitude, []).append(p)
    fine_by_att: dict[int, list[int]] = {}
    for idx, p in enumerate(points):
        fine_by_att.setdefault(p.attitude, []).append(idx)
    for a, known in by_att.items():
        known = sorted(known)
        tree = cKDTree(_embed(lattice, known))
        idxs = fine_by_att.get(a, [])
        _, nearest = tree.query(_embed(lattice, [points[i] for i in idxs]))
        for idx, k in zip(idxs, nearest, strict=True):
            labels[idx] = label_of.get(known[int(k)], NON_VIABLE)
    return FineLabels(points, labels, np.array(weights), np.array(pos_ids))


def volumes(fine: FineLabels, n_labels: int) -> list[float]:
    """m³ of reference-point positions per label (a position counts once per label)."""
    out = []
    for label in range(n_labels):
        mask = fine.labels == label
        _, first = np.unique(fine.position_ids[mask], return_index=True)
        out.append(float(fine.weights[mask][first].sum()))
    return out


def describe(samples: list[StoredPose]) -> str:
    """Which digits touch which part of the object, from the members' contacts."""
    digit_sets = Counter(s.digits for s in samples)
    digits = sorted(digit_sets.most_common(1)[0][0]) if digit_sets else []
    parts = []
    for d in digits:
        pts = [s.contacts[d] for s in samples if d in s.contacts]
        if not pts:
            continue
        x, y, z = (sum(p[i] for p in pts) / len(pts) for i in range(3))
        spread = max(math.dist(p, (x, y, z)) for p in pts)
        parts.append(
            f"{d} at ({100 * x:.1f}, {100 * y:.1f}, {100 * z:.1f}) cm ± {100 * spread:.1f} cm"
        )
    touched = ", ".join(digits) or "nothing"
    return f"{touched} touch the object — " + "; ".join(parts)
