"""The simulated workers of benchmarks/bench_fleet.py: one OS process runs many.

Each is a zenoh client session of its own speaking the real protocol (lease query → one
TileLease per tile → a ResultBatch query → the Ack), sleeping `pose_s` per pose instead of
simulating. Run by bench_fleet.py as
`python benchmarks/fleet_workers.py ENDPOINT COUNT FIRST POSE_S OUT`: `COUNT` workers until
SIGTERM, then what they saw (Tally) as JSON in OUT.
"""

from __future__ import annotations

import json
import signal
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


class Tally:
    """What one fleet process saw, written as JSON when it is told to stop."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.lease_ms: list[float] = []
        self.ack_ms: list[float] = []
        self.tiles = self.poses_sent = self.inserted = self.duplicates = 0
        self.missing = self.refused = self.empty_leases = 0
        self.connected = self.connect_failures = self.resent = 0

    def as_dict(self) -> dict[str, object]:
        return {k: v for k, v in vars(self).items() if k != "lock"}


def _result_template() -> dict[str, object]:
    """A real-sized held result as JSON-ready data (pose, key and effective r set per pose)."""
    from graspscape.shared.specs.pose import Pose
    from graspscape.workers.runtime.instant import instant_result

    return json.loads(instant_result(Pose(theta=0.0, phi=0.0, r=0.0)).model_dump_json())


def _batch_payload(template: dict[str, object], worker_id: str, tile) -> tuple[bytes, int]:  # type: ignore[no-untyped-def]
    """The ResultBatch of a whole tile, as bytes: one template dict per pose, dumped by the
    C json encoder (pydantic per pose would cost the fleet's processes more than the
    coordinator's work being measured)."""
    from graspscape.shared.wire.messages import WIRE_VERSION

    results = []
    for pose in tile.poses():
        result = dict(template)
        result["pose"] = pose.model_dump(mode="json")
        result["pose_key"] = pose.key()
        result["effective_r"] = pose.r
        results.append(result)
    batch = {"v": WIRE_VERSION, "kind": "result_batch", "worker_id": worker_id,
             "session_key": _session_key(worker_id), "tile_id": tile.tile_id,
             "lease_epoch": tile.lease_epoch, "results": results,
             "final": True, "release": False, "error": None}
    return json.dumps(batch).encode(), len(results)


def _session_key(worker_id: str) -> str:
    """A simulated worker's session key (the coordinator binds the id to it)."""
    import hashlib

    return hashlib.sha256(worker_id.encode()).hexdigest()[:32]


def simulated_worker(endpoint: str, worker_id: str, pose_s: float, stop: threading.Event,
                     tally: Tally, template: dict[str, object]) -> None:
    import zenoh
    from graspscape.shared.wire import keys
    from graspscape.shared.wire.codec import decode_as, decode_reply_error, encode
    from graspscape.shared.wire.messages import Ack, LeaseRequest, TileLease
    from graspscape.shared.wire.session import zenoh_config

    session = None
    while session is None:  # as a real worker does: retry until the coordinator lets it in
        try:
            session = zenoh.open(zenoh_config(mode="client", connect=[endpoint],
                                              connect_timeout_ms=10_000))
        except zenoh.ZError:
            with tally.lock:
                tally.connect_failures += 1
            if stop.wait(1.0):
                return
    with tally.lock:
        tally.connected += 1
    token = session.liveliness().declare_token(keys.alive_key(worker_id))
    request = encode(LeaseRequest(worker_id=worker_id, session_key=_session_key(worker_id),
                                  host="fleet", capacity=1))
    idle = 0.5
    try:
        while not stop.is_set():
            start = time.perf_counter()
            tiles = []
            for reply in session.get(keys.LEASE_QUERY, payload=request, timeout=60.0,
                                     consolidation=zenoh.ConsolidationMode.NONE):
                if reply.ok is not None:
                    message = decode_as(reply.ok.payload.to_bytes(), TileLease)
                    if isinstance(message, TileLease):
                        tiles.append(message)
            lease_ms = (time.perf_counter() - start) * 1000
            with tally.lock:
                tally.lease_ms.append(lease_ms)
                tally.empty_leases += not tiles
            if not tiles:
                stop.wait(idle)
                idle = min(idle * 2, 5.0)
                continue
            idle = 0.5
            for tile in tiles:
                payload, n = _batch_payload(template, worker_id, tile)
                if stop.wait(pose_s * n):
                    return  # told to stop: the lease runs out and the tile goes round again
                start = time.perf_counter()
                ack = None
                for _attempt in range(5):  # as a real worker: sent again until acknowledged
                    for reply in session.get(keys.results_key(tile.tile_id, tile.lease_epoch),
                                             payload=payload, timeout=60.0,
                                             consolidation=zenoh.ConsolidationMode.NONE):
                        message = (decode_as(reply.ok.payload.to_bytes(), Ack)
                                   if reply.ok is not None
                                   else decode_reply_error(reply.err.payload.to_bytes()))
                        if isinstance(message, Ack):
                            ack = message
                    if ack is not None:
                        break
                    with tally.lock:
                        tally.resent += 1
                ack_ms = (time.perf_counter() - start) * 1000
                with tally.lock:
                    tally.ack_ms.append(ack_ms)
                    tally.tiles += 1
                    tally.poses_sent += n
                    if ack is None:
                        tally.refused += 1
                    else:
                        tally.inserted += ack.inserted
                        tally.duplicates += ack.duplicates
                        tally.missing += len(ack.missing)
    finally:
        token.undeclare()
        session.close()


def fleet_main(endpoint: str, count: int, first: int, pose_s: float, out: Path) -> None:
    """One OS process of the fleet: `count` workers until SIGTERM, then the tally to `out`."""
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    tally, template = Tally(), _result_template()
    threads = [threading.Thread(target=simulated_worker, daemon=True,
                                args=(endpoint, f"fleet-{first + i}", pose_s, stop, tally,
                                      template))
               for i in range(count)]
    for t in threads:
        t.start()
        time.sleep(0.01)  # not a thousand handshakes in the same millisecond
    stop.wait()
    for t in threads:
        t.join(timeout=30)
    out.write_text(json.dumps(tally.as_dict()))


if __name__ == "__main__":
    endpoint, count, first, pose_s, out = sys.argv[1:6]
    fleet_main(endpoint, int(count), int(first), float(pose_s), Path(out))
