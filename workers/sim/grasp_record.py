"""What a result records about the synthesized grasp, read from the scene of either engine
(workers/sim/engine.py): the grasp configuration in the object frame, the grasp-type
signature, contacts per link and the static metrics μg, μf, μm."""

from __future__ import annotations

import numpy as np
from graspscape.shared.specs.results import GraspConfiguration
from graspscape.workers.sim.geometry import quat_from_matrix
from graspscape.workers.sim.grasp_metrics import scene_metrics
from graspscape.workers.sim.signature import build_signature


def grasp_fields(scene, length: float, mass_kg: float) -> dict:
    """The result's grasp, signature, contacts_per_link, mu_g, mu_f and mu_m."""
    hand = scene.hand
    obj_pos, obj_rot = scene.object_pose()
    base_pos, base_rot = hand.frame_pose()
    rel_rot = obj_rot.T @ base_rot
    raw = [(hand.link_names[c.link_index_a],
            tuple((obj_rot.T @ (np.array(c.position_on_b) - obj_pos)).tolist()),
            c.normal_force) for c in scene.contacts()]
    angles = hand.joint_angles()
    fields: dict = {
        "grasp": GraspConfiguration(
            base_position=tuple((obj_rot.T @ (base_pos - obj_pos)).tolist()),
            base_orientation=tuple(quat_from_matrix(rel_rot)),
            joint_angles=angles,
        ),
        "signature": build_signature(raw, angles),
    }
    counts: dict[str, int] = {}
    for link, _, _ in raw:
        counts[link] = counts.get(link, 0) + 1
    fields["contacts_per_link"] = counts
    fields.update(scene_metrics(scene, length, mass_kg))  # μg, μf, μm
    return fields
