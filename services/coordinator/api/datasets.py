"""Routes for the grasp datasets other tools read (services/coordinator/datasets): GraspGen's
JSON, an ACRONYM-style HDF5 and the object's mesh in their frame. Each export is written to a
temporary file first, so a refusal (no such exploration, no mesh) is a 4xx and not a broken
download, and then streamed from it: memory holds one chunk of poses, never the table.
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator
from typing import IO, Any

from fastapi import APIRouter
from fastapi.responses import Response
from graspscape.services.coordinator.api.deps import SessionDep
from graspscape.services.coordinator.api.explorations import Id
from graspscape.services.coordinator.api.finite import FiniteJSONRoute
from graspscape.services.coordinator.api.responses import error
from graspscape.services.coordinator.api.streams import ClosingStream
from graspscape.services.coordinator.datasets.formats import FORMATS, DatasetFormat

router = APIRouter(tags=["datasets"], route_class=FiniteJSONRoute)

_BLOCK = 1 << 20


def _stream(file: IO[bytes]) -> Iterator[bytes]:
    try:
        while block := file.read(_BLOCK):
            yield block
    finally:
        file.close()


def _route(name: str, fmt: DatasetFormat) -> None:
    def export(exploration_id: Id, session: SessionDep) -> Response:
        # Closed by the stream once sent (or here on a refusal), so no `with`.
        file = tempfile.TemporaryFile()  # noqa: SIM115
        try:
            fmt.write(session, exploration_id, file)
        except BaseException:
            file.close()
            raise
        file.seek(0)
        disposition = f'attachment; filename="exploration-{exploration_id}-{name}"'
        # Closed when the client goes away too (api/streams.py), not only once sent.
        return ClosingStream(_stream(file), what=f"{name} of exploration {exploration_id}",
                             media_type=fmt.media_type,
                             headers={"Content-Disposition": disposition})

    responses: dict[int | str, dict[str, Any]] = {
        404: error("no such exploration"),
        409: error("the object's mesh is needed and unavailable in this coordinator"),
        200: {"content": {fmt.media_type: {}}, "description": fmt.summary},
    }
    router.add_api_route(f"/explorations/{{exploration_id}}/export/{name}", export,
                         methods=["GET"], response_class=Response, responses=responses,
                         summary=fmt.summary, name="export_" + name.replace(".", "_"))


for _name, _fmt in FORMATS.items():
    _route(_name, _fmt)
