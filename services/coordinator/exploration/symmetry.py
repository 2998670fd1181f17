"""Shortcut 3: object symmetries, detected from the mesh and mirrored onto the map (pure).

Candidates are the symmetries a grasp map can use without knowing more about the object:
rotations about the object's z axis by 2π/k (k = 2…8), mirrors in vertical planes through
the z axis (azimuth α = j·π/8), and the mirror z → −z. A candidate is kept when every
sampled surface point, transformed, lies on the surface again (within 0.5 % of the object's
radius, at least 0.5 mm).

A symmetry acts on poses and on results. The start attitude of the gripper is built from the
approach direction and "up" (+z), so: a rotation about z keeps the roll; a vertical mirror
sends roll → −roll; the z mirror sends roll → π − roll. A mirror also mirrors the hand: it is
usable only for a gripper that is itself mirror-symmetric in its xz plane (fingers paired by
mount y ↔ −y), whose paired fingers then trade places (links and joints; spread joints change
sign). Attitudes with pitch/yaw tilts are not mirrored (their images are not grid attitudes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from graspscape.services.coordinator.objects.geometry import MESH_QUERIES
from graspscape.shared.specs.gripper import AnyGripperSpec, GripperSpec
from graspscape.shared.specs.pose import Pose
from scipy.spatial.transform import Rotation

TWO_PI = 2 * math.pi


@dataclass(frozen=True)
class Symmetry:
    kind: str  # "rot_z" | "mirror_v" | "mirror_z"
    angle: float = 0.0  # rotation angle, or the mirror plane's azimuth

    @property
    def reflects(self) -> bool:
        return self.kind != "rot_z"

    def matrix(self) -> np.ndarray:
        c, s = math.cos(self.angle), math.sin(self.angle)
        if self.kind == "rot_z":
            return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        if self.kind == "mirror_v":
            c2, s2 = math.cos(2 * self.angle), math.sin(2 * self.angle)
            return np.array([[c2, s2, 0.0], [s2, -c2, 0.0], [0.0, 0.0, 1.0]])
        return np.diag([1.0, 1.0, -1.0])

    def pose(self, pose: Pose) -> Pose | None:
        if pose.pitch or pose.yaw:
            return None
        theta, phi, roll = pose.theta, pose.phi, pose.roll
        if self.kind == "rot_z":
            phi = phi + self.angle
        elif self.kind == "mirror_v":
            phi, roll = 2 * self.angle - phi, -roll
        else:
            theta, roll = math.pi - theta, math.pi - roll
        return Pose(theta=min(math.pi, max(0.0, theta)), phi=phi % TWO_PI, r=pose.r,
                    roll=roll % TWO_PI, pitch=0.0, yaw=0.0)

    def describe(self) -> str:
        if self.kind == "rot_z":
            return f"rotation about z by {math.degrees(self.angle):.0f}°"
        if self.kind == "mirror_v":
            return f"mirror in the vertical plane at φ = {math.degrees(self.angle):.1f}°"
        return "mirror z → −z"


def detect(mesh: Any, *, samples: int = 800, seed: int = 0) -> list[Symmetry]:
    """The candidate symmetries the mesh has (see the module doc)."""
    import trimesh

    points, _ = trimesh.sample.sample_surface_even(mesh, samples, seed=seed)
    points = np.vstack([points, mesh.vertices[:: max(1, len(mesh.vertices) // 300)]])
    radius = float(np.linalg.norm(mesh.vertices, axis=1).max())
    tol = max(5e-4, 0.005 * radius)
    candidates = [Symmetry("rot_z", TWO_PI / k) for k in range(2, 9)]
    candidates += [Symmetry("mirror_v", j * math.pi / 8) for j in range(8)]
    candidates.append(Symmetry("mirror_z"))
    found = []
    for sym in candidates:
        moved = points @ sym.matrix().T
        with MESH_QUERIES:  # a cached mesh's lazy rtree is not thread-safe (objects/geometry)
            _, dist, _ = trimesh.proximity.closest_point(mesh, moved)
        if float(dist.max()) <= tol:
            found.append(sym)
    return found


def task_symmetries(found: list[Symmetry], gripper: AnyGripperSpec) -> list[Symmetry]:
    """The object's symmetries that the grasping task keeps: z → −z never (gravity and the
    lift act along z, so a grasp from below is not the mirror image of one from above), and
    mirrors only for a gripper that is itself mirror-symmetric."""
    kept = [s for s in found if s.kind != "mirror_z"]
    if hand_mirror(gripper) is None:
        kept = [s for s in kept if not s.reflects]
    return kept


LATTICE_MULTIPLES = (1, 2, 4, 8)


def lattice_multiple(sym: Symmetry) -> int:
    """The azimuth multiple q a ring needs to map onto itself under `sym`: k for a rotation by
    2π/k, 8/gcd(j, 8) for a mirror at azimuth j·π/8, 1 for z → −z."""
    if sym.kind == "rot_z":
        return round(TWO_PI / sym.angle)
    if sym.kind == "mirror_v":
        return 8 // math.gcd(round(sym.angle * 8 / math.pi), 8)
    return 1


def azimuth_multiple(symmetries: list[Symmetry]) -> int:
    """The lattice's azimuth multiple for an object with these symmetries: the largest one a
    symmetry needs among 1, 2, 4 and 8 (the orders that survive the lattice's doubling of
    azimuths per level; a 3-fold symmetry is not used)."""
    needs = [lattice_multiple(s) for s in symmetries]
    return max([q for q in needs if q in LATTICE_MULTIPLES], default=1)


@dataclass(frozen=True)
class HandMirror:
    """How a mirror-symmetric gripper's links and joints trade places under a reflection."""

    fingers: dict[str, str]  # finger → its mirror image (itself on the plane)

    def link(self, name: str) -> str:
        head, _, tail = name.partition("_")
        return f"{self.fingers[head]}_{tail}" if tail and head in self.fingers else name

    def joint(self, name: str, value: float) -> tuple[str, float]:
        head, _, tail = name.partition("_")
        if not tail or head not in self.fingers:
            return name, value
        mirrored = f"{self.fingers[head]}_{tail}"
        return mirrored, -value if tail == "spread" else value


def hand_mirror(gripper: AnyGripperSpec, tol: float = 1e-6) -> HandMirror | None:
    """The pairing of fingers by mount y ↔ −y, or None if the gripper is not symmetric."""
    if not isinstance(gripper, GripperSpec):
        return None  # a URDF gripper: its mounts are not in the spec, so no mirror is claimed
    fingers = {}
    for f in gripper.fingers:
        x, y, z = f.mount_xyz
        twin = [g for g in gripper.fingers
                if abs(g.mount_xyz[0] - x) < tol and abs(g.mount_xyz[1] + y) < tol
                and abs(g.mount_xyz[2] - z) < tol and len(g.phalanges) == len(f.phalanges)]
        if not twin:
            return None
        fingers[f.name] = twin[0].name
    return HandMirror(fingers)


def mirror_result(row: dict[str, Any], sym: Symmetry, hand: HandMirror | None) -> dict[str, Any]:
    """A stored pose row's fields (signature, grasp, contacts) under the symmetry."""
    m = sym.matrix()
    out = dict(row)

    def point(p: Any) -> list[float]:
        return [float(v) for v in m @ np.asarray(p, dtype=float)]

    def link(name: str) -> str:
        return hand.link(name) if sym.reflects and hand is not None else name

    def joints(angles: dict[str, float]) -> dict[str, float]:
        if not sym.reflects or hand is None:
            return dict(angles)
        return dict(sorted(hand.joint(k, v) for k, v in angles.items()))

    sig = row.get("signature")
    if sig:
        contacts = [{**c, "link": link(c["link"]), "position_object": point(c["position_object"])}
                    for c in sig.get("contacts", ())]
        out["signature"] = {
            **sig,
            "links_in_contact": sorted(link(x) for x in sig.get("links_in_contact", ())),
            "contacts": sorted(contacts, key=lambda c: c["link"]),
            "joint_angles": joints(sig.get("joint_angles") or {}),
        }
    grasp = row.get("grasp")
    if grasp:
        rot = Rotation.from_quat(grasp["base_orientation"]).as_matrix()
        gripper_flip = np.diag([1.0, -1.0, 1.0]) if sym.reflects else np.eye(3)
        out["grasp"] = {
            **grasp,
            "base_position": point(grasp["base_position"]),
            "base_orientation": [float(v) for v in
                                 Rotation.from_matrix(m @ rot @ gripper_flip).as_quat()],
            "joint_angles": joints(grasp.get("joint_angles") or {}),
        }
    if row.get("contacts_per_link"):
        out["contacts_per_link"] = {link(k): v for k, v in row["contacts_per_link"].items()}
    return out


class Orbits:
    """Orbits of lattice points under the detected symmetries (only images that are lattice
    points count: a rotation or mirror maps a ring either entirely onto the lattice or not at
    all, so orbits are consistent). The representative of an orbit is its smallest pose key."""

    def __init__(self, lattice: Any, symmetries: list[Symmetry]) -> None:
        self.lattice = lattice
        self.symmetries = symmetries
        self._cache: dict[Any, dict[Any, tuple[Symmetry, ...]]] = {}

    def _image(self, p: Any, sym: Symmetry) -> Any | None:
        pose = sym.pose(self.lattice.pose(p))
        if pose is None:
            return None
        try:
            q = self.lattice.point(pose)
        except ValueError:
            return None
        if not 0 <= q.ring <= self.lattice.n_rings or self.lattice.pose(q).key() != pose.key():
            return None
        return q

    def orbit(self, p: Any) -> dict[Any, tuple[Symmetry, ...]]:
        """Every orbit member with the chain of symmetries that maps p onto it."""
        cached = self._cache.get(p)
        if cached is not None:
            return cached
        paths: dict[Any, tuple[Symmetry, ...]] = {p: ()}
        frontier = [p]
        while frontier:
            nxt = []
            for q in frontier:
                for sym in self.symmetries:
                    image = self._image(q, sym)
                    if image is not None and image not in paths:
                        paths[image] = (*paths[q], sym)
                        nxt.append(image)
            frontier = nxt
        self._cache[p] = paths
        return paths

    def representative(self, p: Any) -> Any:
        return min(self.orbit(p), key=lambda q: self.lattice.pose(q).key())
