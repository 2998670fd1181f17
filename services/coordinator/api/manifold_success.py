"""Each large manifold's best grasp by P(success), for the manifold table (/manifolds, its
JSON export and the viewer): the first answer /best?manifold=L gives under rank=p_success, with
its k of n draws, bounds and claim, so the table and /best never disagree."""

from __future__ import annotations

from graspscape.services.coordinator.manifolds import best as ranking
from graspscape.services.coordinator.manifolds import p_success
from graspscape.services.coordinator.manifolds.grouping import label_name as manifold_name
from graspscape.services.coordinator.manifolds.p_success import SuccessOut
from pydantic import BaseModel, Field
from sqlalchemy.orm import Session


class ManifoldSuccess(BaseModel):
    """A large manifold's best grasp by P(success): what /best?manifold=L answers first."""

    pose_key: str
    success: SuccessOut | None = Field(description="its P(success) under the exploration's "
                                       "uncertainty model; null where nothing was drawn")


def manifold_successes(session: Session, exploration_id: int,
                       labels: list[int]) -> dict[str, ManifoldSuccess]:
    """The first answer of /best?manifold=L (rank p_success) of each label, with P(success)."""
    firsts = {}
    for number in labels:
        rows = ranking.best_poses(session, exploration_id, label=number, limit=1,
                                  rank=ranking.Rank.P_SUCCESS)
        if rows:
            firsts[manifold_name(number)] = rows[0].pose_key
    chances = p_success.estimates(session, exploration_id, firsts.values()) if firsts else {}
    return {name: ManifoldSuccess(pose_key=key, success=chances.get(key))
            for name, key in firsts.items()}
