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

SESSION_KEY = "5e55" * 8  # a worker session's key (any 32 hex digits)


def test_round_trip() -> None:
    for message in (
        LeaseRequest(session_key=SESSION_KEY, worker_id="host-1-p0-42", capacity=2, holding=[3]),
        Ack(tile_id=1, lease_epoch=2, inserted=3, duplicates=0, tile_state="done"),
        Ack(tile_id=1, lease_epoch=2, inserted=1, duplicates=0, tile_state="leased",
            missing=["0.100000/0.200000/0.010000/0.000000/0.000000/0.000000"]),
        ErrorReply(code=ErrorCode.NOT_LEASE_HOLDER, message="tile 1 is leased to w-2"),
        ObjectRequest(content_hash="a" * 64),
        ObjectData.of("b" * 64, "stl", bytes(range(256))),
        ErrorReply(code=ErrorCode.INVALID, message="no"),
    ):
        assert decode(encode(message)) == message
    assert decode(encode(ObjectData.of("b" * 64, "stl", b"\x00\xff"))).mesh() == b"\x00\xff"


def test_newer_optional_fields_are_ignored() -> None:
    raw = json.loads(encode(LeaseRequest(session_key=SESSION_KEY, worker_id="w", capacity=1)))
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


def test_a_tiles_keys_are_the_keys_of_its_poses() -> None:
    """The coordinator checks batches against tile_pose_keys; workers key their results by
    Pose.key() of tile_poses: the two must agree everywhere, poles, wrapped angles, -0.0,
    integers from JSON and values at the rounding edge included."""
    import math

    from graspscape.shared.specs.pose import tile_pose_keys, tile_poses

    rng = random.Random(19)
    edges = [0, 0.0, -0.0, 1e-7, -1e-7, 5e-7, 4.9999995e-7, math.pi, math.pi - 1e-7, 2 * math.pi]
    for _ in range(500):
        cells = [(rng.choice([*edges[:4], math.pi, math.pi - 1e-7, rng.uniform(0, math.pi)]),
                  rng.choice([*edges, rng.uniform(-10, 10)])) for _ in range(rng.randint(1, 4))]
        r_levels = [rng.choice([0, 0.01, 1, rng.uniform(0, 1)]) for _ in range(rng.randint(1, 3))]
        attitudes = [(rng.choice([*edges, rng.uniform(-10, 10)]),
                      rng.choice([0, -0.0, 5e-7, rng.uniform(-math.pi, math.pi)]),
                      rng.choice([0, -0.0, -5e-7, rng.uniform(-math.pi / 2, math.pi / 2)]))
                     for _ in range(rng.randint(1, 3))]
        assert tile_pose_keys(cells, r_levels, attitudes) == [
            pose.key() for pose in tile_poses(cells, r_levels, attitudes)]
