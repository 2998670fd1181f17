"""A pose export whose client goes away gives its database connection back at once, on both
databases: a real uvicorn server, a real client that reads a little and closes its socket
(issue 21: abandoned streams held their connections until the export ended and exhausted the
pool)."""

from __future__ import annotations

import logging
import math
import socket
import threading
import time

import pytest
import uvicorn
from graspscape.services.coordinator.app import create_app
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds import export
from graspscape.services.coordinator.store.models import ExplorationRow
from graspscape.services.coordinator.store.queue import lease_tiles
from graspscape.shared.specs.exploration import ExplorationSpec

from tests.factories import oracle_result


def _explored(sessions, object_id: int) -> tuple[int, int]:  # type: ignore[no-untyped-def]
    """A grid exploration stored through the real ingest, its table marked current (the
    export reads the stored labels); (id, poses)."""
    spec = ExplorationSpec(object_id=object_id, gripper="robotiq_3f", strategy={"name": "grid"},
                           grid={"dtheta": math.radians(12), "r_min": 0.0, "r_max": 0.05,
                                 "dr": 0.01, "attitudes": {"rolls": 4}},
                           refinement={"levels": 0})
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=500, max_poses=10**6).id
        poses = 0
        while tiles := lease_tiles(s, worker_id="t", n=8, lease_seconds=3600):
            for tile in tiles:
                poses += ingest_results(s, tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                                        worker_id="t", results=[
                                            oracle_result(p) for p in tile.poses()]).inserted
        row = s.get(ExplorationRow, eid)
        row.manifolds_poses_done, row.manifolds_final = row.poses_done, True
        s.commit()
    return eid, poses


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_an_abandoned_export_gives_its_connection_back(settings, sessions, named_object,
                                                       monkeypatch, fmt) -> None:
    eid, poses = _explored(sessions, named_object("sphere"))
    # Pieces of 20 rows: the stream is hundreds of pieces long, far more than the socket
    # buffers hold, so the server is still streaming when the client leaves.
    monkeypatch.setattr(export, "CHUNK", 20)
    monkeypatch.setattr(export, "BLOCK_BYTES", 4096)
    app = create_app(settings)
    records: list[logging.LogRecord] = []
    handler = logging.Handler()
    handler.emit = records.append  # type: ignore[method-assign]
    logger = logging.getLogger("graspscape.coordinator.api")
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        while not server.started:
            time.sleep(0.02)
        port = server.servers[0].sockets[0].getsockname()[1]
        pool = app.state.engine.pool
        client = socket.socket()
        client.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        client.connect(("127.0.0.1", port))
        client.sendall(f"GET /explorations/{eid}/export/poses.{fmt} HTTP/1.1\r\n"
                       "Host: test\r\n\r\n".encode())
        got = b""
        while len(got) < 2048:
            got += client.recv(1024)
        assert got.startswith(b"HTTP/1.1 200")

        time.sleep(0.3)  # the server fills the socket buffers and waits on the client
        # CSV: the stream's own session, mid-export; Parquet: none (the file is written,
        # its blocks are sent from the spool).
        assert pool.checkedout() == (1 if fmt == "csv" else 0)
        client.close()

        def stopped() -> list[str]:
            return [r.getMessage() for r in records if "client went away" in r.getMessage()]

        # The log line follows the generator's close, which gives the connection back: wait
        # for both, or a fast check-in is seen before the line is written (a CI failure).
        deadline = time.monotonic() + 10
        while ((pool.checkedout() or (fmt == "csv" and not stopped()))
               and time.monotonic() < deadline):
            time.sleep(0.02)
        assert pool.checkedout() == 0
        if fmt == "csv":  # stopped, not run to its end (Parquet may be in the buffers)
            lines = stopped()
            assert len(lines) == 1, [r.getMessage() for r in records]
            sent = int(lines[0].split(" after ")[1].split(" ")[0])
            assert 0 < sent < math.ceil(poses / 20)
    finally:
        logger.removeHandler(handler)
        server.should_exit = True
        thread.join(10)
