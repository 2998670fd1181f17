"""A pytest plugin (`-p _suite_timing`) for bench_test_suite.py: where a run's time goes.

Writes JSON to $GS_SUITE_TIMING_OUT at the end of the session: collection wall and CPU
seconds, the sums of the setup / call / teardown phases pytest reports, each fixture's setup
wall and CPU seconds (its own body, not its dependencies: pytest sets those up first), the
tests that started a subprocess, and the outcomes. CPU is this process's (threads included,
not its children's or the database server's).
"""

from __future__ import annotations

import collections
import json
import os
import subprocess
import time
from collections.abc import Iterator
from typing import Any

import pytest

_PHASES: collections.Counter[str] = collections.Counter()
_OUTCOMES: collections.Counter[str] = collections.Counter()
_FIXTURES: dict[str, list[float]] = collections.defaultdict(lambda: [0, 0.0, 0.0])
_COLLECTION: dict[str, float] = {}
_SUBPROCESSES: collections.Counter[str] = collections.Counter()
_CURRENT = {"test": "<collection>"}

_popen_init = subprocess.Popen.__init__


def _counting_init(self: subprocess.Popen, *args: Any, **kwargs: Any) -> None:
    _SUBPROCESSES[_CURRENT["test"]] += 1
    _popen_init(self, *args, **kwargs)


subprocess.Popen.__init__ = _counting_init  # type: ignore[method-assign]


@pytest.hookimpl(hookwrapper=True)
def pytest_collection(session: pytest.Session) -> Iterator[None]:
    wall, cpu = time.perf_counter(), time.process_time()
    yield
    _COLLECTION["wall_s"] = time.perf_counter() - wall
    _COLLECTION["cpu_s"] = time.process_time() - cpu


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    _CURRENT["test"] = item.nodeid
    yield
    _CURRENT["test"] = "<between tests>"


@pytest.hookimpl(hookwrapper=True)
def pytest_fixture_setup(fixturedef: Any, request: pytest.FixtureRequest) -> Iterator[None]:
    wall, cpu = time.perf_counter(), time.process_time()
    yield
    entry = _FIXTURES[f"{fixturedef.argname} ({fixturedef.scope})"]
    entry[0] += 1
    entry[1] += time.perf_counter() - wall
    entry[2] += time.process_time() - cpu


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    _PHASES[report.when] += report.duration
    if report.when == "call" or report.outcome != "passed":
        _OUTCOMES[report.outcome] += 1


def pytest_sessionfinish(session: pytest.Session) -> None:
    out = os.environ.get("GS_SUITE_TIMING_OUT")
    if not out:
        return
    fixtures = {name: {"count": int(n), "setup_wall_s": w, "setup_cpu_s": c}
                for name, (n, w, c) in _FIXTURES.items()}
    data = {
        "collection": _COLLECTION,
        "phases_s": dict(_PHASES),
        "outcomes": dict(_OUTCOMES),
        "fixtures": fixtures,
        "subprocesses": {k: v for k, v in _SUBPROCESSES.items()},
        "process_cpu_s": time.process_time(),
    }
    with open(out, "w") as f:
        json.dump(data, f, indent=1)
