"""The policy registry: a policy class registers itself under its name with
`@register_policy("name")` (ManiSkill's `register_env` style), and evaluations look it up by
the name in their settings (`SimSettings.policy_name`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

import numpy as np
from graspscape.shared.specs.results import Outcome, PhaseTimes

if TYPE_CHECKING:
    from graspscape.shared.specs.sim import SimSettings


class Policy(Protocol):
    """Drives the scene from the start pose until a grasp has formed (returns None) or
    clearly cannot (returns the outcome)."""

    def synthesize(self, scene, position: np.ndarray, rotation: np.ndarray,
                   target: np.ndarray, settings: SimSettings,
                   phases: PhaseTimes) -> Outcome | None: ...


REGISTERED_POLICIES: dict[str, type[Policy]] = {}


def register_policy(name: str) -> Callable[[type[Policy]], type[Policy]]:
    """Class decorator: makes the policy available as `name`. A name is registered once."""

    def register(cls: type[Policy]) -> type[Policy]:
        known = REGISTERED_POLICIES.get(name)
        if known is not None and known is not cls:
            raise ValueError(f"policy {name!r} is already registered ({known.__qualname__})")
        REGISTERED_POLICIES[name] = cls
        return cls

    return register


def list_policies() -> list[str]:
    return sorted(REGISTERED_POLICIES)


def get_policy(name: str) -> Policy:
    try:
        return REGISTERED_POLICIES[name]()
    except KeyError:
        raise ValueError(f"unknown policy {name!r}; known: {', '.join(list_policies())}") from None
