"""Pydantic shapes of objects at the HTTP boundary."""

from __future__ import annotations

from datetime import datetime
from typing import Any, Literal

from graspscape.services.coordinator.objects.mesh import MeshInfo
from pydantic import BaseModel, ConfigDict, Field, model_validator

_COLUMNS = ("id", "kind", "name", "content_hash", "mesh_format", "properties", "created_at")


class ObjectOut(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: int
    kind: Literal["named", "upload", "shared"]
    name: str
    content_hash: str | None
    mesh_format: str | None
    properties: dict[str, Any]
    mesh_info: MeshInfo | None
    warnings: list[str] = Field(
        default_factory=list,
        description="what the validation at upload warned about (docs/howto/add-object.md, "
        "'Validation'): the object is accepted, but check these",
    )
    created_at: datetime

    @model_validator(mode="before")
    @classmethod
    def _from_row(cls, data: Any) -> Any:
        # The row's mesh_info column holds the mesh facts and the warnings together (a named
        # object's only its warnings): split them into the two fields.
        if isinstance(data, dict):
            return data
        stored = dict(getattr(data, "mesh_info", None) or {})
        warnings = stored.pop("warnings", [])
        out = {c: getattr(data, c) for c in _COLUMNS}
        return {**out, "mesh_info": stored or None, "warnings": warnings}
