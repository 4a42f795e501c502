"""Ctrl-C (SIGINT) and SIGTERM in one place: their Python handlers swapped for a while, and put back.

SIGTERM (``kill PID``, a scheduler's stop) is handled as Ctrl-C is where it was left to the system
(:func:`sigterm_as_interrupt`): :class:`Terminated` is a ``KeyboardInterrupt``, so a command stops
the same clean way (its workers ended, its claims released, nothing partial written). A worker
process dies with its parent (:func:`die_with_parent`), even when the parent is killed outright.

Python runs signal handlers in the main thread only, and it raises ``KeyboardInterrupt`` on
SIGINT only where SIGINT was not ignored when the process started: a shell runs a script's
background commands with SIGINT ignored, so that a Ctrl-C meant for the foreground command
leaves them running. :func:`sigint_handler` swaps the handler only where Python's would raise, so
such an ignore (or a handler set outside Python) is kept.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

from aacmm_pin.machine import libc

Handler = Callable[[int, FrameType | None], Any]
"""A Python signal handler: ``handler(signum, frame)``."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C raises ``KeyboardInterrupt``, for the same clean stop."""


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    raise Terminated


@contextmanager
def sigterm_as_interrupt() -> Iterator[bool]:
    """Within: SIGTERM raises :class:`Terminated` (in the main thread), where it was left to the system.

    Yields whether it does: not in another thread, not where SIGTERM is ignored or handled by
    someone else (a handler set before is kept).
    """
    on_main = threading.current_thread() is threading.main_thread()
    if not on_main or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        yield False
        return
    try:
        signal.signal(signal.SIGTERM, _raise_terminated)
    except ValueError:  # a subinterpreter's main thread
        yield False
        return
    try:
        yield True
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


PR_SET_PDEATHSIG = 1
"""Linux ``prctl`` option: the signal a process gets when the thread that made it ends."""


def die_with_parent(parent: int) -> None:
    """In a worker process just started by ``parent``: be killed (SIGKILL) when the parent ends.

    Linux ``prctl(PR_SET_PDEATHSIG)``: the kernel kills the worker however the parent ends
    (SIGKILL included), so no orphan goes on working. If the parent already ended, the worker
    ends now. SIGTERM gets its default action (the parent's ``terminate()`` ends the worker; the
    handler inherited from the parent would raise :class:`Terminated` in it). Elsewhere the
    parent's end is not seen: its ``terminate()`` on Ctrl-C and SIGTERM still ends the workers.
    """
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if not sys.platform.startswith("linux"):
        return
    try:
        libc().prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)  # type: ignore[union-attr]
    except AttributeError:
        return
    if os.getppid() != parent:  # it ended before the prctl: no signal will come
        os._exit(1)


@contextmanager
def sigint_handler(handler: Handler, signum: int = signal.SIGINT) -> Iterator[bool]:
    """Within: ``handler`` handles SIGINT in place of the Python handler before; after: that one.

    ``signum``: another signal (SIGTERM) in the same way.

    Yields whether the handler was swapped: not in another thread, not where SIGINT is ignored or
    left to the system (``SIG_IGN``, ``SIG_DFL``, a handler not set from Python), not in a
    subinterpreter (its signals belong to the main interpreter). The handler before is put back
    even if a pending signal's handler raises meanwhile (Python runs pending handlers before it
    sets one); that error is raised then.
    """
    on_main = threading.current_thread() is threading.main_thread()
    before = signal.getsignal(signum) if on_main else None
    swapped = False
    if callable(before):
        try:
            signal.signal(signum, handler)
            swapped = True
        except ValueError:  # a subinterpreter's main thread
            pass
    try:
        yield swapped
    finally:
        if swapped:
            assert callable(before)
            _restore(before, signum)


def _restore(handler: Handler, signum: int) -> None:
    """Set ``handler`` for ``signum``, then raise what a pending signal's handler raised meanwhile."""
    error: BaseException | None = None
    while True:
        try:
            signal.signal(signum, handler)
            break
        except BaseException as exc:  # noqa: BLE001 - raised once the handler is back
            error = error or exc
    if error is not None:
        raise error


@contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Hold a Ctrl-C (or a SIGTERM handled from Python) back while inside; raised again on leaving.

    Then it is handled as it would have been. For a block that makes what only the code after it
    removes (a lock file): no ``KeyboardInterrupt`` lands between the two.
    """
    noted: list[int] = []

    def note(signum: int, frame: FrameType | None) -> None:
        noted.append(signum)

    try:
        with sigint_handler(note), sigint_handler(note, signal.SIGTERM):
            yield
    finally:
        for signum in dict.fromkeys(noted):
            signal.raise_signal(signum)
