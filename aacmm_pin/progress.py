"""Progress that tells the truth: a count and the latest state, on a terminal or as log lines.

Work whose length is known (Monte Carlo trials, candidate postures) shows a bar with its total.
A solver that iterates to a tolerance has no honest total: it shows how many evaluations it has
made and its cost, never an ETA. On a terminal this is a tqdm line; when stderr is a pipe or a file
(a log, CI), one plain line every :data:`LOG_EVERY_S` seconds and a last one at the end, so that a
long command is never silent.

Work that counts nothing (reading files, a single long solve, writing figures) is covered by
:class:`Heartbeat`: around a whole command, it prints ``<desc>: still working[, <phase>], <t> s``
(e.g. ``aacmm-pin demo: still working, writing figures, 7.8 s``) whenever the command has shown
nothing for :data:`HEARTBEAT_S` seconds.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from types import TracebackType
from typing import IO, Any

LOG_EVERY_S = 1.0
"""Seconds between two log lines when stderr is not a terminal, counted from the last line the
command showed (under a :class:`Heartbeat`, which speaks only after :data:`HEARTBEAT_S`, longer:
work that progresses logs its own lines, silent work gets the heartbeat's)."""


class Progress:
    """Count units of work and show them (see module doc).

    Args:
        desc: what is running, e.g. ``"identify proposed"``.
        unit: the unit counted, singular (``"evaluation"``, ``"trial"``).
        total: how many units there will be, or None when a tolerance decides.
        enabled: False shows nothing (the API's default; the CLI turns it on).
        stream: where to write (default: stderr).
    """

    def __init__(self, desc: str, unit: str, total: int | None = None, enabled: bool = True,
                 stream: IO[str] | None = None):
        self.desc, self.unit, self.total, self.enabled = desc, unit, total, enabled
        self.stream = stream if stream is not None else sys.stderr
        self.n = 0
        self.state: dict[str, Any] = {}
        self._start = time.monotonic()
        self._last_log = self._start
        self._logged = False
        self._bar: Any = None
        if enabled and _is_terminal(self.stream):
            from tqdm.auto import tqdm

            self._bar = tqdm(total=total, desc=desc, unit=f" {unit}s", leave=False, file=self.stream)

    def update(self, n: int = 1, **state: Any) -> None:
        """Count ``n`` more units; ``state`` (e.g. ``cost=1.2e-3``) is shown beside the count."""
        self.n += n
        self.state.update(state)
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(n)
            if state:
                self._bar.set_postfix({k: _format(v) for k, v in self.state.items()}, refresh=False)
            return
        now = time.monotonic()
        if now - max(self._last_log, _last_shown()) >= LOG_EVERY_S:
            self._last_log = now
            self._log(now)

    def close(self) -> None:
        """Finish: a terminal line disappears; a log gets its last line if it had any."""
        if self._bar is not None:
            self._bar.close()
        elif self.enabled and self._logged:
            self._log(time.monotonic(), done=True)

    def _log(self, now: float, done: bool = False) -> None:
        count = f"{self.n}" + (f"/{self.total}" if self.total is not None else "")
        extra = "".join(f", {k} {_format(v)}" for k, v in self.state.items())
        print(f"{self.desc}: {count} {self.unit}s{extra}, {now - self._start:.1f} s"
              f"{' (done)' if done else ''}", file=self.stream, flush=True)
        self._logged = True

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


HEARTBEAT_S = 1.5
"""Seconds of silence after which :class:`Heartbeat` prints a line (below 2 s: a user never waits
two seconds for a sign of life)."""

FIRST_BEAT_S = 1.0
"""Seconds after the start of a silent command for its first line (Python's start-up, before the
heartbeat runs, takes 0.1-0.5 s of the user's first two seconds)."""


class _Stamped:
    """A text stream that notes when it was last written to (all other attributes delegated).

    A write that ends a line is flushed at once (as on a terminal): text in a pipe's buffer is
    not a sign of life the user can see, and lines keep their order beside the heartbeat's.
    """

    def __init__(self, stream: IO[str], beat: Heartbeat):
        self._stream, self._beat = stream, beat
        self.line_open = False
        """The last write did not end its line."""

    def write(self, text: str) -> int:
        with self._beat.lock:
            n = self._stream.write(text)
            if text:
                if "\n" in text:
                    self._stream.flush()
                self._beat.last_write = time.monotonic()
                self.line_open = not text.endswith("\n")
            return n

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


class Heartbeat:
    """Print a line whenever a command has been silent for :data:`HEARTBEAT_S` seconds.

    A context manager around a whole command: ``sys.stdout`` and ``sys.stderr`` are wrapped so
    that every write is noted; a daemon thread writes ``<desc>: still working[, <phase>], <t> s``
    to stderr after each silence of :data:`HEARTBEAT_S` (:data:`FIRST_BEAT_S` for a command that
    has said nothing yet). A :class:`Progress` that counts work logs its own line after
    :data:`LOG_EVERY_S` of silence, before the heartbeat would speak, so it stays quiet while work
    progresses. :meth:`stop`
    ends it early, e.g. before a server waits for the user. Heartbeats nest (the inner one speaks
    while it runs); a forked child process starts without one.

    Args:
        desc: what runs, e.g. ``"aacmm-pin identify"``.
        enabled: False does nothing.
    """

    def __init__(self, desc: str, enabled: bool = True):
        self.desc, self.enabled = desc, enabled
        self.lock = threading.Lock()
        self.last_write = self._start = time.monotonic()
        self.phase = ""
        """What runs now, shown in the line (empty: nothing said)."""
        self._done = threading.Event()
        self._thread: threading.Thread | None = None
        self._saved: tuple[Any, Any] | None = None
        self._outer: Heartbeat | None = None

    def __enter__(self) -> Heartbeat:
        global _current
        if self.enabled:
            _register_fork_handler()
            self._outer, _current = _current, self
            self._saved = (sys.stdout, sys.stderr)
            sys.stdout = _Stamped(sys.stdout, self)
            sys.stderr = _Stamped(sys.stderr, self)
            self._thread = threading.Thread(target=self._run, name="heartbeat", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        try:
            while not self._done.wait(0.1):
                with self.lock:
                    self._beat(time.monotonic())
        except (OSError, ValueError):  # the reader left or the stream closed: stop quietly
            return

    def _beat(self, now: float) -> None:
        """Write the line if the command has been silent long enough (called under the lock)."""
        if self._saved is None:
            return
        first = self.last_write == self._start
        if now - self.last_write < (FIRST_BEAT_S if first else HEARTBEAT_S):
            return
        out, err = sys.stdout, sys.stderr
        # a line left open on stderr, or on stdout when both show on one terminal, is ended first
        open_line = (isinstance(err, _Stamped) and err.line_open) or (
            isinstance(out, _Stamped) and out.line_open and _is_terminal(out))
        phase = f", {self.phase}" if self.phase else ""
        self._saved[1].write(("\n" if open_line else "")
                             + f"{self.desc}: still working{phase}, {now - self._start:.1f} s\n")
        self._saved[1].flush()
        self.last_write = now
        if isinstance(err, _Stamped):
            err.line_open = False
        if isinstance(out, _Stamped) and _is_terminal(out):
            out.line_open = False

    def stop(self) -> None:
        """Stop the heartbeat and give back the streams (idempotent)."""
        global _current
        if _current is self:
            _current = self._outer
        self._done.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._saved is not None:
            with self.lock:
                sys.stdout, sys.stderr = self._saved
                self._saved = None

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()


_current: Heartbeat | None = None
"""The running heartbeat, if any (the innermost)."""
_fork_handler = False


def _register_fork_handler() -> None:
    """Make forked children (worker processes) start without a heartbeat.

    The heartbeat's thread does not come along, and its lock may have been held at the fork.
    """
    global _fork_handler
    if not _fork_handler and hasattr(os, "register_at_fork"):
        os.register_at_fork(after_in_child=_after_fork_in_child)
        _fork_handler = True


def _after_fork_in_child() -> None:
    global _current
    beat = _current
    while beat is not None:
        beat.lock = threading.Lock()
        if beat._saved is not None:
            sys.stdout, sys.stderr = beat._saved
            beat._saved = None
        beat._thread = None
        beat = beat._outer
    _current = None


def phase(text: str) -> None:
    """Say what runs now in the running heartbeat's lines (no heartbeat: nothing happens)."""
    if _current is not None:
        _current.phase = text


def _last_shown() -> float:
    """Return the ``time.monotonic`` of the running command's last shown line (-inf: none)."""
    return float("-inf") if _current is None else _current.last_write


def idle() -> None:
    """Stop the running heartbeat: the work is done and the command now waits (e.g. a server)."""
    if _current is not None:
        _current.stop()


def _is_terminal(stream: object) -> bool:
    isatty = getattr(stream, "isatty", None)
    return bool(isatty is not None and isatty())


def _format(value: Any) -> str:
    return f"{value:.3g}" if isinstance(value, float) else str(value)
