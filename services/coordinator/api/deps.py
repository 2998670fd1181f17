"""Request dependencies: a database session per request, the settings, the bearer token."""

from __future__ import annotations

import secrets
from collections.abc import AsyncIterator
from typing import Annotated

import anyio.to_thread
from anyio import CancelScope, CapacityLimiter
from fastapi import Depends, HTTPException, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from graspscape.services.coordinator.settings import Settings
from sqlalchemy.orm import Session

_bearer = HTTPBearer(auto_error=False, description="needed on mutating routes when configured")


def get_settings_dep(request: Request) -> Settings:
    return request.app.state.settings


async def get_session(request: Request) -> AsyncIterator[Session]:
    """A session per request. Made on the event loop: a new Session touches no connection
    (one is checked out at its first statement, in the route's thread), so entering it in a
    worker thread, as a sync generator dependency is, was a thread hop for nothing (issue 21).
    Closing it returns the connection (a rollback: I/O), so that stays in a thread, with its
    own limiter and shielded from cancellation as FastAPI closes a sync dependency: waiting
    for a token of the shared thread pool while routes hold them all, waiting for this
    connection, would deadlock."""
    session = request.app.state.sessionmaker()
    try:
        yield session
    finally:
        with CancelScope(shield=True):
            await anyio.to_thread.run_sync(session.close, limiter=CapacityLimiter(1))


def require_token(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> None:
    """Mutating routes: with settings.api.token set, demand that token (constant-time compare)."""
    token = request.app.state.settings.api.token
    if token is None:
        return
    given = credentials.credentials if credentials is not None else ""
    if not secrets.compare_digest(given.encode(), token.get_secret_value().encode()):
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            detail="missing or wrong bearer token (Authorization: Bearer <api_token>)",
            headers={"WWW-Authenticate": "Bearer"},
        )


SessionDep = Annotated[Session, Depends(get_session)]
SettingsDep = Annotated[Settings, Depends(get_settings_dep)]
Mutating = [Depends(require_token)]
