"""One CSV file of a campaign or of readouts, read and checked cell by cell into named columns.

:func:`read_table` is told which columns a file must and may have, reads it with a bound on its
size, one row at a time, and adds a :class:`~aacmm_pin.errors.Problem` (file, line, column, reason)
for every bad header or cell instead of stopping at the first: a few of each kind, the others
counted (:class:`~aacmm_pin.data.problem_log.ProblemLog`), so that memory and output stay
bounded. Values stay in file units (mm, deg); the callers (:mod:`aacmm_pin.data.campaign`) convert
them. Per-sample columns (``t_s``, ``temp_c``, ``sigma_um``
and any extra numeric column) are checked against the column table, :mod:`aacmm_pin.data.columns`.
"""

from __future__ import annotations

import itertools
import math
import re
from array import array
from collections.abc import Callable, Iterable, Iterator, MutableSequence, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TypeGuard

import numpy as np

from aacmm_pin.data.columns import MAX_ANGLE_DEG, Column, column, has_unit, registered_columns
from aacmm_pin.data.couplings import AxisCoupling, fill_or_check
from aacmm_pin.data.csv_rows import Rows, data_rows, read_text, records
from aacmm_pin.data.poses import POSE_COLUMN
from aacmm_pin.data.problem_log import MAX_SHOWN, ProblemLog, close_match
from aacmm_pin.errors import Problem
from aacmm_pin.units import (
    BAR_LENGTH_MAX,
    BAR_LENGTH_MIN,
    MAX_COORDINATE,
    RADIAN_MIN_ROWS,
    RTEST_RANGE,
)

Q_COLUMN = re.compile(r"q([1-9][0-9]*)_deg")
"""A readout column in axis order, ``q<n>_deg``."""
MAX_FILE_BYTES = 256 * 2**20
"""Largest campaign or readouts CSV read, bytes (about 2 million SPAT rows)."""
MAX_COLUMNS = 256
"""Most columns of a CSV header (and the highest q<n>_deg readout column)."""
POINT = ("x_mm", "y_mm", "z_mm")
"""The columns of a measured point (or a prediction)."""
DISPLACEMENT = ("dx_mm", "dy_mm", "dz_mm")
"""The columns of an R-Test's sphere displacement (``spat.csv``)."""
# Column -> kind of cell; q columns are "angle", per-sample columns "column", others "number".
_KINDS = {"location": "id", "placement": "id", "socket": "text", "from": "text", "to": "text",
          "length_mm": "length", "group": "id", "tool": "text",
          "dx_mm": "displacement", "dy_mm": "displacement", "dz_mm": "displacement",
          "x_mm": "coordinate", "y_mm": "coordinate", "z_mm": "coordinate"}
Extras = Literal["refuse", "numbers", "readouts"]
"""What a file's other columns are: refused (``unknown column``), numbers (each checked, a campaign
log's), or, in a readouts file, numbers where the column has a unit or every cell is a number (a
text column such as a pose id is left to :func:`aacmm_pin.data.campaign.read_id_columns`)."""


@dataclass
class Table:
    """The checked cells of one CSV file, by column."""

    path: Path
    """The file."""
    q_columns: list[str]
    """The readout columns in axis order (``q1_deg..qn_deg`` or ``<joint>_deg``); empty if they
    are missing or have gaps."""
    lines: MutableSequence[int]
    """1-based file line of each row kept (rows with the header's number of cells)."""
    cols: dict[str, Any]
    """Parsed cells of each known column, in file units: a typed array (``array("d")``, ids
    ``array("q")``) or a list of str; lists with None where a cell is bad."""
    per_sample: list[str] = field(default_factory=list)
    """The per-sample columns read (optional ones of the column table and extra ones), in file
    order; their cells are checked against :func:`aacmm_pin.data.columns.column`."""
    complete: bool = True
    """Whether every row with the header's number of cells is kept (False: the file has so many
    problems that the rows after them are only checked, and cross-file checks are skipped)."""

    @property
    def n_axes(self) -> int:
        """Number of readout columns (0: missing or with gaps)."""
        return len(self.q_columns)


def _parse(text: str, kind: str, col: Column | None = None) -> tuple[Any, str | None, str]:
    """Return (value, None, "") for a good cell, or (None, reason, kind of problem).

    The kind is the reason without the cell's text: the cells alike are counted together.
    """
    if not text or kind == "text":
        return (text, None, "") if text else (None, "empty cell", "empty cell")
    try:
        value = int(text) if kind == "id" else float(text)
    except ValueError:
        why = f"is not {'an integer' if kind == 'id' else 'a number'}"
        return None, f"'{text}' {why}", why
    bad = col.check(value) if col is not None else _bad_value(value, kind)
    return (None, f"{text} {bad}", bad) if bad else (value, None, "")


def _bad_value(value: float, kind: str) -> str | None:
    """Return why a parsed cell's value is not acceptable for its kind, or None (first failed check)."""
    if kind == "id":
        return ("is not an integer >= 1" if value < 1
                else "is too large for an id" if value >= 2**63 else None)
    if not math.isfinite(value):
        return "is not a finite number"
    if kind == "angle" and abs(value) > MAX_ANGLE_DEG:
        return f"deg is outside +-{MAX_ANGLE_DEG:g} deg"
    if kind == "length" and value <= 0:
        return "mm is not a positive bar length"
    if kind == "length" and not BAR_LENGTH_MIN * 1e3 <= value <= BAR_LENGTH_MAX * 1e3:
        return (f"mm is not a plausible bar length ({BAR_LENGTH_MIN * 1e3:g} mm to "
                f"{BAR_LENGTH_MAX:g} m)")
    if kind == "displacement" and abs(value) > RTEST_RANGE * 1e3:
        # a value within range once divided by 1000 is most likely written in um
        unit = ("; in um? write mm" if abs(value) <= RTEST_RANGE * 1e6 else "")
        return (f"mm is beyond an R-Test's measuring range (+-{RTEST_RANGE * 1e3:g} mm): a unit "
                f"or sensor error{unit}")
    if kind == "coordinate" and abs(value) > MAX_COORDINATE * 1e3:
        return f"mm is beyond +-{MAX_COORDINATE:g} m: not a position an arm or tracker measures"
    return None


CHUNK_ROWS = 1024
"""Rows checked together: a chunk whose every cell is good is converted and checked a column at
a time; one with a problem is read cell by cell (the same checks, each problem added)."""
_FLOAT = np.dtype(float)


def _chunks(rows: Rows) -> Iterator[list[tuple[int, list[str]]]]:
    """Yield the rows in lists of :data:`CHUNK_ROWS`."""
    while chunk := list(itertools.islice(rows, CHUNK_ROWS)):
        yield chunk


def _all_good(values: np.ndarray, kind: str, col: Column | None) -> bool:
    """Whether :func:`_bad_value` (or ``col.check``) passes every parsed value of one kind."""
    if col is not None and type(col) is not Column:  # a subclass's own check: value by value
        return all(col.check(float(v)) is None for v in values)
    ok = np.isfinite(values)
    if col is not None:
        ok &= (values >= col.low) & (values <= col.high)
        if col.positive:
            ok &= values > 0
    elif kind == "angle":
        ok &= np.abs(values) <= MAX_ANGLE_DEG
    elif kind == "length":
        ok &= (values > 0) & (values >= BAR_LENGTH_MIN * 1e3) & (values <= BAR_LENGTH_MAX * 1e3)
    elif kind == "displacement":
        ok &= np.abs(values) <= RTEST_RANGE * 1e3
    elif kind == "coordinate":
        ok &= np.abs(values) <= MAX_COORDINATE * 1e3
    return bool(ok.all())


class _Cells:
    """The kept cells of a table, by column, filled a chunk of rows at a time.

    Numbers in typed arrays (``array("d")``, ids ``array("q")``: 8 bytes a cell, no Python object
    per cell), text in lists of str; once :meth:`finish` ran, a table with a bad cell has lists
    with None at its bad cells (as the cell-by-cell reading gives them).
    """

    def __init__(self, kinds: dict[str, str], checks: dict[str, Column]):
        self.kinds, self.checks = kinds, checks
        self.cols: dict[str, Any] = {
            name: [] if kind == "text" else array("q" if kind == "id" else "d")
            for name, kind in kinds.items()}
        self.bad: list[tuple[str, int]] = []
        """(column, row) of every bad cell kept: None once the table is read."""

    def fast(self, chunk: list[tuple[int, list[str]]], index: dict[str, int], width: int,
             keep: bool) -> bool:
        """Check and keep (if ``keep``) a chunk whose every row and cell is good (cells as written).

        Returns:
            Whether it was; if not, nothing is kept (the chunk is then read cell by cell).
        """
        if not all(len(row) == width and any(row) for _, row in chunk):
            return False
        parsed: dict[str, list[Any]] = {}
        by_column = list(zip(*(row for _, row in chunk)))  # cells as written: int() and
        for name, k in index.items():  # float() ignore the spaces that strip() removes
            kind, texts = self.kinds[name], by_column[k]
            try:
                if kind == "text":
                    if not all(stripped := [t.strip() for t in texts]):
                        return False
                    parsed[name] = stripped
                elif kind == "id":
                    ids = list(map(int, texts))
                    if not (min(ids) >= 1 and max(ids) < 2**63):
                        return False
                    parsed[name] = ids
                else:
                    values = list(map(float, texts))
                    if not _all_good(np.array(values, dtype=_FLOAT), kind, self.checks.get(name)):
                        return False
                    parsed[name] = values
            except ValueError:  # a cell that is not a number (or empty): read cell by cell
                return False
        if keep:
            for name, values in parsed.items():
                self.cols[name].extend(values)
        return True

    def parse(self, name: str, text: str, keep: bool) -> tuple[Any, str | None, str]:
        """:func:`_parse` one cell of column ``name``, keeping its value (if ``keep``)."""
        value, reason, why = _parse(text, self.kinds[name], self.checks.get(name))
        if keep:
            col = self.cols[name]
            if value is None and not isinstance(col, list):
                self.bad.append((name, len(col)))
            col.append(value if value is not None or isinstance(col, list)
                       else 0 if self.kinds[name] == "id" else math.nan)
        return value, reason, why

    def finish(self) -> None:
        """With a bad cell kept, every column a list with None at the bad cells (as read)."""
        if self.bad:
            self.as_lists()

    def as_lists(self) -> None:
        """Turn the typed columns into lists of Python numbers, None at the bad cells."""
        for name, col in self.cols.items():
            if not isinstance(col, list):
                self.cols[name] = col.tolist()
        for name, row in self.bad:
            self.cols[name][row] = None
        self.bad = []


def _text(path: Path, log: ProblemLog) -> str | None:
    """Return a CSV file's text read within :data:`MAX_FILE_BYTES`, or None (its problem added)."""
    return read_text(path, log, MAX_FILE_BYTES)


def _separator(header: list[str]) -> str | None:
    """Return the separator a one-cell header seems to use instead of commas, or None."""
    if len(header) != 1:
        return None
    return next((sep for sep in (";", "\t", "|", " ")
                 if len([c for c in header[0].split(sep) if c.strip()]) > 1), None)


@dataclass
class _Header:
    """The columns a header names: known ones by index, the readouts, the extra ones."""

    index: dict[str, int]
    q_columns: list[str]
    unknown: list[tuple[int, str]]
    missing: list[str]


def _header(header: list[str], top: int, required: tuple[str, ...], has_q: bool,
            optional: tuple[str, ...], named: list[str], add: Any,
            coupled: Sequence[int] = ()) -> _Header:
    """Sort a header's names into known, readout and unknown columns; report what is wrong.

    ``coupled``: 0-based axes whose readout column may be missing (coupled joints).
    """
    index: dict[str, int] = {}
    unknown: list[tuple[int, str]] = []
    for k, name in enumerate(header):
        known = (name in required or name in optional or name in named
                 or bool(has_q and Q_COLUMN.fullmatch(name)))
        if not name:
            add(top, str(k + 1), "empty column name")
        elif name in index:
            add(top, name, f"duplicated column (columns {index[name] + 1} and {k + 1})")
        elif has_q and (m := Q_COLUMN.fullmatch(name)) and int(m[1]) > MAX_COLUMNS:
            add(top, name, f"readout column beyond q{MAX_COLUMNS}_deg")
        elif known:
            index[name] = k
        else:
            unknown.append((k, name))
    q_found = [int(m[1]) for name in index if (m := Q_COLUMN.fullmatch(name))] if has_q else []
    by_name = [name for name in named if name in index]
    q_missing = False
    if by_name and q_found:
        q_missing = True
        first_q = next(name for name in index if Q_COLUMN.fullmatch(name))
        add(top, first_q, f"mixes q<n>_deg and joint-name readout columns ({by_name[0]}): "
                          "use q1_deg..qn_deg or one <joint name>_deg column per axis")
    n_q = max(q_found, default=0)
    if named and q_found and n_q < len(named) and set(range(n_q, len(named))) <= set(coupled):
        n_q = len(named)  # the last axes are coupled: their columns may be left out
    q_columns = by_name and named or q_names(n_q)
    may_miss = {name for k in coupled for name in (f"q{k + 1}_deg", *named[k:k + 1])}
    wanted = [*required, *(q_columns or ["q1_deg"] if has_q and not q_missing else [])]
    wanted = [name for name in wanted if name not in may_miss]
    for name in (missing := [name for name in wanted if name not in index]):
        if name in named:
            add(top, name, "missing column: joint-name readout columns need one per axis "
                           f"({', '.join(named)})")
        else:
            gap = "; q columns run from q1_deg to qn_deg without gaps" if name[0] == "q" else ""
            add(top, name, f"missing column{gap}")
    if q_missing or any(name in q_columns or name == "q1_deg" for name in missing):
        q_columns = []  # unknown
        missing = missing or ["q1_deg"]
    return _Header(index, q_columns, unknown, missing)


def _numeric_columns(head: _Header, rows: Rows, width: int) -> set[int]:
    """Return the unknown columns (by index) whose every cell of a full row is a number."""
    numeric = {k for k, _ in head.unknown}
    for _, cells in rows:
        if len(cells) == width and any(cells):
            numeric = {k for k in numeric if _parse(cells[k], "number")[1] is None}
            if not numeric:
                break
    return numeric


def _take_extras(head: _Header, top: int, numeric: set[int], extras: Extras, add: Any
                 ) -> list[str]:
    """Move the unknown columns a file may carry into its index; return their names.

    ``numeric``: the unknown columns whose every cell is a number (a readouts file's).
    """
    if extras == "readouts":
        taken = [(k, name) for k, name in head.unknown
                 if name not in POINT and (has_unit(name) or k in numeric)]
    else:
        taken = list(head.unknown)
    head.unknown = [u for u in head.unknown if u not in taken]
    for k, name in taken:
        if name in head.index:
            add(top, name, f"duplicated column (columns {head.index[name] + 1} and {k + 1})")
        else:
            head.index[name] = k
    return list(dict.fromkeys(name for _, name in taken))


def _unknown_columns(head: _Header, top: int, expected: list[str], listing: str, has_q: bool,
                     add: Any) -> None:
    """Report a header's unknown columns in one line, with the names they likely mean.

    ``expected``: the names a column may have; ``listing``: the same, as shown.
    """
    names = [name for _, name in head.unknown]
    if not names:
        return
    # a <name>_deg column is a joint's: guessed among the joint names only (L2_deg is not q2_deg)
    joints = [n for n in expected if n.endswith("_deg") and not Q_COLUMN.fullmatch(n)]
    meant = [close_match(name, joints if name.endswith("_deg") else expected) for name in names]
    guesses = ([m for m in meant if m] if all(meant)
               else [f"{m} for {n}" for n, m in zip(names, meant) if m])
    deg = [n for n in names if n.endswith("_deg")]
    hint = ("; <joint name>_deg columns are read only with the arm (arm=..., --arm)"
            if has_q and deg and not any(m for n, m in zip(names, meant) if n in deg) else "")
    shown = ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8 else "")
    what = "unknown column" if len(names) == 1 else f"unknown columns {shown} ({len(names)})"
    mean = f"; did you mean {', '.join(guesses[:8])}?" if guesses else ""
    add(top, names[0], f"{what}{mean}{hint}; expected: {listing}")


def read_table(path: Path, required: tuple[str, ...], has_q: bool, optional: tuple[str, ...],
               problems: list[Problem], *, extras: Extras = "refuse",
               axis_names: Iterable[str] | None = None,
               couplings: Sequence[AxisCoupling] = ()) -> Table | None:
    """Read and check one CSV file, adding its problems; return None if it has no usable header.

    The rows are read one at a time and the problems capped (:class:`ProblemLog`: a few of each
    kind shown, the others counted), so memory and output stay bounded for any file under
    :data:`MAX_FILE_BYTES`; once a file has :data:`~aacmm_pin.data.problem_log.MAX_SHOWN`
    problems its further rows are checked but no longer kept (the table is not ``complete``).

    Args:
        path: the file.
        required: columns it must have besides the readouts.
        has_q: whether it holds readouts (``q1_deg..qn_deg`` or ``<joint name>_deg``).
        optional: columns it may have; those of the column table are per-sample columns.
        problems: where each problem found is added.
        extras: what its other columns are (see :data:`Extras`); a file that misses a required
            column reports them as unknown (a misspelt name).
        axis_names: the arm's joint names, when known: allows ``<joint name>_deg`` readouts.
        couplings: the arm's coupled axes (:mod:`aacmm_pin.data.couplings`): their readout
            columns may be left out (then filled), a given one is checked.
    """
    log = ProblemLog(problems, path)
    try:
        return _read_table(path, required, has_q, optional, log, extras, axis_names, couplings)
    finally:
        log.close()


def _wrong_axis_count(q_columns: list[str], named: list[str], line: int,
                      add: Callable[..., None]) -> None:
    """Report readout columns of another number of axes than the arm's (the arm-match check).

    Args:
        q_columns: the file's readout columns, in axis order.
        named: ``<joint name>_deg`` of each of the arm's axes.
        line: the header's line.
        add: the file's problem log's ``add(line, column, reason)``.
    """
    extra = q_columns[len(named)] if len(q_columns) > len(named) else None
    n = len(named)
    add(line, extra, f"{len(q_columns)} readout columns in degrees ({q_columns[0]}.."
                     f"{q_columns[-1]}), but the arm has {n} axes (q1_deg..q{n}_deg, or "
                     f"{named[0]}..{named[-1]}): readouts of another arm, or the wrong --arm "
                     "(aacmm-pin axes ARM lists an arm's readout columns)")


def _text_and_header(path: Path, log: ProblemLog) -> tuple[str, int, list[str]] | None:
    """Return (the file's text, the header's line, its cells), or None (its problem added)."""
    add = log.add
    if (text := _text(path, log)) is None:
        return None
    first = next(records(text, log), None)
    if first is None and log.count:
        return None  # a CSV syntax error on the first line
    if first is None or not any(first[1]):
        add(1 if first else None, None, "blank first line instead of a header row" if first
            else "empty file: no header row")
        return None
    top, header = first
    if sep := _separator(header):
        add(top, None, f"the header is separated by {sep!r}, not by commas: write a CSV file "
                       "with ',' between cells and '.' as decimal point (12.5, not 12,5)")
        return None
    if len(header) > MAX_COLUMNS:
        add(top, None, f"{len(header)} columns in the header; at most {MAX_COLUMNS} are read")
        return None
    return text, top, header


def _read_rows(table: Table, cells: _Cells, rows: Rows, index: dict[str, int], width: int,
               taken: list[str], log: ProblemLog) -> int:
    """Check the data rows (cells as written) into ``table``; return their number.

    Args:
        table: where the lines of the rows kept go (its ``complete`` cleared once the file has
            :data:`~aacmm_pin.data.problem_log.MAX_SHOWN` problems).
        cells: the columns' parsed cells.
        rows: the data rows, cells as written.
        index: column name -> its index in a row.
        width: the header's number of columns.
        taken: the extra columns read as numbers.
        log: the file's problems.
    """
    add, n_rows = log.add, 0
    for chunk in _chunks(rows):
        n_rows += len(chunk)
        if cells.fast(chunk, index, width, keep := table.complete and log.count < MAX_SHOWN):
            table.complete = keep
            if keep:
                table.lines.extend(line for line, _ in chunk)
            continue
        for line, cells_written in chunk:  # a problem: cell by cell, each problem added
            row = [c.strip() for c in cells_written]
            if not any(row):
                add(line, None, "blank line among the data rows")
                continue
            if len(row) != width:
                add(line, None, f"{len(row)} cells, but the header has {width} columns",
                    kind=("cells", len(row)))
                continue
            keep = table.complete = table.complete and log.count < MAX_SHOWN
            if keep:
                table.lines.append(line)
            for name, k in index.items():
                value, reason, why = cells.parse(name, row[k], keep)
                if reason and value is None and reason.startswith("'"):
                    if name == POSE_COLUMN:
                        reason += ("; the pose column numbers each row's pose (rows with the same "
                                   "number are one pose; import-points --pose numbers labels)")
                    elif name in taken:
                        reason += f"; {table.path.name}'s further columns hold numbers"
                if reason:
                    add(line, name, reason, kind=why, unit="cells")
    cells.finish()
    return n_rows


def _read_table(path: Path, required: tuple[str, ...], has_q: bool, optional: tuple[str, ...],
                log: ProblemLog, extras: Extras, axis_names: Iterable[str] | None,
                couplings: Sequence[AxisCoupling] = ()) -> Table | None:
    """:func:`read_table` with its problems going to ``log``."""
    add = log.add
    if (read := _text_and_header(path, log)) is None:
        return None
    text, top, header = read
    named = [f"{n}_deg" for n in axis_names or []] if has_q else []
    coupled = [c.axis for c in couplings] if has_q else []
    head = _header(header, top, required, has_q, optional, named, add, coupled)
    if named and head.q_columns and len(head.q_columns) != len(named):
        _wrong_axis_count(head.q_columns, named, top, add)
    taken: list[str] = []
    if extras != "refuse" and not head.missing:
        quiet = ProblemLog([], path)  # a syntax error is reported by the reading pass below
        numeric = (_numeric_columns(head, data_rows(text, quiet), len(header))
                   if extras == "readouts" and head.unknown else set())
        taken = _take_extras(head, top, numeric, extras, add)
    if extras == "numbers" and head.missing:  # a declared column is carried, not misspelt
        declared = {c.name for c in registered_columns()}
        head.unknown = [(k, name) for k, name in head.unknown if name not in declared]
    if extras == "refuse" or (extras == "numbers" and head.missing):
        expected = [*required, *optional,
                    *([*named, *q_names(max(len(header), 9))] if has_q else [])]
        listing = ", ".join([*required, *(["q1_deg..qn_deg"] if has_q else []), *optional])
        if named:
            listing += f" (or {', '.join(named)} instead of q1_deg..q{len(named)}_deg)"
        _unknown_columns(head, top, expected, listing, has_q and not named, add)
    per_sample = [name for name in header if name in taken or (name in optional and name in head.index
                                                                and (has_unit(name) or name == POSE_COLUMN))]
    kinds = {name: ("angle" if name in head.q_columns or Q_COLUMN.fullmatch(name)
                    or name in named else "column" if name in per_sample
                    else _KINDS.get(name, "number")) for name in head.index}
    cells = _Cells(kinds, {name: column(name) for name in per_sample})
    table = Table(path, head.q_columns, array("q"), cells.cols, per_sample)
    n_rows = _read_rows(table, cells, data_rows(text, log, strip=False), head.index,
                        len(header), taken, log)
    if not n_rows:
        add(None, None, "header only: no data rows")
    if coupled and head.q_columns:
        cells.as_lists()  # a filled column holds None where a cell it needs is bad
        fill_or_check(table.cols, table.q_columns, table.lines, couplings, add)
    return table


def q_names(n: int) -> list[str]:
    """Return the names of the encoder columns, q1_deg..qn_deg."""
    return [f"q{i}_deg" for i in range(1, n + 1)]


def numbers(table: Table, name: str) -> np.ndarray:
    """Return one column of numbers as floats, shape (rows,), NaN at its bad cells."""
    col = table.cols[name]
    if isinstance(col, list):
        return np.array([math.nan if v is None else v for v in col], dtype=float)
    return np.array(col, dtype=float)


def matrix(table: Table, names: Iterable[str], scale: float) -> np.ndarray:
    """Return the named columns as a float array, shape (rows, len(names)), times ``scale``."""
    out: np.ndarray = np.array([table.cols[name] for name in names], dtype=float).T * scale
    return out


def per_sample_columns(table: Table) -> dict[str, np.ndarray]:
    """Return a table's per-sample columns by file name, in SI (see :mod:`aacmm_pin.data.columns`)."""
    return {name: column(name).to_si(table.cols[name]) for name in table.per_sample}


def check_radians(table: Table, out: list[Problem]) -> None:
    """Report readouts that look like radians: every column within +-2 pi over many rows.

    With ``units.RADIAN_MIN_ROWS`` rows or more, every readout column within +-2 pi and some
    column moving by 1 or more: in degrees that is an arm that turned less than 6.3 deg on every
    axis through a whole measurement (a SPAT, bar or tracker campaign moves axes by tens of
    degrees), in radians an ordinary one.
    """
    if len(table.lines) < RADIAN_MIN_ROWS or not table.q_columns or not table.complete:
        return
    cols = [numbers(table, name) for name in table.q_columns]
    if any(np.isnan(c).any() for c in cols):
        return  # bad cells, reported already
    k = radian_like_column(np.stack(cols, axis=1))
    if k is not None:
        name = table.q_columns[k]
        out.append(Problem(table.path, table.lines[0], name,
                           f"every readout column lies within +-6.29 over {len(table.lines)} "
                           f"rows ({name} spans {float(np.ptp(cols[k])):.3g}): these look like "
                           "radians; write degrees"))


def radian_like_column(degrees: np.ndarray) -> int | None:
    """Return the column that moves most if angle columns in degrees look like radians, else None.

    ``degrees`` (N, n): the angles as written in a file that says degrees. They look like radians
    when every value lies within +-2 pi and some column moves by 1 or more (see
    :func:`check_radians`); the caller checks ``N >= units.RADIAN_MIN_ROWS``.
    """
    ptp = np.ptp(degrees, axis=0)
    if np.max(np.abs(degrees)) <= 2 * math.pi and np.max(ptp) >= 1.0:
        return int(np.argmax(ptp))
    return None


def usable(table: Table | None, *columns: str) -> TypeGuard[Table]:
    """Tell whether a table has data rows and these columns (else its problems are reported)."""
    return (table is not None and table.complete and bool(table.lines)
            and set(columns) <= table.cols.keys())
