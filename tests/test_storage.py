"""Storage: migrations, engines, blobs and the measurement audit trail, on SQLite and PostgreSQL."""

from __future__ import annotations

import datetime as dt

import pytest
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import text
from sqlmodel import SQLModel

from storage import animals, blobs, measurements, sessions
from storage.db import current_revision, head_revision, make_engine, session_scope, upgrade
from storage.errors import ConflictError, NotFoundError
from storage.models import AnimalCreate, AnimalUpdate, SessionCreate
from tests.backend_support import (
    finished_calibration,
    migrated_engine,
)


def test_migrations_produce_exactly_the_model_schema(engine):
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn, opts={"compare_type": True}), SQLModel.metadata)
    assert diff == []
    assert current_revision(engine) == head_revision()


def test_database_at_first_revision_upgrades_and_keeps_its_rows(db_url):
    engine = make_engine(db_url)
    upgrade(engine, "0001")
    with engine.begin() as conn:
        conn.execute(text("INSERT INTO animal (tag, species, breed, sex, status, notes, created_at, updated_at) "
                          "VALUES ('A1', 'cattle', '', 'female', 'active', '', :t, :t)"), {"t": dt.datetime(2025, 1, 2)})
        conn.execute(text("INSERT INTO calibration (name, board_cols, board_rows, square_mm, stripes, status, "
                          "created_at) VALUES ('old', 9, 6, 20.0, 40, 'running', :t)"), {"t": dt.datetime(2025, 1, 2)})
        conn.execute(text("INSERT INTO job (kind, status, progress, stage, result_id, created_at) "
                          "VALUES ('calibration', 'running', 0.5, 'planes', 1, :t)"), {"t": dt.datetime(2025, 1, 2)})
    upgrade(engine)
    assert current_revision(engine) == head_revision() != "0001"
    with session_scope(engine) as db:
        assert animals.get_animal(db, 1).tag == "A1"
        job = db.exec(text("SELECT attempts, worker, heartbeat_at, stage FROM job")).one()
    assert tuple(job) == (0, None, None, "planes")
    upgrade(engine)  # idempotent at head
    engine.dispose()


def test_sqlite_runs_in_wal_mode_with_a_busy_timeout(tmp_path):
    engine = migrated_engine(f"sqlite:///{tmp_path / 'x' / 'bodyscan.db'}")
    with engine.connect() as conn:
        assert conn.execute(text("PRAGMA journal_mode")).scalar() == "wal"
        assert conn.execute(text("PRAGMA busy_timeout")).scalar() >= 5000
        assert conn.execute(text("PRAGMA foreign_keys")).scalar() == 1


def test_blobs_round_trip_and_compress_what_compresses(engine):
    raw = b"stripe " * 10_000
    noise = bytes(range(256)) * 4
    with session_scope(engine) as db:
        a, b = blobs.put_blob(db, raw), blobs.put_blob(db, noise)
        assert (a.codec, len(a.data) < len(raw) / 10) == ("zlib", True)
    with session_scope(engine) as db:
        assert blobs.get_bytes(db, a.id) == raw
        assert blobs.get_bytes(db, b.id) == noise
        with pytest.raises(NotFoundError):
            blobs.get_bytes(db, 999)


def test_animal_tags_are_unique_and_animals_with_sessions_cannot_be_deleted(engine):
    cal = finished_calibration(engine)
    with session_scope(engine) as db:
        a = animals.create_animal(db, AnimalCreate(tag=" A7 ", species="Cattle"))
        animals.create_animal(db, AnimalCreate(tag="B1"))
        with pytest.raises(ConflictError, match="'A7' already exists"):
            animals.create_animal(db, AnimalCreate(tag="A7"))
        with pytest.raises(ConflictError, match="already exists"):
            animals.update_animal(db, a.id, AnimalUpdate(tag="B1"))
        assert [x.tag for x in animals.list_animals(db, species="cattle")] == ["A7"]
        sessions.create_session(db, SessionCreate(animal_id=a.id, calibration_id=cal))
    with session_scope(engine) as db, pytest.raises(ConflictError, match="1 session"):
        animals.delete_animal(db, a.id)


def test_measurement_changes_are_appended_and_the_history_kept(engine):
    cal = finished_calibration(engine)
    with session_scope(engine) as db:
        animal = animals.create_animal(db, AnimalCreate(tag="H1"))
        sid = sessions.create_session(db, SessionCreate(animal_id=animal.id, calibration_id=cal)).id
        first = measurements.add_measurement(db, session_id=sid, name="heart_girth", kind="manual",
                                             value_mm=1800.0, created_by="ann")
        other = measurements.add_measurement(db, session_id=sid, name="tail_length", kind="manual", value_mm=700.0)
    with session_scope(engine) as db:
        second = measurements.revise_measurement(db, first.id, value_mm=1810.0, created_by="bob", note="re-taped")
        measurements.delete_measurement(db, other.id, by="bob", note="wrong animal")
    with session_scope(engine) as db:
        current = measurements.current_measurements(db, [sid])
        assert [(m.name, m.value_mm, m.revision) for m in current] == [("heart_girth", 1810.0, 2)]
        trail = measurements.history(db, first.id)
        assert [(m.value_mm, m.created_by) for m in trail] == [(1800.0, "ann"), (1810.0, "bob")]
        assert measurements.history(db, second.id) == trail
        assert len(measurements.session_history(db, sid)) == 4
        with pytest.raises(NotFoundError):
            measurements.revise_measurement(db, other.id, value_mm=1.0)


def _upgrade_in_process(url: str) -> None:
    upgrade(make_engine(url))


def test_processes_starting_together_migrate_one_after_the_other(db_url):
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    procs = [ctx.Process(target=_upgrade_in_process, args=(db_url,)) for _ in range(3)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
    assert [p.exitcode for p in procs] == [0, 0, 0]
    assert current_revision(make_engine(db_url)) == head_revision()
