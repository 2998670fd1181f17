"""A picture of a MuJoCo grasp, drawn by the same renderer as pybullet's pictures
(render.render_grasp, TinyRenderer: headless, no OpenGL): the object and the hand are loaded
into a throwaway pybullet client and posed as MuJoCo has them, without stepping."""

from __future__ import annotations

from pathlib import Path

import pybullet as p
from graspscape.shared.specs.gripper import MjcfGripperSpec
from graspscape.workers.sim.geometry import quat_from_matrix
from graspscape.workers.sim.gripper.hand import Hand
from graspscape.workers.sim.objects import forget_client, spawn_object
from graspscape.workers.sim.render import render_grasp


def draw_scene(evaluator, path: Path) -> Path:
    """Writes the present MuJoCo scene of `evaluator` (an MjEvaluator) to `path` (PNG)."""
    if isinstance(evaluator.gripper, MjcfGripperSpec):
        raise ValueError(f"no picture of {evaluator.gripper.name}: pictures are drawn by "
                         "pybullet's renderer, which loads TOML and URDF grippers, not MJCF")
    cid = p.connect(p.DIRECT)
    try:
        scene, mj_hand = evaluator.scene, evaluator.scene.hand
        body = spawn_object(cid, evaluator.prepared)
        obj_pos, obj_rot = scene.object_pose()
        p.resetBasePositionAndOrientation(body, obj_pos.tolist(), quat_from_matrix(obj_rot),
                                          physicsClientId=cid)
        hand = Hand(cid, evaluator.gripper, evaluator.work_dir / "urdf")
        com, orn = hand.com_pose_for(*mj_hand.frame_pose())
        p.resetBasePositionAndOrientation(hand.body, com, orn, physicsClientId=cid)
        for name, joint in hand.joint_by_name.items():
            if name in mj_hand.joint_by_name:
                q = float(mj_hand.data.qpos[mj_hand._qpos[mj_hand.joint_by_name[name]]])
                p.resetJointState(hand.body, joint, q, 0.0, physicsClientId=cid)
        p.performCollisionDetection(physicsClientId=cid)
        return render_grasp(cid, hand.body, body, path)
    finally:
        p.disconnect(cid)
        forget_client(cid)
