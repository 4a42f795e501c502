"""Single-threaded BLAS for work made of many small products."""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Limit BLAS to one thread in this block (when called from a main thread).

    Small products (hundreds of columns) gain nothing from BLAS threads, and spinning threads on a
    few busy cores slow them down many times (measured 10-26x on 2 loaded cores). The limit is
    process-wide: it is set only from a main thread (serial, or a worker process), never from the
    threads of a thread pool, which would undo each other's limits.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        yield
