"""Freed memory given back to the system: the C heap's free pages after a large pass.

numpy takes arrays of up to 32 MB from the C library's heap (glibc's adaptive threshold: above it
each array is a mapping of its own, returned when freed). A large campaign's chunked passes free
tens of MB of such temporaries per chunk between arrays that stay, and the heap keeps those free
pages resident: the process' peak grew by about 150 MB over a 1.6M-sample fit without holding
more data. :func:`release_free_heap` hands them back (glibc's ``malloc_trim``, which returns free
pages anywhere in the heap); elsewhere it does nothing.
"""

from __future__ import annotations

from aacmm_pin.machine import libc


def release_free_heap() -> None:
    """Return the C heap's free pages to the system (glibc; a no-op elsewhere).

    Costs a walk of the heap's free lists (about a millisecond) and, later, the page faults of the
    pages used again: call it after work that freed tens of MB, not in a tight loop.
    """
    trim = getattr(libc(), "malloc_trim", None)  # glibc's; None elsewhere
    if trim is not None:
        trim(0)
