"""``bodyscan serve`` and ``bodyscan worker``: the web service and the job workers."""

from __future__ import annotations

import argparse
import logging

from app.config import Settings, get_settings

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``serve`` and ``worker`` commands to the bodyscan command line."""
    s = sub.add_parser("serve", help="run the web service (REST API, /docs) with a pool of job workers",
                       description="Serve the REST API. BODYSCAN_DATABASE_URL selects the database, otherwise "
                                   "a SQLite file in BODYSCAN_DATA_DIR (default ./data) is used; the schema is "
                                   "migrated at start.")
    s.add_argument("--host", default="127.0.0.1", help="interface to listen on (default 127.0.0.1)")
    s.add_argument("--port", type=int, default=8000, help="TCP port (default 8000)")
    s.add_argument("--workers", type=int, default=None,
                   help="job worker processes to start with the server (default BODYSCAN_WORKERS or 2; "
                        "0 when separate `bodyscan worker` processes take the jobs)")
    s.set_defaults(func=cmd_serve)

    w = sub.add_parser("worker", help="take calibration and scan jobs from the database until stopped",
                       description="Claim and run jobs from the database given by BODYSCAN_DATABASE_URL; run "
                                   "as many as you like, on any machine that reaches the database.")
    w.add_argument("--once", action="store_true", help="run the queued jobs, then exit")
    w.set_defaults(func=cmd_worker)


def _settings(**overrides) -> Settings:
    settings = get_settings()
    changes = {k: v for k, v in overrides.items() if v is not None}
    return settings.model_copy(update=changes) if changes else settings


def cmd_serve(args: argparse.Namespace) -> None:
    import uvicorn

    from app.main import configure_logging, create_app

    settings = _settings(workers=args.workers)
    configure_logging(settings)
    print(f"bodyscan serving on http://{args.host}:{args.port} (API docs at /docs), "  # noqa: T201
          f"{settings.workers} worker process(es)", flush=True)
    uvicorn.run(create_app(settings), host=args.host, port=args.port, log_level=settings.log_level.lower())


def cmd_worker(args: argparse.Namespace) -> None:
    from app.jobs import run_until_idle, run_worker
    from app.main import configure_logging
    from storage.db import make_engine, upgrade

    settings = _settings()
    configure_logging(settings)
    if args.once:
        engine = make_engine(settings.db_url)
        upgrade(engine)
        count = run_until_idle(engine, settings)
        print(f"ran {count} job(s)")  # noqa: T201
        return
    run_worker(settings)
