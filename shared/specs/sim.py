"""Settings of one grasp evaluation: physics, the policy's parameters, the reference
trajectory, the μs probe and the start-pose rule. JSON-serialisable, part of an exploration
spec, and the only inputs besides the pose that a result depends on."""

from __future__ import annotations

from typing import Literal

from graspscape.shared.specs.haptic import HapticPolicySettings
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.shared.specs.support import TableScene
from pydantic import BaseModel, ConfigDict, Field

# The grasp synthesis policies the workers register (workers/sim/policies), named here so a
# submitted spec is validated without loading the simulation; a test keeps the two equal.
POLICY_NAMES: tuple[str, ...] = ("baseline", "haptic")
# The physics engines a result can come from (workers/sim/engine.py); pybullet is the default.
ENGINE_NAMES: tuple[str, ...] = ("pybullet", "mujoco")
EngineName = Literal["pybullet", "mujoco"]


class PhysicsSettings(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    rate_hz: float = Field(default=240.0, ge=60.0, le=2000.0)
    solver_iterations: int = Field(default=50, ge=1, le=500)
    mujoco_substeps: int = Field(
        default=2, ge=1, le=16,
        description="MuJoCo steps per pybullet step (MuJoCo needs ~2 ms: 4 ms let joints "
        "pass their limits); the policy's checks and the probe windows keep their duration")

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz


class PlacementSettings(BaseModel):
    """What r means, and what happens when the open hand at its start pose would
    interpenetrate the object.

    `start_gap = "palm"`: r is the palm's gap; a hand that would interpenetrate is backed off
    along the surface normal in `backoff_step_m` steps (so many r levels start at one place).
    `"clearance"`: r is the clearance between the whole open hand and the object; the palm gap
    that gives it is found along the same normal by the same steps, then by bisection to
    `clearance_tolerance_m` (docs/design/simulation.md, "Start gap")."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    start_gap: Literal["palm", "clearance"] = "palm"
    on_interpenetration: Literal["back_off", "infeasible"] = "back_off"
    backoff_step_m: float = Field(default=0.005, gt=0.0, le=0.05)
    max_backoff_m: float = Field(default=0.10, ge=0.0, le=0.5)
    penetration_tolerance_m: float = Field(default=0.0005, ge=0.0, le=0.01)
    clearance_tolerance_m: float = Field(default=0.0001, gt=0.0, le=0.005)


class BaselinePolicySettings(BaseModel):
    """G_c: a constant force toward x_c, then a constant closing torque until motion halts."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    approach_force_n: float = Field(default=6.0, gt=0.0, le=200.0)
    approach_speed_cap_m_s: float = Field(
        default=0.25, gt=0.0, le=2.0, description="an arm's speed limit on the free approach"
    )
    approach_overshoot_m: float = Field(
        default=0.02, ge=0.0, le=0.2, description="travel past the start gap before giving up"
    )
    closing_effort: float | None = Field(
        default=None, gt=0.0, le=100.0, description="N·m (or N); default: the gripper's own"
    )
    closing_speed: float = Field(default=6.0, gt=0.0, le=20.0, description="rad/s (or m/s)")
    hold_effort_factor: float = Field(
        default=3.0, gt=0.0, le=100.0, description="joints not yet closing hold this × effort"
    )
    check_every_steps: int = Field(default=6, ge=1, le=100)
    stall_tolerance: float = Field(
        default=0.01, gt=0.0, le=0.5, description="joint change per check that counts as halted"
    )
    closing_cap_s: float = Field(default=0.6, gt=0.0, le=5.0)


class TrajectorySpec(BaseModel):
    """The reference task: lift, move sideways and turn, with minimum-jerk timing.

    The default loads the grasp (docs/concepts/quality.md, "The reference task"): 15 cm up and 15 cm
    sideways in 0.4 s peak at 5.4 m/s² per axis (0.78 g together, against the 0.08 g of the
    first wave's 1 s task), the order of the community's 1 g gravity and m·g force tests. The
    turn stays gentle (0.3 rad, 1.4 rad/s at most): pybullet's first-order integration of a
    turning hand makes even a weld move against it in proportion to the turn's rate."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    settle_s: float = Field(
        default=0.1, ge=0.0, le=2.0,
        description="base held still after release while the grasp takes the object's weight",
    )
    duration_s: float = Field(default=0.4, gt=0.05, le=10.0)
    lift_m: float = Field(default=0.15, ge=-1.0, le=1.0)
    lateral_m: float = Field(default=0.15, ge=-1.0, le=1.0)
    turn_rad: float = Field(default=0.3, ge=-3.2, le=3.2, description="about the world z axis")
    gravity_m_s2: float = Field(default=9.81, ge=0.0, le=50.0)
    slip_distance_m: float = Field(
        default=0.03, gt=0.0, le=0.5, description="object displacement in the hand that is a drop"
    )
    slip_angle_rad: float = Field(default=1.0, gt=0.0, le=3.2)


class MetricSettings(BaseModel):
    """How μs is measured: see docs/concepts/quality.md for why each value."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    instants: int = Field(default=4, ge=1, le=50, description="sampled instants along the task")
    window_steps: int = Field(default=8, ge=1, le=100, description="probe window (the paper's ±ε)")
    perturbation_m_s2: float = Field(
        default=10.0, gt=0.0, le=100.0, description="linear probe acceleration ε")
    angular_perturbation_rad_s2: float = Field(
        default=100.0, gt=0.0, le=2000.0, description="angular probe acceleration")
    differences: Literal["forward", "central"] = Field(
        default="central", description="one-sided probes (+ε) or two-sided (±ε)")
    characteristic_length: Literal["radius_of_gyration"] | float = Field(
        default="radius_of_gyration",
        description="length that turns rad/s² into m/s²; default: the object's radius of gyration",
    )


class SimSettings(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    engine: EngineName = Field(
        default="pybullet",
        description="physics engine: pybullet, or mujoco (its step is rate_hz × "
        "mujoco_substeps; docs/design/simulation.md, \"MuJoCo\")")

    policy_name: str = Field(default="baseline", pattern=r"^[a-z][a-z0-9_]*$",
                             description="grasp synthesis policy (workers/sim/policies)")
    physics: PhysicsSettings = PhysicsSettings()
    placement: PlacementSettings = PlacementSettings()
    policy: BaselinePolicySettings = BaselinePolicySettings()
    haptic: HapticPolicySettings = HapticPolicySettings()
    trajectory: TrajectorySpec = TrajectorySpec()
    metric: MetricSettings = MetricSettings()
    robustness: RobustnessSettings = Field(
        default_factory=RobustnessSettings,
        description="margins and grasp tests run on every held pose (none by default)")
    spread_mode: str = "basic"
    table: TableScene | None = Field(
        default=None,
        description="the table the object rests on (set by the coordinator for an exploration "
        "with support 'plane'); None: the free-floating object")
