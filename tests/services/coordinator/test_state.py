"""The coordinator's state (services/coordinator/state.py): each app has its own, its lifespan's
end leaves no thread it started running and no cache filled, and no module of the coordinator
keeps a cache or starts a thread beside it (a source scan, as tests/test_layers.py reads
imports)."""

from __future__ import annotations

import ast
import math
import threading
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator import state
from graspscape.services.coordinator.app import create_app
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.maps import stored
from graspscape.services.coordinator.settings import Settings
from graspscape.services.coordinator.store.models import MapPictureRow
from graspscape.services.coordinator.store.queue import lease_tiles
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from tests.factories import oracle_result
from tests.services.coordinator.conftest import _settings

ROOT = Path(__file__).resolve().parents[3]
COORDINATOR = ROOT / "services" / "coordinator"
GRID = {"dtheta": math.radians(45), "r_min": 0.0, "r_max": 0.02, "dr": 0.01}

# What may stay beside the state, and why (the state module's docstring says the same).
ALLOWED = {
    # the composing package's hooks: which worker code to call, set once per process
    ("objects/geometry.py", "global _source"),
    ("web/grasp.py", "global _painter"),
    # facts about the process: uvicorn's exit signal, matplotlib's first use paid
    ("web/events.py", "_shutting_down"),
    ("maps/stored.py", "_warmed"),
    # pure functions of their arguments: compiled statements, the code's digest, the
    # environment's settings, a gripper's joint groups by joint names
    ("store/workers.py", "cache _touch_statement"),
    ("store/pose_rows.py", "cache _sqlite_insert"),
    ("manifolds/snapshot.py", "cache code_version"),
    ("settings.py", "cache get_settings"),
    ("manifolds/behaviour.py", "_PLANS"),
}
# Made empty and filled at run time (a table of constants is written non-empty).
_CONTAINERS = {"dict", "list", "set", "OrderedDict", "defaultdict", "deque", "Counter",
               "WeakValueDictionary", "WeakKeyDictionary", "Event", "Bounded", "MapCache",
               "ReplayCache", "Keeper", "CoordinatorState"}
_CACHES = {"cache", "lru_cache"}


def _name(node: ast.AST) -> str:
    if isinstance(node, ast.Call):
        node = node.func
    if isinstance(node, ast.Attribute):
        return node.attr
    return node.id if isinstance(node, ast.Name) else ""


def _is_state(value: ast.AST) -> bool:
    if isinstance(value, (ast.Dict, ast.List, ast.Set)):
        return not (value.keys if isinstance(value, ast.Dict) else value.elts)
    return isinstance(value, ast.Call) and _name(value) in _CONTAINERS


def state_beside(source: str) -> set[str]:
    """What a module's source keeps or starts beside the coordinator's state: module-level
    containers made empty (and cache objects), `global`, cache decorators, threads."""
    tree = ast.parse(source)
    found: set[str] = set()
    for node in tree.body:
        targets = (node.targets if isinstance(node, ast.Assign)
                   else [node.target] if isinstance(node, ast.AnnAssign) else [])
        value = getattr(node, "value", None)
        if value is not None and _is_state(value):
            found.update(_name(t) for t in targets)
    for node in ast.walk(tree):
        if isinstance(node, ast.Global):
            found.update(f"global {n}" for n in node.names)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            found.update(f"cache {node.name}" for d in node.decorator_list
                         if _name(d) in _CACHES)
        elif isinstance(node, ast.Call) and _name(node) == "Thread":
            found.add(f"Thread at line {node.lineno}")
    return found


def test_the_scan_sees_caches_globals_and_threads() -> None:
    # The check must be able to fail: a module written like the ones it forbids is seen.
    source = ("import functools, threading\nfrom collections import OrderedDict\n"
              "TABLE = {'a': 1}\n_kept: dict[str, int] = {}\n_lru = OrderedDict()\n"
              "_stop = threading.Event()\n_on = None\n"
              "@functools.lru_cache(maxsize=4)\ndef f(x): return x\n"
              "def g():\n    global _on\n    threading.Thread(target=f).start()\n")
    assert state_beside(source) == {"_kept", "_lru", "_stop", "cache f", "global _on",
                                    "Thread at line 12"}


def test_no_module_keeps_state_beside_the_coordinators_state() -> None:
    found = set()
    for path in sorted(COORDINATOR.rglob("*.py")):
        where = path.relative_to(COORDINATOR).as_posix()
        if where != "state.py":
            found.update((where, what) for what in state_beside(path.read_text()))
    assert found - ALLOWED == set()
    assert ALLOWED - found == set()  # the list stays what is there


def _explore(client: TestClient, sessions: sessionmaker[Session], object_id: int) -> int:
    """A finished grid exploration, ingested with the app's state current (as the dispatcher
    would), so that its keeper, running map and draw-ahead are the app's."""
    eid = client.post("/explorations", json={
        "object_id": object_id, "gripper": "robotiq_3f", "grid": GRID,
        "strategy": {"name": "grid"}, "refinement": {"levels": 0}}).json()["id"]
    with state.using(state.of(client.app)), sessions() as s:
        for t in lease_tiles(s, worker_id="w", n=1000, lease_seconds=60):
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
    return eid


@pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)
def test_an_apps_end_joins_its_threads_and_empties_its_caches(
        settings: Settings, sessions: sessionmaker[Session],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(stored, "PRERENDER_MIN_POSES", 0)  # a draw-ahead thread, too
    app = create_app(settings)
    own = state.of(app)
    with TestClient(app) as client:
        object_id = client.post("/objects", data={"name": "sphere"}).json()["id"]
        eid = _explore(client, sessions, object_id)
        for path in ("best", "manifolds", "map.png?cut=vertical"):
            assert client.get(f"/explorations/{eid}/{path}").status_code == 200
        # One that runs until the state closes: its close must stop waiting on it.
        own.start_thread(own.closed.wait, name="until-closed")
        started = own.threads()
        assert own.cached() > 0 and own.snapshot_dir is not None
        assert own.answers and own.pictures and len(own.maps) and own.specs
    assert started and not any(t.is_alive() for t in started)
    with sessions() as s:  # the draw-ahead the final table started had ended before the close
        assert s.scalar(select(MapPictureRow.version).where(
            MapPictureRow.exploration_id == eid)) is not None
    assert own.threads() == [] and own.cached() == 0 and own.closed.is_set()
    assert own.snapshot_dir is None and not own.drawing_ahead
    assert not [t for t in threading.enumerate() if t in started]


@pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)
def test_two_apps_in_one_process_share_no_state(
        db_url: str, tmp_path: Path, sessions: sessionmaker[Session]) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first = create_app(_settings(db_url, tmp_path / "a"))
    second = create_app(_settings(db_url, tmp_path / "b"))
    process = len(state.default().answers)
    assert state.of(first) is not state.of(second)
    assert state.of(first).keeper is not state.of(second).keeper
    with TestClient(first) as one, TestClient(second) as two:
        object_id = one.post("/objects", data={"name": "sphere"}).json()["id"]
        eid = _explore(one, sessions, object_id)
        assert one.get(f"/explorations/{eid}/best").status_code == 200
        assert state.of(first).answers and not state.of(second).answers
        assert not state.of(second).specs
        assert two.get(f"/explorations/{eid}/best").json() == one.get(
            f"/explorations/{eid}/best").json()
        assert state.of(second).answers  # its own, computed again
        # and deeper down, in the route's thread (the parsed spec: mapspace/specs.py)
        assert state.of(second).specs
        assert len(state.default().answers) == process  # neither app's went to the process's


def test_a_bounded_cache_drops_the_least_recently_used() -> None:
    kept: state.Bounded[str, int] = state.Bounded(2)
    kept.put("a", 1)
    kept.put("b", 2)
    assert kept.peek("a") == 1  # looked at, not used: still the first out
    kept.put("c", 3)
    assert "a" not in kept and kept.get("b") == 2  # used: "c" is now the oldest
    kept.put("d", 4)
    assert "c" not in kept and kept.setdefault("b", 20) == 2 and kept.setdefault("e", 5) == 5
    assert sorted(kept.values()) == [2, 5]
    kept.clear()
    assert len(kept) == 0
