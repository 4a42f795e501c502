"""One CSV file of a campaign or of readouts, read and checked cell by cell into named columns.

:func:`read_table` is told which columns a file must and may have, reads it with a bound on its
size, and adds a :class:`~aacmm_pin.errors.Problem` (file, line, column, reason) for every bad
header or cell instead of stopping at the first. Values stay in file units (mm, deg); the callers
(:mod:`aacmm_pin.data.campaign`) convert them. Per-sample columns (``t_s``, ``temp_c``, ``sigma_um``
and any extra numeric column) are checked against the column table, :mod:`aacmm_pin.data.columns`.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TypeGuard

import numpy as np

from aacmm_pin.data.columns import MAX_ANGLE_DEG, Column, column, has_unit
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
    lines: list[int]
    """1-based file line of each row kept (rows with the header's number of cells)."""
    cols: dict[str, list[Any]]
    """Parsed cells of each known column, in file units; None where a cell is bad."""
    per_sample: list[str] = field(default_factory=list)
    """The per-sample columns read (optional ones of the column table and extra ones), in file
    order; their cells are checked against :func:`aacmm_pin.data.columns.column`."""

    @property
    def n_axes(self) -> int:
        """Number of readout columns (0: missing or with gaps)."""
        return len(self.q_columns)


def _parse(text: str, kind: str, col: Column | None = None) -> tuple[Any, str | None]:
    """Return (value, None) for a good cell, or (None, reason)."""
    if not text or kind == "text":
        return (text, None) if text else (None, "empty cell")
    try:
        value = int(text) if kind == "id" else float(text)
    except ValueError:
        return None, f"'{text}' is not {'an integer' if kind == 'id' else 'a number'}"
    why = col.check(value) if col is not None else _bad_value(value, kind)
    reason = None if why is None else f"{text} {why}"
    return (None if reason else value), reason


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
        return (f"mm is beyond an R-Test's measuring range (+-{RTEST_RANGE * 1e3:g} mm): a unit "
                "or sensor error")
    if kind == "coordinate" and abs(value) > MAX_COORDINATE * 1e3:
        return f"mm is beyond +-{MAX_COORDINATE:g} m: not a position an arm or tracker measures"
    return None


def _rows(path: Path, add: Any) -> list[tuple[int, list[str]]] | None:
    """Return the (line, stripped cells) of a CSV file read within the size bound, or None."""
    try:
        with path.open("rb") as f:
            data = f.read(MAX_FILE_BYTES + 1)  # bounded: a huge file or /dev/zero fails fast
        if len(data) > MAX_FILE_BYTES:
            add(None, None, f"larger than {MAX_FILE_BYTES // 2**20} MiB: split the campaign or "
                            "decimate it")
            return None
        reader = csv.reader(io.StringIO(data.decode("utf-8-sig")))
        rows = [(reader.line_num, [c.strip() for c in row]) for row in reader]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else f"{exc}"
        add(None, None, "file not found" if isinstance(exc, FileNotFoundError) else why)
        return None
    while rows and not any(rows[-1][1]):
        rows.pop()  # blank trailing lines
    if not rows or not any(rows[0][1]):
        add(1 if rows else None, None, "blank first line instead of a header row" if rows
            else "empty file: no header row")
        return None
    return rows


@dataclass
class _Header:
    """The columns a header names: known ones by index, the readouts, the extra ones."""

    index: dict[str, int]
    q_columns: list[str]
    unknown: list[tuple[int, str]]
    missing: list[str]


def _header(header: list[str], top: int, required: tuple[str, ...], has_q: bool,
            optional: tuple[str, ...], named: list[str], add: Any) -> _Header:
    """Sort a header's names into known, readout and unknown columns; report what is wrong."""
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
    q_columns = by_name and named or q_names(max(q_found, default=0))
    wanted = [*required, *(q_columns or ["q1_deg"] if has_q and not q_missing else [])]
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


def _take_extras(head: _Header, rows: list[tuple[int, list[str]]], extras: Extras, add: Any
                 ) -> list[str]:
    """Move the unknown columns a file may carry into its index; return their names."""
    if extras == "readouts":
        width = len(rows[0][1])

        def numeric(k: int) -> bool:
            cells = [c[k] for _, c in rows[1:] if len(c) == width and any(c)]
            return all(_parse(c, "number")[1] is None for c in cells)

        taken = [(k, name) for k, name in head.unknown
                 if name not in POINT and (has_unit(name) or numeric(k))]
    else:
        taken = list(head.unknown)
    head.unknown = [u for u in head.unknown if u not in taken]
    for k, name in taken:
        if name in head.index:
            add(rows[0][0], name, f"duplicated column (columns {head.index[name] + 1} and {k + 1})")
        else:
            head.index[name] = k
    return list(dict.fromkeys(name for _, name in taken))


def read_table(path: Path, required: tuple[str, ...], has_q: bool, optional: tuple[str, ...],
               problems: list[Problem], *, extras: Extras = "refuse",
               axis_names: Iterable[str] | None = None) -> Table | None:
    """Read and check one CSV file, adding its problems; return None if it has no usable header.

    Args:
        path: the file.
        required: columns it must have besides the readouts.
        has_q: whether it holds readouts (``q1_deg..qn_deg`` or ``<joint name>_deg``).
        optional: columns it may have; those of the column table are per-sample columns.
        problems: where each problem found is added.
        extras: what its other columns are (see :data:`Extras`); a file that misses a required
            column reports them as unknown (a misspelt name).
        axis_names: the arm's joint names, when known: allows ``<joint name>_deg`` readouts.
    """

    def add(line: int | None, column: str | None, reason: str) -> None:
        problems.append(Problem(path, line, column, reason))

    if (rows := _rows(path, add)) is None:
        return None
    top, header = rows[0]
    if len(header) > MAX_COLUMNS:
        add(top, None, f"{len(header)} columns in the header; at most {MAX_COLUMNS} are read")
        return None
    named = [f"{n}_deg" for n in axis_names or []] if has_q else []
    head = _header(header, top, required, has_q, optional, named, add)
    taken = [] if extras == "refuse" or head.missing else _take_extras(head, rows, extras, add)
    if extras == "refuse" or (extras == "numbers" and head.missing):
        expected = ", ".join([*required, *(["q1_deg..qn_deg"] if has_q else []), *optional])
        if named:
            expected += f" (or {', '.join(named)} instead of q1_deg..q{len(named)}_deg)"
        for _, name in head.unknown:
            hint = ("; <joint name>_deg columns are read only with the arm (arm=..., --arm)"
                    if has_q and not named and name.endswith("_deg") else "")
            add(top, name, f"unknown column; expected: {expected}{hint}")
    if len(rows) == 1:
        add(None, None, "header only: no data rows")
    per_sample = [name for name in header if name in taken
                  or (name in optional and name in head.index and has_unit(name))]
    table = Table(path, head.q_columns, [], {name: [] for name in head.index}, per_sample)
    kinds = {name: ("angle" if name in head.q_columns or Q_COLUMN.fullmatch(name)
                    or name in named else "column" if name in per_sample
                    else _KINDS.get(name, "number")) for name in head.index}
    checks = {name: column(name) for name in per_sample}
    for line, cells in rows[1:]:
        if not any(cells):
            add(line, None, "blank line among the data rows")
        elif len(cells) != len(header):
            add(line, None, f"{len(cells)} cells, but the header has {len(header)} columns")
        else:
            table.lines.append(line)
            for name, k in head.index.items():
                value, reason = _parse(cells[k], kinds[name], checks.get(name))
                table.cols[name].append(value)
                if reason and name in taken and value is None and reason.startswith("'"):
                    reason += f"; {path.name}'s further columns hold numbers"
                if reason:
                    add(line, name, reason)
    return table


def q_names(n: int) -> list[str]:
    """Return the names of the encoder columns, q1_deg..qn_deg."""
    return [f"q{i}_deg" for i in range(1, n + 1)]


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
    if len(table.lines) < RADIAN_MIN_ROWS or not table.q_columns:
        return
    cols = [np.array([math.nan if v is None else v for v in table.cols[name]], dtype=float)
            for name in table.q_columns]
    if any(np.isnan(c).any() for c in cols):
        return  # bad cells, reported already
    ptp = [float(np.ptp(c)) for c in cols]
    if max(float(np.max(np.abs(c))) for c in cols) <= 2 * math.pi and max(ptp) >= 1.0:
        name = table.q_columns[int(np.argmax(ptp))]
        out.append(Problem(table.path, table.lines[0], name,
                           f"every readout column lies within +-6.29 over {len(table.lines)} "
                           f"rows ({name} spans {max(ptp):.3g}): these look like radians; "
                           "write degrees"))


def usable(table: Table | None, *columns: str) -> TypeGuard[Table]:
    """Tell whether a table has data rows and these columns (else its problems are reported)."""
    return table is not None and bool(table.lines) and set(columns) <= table.cols.keys()
