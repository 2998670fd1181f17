"""Map pictures read the stored poses as arrays (maps.points) with the stored manifold labels:
the same points and labels the in-memory map has, lattice indices as `Lattice.point` finds
them, the 3D view thinned only for large maps, and the bytes kept per map version."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from graspscape.services.coordinator.errors import InvalidInput
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.exploration.samples import lattice_of, point_or_none
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds.service import compute_map
from graspscape.services.coordinator.maps import render
from graspscape.services.coordinator.maps.picture import picture_bytes
from graspscape.services.coordinator.maps.points import MapPoints, _lattice_indices, stored_points
from graspscape.services.coordinator.state import current
from graspscape.services.coordinator.store.queue import lease_tiles
from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec
from graspscape.shared.specs.pose import Pose

from tests.factories import oracle_result


def explore(sessions, object_id: int) -> int:  # type: ignore[no-untyped-def]
    """A small adaptive exploration (refinement included) of the oracle, through the ingest."""
    spec = ExplorationSpec(
        object_id=object_id,
        grid={"dtheta": math.radians(45), "r_min": 0.0, "r_max": 0.02, "dr": 0.01,
              "attitudes": {"rolls": 2}},
        refinement={"levels": 1, "local_search_rounds": 0},
    )
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=40, max_poses=10**6).id
        while tiles := lease_tiles(s, worker_id="w", n=8, lease_seconds=60):
            for t in tiles:
                ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                               results=[oracle_result(p) for p in t.poses()])
    return eid


def explored_and_drawn_ahead(sessions, object_id: int, monkeypatch) -> int:  # type: ignore[no-untyped-def]
    """`explore`, with the finished map's default picture drawn ahead as the coordinator's API
    has it (maps/stored.py; small maps included) and that draw done."""
    from graspscape.services.coordinator.maps import stored
    from graspscape.services.coordinator.store.models import ExplorationRow

    monkeypatch.setattr(stored, "PRERENDER_MIN_POSES", 0)
    stored.draw_finished_maps_ahead()
    eid = explore(sessions, object_id)
    stored.wait_prerendered()
    with sessions() as s:
        assert s.get(ExplorationRow, eid).manifolds_final
    return eid


@pytest.mark.slow  # seconds of physics or subprocess: the default run stays near 90 s
def test_stored_points_are_the_computed_maps_points_and_labels(sessions, named_object) -> None:
    eid = explore(sessions, named_object("sphere"))
    with sessions() as s:
        computed = compute_map(s, eid)
        got = stored_points(s, eid, computed.lattice)
        pts = sorted(computed.samples)
        assert len(pts) > 100 and len(set(computed.label_of.values())) >= 2
        assert [tuple(int(x) for x in t) for t in zip(
            got.ring, got.azimuth, got.r_index, got.attitude, strict=True)] == [
            (p.ring, p.azimuth, p.r_index, p.attitude) for p in pts]
        assert got.r.tolist() == [computed.samples[p].r for p in pts]
        assert got.mu_s.tolist() == [computed.samples[p].mu_s for p in pts]
        assert got.viable.tolist() == [computed.samples[p].viable for p in pts]
        assert got.label.tolist() == [computed.label_of.get(p, -1) for p in pts]
        assert np.allclose(got.directions(computed.lattice),
                           [computed.lattice.direction(p) for p in pts], rtol=0, atol=0)


def test_lattice_indices_are_those_of_lattice_point_on_and_off_the_lattice() -> None:
    lattice = Lattice(PoseGridSpec(dtheta=0.5, r_min=0.0, r_max=0.02, dr=0.01,
                                   attitudes={"rolls": 4, "tilts": [0.3]}), 2)
    rng = random.Random(3)
    on = [lattice.pose(p) for p in lattice.coarse_points()]
    on += [lattice.pose(lattice.point(Pose(theta=rng.uniform(0, math.pi),
                                           phi=rng.uniform(0, 2 * math.pi),
                                           r=rng.choice([0.0025, 0.0075, 0.0125]),
                                           roll=a[0], pitch=a[1], yaw=a[2])))
           for a in rng.choices(lattice.attitudes, k=300)]
    off = [Pose(theta=rng.uniform(0, math.pi), phi=rng.uniform(0, 2 * math.pi),
                r=rng.uniform(0, 0.02), roll=rng.uniform(0, 6), pitch=0.0, yaw=0.0)
           for _ in range(300)]
    off += [p.model_copy(update={"phi": p.phi + 2e-6}) for p in on[:50] if 0 < p.theta < 3]
    poses = on + off
    cols = np.array([(p.theta, p.phi, p.r, p.roll, p.pitch, p.yaw) for p in poses])
    K, J, I, att, found = _lattice_indices(lattice, cols)  # noqa: E741
    for i, pose in enumerate(poses):
        p = point_or_none(lattice, pose)
        assert bool(found[i]) == (p is not None), pose
        if p is not None:
            assert (K[i], J[i], I[i], att[i]) == (p.ring, p.azimuth, p.r_index, p.attitude)
    assert found[: len(on)].all() and not found[len(on):].any()


def test_the_3d_view_is_thinned_only_beyond_its_marker_budget() -> None:
    n = 3 * render.SCATTER_MAX
    ring = np.arange(n) // 8
    small = MapPoints(ring[:100], ring[:100] * 0, ring[:100] * 0, ring[:100] * 0,
                      np.zeros(100), np.zeros(100), np.ones(100, dtype=bool), ring[:100] % 3)
    assert render._scattered(small) is small
    big = MapPoints(ring, np.arange(n) % 8 // 2, ring * 0, np.arange(n) % 2, np.zeros(n),
                    np.zeros(n), np.ones(n, dtype=bool), ring % 3)
    thinned = render._scattered(big)
    assert render.SCATTER_MAX // 2 <= len(thinned) <= render.SCATTER_MAX
    # Sorted as before, one marker per position and label.
    assert np.all(np.diff(thinned.ring) >= 0)
    assert len({(a, b, c) for a, b, c in zip(thinned.ring, thinned.azimuth, thinned.label,
                                             strict=True)}) == len(thinned)


@pytest.mark.slow  # seconds of physics or subprocess: the default run stays near 90 s
@pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)
def test_a_picture_is_kept_per_map_version_and_checks_its_attitude(sessions,
                                                                   named_object) -> None:
    eid = explore(sessions, named_object("sphere"))
    with sessions() as s:
        first, manifolds, poses = picture_bytes(s, eid, "png")
        assert first.startswith(b"\x89PNG") and manifolds >= 2 and poses > 100
        assert picture_bytes(s, eid, "png")[0] is first  # kept
        assert picture_bytes(s, eid, "png", attitude=1)[0] != first
        with pytest.raises(InvalidInput):
            picture_bytes(s, eid, "png", attitude=2)


def _ring_map():  # type: ignore[no-untyped-def]
    """A flat ring (hole at the centre of mass) and a map of one manifold over a 30° grid
    refined once, every point known: robust, except uncertain and fragile bands."""
    import trimesh
    from graspscape.services.coordinator.manifolds.summary import ManifoldSummary, PoseBrief
    from graspscape.services.coordinator.maps.points import ROBUST_CODES

    mesh = trimesh.creation.annulus(r_min=0.02, r_max=0.05, height=0.03)
    lattice = Lattice(PoseGridSpec(dtheta=math.radians(30), r_min=0.0, r_max=0.02, dr=0.01), 1)
    pts = sorted(
        (K, J, i, 0) for K, J in lattice.cells(1) for i in range((lattice.n_r << 1) + 1))
    ring, az, ri, att = (np.array(c) for c in zip(*pts, strict=True))
    n = len(pts)
    phi = np.array([lattice.pose(Point(*p)).phi for p in pts])
    robust = np.where(phi < 1.0, ROBUST_CODES["uncertain"],
                      np.where(phi > 5.0, ROBUST_CODES["fragile"], ROBUST_CODES["robust"]))
    points = MapPoints(ring, az, ri, att, ri * lattice.dr(1), np.full(n, 0.5),
                       np.ones(n, dtype=bool), np.zeros(n, dtype=np.int64), robust)
    # A local maximum at every direction, r = 5 mm (off the surface: a point on it is neither
    # in nor out for `contains`): in the plane and off it by up to 90°.
    maxima = [PoseBrief(key=str(k), theta=lattice.theta(K), phi=lattice.pose(Point(K, J, 0, 0)).phi,
                        r=0.005, roll=0.0, pitch=0.0, yaw=0.0, mu_s=0.5, effort_max_nm=1.0)
              for k, (K, J) in enumerate(lattice.cells(1))]
    summary = ManifoldSummary(
        label=0, name="A", description="", digits=[], pose_count=n, evaluated_count=n,
        volume_cm3=1.0, mu_s_min=0.5, mu_s_mean=0.5, mu_s_max=0.5, mu_s_std=0.0,
        best=maxima[0], local_maxima=maxima)
    return mesh, lattice, points, summary


def test_local_maxima_are_drawn_only_where_they_lie_in_the_cut() -> None:
    mesh, lattice, points, summary = _ring_map()
    field = render.cut_field(lattice, points, mesh, pixels=120)
    dots = render.maxima_in_cut(field, [summary], lattice)
    # Only the equator's maxima (the plane z = 0 passes through their cells), each once.
    on_plane = [m for m in summary.local_maxima if abs(m.theta - math.pi / 2) < 1e-9]
    assert len(dots) == len(on_plane) > 8
    for x, y, label in dots:
        assert label == 0
        # Beyond the ring's outer wall by r, never inside its outline or its hole.
        assert math.hypot(x, y) == pytest.approx(0.055, abs=1e-3)
        assert not mesh.contains([[x, y, 0.0]])[0]
    # Placed as before (the 3D position projected, within one coarse step of the plane), the
    # maxima 30° off the plane land on the ring's top face, inside its outline.
    normal = np.array([0.0, 0.0, 1.0])
    old_inside = 0
    for m in summary.local_maxima:
        u = np.array([math.sin(m.theta) * math.cos(m.phi), math.sin(m.theta) * math.sin(m.phi),
                      math.cos(m.theta)])
        if 0 < abs(math.asin(float(u @ normal))) <= lattice.dtheta(0):
            rho = float(render.surface_radii(mesh, u[None, :], 0.05)[0])
            pos = (rho + m.r) * u
            old_inside += bool(mesh.contains([[pos[0], pos[1], 0.0]])[0])
    assert old_inside > 0
    # Another attitude's maxima are not this cut's.
    rolled = summary.model_copy(update={"local_maxima": [
        m.model_copy(update={"roll": 1.0}) for m in summary.local_maxima]})
    assert render.maxima_in_cut(field, [rolled], lattice) == []


def test_the_cut_carries_the_robust_labels_and_shades_them() -> None:
    from graspscape.services.coordinator.maps.points import ROBUST_CODES

    mesh, lattice, points, summary = _ring_map()
    field = render.cut_field(lattice, points, mesh, pixels=80)
    shell = np.isfinite(field["labels"])
    codes = set(np.unique(field["robust"][shell]).tolist())
    assert codes == {ROBUST_CODES["robust"], ROBUST_CODES["uncertain"], ROBUST_CODES["fragile"]}
    assert (field["robust"][~shell] == -1).all()
    # Drawn: a grey wash over the uncertain pixels and a stipple over the fragile ones.
    import matplotlib.pyplot as plt

    def drawn(f: dict) -> list:  # type: ignore[type-arg]
        fig, ax = plt.subplots()
        render._draw_cut(ax, f, [summary], lattice, None, "")
        out = [c for c in ax.collections if c.get_zorder() == 2]
        plt.close(fig)
        return out

    shades = drawn(field)
    assert len(shades) == 2 and [list(c.hatches) for c in shades] == [[None], ["."]]
    assert drawn({**field, "robust": np.zeros_like(field["robust"])}) == []


def test_the_map_routes_cut_at_one_r(client, sessions, named_object) -> None:
    """`r_mm` narrows the cut to the band of one r level of the finest lattice (10 mm steps
    here): snapped to the nearest level, refused beyond the grid's r range. One picture drawn
    (a few seconds under load): the snapped request is the kept one."""
    spec = ExplorationSpec(object_id=named_object("sphere"),
                           grid={"dtheta": math.radians(90), "r_min": 0.0, "r_max": 0.02,
                                 "dr": 0.01},
                           refinement={"levels": 0, "local_search_rounds": 0})
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=40, max_poses=10**6).id
        while tiles := lease_tiles(s, worker_id="w", n=8, lease_seconds=60):
            for t in tiles:
                ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                               results=[oracle_result(p) for p in t.poses()])
    at_10 = client.get(f"/explorations/{eid}/map.png", params={"r_mm": 10})
    assert at_10.status_code == 200, at_10.text
    assert at_10.headers["content-type"] == "image/png" and at_10.content[:4] == b"\x89PNG"
    # 13 mm is the 10 mm level: the same picture, as kept.
    assert client.get(f"/explorations/{eid}/map.png", params={"r_mm": 13}).content == \
        at_10.content
    for bad in (26, -6, 1e5):
        refused = client.get(f"/explorations/{eid}/map.svg", params={"r_mm": bad})
        assert refused.status_code == 422, refused.text
        assert "r_mm" in refused.text and "out of range" in refused.text
    # The band holds only pixels at that r, a part of the whole shell.
    with sessions() as s:
        lattice = lattice_of(spec)
        points = stored_points(s, eid, lattice)
    assert {round(float(r), 3) for r in points.r} == {0.0, 0.01, 0.02}
    full = render.cut_field(lattice, points, None, pixels=80)
    band = render.cut_field(lattice, points, None, pixels=80, r_level=0.01)
    assert band["inside"].sum() > 0 and not (band["inside"] & ~full["inside"]).any()
    assert band["inside"].sum() < full["inside"].sum() / 2
    drawn = np.isfinite(band["labels"])
    assert drawn.any() and not (drawn & ~band["inside"]).any()


@pytest.mark.slow  # two renders, seconds under load
def test_a_finished_maps_default_picture_is_drawn_ahead_and_read_from_its_row(
        sessions, named_object, monkeypatch) -> None:
    """The refresh to final draws the default picture after its commit and stores it with the
    map version (maps/stored.py); a process that has not drawn it reads the row, at that
    version only."""
    from graspscape.services.coordinator.maps import stored
    from graspscape.services.coordinator.store.models import ExplorationRow, MapPictureRow
    from sqlalchemy import select, update

    eid = explored_and_drawn_ahead(sessions, named_object("sphere"), monkeypatch)
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        kept = s.scalars(select(MapPictureRow).where(MapPictureRow.exploration_id == eid)).one()
        assert kept.png.startswith(b"\x89PNG") and kept.version == stored.version_text(row)
        png = kept.png
    current().pictures.clear()  # another process: nothing drawn in its memory

    def no_render(*_args, **_kwargs):
        raise AssertionError("drawn again")

    monkeypatch.setattr(render, "render_map", no_render)
    title = stored.default_title(eid)
    with sessions() as s:
        assert picture_bytes(s, eid, "png", title=title)[0] == png
        with pytest.raises(AssertionError, match="drawn again"):  # not the default: drawn
            picture_bytes(s, eid, "png", title=title, attitude=1)
        # A row of another version is not served.
        s.execute(update(MapPictureRow).values(version="older"))
        s.commit()
        current().pictures.clear()
        with pytest.raises(AssertionError, match="drawn again"):
            picture_bytes(s, eid, "png", title=title)
