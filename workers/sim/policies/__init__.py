"""Grasp synthesis policies, chosen by name. A policy drives the scene from the start pose
until a grasp has formed (return None) or clearly cannot (return the outcome)."""

from __future__ import annotations

from typing import Protocol

import numpy as np
from graspscape.shared.specs.results import Outcome, PhaseTimes


class Policy(Protocol):
    name: str

    def synthesize(self, scene, position: np.ndarray, rotation: np.ndarray,
                   target: np.ndarray, settings, phases: PhaseTimes) -> Outcome | None: ...


def get_policy(name: str) -> Policy:
    if name == "baseline":
        from graspscape.workers.sim.policies.baseline import BaselinePolicy

        return BaselinePolicy()
    raise ValueError(f"unknown policy {name!r}; known: baseline")
