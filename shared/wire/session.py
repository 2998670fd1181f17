"""Opening a zenoh session the way both sides need it: explicit endpoints, no multicast.

Multicast scouting is off so that a worker only ever talks to the coordinator or router it
was pointed at (two stacks on one LAN must not find each other). Open a session only in the
process that uses it, after that process started: a session shared across fork is broken.
"""

from __future__ import annotations

import json
from typing import Literal

import zenoh


def zenoh_config(
    *,
    mode: Literal["peer", "client"],
    listen: list[str] | tuple[str, ...] = (),
    connect: list[str] | tuple[str, ...] = (),
    connect_timeout_ms: int = -1,
    exit_on_failure: bool = False,
) -> zenoh.Config:
    config: dict = {
        "mode": mode,
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "listen": {"endpoints": list(listen)},
        "connect": {
            "endpoints": list(connect),
            # -1: wait for the endpoints forever (a peer keeps retrying in the background);
            # a worker passes a bounded timeout and retries itself, so it can still stop.
            "timeout_ms": connect_timeout_ms,
            "exit_on_failure": exit_on_failure,
        },
    }
    return zenoh.Config.from_json5(json.dumps(config))
