"""The multi-resolution pose lattice: equal-area rings on the sphere × r levels × attitudes.

Pure geometry, no store. Level 0 is the coarse pass; level L halves Δθ and Δr L times. Every
point of level L is also a point of every finer level (the lattice is nested), so a pose keeps
one identity (and one pose key) whatever level reaches it first.

Equal area. Level L has N_L = n·2^L + 1 rings θ_k = k·π/(n·2^L) (n = round(π/Δθ)). A ring is
born at the first level where it exists; at its birth level b it gets
m_b = max(1, round(2π·sin θ / Δθ_b)) evenly spaced azimuths, so its cells span about Δθ_b in
both directions and every cell of the sphere covers about Δθ_b² steradians (a band of area
2π·sin θ·Δθ cut into pieces ∝ sin θ): no pile-up of cells at the poles. With an azimuth
multiple q > 1 (`PoseGridSpec.azimuth_multiple`), m_b is rounded to the nearest multiple of
q (at least q), so every ring maps onto itself under rotations about z by 2π/q and mirrors in
vertical planes at multiples of π/q — the symmetry shortcut can use only the symmetries the
lattice itself has. At each finer level the ring's azimuth count doubles, which keeps the
nesting. The poles are one point each at every level.

Points are stored as integers at the finest level D (the refinement depth): `ring` (K),
`azimuth` (J, the azimuth index on ring K at level D), `r_index` (I, in steps of Δr/2^D) and
`attitude` (a, the index into the grid's attitudes); the formulas here use the letters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

from graspscape.shared.specs.exploration import PoseGridSpec
from graspscape.shared.specs.pose import Pose

TWO_PI = 2 * math.pi


class Point(NamedTuple):
    """A lattice point by its integer indices at the finest level (K, J, I, a above).

    A NamedTuple rather than a frozen dataclass: hashing, equality and ordering run in C
    (the running map makes, hashes and compares millions of these; about a fifth of its
    upkeep was the dataclass's Python-level __hash__/__eq__/__lt__). Same fields in the same
    order, so the same hash, sort order and repr as the dataclass had. Unlike it, a Point
    equals the plain tuple of its fields and is iterable; nothing stores one as JSON."""

    ring: int  # K: ring index at the finest level
    azimuth: int  # J: azimuth index on that ring at the finest level
    r_index: int  # I: r index at the finest level (r = r_min + I·Δr/2^D)
    attitude: int  # a: attitude index into the spec's attitude list

    def at_r(self, r_index: int) -> Point:
        """The point of the same direction and attitude at another r index (its normal)."""
        return Point(self.ring, self.azimuth, r_index, self.attitude)


def _trailing_zeros(x: int, cap: int) -> int:
    if x == 0:
        return cap
    t = 0
    while x % 2 == 0 and t < cap:
        x //= 2
        t += 1
    return t


@dataclass(frozen=True)
class Lattice:
    """The nested pose lattice of one grid spec down to depth D (0 = coarse pass only)."""

    grid: PoseGridSpec
    depth: int = 0

    @cached_property
    def n(self) -> int:
        return max(1, round(math.pi / self.grid.dtheta))

    @cached_property
    def azimuth_multiple(self) -> int:
        return self.grid.azimuth_multiple or 1

    @cached_property
    def n_rings(self) -> int:  # rings at the finest level are 0 … n_rings
        return self.n << self.depth

    @cached_property
    def attitudes(self) -> list[tuple[float, float, float]]:
        return self.grid.attitudes.attitudes()

    @cached_property
    def n_r(self) -> int:  # coarse r intervals (levels − 1)
        return len(self.grid.r_levels()) - 1

    def scale(self, level: int) -> int:
        """Finest-level index steps per step at `level`."""
        return 1 << (self.depth - level)

    def dtheta(self, level: int) -> float:
        return math.pi / (self.n << level)

    def dr(self, level: int) -> float:
        return self.grid.dr / (1 << level)

    # --- rings ---------------------------------------------------------------------------
    def is_pole(self, K: int) -> bool:
        return K == 0 or self.n_rings == K

    def ring_birth(self, K: int) -> int:
        return self.depth - _trailing_zeros(K, self.depth)

    def theta(self, K: int) -> float:
        # K·π/n rounds to π + 1 ulp for some n (13, 26, 47, …): a south pole out of Pose's
        # range, which no worker could expand.
        return min(math.pi, K * math.pi / self.n_rings)

    @cached_property
    def _m_birth(self) -> list[int]:
        """Azimuths of every ring at its birth level (1 at the poles)."""
        q = self.azimuth_multiple
        out = []
        for K in range(self.n_rings + 1):
            b = self.ring_birth(K)
            m_b = q * max(1, round(TWO_PI * math.sin(self.theta(K)) / self.dtheta(b) / q))
            out.append(1 if self.is_pole(K) else m_b)
        return out

    @cached_property
    def _ring_births(self) -> list[int]:
        return [self.ring_birth(K) for K in range(self.n_rings + 1)]

    @cached_property
    def _m_finest(self) -> list[int]:
        return [self.m_at(K, self.depth) for K in range(self.n_rings + 1)]

    def m_at(self, K: int, level: int) -> int:
        """Azimuths on ring K at `level` (the ring must exist there)."""
        if self.is_pole(K):
            return 1
        return self._m_birth[K] << (level - self._ring_births[K])

    def m(self, K: int) -> int:
        return self._m_finest[K]

    def ring_exists(self, K: int, level: int) -> bool:
        return K % self.scale(level) == 0

    # --- points --------------------------------------------------------------------------
    def exists(self, p: Point, level: int) -> bool:
        s = self.scale(level)
        if not self.ring_exists(p.ring, level) or p.r_index % s:
            return False
        return self.is_pole(p.ring) or p.azimuth % (self.m(p.ring) // self.m_at(p.ring, level)) == 0

    def birth(self, p: Point) -> int:
        for level in range(self.depth + 1):
            if self.exists(p, level):
                return level
        raise ValueError(f"{p} is not a lattice point")

    def pose(self, p: Point) -> Pose:
        roll, pitch, yaw = self.attitudes[p.attitude]
        return Pose(
            theta=self.theta(p.ring),
            phi=0.0 if self.is_pole(p.ring) else p.azimuth * TWO_PI / self.m(p.ring),
            r=round(self.grid.r_min + p.r_index * self.dr(self.depth), 9),
            roll=roll,
            pitch=pitch,
            yaw=yaw,
        )

    def point(self, pose: Pose) -> Point:
        """The lattice point of a pose (inverse of `pose`, by rounding)."""
        K = round(pose.theta * self.n_rings / math.pi)
        m = self.m(K)
        J = 0 if m == 1 else round((pose.phi % TWO_PI) * m / TWO_PI) % m
        I = round((pose.r - self.grid.r_min) / self.dr(self.depth))  # noqa: E741
        att = (pose.roll % TWO_PI, pose.pitch, pose.yaw)
        for a, (roll, pitch, yaw) in enumerate(self.attitudes):
            if (
                abs(math.remainder(att[0] - roll, TWO_PI)) < 1e-6
                and abs(att[1] - pitch) < 1e-6
                and abs(att[2] - yaw) < 1e-6
            ):
                return Point(K, J, I, a)
        raise ValueError(f"attitude of {pose} is not one of the grid's")

    def cells(self, level: int) -> list[tuple[int, int]]:
        """(K, J) of every direction at `level`, ring by ring from θ = 0."""
        s = self.scale(level)
        out = []
        for K in range(0, self.n_rings + 1, s):
            m_l = self.m_at(K, level)
            step = self.m(K) // m_l if not self.is_pole(K) else 1
            out += [(K, j * step) for j in range(m_l)]
        return out

    def coarse_points(self) -> list[Point]:
        s = self.scale(0)
        return [
            Point(K, J, i * s, a)
            for K, J in self.cells(0)
            for i in range(self.n_r + 1)
            for a in range(len(self.attitudes))
        ]

    def direction(self, p: Point) -> tuple[float, float, float]:
        pose = self.pose(p)
        st = math.sin(pose.theta)
        return (st * math.cos(pose.phi), st * math.sin(pose.phi), math.cos(pose.theta))

    def angle(self, p: Point, q: Point) -> float:
        u, v = self.direction(p), self.direction(q)
        return math.acos(max(-1.0, min(1.0, sum(a * b for a, b in zip(u, v, strict=True)))))

    # --- neighbours and midpoints at one level ------------------------------------------
    def normal_neighbours(self, p: Point, level: int) -> list[Point]:
        """Same direction and attitude, the next r level in and out."""
        s = self.scale(level)
        top = self.n_r << self.depth
        return [p.at_r(i) for i in (p.r_index - s, p.r_index + s) if 0 <= i <= top]

    def ring_neighbours(self, p: Point, level: int) -> list[Point]:
        """Same ring, the next azimuth either way (none at a pole)."""
        if self.is_pole(p.ring) or self.m_at(p.ring, level) < 2:
            return []
        step = self.m(p.ring) // self.m_at(p.ring, level)
        m = self.m(p.ring)
        return sorted({Point(p.ring, (p.azimuth + d * step) % m, p.r_index, p.attitude)
                       for d in (-1, 1)})

    def cross_neighbours(self, p: Point, level: int) -> list[Point]:
        """Points of the rings just above and below whose azimuth cells overlap p's."""
        s = self.scale(level)
        pole = self.is_pole(p.ring)
        phi = 0.0 if pole else p.azimuth * TWO_PI / self.m(p.ring)  # as pose() has it
        half = math.pi / self.m_at(p.ring, level)
        out = []
        for K in (p.ring - s, p.ring + s):
            if not 0 <= K <= self.n_rings:
                continue
            m_l = self.m_at(K, level)
            if pole or self.is_pole(K):
                step = 1 if self.is_pole(K) else self.m(K) // m_l
                out += [Point(K, j * step, p.r_index, p.attitude) for j in range(m_l)]
                continue
            step = self.m(K) // m_l
            # Only azimuths within half a cell of each ring's width can overlap: test those
            # (the test itself unchanged) instead of every azimuth of the ring.
            reach = half + math.pi / m_l - 1e-9
            centre = round(phi * m_l / TWO_PI)
            width = math.ceil(reach * m_l / TWO_PI) + 1
            if 2 * width + 1 >= m_l:
                candidates = range(m_l)
            else:
                candidates = sorted({(centre + d) % m_l for d in range(-width, width + 1)})
            for j in candidates:
                gap = abs(math.remainder(j * TWO_PI / m_l - phi, TWO_PI))
                if gap < reach:
                    out.append(Point(K, j * step, p.r_index, p.attitude))
        return out

    def attitude_neighbours(self, p: Point) -> list[Point]:
        """Same position, the next roll either way (same tilt), or the tilt variants of the
        same roll (attitudes are not refined: they are neighbours at every level)."""
        per_roll = 1 + 4 * len(self.grid.attitudes.tilts)
        rolls = self.grid.attitudes.rolls
        roll, tilt = divmod(p.attitude, per_roll)
        out = {((roll + d) % rolls) * per_roll + tilt for d in (-1, 1)} if rolls > 1 else set()
        if tilt == 0:
            out |= {roll * per_roll + t for t in range(1, per_roll)}
        else:
            out.add(roll * per_roll)
        out.discard(p.attitude)
        return [Point(p.ring, p.azimuth, p.r_index, a) for a in sorted(out)]

    def neighbours(self, p: Point, level: int) -> list[tuple[str, Point]]:
        return (
            [("normal", q) for q in self.normal_neighbours(p, level)]
            + [("ring", q) for q in self.ring_neighbours(p, level)]
            + [("cross", q) for q in self.cross_neighbours(p, level)]
        )

    def midpoint(self, p: Point, q: Point, level: int) -> Point | None:
        """The level+1 point between two level neighbours, if it is new at level+1."""
        if level >= self.depth:
            return None
        if p.ring == q.ring and p.azimuth == q.azimuth:  # along the normal
            mid = p.at_r((p.r_index + q.r_index) // 2)
        elif p.ring == q.ring:  # along the ring: the azimuth halfway, the short way round
            m = self.m(p.ring)
            d = (q.azimuth - p.azimuth) % m
            lo = p if d <= m // 2 else q
            width = min(d, m - d)
            mid = Point(p.ring, (lo.azimuth + width // 2) % m, p.r_index, p.attitude)
        else:
            K = (p.ring + q.ring) // 2
            if self.is_pole(p.ring):
                phi = self.pose(q).phi
            elif self.is_pole(q.ring):
                phi = self.pose(p).phi
            else:
                a, b = self.pose(p).phi, self.pose(q).phi
                phi = a + math.remainder(b - a, TWO_PI) / 2
            m_l = self.m_at(K, level + 1)
            j = round((phi % TWO_PI) * m_l / TWO_PI) % m_l
            mid = Point(K, j * (self.m(K) // m_l), p.r_index, p.attitude)
        return mid if self.birth(mid) == level + 1 else None

    def cell_area(self, K: int, level: int) -> float:
        """Solid angle of one cell of ring K at `level` (its band of the sphere / its cells)."""
        half = self.dtheta(level) / 2
        lo = max(0.0, self.theta(K) - half)
        hi = min(math.pi, self.theta(K) + half)
        return TWO_PI * (math.cos(lo) - math.cos(hi)) / self.m_at(K, level)
