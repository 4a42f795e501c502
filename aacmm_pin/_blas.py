"""Single-threaded BLAS for work made of many small products."""

from __future__ import annotations

import contextlib
import functools
import threading
from collections.abc import Iterator

_STARTED_SINGLE_THREADED = [False]
"""Whether this process started its BLAS libraries with one thread (:func:`started_single_threaded`)."""


def started_single_threaded() -> None:
    """Note that every BLAS library of this process starts with one thread.

    Called by the command line, which sets the BLAS thread variables before numpy is loaded
    (``aacmm_pin.cli.one_blas_thread_at_start``): :func:`single_threaded_blas` then has nothing
    to limit where numpy's and SciPy's BLAS read that variable (their wheels' OpenBLAS) and skips
    ``threadpoolctl`` (importing it and finding the libraries: ~20 ms of each
    ``identify``).
    """
    _STARTED_SINGLE_THREADED[0] = True


@functools.cache
def _threads_from_environment() -> bool:
    """Whether numpy's and SciPy's BLAS take their threads from ``OPENBLAS_NUM_THREADS``.

    True for the OpenBLAS of their wheels (scipy-openblas, built with its own threads); an
    OpenMP build of OpenBLAS, MKL or BLIS may follow other variables, so there the limit of
    :func:`single_threaded_blas` is set as for any process (``threadpoolctl``).
    """
    import numpy
    import scipy

    for package in (numpy, scipy):
        blas = getattr(package, "__config__", None)
        info = getattr(blas, "CONFIG", {}).get("Build Dependencies", {}).get("blas", {})
        if not (str(info.get("name", "")).startswith("scipy-openblas")
                and "USE_OPENMP=1" not in str(info.get("openblas configuration", ""))):
            return False
    return True


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Limit BLAS to one thread in this block (when called from a main thread).

    Small products (hundreds of columns) gain nothing from BLAS threads, and spinning threads on a
    few busy cores slow them down many times (measured 10-26x on 2 loaded cores). The limit is
    process-wide: it is set only from a main thread (serial, or a worker process), never from the
    threads of a thread pool, which would undo each other's limits.
    """
    if threading.current_thread() is not threading.main_thread() or (
            _STARTED_SINGLE_THREADED[0] and _threads_from_environment()):
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        yield
