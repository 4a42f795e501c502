"""Single-threaded BLAS for work made of many small products."""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator

_STARTED_SINGLE_THREADED = [False]
"""Whether this process started its BLAS libraries with one thread (:func:`started_single_threaded`)."""


def started_single_threaded() -> None:
    """Note that every BLAS library of this process starts with one thread.

    Called by the command line, which sets the BLAS thread variables before numpy is loaded
    (``aacmm_pin.cli.one_blas_thread_at_start``): :func:`single_threaded_blas` then has nothing
    to limit and skips ``threadpoolctl`` (importing it and finding the libraries: ~20 ms of each
    ``identify``).
    """
    _STARTED_SINGLE_THREADED[0] = True


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Limit BLAS to one thread in this block (when called from a main thread).

    Small products (hundreds of columns) gain nothing from BLAS threads, and spinning threads on a
    few busy cores slow them down many times (measured 10-26x on 2 loaded cores). The limit is
    process-wide: it is set only from a main thread (serial, or a worker process), never from the
    threads of a thread pool, which would undo each other's limits.
    """
    if _STARTED_SINGLE_THREADED[0] or threading.current_thread() is not threading.main_thread():
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        yield
