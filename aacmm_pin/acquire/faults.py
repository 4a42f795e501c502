"""The faults of an acquisition: the errors it raises and the counts it keeps of bad input.

A bad line never stops a run: it is counted under one of :data:`FAULT_KINDS` for its port and
dropped. :class:`AcquisitionError` is raised only before recording starts (a port that cannot be
opened, a spat.csv with other columns, a conflicting zero position).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from aacmm_pin.errors import AcquisitionError

__all__ = ["FAULT_KINDS", "AcquisitionError", "LineError", "PortCounts"]

FAULT_KINDS = ("garbled", "checksum", "out_of_range", "timeout", "port_lost")
"""Kinds of faults counted per port: a line that does not parse, a line whose checksum does not
match, a value outside the device's range, a silence longer than the timeout, a port that fails."""


class LineError(AcquisitionError):
    """One line from a device is unusable; ``kind`` is one of :data:`FAULT_KINDS`.

    Raised by the line parsers of :mod:`aacmm_pin.acquire.protocols`, caught and counted by the
    port readers: a bad line is never data.
    """

    def __init__(self, kind: str, line: bytes, reason: str):
        if kind not in FAULT_KINDS:
            raise ValueError(f"kind: choose from {', '.join(FAULT_KINDS)}, got {kind!r}")
        self.kind = kind
        self.line = bytes(line)
        self.reason = reason
        super().__init__(f"{kind}: {reason}: {self.line[:80]!r}")


@dataclass
class PortCounts:
    """What one port delivered: good lines and each kind of fault."""

    lines: int = 0
    """Good lines (parsed, in range)."""
    garbled: int = 0
    """Lines that do not follow the format (noise, truncated, unknown channel, overlong)."""
    checksum: int = 0
    """Lines whose checksum does not match their content."""
    out_of_range: int = 0
    """Lines with a value outside the device's range (gauge range, +-720 deg for the arm)."""
    timeout: int = 0
    """Silences longer than the timeout (counted once per silence)."""
    port_lost: int = 0
    """Read or write failures of the port (cable pulled, device gone)."""
    reconnects: int = 0
    """Times the port was opened again after a failure."""

    def add(self, kind: str, n: int = 1) -> None:
        """Add ``n`` to the count of ``kind`` (a field name)."""
        setattr(self, kind, getattr(self, kind) + n)

    @property
    def faults(self) -> int:
        """Number of faults of every kind."""
        return sum(getattr(self, kind) for kind in FAULT_KINDS)

    def to_dict(self) -> dict[str, Any]:
        """Return the counts as a plain dict."""
        return {f.name: getattr(self, f.name) for f in fields(self)}
