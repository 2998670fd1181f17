"""A live coordinator for the client's tests: the real app under uvicorn on loopback, on each
database backend (the coordinator's `settings` and `sessions` fixtures)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from graspscape.services.coordinator.app import create_app
from graspscape.services.coordinator.settings import Settings

from tests.live_server import serving
from tests.services.coordinator.conftest import _composed, _settings, named_object  # noqa: F401


@pytest.fixture
def settings(db_url: str, tmp_path) -> Settings:  # type: ignore[no-untyped-def]
    return _settings(db_url, tmp_path)


@pytest.fixture
def live_url(settings: Settings) -> Iterator[str]:
    """The base URL of a running coordinator; stopped at the end."""
    with serving(create_app(settings)) as url:
        yield url
