"""Settings of the robustness margins and grasp tests run on a synthesized grasp
(workers/sim/robustness.py; docs/concepts/quality.md, "Robustness margins and grasp tests").

All tests are off by default (`tests=()`): they cost several trajectories' worth of simulation
per pose, so they run only when asked for (`RobustnessSettings.every_test()`, or
`graspscape eval-pose --robustness`). JSON-serialisable, frozen, like every settings model.
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

TestName = Literal["torque_margin", "friction_margin", "gravity", "force", "tug", "shake"]
TEST_NAMES: tuple[TestName, ...] = (
    "torque_margin", "friction_margin", "gravity", "force", "tug", "shake")

FIFTEEN_DEGREES = math.radians(15.0)


class RobustnessSettings(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    tests: tuple[TestName, ...] = Field(
        default=(), description="which tests run; none by default")

    # --- margins (bisection over release + reference trajectory, no μs probes) -----------
    margin_trials: int = Field(
        default=6, ge=2, le=30,
        description="trajectories per margin, the nominal one and the lower bound included")
    torque_lo_fraction: float = Field(
        default=0.02, gt=0.0, lt=1.0,
        description="lower bound of the torque bisection, as a fraction of the closing effort")
    friction_lo: float = Field(
        default=0.02, gt=0.0, le=1.0,
        description="lower bound of the friction bisection (the object's coefficient)")

    # --- hold-still tests: the drive holds the hand at its synthesized pose ----------------
    settle_s: float = Field(
        default=0.1, ge=0.0, le=2.0,
        description="after the fixture lets go and before any load: the grasp takes the object")
    load_frame: Literal["hand", "world"] = Field(
        default="hand", description="frame of the ±x ±y ±z directions of the gravity and "
        "force tests (hand: the gripper frame, z the approach axis)")
    gravity_m_s2: float = Field(default=9.81, gt=0.0, le=50.0)
    gravity_duration_s: float = Field(default=1.0, gt=0.0, le=10.0)
    gravity_max_shift_m: float = Field(default=0.02, gt=0.0, le=0.5)
    gravity_max_turn_rad: float = Field(default=FIFTEEN_DEGREES, gt=0.0, le=math.pi)
    force_weights: float = Field(
        default=1.0, gt=0.0, le=100.0, description="external force, in object weights m·g")
    force_duration_s: float = Field(default=1.0, gt=0.0, le=10.0)
    force_max_shift_m: float = Field(default=0.05, gt=0.0, le=0.5)
    force_max_turn_rad: float = Field(default=FIFTEEN_DEGREES, gt=0.0, le=math.pi)
    tug_max_weights: float = Field(
        default=50.0, gt=0.0, le=1000.0, description="top of the pull ramp, in object weights")
    tug_ramp_s: float = Field(default=1.0, gt=0.0, le=10.0)
    tug_slip_m: float = Field(default=0.01, gt=0.0, le=0.5)
    shake_amplitude_m: float = Field(default=0.02, gt=0.0, le=0.2)
    shake_frequency_hz: float = Field(default=4.0, gt=0.0, le=50.0)
    shake_axis_s: float = Field(
        default=0.5, gt=0.0, le=10.0, description="shaking time per world axis x, y, z")
    shake_fall_m: float = Field(default=0.03, gt=0.0, le=0.5)

    @classmethod
    def every_test(cls, **overrides) -> RobustnessSettings:
        return cls(tests=TEST_NAMES, **overrides)

    def runs(self, name: TestName) -> bool:
        return name in self.tests
