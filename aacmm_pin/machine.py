"""What the machine offers a command's worker processes: cores and memory, checked before the work.

``uncertainty --workers 1000`` forked a thousand processes on two cores; :func:`check_workers`
refuses more workers than cores, or than the memory available holds, in one line. Imports nothing
heavy: a command checks its option before it loads numpy, SciPy or Pinocchio.
"""

from __future__ import annotations

import ctypes
import os
import sys
from functools import cache

from aacmm_pin.errors import ArgumentError

WORKER_MEMORY = 150e6
"""Memory a local worker process takes, bytes (measured: 146 MB resident each on the shared sample
campaign; more on larger ones)."""


@cache
def libc() -> ctypes.CDLL | None:
    """Return the C library this process runs on (its global symbols, errno kept), None off Linux.

    ``ctypes.CDLL(None)`` opens the process itself, which is linked to the C library: no search
    (``ctypes.util.find_library`` starts ``ldconfig`` in a subprocess: ~10 ms of each command that
    wrote a folder).
    """
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True)
    except OSError:
        return None


def usable_cores() -> int:
    """Return the cores this process may run on (its CPU affinity, else ``os.cpu_count()``)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def available_memory() -> float | None:
    """Return the memory available to new processes, bytes (Linux ``MemAvailable``), or None."""
    try:
        with open("/proc/meminfo", encoding="ascii") as info:
            for line in info:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def check_workers(workers: int) -> None:
    """Refuse more local worker processes than the machine's cores or memory can run.

    Raises:
        ArgumentError: one line naming ``workers`` with the cores and memory there are.
    """
    cores = usable_cores()
    if workers > cores:
        raise ArgumentError(f"workers: {workers:,} processes on {cores} core"
                            f"{'s' if cores > 1 else ''}: at most one a core ({cores}); more only "
                            "share the same cores")
    memory = available_memory()
    if memory is not None and workers * WORKER_MEMORY > memory:
        raise ArgumentError(f"workers: {workers} processes need about {workers * WORKER_MEMORY / 1e9:.1f}"
                            f" GB ({WORKER_MEMORY / 1e6:.0f} MB each), {memory / 1e9:.1f} GB are "
                            f"available: at most {max(1, int(memory // WORKER_MEMORY))}")
