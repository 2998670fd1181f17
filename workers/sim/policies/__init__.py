"""Grasp synthesis policies, chosen by name (`SimSettings.policy_name`). A policy drives the
scene from the start pose until a grasp has formed or clearly cannot (`registry.Policy`).

A policy is a class decorated with `@register_policy("name")` (registry.py) in a module of this
package; the imports below register them. Adding one is adding its module and its import
here, and its name to `shared/specs/sim.py`'s `POLICY_NAMES` (the coordinator validates
specs against that list without loading the simulation; a test keeps the two equal).
"""

from __future__ import annotations

from graspscape.workers.sim.policies import baseline, haptic  # noqa: F401 (they register)
from graspscape.workers.sim.policies.registry import (
    Policy,
    get_policy,
    list_policies,
    register_policy,
)

__all__ = ["Policy", "get_policy", "list_policies", "register_policy"]
