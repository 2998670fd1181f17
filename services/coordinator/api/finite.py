"""Non-finite numbers never get past the HTTP boundary, and a 422 can always be written.

JSON has no NaN or Infinity, but Python's parser (which FastAPI uses for bodies) accepts the
tokens `NaN`, `Infinity` and `-Infinity` and turns `1e999` into infinity. Every route's JSON
body is checked here before FastAPI parses it: each non-finite number is refused with a 422
in the validation shape, naming where it is (`["body", "grid", "dtheta"]`). Query and form
numbers are declared `allow_inf_nan=False` where they are declared.

A number too small for a float (`1e-400`) parses to 0.0 and would pass a bound such as
`friction ≥ 0` as a value nobody gave: it is refused the same way (`float_underflow`), in JSON
bodies here and in form fields by `NoUnderflow`.

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
from graspscape.shared.specs.numbers import UNDERFLOW_MESSAGE, underflows
from pydantic import BeforeValidator

FINITE_MESSAGE = "Input should be a finite number"
__all__ = ["FINITE_MESSAGE", "UNDERFLOW_MESSAGE", "FiniteJSONRoute", "NoUnderflow", "underflows"]


def _refuse_underflow(value: Any) -> Any:
    if isinstance(value, str) and underflows(value):
        raise ValueError(UNDERFLOW_MESSAGE)
    return value


# For form and query numbers, which arrive as text: `Annotated[float, NoUnderflow, Form()]`.
NoUnderflow = BeforeValidator(_refuse_underflow)


class _NonFinite:
    """Left in the parsed document where a non-finite number was."""

    __slots__ = ("text", "underflow")

    def __init__(self, text: str, underflow: bool = False) -> None:
        self.text, self.underflow = text, underflow


def non_finite_locations(body: bytes) -> list[tuple[tuple[str | int, ...], str]]:
    """(path, token) of every non-finite number in a JSON document; [] if none, or if the
    document is not JSON at all (FastAPI says so itself)."""
    return [(path, marker.text) for path, marker in _unusable_numbers(body)
            if not marker.underflow]


def _unusable_numbers(body: bytes) -> list[tuple[tuple[str | int, ...], _NonFinite]]:
    """(path, marker) of every non-finite or underflowing number in a JSON document."""
    found: list[_NonFinite] = []

    def mark(text: str, underflow: bool = False) -> _NonFinite:
        marker = _NonFinite(text, underflow)
        found.append(marker)
        return marker

    def number(text: str) -> float | _NonFinite:
        value = float(text)
        if not math.isfinite(value):
            return mark(text)
        return mark(text, underflow=True) if underflows(text) else value

    try:
        document = json.loads(body, parse_constant=mark, parse_float=number)
    except (ValueError, UnicodeDecodeError, RecursionError):
        return []
    if not found:
        return []
    out: list[tuple[tuple[str | int, ...], _NonFinite]] = []
    stack: list[tuple[tuple[str | int, ...], Any]] = [((), document)]
    while stack:
        path, value = stack.pop()
        if isinstance(value, _NonFinite):
            out.append((path, value))
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
    """An APIRoute that refuses a JSON body holding NaN, ±Infinity or an underflowing number
    with a 422."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()

        async def finite_only(request: Request) -> Response:
            if request.method in ("POST", "PUT", "PATCH") and _is_json(
                request.headers.get("content-type")
            ):
                body = await request.body()  # cached: FastAPI reads the same bytes next
                bad = _unusable_numbers(body) if body else []
                if bad:
                    raise RequestValidationError([
                        {"type": "float_underflow", "loc": ("body", *path),
                         "msg": UNDERFLOW_MESSAGE, "input": marker.text}
                        if marker.underflow else
                        {"type": "finite_number", "loc": ("body", *path),
                         "msg": FINITE_MESSAGE, "input": marker.text}
                        for path, marker in bad
                    ])
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
