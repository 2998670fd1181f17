"""One pose that cannot be evaluated does not cost its tile: it is stored with outcome
`error` and the exception's message, and the tile goes on.

An error that is the tile's rather than the pose's (the object cannot be loaded, the process
is broken) shows up on every pose; `ErrorStreak` tells the two apart by the first poses of a
tile: if the first `SYSTEMATIC_AFTER` evaluated poses all raise, the tile is reported failed
(queued again or failed at `max_attempts`, as before) instead of storing a tile of errors.
"""

from __future__ import annotations

from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import Outcome, PoseResult, nonfinite_fields

SYSTEMATIC_AFTER = 3
_MAX_MESSAGE = 2000


def error_result(pose: Pose, exc: BaseException) -> PoseResult:
    """The stored record of a pose whose evaluation raised `exc`."""
    message = f"{type(exc).__name__}: {exc}"[:_MAX_MESSAGE]
    return PoseResult(pose=pose, pose_key=pose.key(), outcome=Outcome.ERROR, viable=False,
                      mu_s=0.0, error=message)


def finite_or_error(result: PoseResult) -> PoseResult:
    """The result, or where any of its numbers is NaN or ±∞ (a blown-up simulation) the
    pose's `error` record naming them: its values are not sent. Sent as they are, they would
    go out as `null` and the coordinator would refuse the whole batch."""
    bad = nonfinite_fields(result)
    if not bad:
        return result
    shown = ", ".join(bad[:5]) + (f" and {len(bad) - 5} more" if len(bad) > 5 else "")
    return error_result(result.pose, ValueError(f"non-finite result values: {shown}"))


class ErrorStreak:
    """Counts a tile's evaluations; `systematic()` once its first poses all raised."""

    def __init__(self, after: int = SYSTEMATIC_AFTER) -> None:
        self.after = after
        self.evaluated = 0
        self.errors = 0

    def record(self, result: PoseResult) -> None:
        self.evaluated += 1
        self.errors += result.outcome == Outcome.ERROR

    def systematic(self) -> bool:
        return self.evaluated >= self.after and self.errors == self.evaluated
