"""The cut's manifold labels never overlap: each other, or the μs contour labels. A crowded
synthetic map (a patchwork of small manifolds round a handle-like ring, where the labels at
the regions' centres pile up) is laid out as the picture is drawn, and the drawn boxes are
measured; the placement itself is checked on boxes alone."""

from __future__ import annotations

import math
from itertools import combinations

import matplotlib.pyplot as plt
import numpy as np
import pytest
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds.summary import ManifoldSummary, PoseBrief
from graspscape.services.coordinator.maps import render
from graspscape.services.coordinator.maps.labels import (
    LabelRequest,
    box_at,
    overlap,
    place,
    place_on_axes,
)
from graspscape.services.coordinator.maps.points import ROBUST_CODES, MapPoints
from graspscape.shared.specs.exploration import PoseGridSpec

N_MANIFOLDS = 20


def _crowded_map():  # type: ignore[no-untyped-def]
    import trimesh

    mesh = trimesh.creation.annulus(r_min=0.02, r_max=0.05, height=0.03)
    lattice = Lattice(PoseGridSpec(dtheta=math.radians(15), r_min=0.0, r_max=0.02, dr=0.01), 1)
    pts = sorted(
        (K, J, i, 0) for K, J in lattice.cells(1) for i in range((lattice.n_r << 1) + 1))
    ring, az, ri, att = (np.array(c) for c in zip(*pts, strict=True))
    n = len(pts)
    phi = np.array([lattice.pose(Point(*p)).phi for p in pts])
    # One large manifold, and on one side a patchwork of small ones by direction and r.
    label = np.where(phi < 1.6, 1 + ((np.floor(phi / 0.1) + 3 * ri) % (N_MANIFOLDS - 1)), 0)
    mu = 0.3 + 0.2 * np.cos(phi) + 0.01 * ri
    points = MapPoints(ring, az, ri, att, ri * lattice.dr(1), mu, np.ones(n, dtype=bool),
                       label.astype(np.int64), np.full(n, ROBUST_CODES["robust"]))
    brief = PoseBrief(key="0", theta=math.pi / 2, phi=0.0, r=0.0, roll=0.0, pitch=0.0, yaw=0.0,
                      mu_s=0.4, effort_max_nm=1.0)
    # Local maxima in the plane, every few directions (each drawn where its manifold is).
    maxima = [brief.model_copy(update={"key": str(k), "phi": k * math.pi / 12, "r": 0.005})
              for k in range(0, 24, 2)]
    manifolds = [ManifoldSummary(
        label=k, name=chr(65 + k), description="", digits=[], pose_count=1,
        evaluated_count=1, volume_cm3=1.0, mu_s_min=0.2, mu_s_mean=0.3, mu_s_max=0.4,
        mu_s_std=0.0, best=brief, local_maxima=maxima) for k in range(N_MANIFOLDS)]
    return mesh, lattice, points, manifolds


def _boxes(texts) -> list[tuple[float, float, float, float]]:  # type: ignore[no-untyped-def]
    renderer = texts[0].figure.canvas.get_renderer()
    return [tuple(t.get_window_extent(renderer).extents) for t in texts]


def test_the_labels_of_a_crowded_cut_do_not_overlap(monkeypatch: pytest.MonkeyPatch) -> None:
    mesh, lattice, points, manifolds = _crowded_map()
    field = render.cut_field(lattice, points, mesh, cut="horizontal")
    at_centres = []  # each label's box at its region's centre, where it was drawn before
    drawn_dots: list = []  # the local maxima's dots, drawn over the labels

    def placing(ax, texts, fixed=(), dots=(), dot_pt=6.0):  # type: ignore[no-untyped-def]
        renderer = ax.figure.canvas.get_renderer()
        ax.apply_aspect()
        for text, spots in texts:
            extent = text.get_window_extent(renderer)
            centre = tuple(ax.transData.transform(spots[0]))
            at_centres.append(box_at(centre, (extent.width, extent.height)))
        drawn_dots.extend(box_at(tuple(ax.transData.transform(d)), (6 * ax.figure.dpi / 72,) * 2)
                          for d in dots)
        return place_on_axes(ax, texts, fixed, dots, dot_pt)

    monkeypatch.setattr(render, "place_on_axes", placing)
    with render._drawing:
        fig = render.compose(field, lattice, points, manifolds, mesh, cut="horizontal",
                             phi0=0.0, attitude=0)
        try:
            fig.canvas.draw()  # measured as drawn, not as planned
            ax = fig.axes[0]
            labels = [t for t in ax.texts if t.get_gid() == "manifold-label"]
            contour = [t for t in ax.texts if t.get_gid() != "manifold-label" and t.get_text()]
            boxes, others = _boxes(labels), _boxes(contour) if contour else []
            frame = ax.get_window_extent(fig.canvas.get_renderer()).extents
            # What the crowding would have done: every label at its region's centre.
            regions = {int(v) for v in np.unique(field["labels"][np.isfinite(field["labels"])])
                       if v >= 0 and (field["labels"] == v).sum() > 3}
        finally:
            plt.close(fig)
    assert len(labels) == len(regions) >= 15  # every region with room for a label has one
    assert sum(overlap(a, b) for a, b in combinations(at_centres, 2)) >= 10  # it is crowded
    for a, b in combinations(boxes, 2):
        assert not overlap(a, b), (a, b)
    assert len(drawn_dots) >= 5
    for a in boxes:
        assert not any(overlap(a, b) for b in others + drawn_dots)
        assert frame[0] <= a[0] and a[2] <= frame[2] and frame[1] <= a[1] and a[3] <= frame[3]


def test_crowded_requests_are_placed_apart_with_leaders_when_their_regions_are_full() -> None:
    size = (20.0, 14.0)
    # Ten labels asking for the same few spots: the first gets its region, others go round.
    same = tuple((100.0 + dx, 100.0) for dx in (0.0, 3.0, 6.0))
    requests = [LabelRequest(size, same, same[0]) for _ in range(10)]
    obstacle = box_at((100.0, 130.0), (30.0, 10.0))
    placed = place(requests, (0.0, 0.0, 300.0, 300.0), [obstacle])
    assert all(p is not None for p in placed)
    assert not placed[0].leader and all(p.leader for p in placed[1:])
    for a, b in combinations([p.box for p in placed] + [obstacle], 2):
        assert not overlap(a, b)
    # A frame with no room left: the label is left out, never put on top of another.
    tight = place(requests[:3], (90.0, 93.0, 110.0, 107.0))
    assert tight[0] is not None and tight[1:] == [None, None]
