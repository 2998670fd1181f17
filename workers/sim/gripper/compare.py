"""Two models of one gripper (the Robotiq 3F as a TOML of boxes and as a URDF) evaluated on the
same poses of one object with the same policy: on how many do they agree?

Agreement is counted on the outcome (held, slipped, no grasp, ...) of each pose, and, for
poses both hold, on the digits in contact (the grasp type as the map's manifolds tell them
apart, manifolds/behaviour.py).
"""

from __future__ import annotations

import math
from pathlib import Path

from graspscape.shared.specs.gripper import AnyGripperSpec
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import PoseResult
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.evaluate import Evaluator
from graspscape.workers.sim.objects import prepare_object
from pydantic import BaseModel


def grid_50() -> list[Pose]:
    """5 polar angles × 10 azimuths at a 2 cm start gap, roll 0: 50 poses."""
    thetas = [math.radians(a) for a in (20, 55, 90, 125, 160)]
    return [Pose(theta=t, phi=k * math.pi / 5, r=0.02) for t in thetas for k in range(10)]


class PoseAgreement(BaseModel):
    pose: Pose
    outcome_a: str
    outcome_b: str
    digits_a: list[str]
    digits_b: list[str]
    eval_s_a: float
    eval_s_b: float


class Agreement(BaseModel):
    poses: int
    same_outcome: int
    both_viable: int
    same_digits_when_both_viable: int
    viable_a: int
    viable_b: int
    rows: list[PoseAgreement]

    @property
    def outcome_share(self) -> float:
        return self.same_outcome / self.poses


def _digits(result: PoseResult) -> list[str]:
    return sorted({link.split("_", 1)[0] for link in (result.contacts_per_link or {})})


def compare(a: AnyGripperSpec, b: AnyGripperSpec, obj: str, poses: list[Pose], cache: Path,
            settings: SimSettings | None = None) -> Agreement:
    prepared = prepare_object(ObjectSpec(name=obj), cache / "objects")
    results = []
    for spec in (a, b):
        with Evaluator(prepared, spec, settings or SimSettings(), work_dir=cache) as evaluator:
            results.append([evaluator.evaluate(pose) for pose in poses])
    rows = [PoseAgreement(pose=pose, outcome_a=ra.outcome.value, outcome_b=rb.outcome.value,
                          digits_a=_digits(ra), digits_b=_digits(rb),
                          eval_s_a=ra.eval_time_s, eval_s_b=rb.eval_time_s)
            for pose, ra, rb in zip(poses, *results, strict=True)]
    both = [(ra, rb) for ra, rb in zip(*results, strict=True) if ra.viable and rb.viable]
    return Agreement(
        poses=len(poses),
        same_outcome=sum(r.outcome_a == r.outcome_b for r in rows),
        both_viable=len(both),
        same_digits_when_both_viable=sum(_digits(ra) == _digits(rb) for ra, rb in both),
        viable_a=sum(r.viable for r in results[0]),
        viable_b=sum(r.viable for r in results[1]),
        rows=rows)
