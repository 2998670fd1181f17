"""Routes for objects: POST /objects (mesh upload or name), GET list and one."""

from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal

from fastapi import APIRouter, File, Form, Path, Query, Request, Response, UploadFile, status
from graspscape.services.coordinator.api.deps import Mutating, SessionDep, SettingsDep
from graspscape.services.coordinator.api.finite import (
    FiniteJSONRoute,
    NoUnderflow,
    underflows,
)
from graspscape.services.coordinator.api.pages import Page
from graspscape.services.coordinator.api.responses import NOT_FOUND, UNAUTHORIZED, error
from graspscape.services.coordinator.api.uploads import read_limited, refuse_large_body
from graspscape.services.coordinator.errors import InvalidInput
from graspscape.services.coordinator.objects import service
from graspscape.services.coordinator.objects.schemas import ObjectOut

router = APIRouter(tags=["objects"], route_class=FiniteJSONRoute)

_CONTROL = re.compile(r"[\x00-\x1f\x7f]")
_ERRORS: dict[int | str, dict[str, Any]] = {
    **UNAUTHORIZED,
    400: error("malformed multipart body"),
    413: error("upload larger than max_upload_bytes"),
    415: error("unsupported mesh file format"),
    422: {
        "description": "invalid properties, unknown name, or a mesh the validation refuses "
        "(docs/howto/add-object.md, 'Validation'); the detail names each problem and what to do"
    },
}


def _inertia(text: str | None) -> tuple[float, float, float] | None:
    if text is None or text == "":
        return None
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if (len(values) != 3 or not all(math.isfinite(v) for v in values)
            or any(underflows(v) for v in text.split(","))):
        raise InvalidInput(
            "inertia_diag must be three finite comma-separated numbers, kg·m²",
            loc=("body", "inertia_diag"),
        )
    return values  # type: ignore[return-value]


@router.post(
    "/objects",
    response_model=ObjectOut,
    status_code=status.HTTP_201_CREATED,
    dependencies=Mutating,
    responses={
        200: {"description": "the same object was stored before", "model": ObjectOut},
        **_ERRORS,
    },
    summary="Store an object: upload a mesh (with properties) or name one",
)
def create_object(
    request: Request,
    response: Response,
    session: SessionDep,
    settings: SettingsDep,
    file: Annotated[UploadFile | None, File(description="mesh: .obj .stl .ply .glb .off")] = None,
    name: Annotated[
        str | None,
        Form(max_length=300, description="built-in, 'pb:…', 'ycb:…' or 'shared:<file>'"),
    ] = None,
    mass_kg: Annotated[float | None, NoUnderflow,
                       Form(allow_inf_nan=False, description="kg, (0, 50]")] = None,
    friction: Annotated[
        float | None, NoUnderflow,
        Form(allow_inf_nan=False, description="lateral friction, [0, 5]")
    ] = None,
    scale: Annotated[
        float | None, NoUnderflow,
        Form(allow_inf_nan=False, description="uniform mesh scale, (0, 100]")
    ] = None,
    inertia_diag: Annotated[
        str | None, Form(max_length=200, description="'Ixx,Iyy,Izz' in kg·m²")
    ] = None,
    units: Annotated[
        Literal["m", "cm", "mm"] | None,
        Form(description="length unit of the mesh file (default m); multiplies scale"),
    ] = None,
) -> Any:
    refuse_large_body(request, settings.api.max_upload_bytes)
    props: dict[str, Any] = {
        k: v
        for k, v in {
            "mass_kg": mass_kg,
            "friction": friction,
            "scale": scale,
            "inertia_diag": _inertia(inertia_diag),
            "units": units,
        }.items()
        if v is not None
    }
    for label, field, text in (
        ("name", "name", name),
        ("file name", "file", file.filename if file else None),
    ):
        if text is not None and _CONTROL.search(text):
            raise InvalidInput(f"{label} contains control characters", loc=("body", field))
    if file is not None and name:
        raise InvalidInput("give either a mesh file or a name, not both")
    if file is not None:
        data = read_limited(file, settings.api.max_upload_bytes, "mesh file")
        row, created = service.create_uploaded(
            session, filename=file.filename, data=data, properties=props
        )
    elif name:
        row, created = service.create_named(
            session, name=name, properties=props, shared_dir=settings.api.shared_objects_dir
        )
    else:
        raise InvalidInput("give a mesh file (field 'file') or an object name (field 'name')")
    if not created:
        response.status_code = status.HTTP_200_OK
    return row


@router.get("/objects", response_model=Page[ObjectOut], summary="List stored objects")
def list_objects(
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=2**31 - 1)] = 0,
) -> Any:
    rows, total = service.list_objects(session, limit=limit, offset=offset)
    return Page[ObjectOut](items=rows, total=total, limit=limit, offset=offset)


@router.get(
    "/objects/{object_id}",
    response_model=ObjectOut,
    responses=NOT_FOUND,
)
def get_object(session: SessionDep, object_id: Annotated[int, Path(ge=1, le=2**31 - 1)]) -> Any:
    return service.get_object(session, object_id=object_id)
