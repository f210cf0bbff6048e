"""Builders shared by the backend tests (storage, jobs, API): settings, clients, databases, records.

PostgreSQL: ``BODYSCAN_TEST_POSTGRES_URL`` names a server (``.ci/run`` exports it from
``.ci/postgres.sh start``); without it the tests start a private server with ``.ci/postgres.sh`` and
stop it at exit. Each test gets a fresh database on that server. When no server can be started the
PostgreSQL tests are skipped with the reason.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import io
import os
import socket
import subprocess
import tempfile
import uuid
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest
from sqlalchemy import create_engine, text
from sqlalchemy.engine import make_url

from app.config import Settings
from storage.db import make_engine, normalize_url, session_scope, upgrade

ROOT = Path(__file__).resolve().parents[1]


def settings_for(tmp_path: Path, database_url: str | None = None, **overrides) -> Settings:
    """Settings of a test service: its own SQLite file (or ``database_url``), no worker processes."""
    return Settings(database_url=database_url, data_dir=tmp_path, workers=0, **overrides)


def migrated_engine(url: str):
    engine = make_engine(url)
    upgrade(engine)
    return engine


def png(width: int = 64, height: int = 48, value: int = 128) -> bytes:
    """A small valid gray PNG."""
    img = np.full((height, width), value, np.uint8)
    img[::7] = 255 - value
    ok, buf = cv2.imencode(".png", img)
    assert ok
    return buf.tobytes()


def zip_bytes(files: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name, data in files.items():
            zf.writestr(name, data)
    return buf.getvalue()


# --- PostgreSQL --------------------------------------------------------------------------------------


@functools.cache
def postgres_server() -> tuple[str | None, str]:
    """(URL of a running PostgreSQL server or None, reason when None)."""
    url = os.environ.get("BODYSCAN_TEST_POSTGRES_URL")
    if url:
        return normalize_url(url), ""
    script = ROOT / ".ci" / "postgres.sh"
    env = dict(os.environ, BODYSCAN_PG_DIR=tempfile.mkdtemp(prefix="bodyscan-pg-"), BODYSCAN_PG_PORT=str(_free_port()))
    try:
        out = subprocess.run([str(script), "start"], env=env, capture_output=True, text=True, timeout=300)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return None, f"PostgreSQL could not be started ({exc}); set BODYSCAN_TEST_POSTGRES_URL"
    if out.returncode != 0:
        tail = (out.stderr.strip().splitlines() or ["no output"])[-1]
        return None, f"PostgreSQL could not be started by .ci/postgres.sh: {tail}"
    atexit.register(subprocess.run, [str(script), "stop"], env=env, capture_output=True, timeout=60)
    url = out.stdout.strip().splitlines()[-1].split("=", 1)[1]
    return normalize_url(url), ""


def fresh_postgres_database(migrated: bool = False) -> str:
    """URL of a new database on the test server, empty or (copied from a template) at the newest schema.

    Skips the test when there is no server.
    """
    server, reason = postgres_server()
    if server is None:
        pytest.skip(reason)
    name = f"t_{uuid.uuid4().hex[:12]}"
    template = f' TEMPLATE "{_migrated_template()}"' if migrated else ""
    admin = create_engine(server, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f'CREATE DATABASE "{name}"{template}'))
    admin.dispose()
    return make_url(server).set(database=name).render_as_string(hide_password=False)


@functools.cache
def _migrated_template() -> str:
    """A database at the newest schema to copy from (migrating each test database costs ~0.5 s)."""
    url = fresh_postgres_database()
    engine = migrated_engine(url)
    engine.dispose()  # a template must have no open connections
    atexit.register(drop_postgres_database, url)
    return make_url(url).database


def drop_postgres_database(url: str) -> None:
    server, _ = postgres_server()
    name = make_url(url).database
    admin = create_engine(server, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
    admin.dispose()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# --- records -----------------------------------------------------------------------------------------


def finished_calibration(engine, image_size=(640, 427)) -> int:
    """A calibration record whose job succeeded (stored result with the image size only)."""
    from storage import calibrations
    from storage.jobs import claim_next, finish_job

    with session_scope(engine) as db:
        record, job = calibrations.create_calibration(
            db, {"board_cols": 9, "board_rows": 6, "square_mm": 20.0, "stripes": 40}, {"pose_01_board.png": png()})
    claimed = claim_next(engine, "test:1")
    assert claimed.id == job.id
    with session_scope(engine) as db:
        calibrations.store_result(db, record.id, {"image_size": list(image_size)})
        assert finish_job(db, job.id, "test:1")
    return record.id


def scan_with_cloud(engine, session_id: int, points, stripe, uv, measurements=None) -> int:
    """A scan of ``session_id`` whose job succeeded with the given cloud arrays (mm, px)."""
    from storage import sessions
    from storage.jobs import claim_next, finish_job

    with session_scope(engine) as db:
        scan, job = sessions.create_scan(db, session_id, "side", "side.png", png())
    claimed = claim_next(engine, "test:2")
    assert claimed.id == job.id
    with session_scope(engine) as db:
        sessions.store_scan_result(db, scan.id, {"points": points, "stripe": stripe, "uv": uv},
                                   measurements or {"point_count": len(points)})
        assert finish_job(db, job.id, "test:2")
    return scan.id


@contextlib.contextmanager
def backend_client(backend: str, tmp_path: Path, **overrides):
    """A TestClient of the app on a fresh SQLite file or PostgreSQL database (dropped afterwards)."""
    from fastapi.testclient import TestClient

    from app.main import create_app

    url = fresh_postgres_database(migrated=True) if backend == "postgresql" else None
    try:
        with TestClient(create_app(settings_for(tmp_path, url, **overrides)), raise_server_exceptions=False) as client:
            yield client
    finally:
        if url:
            drop_postgres_database(url)


# --- database fixtures shared by the storage and job tests (import them into the test module) ------

@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request, tmp_path):
    """A SQLite file, and a fresh database on the test PostgreSQL server (skipped when there is none)."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'bodyscan.db'}"
        return
    url = fresh_postgres_database()
    yield url
    drop_postgres_database(url)


@pytest.fixture
def engine(db_url):
    """An engine on ``db_url`` migrated to the newest schema."""
    engine = migrated_engine(db_url)
    yield engine
    engine.dispose()
