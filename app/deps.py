"""FastAPI dependencies: settings and a database session per request."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Annotated

from fastapi import Depends, Request
from sqlmodel import Session

from app.config import Settings
from storage.db import session_scope


def get_app_settings(request: Request) -> Settings:
    """The settings the application was created with."""
    return request.app.state.settings


def get_db(request: Request) -> Iterator[Session]:
    """A session committed when the route returns, rolled back if it raises.

    Used with ``scope="function"`` so the commit happens before the response is sent: a client that
    reads the job id from a 202 can poll it at once, and a failing commit becomes the response.
    """
    with session_scope(request.app.state.engine) as session:
        yield session


SettingsDep = Annotated[Settings, Depends(get_app_settings)]
DbDep = Annotated[Session, Depends(get_db, scope="function")]
