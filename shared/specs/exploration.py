"""What an exploration is, as a user submits it: object, gripper, policy, pose grid, trajectory.

The coordinator stores the spec exactly as submitted and derives its tiles of work from the
pose grid; workers read the gripper and the simulation settings (policy, trajectory, metric)
from it. Ranges are validated here
so that a bad spec fails at submission with a message naming the field, not hours later on a
worker.
"""

from __future__ import annotations

import math
from typing import Literal

from graspscape.shared.specs.gripper import (
    STORED_GRIPPER,
    STORED_PREFIX,
    engine_problem,
    find_gripper,
    unknown_gripper_message,
)
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.shared.specs.sim import POLICY_NAMES, SimSettings
from graspscape.shared.specs.strategies import AdaptiveStrategySpec, StrategySpec
from graspscape.shared.specs.support import RestingPose, SupportSpec, support_problem, table_scene
from graspscape.shared.specs.uncertainty import UncertaintyModel
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)

# Names of grippers and policies are resolved by the workers (configs/grippers, policy
# registry); here they only have to be safe identifiers.


class AttitudeSpec(BaseModel):
    """Which gripper attitudes are tried at every (θ, φ, r) grid point."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    rolls: Literal[1, 2, 4, 8] = Field(
        default=1, description="number of rolls about the palm normal, evenly spaced over 2π"
    )
    tilts: tuple[float, ...] = Field(
        default=(),
        max_length=4,
        description=(
            "tilt angles of the palm normal off the surface normal, rad; each tilt t adds the "
            "variants pitch=±t and yaw=±t to every roll"
        ),
    )

    @model_validator(mode="after")
    def _tilt_range(self) -> AttitudeSpec:
        for tilt in self.tilts:
            if not 0.0 < tilt <= math.pi / 4:
                raise ValueError(f"tilt {tilt} must be in (0, π/4] rad")
        if len(set(self.tilts)) != len(self.tilts):
            raise ValueError("tilts must be distinct")
        return self

    def attitudes(self) -> list[tuple[float, float, float]]:
        """Every (roll, pitch, yaw) variant, in a fixed order."""
        tilt_variants = [(0.0, 0.0)]
        for t in self.tilts:
            tilt_variants += [(t, 0.0), (-t, 0.0), (0.0, t), (0.0, -t)]
        rolls = [k * 2 * math.pi / self.rolls for k in range(self.rolls)]
        return [(roll, pitch, yaw) for roll in rolls for pitch, yaw in tilt_variants]


class PoseGridSpec(BaseModel):
    """The coarse grid over the pose space: rings of constant θ, r levels, attitudes."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    dtheta: float = Field(
        default=math.radians(10),
        ge=0.01,
        le=math.pi / 2,
        description="angular step between grid points on the sphere of approach directions, rad",
    )
    r_min: float = Field(default=0.0, ge=0.0, le=0.5, description="smallest start gap, m")
    r_max: float = Field(default=0.05, ge=0.0, le=0.5, description="largest start gap, m")
    dr: float = Field(default=0.01, ge=0.001, le=0.5, description="step between r levels, m")
    attitudes: AttitudeSpec = Field(default_factory=AttitudeSpec)
    azimuth_multiple: int | None = Field(
        default=None,
        ge=1,
        le=16,
        description=(
            "every ring's azimuth count is rounded to a multiple of this, so that the rings map "
            "onto themselves under the object's rotations and mirrors about its z axis; unset: "
            "decided at submission (the object's symmetry order when the symmetry shortcut is "
            "on, else 1)"
        ),
    )

    @model_validator(mode="after")
    def _r_range(self) -> PoseGridSpec:
        if self.r_max < self.r_min:
            raise ValueError(f"r_max ({self.r_max}) must not be below r_min ({self.r_min})")
        return self

    def r_levels(self) -> list[float]:
        n = math.floor((self.r_max - self.r_min) / self.dr + 1e-9) + 1
        return [round(self.r_min + i * self.dr, 9) for i in range(n)]


class RefinementSpec(BaseModel):
    """How the adaptive pass refines the coarse grid where outcomes change."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    # Default 0 (coarse pass only): refinement is asked for explicitly, so that a submitted
    # spec's cost is bounded by what it states (docs/design/exploration.md).
    levels: int = Field(
        default=0,
        ge=0,
        le=6,
        description="refinement depth: halvings of Δθ and Δr at borders (0: coarse pass only)",
    )
    boundary_only: bool = Field(
        default=True, description="refine only cells whose neighbours differ in outcome"
    )
    max_poses: int = Field(
        default=200_000, ge=0, le=50_000_000, description="budget of refinement poses"
    )
    mu_step_max: float | None = Field(
        default=None,
        gt=0.0,
        le=1.0,
        description="slope criterion: also refine between neighbours of one manifold whose μs "
        "differ by more than this (None: refine at borders only)",
    )
    local_search_rounds: int = Field(
        default=3, ge=0, le=20, description="rounds of gradient ascent on μs per manifold"
    )
    local_search_starts: int = Field(
        default=2, ge=1, le=20, description="local maxima followed per manifold"
    )


class ConfigurationMatch(BaseModel):
    """When two synthesized grasps count as the same grasp configuration (shortcut 2): the
    same links touch, and the base pose in the object frame and every joint angle agree
    within these tolerances."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    position_m: float = Field(default=0.002, gt=0.0, le=0.05)
    angle_rad: float = Field(default=0.02, gt=0.0, le=0.5)
    joint_rad: float = Field(default=0.05, gt=0.0, le=0.5)


class ShortcutsSpec(BaseModel):
    """The paper's shortcuts (section IV.B); each can be switched on alone."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    normal_reuse: bool = Field(
        default=False,
        description="along a surface normal, evaluate the r ends first and infer the levels "
        "between when both ends give the same grasp (bisect otherwise)",
    )
    configuration_inference: bool = Field(
        default=False,
        description="in the coarse pass, a pose whose synthesized grasp matches one that a "
        "pose of the same tile already took through the trajectory reuses that pose's outcome, "
        "μs and effort instead of running trajectory and probes",
    )
    configuration_match: ConfigurationMatch = Field(default_factory=ConfigurationMatch)
    symmetry: bool = Field(
        default=False,
        description="detect mirror/rotation symmetries of the mesh and mirror results onto "
        "the symmetric poses instead of evaluating them",
    )


class CertificationSpec(BaseModel):
    """The adaptive strategy's last stage (services/coordinator/exploration/certify.py): after
    border refinement and local search, each large manifold's candidates race for draws of
    the exploration's uncertainty model, sampled by an anytime-valid sequential rule, so that
    P(success) has a 95 % bound and "certified" means the lower bound clears `level`
    (docs/design/exploration.md, "Certification"; docs/concepts/success-probability.md).
    `pose_error_mm`,
    `pose_error_deg` and `jitters` are read only by the pure plan without a race."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    share: float = Field(
        default=0.35, ge=0.0, le=0.5,
        description="budget: extra evaluations as a share of the exploration's other planned "
        "poses, shared among the large manifolds (0: no certification); the draws of the "
        "P(success) race take all but `core_share` of it")
    core_share: float = Field(
        default=0.25, ge=0.0, le=1.0,
        description="of that budget, the share kept for core claims: completing N_δ around "
        "poses deep inside large manifolds, so the robust core is claimed where it is (they "
        "also take what the best grasps leave; 0: no claims)")
    candidates: int = Field(
        default=3, ge=0, le=20,
        description="per large manifold, the candidates that race for P(success) draws (its "
        "best by the robust map), and its best poses by μs whose N_δ is completed")
    pose_error_mm: float = Field(
        default=2.0, ge=0.0, le=50.0,
        description="σ_pos: the robot's position error (one standard deviation, per axis), mm")
    pose_error_deg: float = Field(
        default=2.0, ge=0.0, le=45.0,
        description="σ_ang: the robot's attitude error (one standard deviation, per axis), deg")
    jitters: int = Field(
        default=8, ge=0, le=64,
        description="unused: draws of the uncertainty model are planned by the sequential "
        "rule (docs/concepts/success-probability.md); kept so stored specs still read")
    level: float = Field(
        default=0.9, gt=0.0, lt=1.0,
        description="certified: the 95 % lower bound of P(success) under the exploration's "
        "uncertainty model is at least this")


# An exploration measures the torque margin of every held pose unless told otherwise: it is
# what /best ranks by (docs/concepts/quality.md, "What /best ranks by"), at about one more
# evaluation's worth of simulation per held pose.
EXPLORATION_ROBUSTNESS = RobustnessSettings(tests=("torque_margin",))


class ExplorationSpec(BaseModel):
    """One exploration as submitted: everything needed to reproduce it."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    object_id: int = Field(
        ge=1, le=2**31 - 1, description="id of an object stored through POST /objects"
    )
    gripper: str = Field(
        default="robotiq_3f", min_length=1, max_length=1024, pattern=r"^[^\x00-\x1f]*$",
        description="gripper: a name (the shipped grippers, or one in the folders of "
        "GRASPSCAPE_GRIPPER_PATH), an absolute path to a TOML spec or a URDF gripper's folder "
        "as the coordinator sees it, or 'sha256:<hash>' of one uploaded with POST /grippers; "
        "any but a shipped gripper is packed at submit and fetched by the workers"
    )
    grid: PoseGridSpec = Field(default_factory=PoseGridSpec)
    settings: SimSettings = Field(
        default_factory=lambda: SimSettings(robustness=EXPLORATION_ROBUSTNESS),
        description="what every pose evaluation depends on: policy (settings.policy_name), "
        "trajectory, physics, metric, start-pose rule, and the robustness tests run on every "
        "held pose (by default the torque margin, which /best ranks by)",
    )
    refinement: RefinementSpec = Field(default_factory=RefinementSpec)
    shortcuts: ShortcutsSpec = Field(default_factory=ShortcutsSpec)
    uncertainty: UncertaintyModel = Field(
        default_factory=UncertaintyModel,
        description="the errors P(success) is stated under: start pose error, friction, mass "
        "and closing-effort scales; presets 'none', 'lab' (default), 'field'")
    certification: CertificationSpec = Field(
        default_factory=CertificationSpec,
        description="the adaptive strategy's certification of its best grasps (used by "
        "'adaptive' with refinement levels ≥ 1 only)")
    label: str | None = Field(
        default=None, max_length=200, pattern=r"^[^\x00]*$", description="free text for humans"
    )
    strategy: StrategySpec = Field(
        default_factory=AdaptiveStrategySpec,
        description="how the pose space is explored, by name: 'adaptive' (the default: coarse "
        "grid, refinement, shortcuts, local search), 'grid' (the dense grid at the finest "
        "level), 'random' (a seeded uniform sample of `poses` poses), 'cmaes' (CMA-ES with "
        "restarts, `poses` evaluations) or 'ppo' (PPO, `poses` evaluations; optional extra "
        "`rl`)",
    )

    support: SupportSpec = Field(
        default_factory=SupportSpec,
        description="what the object rests on: 'none' (free-floating) or 'plane' (a table; "
        "one exploration per chosen stable resting pose, docs/concepts/support.md)")

    @model_validator(mode="after")
    def _support_matches_settings(self) -> ExplorationSpec:
        problem = support_problem(self.support, self.settings.table, self.settings.engine)
        if problem is not None:
            raise ValueError(problem)
        return self

    @model_validator(mode="after")
    def _engines_load_gripper(self, info: ValidationInfo) -> ExplorationSpec:
        # Refused at submit, not pose by pose in the workers; a stored spec passed this once.
        if isinstance(info.context, dict) and info.context.get("stored"):
            return self
        problem = engine_problem(self.gripper, {self.settings.engine, *self.draw_engines()})
        if problem is not None:
            raise ValueError(problem)
        return self

    def at_rest(self, resting: RestingPose) -> ExplorationSpec:
        """This spec (support 'plane') at one resting pose, in its support and settings."""
        support = self.support.model_copy(update={"resting": resting})
        settings = self.settings.model_copy(update={"table": table_scene(support)})
        return self.model_copy(update={"support": support, "settings": settings})

    @field_validator("gripper")
    @classmethod
    def _known_gripper(cls, name: str, info: ValidationInfo) -> str:
        # A stored spec is read again without the check: its gripper was packed at submit
        # and travels by hash (explorations.gripper_hash), so the path may be gone since.
        # A `sha256:` name is one stored on the coordinator, which checks it at submit.
        stored = isinstance(info.context, dict) and info.context.get("stored")
        if stored or STORED_GRIPPER.match(name):
            return name
        if name.startswith(STORED_PREFIX):
            raise ValueError(f"{name!r}: a stored gripper is '{STORED_PREFIX}' and 64 "
                             "lower-case hex digits, as POST /grippers answers")
        if find_gripper(name) is None:
            raise ValueError(unknown_gripper_message(name))
        return name

    @field_validator("settings", mode="before")
    @classmethod
    def _exploration_robustness(cls, settings: object) -> object:
        # Settings that do not say which robustness tests to run get the exploration's
        # default, whether given as JSON or as a SimSettings.
        if isinstance(settings, dict) and "robustness" not in settings:
            return {**settings, "robustness": EXPLORATION_ROBUSTNESS}
        if isinstance(settings, SimSettings) and "robustness" not in settings.model_fields_set:
            return settings.model_copy(update={"robustness": EXPLORATION_ROBUSTNESS})
        return settings

    @field_validator("settings")
    @classmethod
    def _known_policy(cls, settings: SimSettings) -> SimSettings:
        known = POLICY_NAMES
        if settings.policy_name not in known:
            raise ValueError(
                f"unknown policy {settings.policy_name!r}; known: {', '.join(known)}")
        return settings

    def draw_engines(self) -> tuple[str, ...]:
        """The engines each P(success) draw is simulated in: the uncertainty model's, else
        the exploration's own."""
        return self.uncertainty.engines or (self.settings.engine,)
