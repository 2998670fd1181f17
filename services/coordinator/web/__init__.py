"""The web viewer the coordinator serves at `/`: static pages, live progress, grasp pictures.

`mount(app)` adds it to an app: the page and its assets (`router.py`, `static/`, three.js
vendored from npm, no CDN, no build step), the server-sent progress events (`events.py`),
the few read-only JSON shapes the pages need beyond the REST API (`data.py`) and the best-grasp
picture (`grasp.py`, drawn by the workers' renderer where `services/local` wires one in).
None of these routes are in the OpenAPI document: they serve the pages, not API clients.
"""

from __future__ import annotations

from fastapi import FastAPI


def mount(app: FastAPI) -> None:
    """Serve the viewer from `app` (after the API routes, so those keep their paths)."""
    from graspscape.services.coordinator.web import data, events, grasp, router

    app.include_router(events.router)
    app.include_router(data.router)
    app.include_router(grasp.router)
    router.mount_static(app)
