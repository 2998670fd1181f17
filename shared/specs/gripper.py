"""The gripper spec format: a palm and fingers made of phalanges, generic enough for any
serial-finger gripper (the Robotiq 3-finger hand, a parallel-jaw gripper, ...).

Frames: the gripper base frame has its origin at the centre of the palm surface and +z along
the palm normal, pointing out of the palm toward where the fingers reach. Each finger has a
mount frame (its knuckle) given by a position on the palm and a yaw about the palm normal; in
the mount frame the finger extends along +z and closes toward +x.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "grippers"


class PalmSpec(BaseModel):
    model_config = ConfigDict(frozen=True)

    size: tuple[float, float, float] = Field(description="x, y, thickness (m)")
    mass: float = Field(gt=0)


class PhalanxSpec(BaseModel):
    """One link of a finger and the joint that carries it."""

    model_config = ConfigDict(frozen=True)

    name: str
    joint: Literal["revolute", "prismatic"] = "revolute"
    length: float = Field(gt=0, description="along the finger (+z of its joint frame), m")
    width: float = Field(gt=0, description="across the finger (y), m")
    thickness: float = Field(gt=0, description="in the closing direction (x), m")
    mass: float = Field(gt=0)
    lower: float = Field(description="joint limit: rad (revolute) or m (prismatic)")
    upper: float
    open: float = Field(description="joint value of the open hand")
    torque_share: float = Field(
        default=1.0, gt=0, le=1.0, description="share of the finger's closing effort"
    )

    @model_validator(mode="after")
    def _limits(self) -> PhalanxSpec:
        if not self.lower < self.upper or not self.lower <= self.open <= self.upper:
            raise ValueError(f"phalanx {self.name}: need lower < upper and open within them")
        return self


class SpreadSpec(BaseModel):
    """A joint about the palm normal that turns a finger's closing plane (Robotiq scissor)."""

    model_config = ConfigDict(frozen=True)

    lower: float
    upper: float
    mass: float = Field(default=0.05, gt=0)


class FingerSpec(BaseModel):
    model_config = ConfigDict(frozen=True)

    name: str
    mount_xyz: tuple[float, float, float]
    mount_yaw: float = Field(description="rotation of the mount frame about the palm normal")
    spread: SpreadSpec | None = None
    spread_sign: float = Field(default=1.0, description="how this finger follows the spread mode")
    phalanges: tuple[PhalanxSpec, ...] = Field(min_length=1)


class GripperSpec(BaseModel):
    model_config = ConfigDict(frozen=True)

    name: str
    description: str = ""
    palm: PalmSpec
    fingers: tuple[FingerSpec, ...] = Field(min_length=1)
    closing_effort: float = Field(
        gt=0, description="default closing torque (N·m) or force (N) per finger actuator"
    )
    spread_modes: dict[str, float] = Field(
        default_factory=lambda: {"basic": 0.0}, description="named spread angles, rad"
    )

    @model_validator(mode="after")
    def _unique_names(self) -> GripperSpec:
        names = [f.name for f in self.fingers]
        links = [f"{f.name}_{p.name}" for f in self.fingers for p in f.phalanges]
        if len(set(names)) != len(names) or len(set(links)) != len(links):
            raise ValueError("finger and phalanx names must be unique")
        return self

    def reach(self) -> float:
        """How far the open hand reaches past the palm surface along its normal, m."""
        import math

        best = 0.0
        for finger in self.fingers:
            z, angle = finger.mount_xyz[2], 0.0
            for phalanx in finger.phalanges:
                if phalanx.joint == "revolute":
                    angle += phalanx.open
                z += phalanx.length * math.cos(angle)
            best = max(best, z)
        return best


def load_gripper(name_or_path: str) -> GripperSpec:
    """A gripper by name (a file in configs/grippers/) or by path to a TOML spec."""
    path = Path(name_or_path)
    if not path.suffix:
        path = CONFIG_DIR / f"{name_or_path}.toml"
    if not path.is_file():
        known = sorted(p.stem for p in CONFIG_DIR.glob("*.toml"))
        raise ValueError(f"unknown gripper {name_or_path!r}; known: {', '.join(known)}")
    with path.open("rb") as fh:
        return GripperSpec.model_validate(tomllib.load(fh))


def list_grippers() -> list[str]:
    return sorted(p.stem for p in CONFIG_DIR.glob("*.toml"))
