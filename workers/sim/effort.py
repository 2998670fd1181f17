"""Minimum closing effort: the least closing torque τ_c that still holds the object along the
reference trajectory (the paper's Table 1), by bisection over repeated evaluations.

Each trial is a full evaluation of the same pose with only `policy.closing_effort` changed, so
the grasp is synthesized again with that torque (as in the paper, where efforts are reduced
"until we reach grasp failure"): a lower torque can also form a different grasp. Bisection
assumes holding is monotone in τ_c between the bounds; it reports the smallest torque it saw
hold, with the largest it saw drop just below it. It costs ~log2((hi − lo)/tolerance) + 2
evaluations, so it is not part of every evaluation (see compare_policies --min-effort).
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class EffortSearch(BaseModel):
    model_config = ConfigDict(frozen=True)

    min_closing_effort: float | None = Field(
        description="least torque seen to hold, N·m; None if even `hi` drops")
    highest_dropping: float | None = Field(
        description="largest torque seen to drop (below the minimum), N·m; None if `lo` holds")
    evaluations: int


def _holds(evaluator, pose, effort: float) -> bool:
    settings = evaluator.settings
    policy = settings.policy.model_copy(update={"closing_effort": effort})
    evaluator.settings = settings.model_copy(update={"policy": policy})
    try:
        return evaluator.evaluate(pose).viable
    finally:
        evaluator.settings = settings


def search_closing_effort(evaluator, pose, lo: float, hi: float,
                          tolerance: float = 0.02) -> EffortSearch:
    if not 0.0 < lo < hi or tolerance <= 0.0:
        raise ValueError("need 0 < lo < hi and a positive tolerance")
    count = 1
    if not _holds(evaluator, pose, hi):
        return EffortSearch(min_closing_effort=None, highest_dropping=hi, evaluations=count)
    count += 1
    if _holds(evaluator, pose, lo):
        return EffortSearch(min_closing_effort=lo, highest_dropping=None, evaluations=count)
    while hi - lo > tolerance:
        mid = 0.5 * (lo + hi)
        count += 1
        if _holds(evaluator, pose, mid):
            hi = mid
        else:
            lo = mid
    return EffortSearch(min_closing_effort=hi, highest_dropping=lo, evaluations=count)


def minimum_closing_effort(evaluator, pose, lo: float, hi: float,
                           tolerance: float = 0.02) -> float | None:
    """The least closing torque (N·m) in [lo, hi], to `tolerance`, at which `pose` is still
    held along the trajectory; None if it drops even at `hi`."""
    return search_closing_effort(evaluator, pose, lo, hi, tolerance).min_closing_effort
