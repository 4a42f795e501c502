"""The campaign files: read a folder of CSV files into a :class:`Campaign`, write one back.

The folder holds ``spat.csv`` + ``locations.csv`` (R-Test SPAT), ``lengthbar.csv`` + ``bar.csv``
(length bar) and/or ``points.csv`` (absolute tool points from a laser tracker or motion capture),
comma separated with a header row, in mm and degrees (the columns are in
``_FILES`` below). Readers check every cell and raise one :class:`CampaignFormatError` listing every
problem of every file with its line and column. Inside the package everything is SI (m, rad, s).

**Readout columns.** Either ``q1_deg..qn_deg`` (axis order) or, when the reader is told the arm's
joint names, one ``<joint name>_deg`` column per axis (``A1_deg``, ``left_j3_deg``), in any column
order; not both. **Tools.** ``points.csv`` may name the tool each point measures in a ``tool``
column (e.g. ``left``): optional for a single-tool arm, needed for several tools; told the tool
names, the reader checks it (else :func:`aacmm_pin.fit.measurements.check_points` does).
**Per-sample columns.** Any further numeric column of ``spat.csv``, ``lengthbar.csv``,
``points.csv`` or a readouts file (``t_s``, ``temp_c``, a user's ``temp_wrist_c``) is read by name
into the log's ``columns``, in SI, its cells checked against :mod:`aacmm_pin.data.columns`.

The readers never load an arm: they are told its axis and tool names, by any object with
``axis_names`` and ``tool_names`` (:class:`ArmNames`, e.g. an :class:`~aacmm_pin.model.arm.Arm`) or by
the keywords ``axis_names=`` and ``tool_names=``.
"""

from __future__ import annotations

import csv
import math
import warnings
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aacmm_pin.data.arm_names import ArmNames, couplings_of, given_names
from aacmm_pin.data.campaign_writer import write_campaign, write_points
from aacmm_pin.data.columns import MAX_ANGLE_DEG, check_names
from aacmm_pin.data.csv_table import (
    DISPLACEMENT,
    MAX_COLUMNS,
    MAX_FILE_BYTES,
    POINT,
    Q_COLUMN,
    Table,
    check_radians,
    matrix,
    numbers,
    per_sample_columns,
    read_table,
    usable,
)
from aacmm_pin.data.logs import (
    NOISE_FILE,
    Campaign,
    LengthBarLog,
    PointLog,
    SpatLog,
    StatedNoise,
    read_noise,
)
from aacmm_pin.data.output_claim import CALIBRATION_FILES
from aacmm_pin.data.poses import POSE_COLUMN
from aacmm_pin.data.problem_log import ProblemLogs
from aacmm_pin.errors import CampaignFormatError, CampaignWarning, Problem

__all__ = ["MAX_ANGLE_DEG", "MAX_COLUMNS", "MAX_FILE_BYTES", "NOISE_FILE", "ArmNames", "Campaign",
           "LengthBarLog", "PointLog", "SpatLog", "StatedNoise", "read_campaign", "read_id_columns",
           "read_noise", "read_readout_columns", "read_readouts", "read_sample_columns",
           "read_tool_column", "write_campaign", "write_points"]

_XYZ = {"spat": DISPLACEMENT, "loc": POINT}
_OPTIONAL = ("t_s", "temp_c")
# File -> (required columns besides q, has q1_deg..qn_deg, optional columns), in file order.
_FILES: dict[str, tuple[tuple[str, ...], bool, tuple[str, ...]]] = {
    "spat.csv": (("location", *_XYZ["spat"]), True, _OPTIONAL),
    "locations.csv": (("location", *_XYZ["loc"]), False, ()),
    "lengthbar.csv": (("placement", "socket"), True, _OPTIONAL),
    "bar.csv": (("from", "to", "length_mm"), False, ()),
    "points.csv": (_XYZ["loc"], True, ("group", "tool", "sigma_um", *_OPTIONAL, POSE_COLUMN)),
}
_LOGS = ("spat.csv", "lengthbar.csv", "points.csv")  # files whose extra numeric columns are read
_CAMPAIGN_COLUMNS = tuple(dict.fromkeys(c for required, _, optional in _FILES.values()
                                        for c in (*required, *optional)))
"""Every column a campaign file has: a readouts file cut from one carries them, not as unknowns."""


def _first_lines(lines: Sequence[int], values: Any) -> tuple[dict[Any, int], Counter[Any]]:
    """Return the first line of each value of a column and how many rows hold it.

    A typed column (an ``array``: every cell good) is counted without a Python object per row
    (1.6M samples: a list of (line, value) tuples took 150 MB); a list (bad cells are None) as is.
    """
    if not isinstance(values, list):
        uniq, first, count = np.unique(np.asarray(values), return_index=True, return_counts=True)
        at = np.asarray(lines)[first]
        return (dict(zip(uniq.tolist(), at.tolist())),
                Counter(dict(zip(uniq.tolist(), count.tolist()))))
    return ({v: line for line, v in reversed(list(zip(lines, values)))}, Counter(values))


def _check_locations(spat: Table, locs: Table, min_samples: int, out: ProblemLogs) -> None:
    """Check duplicated ids, locations without zero position and locations with too few samples."""
    zero_line: dict[int, int] = {}
    for line, v in zip(locs.lines, locs.cols["location"]):
        if v is not None and v in zero_line:
            out.add(locs.path, line, "location",
                    f"location {v} is duplicated (also on line {zero_line[v]})", "duplicated")
        zero_line.setdefault(v, line)
    first_line, counts = _first_lines(spat.lines, spat.cols["location"])
    least = max(min_samples, 1)
    for v in sorted((set(first_line) | set(zero_line)) - {None}):
        path, line = (spat.path, first_line[v]) if v in first_line else (locs.path, zero_line[v])
        if v not in zero_line:
            out.add(path, line, "location", f"location {v} has no zero position in locations.csv",
                    "no zero")
        elif counts[v] < least:
            out.add(path, line, "location", f"location {v} has {counts[v]} samples in spat.csv, "
                                            f"fewer than {least}", "few samples")


def _check_bar(log: Table, bar: Table, out: ProblemLogs) -> None:
    """Check that every measured socket is in bar.csv and every bar.csv pair is measured once."""
    first_line = {s: line for line, s in reversed(list(zip(log.lines, log.cols["socket"])))}
    together: dict[int, set[str]] = {}
    for placement, s in zip(log.cols["placement"], log.cols["socket"]):
        together.setdefault(placement, set()).add(s)
    pair_line: dict[frozenset[str], int] = {}

    def say(line: int, column: str | None, reason: str) -> None:
        out.add(bar.path, line, column, reason, (column, reason.split("'")[0]))

    for line, a, b in zip(bar.lines, bar.cols["from"], bar.cols["to"]):
        if a is None or b is None:
            continue  # an empty cell, reported already
        pair = frozenset((a, b))
        if a == b or pair in pair_line:
            say(line, "to", f"a bar from socket '{a}' to itself" if a == b
                else f"pair {a},{b} is also on line {pair_line[pair]}")
        pair_line.setdefault(pair, line)
        for side, s in (("from", a), ("to", b)):
            if s not in first_line:
                say(line, side, f"socket '{s}' is never measured in lengthbar.csv")
        if {a, b} <= first_line.keys() and not any(pair <= both for both in together.values()):
            say(line, None, f"sockets '{a}' and '{b}' are never measured in one placement")
    named = {s for pair in pair_line for s in pair}
    for s, line in first_line.items():
        if s is not None and s not in named:
            out.add(log.path, line, "socket", f"socket '{s}' is not named in bar.csv", "unnamed")


def _check_tools(points: Table, tool_names: list[str], out: ProblemLogs) -> None:
    """Check the ``tool`` column of points.csv against the arm's tools (names or tool joints)."""
    names = set(tool_names) | {n if n == "tool" else f"tool_{n}" for n in tool_names}
    listing = ", ".join(tool_names)
    if "tool" not in points.cols:
        if len(tool_names) > 1:
            out.add(points.path, 1, "tool", f"missing column: the arm has {len(tool_names)} tools "
                                            f"({listing}); say which one each point measures")
        return
    for line, name in zip(points.lines, points.cols["tool"]):
        if name is not None and name not in names:
            out.add(points.path, line, "tool", f"unknown tool '{name}'; the arm's tools: {listing}",
                    "unknown tool")


_MIX = np.uint64(0x9E3779B97F4A7C15)
"""An odd 64-bit constant (the golden ratio's): multiplying by it spreads a row's cells over its
hash."""


def _cell_codes(col: Any) -> np.ndarray:
    """Return one uint64 per cell, equal exactly where the cells are equal (shape (rows,))."""
    if isinstance(col, list) and col and isinstance(col[0], str):
        return np.unique(np.asarray(col, dtype=object), return_inverse=True)[1].reshape(-1).astype(
            np.uint64)
    values = np.asarray(col)
    if values.dtype.kind == "f":
        values = values + 0.0  # -0.0 == 0.0: one bit pattern
    return np.ascontiguousarray(values).view(np.uint64).reshape(-1)


def _repeated_rows(cols: list[Any]) -> tuple[np.ndarray, np.ndarray, int] | None:
    """Return the rows that repeat an earlier row cell for cell, or None if none does.

    Returns:
        ``(copies, first, most)``: the repeating rows (ascending), the earlier row each repeats
        (its first occurrence), the most copies of one row. Rows are hashed (a pass per column);
        only rows whose hash repeats are compared cell by cell.
    """
    codes = [_cell_codes(c) for c in cols]
    digest = np.zeros(len(codes[0]), dtype=np.uint64)
    for c in codes:
        digest = (digest ^ c) * _MIX
    order = np.argsort(digest, kind="stable")
    same = digest[order[1:]] == digest[order[:-1]]
    shared = np.zeros(len(digest), dtype=bool)
    shared[order[1:][same]] = shared[order[:-1][same]] = True
    rows = np.flatnonzero(shared)
    if not rows.size:
        return None
    _, first, inverse = np.unique(np.stack([c[rows] for c in codes], axis=1), axis=0,
                                  return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    copied = first[inverse] != np.arange(len(rows))
    if not copied.any():
        return None  # the hashes met, the rows differ
    return rows[copied], rows[first[inverse[copied]]], int(np.bincount(inverse).max())


def _copies(table: Table) -> str | None:
    """Return a note on the rows of a measurement log that repeat an earlier row cell for cell.

    Noted, not refused: a static arm read twice within one clock tick gives equal rows (the
    package's own ``acquire`` writes them on a loaded machine), and the file cannot tell such a
    reading from a pasted copy. A copy counts one measurement twice, so the fit's claimed standard
    deviations shrink as if it were independent (by sqrt(copies) for a row copied throughout).
    """
    if not table.n_axes or any(isinstance(c, list) and None in c for c in table.cols.values()):
        return None  # bad readout columns or cells, reported already
    found = _repeated_rows(list(table.cols.values()))
    if found is None:
        return None
    copies, first, most = found
    lines = np.asarray(table.lines)
    k = int(copies[0])
    return (f"{table.path}:{lines[k]}: {copies.size} row(s) repeat an earlier row cell for cell "
            f"(this one is line {lines[first[0]]}; up to {most} copies of one row): "
            "each copy counts as one more measurement and shrinks the claimed std; remove "
            "copies that are not distinct readings")


def _log_fields(table: Table) -> dict[str, Any]:
    """Return the q (rad), lines and per-sample columns (by file name, SI) of a log's table."""
    return {"q": matrix(table, table.q_columns, math.pi / 180.0),
            "lines": np.array(table.lines, dtype=np.int64), "columns": per_sample_columns(table)}


def _logs(tables: dict[str, Table]) -> dict[str, Any]:
    """Return the Campaign fields of checked tables (spat, locations, lengthbar, bar, points)."""
    spat, locs = tables.get("spat.csv"), tables.get("locations.csv")
    log, bar = tables.get("lengthbar.csv"), tables.get("bar.csv")
    points = tables.get("points.csv")
    return dict(
        spat=None if not (spat and locs) else SpatLog(
            location=np.array(spat.cols["location"], dtype=np.int64),
            displacement=matrix(spat, _XYZ["spat"], 1e-3), **_log_fields(spat)),
        locations={} if not locs else dict(zip(locs.cols["location"],
                                                matrix(locs, _XYZ["loc"], 1e-3))),
        lengthbar=None if not (log and bar) else LengthBarLog(
            placement=np.array(log.cols["placement"], dtype=np.int64),
            socket=np.array(log.cols["socket"], dtype=str), **_log_fields(log)),
        bar={} if not bar else {(a, b): v * 1e-3 for a, b, v in zip(
            bar.cols["from"], bar.cols["to"], bar.cols["length_mm"])},
        points=None if not points else PointLog(
            group=np.array(points.cols.get("group", [1] * len(points.lines)), dtype=np.int64),
            point=matrix(points, _XYZ["loc"], 1e-3),
            tool=np.array(points.cols["tool"], dtype=str) if "tool" in points.cols else None,
            **_log_fields(points)))


def _other_csv_hint(folder: Path) -> str:
    """Return a hint for a folder holding other CSV files (an instrument's export?), else "".

    Not for a calibration folder (its ``encoder_maps.csv``).
    """
    others = sorted(p.name for p in folder.glob("*.csv") if p.is_file())
    if not others or (folder / CALIBRATION_FILES[0]).exists():
        return ""
    shown = ", ".join(others[:3]) + (f" and {len(others) - 3} more" if len(others) > 3 else "")
    return (f"; it holds {shown}: convert a laser-tracker or motion-capture file with "
            "`aacmm-pin import-points FILE --out FOLDER`")


def read_campaign(folder: str | Path, *, min_samples_per_location: int = 3,
                  arm: ArmNames | None = None, axis_names: Sequence[str] | None = None,
                  tool_names: Sequence[str] | None = None) -> Campaign:
    """Read and validate a campaign folder.

    Args:
        folder: folder holding spat.csv + locations.csv, lengthbar.csv + bar.csv and/or
            points.csv.
        min_samples_per_location: fewest SPAT samples accepted at one R-Test location.
        arm: the arm (any object with ``axis_names`` and ``tool_names``, :class:`ArmNames`), when
            known: allows ``<joint name>_deg`` readout columns (put in axis order) and checks the
            ``tool`` column of points.csv against its tools.
        axis_names: the arm's joint names (instead of ``arm``, or overriding its).
        tool_names: the arm's tool names (instead of ``arm``, or overriding its).

    Returns:
        The campaign in SI units (m, rad, s), with ``source`` set to the folder; every extra
        numeric column of spat.csv, lengthbar.csv and points.csv in its log's ``columns``.

    Raises:
        CampaignFormatError: listing every problem of all files, each with file, line and column.
    """
    folder = Path(folder)
    paths = {name: folder / name for name in _FILES}
    present = {name for name, path in paths.items() if path.is_file()}
    if not present & set(_LOGS):
        why = ("does not exist" if not folder.exists() else "is not a folder"
               if not folder.is_dir() else "holds neither spat.csv, lengthbar.csv nor points.csv"
               + _other_csv_hint(folder))
        raise CampaignFormatError([Problem(folder, None, None, f"the campaign folder {why}")])
    problems: list[Problem] = []
    for pair in (["spat.csv", "locations.csv"], ["lengthbar.csv", "bar.csv"]):
        if len(found := [name for name in pair if name in present]) == 1:
            problems.append(Problem(paths[(set(pair) - set(found)).pop()], None, None,
                                    f"file not found; {found[0]} needs it (they come in a pair)"))
    axes, tools = given_names(arm, axis_names, tool_names)
    tables = {name: read_table(paths[name], *_FILES[name], problems, axis_names=axes,
                               extras="numbers" if name in _LOGS else "refuse",
                               couplings=couplings_of(arm))
              for name in _FILES if name in present}
    spat, locs = tables.get("spat.csv"), tables.get("locations.csv")
    log, bar = tables.get("lengthbar.csv"), tables.get("bar.csv")
    points = tables.get("points.csv")
    checks = ProblemLogs(problems)
    if usable(spat, "location") and usable(locs, "location"):
        _check_locations(spat, locs, min_samples_per_location, checks)
    if usable(log, "placement", "socket") and usable(bar, "from", "to"):
        _check_bar(log, bar, checks)
    if points is not None and tools is not None and points.lines:
        _check_tools(points, tools, checks)
    checks.close()
    carried = [note for name, table in tables.items() if table is not None and name in _LOGS
               and (note := check_names(table.path, table.per_sample, _FILES[name][2], problems))
               is not None]
    for table in (spat, log, points):
        if table is not None:
            check_radians(table, problems)
    first = next((t for t in (spat, log, points) if t and t.n_axes), None)
    for other in (log, points):
        if first and other and other is not first and other.n_axes and other.n_axes != first.n_axes:
            problems.append(Problem(other.path, 1, None,
                                    f"{other.n_axes} axes ({other.q_columns[0]}.."
                                    f"{other.q_columns[-1]}), but "
                                    f"{first.path.name} has {first.n_axes}"))
    if problems:
        order: dict[Path | str, int] = {path: k for k, path in enumerate(paths.values())}
        raise CampaignFormatError(sorted(problems, key=lambda p: (order[p.path], p.line or 0)))
    noise = read_noise(folder / NOISE_FILE) if (folder / NOISE_FILE).is_file() else None
    notes = tuple(note for table in (spat, log, points) if usable(table)
                  and (note := _copies(table)) is not None)
    for note in (*notes, *carried):
        warnings.warn(note, CampaignWarning, stacklevel=2)
    for table in (spat, log, points):
        if usable(table) and (beyond := _limits_note(table, arm)) is not None:
            warnings.warn(beyond, CampaignWarning, stacklevel=2)
    return Campaign(**_logs({k: v for k, v in tables.items() if v is not None}), source=folder,
                    noise=noise, notes=notes)


LIMIT_MARGIN_DEG = 1.0
"""Readouts beyond an axis' stated limit by more than this, deg, are warned of: a readout is the
true angle plus the encoder's error (tens of arcsec on an arm worth calibrating; 1 deg is 3600)."""


def _limits_note(table: Table, arm: ArmNames | None) -> str | None:
    """Return one line if readouts of ``table`` lie beyond the arm's stated limits, else None.

    The arm's ``stated_limits`` (shape (n_axes, 2), rad, NaN where none; an
    :class:`~aacmm_pin.model.arm.Arm` has them) and :data:`LIMIT_MARGIN_DEG`; an arm without them,
    or a file with another number of axes (refused already), is not checked.
    """
    limits = getattr(arm, "stated_limits", None)
    if limits is None or not table.q_columns or len(table.q_columns) != len(limits):
        return None
    low, high = (np.degrees(limits[:, k]) for k in (0, 1))
    beyond = []
    for a, name in enumerate(table.q_columns):
        q = numbers(table, name)
        with np.errstate(invalid="ignore"):
            out = (q < low[a] - LIMIT_MARGIN_DEG) | (q > high[a] + LIMIT_MARGIN_DEG)
        beyond += [(int(r), a, name, float(q[r])) for r in np.flatnonzero(out)]
    if not beyond:
        return None
    r, a, name, value = min(beyond)
    more = f" (and {len(beyond) - 1} more readouts beyond their axis' limits)" if len(beyond) > 1 \
        else ""
    assert arm is not None
    return (f"{table.path.name} line {table.lines[r]}: column '{name}': {value:g} deg is beyond "
            f"{arm.axis_names[a]}'s limits ({low[a]:g}..{high[a]:g} deg){more}: readouts of "
            "another arm, or columns in another order (aacmm-pin axes ARM lists them)")


def _readout_table(path: str | Path, optional: tuple[str, ...], arm: ArmNames | None,
                   axis_names: Sequence[str] | None, tool_names: Sequence[str] | None = None,
                   ) -> Table:
    """Read a readouts file's q columns and per-sample columns; raise on any problem.

    A ``tool`` column is read, and checked against the tool names, if ``optional`` names it.
    """
    problems: list[Problem] = []
    axes, tools = given_names(arm, axis_names, tool_names)
    table = read_table(Path(path), (), True, optional, problems, extras="readouts",
                       axis_names=axes, couplings=couplings_of(arm))
    if table is not None and tools is not None and "tool" in optional and table.lines:
        checks = ProblemLogs(problems)
        _check_tools(table, tools, checks)
        checks.close()
    carried = None if table is None else check_names(
        table.path, table.per_sample, (*optional, *_CAMPAIGN_COLUMNS), problems)
    if problems or table is None:
        raise CampaignFormatError(problems)
    for note in (carried, _limits_note(table, arm)):
        if note is not None:
            warnings.warn(note, CampaignWarning, stacklevel=3)
    return table


def read_readouts(path: str | Path, arm: ArmNames | None = None, *,
                  axis_names: Sequence[str] | None = None) -> np.ndarray:
    """Read encoder readouts from a CSV file with columns q1_deg..qn_deg, e.g. a lengthbar.csv.

    Other columns are ignored; the q columns and cells are checked as in :func:`read_campaign`
    (told the joint names, by ``arm`` or ``axis_names``, ``<joint name>_deg`` columns are read too).

    Returns:
        Encoder readouts, shape (N, n), in rad.

    Raises:
        CampaignFormatError: listing every problem in the q columns, with line and column.
    """
    return read_sample_columns(path, arm, axis_names=axis_names)[0]


def read_sample_columns(path: str | Path, arm: ArmNames | None = None, *,
                        axis_names: Sequence[str] | None = None
                        ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Read encoder readouts and every per-sample column of a readouts file (e.g. predict's input).

    A per-sample column is one of the column table (``t_s``, ``temp_c``, ``sigma_um``, a
    registered one), one whose name ends with a unit suffix (``temp_wrist_c``), or one whose every
    cell is a number; its cells are checked (:mod:`aacmm_pin.data.columns`). Text columns (a pose id, a
    ``tool`` column) and ``x_mm``, ``y_mm``, ``z_mm`` are left out.

    Returns:
        ``(q, columns)``: readouts (N, n) rad, and each per-sample column (N,) in SI by file name.

    Raises:
        CampaignFormatError: listing every problem in these columns, with line and column.
    """
    table = _readout_table(path, _OPTIONAL, arm, axis_names)
    fields = _log_fields(table)
    return fields["q"], fields["columns"]


def read_readout_columns(path: str | Path, arm: ArmNames | None = None, *,
                         axis_names: Sequence[str] | None = None
                         ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Read encoder readouts and, when present, the ``temp_c`` and ``t_s`` columns.

    Told the joint names, the readouts may be ``<joint name>_deg`` columns (see
    :func:`read_campaign`); every other per-sample column: :func:`read_sample_columns`.

    Returns:
        ``(q, temp, t)``: readouts (N, n) rad, temperature (N,) deg C or None, time (N,) s or None.

    Raises:
        CampaignFormatError: listing every problem in these columns, with line and column.
    """
    q, columns = read_sample_columns(path, arm, axis_names=axis_names)
    return q, columns.get("temp_c"), columns.get("t_s")


def read_tool_column(path: str | Path, arm: ArmNames | None = None, *,
                     axis_names: Sequence[str] | None = None,
                     tool_names: Sequence[str] | None = None) -> np.ndarray | None:
    """Read the ``tool`` column of a readouts file (e.g. predict's input), checked against the arm.

    Args:
        path: the readouts file.
        arm: the arm, or any object with ``axis_names`` and ``tool_names`` (:class:`ArmNames`).
        axis_names: the arm's joint names (instead of ``arm``).
        tool_names: the arm's tool names (instead of ``arm``).

    Returns:
        The tool name of each row, shape (N,), str, or None if the file has no ``tool`` column.

    Raises:
        CampaignFormatError: for an unknown tool (line and column), or no column while the arm has
            several tools.
        ValueError: if neither ``arm`` nor ``tool_names`` is given.
    """
    if arm is None and tool_names is None:
        raise ValueError("arm, tool_names: give the arm or its tool names")
    table = _readout_table(path, ("tool", *_OPTIONAL), arm, axis_names, tool_names)
    return np.array(table.cols["tool"], dtype=str) if "tool" in table.cols else None


def read_id_columns(path: str | Path, arm: ArmNames | None = None, *,
                    axis_names: Sequence[str] | None = None) -> dict[str, list[str]]:
    """Return the columns of a readouts file that are neither readouts nor points, as read.

    E.g. a pose id or a ``tool`` column: what a user wants to find again beside the predicted
    points. Readout columns are ``q<n>_deg`` and, told the joint names (by ``arm`` or
    ``axis_names``), ``<joint name>_deg``; ``x_mm``, ``y_mm``, ``z_mm`` are left out (the
    prediction replaces them).
    """
    with Path(path).open(newline="", encoding="utf-8-sig") as f:
        rows = [r for r in csv.reader(f) if r and any(c.strip() for c in r)]
    if not rows:
        return {}
    header = [h.strip() for h in rows[0]]
    axes, _ = given_names(arm, axis_names, None)
    joints = {f"{n}_deg" for n in axes or []}
    skip = set(_XYZ["loc"]) | joints
    return {h: [r[i].strip() if i < len(r) else "" for r in rows[1:]]
            for i, h in enumerate(header) if h and not Q_COLUMN.fullmatch(h) and h not in skip}
