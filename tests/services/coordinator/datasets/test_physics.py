"""A real (pybullet) exploration of the sphere exported as a grasp dataset: every held grasp's
transform puts the palm within the gripper's reach of the sphere and facing it."""

from __future__ import annotations

import io
import math
from concurrent.futures import ProcessPoolExecutor

import h5py
import numpy as np
import pytest
from graspscape.services.coordinator.datasets.acronym import write_acronym
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.local.run import pybullet_evaluator, run_local
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.gripper import load_gripper
from graspscape.shared.specs.objects import ObjectSpec


@pytest.mark.slow
def test_held_grasps_hold_the_palm_within_reach_of_the_sphere(sessions, named_object) -> None:
    spec = ExplorationSpec(object_id=named_object("sphere"),
                           grid={"dtheta": math.radians(60), "r_min": 0.01, "r_max": 0.01},
                           refinement={"levels": 0, "local_search_rounds": 0})
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=16, max_poses=10**6).id
    with ProcessPoolExecutor(2) as pool:
        run_local(sessions, pybullet_evaluator(ObjectSpec(name="sphere"), pool=pool), workers=2)
    buffer = io.BytesIO()
    with sessions() as s:
        write_acronym(s, eid, buffer)
    with h5py.File(buffer, "r") as f:
        transforms = np.array(f["grasps/transforms"])
        held = np.array(f["grasps/qualities/flex/object_in_gripper"]).astype(bool)
        radius = float(np.linalg.norm(f["object/mesh/vertices"], axis=1).max())
    assert held.sum() >= 0.5 * len(held) > 0
    reach = load_gripper("robotiq_3f").reach()
    for t in transforms[held]:
        palm, normal = t[:3, 3], t[:3, 2]
        distance = float(np.linalg.norm(palm))
        # The fingers close on the sphere, so its surface lies within their reach of the palm.
        assert radius <= distance <= radius + reach
        # The palm faces the sphere: its normal points at the centre, within the tilt the
        # closing fingers can give it.
        assert normal @ (-palm / distance) > math.cos(math.radians(45))
