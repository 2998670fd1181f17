"""Documented error responses, so the OpenAPI document lists every status a route returns.

Refusals other than 422 carry `{"detail": "<what is wrong>"}`. A 422 has FastAPI's validation
shape `{"detail": [{"loc", "msg", "type"}]}` whether pydantic or a service refused the
input, so clients parse one format.
"""

from __future__ import annotations

from typing import Any

from fastapi.responses import Response
from pydantic import BaseModel


class ErrorOut(BaseModel):
    detail: str


def error(description: str) -> dict[str, Any]:
    return {"model": ErrorOut, "description": description}


UNAUTHORIZED = {401: error("bearer token missing or wrong (when api_token is set)")}
NOT_FOUND = {404: error("no such resource")}


def encoded(model: BaseModel) -> bytes:
    """A model's JSON as FastAPI 0.165 writes a response model (pydantic's serializer, by
    alias, in one pass). A route that returns these bytes (`json_response`) answers the same
    document without FastAPI validating and encoding the model a second time."""
    return type(model).__pydantic_serializer__.to_json(model, by_alias=True)


def json_response(body: bytes) -> Response:
    return Response(content=body, media_type="application/json")
