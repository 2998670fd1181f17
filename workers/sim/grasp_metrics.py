"""Static grasp metrics μg, μf and μm (paper Sec. II, Table 1), from a grasp's contacts.

Pure functions on `Contact`s (object frame: positions relative to the object's centre of mass,
unit inward normals, friction coefficient, normal force) plus the glue `scene_metrics` that
reads the contacts of a synthesized grasp from the scene (either engine). docs/concepts/quality.md
derives each formula.

Units. A wrench is [f; τ/L]: torques are divided by a characteristic length L (the evaluator's,
by default the object's radius of gyration, the same length μs uses), so force and torque rows
weigh alike and every metric is non-dimensional and invariant to scaling the grasp (positions
and L by the same factor) and to rotating it. Contact model: point contact with Coulomb
friction (pybullet's contacts have no torsional friction), the cone linearised by `edges`
generators.

- μg (Li & Sastry 1988): the smallest singular value of the grasp matrix G (6 × 3n) built from
  unit contact frames; 0 when the contacts cannot produce some wrench direction at all (one
  contact, or a two-point pinch, which cannot resist a torque about the line between them).
- μf (Ferrari & Canny 1992): ε, the radius of the largest origin-centred ball in the grasp
  wrench space, the convex hull of the primitive wrenches of unit normal forces (L1 GWS);
  0 unless the grasp is in force closure. `gws_volume` gives the hull's 6-volume too.
- μm (after Kim et al. 2001, resistance to external perturbation, non-dimensionalised): the
  same ε computed with each contact's primitive wrenches scaled by the normal force it actually
  applies, divided by the object's weight: the magnitude of the smallest external wrench, in
  units of m·g (force) and m·g·L (torque), that the grasp's present contact forces can no
  longer balance in its worst direction. Unlike μf it grows with the closing effort.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.spatial import ConvexHull, QhullError

STANDARD_GRAVITY = 9.81
DEFAULT_EDGES = 8


@dataclass(frozen=True)
class Contact:
    position: np.ndarray  # object frame, relative to the centre of mass, m
    normal: np.ndarray  # unit, pointing into the object (direction of the pushing force)
    friction: float  # Coulomb coefficient μ
    force: float = 1.0  # normal force actually applied, N (used by μm only)


def contact_frame(normal: np.ndarray) -> np.ndarray:
    """Columns: the unit normal and two tangents (any orthonormal pair)."""
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1)
    return np.column_stack([n, t1, np.cross(n, t1)])


def _wrench_map(position: np.ndarray, length: float) -> np.ndarray:
    """6 × 3: a force at `position` → [f; (p × f)/L]."""
    x, y, z = np.asarray(position, dtype=float) / length
    cross = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.vstack([np.eye(3), cross])


def grasp_matrix(contacts: list[Contact], length: float) -> np.ndarray:
    """G (6 × 3n): contact-frame forces (normal, t1, t2) of all contacts → object wrench."""
    if not contacts:
        return np.zeros((6, 0))
    return np.hstack([_wrench_map(c.position, length) @ contact_frame(c.normal)
                      for c in contacts])


def mu_g(contacts: list[Contact], length: float) -> float:
    """Smallest singular value of G, counting the zero ones when 3n < 6."""
    g = grasp_matrix(contacts, length)
    values = np.zeros(6)
    if g.shape[1]:
        s = np.linalg.svd(g, compute_uv=False)
        values[: len(s)] = s
    return float(values.min())


def primitive_wrenches(contacts: list[Contact], length: float, edges: int = DEFAULT_EDGES,
                       scale_by_force: bool = False) -> np.ndarray:
    """The wrenches of the friction-cone edges of each contact (unit normal force, or the
    contact's own normal force with `scale_by_force`): rows of an (n·edges) × 6 array."""
    rows = []
    angles = 2.0 * np.pi * np.arange(edges) / edges
    for c in contacts:
        frame = contact_frame(c.normal)
        wrench = _wrench_map(c.position, length)
        weight = c.force if scale_by_force else 1.0
        for a in angles:
            f = frame[:, 0] + c.friction * (np.cos(a) * frame[:, 1] + np.sin(a) * frame[:, 2])
            rows.append(weight * (wrench @ f))
    return np.array(rows).reshape(-1, 6)


def _hull(wrenches: np.ndarray) -> ConvexHull | None:
    # A hull of fewer than 7 points, or one lying in a subspace (one contact, a pinch), has no
    # 6-volume: Qhull refuses it, and it contains no ball around the origin.
    if len(wrenches) < 7 or not np.isfinite(wrenches).all():
        return None
    try:
        return ConvexHull(wrenches)
    except (QhullError, ValueError):
        return None


def ferrari_canny(wrenches: np.ndarray) -> float:
    """ε: distance from the origin to the nearest facet of the hull; 0 if the origin is not
    strictly inside (no force closure)."""
    hull = _hull(wrenches)
    if hull is None:
        return 0.0
    # Facets: n·x + b ≤ 0 inside, |n| = 1, so the origin's distance to a facet is −b.
    distance = -hull.equations[:, -1]
    return float(max(distance.min(), 0.0))


def gws_volume(wrenches: np.ndarray) -> float:
    hull = _hull(wrenches)
    return 0.0 if hull is None else float(hull.volume)


def mu_f(contacts: list[Contact], length: float, edges: int = DEFAULT_EDGES) -> float:
    return ferrari_canny(primitive_wrenches(contacts, length, edges))


def mu_m(contacts: list[Contact], length: float, weight_n: float,
         edges: int = DEFAULT_EDGES) -> float:
    if weight_n <= 0.0:
        raise ValueError("μm needs a positive object weight")
    return ferrari_canny(primitive_wrenches(contacts, length, edges, scale_by_force=True)) \
        / weight_n


class LinkPoint(NamedTuple):
    """One contact point of a hand link on the object, object frame."""

    link: str
    position: np.ndarray
    normal: np.ndarray  # unit, pointing into the object
    force: float  # normal force, N
    friction: float  # the pair's combined Coulomb coefficient


def merge_by_link(points: list[LinkPoint]) -> list[Contact]:
    """One contact per link: its points → force-weighted centroid and mean normal. pybullet
    reports 1–4 manifold points per touching pair, a number set by its collision algorithm,
    not the grasp; merging keeps the metrics from counting that artefact."""
    by_link: dict[str, list[LinkPoint]] = {}
    for point in points:
        by_link.setdefault(point.link, []).append(point)
    merged = []
    for link in sorted(by_link):
        pts = by_link[link]
        forces = np.array([pt.force for pt in pts])
        total = float(forces.sum())
        weights = forces / total if total > 1e-12 else np.full(len(pts), 1.0 / len(pts))
        position = sum(w * pt.position for w, pt in zip(weights, pts, strict=True))
        normal = sum(w * pt.normal for w, pt in zip(weights, pts, strict=True))
        norm = float(np.linalg.norm(normal))
        if norm < 1e-9:  # opposing points on one link cancel: keep the strongest one's
            normal = pts[int(np.argmax(forces))].normal
            norm = float(np.linalg.norm(normal))
        merged.append(Contact(position=np.asarray(position), normal=normal / norm,
                              friction=pts[0].friction, force=total))
    return merged


def scene_contacts(scene) -> list[Contact]:
    """The synthesized grasp's contacts in the object frame, one per link."""
    hand = scene.hand
    obj_pos, obj_rot = scene.object_pose()
    points = []
    for c in scene.contacts():
        link = c.link_index_a
        mu = scene.pair_friction(link)  # as the engine combines the two bodies' frictions
        position = obj_rot.T @ (np.array(c.position_on_b) - obj_pos)
        # The normal points from the object (B) toward the hand (A): the hand pushes the
        # object the other way.
        normal = -(obj_rot.T @ np.array(c.contact_normal_on_b))
        points.append(LinkPoint(hand.link_names[link], position, normal,
                                max(c.normal_force, 0.0), mu))
    return merge_by_link(points)


def scene_metrics(scene, length: float, mass_kg: float) -> dict[str, float]:
    """μg, μf, μm of the grasp the policy left in the scene (before the trajectory). μm's
    weight uses standard gravity, so it does not depend on the trajectory's gravity setting."""
    contacts = scene_contacts(scene)
    quality = mu_g(contacts, length)
    if quality <= 1e-12:
        # G has no full rank, so no combination of the contacts' forces spans the wrench
        # space: the hulls are flat and ε is 0. Skipping Qhull saves most of the cost here.
        return {"mu_g": 0.0, "mu_f": 0.0, "mu_m": 0.0}
    f = mu_f(contacts, length)
    if f == 0.0:
        # The origin is not strictly inside the unit-force hull. μm's wrenches are the same
        # ones scaled by each contact's force (≥ 0), which spans the same cone or a smaller
        # one, so the origin is not inside its hull either: μm is 0 too, without a second hull.
        return {"mu_g": quality, "mu_f": 0.0, "mu_m": 0.0}
    return {"mu_g": quality, "mu_f": f,
            "mu_m": mu_m(contacts, length, mass_kg * STANDARD_GRAVITY)}
