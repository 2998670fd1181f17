"""The policy registry: policies register themselves by decorator, under the names shared's
plain list gives the coordinator."""

from __future__ import annotations

import pytest
from graspscape.shared.specs.sim import POLICY_NAMES
from graspscape.workers.sim.policies import get_policy, list_policies, register_policy
from graspscape.workers.sim.policies.baseline import BaselinePolicy
from graspscape.workers.sim.policies.haptic import HapticPolicy
from graspscape.workers.sim.policies.registry import REGISTERED_POLICIES


def test_the_registry_holds_the_names_shared_lists():
    # The coordinator validates specs against shared's list, without loading the simulation.
    assert list_policies() == sorted(POLICY_NAMES)
    assert REGISTERED_POLICIES["baseline"] is BaselinePolicy
    assert isinstance(get_policy("haptic"), HapticPolicy)


def test_a_name_is_registered_once():
    class Impostor:
        def synthesize(self, *args):
            return None

    with pytest.raises(ValueError, match="already registered"):
        register_policy("baseline")(Impostor)
    assert REGISTERED_POLICIES["baseline"] is BaselinePolicy
    # The same class again (a module imported twice) is no conflict.
    assert register_policy("baseline")(BaselinePolicy) is BaselinePolicy


def test_an_unknown_name_lists_the_known_ones():
    with pytest.raises(ValueError, match="unknown policy 'grab'; known: baseline, haptic"):
        get_policy("grab")
