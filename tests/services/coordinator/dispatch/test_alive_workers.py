"""The coordinator asks who is alive (the orphan sweep after a start) with more workers than a
zenoh reply channel holds, through a router: a real router process, real sessions on loopback.

With replies collected in zenoh's default FIFO channel (bounded), the answer to a liveliness
query from a client session is pushed into that channel while the query is still being
declared, under the session's lock; with more tokens than the channel holds, the call waited
for a reader that only runs after it returns, and the network thread waited for the lock:
the coordinator's whole zenoh session hung (bench_fleet --via-router at N = 1,000, 10 s after
start). The replies are now collected by a callback, so the call returns with every token.
"""

from __future__ import annotations

import subprocess
import sys
import threading
from collections.abc import Iterator

import pytest
import zenoh
from graspscape.services.coordinator.dispatch.service import Dispatcher
from graspscape.services.coordinator.settings import Settings, ZenohSettings
from graspscape.shared.wire import keys
from graspscape.shared.wire.session import zenoh_config
from prometheus_client import CollectorRegistry
from sqlalchemy.orm import Session, sessionmaker

from tests.services.coordinator.dispatch.support import REPO, free_port, wait_for

TOKENS = 600  # well above the default channel's capacity (256)


@pytest.fixture
def router() -> Iterator[str]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    process = subprocess.Popen([sys.executable, "-m", "tests.faults.router", "--listen", endpoint],
                               cwd=REPO, stdout=subprocess.PIPE, text=True)
    assert process.stdout is not None
    process.stdout.readline()  # listening
    yield endpoint
    process.terminate()
    process.wait(10)


@pytest.mark.slow  # a router subprocess and 600 sessions' tokens: 2 s
def test_alive_workers_through_a_router_returns_every_token(
    router: str, sqlite_url: str, sqlite_sessions: sessionmaker[Session]
) -> None:
    fleet = zenoh.open(zenoh_config(mode="client", connect=[router]))
    tokens = [fleet.liveliness().declare_token(keys.alive_key(f"w{i}")) for i in range(TOKENS)]
    settings = Settings(database={"url": sqlite_url},
                        zenoh=ZenohSettings(enabled=True, mode="client", connect=[router],
                                            orphan_grace_s=3600))
    dispatcher = Dispatcher(settings, sqlite_sessions, CollectorRegistry())
    dispatcher.start()
    try:
        # Asked until the coordinator's session has learnt every token from the router (the
        # case where the query was answered in place); each ask must return, never hang.
        def ask() -> set[str] | None:
            answered: list[set[str] | None] = []
            asking = threading.Thread(
                target=lambda: answered.append(dispatcher.alive_workers()), daemon=True)
            asking.start()
            asking.join(15)
            assert answered, "alive_workers() hung"
            return answered[0]

        found = wait_for(lambda: (lambda got: got if got and len(got) == TOKENS else None)(ask()),
                         30, "every token", every=0.5)
        assert found == {f"w{i}" for i in range(TOKENS)}
        # A query cut by its timeout is no answer: half of one would send live workers'
        # leases back to the queue (the orphan sweep).
        assert dispatcher.alive_workers(timeout_s=1e-4) in (None, found)
    finally:
        dispatcher.stop()
        for token in tokens:
            token.undeclare()
        fleet.close()
