"""The palm gap at which the open hand starts: the search behind `placement.start_gap`.

The palm moves along the surface normal of its nearest point x_c; `clear(d)` says whether the
hand with its palm at gap d is far enough from the object. Both modes walk out from the
nominal gap in fixed steps to the first clear one (the "palm" mode stops there, as the back-off
always did); the "clearance" mode then bisects the last step, so the start lies within a
tolerance of where the hand just clears, not up to a whole step beyond it. Neighbouring poses
then start at their own clearance, not at one rounded up to the same 5 mm step, and the r
levels stay apart. Pure (the predicate carries the physics), so it is tested without pybullet.
"""

from __future__ import annotations

from collections.abc import Callable


def first_clear_gap(clear: Callable[[float], bool], start: float, step: float,
                    max_extra: float, tolerance: float | None = None) -> float | None:
    """The first gap start + k·step (k = 0, 1, …, up to `max_extra` beyond `start`) where
    `clear` holds, or None. With `tolerance`, that step is then bisected: the result is the
    upper end of an interval no wider than `tolerance` whose lower end is not clear, so it
    lies within `tolerance` of a gap where the hand just clears. Deterministic: the same
    predicate gives the same gap."""
    gap, extra = start, 0.0
    while not clear(gap):
        if extra >= max_extra - 1e-12:
            return None
        gap += step
        extra += step
    if tolerance is None or extra == 0.0:
        return gap
    low, high = gap - step, gap  # not clear at low (the previous step), clear at high
    while high - low > tolerance:
        middle = 0.5 * (low + high)
        if clear(middle):
            high = middle
        else:
            low = middle
    return high
