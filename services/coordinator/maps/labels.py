"""Manifold labels on the cut that never overlap: a greedy placement of text boxes.

Each region of the cut asks for its label with candidate spots (its own pixels, nearest its
centroid first). Regions are served largest first: a label goes to the first candidate whose
box, centred there, is inside the axes and clear of every box placed before (the μs contour
labels included); a region whose own pixels have no room gets its label on a spiral around
its anchor, with a leader line back to it. Pure geometry on boxes in display units, so the
placement is tested without drawing; `place_on_axes` applies it to a laid-out figure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

Box = tuple[float, float, float, float]  # x0, y0, x1, y1
CANDIDATES = 40  # spots tried inside a region before going around it
_SPIRAL_TURNS = 24
_SPIRAL_ANGLES = 12
_GAP = 3.0  # display units kept free between two labels (a leader's label has a pad)


@dataclass(frozen=True)
class LabelRequest:
    size: tuple[float, float]  # the text's width and height
    candidates: tuple[tuple[float, float], ...]  # spots inside the region, best first
    anchor: tuple[float, float]  # where a leader line points to (the first candidate)


@dataclass(frozen=True)
class Placement:
    centre: tuple[float, float]
    box: Box
    leader: bool  # placed off its region: a line joins it to the anchor


def box_at(centre: tuple[float, float], size: tuple[float, float]) -> Box:
    (x, y), (w, h) = centre, size
    return (x - w / 2, y - h / 2, x + w / 2, y + h / 2)


def overlap(a: Box, b: Box, gap: float = 0.0) -> bool:
    return (a[0] < b[2] + gap and b[0] < a[2] + gap
            and a[1] < b[3] + gap and b[1] < a[3] + gap)


def _inside(box: Box, bounds: Box) -> bool:
    return (box[0] >= bounds[0] and box[1] >= bounds[1] and box[2] <= bounds[2]
            and box[3] <= bounds[3])


def _spiral(anchor: tuple[float, float], size: tuple[float, float]):
    step = max(size) * 0.6
    for turn in range(1, _SPIRAL_TURNS + 1):
        for k in range(_SPIRAL_ANGLES):
            angle = 2 * math.pi * (k + 0.5 * (turn % 2)) / _SPIRAL_ANGLES
            yield (anchor[0] + turn * step * math.cos(angle),
                   anchor[1] + turn * step * math.sin(angle))


def place(requests: list[LabelRequest], bounds: Box,
          obstacles: list[Box] | None = None) -> list[Placement | None]:
    """One placement per request, in the requests' order (serve them in priority order);
    None where no spot inside `bounds` is free (a picture too crowded for the label)."""
    taken = list(obstacles or [])
    out: list[Placement | None] = []
    for request in requests:
        found = None
        for leader, spots in ((False, request.candidates),
                              (True, _spiral(request.anchor, request.size))):
            for spot in spots:
                box = box_at(spot, request.size)
                if _inside(box, bounds) and not any(overlap(box, t, _GAP) for t in taken):
                    found = Placement(spot, box, leader)
                    break
            if found is not None:
                break
        if found is not None:
            taken.append(found.box)
        out.append(found)
    return out


def candidates(xs: Any, ys: Any, n: int = CANDIDATES) -> list[tuple[float, float]]:
    """Up to n spots of a region's pixels (arrays of data coordinates), the one nearest the
    region's centroid first (a ring's centroid lies outside it), then evenly among the
    rest by that distance."""
    import numpy as np

    d = (xs - xs.mean()) ** 2 + (ys - ys.mean()) ** 2
    order = np.argsort(d, kind="stable")
    if len(order) > n:
        order = order[np.linspace(0, len(order) - 1, n).astype(int)]
    return [(float(xs[k]), float(ys[k])) for k in order]


def place_on_axes(ax: Any, texts: list[tuple[Any, list[tuple[float, float]]]],
                  fixed: list[Any] = (), dots: list[tuple[float, float]] = (),
                  dot_pt: float = 6.0) -> list[Box]:
    """Move each (text, its candidate spots in data coordinates) of a laid-out axes to its
    placement; `fixed`: texts that stay where they are and are avoided (the contour labels);
    `dots`: markers of `dot_pt` points drawn over the labels (the local maxima), avoided too.
    A text with no free spot is removed. Returns the boxes placed, in display units."""
    ax.apply_aspect()  # an equal-aspect axes takes its final box when drawn: take it now
    renderer = ax.figure.canvas.get_renderer()
    to_display, to_data = ax.transData.transform, ax.transData.inverted().transform
    requests = []
    for text, spots in texts:
        extent = text.get_window_extent(renderer)
        shown = [tuple(to_display(s)) for s in spots]
        requests.append(LabelRequest((extent.width, extent.height), tuple(shown), shown[0]))
    frame = ax.get_window_extent(renderer)
    obstacles = [tuple(t.get_window_extent(renderer).extents) for t in fixed
                 if t.get_visible() and t.get_text()]
    side = dot_pt * ax.figure.dpi / 72
    obstacles += [box_at(tuple(to_display(d)), (side, side)) for d in dots]
    boxes = []
    for (text, _), request, placement in zip(texts, requests,
                                              place(requests, tuple(frame.extents), obstacles),
                                              strict=True):
        if placement is None:
            text.remove()
            continue
        x, y = to_data(placement.centre)
        text.set_position((x, y))
        if placement.leader:
            ax0, ay0 = to_data(request.anchor)
            ax.plot([ax0, x], [ay0, y], color="0.15", linewidth=0.7, zorder=4.5)
            text.set_bbox({"boxstyle": "round,pad=0.1", "facecolor": "white", "alpha": 0.75,
                           "edgecolor": "none"})
        boxes.append(placement.box)
    return boxes
