"""A live coordinator for the client's tests: the real app under uvicorn on loopback, on each
database backend (the coordinator's `settings` and `sessions` fixtures)."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest
import uvicorn
from graspscape.services.coordinator.app import create_app
from graspscape.services.coordinator.settings import Settings

from tests.services.coordinator.conftest import _composed, _settings, named_object  # noqa: F401


@pytest.fixture
def settings(db_url: str, tmp_path) -> Settings:  # type: ignore[no-untyped-def]
    return _settings(db_url, tmp_path)


@pytest.fixture
def live_url(settings: Settings) -> Iterator[str]:
    """The base URL of a running coordinator; stopped at the end."""
    server = uvicorn.Server(uvicorn.Config(create_app(settings), host="127.0.0.1", port=0,
                                           log_level="warning"))
    started = threading.Event()
    startup = server.startup

    async def startup_then_signal(sockets=None):  # type: ignore[no-untyped-def]
        await startup(sockets)
        started.set()

    server.startup = startup_then_signal  # type: ignore[method-assign]
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    assert started.wait(30), "the server did not start"
    port = server.servers[0].sockets[0].getsockname()[1]
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(30)
