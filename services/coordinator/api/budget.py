"""Route for what an exploration spent and found: GET /explorations/{id}/budget, counted one
way for every strategy (exploration/accounting.py)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path
from graspscape.services.coordinator.api.deps import SessionDep
from graspscape.services.coordinator.api.finite import FiniteJSONRoute
from graspscape.services.coordinator.api.responses import error
from graspscape.services.coordinator.exploration.accounting import (
    ExplorationBudget,
    exploration_budget,
)

router = APIRouter(tags=["explorations"], route_class=FiniteJSONRoute)

Id = Annotated[int, Path(ge=1, le=2**31 - 1, description="exploration id")]


@router.get(
    "/explorations/{exploration_id}/budget",
    response_model=ExplorationBudget,
    responses={404: error("no such exploration")},
    summary="Evaluations, wall time, best quality, grasp types, grasps, misses and the times to "
    "the first grasp and to within 5 % of the best, the same for every strategy",
)
def get_budget(exploration_id: Id, session: SessionDep) -> Any:
    return exploration_budget(session, exploration_id)
