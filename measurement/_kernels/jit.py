"""How the kernels are compiled: ``njit`` without Python exceptions for x / 0, cached on disk where
numba finds a writable place."""

from __future__ import annotations

import logging
import os

from numba import njit

_log = logging.getLogger(__name__)
_OPTIONS = {"nogil": True, "error_model": "numpy"}  # numpy: x / 0 is inf or NaN, no exception
_UNCACHED: list[str] = []  # kernels compiled without a cache


def compiled(fn):
    """``njit`` with an on-disk cache when numba finds a writable place for one."""
    try:
        return njit(cache=True, **_OPTIONS)(fn)
    except RuntimeError:  # numba: "cannot cache function ...: no locator available"
        if not _UNCACHED:
            _log.warning("numba finds no writable cache directory for %s: the kernels compile on each start "
                         "(set NUMBA_CACHE_DIR)", os.path.dirname(__file__))
        _UNCACHED.append(fn.__name__)
        return njit(**_OPTIONS)(fn)
