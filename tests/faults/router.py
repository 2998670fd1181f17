"""A zenoh router as a process of its own, for the fault tests: `python -m tests.faults.router
--listen tcp/127.0.0.1:7447 [--users-file FILE]`.

The compose stack runs `zenohd` 1.10.2; there is no zenohd on PyPI or in Debian, so the fault
tests open a session in zenoh's `router` mode through the eclipse-zenoh package of the same
version (the Python wheel carries zenoh's Rust runtime, routing included). Like zenohd, it
listens, routes between the coordinator (a client) and the workers (clients), and checks the
usrpwd dictionary it is given. It runs until SIGTERM or SIGKILL.
"""

from __future__ import annotations

import argparse
import json
import signal
import threading

import zenoh


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--listen", action="append", required=True)
    parser.add_argument("--users-file")
    # zenoh's defaults: at most 100 sessions in their handshake at once and 1,000 sessions in
    # all (transport/unicast/accept_pending, max_sessions); a fleet of a thousand needs more.
    parser.add_argument("--accept-pending", type=int)
    parser.add_argument("--max-sessions", type=int)
    args = parser.parse_args()
    config: dict = {
        "mode": "router",
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "listen": {"endpoints": args.listen},
    }
    transport: dict = {}
    if args.users_file:
        transport["auth"] = {"usrpwd": {"dictionary_file": args.users_file}}
    unicast = {key: value for key, value in (("accept_pending", args.accept_pending),
                                             ("max_sessions", args.max_sessions))
               if value is not None}
    if unicast:
        transport["unicast"] = unicast
    if transport:
        config["transport"] = transport
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    session = zenoh.open(zenoh.Config.from_json5(json.dumps(config)))
    print("router listening on", ", ".join(args.listen), flush=True)
    stop.wait()
    session.close()


if __name__ == "__main__":
    main()
