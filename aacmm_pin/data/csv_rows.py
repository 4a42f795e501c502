"""The rows of a CSV file, read within a bound on its size: the text, then one row at a time.

:func:`read_text` reads a file's bytes up to a bound (:func:`~aacmm_pin.data.bounded_read.read_bounded`)
and decodes them; :func:`records` and :func:`data_rows` yield its rows one at a time, never all
held (:mod:`aacmm_pin.data.csv_table` checks them cell by cell); :func:`read_rows` returns the
non-blank rows of a small file at once, for the readers that want them all (a points file of
:mod:`aacmm_pin.analyses.iso10360`).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator
from pathlib import Path

from aacmm_pin.data.bounded_read import read_bounded
from aacmm_pin.data.problem_log import ProblemLog
from aacmm_pin.errors import FileFormatError, Problem

Rows = Iterator[tuple[int, list[str]]]
"""The (1-based line, stripped cells) of each data row of a CSV file, read as they come."""


def too_large(bound: int) -> str:
    """Return the reason a file over ``bound`` bytes is refused."""
    return f"larger than {bound // 2**20} MiB: split the campaign or decimate it"


def read_text(path: Path, log: ProblemLog, bound: int) -> str | None:
    """Return a CSV file's text read within ``bound`` bytes, or None (its problem added)."""
    try:
        data = read_bounded(path, bound)  # a huge file or /dev/zero fails fast
        if data is None:
            log.add(None, None, too_large(bound))
            return None
        return data.decode("utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else f"{exc}"
        log.add(None, None, "file not found" if isinstance(exc, FileNotFoundError) else why)
        return None


def lines(text: str) -> Iterator[str]:
    """Yield the lines of a text, each with its newline, as ``io.StringIO(text)`` iterates them.

    Without StringIO's copy of the text (4 bytes a character: 860 MB for a 215 MB file).
    """
    start, find = 0, text.find
    while (end := find("\n", start)) >= 0:
        yield text[start:end + 1]
        start = end + 1
    if start < len(text):
        yield text[start:]


def records(text: str, log: ProblemLog, strip: bool = True) -> Rows:
    """Yield the (line, cells) of every row of a CSV text but trailing blank ones.

    One row at a time: the rows are never all held. A CSV syntax error ends the rows, added as a
    problem at its line. ``strip``: the cells stripped of surrounding spaces (else as written).
    """
    # the last line with content: rows after it are blank (trailing newlines, empty cells)
    end = len(text)
    while end and text[end - 1] in " \t\r\n,":
        end -= 1
    last = text.count("\n", 0, end) + 1 if end else 0
    reader = csv.reader(lines(text))
    try:
        for row in reader:
            if reader.line_num > last:
                return
            yield reader.line_num, [c.strip() for c in row] if strip else row
    except csv.Error as exc:
        log.add(reader.line_num, None, f"{exc}")


def data_rows(text: str, log: ProblemLog, strip: bool = True) -> Rows:
    """Yield the data rows of a CSV text (the rows after its header), stripped if ``strip``."""
    rows = records(text, log, strip)
    next(rows, None)
    yield from rows


def read_rows(path: str | Path, bound: int) -> list[tuple[int, list[str]]]:
    """Return the (1-based row number, stripped cells) of every row of a CSV file with a cell.

    For small files read whole (the rows are all held): the file is read within ``bound`` bytes.

    Raises:
        FileFormatError: if the file is larger than ``bound``, cannot be read or decoded as
            UTF-8, or is not CSV (the reason as the error gives it).
    """
    path = Path(path)
    try:
        data = read_bounded(path, bound)
        if data is None:
            raise FileFormatError([Problem(path, None, None, too_large(bound))])
        reader = csv.reader(io.StringIO(data.decode("utf-8-sig"), newline=""))
        return [(k, [c.strip() for c in row]) for k, row in enumerate(reader, start=1)
                if any(c.strip() for c in row)]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise FileFormatError([Problem(path, None, None, str(exc))]) from None
