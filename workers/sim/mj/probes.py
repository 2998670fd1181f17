"""μs probes in MuJoCo: the rollouts of workers/sim/sensitivity.py (the same perturbations,
responses and S = Δ_rel Δ_base⁻¹) from a copied mjData.

A copy of mjData is the whole simulation state, the solver's warm start included, so every
rollout from it repeats exactly: no contact-free detour is needed (pybullet's saved states
lack the contact cache; sensitivity.restore_clean).
"""

from __future__ import annotations

import mujoco
import numpy as np
from graspscape.shared.specs.sim import MetricSettings
from graspscape.workers.sim.metric import deviation_matrix, instant_quality_of_deviation
from graspscape.workers.sim.mj.scene import MjScene
from graspscape.workers.sim.sensitivity import Snapshot, _turn, responses
from graspscape.workers.sim.trajectory import ReferencePath


def _snapshot(scene: MjScene, anchor_local: np.ndarray) -> Snapshot:
    d, w = scene.data, scene.world
    rot = d.xmat[w.palm_body].reshape(3, 3).copy()
    anchor = d.xpos[w.palm_body] + rot @ anchor_local
    return Snapshot(anchor=anchor, base_rotation=rot,
                    object_rotation=d.xmat[w.object_body].reshape(3, 3).copy(),
                    relative_offset=d.xpos[w.object_body] - anchor)


def probe_state(scene: MjScene, state: mujoco.MjData, path: ReferencePath, step: int,
                metric: MetricSettings, length: float, window: int) -> float:
    """Quality 1 − σ_max(S) at trajectory `step` from its saved `state`; `window` in MuJoCo
    steps (the metric's window_steps × the substeps, the same duration as pybullet's)."""
    model, d, dt = scene.model, scene.data, scene.dt
    central = metric.differences == "central"
    linear, angular = metric.perturbation_m_s2, metric.angular_perturbation_rad_s2
    mujoco.mj_copyData(d, model, state)
    w = scene.world
    rot0 = d.xmat[w.palm_body].reshape(3, 3)
    anchor_local = rot0.T @ (d.xpos[w.object_body] - d.xpos[w.palm_body])
    pivot = d.xpos[w.object_body].copy()

    def rollout(axis: int | None, sign: float = 1.0) -> Snapshot:
        mujoco.mj_copyData(d, model, state)
        for j in range(1, window + 1):
            amount = sign * 0.5 * (j * dt) ** 2
            if axis is None or axis < 3:
                # The reference rotation: its quaternion is converted once (path.drive).
                position_list, quaternion = path.drive(step + j)
                if axis is not None:
                    position_list = list(position_list)
                    position_list[axis] += linear * amount
                scene.drive_to_quat(position_list, quaternion)
            else:
                position, rotation = path.pose(step + j)
                turn = _turn(axis - 3, angular * amount)
                scene.drive_to(pivot + turn @ (position - pivot), turn @ rotation)
            scene.step()
        return _snapshot(scene, anchor_local)

    d_base, d_rel = np.empty((6, 6)), np.empty((6, 6))
    reference = None if central else rollout(None)
    for axis in range(6):
        if central:
            reference = rollout(axis, -1.0)
        d_base[:, axis], d_rel[:, axis] = responses(rollout(axis), reference)
    return instant_quality_of_deviation(deviation_matrix(d_base, d_rel, length))
