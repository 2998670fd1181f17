"""Grippers described by an MJCF (MuJoCo Menagerie's Robotiq 2F-85 and Franka hand, shipped as
menagerie_robotiq_2f85 and menagerie_franka_hand): loaded by name in the MuJoCo engine, closed
through their own tendon actuator, refused by pybullet (workers/sim/mj/mjcf.py)."""

from __future__ import annotations

import math
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest
from graspscape.shared.specs.gripper import MjcfGripperSpec, list_grippers, load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import Outcome
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.engine import make_evaluator
from graspscape.workers.sim.evaluate import Evaluator
from graspscape.workers.sim.gripper.urdf_import import GripperFileError
from graspscape.workers.sim.mj.evaluate import MjEvaluator
from graspscape.workers.sim.objects import prepare_object

MENAGERIE = ("menagerie_robotiq_2f85", "menagerie_franka_hand")
MUJOCO = SimSettings(engine="mujoco")
# The closing axis (the gripper frame's x) horizontal, the palm toward the sphere's side.
FROM_SIDE = Pose(theta=math.pi / 2, phi=0.0, r=0.01)
FACING_AWAY = Pose(theta=math.pi / 2, phi=0.0, r=0.02, pitch=math.pi)


@pytest.fixture(scope="module")
def small_sphere(object_cache: Path):
    """A 5 cm sphere (the built-in 8 cm one scaled), 0.2 kg."""
    return prepare_object(ObjectSpec(name="sphere", scale=0.625), object_cache)


@pytest.fixture(scope="module", params=MENAGERIE)
def menagerie_hand(request, small_sphere, sim_cache: Path) -> MjEvaluator:
    return make_evaluator(small_sphere, load_gripper(request.param), MUJOCO, work_dir=sim_cache)


def test_menagerie_hands_are_listed_with_their_licences() -> None:
    for name in MENAGERIE:
        assert name in list_grippers()
        spec = load_gripper(name)
        assert isinstance(spec, MjcfGripperSpec)
        folder = Path(spec.folder)
        assert (folder / spec.mjcf).is_file() and (folder / "LICENSE").is_file()
        assert "LICENSE" in spec.licence and "Menagerie" in spec.source


def test_each_menagerie_hand_holds_and_lifts_a_5_cm_sphere_gripped_from_the_side(
        menagerie_hand: MjEvaluator) -> None:
    result = menagerie_hand.evaluate(FROM_SIDE)
    # HELD: the sphere stayed in the hand through the lift (15 cm up, 15 cm sideways).
    assert result.outcome is Outcome.HELD, result.outcome
    assert result.viable and result.mu_s > 0.5
    fingers = {link[0] for link in result.contacts_per_link if link != "palm"}
    assert fingers == {"L", "R"}  # squeezed from both sides
    assert result.effort_max_nm is not None and result.effort_max_nm > 0.1


def test_a_menagerie_hand_facing_away_grasps_nothing(menagerie_hand: MjEvaluator) -> None:
    result = menagerie_hand.evaluate(FACING_AWAY)
    assert result.outcome is not Outcome.HELD
    assert not result.viable and result.mu_s == 0.0


def test_the_2f85_closes_through_its_linkage(small_sphere, sim_cache: Path) -> None:
    """One tendon actuator drives both drivers; the followers (passive, closed by the four-bar
    equalities) are what touch the sphere, and they count for their finger."""
    evaluator = make_evaluator(small_sphere, load_gripper("menagerie_robotiq_2f85"), MUJOCO,
                               work_dir=sim_cache)
    assert evaluator.world.model.nu == 1
    assert evaluator.world.transmission == {"left_driver_joint": (1.0, 0.5),
                                            "right_driver_joint": (1.0, 0.5)}
    result = evaluator.evaluate(FROM_SIDE)
    assert result.outcome is Outcome.HELD
    angles = result.signature.joint_angles
    assert angles["L_1"] == pytest.approx(angles["R_1"], abs=0.01)  # the drivers' equality
    assert 0.05 < angles["L_1"] < 0.8  # stopped by the sphere, short of the range's end
    assert {"L_4", "R_4"} <= set(result.contacts_per_link)  # the followers' pads


def test_pybullet_refuses_an_mjcf_gripper_naming_the_mujoco_engine(small_sphere,
                                                                    sim_cache: Path) -> None:
    with pytest.raises(GripperFileError, match="--engine mujoco"):
        Evaluator(small_sphere, load_gripper("menagerie_franka_hand"), SimSettings(),
                  work_dir=sim_cache)


def _copy_with(tmp_path: Path, name: str, edit) -> MjcfGripperSpec:
    folder = tmp_path / name
    shutil.copytree(Path(load_gripper(name).folder), folder)
    with (folder / "gripper.toml").open("rb") as fh:
        data = tomllib.load(fh)
    edit(data)
    return MjcfGripperSpec.model_validate({**data, "folder": folder})


def test_an_unnamed_moving_joint_is_refused(tmp_path: Path, small_sphere) -> None:
    def drop_passive(data: dict) -> None:
        data["fingers"][0]["passive"] = []

    spec = _copy_with(tmp_path, "menagerie_robotiq_2f85", drop_passive)
    with pytest.raises(GripperFileError, match="left_coupler_joint"):
        MjEvaluator(small_sphere, spec, MUJOCO, work_dir=tmp_path)


def test_an_actuator_that_does_not_move_a_finger_is_refused(tmp_path: Path,
                                                            small_sphere) -> None:
    def wrong_actuator(data: dict) -> None:
        data["actuator"] = "no_such_actuator"

    spec = _copy_with(tmp_path, "menagerie_franka_hand", wrong_actuator)
    with pytest.raises(GripperFileError, match="no_such_actuator"):
        MjEvaluator(small_sphere, spec, MUJOCO, work_dir=tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("name", MENAGERIE)
def test_gripper_check_in_mujoco_finds_no_problem(name: str, sim_cache: Path) -> None:
    from graspscape.workers.sim.mj.check import check_gripper_mujoco

    report = check_gripper_mujoco(load_gripper(name), sim_cache)
    assert report.kind == "mjcf"
    assert not report.problems, report.problems
    assert all(t.viable for t in report.trials if t.object == "sphere")
    assert abs(report.reach_m - report.declared_reach_m) < 0.005


def test_explore_refuses_an_mjcf_gripper_without_the_mujoco_engine(capsys) -> None:
    from graspscape.services.local.cli import main

    assert main(["explore", "sphere", "--gripper", "menagerie_franka_hand"]) == 2
    assert "--engine mujoco" in capsys.readouterr().err


@pytest.mark.parametrize("turn", [0.0, math.pi / 2, 2.5])
def test_the_arm_drive_holds_a_turned_hand_still(small_sphere, sim_cache: Path,
                                                 turn: float) -> None:
    """The 2F-85's centre of mass lies 5 cm behind its palm: however the hand is turned, the
    drive holds it where it is told (the block of the mass matrix coupling the palm's linear
    and angular motion turns with the palm)."""
    from scipy.spatial.transform import Rotation

    evaluator = make_evaluator(small_sphere, load_gripper("menagerie_robotiq_2f85"), MUJOCO,
                               work_dir=sim_cache)
    evaluator._reset()
    scene, data = evaluator.scene, evaluator.data
    rotation = Rotation.from_rotvec([turn, 0.3 * turn, 0.0]).as_matrix()
    target = scene.offset + np.array([0.0, 0.0, 0.5])
    scene.place_hand(target, rotation)
    for _ in range(200):  # 0.4 s
        scene.drive_to(target, rotation)
        scene.step()
    position, now = scene.hand.frame_pose()
    assert float(abs(data.qvel[evaluator.world.palm_dofs]).max()) < 1e-3
    assert float(abs(position - target).max()) < 1e-4
    assert Rotation.from_matrix(now @ rotation.T).magnitude() < 1e-3


def test_a_spec_naming_an_mjcf_gripper_in_pybullet_is_refused_at_submit() -> None:
    """The REST path: the spec itself is refused, for the exploration's engine and for the
    engines its P(success) draws run in; in MuJoCo alone it is taken."""
    from graspscape.shared.specs.exploration import ExplorationSpec
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="only the MuJoCo engine"):
        ExplorationSpec(object_id=1, gripper="menagerie_franka_hand")
    mujoco = {"engine": "mujoco"}
    with pytest.raises(ValidationError, match="asked for: pybullet"):
        ExplorationSpec(object_id=1, gripper="menagerie_franka_hand", settings=mujoco,
                        uncertainty={"preset": "lab", "engines": ["mujoco", "pybullet"]})
    spec = ExplorationSpec(object_id=1, gripper="menagerie_franka_hand", settings=mujoco)
    assert spec.settings.engine == "mujoco"
