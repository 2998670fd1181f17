"""The draws of a pose's P(success) (pure functions): the seeded start poses of its sequence
under an uncertainty model (shared/specs/uncertainty.py) and what counts as a success.

Below exploration/ and manifolds/: the race plans draws with these (exploration/racing.py)
and /best reads them back (manifolds/p_success.py). The service's workers simulate a draw's
start pose; a model's friction, mass and effort scales are not sent with a pose, so a claim is
made only under a model without them (`simulated`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from graspscape.services.coordinator.mapspace.pose import StoredPose
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.uncertainty import UncertaintyModel, draws, perturbed


def simulated(model: UncertaintyModel) -> bool:
    """Whether the service's draws simulate the whole model (its scales are all 1)."""
    return all(r == (1.0, 1.0) for r in (model.friction_scale, model.mass_scale,
                                          model.effort_scale))


def draw_poses(centre: StoredPose, model: UncertaintyModel, radius_m: float, n: int,
               start: int = 0) -> list[Pose]:
    """The start poses of draws start … start + n − 1 of the centre's sequence."""
    pose = Pose(theta=centre.theta, phi=centre.phi, r=centre.r, roll=centre.roll,
                pitch=centre.pitch, yaw=centre.yaw)
    return [perturbed(pose, d, radius_m) for d in draws(centre.key, model, n, start=start)]


def success_of(centre: StoredPose, drawn: StoredPose) -> bool:
    """Held along the reference trajectory with the centre's grasp type."""
    return drawn.viable and centre.viable and drawn.digits == centre.digits


def outcomes(centre: StoredPose, poses: Sequence[Pose], stored: Mapping[str, StoredPose]
             ) -> list[bool]:
    """The stored draws' successes in draw order, up to the first not stored."""
    out = []
    for q in poses:
        s = stored.get(q.key())
        if s is None:
            break
        out.append(success_of(centre, s))
    return out
