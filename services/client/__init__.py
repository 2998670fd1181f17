"""The Python client of the coordinator's REST API (httpx, pydantic; no server or worker code).

`Client` submits, waits, reads progress, the best grasps, manifolds and poses as typed objects
(4×4 numpy transforms), downloads exports and retries failed tiles; docs/howto/client.md.
Its names load on first use, so that the `graspscape` command's --help, which registers the
client's subcommands, stays instant.
"""

from __future__ import annotations

import importlib
from typing import Any

_WHERE = {
    **dict.fromkeys(("EXPORTS", "ApiError", "Client", "object_file_name"), "http"),
    **dict.fromkeys(("Best", "Exploration", "FailedTile", "Manifold", "Manifolds", "Pose",
                     "Retried", "StoredObject", "Submitted", "Success"), "models"),
}
__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
