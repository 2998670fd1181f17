"""What the evaluation of one pose returns: the grasp configuration, its signature and μs."""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Any

from graspscape.shared.specs.pose import Pose
from pydantic import BaseModel, ConfigDict, Field

# Every number of a result is finite: a blown-up simulation's NaN or ∞ is refused where a
# result is built or decoded (and serialized it would go out as `null`), never stored.
_FINITE = ConfigDict(frozen=True, allow_inf_nan=False)


class Outcome(StrEnum):
    HELD = "held"  # a grasp formed and the object stayed in it along the trajectory
    DROPPED = "dropped"  # a grasp formed but the object slipped out during the trajectory
    NO_GRASP = "no_grasp"  # the hand closed but the object was not enclosed
    NO_CONTACT = "no_contact"  # the approach never touched the object
    INFEASIBLE = "infeasible"  # the start pose could not be placed without interpenetration
    # On a table (support 'plane'): the hand at its start pose reaches into the table, so the
    # pose is not simulated; the hand moved the object on the table (tipped or dragged it
    # beyond the table's tolerances) before lift-off.
    INFEASIBLE_TABLE = "infeasible_table"
    KNOCKED = "knocked"
    ERROR = "error"  # the evaluation of this pose raised; PoseResult.error says what


class ContactPoint(BaseModel):
    model_config = _FINITE

    link: str
    position_object: tuple[float, float, float] = Field(description="in the object frame, m")
    normal_force_n: float


class GraspSignature(BaseModel):
    """What kind of grasp formed: which links touch where, and how the hand ended up."""

    model_config = _FINITE

    links_in_contact: tuple[str, ...]
    contacts: tuple[ContactPoint, ...]
    joint_angles: dict[str, float]


class GraspConfiguration(BaseModel):
    """The paper's (η_r(t_c), θ_g(t_c)): base pose in the object frame and joint angles.

    The base pose is the gripper frame's (palm surface centre, z the palm normal) at the end of
    closing, relative to the object's centre-of-mass frame at that instant
    (docs/reference/formats.md)."""

    model_config = _FINITE

    base_position: tuple[float, float, float]
    base_orientation: tuple[float, float, float, float] = Field(description="quaternion xyzw")
    joint_angles: dict[str, float]


class PhaseTimes(BaseModel):
    model_config = ConfigDict(allow_inf_nan=False)

    reset_s: float = 0.0
    approach_s: float = 0.0
    closing_s: float = 0.0
    trajectory_s: float = 0.0
    sensitivity_s: float = 0.0
    approach_steps: int = 0
    closing_steps: int = 0
    trajectory_steps: int = 0
    sensitivity_steps: int = 0


class RobustnessReport(BaseModel):
    """Robustness margins and grasp tests of one synthesized grasp (workers/sim/robustness.py,
    docs/concepts/quality.md). A field is None where its test did not run (not chosen, or the pose
    was not held); a margin is also None where the grasp drops even at the nominal value."""

    model_config = _FINITE

    torque_margin_nm: float | None = Field(
        default=None, ge=0.0,
        description="least closing effort at which the synthesized grasp still holds, N·m")
    torque_margin_ratio: float | None = Field(
        default=None, le=1.0, description="1 − torque_margin_nm / the closing effort used")
    friction_margin: float | None = Field(
        default=None, ge=0.0,
        description="least object lateral friction coefficient (pybullet's per-body value; "
        "the contact's is its product with the links' 0.5) at which the grasp still holds")
    gravity_test_share: float | None = Field(
        default=None, ge=0.0, le=1.0, description="share of 6 gravity directions passed")
    force_test_share: float | None = Field(
        default=None, ge=0.0, le=1.0, description="share of 6 external force directions passed")
    tug_force_n: float | None = Field(
        default=None, ge=0.0,
        description="pull along the approach axis at which the object slips (the ramp's top "
        "if it never does), N")
    shake_survival_s: float | None = Field(
        default=None, ge=0.0,
        description="time into the shake at which the object falls off (the full duration if "
        "it never does), s")


class DrawScales(BaseModel):
    """A draw's scales of the uncertainty model (shared/specs/uncertainty.py): the object's
    friction coefficient and mass and the hand's closing effort, each × this."""

    model_config = _FINITE

    friction: float = Field(default=1.0, ge=0.05, le=2.0)
    mass: float = Field(default=1.0, ge=0.1, le=10.0)
    effort: float = Field(default=1.0, ge=0.1, le=2.0)


class EngineOutcome(BaseModel):
    """One engine's outcome of a draw and the links in contact once the hand had closed."""

    model_config = _FINITE

    outcome: Outcome
    links: tuple[str, ...] = ()


# What an outcome-only evaluation does not measure: present in a draw's result with their
# empty values (μs 0, no signature), never a measurement.
OUTCOME_ONLY_ABSENT: tuple[str, ...] = (
    "mu_s", "effective_r", "effort_max_nm", "contacts_per_link", "grasp", "signature",
    "mu_g", "mu_f", "mu_m", "robustness")


class SampleRecord(BaseModel):
    """A draw of a success probability, evaluated outcome only (workers/sim/samples.py): its
    scales, and per engine its outcome and links in contact. The result's own outcome is the
    first engine's held only where every engine held."""

    model_config = _FINITE

    scales: DrawScales = Field(default_factory=DrawScales)
    engines: dict[str, EngineOutcome] = Field(min_length=1, max_length=4)
    absent: tuple[str, ...] = Field(
        default=OUTCOME_ONLY_ABSENT, description="result fields this evaluation left out")


class PoseResult(BaseModel):
    model_config = ConfigDict(allow_inf_nan=False)

    pose: Pose
    pose_key: str
    outcome: Outcome
    viable: bool = Field(description="a grasp formed and held along the trajectory")
    mu_s: float = Field(ge=0.0, le=1.0)
    effective_r: float | None = Field(
        default=None, description="start gap actually used (after backing off), m"
    )
    effort_max_nm: float = Field(default=0.0, description="largest joint torque used, N·m")
    contacts_per_link: dict[str, int] = Field(default_factory=dict)
    grasp: GraspConfiguration | None = None
    signature: GraspSignature | None = None
    eval_time_s: float = 0.0
    inferred_from: str | None = Field(
        default=None,
        description="shortcut 2: the key of the pose whose outcome, μs and effort this one "
        "reuses, its synthesized grasp matching this one's (trajectory and probes skipped)")
    phases: PhaseTimes = Field(default_factory=PhaseTimes)
    mu_g: float | None = Field(
        default=None, ge=0.0, description="grasp-matrix metric of the synthesized grasp")
    mu_f: float | None = Field(
        default=None, ge=0.0, description="Ferrari–Canny ε of the synthesized grasp")
    mu_m: float | None = Field(
        default=None, ge=0.0, description="perturbation resistance, in object weights")
    min_closing_effort: float | None = Field(
        default=None, ge=0.0, description="least closing torque that still holds, N·m")
    robustness: RobustnessReport | None = Field(
        default=None, description="margins and grasp tests (Evaluator.robustness only)")
    error: str | None = Field(
        default=None, max_length=2000,
        description="outcome `error` only: the exception the evaluation of this pose raised")
    sample: SampleRecord | None = Field(
        default=None, description="a success probability's draw, evaluated outcome only")


def nonfinite_fields(value: Any, path: str = "") -> list[str]:
    """Where a result (any model, dict, sequence or number) holds NaN or ±∞: `name=value` per
    number, by dotted path. A result built with `model_copy(update=…)` or
    `model_construct` skips validation, so the worker checks every number before it sends."""
    if isinstance(value, float):
        return [] if math.isfinite(value) else [f"{path or 'value'}={value}"]
    if isinstance(value, BaseModel):
        items: Any = ((name, getattr(value, name)) for name in type(value).model_fields)
    elif isinstance(value, dict):
        items = value.items()
    elif isinstance(value, (list, tuple)):
        items = enumerate(value)
    else:
        return []
    found: list[str] = []
    for name, item in items:
        found += nonfinite_fields(item, f"{path}.{name}" if path else str(name))
    return found
