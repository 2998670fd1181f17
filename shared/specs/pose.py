"""The pose space P: one initial relative pose of the gripper around an object.

θ (polar angle from the object's +z) and φ (azimuth) give the approach direction from the
object's centre of mass; r is the start gap between the palm surface and the nearest object
point; roll turns the gripper about its palm normal, pitch and yaw tilt the palm normal off
the surface normal. Angles in radians, distances in metres.
"""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field

# Pose keys are rounded so that the same grid point computed along two paths (a coarse pass
# and a refinement, or two workers) gets one key. 1e-6 rad and 1e-6 m are far below any step.
_KEY_DIGITS = 6
_KEY_FORMAT = "/".join([f"%.{_KEY_DIGITS}f"] * 6)
_POLE = 10.0**-_KEY_DIGITS
_TAU = 2 * math.pi


class Pose(BaseModel):
    model_config = ConfigDict(frozen=True, allow_inf_nan=False)

    theta: float = Field(ge=0.0, le=math.pi, description="polar angle from object +z, rad")
    phi: float = Field(description="azimuth about object +z, rad (wrapped to [0, 2π))")
    r: float = Field(ge=0.0, le=1.0, description="start gap palm surface ↔ nearest object point, m")
    roll: float = Field(default=0.0, description="rotation about the palm normal, rad")
    pitch: float = Field(default=0.0, ge=-math.pi, le=math.pi, description="tilt, rad")
    yaw: float = Field(default=0.0, ge=-math.pi / 2, le=math.pi / 2, description="tilt, rad")

    def normal(self) -> tuple[float, float, float, float, float]:
        """The approach line the pose lies on: its direction and attitude, without r."""
        return (self.theta, self.phi, self.roll, self.pitch, self.yaw)

    def key(self) -> str:
        """A stable text key: equal for poses that are the same grid point."""
        return pose_key(self.theta, self.phi, self.r, self.roll, self.pitch, self.yaw)


def pose_key(theta: float, phi: float, r: float, roll: float = 0.0, pitch: float = 0.0,
             yaw: float = 0.0) -> str:
    """`Pose.key()` of these coordinates, without building (and validating) a Pose."""
    phi = math.fmod(phi, _TAU)
    if phi < 0:
        phi += _TAU
    if theta < _POLE or math.pi - theta < _POLE:
        phi = 0.0  # every azimuth is the same point at a pole
    roll = math.fmod(roll, _TAU)
    if roll < 0:
        roll += _TAU
    # Computed for every result on both sides of the wire: one format call, not six.
    # `+ 0.0` turns -0.0 into 0.0.
    return _KEY_FORMAT % (
        round(theta, _KEY_DIGITS) + 0.0,
        round(phi, _KEY_DIGITS) + 0.0,
        round(r, _KEY_DIGITS) + 0.0,
        round(roll, _KEY_DIGITS) + 0.0,
        round(pitch, _KEY_DIGITS) + 0.0,
        round(yaw, _KEY_DIGITS) + 0.0,
    )


def tile_poses(
    cells: list[tuple[float, float]] | list[list[float]],
    r_levels: list[float],
    attitudes: list[tuple[float, float, float]] | list[list[float]],
) -> list[Pose]:
    """Every pose a tile covers, in one fixed order: cells × r levels × attitudes (roll,
    pitch, yaw). Coordinator and workers both expand tiles with this, so keys agree."""
    return [
        Pose(theta=theta, phi=phi, r=r, roll=roll, pitch=pitch, yaw=yaw)
        for theta, phi in cells
        for r in r_levels
        for roll, pitch, yaw in attitudes
    ]


def tile_pose_keys(
    cells: list[tuple[float, float]] | list[list[float]],
    r_levels: list[float],
    attitudes: list[tuple[float, float, float]] | list[list[float]],
) -> list[str]:
    """The keys of `tile_poses(cells, r_levels, attitudes)`, in the same order, without
    building a Pose each. A key is its six coordinates, each formatted alone, joined by "/":
    the parts of each cell, r level and attitude are formatted once and concatenated (the
    coordinator checks every result batch against its tile's keys). Normalized as
    `pose_key` does; a test holds the two equal."""
    num = "%." + str(_KEY_DIGITS) + "f"
    cell_parts = []
    for theta, phi in cells:
        phi = math.fmod(phi, _TAU)
        if phi < 0:
            phi += _TAU
        if theta < _POLE or math.pi - theta < _POLE:
            phi = 0.0
        cell_parts.append(num % (round(theta, _KEY_DIGITS) + 0.0) + "/"
                          + num % (round(phi, _KEY_DIGITS) + 0.0))
    r_parts = [num % (round(r, _KEY_DIGITS) + 0.0) for r in r_levels]
    attitude_parts = []
    for roll, pitch, yaw in attitudes:
        roll = math.fmod(roll, _TAU)
        if roll < 0:
            roll += _TAU
        attitude_parts.append("/".join(num % (round(v, _KEY_DIGITS) + 0.0)
                                       for v in (roll, pitch, yaw)))
    return [
        f"{cell}/{r}/{attitude}"
        for cell in cell_parts
        for r in r_parts
        for attitude in attitude_parts
    ]
