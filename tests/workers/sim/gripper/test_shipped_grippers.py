"""Every shipped gripper closes on the sphere and holds it; the Robotiq 3F from its URDF
behaves as the TOML model does; `gripper check` flags a hand that cannot close. All slow:
each needs its collision meshes decomposed (cold) and full evaluations."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from graspscape.shared.specs.gripper import CONFIG_DIR, load_gripper
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.gripper.check import check_gripper
from graspscape.workers.sim.gripper.compare import compare, grid_50

pytestmark = pytest.mark.slow

SHIPPED = ["franka_hand", "pr2_gripper", "wsg50", "robotiq_3f_urdf", "robotiq_3f",
           "parallel_jaw"]


@pytest.mark.parametrize("name", SHIPPED)
def test_each_shipped_gripper_holds_the_sphere(make_evaluator, name: str) -> None:
    evaluator = make_evaluator("sphere", gripper=name)
    result = evaluator.evaluate(Pose(theta=math.pi / 2, phi=0.0, r=0.02))
    # Held through the trajectory after the fixture let go, by at least two fingers.
    assert result.viable and result.outcome.value == "held"
    fingers = {link.split("_")[0] for link in result.contacts_per_link} - {"palm"}
    assert len(fingers) >= 2


@pytest.mark.parametrize("name", ["franka_hand", "pr2_gripper", "robotiq_3f_urdf", "wsg50"])
def test_the_haptic_policy_runs_unchanged_on_urdf_grippers(make_evaluator, name: str) -> None:
    """G_s senses the palm and every actuated link and moves the actuated joints; a coupled
    finger moves with its driver through the gear (the WSG-50's second jaw is one)."""
    evaluator = make_evaluator("sphere", gripper=name,
                               settings=SimSettings(policy_name="haptic"))
    result = evaluator.evaluate(Pose(theta=math.pi / 2, phi=0.0, r=0.02, roll=math.pi / 2))
    assert result.viable and result.outcome.value == "held"


def test_the_urdf_robotiq_agrees_with_the_toml_one_on_the_mug(sim_cache: Path) -> None:
    agreement = compare(load_gripper("robotiq_3f"), load_gripper("robotiq_3f_urdf"), "mug",
                        grid_50(), sim_cache)
    print(f"same outcome on {agreement.same_outcome} of {agreement.poses} mug poses; "
          f"same digits on {agreement.same_digits_when_both_viable} of "
          f"{agreement.both_viable} both hold")
    assert agreement.viable_a > 5  # the grid has grasps to agree on
    assert agreement.outcome_share >= 0.8


def test_check_finds_nothing_wrong_with_the_franka_hand(sim_cache: Path,
                                                        tmp_path: Path) -> None:
    report = check_gripper(load_gripper("franka_hand"), sim_cache, tmp_path)
    assert report.problems == []
    assert report.digits == {"palm": ["palm"], "L": ["L_1"], "R": ["R_1"]}
    assert report.vendor_names["L_1"] == "panda_leftfinger"
    assert report.opening_m == pytest.approx(0.08, abs=0.005)  # 2 × 40 mm stroke
    assert 1.0 < report.mass_kg < 1.02
    assert len(report.pictures) == 4 + 6 and all(Path(p).is_file() for p in report.pictures)


def test_check_flags_a_finger_that_cannot_close(sim_cache: Path, tmp_path: Path) -> None:
    """The TOML parallel jaw with one pad opened at its closed limit: that joint cannot move."""
    text = (CONFIG_DIR / "parallel_jaw.toml").read_text()
    broken = text.replace("upper = 0.045, open = 0.0 },\n]\n\n[[fingers]]\nname = \"R\"",
                          "upper = 0.045, open = 0.045 },\n]\n\n[[fingers]]\nname = \"R\"", 1)
    assert broken != text
    path = tmp_path / "stuck_jaw.toml"
    path.write_text(broken)
    report = check_gripper(load_gripper(str(path)), sim_cache)
    assert any(problem.startswith("joint L_pad ") and "never moved" in problem
               for problem in report.problems)
