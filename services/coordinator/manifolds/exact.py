"""Exact running sums of floats (pure): order-independent, so a sum kept up to date by adding
and removing terms batch by batch is the sum computed at once, to the last bit.

A float is n / 2^k with k ≤ 1074; scaled by 2^SCALE it is an integer, and Python integers add
exactly. Reading a sum back (`value`) is one correctly rounded division, which is also what
`math.fsum` returns, so a running sum equals `fsum` of its terms whatever their order. The
manifold table's volumes, μs means and spreads are kept this way (manifolds/aggregate.py) and
computed this way by the full recompute (manifolds/summary.py): both give the same table.
"""

from __future__ import annotations

from fractions import Fraction
from statistics import _float_sqrt_of_frac  # type: ignore[attr-defined]

SCALE = 1100  # > 1074: every finite float is an integer multiple of 2^-SCALE
ONE = 1 << SCALE


def exact(x: float) -> int:
    """x × 2^SCALE, exactly."""
    n, d = x.as_integer_ratio()
    return n * (ONE // d)


def value(total: int, count: int = 1) -> float:
    """total / (count × 2^SCALE), correctly rounded (count ≥ 1)."""
    return total / (ONE * count)


def sqrt_of(frac: Fraction) -> float:
    """√frac correctly rounded (the rounding `statistics.pstdev` uses; frac ≥ 0)."""
    if frac <= 0:
        return 0.0
    return float(_float_sqrt_of_frac(frac.numerator, frac.denominator))


def pstdev(count: int, s1: int, s2: int) -> float:
    """`statistics.pstdev` of `count` terms from their exact sum s1 (scale 2^SCALE) and sum
    of squares s2 (scale 2^(2·SCALE)): the same float (both round the exact variance)."""
    sx = Fraction(s1, ONE)
    sxx = Fraction(s2, ONE * ONE)
    return sqrt_of((count * sxx - sx * sx) / count / count)
