"""POST /grippers: store a gripper of one's own, so that a spec can name it from anywhere.

A REST user on another machine cannot name a path of theirs in a spec: the coordinator packs
what it finds on its own disk. Uploading the gripper's files here answers the name the spec
gives instead (`sha256:<hash>`); workers fetch the archive by that hash as they fetch meshes.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, File, Request, Response, UploadFile, status
from graspscape.services.coordinator.api.deps import Mutating, SessionDep
from graspscape.services.coordinator.api.finite import FiniteJSONRoute
from graspscape.services.coordinator.api.responses import UNAUTHORIZED, error
from graspscape.services.coordinator.api.uploads import read_limited, refuse_large_body
from graspscape.services.coordinator.objects import grippers
from graspscape.shared.specs.gripper import STORED_PREFIX
from graspscape.shared.specs.gripper_archive import MAX_ARCHIVE_BYTES
from pydantic import BaseModel, Field

router = APIRouter(tags=["grippers"], route_class=FiniteJSONRoute)


class GripperOut(BaseModel):
    gripper: str = Field(description="what a spec's `gripper` names it by: 'sha256:<hash>'")
    content_hash: str = Field(description="SHA-256 of the stored archive")
    kind: Literal["toml", "urdf"] = Field(description="a TOML spec, or a URDF gripper's folder")
    name: str = Field(description="the gripper's own name, from its description")
    size_bytes: int = Field(description="the stored archive's size, bytes")


@router.post(
    "/grippers",
    response_model=GripperOut,
    status_code=status.HTTP_201_CREATED,
    dependencies=Mutating,
    responses={
        200: {"description": "the same gripper was stored before", "model": GripperOut},
        **UNAUTHORIZED,
        400: error("malformed multipart body"),
        413: error(f"upload larger than {MAX_ARCHIVE_BYTES} bytes"),
        422: {"description": "not a gripper: the detail says why (an unreadable spec, a zip "
              "with unsafe paths or no gripper.toml, a URDF mesh outside its folder)"},
    },
    summary="Store a gripper: a TOML spec file, or a zip of a URDF gripper's folder",
)
def create_gripper(
    request: Request,
    response: Response,
    session: SessionDep,
    file: Annotated[UploadFile, File(description="a gripper's .toml spec, or a .zip of a URDF "
                                     "gripper's folder (its gripper.toml at the top)")],
) -> Any:
    refuse_large_body(request, MAX_ARCHIVE_BYTES)
    data = read_limited(file, MAX_ARCHIVE_BYTES, "the gripper file")
    row, created = grippers.store_upload(session, filename=file.filename, data=data)
    if not created:
        response.status_code = status.HTTP_200_OK
    return GripperOut(gripper=STORED_PREFIX + row.content_hash, content_hash=row.content_hash,
                      kind=row.kind, name=row.name, size_bytes=len(row.archive))
