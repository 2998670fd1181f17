"""The cmaes strategy: CMA-ES (the `cma` package) over the continuous pose space, a baseline.

Search space. A point x is (v_x, v_y, v_z, u_r[, u_roll]): the approach direction is v/|v|
(a vector of R³, normalised, so neither the poles nor the azimuth wrap are edges of the
search space), the start gap r = r_min + fold(u_r)·(r_max − r_min) with fold the triangle
wave of period 2 onto [0, 1] (continuous: a step past r_max comes back in), and, when the grid
has several rolls, roll = 2π·(u_roll mod 1). Pitch and yaw stay 0: tilts are not searched.
The objective is −quality + W·(|v| − 1)²: the quality does not depend on |v|, and the
small penalty keeps |v| near 1 so that a step size means the same angle all run long.

Quality of a stored pose: 0 when not viable, else the spec's objective (the torque margin
ratio, /best's default rank, where stored, else μs; or μs alone).

Rounds. Generation g is round g: its `popsize` poses are queued together (one tile per pose,
as r is continuous), so every worker gets one, and the generation is told once all of it is
stored. When CMA-ES stops (σ collapsed, fitness flat: `es.stop()`) or its best has
stalled for STALL generations, it restarts from a new
random mean with a new seed and a doubled population (IPOP). The budget `poses` counts every
asked pose; the last generation is cut to what is left, and is not told.

State. `next_round` replays every finished generation from the seed, telling each the
qualities the store holds for its poses (a missing pose, whose tile failed, scores 0), then
asks the next one. The run is therefore a function of the spec and the stored results,
whatever the workers, interleaving or coordinator restarts. A replay from the seed costs
O(generations) ask/tell steps, so the last replay's search is kept in memory and resumed
when the qualities it was told are still the stored ones: the same search, sooner. Poses are
off the lattice: stored, listed, exported and ranked by /best, not grouped into manifolds.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import cma
import numpy as np
from graspscape.services.coordinator.exploration.strategies.base import Batch, Planned, Stage
from graspscape.services.coordinator.exploration.strategies.replay_cache import (
    Told,
    next_replayed_round,
)
from graspscape.services.coordinator.exploration.tiling import TilePlan, group_tiles
from graspscape.services.coordinator.state import current
from graspscape.services.coordinator.store.models import PoseRow
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.strategies import CmaesStrategySpec
from sqlalchemy import select
from sqlalchemy.orm import Session

# Weight of the (|v| − 1)² term: small against quality differences (0.1–0.5), enough to keep
# |v| within a few tens of percent of 1.
NORM_WEIGHT = 0.25
# Restart when the search has shrunk below this (x units: ~0.06° of direction, 0.1 % of the
# r range) or the best fitness moved less than TOL_FUN over cma's history window: closer
# poses than that are the same grasp.
TOL_X = 1e-2
TOL_FUN = 1e-6
# Restart also when the run's best quality has not risen by STALL_GAIN in STALL generations:
# a run that sits on a cliff of the map (held on one side, nothing on the other) shrinks its
# σ only slowly, and would spend the budget there.
STALL = 10
STALL_GAIN = 1e-3
# IPOP's population stops doubling here: the budget is spent in generations of at most this.
MAX_POPSIZE = 512


def fold(u: float) -> float:
    """The triangle wave of period 2 onto [0, 1]."""
    t = math.fmod(u, 2.0)
    if t < 0:
        t += 2.0
    return 2.0 - t if t > 1.0 else t


def decode(x: np.ndarray, spec: ExplorationSpec) -> Pose:
    """The pose a search point stands for."""
    grid = spec.grid
    v = np.asarray(x[:3], dtype=float)
    n = float(np.linalg.norm(v))
    if n < 1e-12:
        v, n = np.array([0.0, 0.0, 1.0]), 1.0
    theta = math.acos(max(-1.0, min(1.0, float(v[2]) / n)))
    phi = math.atan2(float(v[1]), float(v[0])) % (2 * math.pi)
    r = grid.r_min + fold(float(x[3])) * (grid.r_max - grid.r_min)
    roll = 2 * math.pi * (float(x[4]) % 1.0) if len(x) > 4 else 0.0
    return Pose(theta=theta, phi=phi, r=r, roll=roll)


def quality(row: Any, objective: str) -> float:
    """A stored pose's quality: 0 when not viable; its rank metric where asked and stored."""
    if not row.viable:
        return 0.0
    if objective == "rank" and row.torque_margin_ratio is not None:
        return float(row.torque_margin_ratio)
    return float(row.mu_s)


@dataclass
class _Normal:
    """cma's `randn` from a generator of our own (an object, not a closure, so that a copied
    search draws from a copied generator)."""

    rng: np.random.Generator

    def __call__(self, *shape: int) -> np.ndarray:
        return self.rng.standard_normal(shape)


@dataclass
class _Search:
    """One CMA-ES run after another (IPOP), replayed from the seed."""

    spec: ExplorationSpec
    strategy: CmaesStrategySpec
    restart: int = 0
    used: int = 0  # poses asked so far, the budget's count
    best: float = -math.inf  # this run's best quality
    stalled: int = 0  # generations since it last rose by STALL_GAIN

    def __post_init__(self) -> None:
        self.dim = 5 if self.spec.grid.attitudes.rolls > 1 else 4
        self.es = self._start()

    def _start(self) -> cma.CMAEvolutionStrategy:
        rng = np.random.default_rng([self.strategy.seed, self.restart])
        v = rng.standard_normal(3)
        mean = [*(v / np.linalg.norm(v)), *rng.uniform(0.0, 1.0, self.dim - 3)]
        popsize = self.strategy.popsize or 4 + int(3 * math.log(self.dim))
        opts = {
            # Our own generator, not numpy's global one (which cma would seed and draw from):
            # the run must not depend on what else in the process draws random numbers.
            "randn": _Normal(rng), "seed": math.nan,
            "popsize": min(MAX_POPSIZE, popsize * 2**self.restart),
            "tolx": TOL_X, "tolfun": TOL_FUN,
            "verbose": -9, "verb_log": 0, "verb_disp": 0, "verb_filenameprefix": "",
        }
        return cma.CMAEvolutionStrategy(mean, self.strategy.sigma0, opts)

    def ask(self) -> tuple[list[np.ndarray], list[Pose]]:
        """The next generation, cut to the budget left (empty when it is spent)."""
        left = self.strategy.poses - self.used
        if left <= 0:
            return [], []
        xs = self.es.ask()[:left]
        self.used += len(xs)
        return xs, [decode(x, self.spec) for x in xs]

    def tell(self, xs: list[np.ndarray], qualities: list[float]) -> None:
        """Learn from a whole generation; restart when the run has converged."""
        if len(xs) < self.es.popsize:
            return  # the budget's last, cut generation: nothing follows it
        fitness = [-q + NORM_WEIGHT * (float(np.linalg.norm(x[:3])) - 1.0) ** 2
                   for x, q in zip(xs, qualities, strict=True)]
        self.es.tell(xs, fitness)
        self.stalled += 1
        if max(qualities) >= self.best + STALL_GAIN:
            self.best, self.stalled = max(qualities), 0
        if self.es.stop() or self.stalled >= STALL:
            self.restart += 1
            self.best, self.stalled = -math.inf, 0
            self.es = self._start()


# Searches as the last replay left them, per exploration (strategies/replay_cache.py), kept
# on the coordinator's state (services/coordinator/state.py).


def _resume(cache_key: str | None, spec: ExplorationSpec, g: int,
            quality_of: Callable[[str], float]) -> tuple[_Search, Told]:
    kept = current().cmaes_searches.resume(cache_key, g, quality_of,
                                           take=lambda snap: copy.deepcopy(snap.search),
                                           pop=False)
    if kept is not None:
        return kept
    strategy = spec.strategy
    assert isinstance(strategy, CmaesStrategySpec)
    return _Search(spec, strategy), []


def generation(spec: ExplorationSpec, g: int, quality_of: Callable[[str], float],
               skip: Callable[[str], bool] = lambda key: False,
               cache_key: str | None = None) -> tuple[int, list[Pose]]:
    """Replay generations 0 … g − 1 (telling each the qualities of its poses), then ask on
    until a generation has a pose for which `skip` is false: (its index, its poses), or
    (index, []) when the budget is spent. With `cache_key`, resume from the last replay's
    snapshot under that key where it still holds."""
    search, told = _resume(cache_key, spec, g, quality_of)
    while True:
        before = copy.deepcopy(search) if len(told) >= g else None
        xs, poses = search.ask()
        if not poses or (before is not None and not all(skip(p.key()) for p in poses)):
            if before is not None:
                current().cmaes_searches.keep(cache_key, before, told)
            return len(told), poses
        keys = [p.key() for p in poses]
        qualities = [quality_of(key) for key in keys]
        search.tell(xs, qualities)
        told.append((keys, qualities))


class CmaesStrategy:
    reacts = True
    has_rounds = True

    def __init__(self, spec: ExplorationSpec) -> None:
        assert isinstance(spec.strategy, CmaesStrategySpec)
        self.spec = spec
        self.strategy = spec.strategy

    def planned_poses(self) -> int:
        return self.strategy.poses

    def initial_work(self, session: Session, *, target_poses: int) -> list[TilePlan]:
        _, poses = generation(self.spec, 0, lambda key: 0.0)
        return group_tiles(poses, target_poses=target_poses)

    def after_batch(self, batch: Batch) -> list[Planned]:
        return []  # a generation is told only once all of it is stored: in next_round

    def next_round(self, batch: Batch) -> list[Planned]:
        values = self._qualities(batch.session, batch.exploration_id)
        return next_replayed_round(batch, self.spec, generation, values, "cmaes")

    def progress(self, batch: Batch, stage: Stage) -> None:
        return None  # off-lattice poses: no manifolds to refresh

    def _qualities(self, session: Session, eid: int) -> Mapping[str, float]:
        rows = session.execute(
            select(PoseRow.pose_key, PoseRow.viable, PoseRow.mu_s, PoseRow.torque_margin_ratio)
            .where(PoseRow.exploration_id == eid))
        return {row.pose_key: quality(row, self.strategy.objective) for row in rows}
