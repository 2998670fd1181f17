"""Opening a zenoh session the way both sides need it: explicit endpoints, no multicast, and
user/password authentication where it is configured.

Multicast scouting is off so that a worker only ever talks to the coordinator or router it
was pointed at (two stacks on one LAN must not find each other). Open a session only in the
process that uses it, after that process started: a session shared across fork is broken.

Authentication is zenoh's `transport.auth.usrpwd`: the side that accepts connections (the
coordinator's embedded peer, or a router) holds a dictionary file of `user:password` lines and
refuses a transport whose credentials are not in it; the side that connects presents `user`
and `password`. Both sides must agree: with zenoh 1.10 a session that presents credentials
to a listener without a dictionary is refused as well, and a listener that has credentials
but no dictionary refuses everyone (docs/design/protocol.md, "Access control").
"""

from __future__ import annotations

import ipaddress
import json
import re
from pathlib import Path
from typing import Literal

import zenoh

# Endpoints that never leave this host: unix sockets and pipes.
_LOCAL_PROTOCOLS = ("unixsock-stream", "unixpipe")


def zenoh_config(
    *,
    mode: Literal["peer", "client"],
    listen: list[str] | tuple[str, ...] = (),
    connect: list[str] | tuple[str, ...] = (),
    connect_timeout_ms: int = -1,
    exit_on_failure: bool = False,
    user: str | None = None,
    password: str | None = None,
    users_file: str | Path | None = None,
) -> zenoh.Config:
    """`user` + `password`: the credentials this session presents where it connects;
    `users_file`: the dictionary it checks sessions that connect to it against."""
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
    usrpwd: dict[str, str] = {}
    if password is not None:
        if not user:
            raise ValueError("a zenoh password needs a user")
        usrpwd.update(user=user, password=password)
    if users_file is not None:
        usrpwd["dictionary_file"] = str(users_file)
    if usrpwd:
        config["transport"] = {"auth": {"usrpwd": usrpwd}}
    return zenoh.Config.from_json5(json.dumps(config))


def write_users_file(path: Path, users: dict[str, str]) -> Path:
    """A zenoh usrpwd dictionary (`user:password` per line), readable by its owner only."""
    for user, password in users.items():
        if not user or ":" in user or "\n" in user + password:
            raise ValueError(f"zenoh user {user!r}: no ':' or line break in names, none in "
                             "passwords, and no empty name")
    path.touch(mode=0o600)
    path.chmod(0o600)
    path.write_text("".join(f"{user}:{password}\n" for user, password in users.items()))
    return path


def is_local_endpoint(endpoint: str) -> bool:
    """Whether a zenoh endpoint (`tcp/127.0.0.1:7447`, `tcp/[::1]:7447`,
    `unixsock-stream//tmp/gs.sock`, ...) can only be reached from this host: loopback
    addresses, `localhost` and unix sockets. Anything else, `0.0.0.0` and host names
    included, counts as reachable from the network."""
    protocol, _, address = endpoint.partition("/")
    if protocol in _LOCAL_PROTOCOLS:
        return True
    address = re.split(r"[?#]", address, maxsplit=1)[0]  # endpoint metadata and config
    host, sep, _port = address.rpartition(":")
    if not sep:
        return False
    host = host.strip("[]")
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
