"""What an object to be grasped is, as users and the wire describe it.

An object is named (a built-in shape, a pybullet_data mesh or a YCB folder entry) or given as
a mesh file or a URDF, with its physical properties; shared/specs/object_checks.py validates
it. Workers turn it into a pybullet body; the coordinator stores it by the content hash of
its mesh.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

LengthUnit = Literal["m", "cm", "mm"]
METRES_PER: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001}


class ObjectSpec(BaseModel):
    model_config = ConfigDict(frozen=True)

    name: str | None = Field(
        default=None,
        description=(
            "built-in ('sphere', 'cube', 'can', 'dumbbell', 'mug', 'spiked_ball'), "
            "pybullet_data ('pb:mug', 'pb:bunny', 'pb:duck', 'pb:teddy') or a YCB folder "
            "entry ('ycb:YcbPowerDrill')"
        ),
    )
    mesh_path: str | None = Field(
        default=None,
        description="mesh file (OBJ, STL, PLY, GLB; in metres unless `units`), or a one-link "
        "URDF whose mass, friction and mesh scale are kept",
    )
    mass_kg: float | None = Field(
        default=None, gt=0.0, le=50.0, description="mass; default: the named object's own"
    )
    friction: float | None = Field(
        default=None, ge=0.0, le=5.0, description="lateral friction coefficient"
    )
    inertia_diag: tuple[float, float, float] | None = Field(
        default=None,
        description=(
            "moments of inertia about the centre of mass along the object-frame axes, kg·m²; "
            "default: from the mesh at mass_kg (see docs/howto/add-object.md)"
        ),
    )
    scale: float = Field(default=1.0, gt=0.0, le=100.0, description="uniform mesh scale")
    units: LengthUnit | None = Field(
        default=None,
        description="length unit of a mesh file ('m', 'cm', 'mm'); default metres. "
        "Multiplies scale; named objects are in metres already",
    )

    @model_validator(mode="after")
    def _one_source(self) -> ObjectSpec:
        if (self.name is None) == (self.mesh_path is None):
            raise ValueError("give exactly one of 'name' and 'mesh_path'")
        if self.inertia_diag is not None and min(self.inertia_diag) <= 0:
            raise ValueError("inertia_diag entries must be positive")
        if self.units is not None and self.name is not None:
            raise ValueError(
                "units apply to mesh files; a named object is in metres already (use scale)"
            )
        return self

    @property
    def metres_per_unit(self) -> float:
        """What one unit of the source file is in metres: scale × units."""
        if self.units is None:
            return self.scale  # as given, so the content hash of existing objects is unchanged
        return self.scale * METRES_PER[self.units]
