"""The FastAPI application: ``create_app`` wires settings, database, routes, errors and the worker pool."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles
from starlette.middleware.base import BaseHTTPMiddleware
from starlette.requests import Request
from starlette.responses import JSONResponse, Response

from app import errors
from app.config import Settings, get_settings, software_version
from app.pool import WorkerPool
from app.routes import api_router
from storage.db import make_engine, upgrade

log = logging.getLogger(__name__)
STATIC = Path(__file__).resolve().parents[1] / "static"


def configure_logging(settings: Settings) -> None:
    """Send bodyscan's log records to stderr at the configured level (only the app entry does this)."""
    logging.basicConfig(level=settings.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(processName)s %(name)s: %(message)s")


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the app. The lifespan migrates the database to the newest schema and starts the workers."""
    settings = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        engine = make_engine(settings.db_url)
        upgrade(engine)
        app.state.engine = engine
        log.info("database %s ready", engine.url.render_as_string(hide_password=True))
        pool = app.state.pool = WorkerPool(settings).start() if settings.workers else None
        try:
            yield
        finally:
            if pool is not None:
                pool.stop()
            engine.dispose()

    app = FastAPI(title="bodyscan", version=software_version(), lifespan=lifespan,
                  description="Animal body measurement from one camera and a stripe projector: records, "
                              "calibration and scan jobs, picked and manual measurements, CSV export.")
    app.state.settings = settings
    app.add_middleware(BaseHTTPMiddleware, dispatch=_limit_body(settings.max_upload_bytes))
    errors.install(app)
    app.include_router(api_router, prefix="/api")
    if (STATIC / "index.html").is_file():  # the technician's web page, when it is shipped
        app.mount("/", StaticFiles(directory=STATIC, html=True), name="static")
    return app


def _limit_body(limit: int):
    async def dispatch(request: Request, call_next) -> Response:
        length = request.headers.get("content-length")
        if length is not None and (not length.isdigit() or int(length) > limit):
            size = f"{int(length) / 2**20:.1f} MB" if length.isdigit() else repr(length)
            return JSONResponse(status_code=413, content={
                "detail": f"upload is {size}, larger than the limit of {limit / 2**20:.0f} MB "
                          "(set BODYSCAN_MAX_UPLOAD_MB to change it)"})
        return await call_next(request)

    return dispatch
