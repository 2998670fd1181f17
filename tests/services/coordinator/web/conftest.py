"""Fixtures of the browser tests: the system Chromium driven by Playwright, skipped (saying
how to install it) where either is missing."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.services.coordinator.web.live import CHROMIUM_ARGS, ConsoleLog, chromium_executable


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    executable = chromium_executable()
    if executable is None:
        pytest.skip("no chromium: apt-get install -y chromium (or set GRASPSCAPE_CHROMIUM)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("no playwright: pip install -e '.[dev]'")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=executable, args=CHROMIUM_ARGS)
        yield b
        b.close()


# Generous: it only bounds waits for pages following a real exploration on a loaded machine.
PAGE_TIMEOUT_MS = 240_000


@pytest.fixture
def page(browser: Any) -> Iterator[tuple[Any, ConsoleLog]]:
    """A fresh browser context and page, with the page's console errors collected."""
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    p = context.new_page()
    p.set_default_timeout(PAGE_TIMEOUT_MS)
    yield p, ConsoleLog(p)
    context.close()
