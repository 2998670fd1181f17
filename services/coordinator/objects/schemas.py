"""Pydantic shapes of objects at the HTTP boundary."""

from __future__ import annotations

from datetime import datetime
from typing import Any, Literal

from graspscape.services.coordinator.objects.mesh import MeshInfo
from pydantic import BaseModel, ConfigDict


class ObjectOut(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: int
    kind: Literal["named", "upload", "shared"]
    name: str
    content_hash: str | None
    mesh_format: str | None
    properties: dict[str, Any]
    mesh_info: MeshInfo | None
    created_at: datetime


class ObjectPage(BaseModel):
    items: list[ObjectOut]
    total: int
    limit: int
    offset: int
