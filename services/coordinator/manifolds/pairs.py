"""`behaviour.same_behaviour` over many neighbour pairs at once (pure): numpy over arrays of
the stored poses' joint angles instead of a Python call per pair.

The running map asks the same question of every pair a batch links (grouping's links, the
speck votes): both viable, the same digits touching, every digit's mean joint-angle
difference within a tolerance. Here each pose is a row once (its digits and its joint
layout, the joint names in its stored order, as small integers; its angles in that order),
and a batch's pairs are answered by a few array operations per layout.

The answer is `joint_difference`'s float itself, so one answer serves every tolerance
(`answers`: the grouping's and the speck votes'):
the columns are summed in the order `joint_difference` sums the names (its plan for the
intersection of two equal name sets, computed by the same expression), each sum starting at
0 and divided by the group's size, so each pair gets the same float to the last bit. Pairs
the arrays do not decide (joint layouts that differ, no joints: `slid` decides, a NaN
angle) are NaN: `answers` asks `same_behaviour` for those, in each argument order.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping, Sequence

import numpy as np
from graspscape.services.coordinator.manifolds.behaviour import StoredPose, same_behaviour
from graspscape.services.coordinator.mapspace.lattice import Point

NOT_SAME = math.inf  # not both viable, or other digits: never within a tolerance


class PairBehaviour:
    """The joint difference of neighbour pairs (`differences`) for the poses `add`ed."""

    def __init__(self) -> None:
        self._row: dict[Point, int] = {}
        self._digits: dict[frozenset[str], int] = {}
        self._layouts: dict[tuple[str, ...], int] = {}
        self._plans: list[list[list[int]]] = []  # per layout: its digits' column groups
        self._n = 0
        # Per row, room for twice the rows held (a batch appends without copying the map):
        self._viable = np.zeros(0, dtype=bool)
        self._kind = np.zeros(0, dtype=np.int64)  # digits id
        self._layout = np.zeros(0, dtype=np.int64)  # -1: no joints, or NaN among them
        self._angles = np.zeros((0, 0))  # in the layout's order, NaN beyond its width

    def add(self, poses: Mapping[Point, StoredPose]) -> None:
        """Rows for poses not seen yet."""
        new = [(p, s) for p, s in poses.items() if p not in self._row]
        if not new:
            return
        kind, layout, angles = [], [], []
        digits, row, start = self._digits, self._row, self._n
        for k, (p, s) in enumerate(new):
            row[p] = start + k
            kind.append(digits.setdefault(s.digits, len(digits)))
            values = list(s.joints.values())
            layout.append(self._layout_of(s.joints)
                          if values and not any(v != v for v in values) else -1)
            angles.append(values)
        width = max(len(v) for v in angles)
        self._room(start + len(new), width)
        end = start + len(new)
        self._viable[start:end] = [s.viable for _, s in new]
        self._kind[start:end] = kind
        self._layout[start:end] = layout
        if all(len(v) == width for v in angles):
            if width:
                self._angles[start:end, :width] = angles
        else:
            for k, values in enumerate(angles):
                self._angles[start + k, : len(values)] = values
        self._n = end

    def _room(self, rows: int, width: int) -> None:
        have, wide = self._angles.shape
        if rows <= have and width <= wide:
            return
        size = max(rows, 2 * have, 64)
        width = max(width, wide)
        angles = np.full((size, width), np.nan)
        angles[:have, :wide] = self._angles
        self._angles = angles
        for name in ("_viable", "_kind", "_layout"):
            old = getattr(self, name)
            grown = np.zeros(size, dtype=old.dtype)
            grown[:have] = old
            setattr(self, name, grown)

    def _layout_of(self, joints: Mapping[str, float]) -> int:
        names = tuple(joints)
        got = self._layouts.get(names)
        if got is None:
            got = self._layouts[names] = len(self._plans)
            # joint_difference's plan for two poses of this layout: the intersection of two
            # equal sets, as same_behaviour computes it, grouped by digit in its order. The
            # sets are made from the dict, as there: a set made from a dict is sized for it
            # at once, one made from a tuple grows as it goes, and the two may iterate in
            # different orders (the float sum with them).
            shared = tuple(set(joints) & set(joints))
            column = {name: i for i, name in enumerate(names)}
            groups: dict[str, list[int]] = {}
            for j in shared:
                groups.setdefault(j.split("_")[0], []).append(column[j])
            self._plans.append(list(groups.values()))
        return got

    def differences(self, pairs: Sequence[tuple[Point, Point]]) -> np.ndarray:
        """Per pair: `joint_difference` of the two (NOT_SAME where they are not both viable
        with the same digits; NaN where `same_behaviour` must decide)."""
        out = np.full(len(pairs), np.nan)
        if not pairs:
            return out
        row = self._row
        a = np.fromiter((row[p] for p, _ in pairs), dtype=np.int64, count=len(pairs))
        b = np.fromiter((row[q] for _, q in pairs), dtype=np.int64, count=len(pairs))
        differ = ~(self._viable[a] & self._viable[b]) | (self._kind[a] != self._kind[b])
        out[differ] = NOT_SAME
        lay_a, lay_b = self._layout[a], self._layout[b]
        decided = ~differ & (lay_a == lay_b) & (lay_a >= 0)
        for lay in np.unique(lay_a[decided]).tolist():
            at = np.flatnonzero(decided & (lay_a == lay))
            delta = np.abs(self._angles[a[at]] - self._angles[b[at]])
            worst = None
            for columns in self._plans[lay]:
                mean = _summed([delta[:, c] for c in columns]) / len(columns)
                worst = mean if worst is None else np.maximum(worst, mean)
            if worst is not None:
                out[at] = worst
        return out


def answers(pairs: Sequence[tuple[Point, Point]], differences: np.ndarray,
            samples: Mapping[Point, StoredPose], tolerance: float) -> list[int]:
    """same_behaviour of each pair with this tolerance, both ways round, as bits: 1 for
    (p, q), 2 for (q, p) (the arrays' answers are the same both ways; a pair they leave
    open, NaN, is asked of `same_behaviour` in each order)."""
    out = (3 * (differences <= tolerance)).tolist()  # NaN compares False
    for k in np.flatnonzero(np.isnan(differences)).tolist():
        a, b = samples[pairs[k][0]], samples[pairs[k][1]]
        out[k] = same_behaviour(a, b, tolerance) + 2 * same_behaviour(b, a, tolerance)
    return out


def _summed(terms: list[np.ndarray]) -> np.ndarray:
    """What the built-in `sum` of each row's terms gives, to the last bit: from 0 (so the
    first term exactly), plain additions before Python 3.12, Neumaier's compensated ones
    from 3.12 on (its C loop, branch for branch)."""
    total = terms[0] + 0.0
    if sys.version_info < (3, 12):
        for x in terms[1:]:
            total = total + x
        return total
    comp = np.zeros_like(total)
    for x in terms[1:]:
        t = total + x
        comp = comp + np.where(np.abs(total) >= np.abs(x), (total - t) + x, (x - t) + total)
        total = t
    fix = (comp != 0) & np.isfinite(comp)
    return np.where(fix, total + comp, total)
