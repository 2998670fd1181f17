"""The uncertainty a grasp's success probability is stated under, and its seeded draws.

A grasp's quality, as a robot needs it, is the probability that it succeeds under the errors
the robot will make (docs/concepts/success-probability.md). `UncertaintyModel` states those errors:

- the start pose's position error (per axis Gaussian with σ = `position_mm`, or uniform in a
  ball of radius `position_mm`) and attitude error (the same forms, `orientation_deg`);
- scales of the object's friction coefficient and mass and of the hand's closing effort, each
  uniform over a range [lo, hi] (1, 1: no error).

Presets: `none` (no error), `lab` (2 mm / 2°, Gaussian: the certification's former default),
`field` (5 mm / 5° uniform ball, friction × 0.5–1, mass × 0.8–1.2). Fields given beside a
preset override it.

Draws are seeded from the pose key, the model's values and a stream name: draw i is a function
of (key, model, stream, i) alone, so a run is repeatable, a larger sample extends a smaller
one, and any number of workers draws the same sample. A fresh check uses another stream.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.sim import EngineName
from pydantic import BaseModel, ConfigDict, Field, model_validator

Range = tuple[float, float]

PRESETS: dict[str, dict[str, Any]] = {
    "none": {"position_mm": 0.0, "orientation_deg": 0.0, "form": "gaussian",
             "friction_scale": (1.0, 1.0), "mass_scale": (1.0, 1.0),
             "effort_scale": (1.0, 1.0)},
    "lab": {"position_mm": 2.0, "orientation_deg": 2.0, "form": "gaussian",
            "friction_scale": (1.0, 1.0), "mass_scale": (1.0, 1.0), "effort_scale": (1.0, 1.0)},
    "field": {"position_mm": 5.0, "orientation_deg": 5.0, "form": "ball",
              "friction_scale": (0.5, 1.0), "mass_scale": (0.8, 1.2),
              "effort_scale": (1.0, 1.0)},
}


def _check_range(name: str, value: Range, lo_min: float, hi_max: float) -> None:
    lo, hi = value
    if not lo_min <= lo <= hi <= hi_max:
        raise ValueError(f"{name} {value} must satisfy {lo_min} ≤ lo ≤ hi ≤ {hi_max}")


class UncertaintyModel(BaseModel):
    """The errors a success probability is stated under (module doc)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    preset: Literal["none", "lab", "field", "custom"] = Field(
        default="lab", description="named model; fields given beside it override its values")
    position_mm: float = Field(
        default=2.0, ge=0.0, le=50.0,
        description="start position error, mm: σ per axis ('gaussian') or the ball's radius")
    orientation_deg: float = Field(
        default=2.0, ge=0.0, le=45.0,
        description="start attitude error, deg: σ per axis ('gaussian') or the ball's radius")
    form: Literal["gaussian", "ball"] = Field(
        default="gaussian",
        description="'gaussian': independent per axis; 'ball': uniform in a ball")
    friction_scale: Range = Field(default=(1.0, 1.0),
                                  description="object friction × uniform [lo, hi]")
    mass_scale: Range = Field(default=(1.0, 1.0), description="object mass × uniform [lo, hi]")
    effort_scale: Range = Field(default=(1.0, 1.0),
                                description="hand closing effort × uniform [lo, hi]")
    engines: tuple[EngineName, ...] | None = Field(
        default=None, min_length=1, max_length=4,
        description="physics engines each draw is simulated in: it succeeds only where it "
        "holds with the grasp type in every one (the claim holds for these only); null: the "
        "exploration's engine")

    @model_validator(mode="before")
    @classmethod
    def _preset(cls, data: object) -> object:
        if isinstance(data, dict):
            name = data.get("preset", "lab")
            if name in PRESETS:
                return {**PRESETS[name], **data}
        return data

    @model_validator(mode="after")
    def _ranges(self) -> UncertaintyModel:
        _check_range("friction_scale", self.friction_scale, 0.05, 2.0)
        _check_range("mass_scale", self.mass_scale, 0.1, 10.0)
        _check_range("effort_scale", self.effort_scale, 0.1, 2.0)
        engines = self.engines or ()
        if len(set(engines)) != len(engines):
            raise ValueError(f"engines {engines} lists one twice")
        scaled = any(r != (1.0, 1.0) for r in (self.friction_scale, self.mass_scale,
                                               self.effort_scale))
        if (scaled or len(engines) > 1) and not (self.position_mm or self.orientation_deg):
            # A draw is stored under its start pose's key: with no pose error every draw
            # would be the centre itself.
            raise ValueError("scales or several engines need a pose error (position_mm or "
                             "orientation_deg > 0): draws are told apart by their start poses")
        return self

    def values(self) -> dict[str, Any]:
        """The model's values without its name: what the draws depend on."""
        return self.model_dump(mode="json", exclude={"preset"})

    def fingerprint(self) -> str:
        v = self.values()
        return "|".join(f"{name}={v[name]!r}" for name in sorted(v))

    def describe(self) -> str:
        """One line for people: the model a number is stated under."""
        form = "σ" if self.form == "gaussian" else "ball"
        parts = [f"{self.preset}: pose {form} {self.position_mm:g} mm / {self.orientation_deg:g}°"]
        for name, (lo, hi) in (("friction", self.friction_scale), ("mass", self.mass_scale),
                               ("effort", self.effort_scale)):
            if (lo, hi) != (1.0, 1.0):
                parts.append(f"{name} ×{lo:g}–{hi:g}")
        if self.engines and self.engines != ("pybullet",):
            parts.append("held in " + " and ".join(self.engines))
        return ", ".join(parts)


@dataclass(frozen=True)
class Draw:
    """One draw of the model: the start's position (m) and attitude (rad) errors in the
    object frame, and the scales."""

    position: tuple[float, float, float]
    rotation: tuple[float, float, float]
    friction_scale: float
    mass_scale: float
    effort_scale: float


def _base_seed(key: str, model: UncertaintyModel, stream: str) -> list[int]:
    digest = hashlib.sha256(f"{key}|{model.fingerprint()}|{stream}".encode()).digest()
    return [int.from_bytes(digest[i:i + 4], "big") for i in range(0, 16, 4)]


def _vector(rng: np.random.Generator, size: float, form: str) -> np.ndarray:
    if size <= 0:
        rng.standard_normal(3)  # keep the stream's use fixed whatever the size
        return np.zeros(3)
    v = rng.standard_normal(3)
    if form == "gaussian":
        return size * v
    # uniform in the ball: a uniform direction, radius size · u^(1/3)
    return size * rng.random() ** (1.0 / 3.0) * v / max(float(np.linalg.norm(v)), 1e-12)


def draw(key: str, model: UncertaintyModel, i: int, stream: str = "run") -> Draw:
    """Draw i of the pose `key`'s sequence under `model` (module doc)."""
    rng = np.random.default_rng([*_base_seed(key, model, stream), i])
    e = _vector(rng, model.position_mm / 1000.0, model.form)
    w = _vector(rng, math.radians(model.orientation_deg), model.form)
    u = rng.random(3)
    scales = [lo + (hi - lo) * x for (lo, hi), x in zip(
        (model.friction_scale, model.mass_scale, model.effort_scale), u, strict=True)]
    return Draw(position=tuple(e.tolist()), rotation=tuple(w.tolist()),
                friction_scale=scales[0], mass_scale=scales[1], effort_scale=scales[2])


def draws(key: str, model: UncertaintyModel, n: int, *, start: int = 0,
          stream: str = "run") -> list[Draw]:
    """Draws start … start + n − 1 of the pose's sequence."""
    return [draw(key, model, i, stream) for i in range(start, start + n)]


def perturbed(pose: Pose, d: Draw, radius_m: float) -> Pose:
    """The start pose moved by a draw's position and attitude errors. The position error e
    moves the start along the approach line (r changes by e·u, reflected at 0: the hand cannot
    start inside the object) and across it (the approach direction turns to the point
    R·u + e_t, R the object's surface radius along u plus r); the attitude error adds to roll,
    pitch and yaw (pitch and yaw clipped to their ranges)."""
    st = math.sin(pose.theta)
    u = (st * math.cos(pose.phi), st * math.sin(pose.phi), math.cos(pose.theta))
    reach = radius_m + pose.r
    e, w = d.position, d.rotation
    along = sum(a * b for a, b in zip(e, u, strict=True))
    v = [reach * u[i] + e[i] - along * u[i] for i in range(3)]
    norm = math.sqrt(sum(c * c for c in v))
    theta = math.acos(max(-1.0, min(1.0, v[2] / norm)))
    phi = math.atan2(v[1], v[0]) % (2 * math.pi)
    return Pose(theta=theta, phi=phi, r=min(1.0, abs(pose.r + along)),
                roll=(pose.roll + w[0]) % (2 * math.pi),
                pitch=max(-math.pi, min(math.pi, pose.pitch + w[1])),
                yaw=max(-math.pi / 2, min(math.pi / 2, pose.yaw + w[2])))
