"""The campaign: SPAT and length-bar readouts, read from and written to a folder of CSV files.

The folder holds ``spat.csv`` + ``locations.csv`` (R-Test SPAT), ``lengthbar.csv`` + ``bar.csv``
(length bar) and/or ``points.csv`` (absolute tool points from a laser tracker or motion capture),
comma separated with a header row, in mm and degrees (the columns are in
``_FILES`` below). Readers check every cell and raise one :class:`CampaignFormatError` listing every
problem of every file with its line and column. Inside the package everything is SI (m, rad, s).

**Readout columns.** Either ``q1_deg..qn_deg`` (axis order, see :mod:`aacmm_pin.model.arm`) or, when the
reader is given the arm, one ``<joint name>_deg`` column per axis (``A1_deg``, ``left_j3_deg``), in
any column order; not both. The joint names are the arm's, so without the arm only ``q`` columns are
read. **Tools.** ``points.csv`` may name the tool each point measures in a ``tool`` column (a name of
``Arm.tool_names``, e.g. ``left``): optional for a single-tool arm, needed for several tools; given
the arm, the reader checks it (else :func:`aacmm_pin.fit.measurements.check_points` does).
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeGuard

import numpy as np

from aacmm_pin.errors import CampaignFormatError, Problem
from aacmm_pin.units import (
    BAR_LENGTH_MAX,
    BAR_LENGTH_MIN,
    MAX_COORDINATE,
    RADIAN_MIN_ROWS,
    RTEST_RANGE,
    SIGMA_LOCATION,
    SIGMA_POINT,
    SIGMA_RTEST,
    SIGMA_SOCKET,
    TEMPERATURE_RANGE_C,
    UM,
)

if TYPE_CHECKING:  # the arm is only passed through (the campaign layer does not load arms)
    from aacmm_pin.model.arm import Arm

MAX_ANGLE_DEG = 720.0
"""Largest encoder readout accepted in a file, in degrees (two turns either way)."""
_Q_COLUMN = re.compile(r"q([1-9][0-9]*)_deg")
MAX_FILE_BYTES = 256 * 2**20
"""Largest campaign or readouts CSV read, bytes (about 2 million SPAT rows)."""
MAX_COLUMNS = 256
"""Most columns of a CSV header (and the highest q<n>_deg readout column)."""
_XYZ = {"spat": ("dx_mm", "dy_mm", "dz_mm"), "loc": ("x_mm", "y_mm", "z_mm")}
_OPTIONAL = ("t_s", "temp_c")
# File -> (required columns besides q, has q1_deg..qn_deg, optional columns), in file order.
_FILES: dict[str, tuple[tuple[str, ...], bool, tuple[str, ...]]] = {
    "spat.csv": (("location", *_XYZ["spat"]), True, _OPTIONAL),
    "locations.csv": (("location", *_XYZ["loc"]), False, ()),
    "lengthbar.csv": (("placement", "socket"), True, _OPTIONAL),
    "bar.csv": (("from", "to", "length_mm"), False, ()),
    "points.csv": (_XYZ["loc"], True, ("group", "tool", "sigma_um", *_OPTIONAL)),
}
# Column -> kind of cell; q columns are "angle", any other column "number".
_KINDS = {"location": "id", "placement": "id", "socket": "text", "from": "text", "to": "text",
          "length_mm": "length", "group": "id", "sigma_um": "sigma", "tool": "text",
          "dx_mm": "displacement", "dy_mm": "displacement", "dz_mm": "displacement",
          "x_mm": "coordinate", "y_mm": "coordinate", "z_mm": "coordinate",
          "temp_c": "temperature"}
# Log field -> (dtype, shape after the row axis); None: any length.
_ARRAYS: dict[str, tuple[Any, tuple[int | None, ...]]] = {
    "location": (np.int64, ()), "placement": (np.int64, ()), "socket": (str, ()),
    "q": (float, (None,)), "displacement": (float, (3,)), "t": (float, ()), "temp": (float, ()),
    "lines": (np.int64, ()), "group": (np.int64, ()), "point": (float, (3,)), "sigma": (float, ()),
    "tool": (str, ())}


NOISE_FILE = "campaign.json"
"""Optional file beside the CSVs stating the campaign's noise: ``{"noise_um": {"rtest": 2.0,
"location": 3.0, "point": 20.0, "socket": 2.0}}`` (any subset of the keys; the others keep the paper's
values)."""


@dataclass(frozen=True)
class StatedNoise:
    """The measurement noise a campaign states per kind of measurement.

    Standard uncertainties per coordinate, m; the paper's values by default (:mod:`aacmm_pin.units`).
    """

    rtest: float = SIGMA_RTEST
    """R-Test gauge reading, m."""
    location: float = SIGMA_LOCATION
    """R-Test nest (zero) position, m."""
    point: float = SIGMA_POINT
    """Absolute tool point of an instrument (laser tracker), m (a ``sigma_um`` column overrides)."""
    socket: float = SIGMA_SOCKET
    """Stylus centre seated in a length-bar socket (its seating repeatability), m."""

    def __post_init__(self) -> None:
        for name in ("rtest", "location", "point", "socket"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: a positive noise in m expected, got {value!r}")

    def to_um(self) -> dict[str, float]:
        """Return the ``campaign.json`` form: kind -> noise, um."""
        return {"rtest": self.rtest / UM, "location": self.location / UM, "point": self.point / UM,
                "socket": self.socket / UM}


def read_noise(path: str | Path) -> StatedNoise:
    """Read a ``campaign.json``'s stated noise (see :data:`NOISE_FILE`).

    Raises:
        CampaignFormatError: if the file is not JSON, or ``noise_um`` is not an object of positive
            numbers with the keys rtest, location, point, socket (each one optional).
    """
    path = Path(path)
    try:
        content = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise CampaignFormatError([Problem(path, None, None, f"not readable as JSON: {exc}")]) from exc
    noise = content.get("noise_um", {}) if isinstance(content, dict) else None
    if not isinstance(noise, dict):
        raise CampaignFormatError([Problem(path, None, "noise_um", "an object {\"rtest\": 2.0, "
                                           "\"location\": 3.0, \"point\": 20.0} (um) expected")])
    kinds = tuple(f.name for f in StatedNoise.__dataclass_fields__.values())
    problems = [Problem(path, None, f"noise_um.{key}", f"unknown kind; choose from {', '.join(kinds)}")
                for key in noise if key not in kinds]
    problems += [Problem(path, None, f"noise_um.{key}", f"a positive number (um) expected, got "
                         f"{value!r}") for key, value in noise.items() if key in kinds and not (
                             isinstance(value, (int, float)) and not isinstance(value, bool)
                             and math.isfinite(value) and value > 0)]
    if problems:
        raise CampaignFormatError(problems)
    return StatedNoise(**{key: float(value) * UM for key, value in noise.items()})


class _Log:
    """Base of the logs: each field is stored as a read-only array with one row per readout."""

    def __post_init__(self) -> None:
        n_rows = None
        for name, value in list(vars(self).items()):
            if value is None and name in ("t", "temp", "lines", "sigma", "tool"):
                continue
            dtype, trailing = _ARRAYS[name]
            arr = np.array(value, dtype=dtype)
            n_rows = len(arr) if n_rows is None and arr.ndim else n_rows
            shape = (n_rows, *trailing)
            if arr.ndim != len(shape) or any(s not in (None, a) for s, a in zip(shape, arr.shape)):
                want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
                raise ValueError(f"{type(self).__name__}.{name}: shape {want} expected, got "
                                 f"{arr.shape}")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)


@dataclass(frozen=True, eq=False)
class SpatLog(_Log):
    """Readouts of a SPAT (single point articulation test) with the R-Test, one row per sample."""

    location: np.ndarray
    """R-Test location (nest) of each sample, shape (N,), integers >= 1."""
    q: np.ndarray
    """Encoder readouts, shape (N, n), in rad."""
    displacement: np.ndarray
    """Sphere displacement measured by the R-Test, shape (N, 3), in m (zero without R-Test)."""
    t: np.ndarray | None = None
    """Time of each sample, shape (N,), in s, or None."""
    temp: np.ndarray | None = None
    """Arm temperature at each sample, shape (N,), in deg C, or None."""
    lines: np.ndarray | None = None
    """1-based line of each sample in spat.csv, shape (N,), or None when built in code."""


@dataclass(frozen=True, eq=False)
class LengthBarLog(_Log):
    """Readouts with the stylus in the sockets of a length bar, one row per readout."""

    placement: np.ndarray
    """Bar placement of each readout, shape (M,), integers >= 1."""
    socket: np.ndarray
    """Socket label of each readout (e.g. "A"), shape (M,), str."""
    q: np.ndarray
    """Encoder readouts, shape (M, n), in rad."""
    t: np.ndarray | None = None
    """Time of each readout, shape (M,), in s, or None."""
    temp: np.ndarray | None = None
    """Arm temperature at each readout, shape (M,), in deg C, or None."""
    lines: np.ndarray | None = None
    """1-based line of each readout in lengthbar.csv, shape (M,), or None when built in code."""


@dataclass(frozen=True, eq=False)
class PointLog(_Log):
    """Absolute positions of the tool point measured by an instrument, one row per pose.

    The instrument (a laser tracker station, a motion-capture system) has its own frame; its
    transform to the arm's base is unknown and identified, one per ``group``.
    """

    group: np.ndarray
    """Instrument set-up (frame) of each point, shape (N,), integers >= 1."""
    q: np.ndarray
    """Joint readouts, shape (N, n), in rad."""
    point: np.ndarray
    """Measured tool point in the instrument frame, shape (N, 3), in m."""
    sigma: np.ndarray | None = None
    """Stated standard uncertainty of each point per coordinate, shape (N,), in m, or None."""
    t: np.ndarray | None = None
    """Time of each pose, shape (N,), in s, or None."""
    temp: np.ndarray | None = None
    """Arm temperature at each pose, shape (N,), in deg C, or None."""
    lines: np.ndarray | None = None
    """1-based line of each pose in points.csv, shape (N,), or None when built in code."""
    tool: np.ndarray | None = None
    """Name of the tool each point measures (``Arm.tool_names``), shape (N,), str, or None (the
    arm's only tool)."""


@dataclass(frozen=True, eq=False)
class Campaign:
    """A measurement campaign: SPAT and/or length-bar readouts with their references.

    Values hold read-only arrays; ``==`` is identity (compare the arrays with numpy).
    """

    spat: SpatLog | None
    """SPAT samples, or None."""
    locations: dict[int, np.ndarray]
    """Zero position of each R-Test location, location -> shape (3,), in m."""
    lengthbar: LengthBarLog | None
    """Length-bar readouts, or None."""
    bar: dict[tuple[str, str], float]
    """Calibrated socket distances, (from, to) -> length in m."""
    source: Path | None = None
    """Folder the campaign was read from, or None."""
    points: PointLog | None = None
    """Absolute tool points (laser tracker, motion capture), or None."""
    noise: StatedNoise | None = None
    """The measurement noise the campaign states (``campaign.json``), or None: the paper's."""

    def __post_init__(self) -> None:
        axes = {log.q.shape[1] for log in self.logs}
        if len(axes) != 1:
            raise ValueError(f"spat, lengthbar, points: give one or more, with one number of axes; "
                             f"got {'none' if not axes else sorted(axes)}")
        locations = {int(k): np.array(v, dtype=float) for k, v in self.locations.items()}
        if bad := [k for k, v in locations.items() if v.shape != (3,)]:
            raise ValueError(f"locations: shape (3,) expected for locations {bad}")
        if sorted(locations) != list(self.location_ids):
            raise ValueError(f"locations: one zero position per SPAT location expected, for "
                             f"{list(self.location_ids)}; got {sorted(locations)}")
        if bool(self.bar) != (self.lengthbar is not None):
            raise ValueError("bar: socket distances come with length-bar readouts, and only then")
        for v in locations.values():
            v.setflags(write=False)
        object.__setattr__(self, "locations", locations)
        object.__setattr__(self, "bar", {(str(a), str(b)): float(v)
                                         for (a, b), v in self.bar.items()})
        object.__setattr__(self, "source", None if self.source is None else Path(self.source))

    @property
    def logs(self) -> list[SpatLog | LengthBarLog | PointLog]:
        """The readout logs present (SPAT, length bar, points), in that order."""
        return [log for log in (self.spat, self.lengthbar, self.points) if log is not None]

    @property
    def n_axes(self) -> int:
        """Number of arm axes n (columns of the readouts)."""
        return int(self.logs[0].q.shape[1])

    @property
    def location_ids(self) -> tuple[int, ...]:
        """Sorted ids of the R-Test locations present in the SPAT (empty without SPAT)."""
        return () if self.spat is None else tuple(int(v) for v in np.unique(self.spat.location))

    def select(self, locations: Iterable[int]) -> Campaign:
        """Return the campaign with only the SPAT samples and zero positions of ``locations``.

        Used for leave-one-out: pass all location ids but one.

        Raises:
            ValueError: if ``locations`` is empty or names a location absent from the SPAT.
        """
        wanted = sorted({int(v) for v in locations})
        unknown = sorted(set(wanted) - set(self.location_ids))
        if self.spat is None or not wanted or unknown:
            raise ValueError(f"locations: choose one or more of {list(self.location_ids)}, "
                             f"got {unknown or 'none'}")
        keep = np.isin(self.spat.location, wanted)
        rows = {k: v[keep] for k, v in vars(self.spat).items() if v is not None}
        return replace(self, spat=replace(self.spat, **rows),
                       locations={k: self.locations[k] for k in wanted})

    def with_spat(self, *, q: np.ndarray | None = None, displacement: np.ndarray | None = None,
                  t: np.ndarray | None = None, temp: np.ndarray | None = None) -> Campaign:
        """Return the campaign with these SPAT fields replaced (shapes and units as in SpatLog).

        Raises:
            ValueError: if the campaign has no SPAT or a shape does not fit.
        """
        if self.spat is None:
            raise ValueError("with_spat: the campaign has no SPAT")
        changes = {"q": q, "displacement": displacement, "t": t, "temp": temp}
        spat = replace(self.spat, **{k: v for k, v in changes.items() if v is not None})
        return replace(self, spat=spat)


@dataclass
class _Table:
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

    @property
    def n_axes(self) -> int:
        """Number of readout columns (0: missing or with gaps)."""
        return len(self.q_columns)


def _parse(text: str, kind: str) -> tuple[Any, str | None]:
    """Return (value, None) for a good cell, or (None, reason)."""
    if not text or kind == "text":
        return (text, None) if text else (None, "empty cell")
    try:
        value = int(text) if kind == "id" else float(text)
    except ValueError:
        return None, f"'{text}' is not {'an integer' if kind == 'id' else 'a number'}"
    why = _bad_value(value, kind)
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
    if kind == "temperature" and not TEMPERATURE_RANGE_C[0] <= value <= TEMPERATURE_RANGE_C[1]:
        return f"deg C is outside {TEMPERATURE_RANGE_C[0]:g} to {TEMPERATURE_RANGE_C[1]:g} deg C"
    if kind == "sigma" and value <= 0:
        return "um is not a positive standard uncertainty"
    if kind == "sigma" and value > MAX_COORDINATE * 1e6:
        return "um is not a plausible standard uncertainty"
    return None


def _read_table(path: Path, required: tuple[str, ...], has_q: bool, optional: tuple[str, ...],
                problems: list[Problem], *, others_allowed: bool = False,
                axis_names: list[str] | None = None) -> _Table | None:
    """Read and check one CSV file, adding its problems; return None if it has no usable header.

    ``axis_names`` (the arm's, when known) allows ``<joint name>_deg`` readout columns.
    """

    def add(line: int | None, column: str | None, reason: str) -> None:
        problems.append(Problem(path, line, column, reason))

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
    top, header = rows[0]
    if len(header) > MAX_COLUMNS:
        add(top, None, f"{len(header)} columns in the header; at most {MAX_COLUMNS} are read")
        return None
    named = [f"{n}_deg" for n in axis_names or []] if has_q else []
    expected = ", ".join([*required, *(["q1_deg..qn_deg"] if has_q else []), *optional])
    if named:
        expected += f" (or {', '.join(named)} instead of q1_deg..q{len(named)}_deg)"
    index: dict[str, int] = {}
    for k, name in enumerate(header):
        known = (name in required or name in optional or name in named
                 or bool(has_q and _Q_COLUMN.fullmatch(name)))
        if not name:
            add(top, str(k + 1), "empty column name")
        elif name in index:
            add(top, name, f"duplicated column (columns {index[name] + 1} and {k + 1})")
        elif has_q and (m := _Q_COLUMN.fullmatch(name)) and int(m[1]) > MAX_COLUMNS:
            add(top, name, f"readout column beyond q{MAX_COLUMNS}_deg")
        elif known:
            index[name] = k
        elif not others_allowed:
            hint = ("; <joint name>_deg columns are read only with the arm (arm=..., --arm)"
                    if has_q and not named and name.endswith("_deg") else "")
            add(top, name, f"unknown column; expected: {expected}{hint}")
    q_found = [int(m[1]) for name in index if (m := _Q_COLUMN.fullmatch(name))] if has_q else []
    by_name = [name for name in named if name in index]
    q_missing = False
    if by_name and q_found:
        q_missing = True
        first_q = next(name for name in index if _Q_COLUMN.fullmatch(name))
        add(top, first_q, f"mixes q<n>_deg and joint-name readout columns ({by_name[0]}): "
                          "use q1_deg..qn_deg or one <joint name>_deg column per axis")
    q_columns = by_name and named or _q_names(max(q_found, default=0))
    wanted = [*required, *(q_columns or ["q1_deg"] if has_q and not q_missing else [])]
    for name in (missing := [name for name in wanted if name not in index]):
        if name in named:
            add(top, name, "missing column: joint-name readout columns need one per axis "
                           f"({', '.join(named)})")
        else:
            gap = "; q columns run from q1_deg to qn_deg without gaps" if name[0] == "q" else ""
            add(top, name, f"missing column{gap}")
    if len(rows) == 1:
        add(None, None, "header only: no data rows")
    if q_missing or any(name in q_columns or name == "q1_deg" for name in missing):
        q_columns = []  # unknown
    table = _Table(path, q_columns, [], {name: [] for name in index})
    kinds = {name: ("angle" if name in q_columns or _Q_COLUMN.fullmatch(name) or name in named
                    else _KINDS.get(name, "number")) for name in index}
    for line, cells in rows[1:]:
        if not any(cells):
            add(line, None, "blank line among the data rows")
        elif len(cells) != len(header):
            add(line, None, f"{len(cells)} cells, but the header has {len(header)} columns")
        else:
            table.lines.append(line)
            for name, k in index.items():
                value, reason = _parse(cells[k], kinds[name])
                table.cols[name].append(value)
                if reason:
                    add(line, name, reason)
    return table


def _q_names(n: int) -> list[str]:
    """Return the names of the encoder columns, q1_deg..qn_deg."""
    return [f"q{i}_deg" for i in range(1, n + 1)]


def _matrix(table: _Table, names: Iterable[str], scale: float) -> np.ndarray:
    """Return the named columns as a float array, shape (rows, len(names)), times ``scale``."""
    out: np.ndarray = np.array([table.cols[name] for name in names], dtype=float).T * scale
    return out


def _log_fields(table: _Table) -> dict[str, Any]:
    """Return the q (rad), t (s), temp (deg C) and lines fields of a log read from a table."""
    extra = {field: np.array(table.cols[name], dtype=float) if name in table.cols else None
             for field, name in (("t", "t_s"), ("temp", "temp_c"))}
    return {"q": _matrix(table, table.q_columns, math.pi / 180.0), **extra,
            "lines": np.array(table.lines, dtype=np.int64)}


def _check_radians(table: _Table, out: list[Problem]) -> None:
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


def _usable(table: _Table | None, *columns: str) -> TypeGuard[_Table]:
    """Tell whether a table has data rows and these columns (else its problems are reported)."""
    return table is not None and bool(table.lines) and set(columns) <= table.cols.keys()


def _check_locations(spat: _Table, locs: _Table, min_samples: int, out: list[Problem]) -> None:
    """Check duplicated ids, locations without zero position and locations with too few samples."""
    zero_line: dict[int, int] = {}
    for line, v in zip(locs.lines, locs.cols["location"]):
        if v is not None and v in zero_line:
            out.append(Problem(locs.path, line, "location",
                               f"location {v} is duplicated (also on line {zero_line[v]})"))
        zero_line.setdefault(v, line)
    first_line = {v: line for line, v in reversed(list(zip(spat.lines, spat.cols["location"])))}
    counts, least = Counter(spat.cols["location"]), max(min_samples, 1)
    for v in sorted((set(first_line) | set(zero_line)) - {None}):
        path, line = (spat.path, first_line[v]) if v in first_line else (locs.path, zero_line[v])
        if v not in zero_line:
            out.append(Problem(path, line, "location",
                               f"location {v} has no zero position in locations.csv"))
        elif counts[v] < least:
            out.append(Problem(path, line, "location", f"location {v} has {counts[v]} samples "
                                                       f"in spat.csv, fewer than {least}"))


def _check_bar(log: _Table, bar: _Table, out: list[Problem]) -> None:
    """Check that every measured socket is in bar.csv and every bar.csv pair is measured once."""
    first_line = {s: line for line, s in reversed(list(zip(log.lines, log.cols["socket"])))}
    together: dict[int, set[str]] = {}
    for placement, s in zip(log.cols["placement"], log.cols["socket"]):
        together.setdefault(placement, set()).add(s)
    pair_line: dict[frozenset[str], int] = {}

    def say(line: int, column: str | None, reason: str) -> None:
        out.append(Problem(bar.path, line, column, reason))

    for line, a, b in zip(bar.lines, bar.cols["from"], bar.cols["to"]):
        if a is None or b is None:
            continue  # an empty cell, reported already
        pair = frozenset((a, b))
        if a == b or pair in pair_line:
            say(line, "to", f"a bar from socket '{a}' to itself" if a == b
                else f"pair {a},{b} is also on line {pair_line[pair]}")
        pair_line.setdefault(pair, line)
        for column, s in (("from", a), ("to", b)):
            if s not in first_line:
                say(line, column, f"socket '{s}' is never measured in lengthbar.csv")
        if {a, b} <= first_line.keys() and not any(pair <= both for both in together.values()):
            say(line, None, f"sockets '{a}' and '{b}' are never measured in one placement")
    named = {s for pair in pair_line for s in pair}
    for s, line in first_line.items():
        if s is not None and s not in named:
            out.append(Problem(log.path, line, "socket", f"socket '{s}' is not named in bar.csv"))


def _check_tools(points: _Table, arm: Arm, out: list[Problem]) -> None:
    """Check the ``tool`` column of points.csv against the arm's tools."""
    names = set(arm.tool_names) | set(arm.tool_joints)
    listing = ", ".join(arm.tool_names)
    if "tool" not in points.cols:
        if arm.n_tools > 1:
            out.append(Problem(points.path, 1, "tool", f"missing column: the arm has "
                                                       f"{arm.n_tools} tools ({listing}); say "
                                                       "which one each point measures"))
        return
    for line, name in zip(points.lines, points.cols["tool"]):
        if name is not None and name not in names:
            out.append(Problem(points.path, line, "tool",
                               f"unknown tool '{name}'; the arm's tools: {listing}"))


def read_campaign(folder: str | Path, *, min_samples_per_location: int = 3,
                  arm: Arm | None = None) -> Campaign:
    """Read and validate a campaign folder.

    Args:
        folder: folder holding spat.csv + locations.csv, lengthbar.csv + bar.csv and/or
            points.csv.
        min_samples_per_location: fewest SPAT samples accepted at one R-Test location.
        arm: the arm, when known: allows ``<joint name>_deg`` readout columns (put in axis order)
            and checks the ``tool`` column of points.csv against its tools.

    Returns:
        The campaign in SI units (m, rad, s), with ``source`` set to the folder.

    Raises:
        CampaignFormatError: listing every problem of all files, each with file, line and column.
    """
    folder = Path(folder)
    paths = {name: folder / name for name in _FILES}
    present = {name for name, path in paths.items() if path.is_file()}
    if not present & {"spat.csv", "lengthbar.csv", "points.csv"}:
        why = ("does not exist" if not folder.exists() else "is not a folder"
               if not folder.is_dir() else "holds neither spat.csv, lengthbar.csv nor points.csv")
        raise CampaignFormatError([Problem(folder, None, None, f"the campaign folder {why}")])
    problems: list[Problem] = []
    for pair in (["spat.csv", "locations.csv"], ["lengthbar.csv", "bar.csv"]):
        if len(found := [name for name in pair if name in present]) == 1:
            problems.append(Problem(paths[(set(pair) - set(found)).pop()], None, None,
                                    f"file not found; {found[0]} needs it (they come in a pair)"))
    axis_names = None if arm is None else arm.axis_names
    tables = {name: _read_table(paths[name], *_FILES[name], problems, axis_names=axis_names)
              for name in _FILES if name in present}
    spat, locs = tables.get("spat.csv"), tables.get("locations.csv")
    log, bar = tables.get("lengthbar.csv"), tables.get("bar.csv")
    points = tables.get("points.csv")
    if _usable(spat, "location") and _usable(locs, "location"):
        _check_locations(spat, locs, min_samples_per_location, problems)
    if _usable(log, "placement", "socket") and _usable(bar, "from", "to"):
        _check_bar(log, bar, problems)
    if points is not None and arm is not None and points.lines:
        _check_tools(points, arm, problems)
    for table in (spat, log, points):
        if table is not None:
            _check_radians(table, problems)
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
    return Campaign(
        spat=None if not (spat and locs) else SpatLog(
            location=np.array(spat.cols["location"], dtype=np.int64),
            displacement=_matrix(spat, _XYZ["spat"], 1e-3), **_log_fields(spat)),
        locations={} if not locs else dict(zip(locs.cols["location"],
                                                _matrix(locs, _XYZ["loc"], 1e-3))),
        lengthbar=None if not (log and bar) else LengthBarLog(
            placement=np.array(log.cols["placement"], dtype=np.int64),
            socket=np.array(log.cols["socket"], dtype=str), **_log_fields(log)),
        bar={} if not bar else {(a, b): v * 1e-3 for a, b, v in zip(
            bar.cols["from"], bar.cols["to"], bar.cols["length_mm"])},
        source=folder,
        points=None if not points else PointLog(
            group=np.array(points.cols.get("group", [1] * len(points.lines)), dtype=np.int64),
            point=_matrix(points, _XYZ["loc"], 1e-3),
            sigma=(np.array(points.cols["sigma_um"], dtype=float) * 1e-6
                   if "sigma_um" in points.cols else None),
            tool=np.array(points.cols["tool"], dtype=str) if "tool" in points.cols else None,
            **_log_fields(points)),
        noise=read_noise(folder / NOISE_FILE) if (folder / NOISE_FILE).is_file() else None)


def read_readouts(path: str | Path, arm: Arm | None = None) -> np.ndarray:
    """Read encoder readouts from a CSV file with columns q1_deg..qn_deg, e.g. a lengthbar.csv.

    Other columns are ignored; the q columns and cells are checked as in :func:`read_campaign`
    (given the arm, ``<joint name>_deg`` columns are read too).

    Returns:
        Encoder readouts, shape (N, n), in rad.

    Raises:
        CampaignFormatError: listing every problem in the q columns, with line and column.
    """
    return read_readout_columns(path, arm)[0]


def read_readout_columns(path: str | Path, arm: Arm | None = None
                         ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Read encoder readouts and, when present, the ``temp_c`` and ``t_s`` columns.

    Given the arm, the readouts may be ``<joint name>_deg`` columns (see :func:`read_campaign`).

    Returns:
        ``(q, temp, t)``: readouts (N, n) rad, temperature (N,) deg C or None, time (N,) s or None.

    Raises:
        CampaignFormatError: listing every problem in these columns, with line and column.
    """
    problems: list[Problem] = []
    table = _read_table(Path(path), (), True, _OPTIONAL, problems, others_allowed=True,
                        axis_names=None if arm is None else arm.axis_names)
    if problems or table is None:
        raise CampaignFormatError(problems)
    fields = _log_fields(table)
    return fields["q"], fields["temp"], fields["t"]


def read_tool_column(path: str | Path, arm: Arm) -> np.ndarray | None:
    """Read the ``tool`` column of a readouts file (e.g. predict's input), checked against the arm.

    Returns:
        The tool name of each row, shape (N,), str, or None if the file has no ``tool`` column.

    Raises:
        CampaignFormatError: for an unknown tool (line and column), or no column while the arm has
            several tools.
    """
    problems: list[Problem] = []
    table = _read_table(Path(path), (), True, ("tool", *_OPTIONAL), problems, others_allowed=True,
                        axis_names=arm.axis_names)
    if table is not None and table.lines:
        _check_tools(table, arm, problems)
    if problems or table is None:
        raise CampaignFormatError(problems)
    return np.array(table.cols["tool"], dtype=str) if "tool" in table.cols else None


def _write_csv(path: Path, columns: Mapping[str, Iterable[Any]]) -> None:
    """Write named columns of cells (floats with 9 decimals) under a header row."""
    cells = [[f"{v:.9f}" if isinstance(v, float) else str(v) for v in c] for c in columns.values()]
    with path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(columns)
        writer.writerows(zip(*cells))


def _file_columns(log: SpatLog | LengthBarLog | PointLog,
                  before: Mapping[str, list[int] | list[float] | list[str]],
                  after: Mapping[str, list[int] | list[float] | list[str]]) -> dict[str, Any]:
    """Return a log's file columns: ``before``, q1_deg..qn_deg, ``after``, t_s and temp_c."""
    q_deg = dict(zip(_q_names(log.q.shape[1]), np.degrees(log.q).T.tolist()))
    extra = (("t_s", log.t), ("temp_c", log.temp))
    return {**before, **q_deg, **after, **{k: v.tolist() for k, v in extra if v is not None}}


def _mm(names: tuple[str, ...], xyz: Any) -> dict[str, list[float]]:
    """Return points, shape (N, 3) in m, as named columns in mm."""
    return dict(zip(names, (np.asarray(xyz, dtype=float).reshape(-1, 3) * 1e3).T.tolist()))


def write_campaign(campaign: Campaign, folder: str | Path) -> None:
    """Write ``campaign`` into ``folder`` (created if needed): the files of the parts present.

    Lengths are written in mm and angles in degrees, with 9 decimals; t_s and temp_c when present;
    the stated noise, when set, in ``campaign.json``.

    Raises:
        FileExistsError: if the folder holds a campaign file for a part that ``campaign`` lacks
            (it would be read back with the new files; remove it or choose another folder).
    """
    folder = Path(folder)
    parts = {"spat.csv": campaign.spat, "locations.csv": campaign.spat,
             "lengthbar.csv": campaign.lengthbar, "bar.csv": campaign.lengthbar,
             "points.csv": campaign.points}
    if stale := [name for name, part in parts.items() if part is None and (folder / name).exists()]:
        raise FileExistsError(f"{folder} already holds {', '.join(stale)}, which this campaign "
                              "has no data for; remove it or write to another folder")
    folder.mkdir(parents=True, exist_ok=True)
    if (spat := campaign.spat) is not None:
        _write_csv(folder / "spat.csv", _file_columns(spat, {"location": spat.location.tolist()},
                                                      _mm(_XYZ["spat"], spat.displacement)))
        ids = sorted(campaign.locations)
        _write_csv(folder / "locations.csv", {"location": ids, **_mm(
            _XYZ["loc"], [campaign.locations[k] for k in ids])})
    if (log := campaign.lengthbar) is not None:
        before = {"placement": log.placement.tolist(), "socket": log.socket.tolist()}
        _write_csv(folder / "lengthbar.csv", _file_columns(log, before, {}))
        _write_csv(folder / "bar.csv", {"from": [a for a, _ in campaign.bar],
                                        "to": [b for _, b in campaign.bar],
                                        "length_mm": [v * 1e3 for v in campaign.bar.values()]})
    if (pts := campaign.points) is not None:
        after = _mm(_XYZ["loc"], pts.point)
        if pts.sigma is not None:
            after["sigma_um"] = (pts.sigma * 1e6).tolist()
        first: dict[str, Any] = {"group": pts.group.tolist()}
        if pts.tool is not None:
            first["tool"] = pts.tool.tolist()
        _write_csv(folder / "points.csv", _file_columns(pts, first, after))
    if campaign.noise is not None:
        (folder / NOISE_FILE).write_text(json.dumps({"noise_um": campaign.noise.to_um()},
                                                    indent=2) + "\n")


def write_points(path: str | Path, points: np.ndarray,
                 keep: Mapping[str, list[str]] | None = None) -> None:
    """Write points, shape (N, 3) in m, to a CSV file with columns x_mm,y_mm,z_mm (9 decimals).

    ``keep``: further columns (name -> N cells, as read) written first, e.g. the id columns of
    the readouts the points were predicted from (:func:`read_id_columns`).

    Raises:
        ValueError: if ``points`` does not have shape (N, 3) or a kept column another length.
    """
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points: shape (N, 3) expected, got {points.shape}")
    keep = dict(keep or {})
    if bad := [k for k, v in keep.items() if len(v) != len(points)]:
        raise ValueError(f"keep: columns {bad} do not have {len(points)} cells")
    _write_csv(Path(path), {**keep, **_mm(_XYZ["loc"], points)})


def read_id_columns(path: str | Path, arm: Arm | None = None) -> dict[str, list[str]]:
    """Return the columns of a readouts file that are neither readouts nor points, as read.

    E.g. a pose id or a ``tool`` column: what a user wants to find again beside the predicted
    points. Readout columns are ``q<n>_deg`` and, given the arm, ``<joint name>_deg``; ``x_mm``,
    ``y_mm``, ``z_mm`` are left out (the prediction replaces them).
    """
    with Path(path).open(newline="", encoding="utf-8-sig") as f:
        rows = [r for r in csv.reader(f) if r and any(c.strip() for c in r)]
    if not rows:
        return {}
    header = [h.strip() for h in rows[0]]
    joints = {f"{n}_deg" for n in (arm.axis_names if arm is not None else [])}
    skip = set(_XYZ["loc"]) | joints
    return {h: [r[i].strip() if i < len(r) else "" for r in rows[1:]]
            for i, h in enumerate(header) if h and not _Q_COLUMN.fullmatch(h) and h not in skip}
