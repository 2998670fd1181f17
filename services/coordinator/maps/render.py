"""The behavioral map as a picture (matplotlib, Agg): a planar cut and a 3D view.

The cut is a plane through the centre of mass: horizontal (z = 0) or vertical (containing z,
at azimuth φ0). Every pixel is a position of the gripper's reference point (the palm centre)
in that plane: its direction u from the centre of mass gives (θ, φ), its distance d gives
r = d − ρ_surface(u). A pixel with r in [r_min, r_max] takes the label of the nearest known
pose of the chosen attitude (in direction and r) and a μs interpolated (inverse distance)
among the nearby known poses of that label. Drawn like the paper's Fig. 2: manifolds coloured
and lettered, the non-viable area hatched, μs level sets inside manifolds, local maxima as
yellow dots (those within one coarse step of the plane), the object's outline in the plane.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping
from typing import Any, Literal

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.grouping import (
    FALLBACK_RADIUS,
    label_name,
    surface_radii,
)
from graspscape.services.coordinator.manifolds.summary import ManifoldMap
from matplotlib.collections import LineCollection
from matplotlib.colors import ListedColormap
from scipy.spatial import cKDTree

Cut = Literal["horizontal", "vertical"]
PIXELS = 260
NEAREST = 6
LEGEND_ENTRIES = 8
_COLOURS = plt.get_cmap("tab10").colors


def _plane_basis(cut: Cut, phi0: float) -> tuple[np.ndarray, np.ndarray]:
    if cut == "horizontal":
        return np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    return np.array([math.cos(phi0), math.sin(phi0), 0.0]), np.array([0.0, 0.0, 1.0])


def _embed(dirs: np.ndarray, r: np.ndarray, lattice: Lattice) -> np.ndarray:
    scale = lattice.dtheta(0) / lattice.grid.dr if lattice.grid.dr > 0 else 0.0
    return np.column_stack([dirs, (r - lattice.grid.r_min) * scale])


def cut_field(
    lattice: Lattice,
    samples: Mapping[Point, StoredPose],
    label_of: Mapping[Point, int],
    mesh: Any | None,
    *,
    cut: Cut = "horizontal",
    phi0: float = 0.0,
    attitude: int = 0,
    pixels: int = PIXELS,
) -> dict[str, Any]:
    """Label and μs per pixel of the cut (NaN outside the explored shell)."""
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
    dirs = (np.outer(np.cos(ang.ravel()), e1) + np.outer(np.sin(ang.ravel()), e2))
    labels = np.full(X.shape, np.nan)
    mu = np.full(X.shape, np.nan)
    known = sorted(p for p in samples if p.attitude == attitude)
    if known and inside.any():
        kd = np.array([lattice.direction(p) for p in known])
        kr = np.array([samples[p].r for p in known])
        tree = cKDTree(_embed(kd, kr, lattice))
        idx = np.flatnonzero(inside.ravel())
        q = _embed(dirs[idx], r.ravel()[idx], lattice)
        k = min(NEAREST, len(known))
        dist, nn = tree.query(q, k=k)
        dist, nn = dist.reshape(len(idx), k), nn.reshape(len(idx), k)
        klabel = np.array([label_of.get(p, -1) for p in known])
        kmu = np.array([samples[p].mu_s for p in known])
        first = klabel[nn[:, 0]]
        same = klabel[nn] == first[:, None]
        w = same / np.maximum(dist, 1e-9)
        m = (w * kmu[nn]).sum(axis=1) / w.sum(axis=1)
        labels.ravel()[idx] = first
        mu.ravel()[idx] = np.where(first >= 0, m, np.nan)
    return {"X": X, "Y": Y, "labels": labels, "mu": mu, "extent": extent, "e1": e1, "e2": e2,
            "inside": inside}


def _section(mesh: Any | None, e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """Segments (n, 2, 2) of the object's outline in the cut plane."""
    if mesh is None:
        return np.zeros((0, 2, 2))
    import trimesh

    segments = trimesh.intersections.mesh_plane(mesh, np.cross(e1, e2), [0.0, 0.0, 0.0])
    return np.stack([segments @ e1, segments @ e2], axis=-1) if len(segments) else np.zeros(
        (0, 2, 2))


def _draw_cut(ax: Any, field: dict[str, Any], mmap: ManifoldMap, lattice: Lattice,
              samples: Mapping[Point, StoredPose], mesh: Any | None, title: str) -> None:
    X, Y, labels, mu = field["X"], field["Y"], field["labels"], field["mu"]
    e1, e2 = field["e1"], field["e2"]
    n = max(1, len(mmap.manifolds))
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
            ax.clabel(cs, fmt="%.2f", fontsize=6)
    outline = _section(mesh, e1, e2)
    if len(outline):
        ax.add_collection(LineCollection(outline, colors="0.2", linewidths=1.6, zorder=4))
    for label in range(n):
        mask = labels == label
        if mask.sum() > 3:
            # At the region's pixel nearest its centroid (a ring's centroid lies outside it).
            xs_, ys_ = X[mask], Y[mask]
            k = int(np.argmin((xs_ - xs_.mean()) ** 2 + (ys_ - ys_.mean()) ** 2))
            ax.text(float(xs_[k]), float(ys_[k]), f"${label_name(label)}$",
                    fontsize=13, ha="center", va="center", zorder=5, weight="bold")
    normal = np.cross(e1, e2)
    band = lattice.dtheta(0)
    for m in mmap.manifolds:
        for pm in m.local_maxima:
            u = np.array([math.sin(pm.theta) * math.cos(pm.phi),
                          math.sin(pm.theta) * math.sin(pm.phi), math.cos(pm.theta)])
            if abs(math.asin(max(-1.0, min(1.0, float(u @ normal))))) > band:
                continue
            rho = float(surface_radii(mesh, u[None, :], FALLBACK_RADIUS)[0])
            pos = (rho + pm.r) * u
            ax.plot(pos @ e1, pos @ e2, "o", color="yellow", markeredgecolor="k",
                    markersize=6, zorder=6)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("m")


def _draw_3d(ax: Any, lattice: Lattice, samples: Mapping[Point, StoredPose],
             label_of: Mapping[Point, int], mesh: Any | None) -> None:
    pts = sorted(p for p in samples if samples[p].viable)
    if pts:
        dirs = np.array([lattice.direction(p) for p in pts])
        rho = surface_radii(mesh, dirs, FALLBACK_RADIUS)
        pos = dirs * (rho + np.array([samples[p].r for p in pts]))[:, None]
        colours = [_COLOURS[label_of.get(p, 0) % 10] for p in pts]
        ax.scatter(pos[:, 0], pos[:, 1], pos[:, 2], c=colours, s=6, depthshade=False,
                   rasterized=True)
    if mesh is not None and len(mesh.faces) <= 20000:
        v = mesh.vertices
        ax.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=mesh.faces, color="0.6",
                        alpha=0.25, linewidth=0, rasterized=True)
    ax.set_title("viable reference-point positions (all attitudes)", fontsize=9)


def render_map(
    lattice: Lattice,
    samples: Mapping[Point, StoredPose],
    label_of: Mapping[Point, int],
    mmap: ManifoldMap,
    mesh: Any | None,
    *,
    cut: Cut = "horizontal",
    phi0: float = 0.0,
    attitude: int = 0,
    fmt: Literal["png", "svg"] = "png",
    title: str = "",
    pixels: int = PIXELS,
) -> bytes:
    field = cut_field(lattice, samples, label_of, mesh, cut=cut, phi0=phi0,
                      attitude=attitude, pixels=pixels)
    fig = plt.figure(figsize=(12, 5.6))
    ax = fig.add_subplot(1, 2, 1)
    roll = lattice.attitudes[attitude][0]
    where = "z = 0" if cut == "horizontal" else f"vertical plane at φ = {math.degrees(phi0):.0f}°"
    _draw_cut(ax, field, mmap, lattice, samples, mesh,
              f"{title} {where}, roll {math.degrees(roll):.0f}°".strip())
    ax3 = fig.add_subplot(1, 2, 2, projection="3d")
    _draw_3d(ax3, lattice, samples, label_of, mesh)
    shown = mmap.manifolds[:LEGEND_ENTRIES]
    handles = [plt.Rectangle((0, 0), 1, 1, color=_COLOURS[m.label % 10], alpha=0.6) for m in shown]
    names = [f"{m.name}: {m.pose_count} poses, {m.volume_cm3:.0f} cm³, mean μs {m.mu_s_mean:.2f}"
             for m in shown]
    if len(mmap.manifolds) > len(shown):
        rest = mmap.manifolds[len(shown):]
        handles.append(plt.Rectangle((0, 0), 1, 1, color="white"))
        names.append(f"+{len(rest)} smaller ({sum(m.volume_cm3 for m in rest):.0f} cm³)")
    if handles:
        fig.legend(handles, names, loc="lower center", ncol=min(4, len(names)), fontsize=8)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=110)
    plt.close(fig)
    return buf.getvalue()
