"""The coordinator's state: every mutable cache and background thread of the coordinator, in
one object that `create_app` makes and its lifespan closes.

What it owns, by attribute (each cache bounded; `Bounded` is the one LRU type they share):

- `specs`: parsed exploration specs (mapspace/specs.py);
- `meshes`, `symmetries`, `orbits`: objects' prepared meshes, their detected symmetries and
  lattice orbits (objects/geometry.py, exploration/object_symmetry.py);
- `cmaes_searches`, `ppo_searches`: the replayed strategies' kept searches;
- `maps`, `snapshot_dir`, `keeper`: the running maps, where they are saved, the keeper of
  the manifold table (manifolds/service.py, snapshot.py, keeper.py);
- `answers`, `routes`: the map's read routes' kept answers (api/answers.py);
- `pictures`, `picture_inputs`, `panels`, `grasp_pictures` and the draw-ahead book-keeping:
  map pictures, what they are drawn from, the 3D panel's pixels, grasp pictures
  (maps/picture.py, panel.py, stored.py, web/grasp.py);
- the threads started through `start_thread`: map draw-aheads, read-aheads, the pictures'
  warm-up, the zenoh dispatcher's workers. `close()` joins them, then empties the caches and
  forgets the snapshot folder; a closed state's event streams end.

How code finds it. Routes and the app's own code reach it as `request.app.state.coordinator`
(`of(app)`). Everything called below them — the scheduler, the keeper, the manifold refresh,
the picture drawing, the dispatcher's handlers — calls `current()`: the chains are deep
(route → service → keeper → refresh → snapshot, or a SQLAlchemy commit listener starting a
draw-ahead) and passing a state through each signature would touch most of the coordinator
for no gain in clarity. `current()` is a context variable: the app sets it for each request
(`UseState`, an ASGI middleware) and for its lifespan (the sweeper, the dispatcher's start),
threads started through `start_thread` run with their state set, and Starlette's thread pool
copies the context, so two apps in one process (tests make one per database) never see each
other's state. Code that is not an app — the local runner, `graspscape map`, benchmarks, tests
that call the services directly — gets the process default (`default()`), made on first use.

Left where they are, because they are not state of an app:
- `functools.cache`/`lru_cache` over pure functions of their arguments: compiled SQL
  statements (store/workers.py, store/pose_rows.py), the code digest (manifolds/snapshot.py),
  settings from the environment (settings.py); and manifolds/behaviour.py's joint groups of a
  gripper's joint names;
- the composing package's hooks `objects/geometry._source` and `web/grasp._painter` (which
  worker code to call, set once per process by `services/local/compose.wire` before any app
  exists); the caches derived from them are keyed by the hook and live here;
- `web/events._shutting_down` (the process got uvicorn's exit signal) and
  `maps/stored._warmed` (matplotlib's first use in this process is paid): facts about the
  process.
`tests/services/coordinator/test_state.py` fails on any other module-level mutable container,
cache decorator, `global` or `threading.Thread(` outside this module.
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import TYPE_CHECKING, Any, Generic, TypeVar

from starlette.types import ASGIApp, Receive, Scope, Send

if TYPE_CHECKING:
    from graspscape.services.coordinator.exploration.strategies.replay_cache import ReplayCache
    from graspscape.services.coordinator.manifolds.keeper import Keeper
    from graspscape.services.coordinator.manifolds.live import MapCache

log = logging.getLogger("graspscape.coordinator")

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")

JOIN_DAEMON_S = 5.0  # a daemon (the dispatcher's) that has not ended by then is left to exit


class Bounded(Generic[K, V]):
    """A thread-safe mapping of the `count` most recently used entries, and, with `size`,
    of at most `max_bytes` by `size(value)`; the least recently used go first."""

    def __init__(self, count: int, *, max_bytes: int | None = None,
                 size: Callable[[V], int] | None = None) -> None:
        self.count = count
        self.max_bytes = max_bytes
        self._size = size
        self._entries: OrderedDict[K, V] = OrderedDict()
        self._held = 0
        self._lock = threading.Lock()

    def get(self, key: K) -> V | None:
        with self._lock:
            value = self._entries.get(key)
            if value is not None:
                self._entries.move_to_end(key)
            return value

    def peek(self, key: K) -> V | None:
        """The kept value, left where it stands in the order."""
        with self._lock:
            return self._entries.get(key)

    def put(self, key: K, value: V) -> V:
        """Keep `value` under `key` (replacing what was there); returns it."""
        with self._lock:
            self._put(key, value)
        return value

    def setdefault(self, key: K, value: V) -> V:
        """The kept value, else `value`, kept now (the first of two racing writers wins)."""
        with self._lock:
            found = self._entries.get(key)
            if found is not None:
                self._entries.move_to_end(key)
                return found
            self._put(key, value)
        return value

    def _put(self, key: K, value: V) -> None:  # under the lock
        old = self._entries.pop(key, None)
        if old is not None:
            self._held -= self._bytes(old)
        self._entries[key] = value
        self._held += self._bytes(value)
        while self._entries and (len(self._entries) > self.count or (
                self.max_bytes is not None and self._held > self.max_bytes)):
            self._held -= self._bytes(self._entries.popitem(last=False)[1])

    def pop(self, key: K) -> V | None:
        with self._lock:
            value = self._entries.pop(key, None)
            if value is not None:
                self._held -= self._bytes(value)
            return value

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()
            self._held = 0

    def values(self) -> list[V]:
        with self._lock:
            return list(self._entries.values())

    def __contains__(self, key: object) -> bool:
        with self._lock:
            return key in self._entries

    def __len__(self) -> int:
        with self._lock:
            return len(self._entries)

    def _bytes(self, value: V) -> int:
        return 0 if self._size is None else self._size(value)


class CoordinatorState:
    """The caches and background threads of one coordinator (an app, or the process default)."""

    def __init__(self, snapshot_dir: Path | None = None) -> None:
        from graspscape.services.coordinator.exploration.strategies.replay_cache import (
            ReplayCache,
        )
        from graspscape.services.coordinator.manifolds.live import MapCache

        self.snapshot_dir = snapshot_dir
        self.closed = threading.Event()
        self.specs: Bounded[Hashable, Any] = Bounded(256)
        self.meshes: Bounded[Hashable, Any] = Bounded(16)
        self.symmetries: Bounded[int, tuple[Any, list[Any]]] = Bounded(64)
        self.orbits: Bounded[Hashable, Any] = Bounded(64)
        self.cmaes_searches: ReplayCache[Any] = ReplayCache()
        self.ppo_searches: ReplayCache[Any] = ReplayCache()
        self.maps: MapCache = MapCache()
        # Bodies by count and bytes: a `/best?limit=100` answer is a few hundred kB.
        self.answers: Bounded[Hashable, bytes] = Bounded(512, max_bytes=32 * 2**20, size=len)
        self.routes: Bounded[Hashable, Any] = Bounded(
            512, max_bytes=32 * 2**20, size=lambda kept: len(kept.body))
        self.route_hits = 0  # answers the fast path served (tests)
        self.pictures: Bounded[Hashable, tuple[bytes, int, int]] = Bounded(16)
        self.picture_inputs: Bounded[Hashable, Any] = Bounded(2)  # 1M poses: ~60 MB each
        self.panels: Bounded[Hashable, Any] = Bounded(8)  # ~1.6 MB each
        self.panel_stats = {"drawn": 0, "reused": 0}
        self.grasp_pictures: Bounded[Hashable, bytes] = Bounded(64)
        # Under maps/picture.py's and maps/stored.py's locks: pictures being drawn, versions
        # being read, read-aheads and draw-aheads in flight and their pacing.
        self.drawing: dict[Hashable, threading.Lock] = {}
        self.reading: dict[Hashable, threading.Lock] = {}
        self.reading_ahead: dict[Hashable, threading.Thread] = {}
        self.drawing_ahead: dict[tuple[str, int], threading.Thread] = {}
        self.draw_again: set[tuple[str, int]] = set()
        self.last_running_draw: dict[tuple[str, int], float] = {}
        self.draw_seconds: dict[tuple[str, int], float] = {}
        self._keeper: Keeper | None = None
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()

    @property
    def keeper(self) -> Keeper:
        """The keeper of the manifold table (made on first use: it imports the map's code)."""
        with self._lock:
            if self._keeper is None:
                from graspscape.services.coordinator.manifolds.keeper import Keeper

                self._keeper = Keeper()
            return self._keeper

    def start_thread(self, target: Callable[..., object], *, name: str,
                     args: tuple[Any, ...] = (), daemon: bool = False) -> threading.Thread:
        """Start `target(*args)` in a thread that `close` joins, with this state current."""
        def run() -> None:
            token = _current.set(self)
            try:
                target(*args)
            finally:
                _current.reset(token)

        thread = threading.Thread(target=run, name=name, daemon=daemon)
        with self._lock:
            self._threads = [t for t in self._threads if t.is_alive()]
            self._threads.append(thread)
        thread.start()
        return thread

    def threads(self) -> list[threading.Thread]:
        """The threads started through this state that are still running."""
        with self._lock:
            return [t for t in self._threads if t.is_alive()]

    def close(self) -> None:
        """Join the threads (a daemon for JOIN_DAEMON_S at most: the dispatcher's, stopped
        before), then empty every cache and forget the snapshot folder."""
        self.closed.set()
        for thread in self.threads():
            if thread is not threading.current_thread():
                thread.join(JOIN_DAEMON_S if thread.daemon else None)
                if thread.is_alive():
                    log.warning("thread %s still running at the coordinator's close",
                                thread.name)
        for cache in (self.specs, self.meshes, self.symmetries, self.orbits, self.answers,
                      self.routes, self.pictures, self.picture_inputs, self.panels,
                      self.grasp_pictures, self.cmaes_searches, self.ppo_searches, self.maps):
            cache.clear()
        for book in (self.drawing, self.reading, self.reading_ahead, self.drawing_ahead,
                     self.draw_again, self.last_running_draw, self.draw_seconds):
            book.clear()
        self.snapshot_dir = None

    def cached(self) -> int:
        """How many entries the caches hold (0 after `close`)."""
        return sum(len(c) for c in (
            self.specs, self.meshes, self.symmetries, self.orbits, self.answers, self.routes,
            self.pictures, self.picture_inputs, self.panels, self.grasp_pictures,
            self.cmaes_searches, self.ppo_searches, self.maps))


_current: ContextVar[CoordinatorState | None] = ContextVar("graspscape_state", default=None)
_default: CoordinatorState | None = None
_default_lock = threading.Lock()


def default() -> CoordinatorState:
    """The process's state, for code that runs without an app (local runner, CLI, benchmarks)."""
    global _default
    with _default_lock:
        if _default is None:
            _default = CoordinatorState()
        return _default


def current() -> CoordinatorState:
    """The state of the app serving this request or thread, else the process default."""
    state = _current.get()
    return state if state is not None else default()


@contextmanager
def using(state: CoordinatorState) -> Iterator[None]:
    """`state` current inside the block (the app's lifespan; tests)."""
    token = _current.set(state)
    try:
        yield
    finally:
        _current.reset(token)


def of(app: Any) -> CoordinatorState:
    """The app's state (`create_app` puts it on `app.state.coordinator`)."""
    state: CoordinatorState = app.state.coordinator
    return state


class UseState:
    """ASGI middleware: the app's state current while it answers (see the module docstring)."""

    def __init__(self, app: ASGIApp, state: CoordinatorState) -> None:
        self.app = app
        self.state = state

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        token = _current.set(self.state)
        try:
            await self.app(scope, receive, send)
        finally:
            _current.reset(token)
