"""MjEvaluator: evaluate_pose in MuJoCo. The same phases as evaluate.Evaluator (placement,
the policy's approach and closing, release, the reference trajectory, μs probes) on the same
object parts, gripper URDF, start pose rule, policy and metric; engine-specific here are
loading, saved states (copies of mjData), release (the fixture weld switched off), gravity and
the probes' rollouts (mj/probes.py).

MuJoCo steps `physics.mujoco_substeps` times per pybullet step: the step counts a policy or a
probe window is given (check_every_steps, the haptic policy's steps_per_iteration,
window_steps) are scaled by it, so each lasts as
long as in pybullet. The robustness margins and grasp tests run as pybullet's do, through
mj/robustness.py's trials; rendering through MuJoCo is not built: a picture is drawn by pybullet's
renderer from the MuJoCo grasp's poses (mj/picture.py).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import mujoco
import numpy as np
from graspscape.shared.specs.gripper import AnyGripperSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import Outcome, PhaseTimes, PoseResult, RobustnessReport
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.grasp_record import grasp_fields
from graspscape.workers.sim.metric import mu_s
from graspscape.workers.sim.mj.hand import MjHand
from graspscape.workers.sim.mj.mjcf import load_world
from graspscape.workers.sim.mj.probes import probe_state
from graspscape.workers.sim.mj.robustness import MjGrasp, capture, run_tests
from graspscape.workers.sim.mj.scene import MjScene
from graspscape.workers.sim.objects import PreparedObject
from graspscape.workers.sim.policies import get_policy
from graspscape.workers.sim.slip import slip_check
from graspscape.workers.sim.start_pose import StartPose, start_pose
from graspscape.workers.sim.trajectory import ReferencePath

PARK_HEIGHT_M = 2.0


class MjEvaluator:
    engine = "mujoco"

    def __init__(self, prepared: PreparedObject, gripper: AnyGripperSpec,
                 settings: SimSettings | None = None, *, work_dir: Path,
                 world_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        self.settings = settings = settings or SimSettings()
        self.prepared, self.gripper, self.work_dir = prepared, gripper, work_dir
        self.policy = get_policy(settings.policy_name)
        k = settings.physics.mujoco_substeps
        self.substeps = k
        # The step counts the policy reads, scaled to keep their duration (module docstring);
        # model_copy skips validation, so a scaled count may pass the spec's upper bound.
        self.run_settings = settings.model_copy(update={
            "policy": settings.policy.model_copy(
                update={"check_every_steps": settings.policy.check_every_steps * k}),
            "haptic": settings.haptic.model_copy(
                update={"steps_per_iteration": settings.haptic.steps_per_iteration * k})})
        dt = settings.physics.dt / k
        offset = np.array(world_offset, dtype=float)
        self.world, model = load_world(prepared, gripper, dt, offset, work_dir)
        self.data = mujoco.MjData(self.world.model)
        hand = MjHand(self.world, self.data, gripper, model)
        self.scene = MjScene(self.world, self.data, hand, offset, dt)
        policy = settings.policy
        hand.reset_open(gripper.spread_modes.get(settings.spread_mode, 0.0),
                        policy.closing_effort or gripper.closing_effort,
                        policy.hold_effort_factor)
        self.scene.place_hand(offset + np.array([0.0, 0.0, PARK_HEIGHT_M]), np.eye(3))
        self.scene.calibrate_drive()
        inertia = np.array(prepared.inertia_diag, dtype=float)
        metric = settings.metric
        if metric.characteristic_length == "radius_of_gyration":
            self.length = float(np.sqrt(inertia.mean() / prepared.mass_kg))
        else:
            self.length = float(metric.characteristic_length)
        self.spread = gripper.spread_modes.get(settings.spread_mode, 0.0)
        self.pristine = mujoco.MjData(self.world.model)
        mujoco.mj_copyData(self.pristine, self.world.model, self.data)

    def close(self) -> None:
        """Nothing to free: the model and data are Python objects."""

    def __enter__(self) -> MjEvaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _reset(self) -> None:
        scene = self.scene
        mujoco.mj_copyData(self.data, self.world.model, self.pristine)
        scene.set_gravity(0.0)
        scene.hold_object(True)
        policy = self.settings.policy
        scene.hand.reset_open(self.spread, policy.closing_effort or self.gripper.closing_effort,
                              policy.hold_effort_factor)
        mujoco.mj_forward(self.world.model, self.data)

    def _start_pose(self, pose: Pose) -> StartPose | None:
        return start_pose(None, self.scene, self.prepared.mesh, pose, self.settings.placement)

    def evaluate(self, pose: Pose, *, picture: Path | None = None, **_: object) -> PoseResult:
        """Simulates one pose (as Evaluator.evaluate; no donors; the robustness tests the
        settings choose). With `picture`, a PNG of the synthesized grasp."""
        return self._evaluate(pose, picture=picture)[0]

    @contextmanager
    def synthesized(self, pose: Pose) -> Iterator[tuple[PoseResult, MjGrasp | None]]:
        """Evaluates `pose` as `evaluate` does and yields its result with the synthesized grasp
        (None where no grasp formed), as Evaluator.synthesized does."""
        yield self._evaluate(pose, keep_grasp=True)

    def robustness(self, pose: Pose, settings: RobustnessSettings | None = None,
                   **_: object) -> tuple[PoseResult, RobustnessReport]:
        """As Evaluator.robustness: `pose` evaluated and, if it held, the chosen tests (None:
        every test) run on its synthesized grasp."""
        settings = settings or RobustnessSettings.every_test()
        with self.synthesized(pose) as (result, grasp):
            report = RobustnessReport()
            if grasp is not None and result.outcome is Outcome.HELD:
                report = run_tests(self, grasp, settings)
        return result.model_copy(update={"robustness": report}), report

    def _evaluate(self, pose: Pose, *, picture: Path | None = None, keep_grasp: bool = False,
                  ) -> tuple[PoseResult, MjGrasp | None]:
        started = time.perf_counter()
        phases = PhaseTimes()
        self._reset()
        start = self._start_pose(pose)
        phases.reset_s = time.perf_counter() - started
        result: dict = dict(pose=pose, pose_key=pose.key(), phases=phases)
        if start is None:
            return self._finish(started, Outcome.INFEASIBLE, result), None
        position, rotation, target, gap = start
        result["effective_r"] = gap
        outcome = self.policy.synthesize(self.scene, position, rotation, target,
                                         self.run_settings, phases)
        if outcome is not None:
            return self._finish(started, outcome, result), None
        result.update(grasp_fields(self.scene, self.length, self.prepared.mass_kg))
        if picture is not None:
            from graspscape.workers.sim.mj.picture import draw_scene

            draw_scene(self, picture)
        tests = self.settings.robustness.tests
        grasp = capture(self) if tests or keep_grasp else None
        held, qualities, effort = self._run_trajectory(phases)
        result["effort_max_nm"] = effort
        if held:
            result["mu_s"] = mu_s(qualities)
            result["viable"] = True
            if tests:
                result["robustness"] = run_tests(self, grasp, self.settings.robustness)
        return (self._finish(started, Outcome.HELD if held else Outcome.DROPPED, result),
                grasp)

    def _release(self) -> tuple[np.ndarray, np.ndarray, int]:
        """Release and settle; returns the start pose of the trajectory and the steps run."""
        scene, spec = self.scene, self.settings.trajectory
        scene.hold_object(False)
        scene.set_gravity(spec.gravity_m_s2)
        start_pos, start_rot = scene.hand.frame_pose()
        scene.drive_to(start_pos, start_rot)
        settle_steps = round(spec.settle_s / scene.dt)
        for _ in range(settle_steps):
            scene.step()
        return start_pos, start_rot, settle_steps

    def _run_trajectory(self, phases: PhaseTimes, *, probes: bool = True,
                        ) -> tuple[bool, list[float], float]:
        scene, hand = self.scene, self.scene.hand
        spec, metric = self.settings.trajectory, self.settings.metric
        t0 = time.perf_counter()
        start_pos, start_rot, settled = self._release()
        obj_pos, obj_rot = scene.object_pose()
        rel_pos0, rel_rot0 = start_rot.T @ (obj_pos - start_pos), start_rot.T @ obj_rot
        path = ReferencePath(spec, start_pos, start_rot, obj_pos, scene.dt)
        n_steps = max(1, round(spec.duration_s / scene.dt))
        instants = {min(n_steps - 1, int((k + 0.5) * n_steps / metric.instants))
                    for k in range(metric.instants)}
        slipped = slip_check(scene, spec, rel_pos0, rel_rot0)
        effort, held, ran = 0.0, scene.in_contact(), 0
        saved: dict[int, mujoco.MjData] = {}
        check = 10 * self.substeps
        for step in range(n_steps if held else 0):
            if probes and step in instants:
                saved[step] = copy = mujoco.MjData(self.world.model)
                mujoco.mj_copyData(copy, self.world.model, self.data)
            scene.drive_to_quat(*path.drive(step + 1))
            scene.step()
            ran += 1
            effort = max(effort, hand.max_finger_torque())
            if step % check == check - 1 and slipped():
                held = False
                break
        phases.trajectory_steps += settled + ran
        held = held and not slipped() and scene.in_contact()
        phases.trajectory_s += time.perf_counter() - t0
        tp = time.perf_counter()
        window = metric.window_steps * self.substeps
        qualities = [probe_state(scene, state, path, step, metric, self.length, window)
                     for step, state in sorted(saved.items())] if held else []
        phases.sensitivity_steps += len(qualities) * (12 if metric.differences == "central"
                                                      else 7) * window
        phases.sensitivity_s += time.perf_counter() - tp
        return held, qualities, effort

    def _finish(self, started: float, outcome: Outcome, result: dict) -> PoseResult:
        result.setdefault("mu_s", 0.0)
        result.setdefault("viable", False)
        result["outcome"] = outcome
        result["eval_time_s"] = time.perf_counter() - started
        return PoseResult(**result)
