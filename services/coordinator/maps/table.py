"""The support table in the map picture: its trace in the cut and a plane in the 3D view."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

# On a table: (the table's up in the object frame, the centre of mass's height over it, m).
Table = tuple[np.ndarray, float]


def table_in_cut(ax: Any, field: dict[str, Any], table: Table) -> None:
    """The table's trace in the cut (a line, the side under it shaded), where the cut is not
    parallel to it."""
    up, height = table
    a, b = float(up @ field["e1"]), float(up @ field["e2"])
    norm = math.hypot(a, b)
    if norm < 1e-6:
        return
    X, Y = field["X"], field["Y"]
    reach = 2.0 * float(max(np.abs(X).max(), np.abs(Y).max()))
    normal = np.array([a, b]) / norm
    on = -height / norm * normal  # the nearest point of the trace to the centre of mass
    along = np.array([-normal[1], normal[0]]) * reach
    below = on - normal * reach
    ax.fill(*np.array([on - along, on + along, below + along, below - along]).T,
            color="0.45", alpha=0.35, zorder=3, linewidth=0)
    ax.plot(*np.array([on - along, on + along]).T, color="0.25", linewidth=1.4, zorder=4)
    ax.set_xlim(float(X.min()), float(X.max()))
    ax.set_ylim(float(Y.min()), float(Y.max()))


def table_in_3d(ax: Any, table: Table, size: float) -> None:
    """The table as a translucent square under the object in the 3D view."""
    up, height = table
    e1 = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    s, t = np.meshgrid([-size, size], [-size, size])
    corner = -height * up[:, None, None] + e1[:, None, None] * s + e2[:, None, None] * t
    ax.plot_surface(*corner, color="0.45", alpha=0.3, linewidth=0)
