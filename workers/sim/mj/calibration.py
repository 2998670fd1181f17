"""The estimator's anchor in MuJoCo: μs of an object welded to the palm (calibration.py's
`weld_reading` for pybullet). A weld moves the object exactly with the hand, so a sound probe
reads S = 0 and μs = 1 (docs/concepts/quality.md, "The estimator")."""

from __future__ import annotations

import mujoco
import numpy as np
from graspscape.shared.specs.pose import Pose
from graspscape.workers.sim.mj.probes import probe_state
from graspscape.workers.sim.trajectory import ReferencePath


def _weld_here(evaluator) -> None:
    """Turns the palm-object weld on at the present relative pose (the hand stands clear of
    the object, so no contact ever forms while it moves with the palm)."""
    d, w, m = evaluator.data, evaluator.world, evaluator.world.model
    mujoco.mj_forward(m, d)
    palm, obj = w.palm_body, w.object_body
    inverse, relative = np.empty(4), np.empty(4)
    mujoco.mju_negQuat(inverse, d.xquat[palm])
    mujoco.mju_mulQuat(relative, inverse, d.xquat[obj])
    # The weld's data: the anchor (0), then the object's pose in the palm's frame (measured:
    # the other reading drifts 2 cm in 0.2 s).
    rel_pos = d.xmat[palm].reshape(3, 3).T @ (d.xpos[obj] - d.xpos[palm])
    m.eq_data[w.grip_weld, :10] = [0.0, 0.0, 0.0, *rel_pos, *relative]
    d.eq_active[w.grip_weld] = 1


def weld_reading(evaluator, pose: Pose) -> list[float]:
    """Per-instant qualities 1 − σ_max(S) of the object welded to the palm at the start pose
    of `pose` ([] where it is infeasible), through the same trajectory and probes."""
    evaluator._reset()
    start = evaluator._start_pose(pose)
    if start is None:
        return []
    scene = evaluator.scene
    scene.place_hand(start[0], start[1])
    _weld_here(evaluator)
    scene.hold_object(False)
    spec, metric = evaluator.settings.trajectory, evaluator.settings.metric
    scene.set_gravity(spec.gravity_m_s2)
    start_pos, start_rot = scene.hand.frame_pose()
    path = ReferencePath(spec, start_pos, start_rot, scene.object_pose()[0], scene.dt)
    n_steps = max(1, round(spec.duration_s / scene.dt))
    instants = {min(n_steps - 1, int((k + 0.5) * n_steps / metric.instants))
                for k in range(metric.instants)}
    window = metric.window_steps * evaluator.substeps
    qualities = []
    for step in range(n_steps):
        if step in instants:
            state = mujoco.MjData(evaluator.world.model)
            mujoco.mj_copyData(state, evaluator.world.model, evaluator.data)
            qualities.append(probe_state(scene, state, path, step, metric, evaluator.length,
                                         window))
            mujoco.mj_copyData(evaluator.data, evaluator.world.model, state)
        scene.drive_to_quat(*path.drive(step + 1))
        scene.step()
    return qualities
