"""P(success) of the poses the certification drew around: /best's default ranking.

A pose's draws are the stored poses of its seeded sequence under the exploration's
uncertainty model (mapspace/draws.py); read in draw order, they give k of n and the
sequential rule's anytime-valid bounds (mapspace/success.py). `rank=p_success` ranks the
poses with draws by their lower bound (then k/n, μs, key), and the poses without draws after
them in the robust order (they have no P(success) to rank by).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from graspscape.services.coordinator.manifolds.grouping import FALLBACK_RADIUS, surface_radii
from graspscape.services.coordinator.mapspace import draws, success
from graspscape.services.coordinator.mapspace.samples import (
    lattice_of,
    load_samples,
    stored_by_key,
)
from graspscape.services.coordinator.mapspace.specs import spec_of
from graspscape.services.coordinator.objects.geometry import object_mesh
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow
from graspscape.shared.specs.uncertainty import UncertaintyModel
from pydantic import BaseModel, Field
from sqlalchemy import select
from sqlalchemy.orm import Session


class SuccessOut(BaseModel):
    """A pose's P(success) under the exploration's uncertainty model."""

    k: int = Field(description="draws held with the pose's grasp type")
    n: int = Field(description="draws of the uncertainty model evaluated")
    p: float = Field(description="k / n")
    lower: float = Field(description="anytime-valid 95 % lower bound (Clopper–Pearson with "
                         "Bonferroni spending over the looks 12, 24, 48, 96)")
    upper: float = Field(description="anytime-valid 95 % upper bound")
    certified: bool = Field(description="lower ≥ the certification level at 95 % under the "
                            "stated model")
    engines: list[str] = Field(
        default_factory=list, description="the physics engines every draw was simulated in "
        "and held in with the pose's grasp type to count as a success")


def model_of(session: Session, exploration_id: int) -> tuple[UncertaintyModel, float]:
    spec = spec_of(session.get(ExplorationRow, exploration_id))
    return spec.uncertainty, spec.certification.level


def estimates(session: Session, exploration_id: int,
              keys: Iterable[str] | None = None) -> dict[str, SuccessOut]:
    """P(success) of every pose with draws (or of those among `keys`), by pose key."""
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        return {}
    query = select(PoseRow.certifies).where(PoseRow.exploration_id == exploration_id,
                                            PoseRow.certifies.is_not(None)).distinct()
    centres = set(session.scalars(query))
    if keys is not None:
        centres &= set(keys)
    if not centres:
        return {}
    spec = spec_of(row)
    lattice = lattice_of(spec)
    samples = load_samples(session, exploration_id, lattice, centres)
    mesh = object_mesh(session, row.object_id)
    seqs = {}
    for p, s in samples.items():
        radius = float(surface_radii(mesh, np.array([lattice.direction(p)]), FALLBACK_RADIUS)[0])
        seqs[s.key] = (s, draws.draw_poses(s, spec.uncertainty, radius, success.LOOKS[-1]))
    keys_drawn = [q.key() for _, seq in seqs.values() for q in seq]
    stored = stored_by_key(session, exploration_id, keys_drawn)
    level, engines = spec.certification.level, spec.draw_engines()
    out = {}
    for key, (centre, seq) in seqs.items():
        e = success.estimate(draws.outcomes(centre, seq, stored, engines), level=level)
        if e.n:
            ran = draws.engines_of(seq, stored, spec.settings.engine)
            out[key] = SuccessOut(k=e.k, n=e.n, p=e.p, lower=e.lower, upper=e.upper,
                                  certified=e.certified,
                                  engines=[x for x in engines if x in ran])
    return out


def confirmed(est: dict[str, SuccessOut], engines: Iterable[str]) -> dict[str, SuccessOut]:
    """The estimates whose draws were all simulated, and counted, in each of `engines`."""
    wanted = set(engines)
    return {k: e for k, e in est.items() if wanted <= set(e.engines)}
