"""The draws of a pose's P(success) (pure functions): the seeded start poses and scales of its
sequence under an uncertainty model (shared/specs/uncertainty.py) and what counts as a
success.

Below exploration/ and manifolds/: the race plans draws with these (exploration/racing.py)
and /best reads them back (manifolds/p_success.py). The service's workers evaluate a draw
outcome only, at its start pose, under its friction, mass and effort scales, in each engine
the model lists (workers/sim/samples.py); a draw succeeds where it held with the centre's
grasp type in every one of them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from graspscape.services.coordinator.mapspace.pose import StoredPose
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import DrawScales
from graspscape.shared.specs.uncertainty import UncertaintyModel, draw, draws, perturbed


def draw_poses(centre: StoredPose, model: UncertaintyModel, radius_m: float, n: int,
               start: int = 0) -> list[Pose]:
    """The start poses of draws start … start + n − 1 of the centre's sequence."""
    pose = Pose(theta=centre.theta, phi=centre.phi, r=centre.r, roll=centre.roll,
                pitch=centre.pitch, yaw=centre.yaw)
    return [perturbed(pose, d, radius_m) for d in draws(centre.key, model, n, start=start)]


def scales_of(centre_key: str, model: UncertaintyModel, i: int) -> DrawScales:
    """Draw i's friction, mass and effort scales (the worker applies them)."""
    d = draw(centre_key, model, i)
    return DrawScales(friction=d.friction_scale, mass=d.mass_scale, effort=d.effort_scale)


def success_of(centre: StoredPose, drawn: StoredPose,
               engines: Sequence[str] | None = None) -> bool:
    """Held along the reference trajectory with the centre's grasp type — in each of
    `engines` where the draw was evaluated outcome only (its per-engine record); an engine
    it did not run in is a failure, so a claim never stands for an engine it was not
    simulated in."""
    if not (centre.viable and drawn.viable):
        return False
    if not drawn.engines:
        return drawn.digits == centre.digits
    wanted = engines if engines is not None else tuple(drawn.engines)
    return all(name in drawn.engines and drawn.engines[name] == (True, centre.digits)
               for name in wanted)


def outcomes(centre: StoredPose, poses: Sequence[Pose], stored: Mapping[str, StoredPose],
             engines: Sequence[str] | None = None) -> list[bool]:
    """The stored draws' successes in draw order, up to the first not stored."""
    out = []
    for q in poses:
        s = stored.get(q.key())
        if s is None:
            break
        out.append(success_of(centre, s, engines))
    return out


def engines_of(poses: Sequence[Pose], stored: Mapping[str, StoredPose], default: str
               ) -> tuple[str, ...]:
    """The engines every stored draw among `poses` ran in (`default`, the exploration's
    engine, for a draw evaluated in full)."""
    found: set[str] | None = None
    for q in poses:
        s = stored.get(q.key())
        if s is None:
            break
        names = set(s.engines) or {default}
        found = names if found is None else found & names
    return tuple(sorted(found or ()))
