"""The evaluation's shortcuts (issue 21 item 5) give the very numbers of what they replace."""

from __future__ import annotations

import math

import numpy as np
from graspscape.shared.specs.sim import TrajectorySpec
from graspscape.workers.sim.geometry import quat_from_matrix
from graspscape.workers.sim.grasp_metrics import Contact, mu_f, mu_m
from graspscape.workers.sim.trajectory import ReferencePath, reference_pose, rotation_angle
from scipy.spatial.transform import Rotation


def test_reference_path_is_reference_pose_bit_for_bit() -> None:
    spec = TrajectorySpec()
    rng = np.random.default_rng(3)
    start, pivot = rng.normal(size=3), rng.normal(size=3)
    rotation = Rotation.random(random_state=4).as_matrix()
    dt = 1 / 240
    path = ReferencePath(spec, start, rotation, pivot, dt)
    for step in (5, 0, 5, 700, 1, 10_000):  # any order, again, and past the trajectory's end
        position, turned = path.pose(step)
        want_position, want_rotation = reference_pose(spec, start, rotation, pivot, step * dt)
        assert position.tobytes() == want_position.tobytes()
        assert turned.tobytes() == want_rotation.tobytes()
        assert path.drive(step) == (want_position.tolist(), quat_from_matrix(want_rotation))


def test_rotation_angle_is_scipys_magnitude() -> None:
    for seed in range(50):
        m = Rotation.random(random_state=seed).as_matrix()
        assert math.isclose(rotation_angle(m), Rotation.from_matrix(m).magnitude(),
                            rel_tol=0.0, abs_tol=1e-12)
    assert rotation_angle(np.eye(3)) == 0.0
    assert math.isclose(rotation_angle(np.diag([1.0, -1.0, -1.0])), math.pi, abs_tol=1e-12)


def test_mu_m_is_zero_wherever_mu_f_is() -> None:
    """scene_metrics skips μm's hull when μf = 0: the force-scaled wrenches never enclose
    the origin where the unit ones do not."""
    rng = np.random.default_rng(5)
    zeros = 0
    for _ in range(60):
        n = int(rng.integers(2, 5))
        contacts = []
        for _ in range(n):
            position = rng.normal(size=3) * 0.03
            normal = -position / np.linalg.norm(position) + rng.normal(size=3) * 0.6
            contacts.append(Contact(position=position, normal=normal / np.linalg.norm(normal),
                                    friction=float(rng.uniform(0.1, 0.8)),
                                    force=float(rng.choice([0.0, rng.uniform(0.1, 20.0)]))))
        if mu_f(contacts, 0.05) == 0.0:
            zeros += 1
            assert mu_m(contacts, 0.05, 1.0) == 0.0
    assert 5 < zeros < 60  # both cases occur
