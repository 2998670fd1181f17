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
from graspscape.services.coordinator.manifolds.behaviour import StoredPose, same_behaviour
from graspscape.services.coordinator.mapspace.lattice import Lattice, Point
from graspscape.services.coordinator.objects.geometry import MESH_QUERIES
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
    merged_out: dict[int, int] | None = None,
) -> list[list[Point]]:
    """Fold specks (fewer than max(MIN_POSES, MIN_SHARE of the viable poses) members) into
    the larger neighbouring component they nearly match most often (same digits, joints
    within SPECK_TOLERANCE_RAD): a lone pose whose fingers closed a little differently is
    noise, not a behaviour. A speck with no such neighbour stays on its own.

    `owner_of(q)` is the index into `comps` of q's component (None: not viable); a caller
    that keeps the components (manifolds/incremental.py) passes its own instead of the
    index built here over every point, and may pass its caches of p's lattice neighbours at
    all its levels (`neighbours_of`) and of the tolerance test (`near`). Components not
    merged are returned as given (the same list objects, already sorted). `merged_out`
    receives which speck (index into `comps`) went into which component."""
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
    if merged_out is not None:
        merged_out.update(merged)
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
    with MESH_QUERIES:  # trimesh's lazy rtree is not thread-safe (objects/geometry.py)
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


@dataclass(frozen=True)
class FineGrid:
    """The finest lattice's positions (cell × r index; every attitude shares them), each
    with its embedding for the nearest-pose search and the m³ it stands for."""

    cells: list[tuple[int, int]]
    n_i: int  # r indices per cell
    n_a: int  # attitudes
    embedding: np.ndarray  # (positions, 4)
    weights: np.ndarray  # (positions,) m³
    weights_exact: list[int]  # the same, exact (manifolds/exact.py)
    cell_index: dict[tuple[int, int], int]

    def position(self, p: Point) -> int:
        return self.cell_index[(p.ring, p.azimuth)] * self.n_i + p.r_index


def fine_grid(lattice: Lattice, radius: Callable[[np.ndarray], np.ndarray]) -> FineGrid:
    from graspscape.services.coordinator.manifolds.exact import exact

    cells = lattice.cells(lattice.depth)
    n_i = (lattice.n_r << lattice.depth) + 1
    dirs = np.array([lattice.direction(Point(K, J, 0, 0)) for K, J in cells])
    rho_s = radius(dirs)
    d = lattice.depth
    dr = lattice.dr(d)
    r0 = lattice.grid.r_min
    r_top = lattice.grid.r_min + lattice.n_r * lattice.grid.dr
    # One coarse r step weighs as much as one coarse angular step.
    scale = lattice.dtheta(0) / lattice.grid.dr if lattice.grid.dr > 0 else 0.0
    weights = []
    embedding = np.empty((len(cells) * n_i, 4))
    for c, (K, _) in enumerate(cells):
        omega = lattice.cell_area(K, d)
        for i in range(n_i):
            r = r0 + i * dr
            lo, hi = max(r0, r - dr / 2), min(r_top, r + dr / 2)
            if hi <= lo:  # a single r level: a shell of one Δr
                lo, hi = r - lattice.grid.dr / 2, r + lattice.grid.dr / 2
            weights.append(omega * ((rho_s[c] + hi) ** 3 - (rho_s[c] + lo) ** 3) / 3)
            embedding[c * n_i + i] = (*dirs[c], i * dr * scale)
    return FineGrid(cells, n_i, len(lattice.attitudes), embedding, np.array(weights),
                    [exact(float(w)) for w in weights], {kj: c for c, kj in enumerate(cells)})


def sq_dist(fine: np.ndarray, sample: np.ndarray) -> np.ndarray:
    """Squared distances, fine embeddings minus sample embeddings (broadcast), rounded to
    1e-12: equal distances of a symmetric lattice compare equal, and the nearest pose is
    then the smaller point. Written term by term so that every caller gets the same bits."""
    d = fine - sample
    return np.round(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]
                    + d[..., 3] * d[..., 3], 12)


_K = 8  # nearest candidates asked of the tree where the 2nd nearest may tie; more where the 8th may


def nearest_known(grid: FineGrid, known: list[Point],
                  positions: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """For each position (every one when None), the index into `known` (sorted points of one
    attitude) of its nearest known pose and the rounded squared distance: the smallest
    `sq_dist`, ties to the smaller point. The tree finds candidates; the choice is
    `sq_dist`'s, so that the running map (manifolds/running.py), which asks this of each
    batch and keeps the better of it and what it had, chooses as the full recompute does."""
    emb = grid.embedding if positions is None else grid.embedding[positions]
    own = grid.embedding[[grid.position(p) for p in known]]
    tree = cKDTree(own)
    # The two nearest first: where the second is clearly farther than the first, no pose
    # can tie with the nearest (most positions); the others ask for more.
    best, best_d2, unsure = _nearest_of(tree, own, emb, min(2, len(known)))
    if unsure is not None and len(unsure):
        best[unsure], best_d2[unsure], unsure_8 = _nearest_of(
            tree, own, emb[unsure], min(_K, len(known)))
        if unsure_8 is not None:  # a pose beyond the 8th may tie with the nearest: ask all
            for f in unsure[unsure_8].tolist():
                cand = np.array(tree.query_ball_point(emb[f], math.sqrt(best_d2[f]) + 1e-6))
                cd2 = sq_dist(emb[f], own[cand])
                j = np.lexsort((cand, cd2))[0]
                best[f], best_d2[f] = cand[j], cd2[j]
    return best, best_d2


def _nearest_of(tree: cKDTree, own: np.ndarray, emb: np.ndarray, k: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The nearest of the k the tree finds (smallest `sq_dist`, ties to the smaller index)
    and the rows where one beyond the k-th may tie with it (None: k is every pose)."""
    dist, idx = tree.query(emb, k=k)
    if k == 1:
        idx = np.asarray(idx, dtype=np.int64)
        return idx, sq_dist(emb, own[idx]), None
    d2 = sq_dist(emb[:, None, :], own[idx])
    order = np.lexsort((idx, d2), axis=-1)[:, 0]
    rows = np.arange(len(emb))
    best, best_d2 = idx[rows, order], d2[rows, order]
    if k == len(own):
        return best, best_d2, None
    return best, best_d2, np.flatnonzero(dist[:, -1] ** 2 - best_d2 <= 4e-12)


def fine_labels(
    lattice: Lattice,
    samples: Mapping[Point, StoredPose],
    label_of: Mapping[Point, int],
    radius: Callable[[np.ndarray], np.ndarray],
    grid: FineGrid | None = None,
) -> FineLabels:
    """Label every finest-lattice point by its nearest known pose of the same attitude
    (`nearest_known`)."""
    grid = grid or fine_grid(lattice, radius)
    n_pos, n_a = len(grid.cells) * grid.n_i, grid.n_a
    points = [Point(K, J, i, a) for K, J in grid.cells for i in range(grid.n_i)
              for a in range(n_a)]
    labels = np.full(n_pos * n_a, NON_VIABLE)
    by_att: dict[int, list[Point]] = {}
    for p in samples:
        by_att.setdefault(p.attitude, []).append(p)
    for a, known in by_att.items():
        known = sorted(known)
        lab = np.array([label_of.get(p, NON_VIABLE) for p in known])
        labels[a::n_a] = lab[nearest_known(grid, known)[0]]
    return FineLabels(points, labels, np.repeat(grid.weights, n_a),
                      np.repeat(np.arange(n_pos), n_a))


def exact_volume(grid: FineGrid, positions: Iterable[int]) -> float:
    """m³ of a set of positions, summed exactly (the running map's sums are the same)."""
    from graspscape.services.coordinator.manifolds.exact import value

    w = grid.weights_exact
    return value(sum(w[int(pos)] for pos in positions))


def volumes(fine: FineLabels, n_labels: int, grid: FineGrid | None = None) -> list[float]:
    """m³ of reference-point positions per label (a position counts once per label)."""
    out = []
    for label in range(n_labels):
        positions = np.unique(fine.position_ids[fine.labels == label])
        if grid is not None:
            out.append(exact_volume(grid, positions))
        else:
            mask = fine.labels == label
            _, first = np.unique(fine.position_ids[mask], return_index=True)
            out.append(float(fine.weights[mask][first].sum()))
    return out
