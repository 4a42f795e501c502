"""Freed memory given back to the system: the C heap's free pages after a large pass.

numpy takes arrays of up to 32 MB from the C library's heap (glibc's adaptive threshold: above it
each array is a mapping of its own, returned when freed). A large campaign's chunked passes free
tens of MB of such temporaries per chunk between arrays that stay, and the heap keeps those free
pages resident: the process' peak grew by about 150 MB over a 1.6M-sample fit without holding
more data. :func:`release_free_heap` hands them back (glibc's ``malloc_trim``, which returns free
pages anywhere in the heap); elsewhere it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from functools import cache
from typing import Any


@cache
def _libc() -> Any:
    """The C library when it has ``malloc_trim`` (glibc), else None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return libc if hasattr(libc, "malloc_trim") else None
    except OSError:
        return None


def release_free_heap() -> None:
    """Return the C heap's free pages to the system (glibc; a no-op elsewhere).

    Costs a walk of the heap's free lists (about a millisecond) and, later, the page faults of the
    pages used again: call it after work that freed tens of MB, not in a tight loop.
    """
    libc = _libc()
    if libc is not None:
        libc.malloc_trim(0)
