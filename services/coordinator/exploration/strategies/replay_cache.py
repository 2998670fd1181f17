"""Searches kept between scheduler rounds, for the explorers that replay from their seed.

CMA-ES and PPO are functions of the spec and of the results told so far, so each round could
replay the whole search from the seed. Keeping the search as the last round left it is only a
speed-up: a kept search is used when what it was told is still what the store says, so
resuming equals replaying. `next_replayed_round` is the scheduler round both explorers share.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

from graspscape.services.coordinator.exploration.strategies.base import Batch, Planned
from graspscape.services.coordinator.state import Bounded
from graspscape.services.coordinator.store.models import PosePlanRow, TileRow
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.pose import Pose
from sqlalchemy import func, select

S = TypeVar("S")

Told = list[tuple[list[str], list[float]]]  # per round: (pose keys, their values)


class Search(Protocol):
    """`cmaes.generation` / `ppo.rollout`: (the round's index, its poses; [] when spent)."""

    def __call__(self, spec: ExplorationSpec, g: int, value_of: Callable[[str], float], *,
                 skip: Callable[[str], bool], cache_key: str | None) -> tuple[int, list[Pose]]:
        ...


@dataclass
class Snapshot(Generic[S]):
    """A search after being told `told` rounds."""

    search: S
    told: Told


class ReplayCache(Generic[S]):
    """The last `kept` searches by cache key (least recently kept dropped first)."""

    def __init__(self, kept: int = 16) -> None:
        self._snapshots: Bounded[str, Snapshot[S]] = Bounded(kept)

    def clear(self) -> None:
        self._snapshots.clear()

    def __len__(self) -> int:
        return len(self._snapshots)

    def resume(self, cache_key: str | None, rounds: int, value_of: Callable[[str], float],
               *, take: Callable[[Snapshot[S]], S], pop: bool) -> tuple[S, Told] | None:
        """The kept search and what it was told, where it was told at most `rounds` rounds
        and every value still equals `value_of(key)`; else None. `pop` takes it out of the
        cache while it runs (a search too costly to copy); `take` makes the caller's copy."""
        if cache_key is None:
            return None
        snap = self._snapshots.pop(cache_key) if pop else self._snapshots.peek(cache_key)
        if snap is None or len(snap.told) > rounds or not all(
                value_of(key) == v
                for keys, vs in snap.told for key, v in zip(keys, vs, strict=True)):
            return None
        return take(snap), list(snap.told)

    def keep(self, cache_key: str | None, search: S, told: Told) -> None:
        if cache_key is None:
            return
        self._snapshots.put(cache_key, Snapshot(search, told))


def next_replayed_round(batch: Batch, spec: ExplorationSpec, search: Search,
                        values: Mapping[str, float], reason: str) -> list[Planned]:
    """The next round of a replayed search (CMA-ES's generation, PPO's rollout): replayed
    from the seed, told `values` (pose key → what the store says), resumed from the kept
    search where it still holds. A round whose poses are all stored or planned already (a
    repeat, down to the key's 1e-6) is told from the store and skipped: queueing nothing
    would end the run."""
    session, eid = batch.session, batch.exploration_id
    done = 1 + (session.scalar(
        select(func.max(TileRow.round)).where(TileRow.exploration_id == eid)) or 0)
    planned = set(session.scalars(
        select(PosePlanRow.pose_key).where(PosePlanRow.exploration_id == eid)))
    k, poses = search(spec, done, lambda key: values.get(key, 0.0),
                      skip=lambda key: key in values or key in planned,
                      cache_key=f"{eid}:{spec.model_dump_json()}")
    return [Planned(pose, plan_level=0, tile_level=0, reason=reason, round=k, counted=False)
            for pose in poses]
