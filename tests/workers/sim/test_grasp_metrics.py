"""Static grasp metrics on hand-checked contact sets, their glue on a simulated grasp, and the
minimum-effort bisection with real pybullet."""

from __future__ import annotations

import math

import numpy as np
import pytest
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import Outcome
from graspscape.shared.specs.sim import BaselinePolicySettings, SimSettings
from graspscape.workers.sim.effort import minimum_closing_effort, search_closing_effort
from graspscape.workers.sim.grasp_metrics import (
    Contact,
    LinkPoint,
    grasp_matrix,
    gws_volume,
    merge_by_link,
    mu_f,
    mu_g,
    mu_m,
    primitive_wrenches,
)
from scipy.spatial.transform import Rotation

R = 0.04  # sphere radius, also the characteristic length


def on_sphere(directions, friction=0.5, force=1.0, radius=R) -> list[Contact]:
    """Contacts on a sphere's surface at the given outward directions, pushing inward."""
    out = []
    for d in directions:
        u = np.asarray(d, dtype=float) / np.linalg.norm(d)
        out.append(Contact(position=radius * u, normal=-u, friction=friction, force=force))
    return out


THREE = [(math.cos(a), math.sin(a), 0.0) for a in (0.0, 2 * math.pi / 3, 4 * math.pi / 3)]
PINCH = [(1.0, 0.0, 0.0), (-1.0, 0.0, 0.0)]


def test_grasp_matrix_of_symmetric_three_contact_grasp_by_hand():
    # G Gᵀ = Σ W_i W_iᵀ with W_i = [I; [p_i]×/L] (contact frames are orthonormal). For three
    # equatorial contacts 120° apart at |p| = L: Σ p_i = 0 decouples force and torque; the force
    # block is 3·I, the torque block 3·I − Σ p̂p̂ᵀ = diag(1.5, 1.5, 3). So σ_min = √1.5.
    contacts = on_sphere(THREE)
    g = grasp_matrix(contacts, R)
    assert g.shape == (6, 9)
    np.testing.assert_allclose(g @ g.T, np.diag([3, 3, 3, 1.5, 1.5, 3]), atol=1e-12)
    assert mu_g(contacts, R) == pytest.approx(math.sqrt(1.5))


def test_three_contact_grasp_beats_two_contact_pinch():
    three, pinch = on_sphere(THREE), on_sphere(PINCH)
    # A point-contact pinch cannot resist a torque about the line through its contacts.
    assert mu_g(pinch, R) == pytest.approx(0.0, abs=1e-12)
    assert mu_f(pinch, R) == 0.0
    assert mu_m(pinch, R, weight_n=2.0) == 0.0
    assert mu_g(three, R) > 0.5
    assert mu_f(three, R) > 0.05
    assert mu_m(three, R, weight_n=2.0) > 0.0


def test_single_contact_has_no_force_closure():
    one = on_sphere([(0.0, 0.0, 1.0)])
    assert mu_g(one, R) == 0.0
    assert mu_f(one, R) == 0.0
    assert gws_volume(primitive_wrenches(one, R)) == 0.0
    assert mu_f([], R) == 0.0 and mu_g([], R) == 0.0


def test_friction_widens_the_wrench_space():
    # Frictionless contacts whose normals all pass through the centre exert no torque at all.
    assert mu_f(on_sphere(THREE, friction=0.0), R) == 0.0
    low, high = mu_f(on_sphere(THREE, friction=0.3), R), mu_f(on_sphere(THREE, friction=0.8), R)
    assert 0.0 < low < high


def test_metrics_are_invariant_to_scale_and_rotation():
    tetra = [(1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1)]
    base = on_sphere(tetra)
    big = on_sphere(tetra, radius=10 * R)
    assert mu_g(big, 10 * R) == pytest.approx(mu_g(base, R))
    assert mu_f(big, 10 * R) == pytest.approx(mu_f(base, R))
    turn = Rotation.from_euler("xyz", [0.3, -1.1, 2.0]).as_matrix()
    turned = [Contact(position=turn @ c.position, normal=turn @ c.normal, friction=c.friction)
              for c in base]
    assert mu_g(turned, R) == pytest.approx(mu_g(base, R))
    # The exact cone is rotation invariant; its 8-edge polygon is not (the edges' tangent
    # frame turns with the contacts only up to a choice), so μf agrees up to the polygon's
    # inscribed-circle shortfall 1 − cos(π/8).
    assert mu_f(turned, R) == pytest.approx(mu_f(base, R), rel=1 - math.cos(math.pi / 8))


def test_mu_m_scales_with_contact_force_and_is_relative_to_weight():
    weak, strong = on_sphere(THREE, force=1.0), on_sphere(THREE, force=3.0)
    # Three times the grip resists three times the perturbation; μf ignores the forces.
    assert mu_m(strong, R, 2.0) == pytest.approx(3 * mu_m(weak, R, 2.0))
    assert mu_f(strong, R) == pytest.approx(mu_f(weak, R))
    # Non-dimensional: a heavier object with proportionally stronger grip scores the same.
    assert mu_m(strong, R, 6.0) == pytest.approx(mu_m(weak, R, 2.0))


def test_manifold_points_of_one_link_merge_into_one_contact():
    n = np.array([0.0, 0.0, -1.0])
    points = [LinkPoint("A_1", np.array([0.01, 0.0, R]), n, 1.0, 0.5),
              LinkPoint("A_1", np.array([-0.01, 0.0, R]), n, 3.0, 0.5)]
    merged = merge_by_link(points)
    assert len(merged) == 1
    np.testing.assert_allclose(merged[0].position, [-0.005, 0.0, R])
    assert merged[0].force == pytest.approx(4.0)


def test_simulated_sphere_grasp_carries_its_static_metrics(sphere_evaluator):
    result = sphere_evaluator.evaluate(Pose(theta=math.pi / 2, phi=0.0, r=0.02))
    assert result.viable
    # All three fingers around the sphere: force closure, so every metric is positive.
    assert result.mu_g > 0.0 and result.mu_f > 0.0 and result.mu_m > 0.0
    assert result.min_closing_effort is None  # only the comparison command bisects


def test_pose_without_grasp_has_no_static_metrics(mug_evaluator):
    # Below the side away from the handle, the hand closes without anything between its
    # fingers: no grasp, so no contacts to score.
    result = mug_evaluator.evaluate(Pose(theta=2.09, phi=math.pi, r=0.02))
    assert result.outcome == Outcome.NO_GRASP and result.signature is None
    assert result.mu_g is None and result.mu_f is None and result.mu_m is None


@pytest.mark.slow
def test_minimum_effort_holds_and_a_clearly_lower_one_drops(make_evaluator):
    # Approached from above, the sphere hangs in the fingers: only their torque holds it.
    pose = Pose(theta=0.0, phi=0.0, r=0.02)
    search_evaluator = make_evaluator("sphere")
    found = search_closing_effort(search_evaluator, pose, 0.01, 1.5, tolerance=0.02)
    assert found.min_closing_effort is not None and found.highest_dropping is not None
    assert found.min_closing_effort - found.highest_dropping <= 0.02 + 1e-9
    assert minimum_closing_effort(search_evaluator, pose, 0.01, 1.5, 0.02) == pytest.approx(
        found.min_closing_effort)

    def evaluate_with(effort):
        settings = SimSettings(policy=BaselinePolicySettings(closing_effort=effort))
        return make_evaluator("sphere", settings=settings).evaluate(pose)

    assert evaluate_with(found.min_closing_effort).viable
    assert not evaluate_with(found.min_closing_effort / 3).viable
    # The search leaves the evaluator's own settings as they were.
    assert search_evaluator.settings == SimSettings()
