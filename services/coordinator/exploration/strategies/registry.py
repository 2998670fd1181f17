"""The strategies by name, as the spec names them (`ExplorationSpec.strategy`)."""

from __future__ import annotations

from graspscape.services.coordinator.exploration.strategies.adaptive import AdaptiveStrategy
from graspscape.services.coordinator.exploration.strategies.base import Strategy
from graspscape.services.coordinator.exploration.strategies.cmaes import CmaesStrategy
from graspscape.services.coordinator.exploration.strategies.grid import GridStrategy
from graspscape.services.coordinator.exploration.strategies.ppo import PpoStrategy
from graspscape.services.coordinator.exploration.strategies.random import RandomStrategy
from graspscape.services.coordinator.exploration.strategies.seeded import SeededStrategy
from graspscape.shared.specs.exploration import ExplorationSpec

_BY_NAME: dict[str, type] = {
    "adaptive": AdaptiveStrategy,
    "grid": GridStrategy,
    "random": RandomStrategy,
    "cmaes": CmaesStrategy,
    "ppo": PpoStrategy,  # needs the optional extra `rl`: refused at submission without it
}


def strategy_for(spec: ExplorationSpec) -> Strategy:
    """The strategy the spec names, for this exploration (cheap: made per batch); on a table
    seeded from a free map, the seeded one (strategies/seeded.py)."""
    if spec.support.seed_exploration is not None and spec.support.resting is not None:
        return SeededStrategy(spec)
    return _BY_NAME[spec.strategy.name](spec)
