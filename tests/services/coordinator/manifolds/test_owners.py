"""The running map's owner array read back as finest-lattice labels (live.fine_labels_of),
before any pose owns a point: every point is not viable (test_running.py checks the labels
against the full recompute once poses arrive)."""

from __future__ import annotations

import math

import numpy as np
from graspscape.services.coordinator.exploration.lattice import Lattice
from graspscape.services.coordinator.manifolds.grouping import NON_VIABLE
from graspscape.services.coordinator.manifolds.live import fine_labels_of
from graspscape.services.coordinator.manifolds.running import RunningMap
from graspscape.shared.specs.exploration import PoseGridSpec


def test_a_map_without_poses_labels_every_point_not_viable() -> None:
    lattice = Lattice(PoseGridSpec(dtheta=math.radians(60), r_min=0.0, r_max=0.01, dr=0.01), 1)
    running = RunningMap(lattice, lambda d: np.full(len(d), 0.05))
    labels = fine_labels_of(running).labels
    assert len(labels) == len(running.owners.owner) > 0
    assert set(labels.tolist()) == {NON_VIABLE}
