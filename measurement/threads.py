"""A scan's threads: the second core, detection's band threads, and BLAS on one thread during a scan.

NumPy's OpenBLAS splits a matrix product over every core once it is large enough (a 10^4-row scatter
matrix, a 10^5-row point-to-plane product). A scan's products are many and small: the second thread's
start and its busy wait cost far more than the arithmetic (a background-plane fit took 14.5 ms of CPU
with two threads, 1.9 ms with one), and on a machine with other work it waits for a core. A scan runs
its products on one thread; its own parallel parts are threads of their own: detection's bands, and the
second core, which takes the steps that can run beside the main one (segment linking, halves of large
compiled loops). Both pools are shared by the scans of a process and restart in a forked child.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from typing import TypeVar

T = TypeVar("T")

_SECOND = "bodyscan-second"


class SecondCore:
    """One worker thread for the parts of a scan that can run beside the main one (the compiled kernels and
    large NumPy operations release the interpreter). A task submitted from that thread itself runs at once
    in it: waiting for the one worker from inside it would never end."""

    def __init__(self) -> None:
        self._pool = ThreadPoolExecutor(1, thread_name_prefix=_SECOND)

    def submit(self, fn: Callable[..., T], /, *args, **kwargs) -> Future[T]:
        if not threading.current_thread().name.startswith(_SECOND):
            return self._pool.submit(fn, *args, **kwargs)
        done: Future[T] = Future()
        try:
            done.set_result(fn(*args, **kwargs))
        except BaseException as error:  # handed to the caller by result(), as the pool would
            done.set_exception(error)
        return done


_controller = None
_executor: SecondCore | None = None
_bands: ThreadPoolExecutor | None = None


def second_core() -> SecondCore:
    """The scan's ``SecondCore``, started on first use."""
    global _executor
    if _executor is None:
        _executor = SecondCore()
    return _executor


def band_workers(workers: int) -> ThreadPoolExecutor:
    """The threads detection's bands of rows run on, started on first use and kept (starting and joining
    four threads on every scan cost 0.4 ms). Shared by concurrent scans: their bands queue."""
    global _bands
    if _bands is None:
        _bands = ThreadPoolExecutor(workers, thread_name_prefix="bodyscan-bands")
    return _bands


def _forget_threads() -> None:
    """In a child process forked after a scan the pools' threads do not exist: start new ones on first use
    (a pool that counts its dead threads as running never starts a task). Scans open in the parent's other
    threads are not running here: no BLAS limit is held, and the lock starts free."""
    global _executor, _bands, _blas_lock, _blas_users, _blas_limit
    _executor = _bands = None
    _blas_lock, _blas_users, _blas_limit = threading.Lock(), 0, None


os.register_at_fork(after_in_child=_forget_threads)


_blas_lock = threading.Lock()
_blas_users = 0
_blas_limit = None  # threadpoolctl's limit while any scan runs


def _limit_blas() -> None:
    """On the second core: BLAS to one thread. threadpoolctl lets one Python thread at a time set the
    OpenBLAS pool's size (process-wide), so the second core, which outlives every scan, always does."""
    global _blas_limit
    assert _controller is not None
    _blas_limit = _controller.limit(limits=1, user_api="blas").__enter__()


def _restore_blas() -> None:
    """On the second core: the BLAS thread counts from before ``_limit_blas``."""
    global _blas_limit
    if _blas_limit is not None:
        _blas_limit.__exit__(None, None, None)
        _blas_limit = None


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """A context in which the BLAS libraries loaded so far use one thread; the previous counts come back when
    the last of the contexts open at once (scans in several threads) is left. Set and restored on the second
    core (so a scan must not itself run as a task of the second core). About 0.1 ms; the libraries are
    looked up once, on the first call (about 1 ms)."""
    global _controller, _blas_users
    with _blas_lock:
        if _controller is None:
            from threadpoolctl import ThreadpoolController

            _controller = ThreadpoolController()
        if _blas_users == 0:
            second_core().submit(_limit_blas).result()
        _blas_users += 1
    try:
        yield
    finally:
        with _blas_lock:
            _blas_users -= 1
            if _blas_users == 0:
                second_core().submit(_restore_blas).result()
