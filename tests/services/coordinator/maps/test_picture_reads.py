"""Map pictures drawn on read (issue 21: map.png ≤ 1 s): the 3D view's pixels kept per map
version (maps/panel.py) give the previous code's picture pixel for pixel; what a picture is
drawn from is read once per map version; a running map's default picture is drawn ahead after
a refresh and served only while its version matches (maps/stored.py)."""

from __future__ import annotations

import datetime as dt
import io
import math
import threading

import numpy as np
import pytest
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds.service import ensure_manifolds
from graspscape.services.coordinator.maps import panel, picture, points, render, stored
from graspscape.services.coordinator.state import current
from graspscape.services.coordinator.store.models import ExplorationRow, MapPictureRow
from graspscape.services.coordinator.store.queue import lease_tiles
from graspscape.shared.specs.exploration import ExplorationSpec
from matplotlib.figure import Figure
from PIL import Image
from sqlalchemy import select, update

from tests.factories import oracle_result
from tests.services.coordinator.manifolds.test_picture import (
    _ring_map,
    explored_and_drawn_ahead,
)


def _pixels(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGBA"))


def _previous_drawing(monkeypatch: pytest.MonkeyPatch, *args: object, **kwargs: object) -> bytes:
    """render_map as the code before maps/panel.py drew a PNG: the 3D view drawn every time,
    and savefig's layout pass kept (tight_layout leaves a placeholder layout engine, for which
    savefig draws the whole figure once without rendering first)."""
    keep = Figure.set_layout_engine
    with monkeypatch.context() as m:
        m.setattr(Figure, "set_layout_engine",
                  lambda self, layout=None, **kw: None if layout is None else keep(
                      self, layout, **kw))
        return render.render_map(*args, **kwargs)  # type: ignore[arg-type]


@pytest.mark.slow  # eight renders: ~4 s quiet, more under load
def test_a_kept_3d_view_gives_the_previous_codes_picture_pixel_for_pixel(monkeypatch) -> None:
    mesh, lattice, pts, summary = _ring_map()
    panel.clear()
    drawn, reused = current().panel_stats["drawn"], current().panel_stats["reused"]
    # The 3D view's place moves with the cut's tick labels: these pairs share one.
    for cut, r_level in (("vertical", None), ("vertical", 0.01), ("horizontal", 0.01),
                         ("horizontal", 0.02)):
        new = render.render_map(lattice, pts, [summary], mesh, cut=cut, title="t",
                                r_level=r_level, panel_key=("ring", 1))
        old = _previous_drawing(monkeypatch, lattice, pts, [summary], mesh, cut=cut,
                                title="t", r_level=r_level)
        assert np.array_equal(_pixels(new), _pixels(old)), (cut, r_level)
    # Drawn at each of the two places, put back at the second picture of each.
    stats = current().panel_stats
    assert (stats["drawn"] - drawn, stats["reused"] - reused) == (2, 2)


def test_a_3d_view_is_neither_kept_nor_put_back_where_something_else_drew() -> None:
    """The kept region must be blank before the 3D view draws: a cut's label reaching into it
    makes the panel draw as before, and nothing is kept from that drawing."""
    panel.clear()

    def draw(spill: bool) -> None:
        fig = Figure(figsize=(6, 3))
        ax = fig.add_subplot(1, 2, 1)
        ax.plot([0, 1], [0, 1])
        if spill:
            ax.text(1.6, 0.5, "a long label into the 3D view", transform=ax.transAxes,
                    clip_on=False)
        ax3 = fig.add_subplot(1, 2, 2, projection="3d")
        ax3.scatter([0, 1], [0, 1], [0, 1])
        panel.reuse_panel(ax, ax3, "key")
        fig.savefig(io.BytesIO(), format="png", dpi=50)

    drawn, reused = current().panel_stats["drawn"], current().panel_stats["reused"]
    draw(spill=True)
    assert not current().panels and current().panel_stats["drawn"] == drawn + 1
    draw(spill=False)
    assert len(current().panels) == 1
    draw(spill=True)  # kept now, yet not put back over the label
    assert current().panel_stats["reused"] == reused and current().panel_stats["drawn"] == drawn + 3
    draw(spill=False)
    assert current().panel_stats["reused"] == reused + 1


def _grid(sessions, object_id: int, tiles: int | None = None) -> int:  # type: ignore[no-untyped-def]
    """A small grid exploration of the oracle through the ingest: every tile, or `tiles`."""
    spec = ExplorationSpec(
        object_id=object_id,
        grid={"dtheta": math.radians(45), "r_min": 0.0, "r_max": 0.02, "dr": 0.01,
              "attitudes": {"rolls": 2}},
        strategy={"name": "grid"}, refinement={"levels": 0})
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=20, max_poses=10**6).id
        _ingest(s, tiles)
    return eid


def _ingest(s, tiles: int | None) -> None:  # type: ignore[no-untyped-def]
    done = 0
    while (tiles is None or done < tiles) and (
            leased := lease_tiles(s, worker_id="w", n=1, lease_seconds=60)):
        for t in leased:
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
            done += 1


@pytest.mark.slow  # three renders
@pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)
def test_what_a_picture_is_drawn_from_is_read_once_per_map_version(
        sessions, named_object, monkeypatch) -> None:
    eid = _grid(sessions, named_object("sphere"))
    reads = []
    read = points.stored_points
    monkeypatch.setattr(points, "stored_points", lambda *a, **k: reads.append(1) or read(*a, **k))
    current().picture_inputs.clear()
    with sessions() as s:
        vertical = picture.picture_bytes(s, eid, "png", cut="vertical")
        other = picture.picture_bytes(s, eid, "png", cut="vertical", phi0_deg=60.0)
        assert vertical[0] != other[0] and vertical[1:] == other[1:]
        assert len(reads) == 1
        row = s.get(ExplorationRow, eid)
        row.updated_at += dt.timedelta(seconds=1)  # as every write to the map moves it
        s.commit()
        picture.picture_bytes(s, eid, "png", cut="vertical", phi0_deg=60.0)
        assert len(reads) == 2  # another version: read again


@pytest.mark.slow  # renders in a background thread, seconds under load
@pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)
def test_a_running_maps_default_picture_is_drawn_ahead_and_served_only_at_its_version(
        sessions, named_object, monkeypatch) -> None:
    monkeypatch.setattr(stored, "PRERENDER_MIN_POSES", 0)
    monkeypatch.setattr(stored, "RUNNING_DRAW_INTERVAL_S", 0.0)
    stored.draw_finished_maps_ahead()  # as the coordinator's API does
    eid = _grid(sessions, named_object("sphere"), tiles=3)
    title = stored.default_title(eid)
    with sessions() as s:
        # a writer's draw (the CLI's) refreshes the stale table first; a route's would not
        picture.picture_bytes(s, eid, "png", cut="vertical", ensure=True)
    stored.wait_prerendered()
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        assert not row.manifolds_final and row.manifolds_poses_done == row.poses_done
        kept = s.scalars(select(MapPictureRow).where(MapPictureRow.exploration_id == eid)).one()
        assert kept.version == stored.version_text(row)
        png, poses = kept.png, kept.poses
    current().pictures.clear()  # another process: nothing drawn in its memory
    drawn = []
    draw = render.render_map
    monkeypatch.setattr(render, "render_map", lambda *a, **k: drawn.append(1) or draw(*a, **k))
    with sessions() as s:
        assert picture.picture_bytes(s, eid, "png", title=title) == (png, kept.manifolds, poses)
        assert not drawn
        picture.wait_read_ahead()  # the other cuts' inputs, read in the background: done
        _ingest(s, 1)  # the version moves: the drawn-ahead picture is not this map's any more
        row = s.get(ExplorationRow, eid)
        s.refresh(row)
        assert row.poses_done > poses and stored.stored_default(s, row) is None
        later = picture.picture_bytes(s, eid, "png", title=title, ensure=False)
        assert later[2] > poses and drawn  # drawn at the new version, not the stored one
        # A map whose draw took long is drawn ahead less often (RUNNING_DRAW_SHARE): this
        # refresh, within 10 × that draw, is not.
        current().draw_seconds[(str(s.get_bind().url), eid)] = 1e6
        ensure_manifolds(s, eid)
        stored.wait_prerendered()
        assert s.scalars(select(MapPictureRow.version)
                         .where(MapPictureRow.exploration_id == eid)).one() == kept.version


def _same_points(a: points.MapPoints, b: points.MapPoints) -> bool:
    return all(
        (x is None and y is None) or (x is not None and y is not None and x.dtype == y.dtype
                                      and np.array_equal(x, y, equal_nan=x.dtype.kind == "f"))
        for x, y in ((getattr(a, f), getattr(b, f)) for f in points._FIELDS))


def test_packed_points_come_back_as_the_same_values_and_dtypes() -> None:
    _mesh, _lattice, pts, _summary = _ring_map()
    rng = np.random.default_rng(0)
    n = 5_000  # beyond int8 and int16 ranges too, NaN μs, no robust labels
    wide = points.MapPoints(
        rng.integers(0, 400, n), rng.integers(0, 70_000, n), rng.integers(0, 3, n),
        np.zeros(n, dtype=np.int64), rng.random(n), np.where(rng.random(n) < 0.3, np.nan, 1.0),
        rng.random(n) < 0.5, rng.integers(-1, 40_000, n))
    empty = wide.take(slice(0, 0))
    for case in (pts, wide, empty):
        back = points.points_from_bytes(points.points_bytes(case))
        assert _same_points(back, case) and len(back) == len(case)
    assert len(points.points_bytes(wide)) < 0.6 * n * 65  # the integers packed small


@pytest.mark.slow  # renders, and the draw-ahead's thread
def test_a_process_that_has_not_read_a_version_loads_the_points_stored_with_its_picture(
        sessions, named_object, monkeypatch) -> None:
    """The draw-ahead stores the version's points beside the default picture (migration
    0015): a cut asked in a process that has not read that version (a restart) draws the same
    picture from them without reading a pose; at another version they are not used."""
    from graspscape.services.coordinator.exploration.samples import lattice_of
    from graspscape.services.coordinator.exploration.specs import spec_of

    eid = explored_and_drawn_ahead(sessions, named_object("sphere"), monkeypatch)
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        kept = stored.stored_points_at(s, eid, stored.version_text(row))
        assert kept is not None
        assert _same_points(kept, points.stored_points(s, eid, lattice_of(spec_of(row))))
        expected = picture.picture_bytes(s, eid, "png", cut="vertical", phi0_deg=60.0)
    reads = []
    read = points.stored_points
    monkeypatch.setattr(points, "stored_points", lambda *a, **k: reads.append(1) or read(*a, **k))
    current().pictures.clear()  # another process: nothing drawn or read in its memory
    current().picture_inputs.clear()
    with sessions() as s:
        got = picture.picture_bytes(s, eid, "png", cut="vertical", phi0_deg=60.0)
        assert not reads and got[1:] == expected[1:]
        assert np.array_equal(_pixels(got[0]), _pixels(expected[0]))
        s.execute(update(MapPictureRow).values(version="older"))
        s.commit()
        current().pictures.clear()
        current().picture_inputs.clear()
        assert picture.picture_bytes(s, eid, "png", cut="vertical", phi0_deg=60.0)[1:] == (
            expected[1:])
        assert reads == [1]  # read from the poses: the stored points are another version's


@pytest.mark.slow  # four small renders
def test_pictures_drawn_at_once_in_the_servers_threads_all_come_out() -> None:
    """matplotlib's mathtext parser and pyplot's figures are not thread-safe: drawn at once
    without render's lock, one of four pictures fails to parse its manifold letters."""
    errors: list[Exception] = []

    def draw() -> None:
        try:
            render.warm_up()
        except Exception as exc:  # what the route would answer 500 for
            errors.append(exc)

    threads = [threading.Thread(target=draw) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors


@pytest.mark.slow  # a render
@pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)
def test_a_draw_ahead_leaves_the_database_to_other_writers_while_it_draws(
        sessions, named_object, monkeypatch, db_url) -> None:
    """On SQLite the first write of a transaction holds the database's write lock to its
    commit: the draw-ahead writes its row after drawing (seconds at 1M poses), so an ingest
    made meanwhile goes through at once instead of waiting for the draw."""
    import sqlite3

    eid = _grid(sessions, named_object("sphere"))
    draw = render.render_map
    written = []

    def draw_and_write_beside(*args, **kwargs):  # type: ignore[no-untyped-def]
        data = draw(*args, **kwargs)
        other = sqlite3.connect(db_url.removeprefix("sqlite:///"), timeout=0.2)
        try:  # another writer, mid-draw: "database is locked" after 0.2 s if it must wait
            other.execute("UPDATE explorations SET viable_count = -1 WHERE id = ?", (eid,))
            other.commit()
            written.append(1)
        finally:
            other.close()
        return data

    with sessions() as s:
        ensure_manifolds(s, eid)  # a table up to date: the draw-ahead refreshes nothing
        s.commit()
    monkeypatch.setattr(render, "render_map", draw_and_write_beside)
    with sessions() as s:
        stored.store_default(s, eid)
        s.commit()
    assert written == [1]
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        assert row.viable_count == -1 and stored.stored_default(s, row) is not None
