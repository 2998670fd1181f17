"""Settings of the shape-informed haptic policy G_s (paper Sec. III-D, Alg. 1).

Lengths in metres, angles in radians. Every limit of the two iterations lives here so that a
result depends only on the pose and the SimSettings it was computed with. docs/concepts/quality.md
explains the defaults.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class HapticPolicySettings(BaseModel):
    model_config = ConfigDict(frozen=True)

    # --- proximity sensor model ---------------------------------------------------------
    sensing_range_m: float = Field(
        default=0.15, gt=0.0, le=1.0,
        description="links read their distance to the object up to this range (longer than "
                    "the open hand's reach, so every link sees the object from a start pose)")
    noise_std_m: float = Field(default=0.0, ge=0.0, le=0.05,
                               description="Gaussian reading noise; 0 is a perfect sensor")
    noise_seed: int = Field(default=0, ge=0,
                            description="seed of the reading noise (combined with the pose)")

    # --- numerical Jacobians --------------------------------------------------------------
    jacobian_joint_step_rad: float = Field(default=0.01, gt=0.0, le=0.2)
    jacobian_base_step_m: float = Field(default=0.002, gt=0.0, le=0.05)
    jacobian_base_step_rad: float = Field(default=0.02, gt=0.0, le=0.3)
    damping: float = Field(default=0.02, ge=0.0, le=10.0,
                           description="damped least squares λ of the pseudo-inverse (m)")

    # --- step 1: digit alignment --------------------------------------------------------
    alignment_tolerance_m: float = Field(
        default=0.01, gt=0.0, le=0.1,
        description="Δd_s: every link's distance offset (link minus palm) within ± this")
    alignment_max_iterations: int = Field(default=40, ge=1, le=1000)
    alignment_stall_m: float = Field(
        default=0.0005, ge=0.0, le=0.05,
        description="less worst-offset improvement than this over `stall_window` iterations "
                    "means no joint configuration reaches the tolerance: non-viable")
    max_joint_step_rad: float = Field(default=0.08, gt=0.0, le=1.0)

    # --- step 2: grasp closure ----------------------------------------------------------
    closure_step_m: float = Field(
        default=0.004, gt=0.0, le=0.05,
        description="every link's distance is asked to shrink by this much per iteration")
    closure_contact_m: float = Field(
        default=0.002, ge=0.0, le=0.05,
        description="d_c: a link this close (or touching) counts as in contact")
    closure_max_iterations: int = Field(default=60, ge=1, le=1000)
    max_base_step_m: float = Field(default=0.004, gt=0.0, le=0.05)
    max_base_step_rad: float = Field(default=0.03, gt=0.0, le=0.5)
    base_force_n: float = Field(
        default=6.0, gt=0.0, le=200.0,
        description="force cap of the base drive while closing in (G_c's approach force)")

    # --- shared -------------------------------------------------------------------------
    steps_per_iteration: int = Field(
        default=4, ge=1, le=100, description="physics steps the hand follows each update for")
    stall_window: int = Field(default=5, ge=1, le=100)
