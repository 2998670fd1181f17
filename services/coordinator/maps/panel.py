"""The 3D view's pixels, kept per map version and place, so that another cut of the same map
does not draw the 3D view again.

The right panel of a map picture (maps/render.py `_draw_3d`: up to 25,000 markers and the
object's mesh, all attitudes, every r) does not depend on the cut, φ0, r or attitude asked
for, yet drawing it costs ~40 % of a PNG's render (0.13 s at 10k poses, 0.2 s at 100k, more
with a mesh). A PNG's render here lets it draw itself once per (map version, its place in the
figure, canvas size) and keeps the pixels right of the cut's axes; later renders at the same
place put those pixels back instead of drawing it. The picture stays the same pixel for pixel
because pixels are kept and put back only where that is exact: the kept region (every column
from the panel's slot rightwards, full height) was blank before the panel drew (the figure's white
background: nothing else had drawn there) and the panel drew nothing left of it, and the
region is put back only where it is blank again at that point of the new drawing (the figure
draws the cut first, the panel next, the legend last, over both). Anything else draws as
before. SVG is not concerned (vector output).
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from typing import Any

import numpy as np
from graspscape.services.coordinator.state import current


def reuse_panel(cut_axes: Any, panel: Any, key: Hashable) -> None:
    """Make `panel` (the 3D axes) draw from kept pixels where exact; `key`: the map version
    (what the panel shows)."""
    draw = panel.draw
    state = current()  # its `panels` (~1.6 MB each at 1320 × 616 pixels), its `panel_stats`

    def kept_draw(renderer: Any) -> None:
        buf = np.asarray(renderer.buffer_rgba())
        # The panel's own column: from its slot's left edge (the cut's tick labels reach
        # past the cut's frame; the panel draws inside its slot, which the check below holds).
        box = panel.get_position(original=True)
        x0 = math.floor(box.x0 * buf.shape[1])
        if not cut_axes.bbox.x1 < x0 < buf.shape[1]:
            draw(renderer)
            return
        place = (key, buf.shape, tuple(box.bounds))
        region = buf[:, x0:]
        blank = bool((region == 255).all())
        found = state.panels.get(place) if blank else None
        if found is not None:
            state.panel_stats["reused"] += 1
            region[...] = found
            return
        left = buf[:, :x0].copy() if blank else None
        draw(renderer)
        state.panel_stats["drawn"] += 1
        if left is not None and np.array_equal(buf[:, :x0], left):
            state.panels.put(place, region.copy())

    panel.draw = kept_draw


def clear() -> None:
    current().panels.clear()
