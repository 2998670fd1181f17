"""The default map picture of a finished map, rendered ahead and stored (migration 0014).

Drawing a map reads every stored pose and renders with matplotlib: 2.4 s at 10k poses, 6 s at
100k and 36 s at 1M on a loaded 2-core machine (benchmarks/results/query.json), while the
issue's target for `map.png` is 1 s. A finished map no longer changes, so its default picture
(`GET …/map.png` without parameters) is rendered once, in a background thread, after the
commit that notes its manifold table final (`draw_finished_maps_ahead`: a listener on
`explorations.manifolds_final`, which the final refresh and the strategies set), and stored in
`map_pictures` with the map version it was drawn at. `picture_bytes` serves that row when the
version still matches, in any coordinator process, also after a restart. Pictures with other
parameters, and those of running explorations (whose version moves with every ingested
batch), are drawn on read and kept in the coordinator's memory (maps/picture.py). The
background threads are started through the coordinator's state, which joins them at its close
(state.py).

A running map's default picture is drawn ahead too, after the commit of a manifold refresh
(a listener on `explorations.manifolds_poses_done`) and stored the same way: a read between
that refresh and the next ingested batch (the version moves with `poses_done`) is a row read.
Refreshes come every 1,000 poses at scale, so a running map is drawn ahead at most once per
RUNNING_DRAW_INTERVAL_S, and no more often than keeps its draws under RUNNING_DRAW_SHARE of
the time (a draw costs ~1 s of CPU at 100k poses, ~15 s at 1M, taken from the ingest's
process), never refreshes the table itself (`ensure=False`: a batch stored since is the next
read's), and a request made while a draw is in flight is drawn after it (the final one too).

The version's points are stored beside the picture (migration 0015, `stored_points_at`): a
process that has not read that version loads them (~0.05 s at 1M poses) for its first cut
instead of reading every pose (~2.3 s), with the directions and 3D markers the picture
derived from them (maps/derived.packed: a cold first cut 10-26 % faster at 1M).

The row is written after the drawing, in a short transaction: on SQLite a transaction's first
write holds the database's write lock until its commit, and a draw at 1M poses takes seconds
in which every other writer would wait (benchmarks/results/draw_ahead_lock.json).

Maps under PRERENDER_MIN_POSES are not drawn ahead: they render in well under a second, and
the tests' many small explorations would each start a render.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Any

from graspscape.services.coordinator.exploration.lattice import Lattice
from graspscape.services.coordinator.maps.points import MapPoints
from graspscape.services.coordinator.state import CoordinatorState, current
from graspscape.services.coordinator.store.models import ExplorationRow, MapPictureRow
from sqlalchemy import delete, event, select
from sqlalchemy.orm import Session, object_session

log = logging.getLogger("graspscape.coordinator.maps")

PRERENDER_MIN_POSES = 2_000
RUNNING_DRAW_INTERVAL_S = 30.0
# And no more often than keeps a running map's draws under this share of the coordinator's
# time: at 1M poses a draw reads a million rows (~15 s), every 30 s would be half a core.
RUNNING_DRAW_SHARE = 0.1
# The state's draw-ahead book (state.py): `drawing_ahead` (the threads in flight),
# `draw_again` (asked for while its draw was in flight), `last_running_draw` (monotonic start
# of a running map's last one), `draw_seconds` (how long the last draw-ahead took).
_lock = threading.Lock()


def default_title(exploration_id: int) -> str:
    """The title the map.png route draws (the default picture's)."""
    return f"exploration {exploration_id}"


def version_text(row: ExplorationRow) -> str:
    """What a picture depends on: the exploration (its creation), its stored poses and the
    manifold table stored for them (the refresh mark)."""
    return (f"{row.created_at.isoformat()}|{row.poses_done}|{row.manifolds_poses_done}|"
            f"{int(bool(row.manifolds_final))}")


def stored_default(session: Session, row: ExplorationRow) -> tuple[bytes, int, int] | None:
    """The stored default picture (PNG, manifolds, poses) if drawn at the row's version."""
    found = session.execute(
        select(MapPictureRow.png, MapPictureRow.manifolds, MapPictureRow.poses).where(
            MapPictureRow.exploration_id == row.id,
            MapPictureRow.version == version_text(row))).one_or_none()
    return None if found is None else (bytes(found[0]), int(found[1]), int(found[2]))


def store_default(session: Session, exploration_id: int, *, ensure: bool = True) -> None:
    """Render the default picture at the current version and store it (the caller commits).
    `ensure=False`: draw the stored table as it is (a running map's draw-ahead: a refresh is
    the reads' and the ingest's to make, not a background thread's)."""
    from graspscape.services.coordinator.exploration.samples import lattice_of
    from graspscape.services.coordinator.exploration.specs import spec_of
    from graspscape.services.coordinator.maps.derived import packed
    from graspscape.services.coordinator.maps.picture import picture_bytes, version_points
    from graspscape.services.coordinator.maps.points import points_bytes
    from graspscape.services.coordinator.objects.geometry import object_mesh

    # Drawn again, not read back (the process's memory may still hold this version's bytes:
    # then they are the picture). Drawn before the row is written: on SQLite the first write
    # takes the database's write lock to the commit, and a draw at 1M poses takes seconds in
    # which every ingest and lease of every exploration would wait (WAL: reads do not).
    data, manifolds, poses = picture_bytes(session, exploration_id, "png",
                                           title=default_title(exploration_id), ensure=ensure,
                                           use_stored=False)
    row = session.get(ExplorationRow, exploration_id)
    assert row is not None  # picture_bytes raised NotFound otherwise
    # The points beside it (just drawn from, so kept in this process, with what the picture
    # derived from them): a cut asked in a process that has not read this version loads
    # them instead of reading every pose and deriving directions and markers again.
    kept = version_points(session, exploration_id)
    points = points_bytes(kept, packed(kept, lattice_of(spec_of(row)),
                                       object_mesh(session, row.object_id)))
    session.execute(delete(MapPictureRow).where(MapPictureRow.exploration_id == exploration_id))
    session.add(MapPictureRow(exploration_id=exploration_id, version=version_text(row),
                              png=data, manifolds=manifolds, poses=poses, points=points))


def stored_points_at(session: Session, exploration_id: int, version: str,
                     lattice: Lattice | None = None) -> MapPoints | None:
    """The points stored beside the default picture, if drawn at `version`; with the map's
    `lattice`, also what the picture derived from them (maps/derived.unpack)."""
    from graspscape.services.coordinator.maps.derived import unpack
    from graspscape.services.coordinator.maps.points import unpacked

    data = session.scalar(select(MapPictureRow.points).where(
        MapPictureRow.exploration_id == exploration_id, MapPictureRow.version == version,
        MapPictureRow.points.is_not(None)))
    if data is None:
        return None
    points, extra = unpacked(bytes(data))
    if lattice is not None:
        unpack(points, lattice, extra)
    return points


def _render(bind: Any, exploration_id: int, key: tuple[str, int]) -> None:
    while True:
        start = time.monotonic()
        try:
            with Session(bind) as session:
                row = session.get(ExplorationRow, exploration_id)
                # A running map whose table is behind its poses: the next refresh draws it.
                if row is not None and (row.manifolds_final
                                        or row.manifolds_poses_done == row.poses_done) and (
                        stored_default(session, row) is None):  # asked twice, one version
                    store_default(session, exploration_id, ensure=bool(row.manifolds_final))
                    session.commit()
        except Exception:  # a background job: say so, the read renders on demand instead
            log.warning("exploration %s: the map picture was not drawn ahead", exploration_id,
                        exc_info=True)
        state = current()
        with _lock:
            state.draw_seconds[key] = time.monotonic() - start
            if key not in state.draw_again:
                state.drawing_ahead.pop(key, None)
                return
            state.draw_again.discard(key)


def prerender_after_commit(session: Session, exploration_id: int, poses: int) -> None:
    """Once `session` commits (the refresh is then visible to other sessions), draw and store
    the default picture in a background thread; one at a time per exploration (asked for
    while one is in flight: drawn again after it)."""
    if poses < PRERENDER_MIN_POSES:
        return
    bind = session.get_bind()
    key = (str(bind.url), exploration_id)

    state = current()  # the commit may come in another context: the state is the writer's

    def start(_session: Session) -> None:
        with _lock:
            if key in state.drawing_ahead:
                state.draw_again.add(key)
                return
            # Started under the lock (its end waits for it): noted before it can end.
            state.drawing_ahead[key] = state.start_thread(
                _render, args=(bind, exploration_id, key), name=f"map-picture-{exploration_id}")

    event.listen(session, "after_commit", start, once=True)


def in_flight(bind: Any, exploration_id: int) -> threading.Thread | None:
    """The thread drawing this exploration's default picture ahead, if one is."""
    with _lock:
        return current().drawing_ahead.get((str(bind.url), exploration_id))


def _final_set(target: ExplorationRow, value: object, _old: object, _initiator: object) -> None:
    if value:
        session = object_session(target)
        if session is not None:
            prerender_after_commit(session, target.id, target.poses_done or 0)


def _refreshed(target: ExplorationRow, value: object, old: object, _initiator: object) -> None:
    """A running map's refresh: drawn ahead at most once per RUNNING_DRAW_INTERVAL_S."""
    session = object_session(target)
    if (session is None or value is None or value == old or target.manifolds_final
            or (target.poses_done or 0) < PRERENDER_MIN_POSES):
        return
    key = (str(session.get_bind().url), target.id)
    now = time.monotonic()
    state = current()
    with _lock:
        wait = max(RUNNING_DRAW_INTERVAL_S, state.draw_seconds.get(key, 0.0) / RUNNING_DRAW_SHARE)
        if now - state.last_running_draw.get(key, -math.inf) < wait:
            return
        state.last_running_draw[key] = now
    prerender_after_commit(session, target.id, target.poses_done or 0)


def draw_finished_maps_ahead() -> None:
    """From now on, in this process, a map noted final (`manifolds_final` set true on its
    row: the final refresh, or a strategy noting the last refresh's table as final) has its
    default picture drawn and stored after that commit, and a running map after a refresh
    (`manifolds_poses_done` set, throttled). The coordinator's API turns this on
    (api/manifolds.py); the local runner, which draws its map itself, does not."""
    if not event.contains(ExplorationRow.manifolds_final, "set", _final_set):
        event.listen(ExplorationRow.manifolds_final, "set", _final_set)
    if not event.contains(ExplorationRow.manifolds_poses_done, "set", _refreshed):
        event.listen(ExplorationRow.manifolds_poses_done, "set", _refreshed)


def start_warm_up(state: CoordinatorState) -> threading.Thread | None:
    """Draw a first picture in the background (`render.warm_up`), through the app's state,
    whose close joins it. Not at import, and not a daemon: a process that exited while a
    daemon thread was inside matplotlib aborted ("terminate called without an active
    exception", 2 of 10 bare `pytest` collections when it was started at import). Once per
    process (matplotlib's first use is the process's): a later app starts none."""
    with _lock:
        if _warmed.is_set():
            return None
        _warmed.set()
        return state.start_thread(_warm_up, name="map-picture-warm-up")


# Set once a warm-up has started in this process: a fact about the process, not an app's state.
_warmed = threading.Event()


def _warm_up() -> None:
    from graspscape.services.coordinator.maps.render import warm_up

    try:
        warm_up()
    except Exception:  # the first read pays the first use instead
        log.warning("the map pictures' warm-up failed", exc_info=True)


def wait_prerendered(timeout: float = 120.0) -> None:
    """Wait for the pictures being drawn ahead (tests, benchmarks)."""
    with _lock:
        threads = list(current().drawing_ahead.values())
    for thread in threads:
        thread.join(timeout)
