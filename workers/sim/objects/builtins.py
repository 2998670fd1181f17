"""Built-in objects generated with trimesh, sized for a Robotiq 3-finger hand.

The open hand spans about 15 cm and the fingers reach about 12 cm past the palm, so every
built-in fits in a 16 cm box. Each generator returns the solid (a watertight boolean union,
for geometry queries and mass properties) and its exact convex parts (for collision), so
built-ins never need an approximate decomposition. Frames: z up, centred on the bounding
box; the preparation step later moves the origin to the centre of mass.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache

import numpy as np
import trimesh

# Bump when any generator changes shape: it is part of the built-ins' content hash.
GENERATOR_VERSION = 1
DEFAULT_FRICTION = 0.8  # rubber-ish fingertip pads on plastic/metal


@dataclass(frozen=True)
class BuiltinShape:
    mesh: trimesh.Trimesh
    parts: list[np.ndarray]  # convex vertex sets, same frame as mesh


@dataclass(frozen=True)
class BuiltinInfo:
    name: str
    description: str
    mass_kg: float
    friction: float
    dimensions_m: dict[str, float] = field(default_factory=dict)
    convex: bool = True


def _union(meshes: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    # manifold3d gives a watertight union; a plain concatenation would count overlaps twice.
    return trimesh.boolean.union(meshes, engine="manifold")


def _sphere(r: float = 0.04) -> BuiltinShape:
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=r)
    return BuiltinShape(mesh, [mesh.vertices])


def _cube(side: float = 0.06) -> BuiltinShape:
    mesh = trimesh.creation.box(extents=(side, side, side))
    return BuiltinShape(mesh, [mesh.vertices])


def _can(r: float = 0.033, h: float = 0.12) -> BuiltinShape:
    mesh = trimesh.creation.cylinder(radius=r, height=h, sections=48)
    return BuiltinShape(mesh, [mesh.vertices])


def _dumbbell(r_ball: float = 0.03, r_bar: float = 0.012, length: float = 0.16) -> BuiltinShape:
    """Two balls on a bar along x; `length` is tip to tip."""
    cx = length / 2 - r_ball
    balls = [
        trimesh.creation.icosphere(3, r_ball).apply_translation((s * cx, 0, 0)) for s in (-1, 1)
    ]
    bar = trimesh.creation.cylinder(radius=r_bar, height=2 * cx, sections=32)
    bar.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (0, 1, 0)))
    parts = [*balls, bar]
    return BuiltinShape(_union(parts), [p.vertices for p in parts])


def _mug(
    r_out: float = 0.04,
    h: float = 0.095,
    wall: float = 0.005,
    bottom: float = 0.006,
    handle_hole: tuple[float, float] = (0.022, 0.044),
    handle_tube_r: float = 0.006,
    wall_segments: int = 16,
    handle_segments: int = 8,
) -> BuiltinShape:
    """Cup with a D-shaped handle on +x; hole (depth along x, height along z) fits a finger."""
    cup = trimesh.creation.cylinder(radius=r_out, height=h, sections=64)
    cavity = trimesh.creation.cylinder(radius=r_out - wall, height=h, sections=64)
    cavity.apply_translation((0, 0, bottom))
    cup = trimesh.boolean.difference([cup, cavity], engine="manifold")
    # Handle: half a torus in the x-z plane whose ends sink into the wall.
    depth, height = handle_hole
    major = height / 2 + handle_tube_r  # hole height sets the ring size
    scale_x = (depth + handle_tube_r) / major  # squash the ring so the hole has `depth`
    z_mid = 0.0
    ring = trimesh.creation.torus(major, handle_tube_r, major_sections=48, minor_sections=16)
    ring.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    ring.apply_scale((scale_x, 1, 1))
    ring.apply_translation((r_out, 0, z_mid))
    keep = trimesh.creation.box(bounds=((r_out - wall / 2, -1, -1), (1, 1, 1)))
    handle = trimesh.boolean.intersection([ring, keep], engine="manifold")
    mesh = _union([cup, handle])

    # Exact-enough convex parts: wall sectors, the bottom disc, handle tube segments.
    parts: list[np.ndarray] = []
    z0, z1 = -h / 2, h / 2
    angles = np.linspace(0, 2 * np.pi, wall_segments + 1)
    for a0, a1 in itertools.pairwise(angles):
        arc = np.linspace(a0, a1, 4)
        ring_pts = [
            (r * np.cos(a), r * np.sin(a), z)
            for r in (r_out - wall, r_out)
            for a in arc
            for z in (z0 + bottom, z1)
        ]
        parts.append(np.asarray(ring_pts))
    parts.append(trimesh.creation.cylinder(r_out, bottom, sections=32).apply_translation(
        (0, 0, z0 + bottom / 2)).vertices)
    v = handle.vertices
    theta = np.arctan2(v[:, 2] - z_mid, (v[:, 0] - r_out) / scale_x)
    edges = np.linspace(-np.pi / 2 - 1e-6, np.pi / 2 + 1e-6, handle_segments + 1)
    for t0, t1 in itertools.pairwise(edges):
        # Overlap neighbours slightly so the parts leave no gaps at the joints.
        sel = (theta >= t0 - 0.05) & (theta <= t1 + 0.05)
        parts.append(v[sel])
    return BuiltinShape(mesh, parts)


def _spiked_ball(
    r_core: float = 0.035, spike_len: float = 0.02, spike_r: float = 0.008
) -> BuiltinShape:
    """Core sphere with 12 cones along the icosahedron's vertex directions."""
    core = trimesh.creation.icosphere(3, r_core)
    dirs = trimesh.creation.icosahedron().vertices
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    base = r_core - 0.005  # start the cone inside the core so the union has no crack
    spikes = []
    for d in dirs:
        cone = trimesh.creation.cone(radius=spike_r, height=r_core + spike_len - base, sections=16)
        align = trimesh.geometry.align_vectors((0, 0, 1), d)
        cone.apply_transform(align)
        cone.apply_translation(d * base)
        spikes.append(cone)
    parts = [core, *spikes]
    return BuiltinShape(_union(parts), [p.vertices for p in parts])


_GENERATORS: dict[str, Callable[[], BuiltinShape]] = {
    "sphere": _sphere,
    "cube": _cube,
    "can": _can,
    "dumbbell": _dumbbell,
    "mug": _mug,
    "spiked_ball": _spiked_ball,
}

BUILTINS: dict[str, BuiltinInfo] = {
    "sphere": BuiltinInfo("sphere", "solid ball", 0.2, DEFAULT_FRICTION, {"radius": 0.04}),
    "cube": BuiltinInfo("cube", "solid cube", 0.25, DEFAULT_FRICTION, {"side": 0.06}),
    "can": BuiltinInfo(
        "can", "closed cylinder (a drinks can), axis z", 0.35, DEFAULT_FRICTION,
        {"radius": 0.033, "height": 0.12},
    ),
    "dumbbell": BuiltinInfo(
        "dumbbell", "two balls joined by a bar, along x", 0.5, DEFAULT_FRICTION,
        {"ball_radius": 0.03, "bar_radius": 0.012, "length": 0.16}, convex=False,
    ),
    "mug": BuiltinInfo(
        "mug", "open cup, axis z, D-shaped handle on +x with a finger-sized hole",
        0.3, DEFAULT_FRICTION,
        {"outer_radius": 0.04, "height": 0.095, "wall": 0.005, "bottom": 0.006,
         "handle_hole_depth": 0.022, "handle_hole_height": 0.044, "handle_tube_radius": 0.006},
        convex=False,
    ),
    "spiked_ball": BuiltinInfo(
        "spiked_ball", "ball with 12 conical spikes (icosahedron directions)", 0.2,
        DEFAULT_FRICTION,
        {"core_radius": 0.035, "spike_length": 0.02, "spike_base_radius": 0.008,
         "spikes": 12},
        convex=False,
    ),
}


@cache
def builtin_shape(name: str) -> BuiltinShape:
    """Generate (once per process) the named built-in's solid and convex parts."""
    return _GENERATORS[name]()
