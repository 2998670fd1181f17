"""A gripper from a URDF plus its description: what the rewrite refuses and what it makes
(pure XML and files, no physics), and one gear-coupled gripper closing in pybullet."""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pybullet as p
import pytest
from graspscape.shared.specs.gripper import (
    UrdfGripperSpec,
    list_grippers,
    load_gripper,
)
from graspscape.workers.sim.gripper.hand import Hand
from graspscape.workers.sim.gripper.urdf_import import (
    GripperFileError,
    prepare_urdf,
    resolve_inside,
)

# Two fingers on prismatic joints; the right follows the left (a <mimic>), and both close as
# their values shrink (the URDF's value is each finger's distance from the middle, like
# Franka's). The base link's origin is 5 cm below the palm surface.
URDF = """<?xml version="1.0"?>
<robot name="jaw">
  <link name="base">
    <inertial><origin xyz="0 0 0.025"/><mass value="0.5"/>
      <inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial>
    <collision><origin xyz="0 0 0.025"/><geometry>MESH</geometry></collision>
  </link>
  <joint name="left" type="prismatic"><parent link="base"/><child link="left_pad"/>
    <origin xyz="0 0 0.05"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.05" effort="1" velocity="1"/>
  </joint>
  <link name="left_pad">
    <inertial><origin xyz="0 0 0.03"/><mass value="0.05"/>
      <inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial>
    <collision><origin xyz="0.005 0 0.03"/>
      <geometry><box size="0.01 0.02 0.06"/></geometry></collision>
  </link>
  <joint name="right" type="prismatic"><parent link="base"/><child link="right_pad"/>
    <origin xyz="0 0 0.05"/><axis xyz="-1 0 0"/>
    <limit lower="0" upper="0.05" effort="1" velocity="1"/>
    <mimic joint="left"/>
  </joint>
  <link name="right_pad">
    <inertial><origin xyz="0 0 0.03"/><mass value="0.05"/>
      <inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial>
    <collision><origin xyz="-0.005 0 0.03"/>
      <geometry><box size="0.01 0.02 0.06"/></geometry></collision>
  </link>
</robot>
"""

DESCRIPTION = """
name = "jaw"
urdf = "jaw.urdf"
base_link = "base"
closing_effort = 20.0
reach_m = 0.06
palm = { origin = [0.0, 0.0, 0.05] }
[[fingers]]
name = "L"
joints = [{ joint = "left", open = 0.04, closing = -1 }]
[[fingers]]
name = "R"
joints = [{ joint = "right", open = 0.04, closing = -1, mimic = { joint = "left" } }]
"""

BOX = '<box size="0.1 0.04 0.05"/>'


def _gripper(folder: Path, mesh: str = BOX, description: str = DESCRIPTION) -> UrdfGripperSpec:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "jaw.urdf").write_text(URDF.replace("MESH", mesh))
    (folder / "gripper.toml").write_text(description)
    spec = load_gripper(str(folder))
    assert isinstance(spec, UrdfGripperSpec)
    return spec


@pytest.mark.parametrize("filename", [
    "../outside.obj",
    "meshes/../../outside.obj",
    "package://jaw/../outside.obj",
    "OUTSIDE_ABSOLUTE",
    "file://OUTSIDE_ABSOLUTE",
])
def test_a_mesh_path_escaping_the_folder_is_refused(tmp_path: Path, filename: str) -> None:
    outside = tmp_path / "outside.obj"
    outside.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    filename = filename.replace("OUTSIDE_ABSOLUTE", str(outside))
    spec = _gripper(tmp_path / "jaw", f'<mesh filename="{filename}"/>')
    with pytest.raises(GripperFileError, match="outside the gripper's folder"):
        prepare_urdf(spec, tmp_path / "cache")


def test_a_link_pointing_out_of_the_folder_is_refused(tmp_path: Path) -> None:
    outside = tmp_path / "outside.obj"
    outside.write_text("v 0 0 0\n")
    folder = tmp_path / "jaw"
    spec = _gripper(folder, '<mesh filename="meshes/base.obj"/>')
    (folder / "meshes").mkdir()
    os.symlink(outside, folder / "meshes" / "base.obj")
    with pytest.raises(GripperFileError, match="outside the gripper's folder"):
        prepare_urdf(spec, tmp_path / "cache")


def test_package_urls_map_to_the_folder(tmp_path: Path) -> None:
    (tmp_path / "meshes").mkdir()
    mesh = tmp_path / "meshes" / "a.stl"
    mesh.write_text("solid a\nendsolid a\n")
    assert resolve_inside(tmp_path, "package://any_pkg/meshes/a.stl") == mesh.resolve()
    assert resolve_inside(tmp_path, "package://meshes/a.stl") == mesh.resolve()
    with pytest.raises(GripperFileError, match="not in the gripper's folder"):
        resolve_inside(tmp_path, "package://any_pkg/meshes/b.stl")


def test_a_moving_joint_no_finger_names_is_refused(tmp_path: Path) -> None:
    only_left = DESCRIPTION.split("[[fingers]]\nname = \"R\"")[0]
    spec = _gripper(tmp_path / "jaw", description=only_left)
    with pytest.raises(GripperFileError, match="right move but are in no finger"):
        prepare_urdf(spec, tmp_path / "cache")


def test_the_rewrite_puts_the_base_at_the_palm_and_closes_positive(tmp_path: Path) -> None:
    prepared = prepare_urdf(_gripper(tmp_path / "jaw"), tmp_path / "cache")
    robot = ET.parse(prepared.path).getroot()
    assert sorted(link.get("name") for link in robot.findall("link")) == ["L_1", "R_1", "palm"]
    joints = {j.get("name"): j for j in robot.findall("joint")}
    left = joints["L_1_joint"]
    # The palm surface (z = 0.05 in the base link) is the new origin: the joint sits on it.
    assert np.allclose([float(v) for v in left.find("origin").get("xyz").split()], 0.0)
    # Closing toward smaller values: axis and limits turned around.
    assert [float(v) for v in left.find("axis").get("xyz").split()] == [-1.0, 0.0, 0.0]
    assert float(left.find("limit").get("lower")) == -0.05
    assert float(left.find("limit").get("upper")) == 0.0
    assert robot.find("joint/mimic") is None
    (finger,) = prepared.fingers
    assert finger.joints == ("L_1_joint",) and finger.open_values == (-0.04,)
    (coupling,) = prepared.couplings
    assert (coupling.follower, coupling.driver, coupling.ratio) == ("R_1_joint", "L_1_joint", 1.0)
    assert prepared.vendor_names["L_1"] == "left_pad"


def _close(spec: UrdfGripperSpec, cache: Path, box: bool) -> tuple[dict[str, float], set[int],
                                                                   dict[str, int]]:
    """Closes the hand fixed at the origin for 2 s, on a 3 cm box between the pads or in free
    air: the joint angles, the links touching the box, the joint indices."""
    client = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, 0, physicsClientId=client)
        hand = Hand(client, spec, cache)
        com, orn = hand.com_pose_for(np.zeros(3), np.eye(3))
        p.resetBasePositionAndOrientation(hand.body, com, orn, physicsClientId=client)
        p.createConstraint(hand.body, -1, -1, -1, p.JOINT_FIXED, [0, 0, 0],
                           (-hand.base_inertial_offset).tolist(), [0, 0, 0],
                           physicsClientId=client)
        target = p.createMultiBody(0, p.createCollisionShape(
            p.GEOM_BOX, halfExtents=[0.015, 0.01, 0.02], physicsClientId=client),
            basePosition=[0, 0, 0.03 if box else 1.0], physicsClientId=client)
        hand.reset_open(0.0, spec.closing_effort, 3.0)
        hand.begin_closing(0.2)
        for _ in range(480):
            p.stepSimulation(physicsClientId=client)
        touching = {c[3] for c in p.getContactPoints(hand.body, target, physicsClientId=client)}
        return hand.joint_angles(), touching, hand.joint_by_name
    finally:
        p.disconnect(client)


def test_the_follower_closes_with_its_driver_on_a_box(tmp_path: Path) -> None:
    """Physics: one actuator, two fingers. The follower moves only through the gear constraint,
    so both pads reaching a box in the middle at the same time is the coupling at work."""
    angles, touching, joints = _close(_gripper(tmp_path / "jaw"), tmp_path / "cache", box=True)
    # Each pad stops at the box's face, 15 mm from the middle (closing-positive: −0.015).
    assert angles["L_1"] == pytest.approx(-0.015, abs=1e-3)
    assert angles["R_1"] == pytest.approx(-0.015, abs=1e-3)
    assert touching == {joints["L_1_joint"], joints["R_1_joint"]}


def test_a_mimic_offset_holds_once_the_driver_stops(tmp_path: Path) -> None:
    """right = left + 1 cm (URDF values): in free air the driver stops at its limit (0) and the
    follower stays 1 cm more open, held there by the gear's position correction."""
    description = DESCRIPTION.replace('mimic = { joint = "left" }',
                                      'mimic = { joint = "left", offset = 0.01 }')
    angles, _, _ = _close(_gripper(tmp_path / "jaw", description=description),
                          tmp_path / "cache", box=False)
    assert angles["L_1"] == pytest.approx(0.0, abs=1e-3)
    assert angles["R_1"] == pytest.approx(-0.01, abs=1e-3)


def test_shipped_grippers_are_listed_with_their_licences() -> None:
    names = list_grippers()
    for name in ("franka_hand", "pr2_gripper", "wsg50", "robotiq_3f_urdf"):
        assert name in names
        spec = load_gripper(name)
        assert isinstance(spec, UrdfGripperSpec)
        assert spec.source and spec.licence
        assert "LICENSE.txt" in spec.licence and (Path(spec.folder) / "LICENSE.txt").is_file()
    assert math.isclose(load_gripper("wsg50").reach(), 0.19)
