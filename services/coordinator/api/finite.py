"""Non-finite numbers never get past the HTTP boundary, and a 422 can always be written.

JSON has no NaN or Infinity, but Python's parser (which FastAPI uses for bodies) accepts the
tokens `NaN`, `Infinity` and `-Infinity` and turns `1e999` into infinity. Every route's JSON
body is checked here before FastAPI parses it: each non-finite number is refused with a 422
in the validation shape, naming where it is (`["body", "grid", "dtheta"]`). Query and form
numbers are declared `allow_inf_nan=False` where they are declared.

The 422 handler replaces FastAPI's: the same `{"detail": [...]}`, but a non-finite number
echoed back in an error (`input`, `ctx`) is written as its JSON-ish token, since
`JSONResponse` refuses NaN and the default handler answered such a request with a 500.
"""

from __future__ import annotations

import email.message
import json
import math
from collections.abc import Callable, Coroutine
from typing import Any

from fastapi import Request, Response
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.routing import APIRoute

FINITE_MESSAGE = "Input should be a finite number"


class _NonFinite:
    """Left in the parsed document where a non-finite number was."""

    __slots__ = ("text",)

    def __init__(self, text: str) -> None:
        self.text = text


def non_finite_locations(body: bytes) -> list[tuple[tuple[str | int, ...], str]]:
    """(path, token) of every non-finite number in a JSON document; [] if none, or if the
    document is not JSON at all (FastAPI says so itself)."""
    found: list[_NonFinite] = []

    def mark(text: str) -> _NonFinite:
        marker = _NonFinite(text)
        found.append(marker)
        return marker

    def number(text: str) -> float | _NonFinite:
        value = float(text)
        return value if math.isfinite(value) else mark(text)

    try:
        document = json.loads(body, parse_constant=mark, parse_float=number)
    except (ValueError, UnicodeDecodeError, RecursionError):
        return []
    if not found:
        return []
    out: list[tuple[tuple[str | int, ...], str]] = []
    stack: list[tuple[tuple[str | int, ...], Any]] = [((), document)]
    while stack:
        path, value = stack.pop()
        if isinstance(value, _NonFinite):
            out.append((path, value.text))
        elif isinstance(value, dict):
            stack.extend(((*path, k), v) for k, v in reversed(value.items()))
        elif isinstance(value, list):
            stack.extend(((*path, i), v) for i, v in reversed(list(enumerate(value))))
    return out


def _is_json(content_type: str | None) -> bool:
    if not content_type:
        return True  # FastAPI parses a body without a content type as JSON
    message = email.message.Message()
    message["content-type"] = content_type
    if message.get_content_maintype() != "application":
        return False
    subtype = message.get_content_subtype()
    return subtype == "json" or subtype.endswith("+json")


class FiniteJSONRoute(APIRoute):
    """An APIRoute that refuses a JSON body holding NaN or ±Infinity with a 422."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()

        async def finite_only(request: Request) -> Response:
            if request.method in ("POST", "PUT", "PATCH") and _is_json(
                request.headers.get("content-type")
            ):
                body = await request.body()  # cached: FastAPI reads the same bytes next
                bad = non_finite_locations(body) if body else []
                if bad:
                    raise RequestValidationError(
                        [
                            {"type": "finite_number", "loc": ("body", *path),
                             "msg": FINITE_MESSAGE, "input": token}
                            for path, token in bad
                        ]
                    )
            return await handler(request)

        return finite_only


def _writable(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
    if isinstance(value, dict):
        return {k: _writable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_writable(v) for v in value]
    return value


async def validation_error_handler(_request: Request, exc: Exception) -> JSONResponse:
    """FastAPI's 422, with non-finite numbers in the echoed input written as tokens."""
    assert isinstance(exc, RequestValidationError)
    return JSONResponse({"detail": _writable(jsonable_encoder(exc.errors()))}, status_code=422)
