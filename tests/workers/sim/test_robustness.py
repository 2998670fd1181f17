"""Robustness margins and grasp tests: the pure helpers, and their anchors measured in the
simulator (an object welded to the palm passes everything with the smallest margins, one the
hand cannot touch fails everything) plus a real grasp between them."""

from __future__ import annotations

import json
import math

import numpy as np
import pybullet as p
import pytest
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import Outcome, RobustnessReport
from graspscape.shared.specs.robustness import TEST_NAMES, RobustnessSettings
from graspscape.workers.sim.bullet import get_pose, matrix_from_quat
from graspscape.workers.sim.geometry import quat_from_matrix
from graspscape.workers.sim.robustness import (
    directions,
    displacement,
    lowest_holding,
    ramp,
    restore_grasp,
    run_tests,
    shake_offset,
    shake_timing,
    torque_ratio,
)

EVERY = RobustnessSettings.every_test()
FROM_ABOVE = Pose(theta=0.3, phi=0.0, r=0.02)

# --- pure helpers ------------------------------------------------------------------------


@pytest.mark.parametrize("threshold", [0.013, 0.37, 0.5, 0.99])
def test_bisection_brackets_the_lowest_holding_value_within_its_trials(threshold):
    calls: list[float] = []

    def holds(value: float) -> bool:
        calls.append(value)
        return value >= threshold

    found = lowest_holding(holds, 0.01, 1.0, trials=8)
    assert len(calls) <= 8
    assert found >= threshold  # never below what holds
    assert found - threshold <= (1.0 - 0.01) / 2 ** 6 + 1e-12  # 6 halvings after the bounds


def test_bisection_bounds():
    assert lowest_holding(lambda v: False, 0.1, 1.0, trials=6) is None
    assert lowest_holding(lambda v: True, 0.1, 1.0, trials=6) == 0.1
    # A known nominal result saves the first trial.
    calls: list[float] = []
    lowest_holding(lambda v: calls.append(v) or v > 0.5, 0.1, 1.0, trials=6, hi_holds=True)
    assert len(calls) == 5 and 1.0 not in calls
    assert lowest_holding(lambda v: True, 0.1, 1.0, trials=6, hi_holds=False) is None


def test_torque_ratio_is_one_minus_the_fraction_of_effort_needed():
    assert torque_ratio(1.5, 1.5) == 0.0
    assert torque_ratio(0.03, 1.5) == pytest.approx(0.98)
    assert torque_ratio(None, 1.5) is None


def test_six_directions_are_the_signed_unit_axes():
    rows = directions()
    assert rows.shape == (6, 3)
    assert np.allclose(rows.sum(axis=0), 0.0)
    assert np.allclose(np.abs(rows).sum(axis=0), 2.0)
    assert np.allclose(np.linalg.norm(rows, axis=1), 1.0)


def test_displacement_reads_distance_and_angle_in_the_hand():
    rest = (np.zeros(3), np.eye(3))
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    moved, turned = displacement(rest, (np.array([0.03, 0.04, 0.0]), turn))
    assert moved == pytest.approx(0.05)
    assert turned == pytest.approx(math.pi / 2)


def test_ramp_rises_linearly_then_stays():
    assert ramp(0.0, 100.0, 1.0) == 0.0
    assert ramp(0.25, 100.0, 1.0) == pytest.approx(25.0)
    assert ramp(3.0, 100.0, 1.0) == 100.0


def test_shake_swings_each_world_axis_in_turn_and_rests_between():
    amplitude, frequency, axis_s = 0.02, 4.0, 0.5
    per_axis = shake_timing(frequency, axis_s)
    assert per_axis == pytest.approx(0.5)
    times = np.linspace(0.0, 3 * per_axis, 3001)
    offsets = np.array([shake_offset(t, amplitude, frequency, axis_s) for t in times])
    for axis in range(3):
        inside = (times > axis * per_axis) & (times < (axis + 1) * per_axis)
        others = [a for a in range(3) if a != axis]
        assert np.allclose(offsets[inside][:, others], 0.0)
        assert offsets[inside][:, axis].max() == pytest.approx(2 * amplitude, rel=1e-3)
        assert offsets[inside][:, axis].min() >= 0.0
    # At rest in the start pose where one axis hands over to the next and at the end: no jumps.
    for t in (0.0, per_axis, 2 * per_axis, 3 * per_axis):
        assert np.allclose(shake_offset(t, amplitude, frequency, axis_s), 0.0, atol=1e-12)
    assert np.abs(np.diff(offsets, axis=0)).max() < 2 * amplitude * 2 * math.pi * frequency * (
        times[1] - times[0])


def test_settings_run_nothing_by_default_and_round_trip():
    assert RobustnessSettings().tests == ()
    every = RobustnessSettings.every_test()
    assert set(every.tests) == set(TEST_NAMES)
    assert RobustnessSettings.model_validate_json(every.model_dump_json()) == every
    with pytest.raises(ValueError):
        RobustnessSettings(tests=("wiggle",))


# --- in the simulator --------------------------------------------------------------------


@pytest.fixture(scope="module")
def own_evaluator(make_evaluator):
    # Its own client: these tests add a weld and switch collisions off, which the shared
    # evaluators must never see.
    return make_evaluator("sphere")


def test_no_test_chosen_runs_nothing(own_evaluator):
    with own_evaluator.synthesized(FROM_ABOVE) as (_, grasp):
        assert run_tests(own_evaluator, grasp, RobustnessSettings()) == RobustnessReport()


def _weld(evaluator) -> int:
    """Welds the object to the palm where it is (maxForce 1e5, as test_metric does)."""
    scene, cid = evaluator.scene, evaluator.client
    obj_pos, obj_rot = scene.object_pose()
    com, orn = get_pose(cid, scene.hand.body)
    rot = matrix_from_quat(orn)
    weld = p.createConstraint(scene.hand.body, -1, scene.object_body, -1, p.JOINT_FIXED,
                              [0, 0, 0], (rot.T @ (obj_pos - np.array(com))).tolist(), [0, 0, 0],
                              parentFrameOrientation=quat_from_matrix(rot.T @ obj_rot),
                              physicsClientId=cid)
    p.changeConstraint(weld, maxForce=1e5, physicsClientId=cid)
    return weld


@pytest.mark.slow  # seconds of physics or subprocess: the default run stays near 90 s
def test_object_welded_to_the_palm_passes_everything_with_the_smallest_margins(own_evaluator):
    ev = own_evaluator
    with ev.synthesized(Pose(theta=1.0, phi=0.5, r=0.02)) as (_, grasp):
        assert grasp is not None
        restore_grasp(ev, grasp)  # the weld must hold the object where synthesis left it
        weld = _weld(ev)
        try:
            report = run_tests(ev, grasp, EVERY)
        finally:
            p.removeConstraint(weld, physicsClientId=ev.client)
    # It holds with the lowest effort and friction tried: the margins sit at the lower bounds.
    assert report.torque_margin_nm == pytest.approx(EVERY.torque_lo_fraction * grasp.effort)
    assert report.torque_margin_ratio == pytest.approx(1.0 - EVERY.torque_lo_fraction)
    assert report.friction_margin == pytest.approx(EVERY.friction_lo)
    assert report.gravity_test_share == 1.0
    assert report.force_test_share == 1.0
    top = EVERY.tug_max_weights * grasp.mass_kg * EVERY.gravity_m_s2
    assert report.tug_force_n == pytest.approx(top)
    assert report.shake_survival_s == pytest.approx(3 * EVERY.shake_axis_s)


def test_object_the_hand_cannot_touch_fails_everything(own_evaluator):
    ev = own_evaluator
    scene, cid = ev.scene, ev.client
    with ev.synthesized(FROM_ABOVE) as (result, grasp):
        assert result.outcome is Outcome.HELD
        for link in scene.hand.link_names:
            p.setCollisionFilterPair(scene.hand.body, scene.object_body, link, -1, 0,
                                     physicsClientId=cid)
        try:
            report = run_tests(ev, grasp, EVERY)
        finally:
            for link in scene.hand.link_names:
                p.setCollisionFilterPair(scene.hand.body, scene.object_body, link, -1, 1,
                                         physicsClientId=cid)
    # It drops even at the full closing effort and the object's own friction: no margin.
    assert report.torque_margin_nm is None and report.torque_margin_ratio is None
    assert report.friction_margin is None
    assert report.gravity_test_share == 0.0
    assert report.force_test_share == 0.0
    assert report.tug_force_n == 0.0
    assert report.shake_survival_s == pytest.approx(0.0, abs=0.02)


def test_pose_that_is_not_held_gets_an_empty_report(own_evaluator):
    result, report = own_evaluator.robustness(
        Pose(theta=math.pi / 2, phi=0.0, r=0.02, pitch=math.pi))
    assert result.outcome is not Outcome.HELD
    assert report == RobustnessReport()
    assert result.robustness == report


def _comparable(result):
    data = result.model_dump(mode="json")
    for key in ("eval_time_s", "phases", "robustness"):
        data.pop(key)
    return data


@pytest.mark.slow
def test_real_grasp_of_the_sphere_from_above_lies_between_the_anchors(sphere_evaluator):
    ev = sphere_evaluator
    result, report = ev.robustness(FROM_ABOVE)
    # The robustness run evaluates the pose exactly as evaluate does and leaves no trace: a
    # plain evaluation after it gives the same result.
    plain = ev.evaluate(FROM_ABOVE)
    assert _comparable(result) == _comparable(plain)
    assert plain.robustness is None and result.robustness == report

    assert result.outcome is Outcome.HELD
    effort = ev.gripper.closing_effort
    # The sphere hangs under the palm in the fingers: it needs some squeeze and some friction,
    # but not all the closing effort nor all its friction (0.8).
    assert EVERY.torque_lo_fraction * effort < report.torque_margin_nm < effort
    assert 0.0 < report.torque_margin_ratio < 1.0 - EVERY.torque_lo_fraction
    assert EVERY.friction_lo < report.friction_margin < ev.prepared.friction
    assert 0.0 < report.gravity_test_share <= 1.0
    assert 0.0 < report.force_test_share <= 1.0
    top = EVERY.tug_max_weights * ev.prepared.mass_kg * EVERY.gravity_m_s2
    assert 0.0 < report.tug_force_n <= top
    assert 0.0 < report.shake_survival_s <= 3 * EVERY.shake_axis_s


@pytest.mark.slow  # seconds of physics or subprocess: the default run stays near 90 s
def test_tests_repeat_exactly_whatever_ran_before(own_evaluator):
    ev = own_evaluator
    chosen = RobustnessSettings(tests=("torque_margin", "shake"))
    with ev.synthesized(Pose(theta=1.1, phi=0.7, r=0.03, roll=0.4)) as (_, grasp):
        first = run_tests(ev, grasp, chosen)
        run_tests(ev, grasp, RobustnessSettings(tests=("tug",)))
        ev.evaluate(Pose(theta=2.0, phi=1.0, r=0.02))
        second = run_tests(ev, grasp, chosen)
    assert first == second
    assert first.torque_margin_nm is not None


@pytest.mark.slow  # seconds of physics or subprocess: the default run stays near 90 s
def test_eval_pose_command_prints_the_report(sim_cache, monkeypatch, capsys):
    # `--robustness` alone runs every test; a choice keeps this test quick.
    import graspscape.workers.sim.evaluate as evaluate_module
    from graspscape.services.local.cli import build_parser, main

    assert build_parser().parse_args(
        ["eval-pose", "--theta", "0", "--phi", "0", "--robustness"]).robustness == "all"
    made: dict = {}
    monkeypatch.setattr(evaluate_module, "_EVALUATORS", made)
    monkeypatch.setenv("GRASPSCAPE_CACHE_DIR", str(sim_cache))
    try:
        assert main(["eval-pose", "sphere", "--theta", "17.19", "--phi", "0",
                     "--robustness", "tug,shake"]) == 0
    finally:
        for evaluator in made.values():
            evaluator.close()
    printed = json.loads(capsys.readouterr().out)
    assert printed["outcome"] == "held"
    report = printed["robustness"]
    assert set(report) == set(RobustnessReport.model_fields)
    assert report["tug_force_n"] > 0.0 and report["shake_survival_s"] > 0.0
    assert {key for key, value in report.items() if value is None} == set(
        RobustnessReport.model_fields) - {"tug_force_n", "shake_survival_s"}


def test_tests_chosen_in_the_settings_run_on_every_held_evaluation(make_evaluator):
    from graspscape.shared.specs.sim import SimSettings

    settings = SimSettings(robustness=RobustnessSettings(tests=("torque_margin",)))
    evaluator = make_evaluator("sphere", settings=settings)
    held = evaluator.evaluate(FROM_ABOVE)
    assert held.outcome is Outcome.HELD
    assert held.robustness is not None and held.robustness.torque_margin_ratio is not None
    assert held.robustness.gravity_test_share is None  # not chosen
    empty = evaluator.evaluate(Pose(theta=0.0, phi=0.0, r=0.5))  # the open hand touches nothing
    assert empty.outcome is not Outcome.HELD
    assert empty.robustness == RobustnessReport()


@pytest.mark.slow
def test_a_fingertip_clamp_ranks_below_a_body_wrap_of_the_same_mug(mug_evaluator):
    # The pair under the default task: a two-fingertip clamp of the rim (A_3 and B_3
    # only) and the wrap of the body in docs/design/simulation.md's picture. Both hold, and μs
    # cannot tell them apart (≈ 0.97 each); the margins can: the clamp needs most of its closing
    # effort and all of its friction, the wrap little of either.
    margins = RobustnessSettings(tests=("torque_margin", "friction_margin"))
    clamp, clamp_report = mug_evaluator.robustness(
        Pose(theta=1.0472, phi=6.0868, r=0.025), margins)
    wrap, wrap_report = mug_evaluator.robustness(
        Pose(theta=1.5708, phi=3.1416, r=0.02, roll=1.5708), margins)
    assert clamp.outcome is Outcome.HELD and wrap.outcome is Outcome.HELD
    assert set(clamp.signature.links_in_contact) == {"A_3", "B_3"}
    assert "palm" in wrap.signature.links_in_contact
    assert clamp_report.torque_margin_ratio < wrap_report.torque_margin_ratio
    assert clamp_report.friction_margin > wrap_report.friction_margin
