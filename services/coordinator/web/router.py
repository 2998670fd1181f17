"""The viewer's page and assets: `/` is the single page (its hash routes pick the view:
explorations, one exploration, submit, workers), `/static/…` its script, style and the
vendored three.js (version and licence in static/vendor/)."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, FastAPI
from fastapi.responses import FileResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles

STATIC_DIR = Path(__file__).with_name("static")

router = APIRouter(include_in_schema=False)


@router.get("/")
def index() -> FileResponse:
    # no-cache: a stale page after an upgrade would talk to routes that changed.
    return FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-cache"})


@router.get("/viewer")
def viewer() -> RedirectResponse:
    return RedirectResponse("/")


def mount_static(app: FastAPI) -> None:
    app.include_router(router)
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
