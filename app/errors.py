"""The one place where core and storage errors become HTTP responses.

Every error body is ``{"detail": "<message a technician can act on>"}``; request validation errors keep
FastAPI's list form under ``detail`` and add a one-line ``message`` naming the fields.
"""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import DataError, IntegrityError, OperationalError

from measurement.errors import MeasurementError
from storage.errors import ConflictError, InvalidInputError, NotFoundError

log = logging.getLogger(__name__)


class UploadTooLarge(Exception):
    """A request body or one uploaded file exceeds the configured limit (413)."""


class BadUpload(Exception):
    """An upload is malformed before the core sees it: missing/duplicate files, a bad form field (422)."""


def _detail(status: int, message: str) -> JSONResponse:
    return JSONResponse(status_code=status, content={"detail": message})


def install(app: FastAPI) -> None:
    """Register the exception handlers on ``app``."""

    @app.exception_handler(NotFoundError)
    async def not_found(_: Request, exc: NotFoundError) -> JSONResponse:
        return _detail(404, str(exc))

    @app.exception_handler(ConflictError)
    async def conflict(_: Request, exc: ConflictError) -> JSONResponse:
        return _detail(409, str(exc))

    @app.exception_handler(UploadTooLarge)
    async def too_large(_: Request, exc: UploadTooLarge) -> JSONResponse:
        return _detail(413, str(exc))

    @app.exception_handler(BadUpload)
    @app.exception_handler(InvalidInputError)
    @app.exception_handler(MeasurementError)
    async def unprocessable(_: Request, exc: Exception) -> JSONResponse:
        return _detail(422, str(exc))

    @app.exception_handler(OverflowError)
    async def overflow(_: Request, exc: OverflowError) -> JSONResponse:
        return _detail(422, "a number in the request is too large (ids and counts are 64-bit integers)")

    @app.exception_handler(DataError)
    async def data_error(_: Request, exc: DataError) -> JSONResponse:
        log.info("value refused by the database: %s", exc.orig)
        return _detail(422, "a value in the request does not fit the database (number too large or text too long)")

    @app.exception_handler(IntegrityError)
    async def integrity(_: Request, exc: IntegrityError) -> JSONResponse:
        log.warning("integrity error: %s", exc.orig)
        return _detail(409, "the change conflicts with stored records (duplicate or still referenced); nothing was changed")

    @app.exception_handler(OperationalError)
    async def database_busy(_: Request, exc: OperationalError) -> JSONResponse:
        log.error("database error: %s", exc.orig)
        return JSONResponse(status_code=503, headers={"Retry-After": "5"},
                            content={"detail": "the database is unavailable or busy; try again shortly"})

    @app.exception_handler(Exception)
    async def unexpected(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unexpected error on %s %s", request.method, request.url.path)
        return _detail(500, f"internal error ({type(exc).__name__}); nothing was changed. This is a bug in "
                            "bodyscan: please report it with the server log")

    @app.exception_handler(RequestValidationError)
    async def invalid_request(_: Request, exc: RequestValidationError) -> JSONResponse:
        errors = exc.errors()
        parts = [f"{'.'.join(str(p) for p in e['loc'] if p != 'body')}: {e['msg']}" for e in errors]
        return JSONResponse(status_code=422, content={"detail": _jsonable(errors), "message": "; ".join(parts)})


def _jsonable(errors: list[dict]) -> list[dict]:
    # "input" can be a whole uploaded file and "ctx" holds exception objects: keep loc, msg, type.
    return [{"loc": list(e["loc"]), "msg": e["msg"], "type": e["type"]} for e in errors]
