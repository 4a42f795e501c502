"""Ctrl-C (SIGINT) in one place: its Python handler swapped for a while, and put back.

Python runs signal handlers in the main thread only, and it raises ``KeyboardInterrupt`` on
SIGINT only where SIGINT was not ignored when the process started: a shell runs a script's
background commands with SIGINT ignored, so that a Ctrl-C meant for the foreground command
leaves them running. :func:`sigint_handler` swaps the handler only where Python's would raise, so
such an ignore (or a handler set outside Python) is kept.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

Handler = Callable[[int, FrameType | None], Any]
"""A Python signal handler: ``handler(signum, frame)``."""


@contextmanager
def sigint_handler(handler: Handler) -> Iterator[bool]:
    """Within: ``handler`` handles SIGINT in place of the Python handler before; after: that one.

    Yields whether the handler was swapped: not in another thread, not where SIGINT is ignored or
    left to the system (``SIG_IGN``, ``SIG_DFL``, a handler not set from Python), not in a
    subinterpreter (its signals belong to the main interpreter). The handler before is put back
    even if a pending signal's handler raises meanwhile (Python runs pending handlers before it
    sets one); that error is raised then.
    """
    on_main = threading.current_thread() is threading.main_thread()
    before = signal.getsignal(signal.SIGINT) if on_main else None
    swapped = False
    if callable(before):
        try:
            signal.signal(signal.SIGINT, handler)
            swapped = True
        except ValueError:  # a subinterpreter's main thread
            pass
    try:
        yield swapped
    finally:
        if swapped:
            assert callable(before)
            _restore(before)


def _restore(handler: Handler) -> None:
    """Set ``handler`` for SIGINT, then raise what a pending signal's handler raised meanwhile."""
    error: BaseException | None = None
    while True:
        try:
            signal.signal(signal.SIGINT, handler)
            break
        except BaseException as exc:  # noqa: BLE001 - raised once the handler is back
            error = error or exc
    if error is not None:
        raise error


@contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Hold a Ctrl-C back while inside; it is raised again on leaving.

    Then it is handled as it would have been. For a block that makes what only the code after it
    removes (a lock file): no ``KeyboardInterrupt`` lands between the two.
    """
    noted: list[int] = []
    try:
        with sigint_handler(lambda signum, frame: noted.append(signum)):
            yield
    finally:
        if noted:
            signal.raise_signal(signal.SIGINT)
