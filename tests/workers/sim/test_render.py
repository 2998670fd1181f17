"""The grasp picture's camera (workers/sim/render.py): in a real synthesized grasp, the
TinyRenderer's segmentation mask from the chosen camera shows the object with a non-trivial
share of the pixels and the fingers beside it — the palm does not hide it — where the old
fixed camera, with the approach coming from its side, saw mostly the back of the palm."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pybullet as p
import pytest
from graspscape.shared.specs.pose import Pose
from graspscape.workers.sim import render
from graspscape.workers.sim.robustness import restore_grasp
from PIL import Image

SIZE = (320, 240)
PIXELS = SIZE[0] * SIZE[1]
# Below the mug, off its axis: a grasp forms, then drops in the trajectory (cheap to simulate).
FROM_BELOW = Pose(theta=2.6, phi=1.0, r=0.01)


def _shares(evaluator, camera: render.Camera) -> tuple[float, float]:
    scene = evaluator.scene
    _, seg = render.capture(evaluator.client, camera, SIZE)
    obj, fingers = render.visible_pixels(seg, scene.hand.body, scene.object_body)
    return obj / PIXELS, fingers / PIXELS


def _fixed_camera(evaluator, yaw: float = 45.0, pitch: float = -25.0) -> render.Camera:
    """The camera `render_scene` used for every grasp picture before."""
    target = evaluator.scene.object_pose()[0]
    view = p.computeViewMatrixFromYawPitchRoll(target.tolist(), 0.35, yaw, pitch, 0.0, 2,
                                               physicsClientId=evaluator.client)
    projection = p.computeProjectionMatrixFOV(render.FOV_DEG, 4 / 3, 0.01, 5.0,
                                              physicsClientId=evaluator.client)
    return render.Camera(tuple(view), tuple(projection), 4 / 3)


def test_grasp_picture_shows_the_object_and_the_fingers(mug_evaluator, tmp_path: Path):
    picture = tmp_path / "grasp.png"
    with mug_evaluator.synthesized(FROM_BELOW, picture=picture) as (_, grasp):
        assert grasp is not None  # the hand closed on the mug
        restore_grasp(mug_evaluator, grasp)
        scene = mug_evaluator.scene
        camera = render.grasp_camera(mug_evaluator.client, scene.hand.body, scene.object_body)
        obj, fingers = _shares(mug_evaluator, camera)
        again = render.grasp_camera(mug_evaluator.client, scene.hand.body, scene.object_body)
    assert obj >= 0.01  # ≥ 1 % of the picture is the mug, not hidden behind the palm
    assert fingers >= 0.005
    assert again == camera  # deterministic
    with Image.open(picture) as image:
        assert image.size == (640, 480)
        pixels = np.asarray(image.convert("RGB"), dtype=int)
    assert (pixels.std(axis=(0, 1)) > 5).all()  # not a blank frame


@pytest.mark.slow
def test_approach_toward_the_old_camera_no_longer_shows_the_back_of_the_palm(mug_evaluator):
    # The gripper sits on the fixed camera's side of the mug: that camera saw the palm's back.
    view = np.array(p.computeViewMatrixFromYawPitchRoll([0, 0, 0], 1.0, 45.0, -25.0, 0.0, 2))
    m = view.reshape(4, 4).T
    eye = -np.linalg.inv(m[:3, :3]) @ m[:3, 3]
    pose = Pose(theta=math.acos(eye[2]), phi=math.atan2(eye[1], eye[0]), r=0.01)
    with mug_evaluator.synthesized(pose) as (_, grasp):
        assert grasp is not None
        restore_grasp(mug_evaluator, grasp)
        scene = mug_evaluator.scene
        old, _ = _shares(mug_evaluator, _fixed_camera(mug_evaluator))
        new, fingers = _shares(mug_evaluator, render.grasp_camera(
            mug_evaluator.client, scene.hand.body, scene.object_body))
    assert old < 0.01  # the palm hid the mug (measured 0.3 %)
    assert new >= 3 * old and new >= 0.01
    assert fingers >= 0.005
