"""The codec: every message round-trips, and no input makes decode raise."""

from __future__ import annotations

import json
import random

from graspscape.shared.wire import keys
from graspscape.shared.wire.codec import decode, decode_as, encode
from graspscape.shared.wire.messages import (
    Ack,
    ErrorCode,
    ErrorReply,
    LeaseRequest,
    ObjectData,
    ObjectRequest,
)


def test_round_trip() -> None:
    for message in (
        LeaseRequest(worker_id="host-1-p0-42", capacity=2, holding=[3]),
        Ack(tile_id=1, lease_epoch=2, inserted=3, duplicates=0, tile_state="done"),
        ObjectRequest(content_hash="a" * 64),
        ObjectData.of("b" * 64, "stl", bytes(range(256))),
        ErrorReply(code=ErrorCode.INVALID, message="no"),
    ):
        assert decode(encode(message)) == message
    assert decode(encode(ObjectData.of("b" * 64, "stl", b"\x00\xff"))).mesh() == b"\x00\xff"


def test_newer_optional_fields_are_ignored() -> None:
    raw = json.loads(encode(LeaseRequest(worker_id="w", capacity=1)))
    raw["priority"] = "high"
    assert isinstance(decode(json.dumps(raw).encode()), LeaseRequest)


def test_no_input_raises() -> None:
    rng = random.Random(4)
    samples = [b"", b"null", b"{}", b'{"v": 1}', b'{"v": true, "kind": "ack"}',
               b'{"v": 1, "kind": "ack", "tile_id": "x"}', b"\xff" * 10]
    samples += [bytes(rng.randrange(256) for _ in range(rng.randrange(64))) for _ in range(300)]
    for data in samples:
        assert isinstance(decode(data), ErrorReply)
        assert isinstance(decode_as(data, Ack), ErrorReply)


def test_worker_ids_are_safe_in_keys() -> None:
    assert keys.worker_of_alive_key(keys.alive_key("h-1-p0-7")) == "h-1-p0-7"
    assert keys.worker_of_alive_key("gs/alive/a/b") is None
    for bad in ("a/b", "*", "", "a b"):
        try:
            keys.alive_key(bad)
        except ValueError:
            continue
        raise AssertionError(bad)


def test_zenoh_errors_of_a_query_are_retryable_and_refusals_stay_refusals() -> None:
    from graspscape.shared.wire.codec import decode_reply_error

    timeout = decode_reply_error(b"Timeout")  # what zenoh replies when no answer came in time
    assert timeout.code == ErrorCode.UNAVAILABLE and timeout.code.retryable
    assert "Timeout" in timeout.message
    assert decode_reply_error(b"").code.retryable
    refusal = ErrorReply(code=ErrorCode.INVALID, message="pose key mismatch")
    assert decode_reply_error(encode(refusal)) == refusal
    assert decode_reply_error(b'{"v": 1, "kind": "ack"}').code == ErrorCode.MALFORMED
