"""evaluate_pose: one initial relative pose in, one scored grasp out.

An Evaluator owns one pybullet client with the object and the gripper loaded once. Every
evaluation starts by restoring the state saved right after loading (positions, velocities and
the contact cache), and sets every motor, constraint and gravity it uses, so a result never
depends on what the client evaluated before. Phases: placement (with back-off from
interpenetration, or at a clearance: `placement.start_gap`), approach (policy), closing
(policy), release and trajectory with μs probes.
`Evaluator.robustness` also keeps the synthesized grasp and runs the margins and grasp tests of
workers/sim/robustness.py on it.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import numpy as np
import pybullet as p
from graspscape.shared.specs.gripper import GripperSpec, load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import (
    Outcome,
    PhaseTimes,
    PoseResult,
    RobustnessReport,
)
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim import table as on_table
from graspscape.workers.sim.bullet import (
    max_abs_motor_torque,
    remove_state,
    restore_state,
    save_state,
    saved_state,
)
from graspscape.workers.sim.configuration_inference import DonorPool, inferred
from graspscape.workers.sim.engine import make_evaluator
from graspscape.workers.sim.grasp_record import grasp_fields
from graspscape.workers.sim.gripper.hand import Hand
from graspscape.workers.sim.metric import mu_s
from graspscape.workers.sim.objects import (
    PreparedObject,
    forget_client,
    prepare_object,
    spawn_object,
)
from graspscape.workers.sim.policies import get_policy
from graspscape.workers.sim.render import render_grasp
from graspscape.workers.sim.robustness import SynthesizedGrasp, capture_grasp, run_tests
from graspscape.workers.sim.scene import Scene
from graspscape.workers.sim.sensitivity import ProbeContext, probe_instant
from graspscape.workers.sim.slip import slip_check
from graspscape.workers.sim.start_pose import StartPose, place_hand, start_pose
from graspscape.workers.sim.trajectory import ReferencePath

FIXTURE_MAX_FORCE_N = 5000.0


class Evaluator:
    def __init__(self, prepared: PreparedObject, gripper: GripperSpec,
                 settings: SimSettings | None = None, *, work_dir: Path,
                 world_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        self.settings = settings or SimSettings()
        self.prepared = prepared
        self.gripper = gripper
        self.policy = get_policy(self.settings.policy_name)
        physics = self.settings.physics
        cid = p.connect(p.DIRECT)
        self.client = cid
        p.setPhysicsEngineParameter(fixedTimeStep=physics.dt,
                                    numSolverIterations=physics.solver_iterations,
                                    deterministicOverlappingPairs=1, physicsClientId=cid)
        offset = np.array(world_offset, dtype=float)
        table = self.settings.table
        # On a table the object starts at its resting attitude (world = table frame); the
        # fixture, should a test hold it, holds it there.
        attitude = [0.0, 0.0, 0.0, 1.0] if table is None else list(table.resting.quaternion)
        object_body = spawn_object(cid, prepared, tuple(offset), attitude)
        hand = Hand(cid, gripper, work_dir / "urdf")
        fixture = p.createConstraint(object_body, -1, -1, -1, p.JOINT_FIXED, [0, 0, 0],
                                     [0, 0, 0], offset.tolist(), childFrameOrientation=attitude,
                                     physicsClientId=cid)
        park = offset + np.array([0.0, 0.0, 2.0])
        com, orn = hand.com_pose_for(park, np.eye(3))
        p.resetBasePositionAndOrientation(hand.body, com, orn, physicsClientId=cid)
        drive = p.createConstraint(hand.body, -1, -1, -1, p.JOINT_FIXED, [0, 0, 0],
                                   (-hand.base_inertial_offset).tolist(), park.tolist(),
                                   physicsClientId=cid)
        self.scene = Scene(client=cid, hand=hand, object_body=object_body,
                           drive_constraint=drive, fixture_constraint=fixture, offset=offset,
                           dt=physics.dt)
        if table is not None:
            on_table.set_table(self.scene, table, prepared.friction)
        inertia = np.array(prepared.inertia_diag, dtype=float)
        metric = self.settings.metric
        if metric.characteristic_length == "radius_of_gyration":
            self.length = float(np.sqrt(inertia.mean() / prepared.mass_kg))
        else:
            self.length = float(metric.characteristic_length)
        self.spread = gripper.spread_modes.get(self.settings.spread_mode, 0.0)
        self.pristine = save_state(cid)

    @property
    def run_settings(self) -> SimSettings:
        """The settings the policy runs under (MuJoCo's scales its step counts)."""
        return self.settings

    def close(self) -> None:
        if p.isConnected(self.client):
            p.disconnect(self.client)
            forget_client(self.client)

    def __enter__(self) -> Evaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- phases --------------------------------------------------------------------------
    def _reset(self) -> None:
        scene, cid = self.scene, self.client
        restore_state(cid, self.pristine)
        # A saved state holds no contact cache: the last evaluation's manifolds survive a
        # restore, and the order in which manifolds were made is the order the solver visits
        # contacts. A collision pass here, where nothing overlaps, drops them all.
        p.performCollisionDetection(physicsClientId=cid)
        p.setGravity(0, 0, 0, physicsClientId=cid)
        policy = self.settings.policy
        effort = policy.closing_effort or self.gripper.closing_effort
        scene.hand.reset_open(self.spread, effort, policy.hold_effort_factor)
        if self.settings.table is None:
            p.changeConstraint(scene.fixture_constraint, jointChildPivot=scene.offset.tolist(),
                               maxForce=FIXTURE_MAX_FORCE_N, physicsClientId=cid)
        else:  # free on the table, under its own weight (workers/sim/table.py)
            p.changeConstraint(scene.fixture_constraint, maxForce=0.0, physicsClientId=cid)
            scene.object_weight_n = self.prepared.mass_kg * self.settings.trajectory.gravity_m_s2
            scene.watch.reset()

    def _place(self, position: np.ndarray, rotation: np.ndarray) -> None:
        place_hand(self.client, self.scene, position, rotation)

    def _start_pose(self, pose: Pose) -> StartPose | None:
        """World start pose of the gripper frame, the target x_c and the effective r."""
        return start_pose(self.client, self.scene, self.prepared.mesh, pose,
                          self.settings.placement)

    def evaluate(self, pose: Pose, *, picture: Path | None = None,
                 donors: DonorPool | None = None) -> PoseResult:
        """Simulates one pose. With `picture`, a PNG of the synthesized grasp (before the
        trajectory) is written there. With `donors` (shortcut 2), a synthesized grasp that
        matches a donor's reuses its outcome, μs and effort; one taken through the trajectory
        joins the donors. The tests of `settings.robustness` (none by default) run on the
        synthesized grasp of every pose that held and was simulated (not inferred)."""
        chosen = self.settings.robustness
        if not chosen.tests:
            return self._evaluate(pose, picture=picture, donors=donors)[0]
        return self.robustness(pose, chosen, picture=picture, donors=donors)[0]

    def _evaluate(self, pose: Pose, *, picture: Path | None = None,
                  donors: DonorPool | None = None, keep_grasp: bool = False,
                  ) -> tuple[PoseResult, SynthesizedGrasp | None]:
        """`evaluate`, and with `keep_grasp` the synthesized grasp (a saved state the caller
        must remove; None where no grasp formed)."""
        started = time.perf_counter()
        phases = PhaseTimes()
        self._reset()
        start = self._start_pose(pose)
        phases.reset_s = time.perf_counter() - started
        result = dict(pose=pose, pose_key=pose.key(), phases=phases)
        if start is None:
            return self._finish(started, Outcome.INFEASIBLE, result), None
        position, rotation, target, gap = start
        result["effective_r"] = gap
        if (blocked := on_table.start_outcome(self.scene)) is not None:
            return self._finish(started, blocked, result), None

        outcome = self.policy.synthesize(self.scene, position, rotation, target,
                                         self.settings, phases)
        outcome = on_table.closing_outcome(self.scene) or outcome
        if outcome is not None:
            return self._finish(started, outcome, result), None

        hand, scene = self.scene.hand, self.scene
        grasp = capture_grasp(scene) if keep_grasp else None
        result.update(grasp_fields(scene, self.length, self.prepared.mass_kg))

        if picture is not None:
            render_grasp(self.client, hand.body, scene.object_body, picture)
        donor = None if donors is None else donors.find(
            pose, result["grasp"], result["signature"].links_in_contact)
        if donor is not None:
            return inferred(self._finish(started, donor.outcome, result), donor), grasp
        held, qualities, effort = self._run_trajectory(phases)
        result["effort_max_nm"] = effort
        if held:
            result["mu_s"] = mu_s(qualities)
            result["viable"] = True
        finished = self._finish(started, Outcome.HELD if held else Outcome.DROPPED, result)
        if donors is not None:
            donors.add(finished)
        return finished, grasp

    # --- robustness (workers/sim/robustness.py) ------------------------------------------
    @contextmanager
    def synthesized(self, pose: Pose, *, picture: Path | None = None,
                    donors: DonorPool | None = None,
                    ) -> Iterator[tuple[PoseResult, SynthesizedGrasp | None]]:
        """Evaluates `pose` as `evaluate` does and yields its result with the synthesized grasp
        (None where no grasp formed), whose saved state is removed on leaving the block."""
        result, grasp = self._evaluate(pose, picture=picture, donors=donors, keep_grasp=True)
        try:
            yield result, grasp
        finally:
            if grasp is not None:
                remove_state(self.client, grasp.state)

    def robustness(self, pose: Pose, settings: RobustnessSettings | None = None, *,
                   picture: Path | None = None, donors: DonorPool | None = None,
                   ) -> tuple[PoseResult, RobustnessReport]:
        """Evaluates `pose` as `evaluate` does and, if it held, runs the chosen tests
        (`settings`; None: every test) on its synthesized grasp. The result carries the report
        in `robustness`; where the pose did not hold, or its outcome was inferred from a donor,
        every field of the report is None."""
        settings = settings or RobustnessSettings.every_test()
        with self.synthesized(pose, picture=picture, donors=donors) as (result, grasp):
            report = RobustnessReport()
            if (grasp is not None and result.outcome is Outcome.HELD
                    and result.inferred_from is None):
                report = run_tests(self, grasp, settings)
        return result.model_copy(update={"robustness": report}), report

    def _run_trajectory(self, phases: PhaseTimes, *, probes: bool = True,
                        ) -> tuple[bool, list[float], float]:
        """Release and reference trajectory from the present state; with `probes`, μs probes
        at the sampled instants of a grasp that held (their qualities are returned)."""
        scene, hand, cid = self.scene, self.scene.hand, self.client
        spec, metric = self.settings.trajectory, self.settings.metric
        t0 = time.perf_counter()
        p.changeConstraint(scene.fixture_constraint, maxForce=0.0, physicsClientId=cid)
        p.setGravity(0, 0, -spec.gravity_m_s2, physicsClientId=cid)
        scene.object_weight_n = 0.0  # gravity is global from here on
        if self.settings.table is not None:
            on_table.lift_off(scene, self.settings.table, phases)
        start_pos, start_rot = hand.frame_pose()
        dt = scene.dt
        scene.drive_to(start_pos, start_rot)
        settle_steps = round(spec.settle_s / dt)
        for _ in range(settle_steps):
            scene.step()
        # Step counts are kept in locals and stored once: setting a pydantic attribute
        # costs microseconds, a per-step cost outside the engine (issue 21 item 5).
        phases.trajectory_steps += settle_steps
        # Slip is measured from where the object came to rest in the hand, not from where
        # the fixture held it: released, an enveloped object is drawn into the palm by the
        # closing effort (centimetres), and that is the grasp taking the weight, not a drop.
        obj_pos, obj_rot = scene.object_pose()
        rel_pos0 = start_rot.T @ (obj_pos - start_pos)
        rel_rot0 = start_rot.T @ obj_rot
        pivot = obj_pos
        n_steps = max(1, round(spec.duration_s / dt))
        instants = {min(n_steps - 1, int((k + 0.5) * n_steps / metric.instants))
                    for k in range(metric.instants)}

        # The reference path, step by step as it is first read (a drop ends it early), kept
        # for the probe windows that read their steps again.
        path = ReferencePath(spec, start_pos, start_rot, pivot, dt)
        target = path.pose
        ctx = ProbeContext(client=cid, hand_body=hand.body, object_body=scene.object_body,
                           drive=scene.drive_to, target=target,
                           contact_free_state=self.pristine, target_drive=path.drive,
                           drive_quat=scene.drive_to_quat)

        slipped = slip_check(scene, spec, rel_pos0, rel_rot0)
        effort = 0.0
        held = scene.in_contact()  # a dropped object has fallen ~5 cm by now, off the hand
        # States at the sampled instants; they are probed only once the grasp has held to the
        # end (a probe restores what it found, so deferring it changes nothing but the cost).
        # The trajectory is not used as the probes' unperturbed rollout: it carries the
        # solver's warm-started contacts, which a restored state lacks (restore_clean), and
        # its response differs from a rollout's by up to 0.08 m/s of ~0.3.
        saved: dict[int, int] = {}
        fingers = hand.finger_joints
        ran = 0
        with ExitStack() as kept:  # the instants' states are freed however this ends
            for step in range(n_steps if held else 0):
                if probes and step in instants:
                    saved[step] = kept.enter_context(saved_state(cid, restore=False))
                scene.drive_to_quat(*path.drive(step + 1))
                scene.step()
                ran += 1
                # hand.max_finger_torque, without a record per joint
                effort = max(effort, max_abs_motor_torque(cid, hand.body, fingers))
                if step % 10 == 9 and slipped():
                    held = False
                    break
            phases.trajectory_steps += ran
            if held and (slipped() or not scene.in_contact()):
                held = False
            phases.trajectory_s += time.perf_counter() - t0
            tp = time.perf_counter()
            qualities = self._probes(ctx, saved if held else {}, phases)
        phases.sensitivity_s += time.perf_counter() - tp
        return held, qualities, effort

    def _probes(self, ctx: ProbeContext, saved: dict[int, int],
                phases: PhaseTimes) -> list[float]:
        """The μs probes at the saved instants (step -> saved state), in step order."""
        metric = self.settings.metric
        central = metric.differences == "central"
        qualities: list[float] = []
        # Each probe restores its own instant cleanly first, and nothing reads the
        # simulation after the last one (the next evaluation restores the pristine state
        # and drops every contact; the robustness tests restore the grasp cleanly): no
        # probe needs to put its instant back.
        for step, state in sorted(saved.items()):
            qualities.append(probe_instant(ctx, step, self.scene.dt, metric, self.length,
                                           state=state, restore=False))
            phases.sensitivity_steps += (12 if central else 7) * metric.window_steps
        return qualities

    def _finish(self, started: float, outcome: Outcome, result: dict) -> PoseResult:
        result.setdefault("mu_s", 0.0)
        result.setdefault("viable", False)
        result["outcome"] = outcome
        result["eval_time_s"] = time.perf_counter() - started
        return PoseResult(**result)


def default_cache_dir() -> Path:
    return Path(os.environ.get("GRASPSCAPE_CACHE_DIR", Path.home() / ".cache" / "graspscape"))


_EVALUATORS: dict[tuple[str, str, str], Evaluator] = {}  # or MjEvaluator (engine.py)


def _evaluator(obj: ObjectSpec, gripper: GripperSpec | str, settings: SimSettings | None,
               cache_dir: Path | None) -> Evaluator:
    spec = load_gripper(gripper) if isinstance(gripper, str) else gripper
    settings = settings or SimSettings()
    cache = cache_dir or default_cache_dir()
    key = (obj.model_dump_json(), spec.model_dump_json(), settings.model_dump_json())
    evaluator = _EVALUATORS.get(key)
    if evaluator is None:
        prepared = prepare_object(obj, cache / "objects")
        evaluator = make_evaluator(prepared, spec, settings, work_dir=cache)
        _EVALUATORS[key] = evaluator
    return evaluator


def evaluate_pose(pose: Pose, *, obj: ObjectSpec, gripper: GripperSpec | str = "robotiq_3f",
                  settings: SimSettings | None = None, cache_dir: Path | None = None,
                  donors: DonorPool | None = None) -> PoseResult:
    """Evaluates one pose, reusing this process's evaluator for the same object, gripper and
    settings (one pybullet client each, loaded once). `donors`: see Evaluator.evaluate."""
    return _evaluator(obj, gripper, settings, cache_dir).evaluate(pose, donors=donors)


def robustness_pose(pose: Pose, *, obj: ObjectSpec, gripper: GripperSpec | str = "robotiq_3f",
                    settings: SimSettings | None = None,
                    robustness: RobustnessSettings | None = None,
                    cache_dir: Path | None = None) -> PoseResult:
    """Evaluates one pose and, if it held, runs the robustness tests (`robustness`; None:
    every test) on its synthesized grasp; the report is the result's `robustness`."""
    return _evaluator(obj, gripper, settings, cache_dir).robustness(pose, robustness)[0]


def render_pose(pose: Pose, path: Path, *, obj: ObjectSpec,
                gripper: GripperSpec | str = "robotiq_3f", settings: SimSettings | None = None,
                cache_dir: Path | None = None) -> tuple[Path, PoseResult]:
    """Evaluates one pose and writes a picture of its synthesized grasp (or of the start pose
    where no grasp formed)."""
    evaluator = _evaluator(obj, gripper, settings, cache_dir)
    result = evaluator.evaluate(pose, picture=path)
    if not path.exists() and isinstance(evaluator, Evaluator):
        render_grasp(evaluator.client, evaluator.scene.hand.body, evaluator.scene.object_body,
                     path)
    elif not path.exists():
        from graspscape.workers.sim.mj.picture import draw_scene

        draw_scene(evaluator, path)
    return path, result
