"""Progress that tells the truth: a count and the latest state, on a terminal or as log lines.

Work whose length is known (Monte Carlo trials, candidate postures) shows a bar with its total.
A solver that iterates to a tolerance has no honest total: it shows how many evaluations it has
made and its cost, never an ETA. On a terminal this is a tqdm line; when stderr is a pipe or a file
(a log, CI), one plain line every :data:`LOG_EVERY_S` seconds and a last one at the end, so that a
long command is never silent.
"""

from __future__ import annotations

import sys
import time
from types import TracebackType
from typing import IO, Any

LOG_EVERY_S = 2.0
"""Seconds between two log lines when stderr is not a terminal."""


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
        self._start = time.perf_counter()
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
        now = time.perf_counter()
        if now - self._last_log >= LOG_EVERY_S:
            self._last_log = now
            self._log(now)

    def close(self) -> None:
        """Finish: a terminal line disappears; a log gets its last line if it had any."""
        if self._bar is not None:
            self._bar.close()
        elif self.enabled and self._logged:
            self._log(time.perf_counter(), done=True)

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


def _is_terminal(stream: IO[str]) -> bool:
    isatty = getattr(stream, "isatty", None)
    return bool(isatty is not None and isatty())


def _format(value: Any) -> str:
    return f"{value:.3g}" if isinstance(value, float) else str(value)
