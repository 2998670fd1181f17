"""What an on-read picture derives from its points is the same as before, only cheaper (issue
21: map.png ≤ 1 s at 1M poses): directions without a Pose per direction, one-key sorts in
place of row sorts, viability/manifold/robust code read packed in one column, and the
directions, trees and 3D markers kept with a version's points (maps/derived.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.exploration.samples import lattice_of
from graspscape.services.coordinator.exploration.specs import spec_of
from graspscape.services.coordinator.maps import derived, picture, points, render, stored
from graspscape.services.coordinator.maps.points import (
    ROBUST_CODES,
    MapPoints,
    _point_order,
    stored_points,
)
from graspscape.services.coordinator.state import current
from graspscape.services.coordinator.store.models import ExplorationRow, ManifoldRow, PoseRow
from graspscape.shared.specs.exploration import PoseGridSpec
from graspscape.shared.specs.pose import Pose
from sqlalchemy import select, update

from tests.services.coordinator.maps.test_picture_reads import _grid


def _points(n: int, seed: int) -> MapPoints:
    rng = np.random.default_rng(seed)
    ints = [rng.integers(0, k, n) for k in (40, 90, 7, 4)]
    return MapPoints(*ints, rng.random(n), rng.random(n), rng.random(n) < 0.7,
                     rng.integers(-1, 3, n), rng.integers(-1, 4, n))


def test_directions_are_the_lattices_own_bit_for_bit() -> None:
    lattice = Lattice(PoseGridSpec(dtheta=math.radians(7), r_min=0.0, r_max=0.02, dr=0.01), 2)
    pts = sorted({Point(K, J, 0, 0) for K, J in lattice.cells(lattice.depth)})
    assert len(pts) > 1000  # poles, every ring, azimuths of every ring size
    got = MapPoints(*(np.array(c) for c in zip(*pts, strict=True)), np.zeros(len(pts)),
                    np.zeros(len(pts)), np.ones(len(pts), dtype=bool),
                    np.zeros(len(pts), dtype=np.int64)).directions(lattice)
    assert np.array_equal(got, np.array([lattice.direction(p) for p in pts]))


def test_the_one_key_sorts_are_the_row_sorts_they_replace() -> None:
    pts = _points(60_000, 1)  # duplicates of (ring, azimuth, r index, attitude): stable order
    assert np.array_equal(_point_order(pts), np.lexsort(
        (pts.attitude, pts.r_index, pts.azimuth, pts.ring)))
    # The 3D view's thinning as it was: unique rows of a 4-column array, first occurrences.
    code = np.stack([pts.ring, pts.azimuth, pts.r_index, pts.label], axis=1)
    _, first = np.unique(code, axis=0, return_index=True)
    first = np.sort(first)
    step = -(-len(first) // derived.SCATTER_MAX)
    assert step > 1 and np.array_equal(derived.scattered_index(pts), first[::step])


def test_a_versions_points_keep_what_the_pictures_derive_from_them() -> None:
    lattice = Lattice(PoseGridSpec(dtheta=math.radians(30), r_min=0.0, r_max=0.02, dr=0.01), 1)
    pts = sorted((K, J, i, 0) for K, J in lattice.cells(1) for i in range(lattice.n_r + 1))
    ring, az, ri, att = (np.array(c) for c in zip(*pts, strict=True))
    n = len(pts)

    def fresh() -> MapPoints:
        return MapPoints(ring, az, ri, att, ri * lattice.dr(1), 0.3 + 0.01 * (az % 7),
                         np.ones(n, dtype=bool), (az > 3).astype(np.int64), az % 4)

    kept = fresh()
    first = render.cut_field(lattice, kept, None, cut="vertical", pixels=60)
    tree = kept.memo[("known", lattice, 0)][1]
    second = render.cut_field(lattice, kept, None, cut="vertical", phi0=1.0, pixels=60)
    assert kept.memo[("known", lattice, 0)][1] is tree  # built once for both cuts
    # The same field as from points that kept nothing.
    for got, cut in ((first, {}), (second, {"phi0": 1.0})):
        new = render.cut_field(lattice, fresh(), None, cut="vertical", pixels=60, **cut)
        for name in ("labels", "mu", "robust"):
            assert np.array_equal(got[name], new[name], equal_nan=name != "robust"), name
    assert kept.take(slice(None)).memo == {}  # a subset keeps nothing of the whole's


def test_what_a_picture_derived_comes_back_with_the_stored_points_as_the_same_values() -> None:
    """Directions and the 3D view's markers stored with the points (maps/derived.packed) are
    put back as the values deriving them again gives: a cold cut draws the same picture."""
    from tests.services.coordinator.manifolds.test_picture import _ring_map

    mesh, lattice, pts, _summary = _ring_map()
    data = points.points_bytes(pts, derived.packed(pts, lattice, mesh))
    back, extra = points.unpacked(data)
    derived.unpack(back, lattice, extra)
    fresh = points.points_from_bytes(data)
    assert {k[0] for k in back.memo} == {"directions", "marker positions"}
    assert np.array_equal(derived.directions(back, lattice), fresh.directions(lattice))
    got = derived.markers(lattice, back, mesh, render._COLOURS)
    want = derived.markers(lattice, fresh, mesh, render._COLOURS)
    assert np.array_equal(got[0], want[0]) and got[1] == want[1] and len(got[0]) > 100
    # Put back, not derived again: moved positions stored come back moved.
    moved = points.points_from_bytes(data)
    derived.unpack(moved, lattice, {**extra, "marker_pos": extra["marker_pos"] + 1.0})
    assert np.array_equal(derived.markers(lattice, moved, mesh, render._COLOURS)[0],
                          want[0] + 1.0)
    # Another version's arrays (other points) are not used.
    other = pts.take(slice(0, len(pts) // 2))
    derived.unpack(other, lattice, extra)
    assert other.memo == {}
    unsorted = pts.take(np.arange(len(pts))[::-1])
    assert derived.packed(unsorted, lattice, mesh) == {}


@pytest.mark.parametrize("db_url", ["sqlite", "postgresql"], indirect=True)
def test_the_packed_column_gives_each_poses_viability_manifold_and_robust_label(
        sessions, named_object) -> None:
    eid = _grid(sessions, named_object("sphere"), tiles=4)
    with sessions() as s:
        ids = s.scalars(select(PoseRow.id).where(PoseRow.exploration_id == eid)
                        .order_by(PoseRow.id)).all()
        manifolds = [ManifoldRow(exploration_id=eid, label=k) for k in (0, 1)]
        s.add_all(manifolds)
        s.flush()
        label_of = {None: -1, manifolds[0].id: 0, manifolds[1].id: 1}
        names = [*ROBUST_CODES, None]
        for k, pid in enumerate(ids):  # every combination of the three
            s.execute(update(PoseRow).where(PoseRow.id == pid).values(
                robust_label=names[k % 5], viable=k % 2 == 0,
                manifold_id=[None, manifolds[0].id, manifolds[1].id][k // 10 % 3]))
        s.commit()
        lattice = lattice_of(spec_of(s.get(ExplorationRow, eid)))
        got = stored_points(s, eid, lattice)
        rows = s.execute(select(PoseRow.theta, PoseRow.phi, PoseRow.r, PoseRow.roll,
                                PoseRow.pitch, PoseRow.yaw, PoseRow.viable,
                                PoseRow.manifold_id, PoseRow.robust_label)
                         .where(PoseRow.exploration_id == eid)).all()
    want = {}
    for *coords, viable, mid, robust in rows:
        p = lattice.point(Pose(**dict(zip(("theta", "phi", "r", "roll", "pitch", "yaw"),
                                          coords, strict=True))))
        want[(p.ring, p.azimuth, p.r_index, p.attitude)] = (
            viable, label_of[mid], ROBUST_CODES.get(robust, -1))
    assert len(got) == len(want) == len(rows) >= 30
    assert len(set(want.values())) == 30
    for i in range(len(got)):
        key = (int(got.ring[i]), int(got.azimuth[i]), int(got.r_index[i]),
               int(got.attitude[i]))
        assert (bool(got.viable[i]), int(got.label[i]), int(got.robust[i])) == want[key]


@pytest.mark.slow  # two renders
@pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)
def test_a_stored_default_picture_served_reads_the_other_cuts_inputs_ahead(
        sessions, named_object, monkeypatch) -> None:
    eid = _grid(sessions, named_object("sphere"))
    with sessions() as s:
        stored.store_default(s, eid)
        s.commit()
    current().pictures.clear()
    current().picture_inputs.clear()  # another process, or a restart: nothing read yet
    reads = []  # the version's points read: from the poses, or stored with the picture
    read, load = points.stored_points, stored.stored_points_at
    monkeypatch.setattr(points, "stored_points", lambda *a, **k: reads.append(1) or read(*a, **k))

    def counted_load(*args, **kwargs):  # type: ignore[no-untyped-def]
        found = load(*args, **kwargs)
        if found is not None:
            reads.append(1)
        return found

    monkeypatch.setattr(stored, "stored_points_at", counted_load)
    with sessions() as s:
        picture.picture_bytes(s, eid, "png", title=stored.default_title(eid))
        assert reads == [] or current().reading_ahead  # the stored picture: read in the background
        picture.wait_read_ahead()
        assert reads == [1]
        (kept, _), = current().picture_inputs.values()
        assert {k[0] for k in kept.memo} == {"directions", "known", "markers", "marker positions"}
        picture.picture_bytes(s, eid, "png", cut="vertical")
        assert reads == [1]  # the cut drew from what was read ahead
