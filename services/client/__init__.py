"""The Python client of the coordinator's REST API (httpx, pydantic; no server or worker code).

`Client` submits, waits, reads progress, the best grasps, manifolds and poses as typed objects
(4×4 numpy transforms), downloads exports and retries failed tiles; docs/client.md.
"""

from graspscape.services.client.http import EXPORTS, ApiError, Client, object_file_name
from graspscape.services.client.models import (
    Best,
    Exploration,
    FailedTile,
    Manifold,
    Manifolds,
    Pose,
    Retried,
    StoredObject,
    Submitted,
)

__all__ = ["EXPORTS", "ApiError", "Best", "Client", "Exploration", "FailedTile", "Manifold",
           "Manifolds", "Pose", "Retried", "StoredObject", "Submitted", "object_file_name"]
