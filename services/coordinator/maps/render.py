"""The behavioral map as a picture (matplotlib, Agg): a planar cut and a 3D view.

The cut is a plane through the centre of mass: horizontal (z = 0) or vertical (containing z,
at azimuth φ0). Every pixel is a position of the gripper's reference point (the palm centre)
in that plane: its direction u from the centre of mass gives (θ, φ), its distance d gives
r = d − ρ_surface(u). A pixel with r in [r_min, r_max] takes the label of the nearest known
pose of the chosen attitude (in direction and r) and a μs interpolated (inverse distance)
among the nearby known poses of that label. Drawn like the paper's Fig. 2: manifolds coloured
and lettered, the non-viable area hatched, μs level sets inside manifolds, local maxima as
yellow dots, the object's outline in the plane. The robust map marks where the picture can be
trusted: a pixel takes the robust label of its nearest known pose (manifolds/robust.py), and
fragile pixels are stippled, uncertain ones washed grey. A local maximum is drawn only where it
lies in the cut (`maxima_in_cut`): of the cut's attitude, its direction within half a finest
step of the plane, placed where the cut draws that direction and r (so never inside the
object's outline or a handle's hole), and only on a pixel of its own manifold.
A cut may be narrowed to one r level (`r_level`, a level of the finest lattice): only the band
of pixels within half a finest r step of it is drawn, and only the maxima at that level.
The 3D view shows the viable reference-point positions coloured by manifold (thinned beyond
SCATTER_MAX markers). The poses come as arrays (`maps.points`) with their stored labels.
"""

from __future__ import annotations

import io
import math
import threading
from collections.abc import Hashable
from typing import Any, Literal

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from graspscape.services.coordinator.exploration.lattice import Lattice
from graspscape.services.coordinator.manifolds.grouping import (
    FALLBACK_RADIUS,
    label_name,
    surface_radii,
)
from graspscape.services.coordinator.manifolds.summary import ManifoldSummary
from graspscape.services.coordinator.maps import derived
from graspscape.services.coordinator.maps.labels import candidates, place_on_axes
from graspscape.services.coordinator.maps.panel import reuse_panel
from graspscape.services.coordinator.maps.points import ROBUST_CODES, MapPoints
from graspscape.services.coordinator.maps.table import Table, table_in_3d, table_in_cut
from matplotlib.collections import LineCollection
from matplotlib.colors import ListedColormap

Cut = Literal["horizontal", "vertical"]
PIXELS = 260
NEAREST = 6
LEGEND_ENTRIES = 8
_COLOURS = plt.get_cmap("tab10").colors
SCATTER_MAX = derived.SCATTER_MAX  # markers in the 3D view (`_scattered`)
_scattered = derived.scattered


def _plane_basis(cut: Cut, phi0: float) -> tuple[np.ndarray, np.ndarray]:
    if cut == "horizontal":
        return np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    return np.array([math.cos(phi0), math.sin(phi0), 0.0]), np.array([0.0, 0.0, 1.0])


def cut_field(
    lattice: Lattice,
    points: MapPoints,
    mesh: Any | None,
    *,
    cut: Cut = "horizontal",
    phi0: float = 0.0,
    attitude: int = 0,
    pixels: int = PIXELS,
    r_level: float | None = None,
) -> dict[str, Any]:
    """Label and μs per pixel of the cut (NaN outside the explored shell, or outside the band
    of `r_level` where one is given)."""
    e1, e2 = _plane_basis(cut, phi0)
    psi = np.linspace(0, 2 * math.pi, 721)[:-1]
    ring_dirs = np.outer(np.cos(psi), e1) + np.outer(np.sin(psi), e2)
    rho_ring = surface_radii(mesh, ring_dirs, FALLBACK_RADIUS)
    extent = float(rho_ring.max()) + lattice.grid.r_max + 0.01
    xs = np.linspace(-extent, extent, pixels)
    X, Y = np.meshgrid(xs, xs)
    d = np.hypot(X, Y)
    ang = np.mod(np.arctan2(Y, X), 2 * math.pi)
    rho = np.interp(ang.ravel(), np.append(psi, 2 * math.pi), np.append(rho_ring, rho_ring[0]))
    rho = rho.reshape(X.shape)
    r = d - rho
    half = lattice.dr(lattice.depth) / 2
    inside = (r >= lattice.grid.r_min - half) & (r <= lattice.grid.r_max + half)
    if r_level is not None:
        inside &= np.abs(r - r_level) <= half
    dirs = (np.outer(np.cos(ang.ravel()), e1) + np.outer(np.sin(ang.ravel()), e2))
    labels = np.full(X.shape, np.nan)
    mu = np.full(X.shape, np.nan)
    robust = np.full(X.shape, -1, dtype=np.int64)
    known, tree = derived.known(points, lattice, attitude)
    if tree is not None and inside.any():
        idx = np.flatnonzero(inside.ravel())
        q = derived.embed(dirs[idx], r.ravel()[idx], lattice)
        k = min(NEAREST, len(known))
        # Each query on its own (exact whatever the split), in parallel: ~0.3 s at 1M poses.
        dist, nn = tree.query(q, k=k, workers=-1)
        dist, nn = dist.reshape(len(idx), k), nn.reshape(len(idx), k)
        klabel, kmu = known.label, known.mu_s
        first = klabel[nn[:, 0]]
        same = klabel[nn] == first[:, None]
        w = same / np.maximum(dist, 1e-9)
        m = (w * kmu[nn]).sum(axis=1) / w.sum(axis=1)
        labels.ravel()[idx] = first
        mu.ravel()[idx] = np.where(first >= 0, m, np.nan)
        if known.robust is not None:
            robust.ravel()[idx] = known.robust[nn[:, 0]]
    return {"X": X, "Y": Y, "labels": labels, "mu": mu, "extent": extent, "e1": e1, "e2": e2,
            "inside": inside, "robust": robust, "psi": psi, "rho_ring": rho_ring,
            "attitude": attitude, "r_level": r_level}


def maxima_in_cut(field: dict[str, Any], manifolds: list[ManifoldSummary],
                  lattice: Lattice) -> list[tuple[float, float, int]]:
    """(x, y, label) in the plane of the local maxima that lie in the cut: of the cut's
    attitude, direction within half a finest angular step of the plane (the plane passes
    through its cell), drawn at the in-plane direction and r as the cut draws them — the
    surface radius there is the outermost along that direction in the plane, so the dot is
    outside the object's outline and any hole of it — and kept only on a pixel of its own
    manifold inside the explored shell."""
    X, labels, inside = field["X"], field["labels"], field["inside"]
    e1, e2 = field["e1"], field["e2"]
    normal = np.cross(e1, e2)
    band = lattice.dtheta(lattice.depth) / 2 + 1e-9
    r_band = lattice.dr(lattice.depth) / 2 + 1e-9
    roll0, pitch0, yaw0 = lattice.attitudes[field["attitude"]]
    psi, rho_ring = field["psi"], field["rho_ring"]
    xs = X[0]
    step = float(xs[1] - xs[0]) if len(xs) > 1 else 1.0
    out = []
    for m in manifolds:
        for pm in m.local_maxima:
            if (abs(math.remainder(pm.roll - roll0, 2 * math.pi)) > 1e-6
                    or abs(pm.pitch - pitch0) > 1e-6 or abs(pm.yaw - yaw0) > 1e-6):
                continue
            u = np.array([math.sin(pm.theta) * math.cos(pm.phi),
                          math.sin(pm.theta) * math.sin(pm.phi), math.cos(pm.theta)])
            if abs(math.asin(max(-1.0, min(1.0, float(u @ normal))))) > band:
                continue
            if field.get("r_level") is not None and abs(pm.r - field["r_level"]) > r_band:
                continue
            a, b = float(u @ e1), float(u @ e2)
            if math.hypot(a, b) < 1e-12:
                continue
            ang = math.atan2(b, a) % (2 * math.pi)
            rho = float(np.interp(ang, np.append(psi, 2 * math.pi),
                                  np.append(rho_ring, rho_ring[0])))
            d = rho + pm.r
            x, y = d * math.cos(ang), d * math.sin(ang)
            j = round(float(x - xs[0]) / step)
            i = round(float(y - xs[0]) / step)
            if not (0 <= i < X.shape[0] and 0 <= j < X.shape[1]):
                continue
            if inside[i, j] and labels[i, j] == m.label:
                out.append((x, y, m.label))
    return out


def _section(mesh: Any | None, e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """Segments (n, 2, 2) of the object's outline in the cut plane."""
    if mesh is None:
        return np.zeros((0, 2, 2))
    import trimesh

    segments = trimesh.intersections.mesh_plane(mesh, np.cross(e1, e2), [0.0, 0.0, 0.0])
    return np.stack([segments @ e1, segments @ e2], axis=-1) if len(segments) else np.zeros(
        (0, 2, 2))


def _draw_cut(ax: Any, field: dict[str, Any], manifolds: list[ManifoldSummary],
              lattice: Lattice, mesh: Any | None, title: str
              ) -> tuple[list[Any], list[Any], list[tuple[float, float]]]:
    """Draws the cut; returns its manifold labels with their candidate spots, to be placed
    once the figure is laid out (maps/labels.py), and the contour labels and local maxima's
    dots they avoid."""
    X, Y, labels, mu = field["X"], field["Y"], field["labels"], field["mu"]
    e1, e2 = field["e1"], field["e2"]
    n = max(1, len(manifolds))
    contour_labels: list[Any] = []
    cmap = ListedColormap([_COLOURS[i % 10] for i in range(n)])
    shown = np.ma.masked_invalid(np.where(labels >= 0, labels, np.nan))
    # Raster inside the SVG too: a vector cell per pixel would make a 10 MB file.
    ax.pcolormesh(X, Y, shown, cmap=cmap, vmin=-0.5, vmax=n - 0.5, alpha=0.45, shading="auto",
                  rasterized=True)
    non = np.where(labels == -1, 1.0, np.nan)
    if np.isfinite(non).any():
        ax.contourf(X, Y, np.ma.masked_invalid(non), levels=[0.5, 1.5], colors="none",
                    hatches=["///"])
        ax.contour(X, Y, np.nan_to_num(non, nan=0.0), levels=[0.5], colors="grey",
                   linewidths=0.5, linestyles="dashed")
    if np.isfinite(mu).sum() > 10:
        finite = mu[np.isfinite(mu)]
        if finite.max() - finite.min() > 1e-3:
            levels = np.linspace(finite.min(), finite.max(), 7)[1:-1]
            cs = ax.contour(X, Y, np.ma.masked_invalid(mu), levels=levels, colors="k",
                            linewidths=0.6)
            contour_labels = ax.clabel(cs, fmt="%.2f", fontsize=6)
    robust = field.get("robust")
    if robust is not None:
        shell = np.isfinite(labels)
        uncertain = np.where(shell & (robust == ROBUST_CODES["uncertain"]), 1.0, np.nan)
        fragile = np.where(shell & (robust == ROBUST_CODES["fragile"]), 1.0, np.nan)
        if np.isfinite(uncertain).any():
            ax.contourf(X, Y, np.ma.masked_invalid(uncertain), levels=[0.5, 1.5],
                        colors=["0.55"], alpha=0.45, zorder=2)
        if np.isfinite(fragile).any():
            # A sparse grey stipple: on a fractal map most of the cut is fragile, and the
            # manifolds' colours and the μs contours must stay readable under it.
            dots = ax.contourf(X, Y, np.ma.masked_invalid(fragile), levels=[0.5, 1.5],
                               colors="none", hatches=["."], zorder=2)
            dots.set_edgecolor("0.35")
            dots.set_linewidth(0.0)
    outline = _section(mesh, e1, e2)
    if len(outline):
        ax.add_collection(LineCollection(outline, colors="0.2", linewidths=1.6, zorder=4))
    texts = []
    sizes = [(int((labels == label).sum()), label) for label in range(n)]
    for count, label in sorted(sizes, key=lambda s: (-s[0], s[1])):  # larger regions first
        if count > 3:
            mask = labels == label
            spots = candidates(X[mask], Y[mask])
            text = ax.text(*spots[0], f"${label_name(label)}$", fontsize=13, ha="center",
                           va="center", zorder=5, weight="bold", gid="manifold-label")
            texts.append((text, spots))
    dots = [(x, y) for x, y, _ in maxima_in_cut(field, manifolds, lattice)]
    for x, y in dots:
        ax.plot(x, y, "o", color="yellow", markeredgecolor="k", markersize=MAXIMUM_PT, zorder=6)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("m")
    return texts, contour_labels, dots


def _draw_3d(ax: Any, lattice: Lattice, points: MapPoints, mesh: Any | None) -> None:
    pos, colours = derived.markers(lattice, points, mesh, _COLOURS)
    if len(pos):
        ax.scatter(pos[:, 0], pos[:, 1], pos[:, 2], c=colours, s=6, depthshade=False,
                   rasterized=True)
    if mesh is not None and len(mesh.faces) <= 20000:
        v = mesh.vertices
        ax.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=mesh.faces, color="0.6",
                        alpha=0.25, linewidth=0, rasterized=True)
    ax.set_title("viable reference-point positions (all attitudes)", fontsize=9)


def render_map(
    lattice: Lattice,
    points: MapPoints,
    manifolds: list[ManifoldSummary],
    mesh: Any | None,
    *,
    cut: Cut = "horizontal",
    phi0: float = 0.0,
    attitude: int = 0,
    fmt: Literal["png", "svg"] = "png",
    title: str = "",
    pixels: int = PIXELS,
    r_level: float | None = None,
    panel_key: Hashable | None = None,
    table: Table | None = None,
) -> bytes:
    """The picture; `panel_key`: the map version, under which a PNG's 3D view is kept and put
    back in later renders of that version where that is exact (maps/panel.py); `table`: on a
    table, drawn in both views."""
    field = cut_field(lattice, points, mesh, cut=cut, phi0=phi0,
                      attitude=attitude, pixels=pixels, r_level=r_level)
    with _drawing:
        return _figure(field, lattice, points, manifolds, mesh, cut=cut, phi0=phi0,
                       attitude=attitude, fmt=fmt, title=title, r_level=r_level,
                       panel_key=panel_key, table=table)


MAXIMUM_PT = 6  # a local maximum's dot, points across

# One figure at a time per process: pyplot's figure registry and mathtext's parser are not
# thread-safe (two pictures drawn at once in the server's threads can fail to parse a label).
_drawing = threading.Lock()


def _figure(field: dict[str, Any], lattice: Lattice, points: MapPoints,
            manifolds: list[ManifoldSummary], mesh: Any | None, *, cut: Cut, phi0: float,
            attitude: int, fmt: Literal["png", "svg"], title: str, r_level: float | None,
            panel_key: Hashable | None, table: Table | None = None) -> bytes:
    fig = compose(field, lattice, points, manifolds, mesh, cut=cut, phi0=phi0,
                  attitude=attitude, title=title, r_level=r_level,
                  panel_key=panel_key if fmt == "png" else None, table=table)
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=110)
    plt.close(fig)
    return buf.getvalue()


def compose(field: dict[str, Any], lattice: Lattice, points: MapPoints,
            manifolds: list[ManifoldSummary], mesh: Any | None, *, cut: Cut, phi0: float,
            attitude: int, title: str = "", r_level: float | None = None,
            panel_key: Hashable | None = None, table: Table | None = None) -> Any:
    """The laid-out figure, labels placed (call under `_drawing`; close it when done)."""
    fig = plt.figure(figsize=(12, 5.6))
    ax = fig.add_subplot(1, 2, 1)
    roll = lattice.attitudes[attitude][0]
    where = "z = 0" if cut == "horizontal" else f"vertical plane at φ = {math.degrees(phi0):.0f}°"
    if r_level is not None:
        where += f", r = {r_level * 1000:g} mm"
    texts, contour_labels, dots = _draw_cut(
        ax, field, manifolds, lattice, mesh,
        f"{title} {where}, roll {math.degrees(roll):.0f}°".strip())
    ax3 = fig.add_subplot(1, 2, 2, projection="3d")
    _draw_3d(ax3, lattice, points, mesh)
    if table is not None:
        table_in_cut(ax, field, table)
        table_in_3d(ax3, table, float(np.abs(field["X"]).max()))
    if panel_key is not None:
        reuse_panel(ax, ax3, panel_key)
    large = [m for m in manifolds if m.large]
    dust = [m for m in manifolds if not m.large]
    shown = large[:LEGEND_ENTRIES]
    handles = [plt.Rectangle((0, 0), 1, 1, color=_COLOURS[m.label % 10], alpha=0.6) for m in shown]
    names = [f"{m.name}: {m.pose_count} poses, {m.volume_cm3:.0f} cm³, mean μs {m.mu_s_mean:.2f}"
             for m in shown]
    if len(large) > len(shown):
        rest = large[len(shown):]
        handles.append(plt.Rectangle((0, 0), 1, 1, color="white"))
        names.append(f"+{len(rest)} smaller ({sum(m.volume_cm3 for m in rest):.0f} cm³)")
    if dust:
        handles.append(plt.Rectangle((0, 0), 1, 1, color="white"))
        names.append(f"dust: {len(dust)} manifolds under 1 % "
                     f"({sum(m.volume_cm3 for m in dust):.0f} cm³)")
    robust = field.get("robust")
    if robust is not None and (robust == ROBUST_CODES["fragile"]).any():
        handles.append(plt.Rectangle((0, 0), 1, 1, facecolor="white", edgecolor="0.35",
                                     hatch="..", linewidth=0.5))
        names.append("fragile (0.1 < s_δ < 0.9)")
    if robust is not None and (robust == ROBUST_CODES["uncertain"]).any():
        handles.append(plt.Rectangle((0, 0), 1, 1, color="0.55", alpha=0.45))
        names.append("uncertain (neighbours unknown)")
    if handles:
        fig.legend(handles, names, loc="lower center", ncol=min(4, len(names)), fontsize=8)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    # tight_layout leaves a placeholder layout engine behind, for which savefig first draws
    # the whole figure once without rendering (~30 % of a render); the layout is done.
    fig.set_layout_engine(None)
    ax.set_xlim(ax.get_xlim())  # the placement below must not move the view it measures in
    ax.set_ylim(ax.get_ylim())
    place_on_axes(ax, texts, contour_labels, dots, MAXIMUM_PT)
    return fig


def warm_up() -> None:
    """Draw a small made-up map once: a process's first picture costs ~0.2 s of CPU more than
    the next (fonts, mathtext, the 3D axes' first use), which a first read of a map after a
    restart would pay otherwise. The coordinator runs it in a background thread at start."""
    from graspscape.services.coordinator.exploration.lattice import Point
    from graspscape.services.coordinator.manifolds.summary import PoseBrief
    from graspscape.shared.specs.exploration import PoseGridSpec

    lattice = Lattice(PoseGridSpec(dtheta=math.radians(45), r_min=0.0, r_max=0.02, dr=0.01), 1)
    pts = sorted((K, J, i, 0) for K, J in lattice.cells(1) for i in range(lattice.n_r + 1))
    ring, az, ri, att = (np.array(c) for c in zip(*pts, strict=True))
    phi = np.array([lattice.pose(Point(*p)).phi for p in pts])
    label = (phi >= math.pi).astype(np.int64)
    robust = np.arange(len(pts)) % len(ROBUST_CODES)
    points = MapPoints(ring, az, ri, att, ri * lattice.dr(1), 0.3 + 0.1 * np.cos(phi),
                       np.ones(len(pts), dtype=bool), label, robust)
    brief = PoseBrief(key="0", theta=math.pi / 2, phi=0.0, r=0.0, roll=0.0, pitch=0.0, yaw=0.0,
                      mu_s=0.4, effort_max_nm=1.0)
    manifolds = [ManifoldSummary(
        label=k, name="AB"[k], description="", digits=[], pose_count=1, evaluated_count=1,
        volume_cm3=1.0, mu_s_min=0.2, mu_s_mean=0.3, mu_s_max=0.4, mu_s_std=0.0, best=brief,
        local_maxima=[brief]) for k in (0, 1)]
    render_map(lattice, points, manifolds, None, title="warm-up")
