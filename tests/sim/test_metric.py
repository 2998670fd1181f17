"""μs: the pure formula, and its two anchors measured in the simulator (welded → 1, let go → 0)."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest
from graspscape.shared.specs.pose import Pose
from graspscape.workers.sim.metric import instant_quality, mu_s, sensitivity_matrix
from graspscape.workers.sim.sensitivity import ProbeContext, probe_instant
from graspscape.workers.sim.trajectory import min_jerk, reference_pose


def test_rigid_follower_scores_one_and_ignoring_object_scores_zero():
    responses = np.diag([1.3, 1.3, 1.3, 0.05, 0.05, 0.05])
    assert instant_quality(sensitivity_matrix(responses, responses, 0.03)) == pytest.approx(1.0)
    assert instant_quality(sensitivity_matrix(responses, np.zeros((6, 6)), 0.03)) == (
        pytest.approx(0.0))


def test_mu_s_is_the_worst_instant_clipped_to_unit_interval():
    assert mu_s([0.9, 0.4, 0.7]) == 0.4
    assert mu_s([0.9, -0.3]) == 0.0
    assert mu_s([]) == 0.0


def test_minimum_jerk_profile_starts_and_ends_at_rest():
    assert min_jerk(0.0) == 0.0 and min_jerk(1.0) == 1.0
    h = 1e-4
    for tau in (0.0, 1.0):
        assert abs(min_jerk(min(tau + h, 1.0)) - min_jerk(max(tau - h, 0.0))) < 1e-8


def _held_scene(evaluator, pose):
    evaluator._reset()
    position, rotation, _, _ = evaluator._start_pose(pose)
    evaluator._place(position, rotation)
    return evaluator.scene


@pytest.fixture(scope="module")
def probe_evaluator(make_evaluator):
    # Its own client: these tests add constraints that the shared evaluators must not see.
    return make_evaluator("sphere")


def test_object_welded_to_the_palm_gives_mu_s_near_one(probe_evaluator):
    # Measured 0.885, not 1: the weld is itself a soft pybullet constraint and lags the hand
    # within the probe window (docs/simulation.md, "Known deviations").
    sphere_evaluator = probe_evaluator
    scene = _held_scene(sphere_evaluator, Pose(theta=1.0, phi=0.5, r=0.02))
    cid = scene.client
    obj_pos, _ = scene.object_pose()
    _, frame_rot = scene.hand.frame_pose()
    com = np.array(p.getBasePositionAndOrientation(scene.hand.body, physicsClientId=cid)[0])
    inv = frame_rot.T
    weld = p.createConstraint(scene.hand.body, -1, scene.object_body, -1, p.JOINT_FIXED,
                              [0, 0, 0], (inv @ (obj_pos - com)).tolist(), [0, 0, 0],
                              parentFrameOrientation=_quat(inv), physicsClientId=cid)
    p.changeConstraint(weld, maxForce=1e5, physicsClientId=cid)
    try:
        quality = _probe_at_start(sphere_evaluator, scene)
    finally:
        p.removeConstraint(weld, physicsClientId=cid)
    assert quality > 0.85


def _probe_at_start(evaluator, scene) -> float:
    """Releases the fixture, switches gravity on and probes G at the trajectory's start."""
    cid = scene.client
    p.changeConstraint(scene.fixture_constraint, maxForce=0.0, physicsClientId=cid)
    p.setGravity(0, 0, -9.81, physicsClientId=cid)
    start_pos, start_rot = scene.hand.frame_pose()
    pivot = scene.object_pose()[0]
    spec = evaluator.settings.trajectory
    ctx = ProbeContext(client=cid, hand_body=scene.hand.body, object_body=scene.object_body,
                       drive=scene.drive_to, contact_free_state=evaluator.pristine,
                       target=lambda step: reference_pose(spec, start_pos, start_rot, pivot,
                                                          step * scene.dt))
    metric = evaluator.settings.metric
    return probe_instant(ctx, 0, metric.window_steps, scene.dt, metric.perturbation_m_s2,
                         evaluator.length)


def test_object_let_go_gives_mu_s_zero(probe_evaluator):
    sphere_evaluator = probe_evaluator
    scene = _held_scene(sphere_evaluator, Pose(theta=0.0, phi=0.0, r=0.08))
    quality = _probe_at_start(sphere_evaluator, scene)
    assert not scene.in_contact()
    assert quality == pytest.approx(0.0, abs=0.02)


def _quat(rotation):
    from graspscape.workers.sim.geometry import quat_from_matrix

    return quat_from_matrix(rotation)


def test_characteristic_length_is_the_radius_of_gyration(sphere_evaluator):
    # A solid sphere of radius R: sqrt(I/m) = sqrt(2/5) R.
    assert sphere_evaluator.length == pytest.approx(math.sqrt(0.4) * 0.04, rel=0.05)


def test_probes_repeat_exactly_whatever_ran_before(mug_evaluator, monkeypatch):
    # pybullet's saved states do not hold the solver's contact cache; the probes pass through
    # a contact-free state so that a rollout never inherits the previous rollout's contacts.
    import graspscape.workers.sim.evaluate as evaluate_module

    probe = evaluate_module.probe_instant
    pairs: list[tuple[float, float]] = []

    def twice(*args, **kwargs):
        first = probe(*args, **kwargs)
        second = probe(*args, **kwargs)  # starts after the first one's seven rollouts
        pairs.append((first, second))
        return first

    monkeypatch.setattr(evaluate_module, "probe_instant", twice)
    result = mug_evaluator.evaluate(Pose(theta=1.3, phi=2.1, r=0.02, roll=1.57))
    assert result.viable and pairs
    assert all(first == second for first, second in pairs)
