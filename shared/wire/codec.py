"""Bytes ↔ messages. Decoding never raises: a bad payload becomes an ErrorReply.

Zenoh callbacks swallow exceptions, so anything that could raise on input from the network is
turned into a typed value here and the caller decides what to answer and what to count.
"""

from __future__ import annotations

import json
from typing import TypeVar

from graspscape.shared.wire.messages import (
    WIRE_VERSION,
    BatchHeader,
    ErrorCode,
    ErrorReply,
    Message,
)
from pydantic import BaseModel, TypeAdapter, ValidationError

_ADAPTER: TypeAdapter[Message] = TypeAdapter(Message)
_KINDS = {"lease_request", "tile_lease", "result_batch", "ack", "object_request",
          "object_data", "error"}
M = TypeVar("M", bound=BaseModel)


def encode(message: BaseModel) -> bytes:
    return message.model_dump_json().encode()


def error(code: ErrorCode, message: str) -> ErrorReply:
    return ErrorReply(code=code, message=message[:4000])


def decode(data: bytes | bytearray | memoryview) -> Message | ErrorReply:
    """Any message, or the ErrorReply that says why the payload is not one."""
    data = bytes(data)
    try:
        # Fast path: pydantic parses and validates the bytes in one pass (half the time of
        # json.loads + validate_python on a 100-pose batch). Only a refused payload takes
        # the slower path below, which says precisely what is wrong with it.
        return _ADAPTER.validate_json(data)
    except ValidationError:
        pass
    try:
        raw = json.loads(data)
    except (ValueError, UnicodeDecodeError) as exc:
        return error(ErrorCode.MALFORMED, f"payload is not JSON: {exc}")
    if not isinstance(raw, dict):
        return error(ErrorCode.MALFORMED, "payload is not a JSON object")
    version = raw.get("v")
    if version != WIRE_VERSION:
        return error(
            ErrorCode.UNSUPPORTED_VERSION,
            f"protocol version {version!r} is not supported (this side speaks {WIRE_VERSION})",
        )
    if raw.get("kind") not in _KINDS:
        return error(ErrorCode.UNKNOWN_KIND, f"unknown message kind {raw.get('kind')!r}")
    try:
        return _ADAPTER.validate_python(raw)
    except ValidationError as exc:
        parts = [
            f"{'.'.join(str(p) for p in e['loc']) or 'message'}: {e['msg']}"
            for e in exc.errors()[:5]
        ]
        return error(ErrorCode.MALFORMED, "; ".join(parts))


def batch_header(data: bytes | bytearray | memoryview) -> BatchHeader | None:
    """The sender and lease of a result batch whose body was refused; None when even those
    cannot be read (then nobody can be held to it)."""
    try:
        return BatchHeader.model_validate_json(bytes(data))
    except ValidationError:
        return None


def decode_reply_error(data: bytes | bytearray | memoryview) -> ErrorReply:
    """What an error reply to a query means.

    A peer of this protocol sends an ErrorReply as JSON. An error reply whose payload is not
    JSON at all was made by zenoh itself: above all its `Timeout`, when no final reply came
    within the query's timeout (a coordinator busy with the database, or not there). That is
    no refusal of the message: it comes back as `unavailable`, which the sender retries.
    """
    data = bytes(data)
    try:
        json.loads(data)
    except (ValueError, UnicodeDecodeError):
        text = data[:200].decode(errors="replace") or "an error without payload"
        return error(ErrorCode.UNAVAILABLE, f"no reply in time (zenoh: {text}); retry")
    return decode_as(data, ErrorReply)


def decode_as(data: bytes | bytearray | memoryview, expected: type[M]) -> M | ErrorReply:
    """A message of the expected type; an error reply (kept as is) or a typed refusal else."""
    message = decode(data)
    if isinstance(message, expected):
        return message
    if isinstance(message, ErrorReply):
        return message
    return error(
        ErrorCode.UNEXPECTED_KIND,
        f"expected {expected.model_fields['kind'].default!r}, got {message.kind!r}",
    )
