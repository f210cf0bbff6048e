"""The worker processes that ``bodyscan serve`` runs beside the web server, kept alive by a supervisor.

A worker that dies (killed for memory by a huge upload, a crash in native code) is started again, at
most ``MAX_RESTARTS`` times a minute; its running job is re-queued by the next worker that polls.
"""

from __future__ import annotations

import logging
import multiprocessing
import threading
import time
from collections import deque

from app.config import Settings
from app.jobs import run_worker

log = logging.getLogger(__name__)
MAX_RESTARTS = 10
CHECK_S = 2.0


def _worker_main(settings_json: str) -> None:
    from app.main import configure_logging

    settings = Settings.model_validate_json(settings_json)
    configure_logging(settings)
    run_worker(settings)


class WorkerPool:
    """``settings.workers`` spawned worker processes (they share nothing with the server)."""

    def __init__(self, settings: Settings, check_s: float = CHECK_S) -> None:
        self.settings, self.check_s = settings, check_s
        self._ctx = multiprocessing.get_context("spawn")
        self._procs: list[multiprocessing.Process] = []
        self._restarts: deque[float] = deque()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._watcher = threading.Thread(target=self._watch, name="worker-pool", daemon=True)

    def start(self) -> WorkerPool:
        with self._lock:
            self._procs = [self._spawn(i) for i in range(self.settings.workers)]
        self._watcher.start()
        return self

    def alive(self) -> int:
        """How many worker processes are running."""
        with self._lock:
            return sum(p.is_alive() for p in self._procs)

    def pids(self) -> list[int | None]:
        with self._lock:
            return [p.pid for p in self._procs]

    def stop(self, timeout_s: float = 10.0) -> None:
        """SIGTERM the workers (a running job goes back to the queue), then kill stragglers."""
        self._stop.set()
        if self._watcher.is_alive():
            self._watcher.join()
        with self._lock:
            procs = list(self._procs)
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
        deadline = time.monotonic() + timeout_s
        for proc in procs:
            proc.join(max(deadline - time.monotonic(), 0.1))
            if proc.is_alive():
                log.warning("worker %s did not stop in time; killing it", proc.name)
                proc.kill()
                proc.join(1.0)

    def _spawn(self, index: int) -> multiprocessing.Process:
        proc = self._ctx.Process(target=_worker_main, args=(self.settings.model_dump_json(),),
                                 name=f"bodyscan-worker-{index + 1}", daemon=True)
        proc.start()
        return proc

    def _watch(self) -> None:
        while not self._stop.wait(self.check_s):
            with self._lock:
                for i, proc in enumerate(self._procs):
                    if proc.is_alive() or self._stop.is_set():
                        continue
                    log.warning("worker %s exited with code %s", proc.name, proc.exitcode)
                    if self._may_restart():
                        self._procs[i] = self._spawn(i)

    def _may_restart(self) -> bool:
        now = time.monotonic()
        while self._restarts and now - self._restarts[0] > 60:
            self._restarts.popleft()
        if len(self._restarts) >= MAX_RESTARTS:
            log.error("workers keep dying (%d restarts in a minute); not restarting — check the log", MAX_RESTARTS)
            return False
        self._restarts.append(now)
        return True
