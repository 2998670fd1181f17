"""A worker process's zenoh session settings."""

from __future__ import annotations

import zenoh
from graspscape.shared.wire.session import zenoh_config
from graspscape.workers.runtime.config import WorkerConfig


def session_config(config: WorkerConfig) -> zenoh.Config:
    """A worker process's zenoh session: a client of the coordinator or router, logging in
    where the config has a password. Bounded connect timeout: the process stays responsive
    to SIGTERM while the coordinator is not up yet. Once open, zenoh reconnects by itself.

    zenoh's shared-memory transport is off: each session that uses it (on by default since
    1.x, for messages over 3 KB between processes of one host) maps a 16 MiB pool file in
    /dev/shm that a killed process never removes and that was left behind after clean exits
    too (the soak, tests/faults/soak.py: 90 MB after 3 kills of 400 tiles). A worker's
    batches are tens of kB, so copying them costs nothing next to their ingest, and remote
    workers never share memory with the coordinator anyway."""
    zenoh_cfg = zenoh_config(mode="client", connect=config.connect, connect_timeout_ms=2000,
                             exit_on_failure=True, **config.zenoh_login())
    zenoh_cfg.insert_json5("transport/shared_memory/enabled", "false")
    return zenoh_cfg
