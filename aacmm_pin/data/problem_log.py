"""The problems of one input file, collected with a cap: a few of each kind kept, the rest counted.

A file of a million bad rows is a million times the same mistake: :class:`ProblemLog` keeps the
first :data:`MAX_LIKE` problems of each kind (and at most :data:`MAX_SHOWN` of the file), counts
the others without storing them, and ends with one line per kind, ``... and 1,745 more rows like
it``, so that memory and output stay bounded whatever the input.
"""

from __future__ import annotations

import difflib
from collections.abc import Hashable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

from aacmm_pin.errors import Problem

MAX_LIKE = 5
"""Problems of one kind (one column, one reason) shown; the others are counted."""
MAX_SHOWN = 50
"""Problems of one file shown in all; the others are counted."""
MAX_KINDS = 1024
"""Kinds counted one by one; the problems of further kinds are counted together."""


@dataclass
class _Kind:
    """What is known of one kind of problem: how many, where the first omitted one is."""

    column: str | None
    unit: str
    columns: dict[str | None, None] = field(default_factory=dict)
    shown: int = 0
    omitted: int = 0
    first_line: int | None = None
    last_line: int | None = None


class ProblemLog:
    """Collect the problems of one file into ``out``, at most :data:`MAX_LIKE` of each kind.

    Args:
        out: where the problems kept are appended (and, on :meth:`close`, the counts).
        path: the file.
        unit: what is counted in the summary lines ("rows", "keys").
    """

    def __init__(self, out: list[Problem], path: Path | str, unit: str = "rows") -> None:
        self.out = out
        self.path = path
        self.unit = unit
        self.count = 0
        """Problems added so far (kept or counted)."""
        self._kinds: dict[Hashable, _Kind] = {}
        self._shown = 0
        self._other = 0
        self._last_line: int | None = None

    def add(self, line: int | None, column: str | None, reason: str,
            kind: Hashable | None = None, unit: str | None = None) -> None:
        """Add one problem; ``kind`` (default: column and reason) groups the problems alike.

        ``unit``: what the problems of this kind are counted as (default: the log's).
        """
        self.count += 1
        if line is not None:
            self._last_line = max(line, self._last_line or 0)
        key = (column, reason) if kind is None else kind
        info = self._kinds.get(key)
        if info is None:
            if len(self._kinds) >= MAX_KINDS:
                self._other += 1
                return
            info = self._kinds[key] = _Kind(column, unit or self.unit)
        if info.shown < MAX_LIKE and self._shown < MAX_SHOWN:
            info.shown += 1
            self._shown += 1
            self.out.append(Problem(self.path, line, column, reason))
            return
        info.omitted += 1
        if len(info.columns) < MAX_LIKE:
            info.columns[column] = None
        if info.first_line is None:
            info.first_line = line
        info.last_line = line

    def close(self) -> None:
        """Append one line per kind with problems left out, and one for the kinds never shown."""
        for info in self._kinds.values():
            if info.shown and info.omitted:
                one = list(info.columns) == [info.column]
                where = [] if one else [", ".join(sorted(str(c) for c in info.columns if c is not None))]
                if info.last_line is not None and info.last_line != info.first_line:
                    where.append(f"to line {info.last_line}")
                detail = f" ({'; '.join(w for w in where if w)})" if any(where) else ""
                self.out.append(Problem(self.path, info.first_line, info.column if one else None,
                                        f"... and {info.omitted:,} more {info.unit} like it"
                                        f"{detail}", info.omitted))
        hidden = self._other + sum(i.omitted for i in self._kinds.values() if not i.shown)
        if hidden:
            self.out.append(Problem(self.path, self._last_line, None, f"... and {hidden:,} more "
                                                                      "problems of other kinds",
                                    hidden))


def close_match(name: str, known: Iterable[str]) -> str | None:
    """Return the known name a misspelt one most likely means, or None.

    A known name that is ``name`` with a unit suffix (``q1`` -> ``q1_deg``) or differs only in
    case comes first; else the closest by :func:`difflib.get_close_matches` (ratio 0.75 or more:
    a letter or two off in a name of eight).
    """
    known = list(known)
    lower = name.lower()
    if not lower:
        return None
    for candidate in known:
        if candidate.lower() == lower or candidate.lower().startswith(lower + "_"):
            return candidate
    found = difflib.get_close_matches(name, known, n=1, cutoff=0.75)
    return found[0] if found else None


def key_problems(path: Path | str, keys: Iterable[str], known: Iterable[str], prefix: str = "",
                 *, strict: bool = True) -> list[Problem]:
    """Return a problem for every key of a JSON object that is not one of the known keys.

    A key close to a known one (:func:`close_match`: ``instrumnet``, ``Noise_um``) names it;
    with ``strict`` False only such keys are problems (the object may carry keys of its own).

    Args:
        path: the file.
        keys: the object's keys.
        known: the keys the reader reads.
        prefix: the object's path in the file, e.g. ``noise_um.`` (empty at the top level).
        strict: whether a key neither known nor close to one is a problem too.
    """
    known = list(known)
    listing = ", ".join(known)
    out = []
    for key in keys:
        if key in known:
            continue
        meant = close_match(key, known)
        if meant is not None or strict:
            guess = f"; did you mean '{meant}'?" if meant else ""
            out.append(Problem(path, None, f"{prefix}{key}",
                               f"unknown key{guess} (the keys: {listing})"))
    return out


class ProblemLogs:
    """One :class:`ProblemLog` per file, for checks that span several files.

    Args:
        out: where the problems kept are appended.
    """

    def __init__(self, out: list[Problem]) -> None:
        self.out = out
        self._logs: dict[Path | str, ProblemLog] = {}

    def add(self, path: Path | str, line: int | None, column: str | None, reason: str,
            kind: Hashable | None = None) -> None:
        """Add one problem of a file (see :meth:`ProblemLog.add`)."""
        if path not in self._logs:
            self._logs[path] = ProblemLog(self.out, path)
        self._logs[path].add(line, column, reason, kind)

    def close(self) -> None:
        """Append the counts of every file's problems left out."""
        for log in self._logs.values():
            log.close()
