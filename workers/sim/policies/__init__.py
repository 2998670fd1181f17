"""Grasp synthesis policies, chosen by name. A policy drives the scene from the start pose
until a grasp has formed (return None) or clearly cannot (return the outcome).

Every module in this package that defines `POLICY` (a class with a `name` and `synthesize`)
is a policy: adding one is adding one module.
"""

from __future__ import annotations

import importlib
import pkgutil
from functools import cache
from typing import TYPE_CHECKING, Protocol

import numpy as np
from graspscape.shared.specs.results import Outcome, PhaseTimes

if TYPE_CHECKING:
    from graspscape.shared.specs.sim import SimSettings


class Policy(Protocol):
    name: str

    def synthesize(self, scene, position: np.ndarray, rotation: np.ndarray,
                   target: np.ndarray, settings: SimSettings,
                   phases: PhaseTimes) -> Outcome | None: ...


@cache
def _registry() -> dict[str, type]:
    policies = {}
    for info in pkgutil.iter_modules(__path__):
        module = importlib.import_module(f"{__name__}.{info.name}")
        policy = getattr(module, "POLICY", None)
        if policy is not None:
            policies[policy.name] = policy
    return policies


def list_policies() -> list[str]:
    return sorted(_registry())


def get_policy(name: str) -> Policy:
    try:
        return _registry()[name]()
    except KeyError:
        raise ValueError(f"unknown policy {name!r}; known: {', '.join(list_policies())}") from None
