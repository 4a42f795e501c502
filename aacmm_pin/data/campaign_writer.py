"""Writing a campaign folder: whole (:func:`write_campaign`), or a SPAT run's rows as they come.

:func:`write_campaign` writes every file of a :class:`~aacmm_pin.data.logs.Campaign`;
:class:`SpatWriter` appends the rows of one R-Test location to ``spat.csv`` while they are
acquired, and :func:`write_zero` adds a location's zero position to ``locations.csv``: the one
module that writes the campaign files, with one cell format (lengths in mm and angles in degrees
with 9 decimals).

**Appending.** ``spat.csv`` is opened for appending: a run adds the rows of one location to the
rows of earlier runs (other locations, or more of the same). Every row is one ``write`` of a whole
line, flushed to the operating system at once, so a killed process or a pulled cable loses at most
the line in flight; the file is also ``fsync``-ed every ``fsync_interval`` seconds against power
loss. A line left incomplete by an interrupted run is removed (and reported) when the file is
opened again. The header is written with the first row, and ``locations.csv`` gets the nest's zero
position with the first row too, so a run that records nothing leaves the campaign as it was.
``locations.csv`` is rewritten whole through a temporary file beside it
(``.locations.csv.<pid>.*.tmp``) and one rename.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tempfile
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from aacmm_pin.data.arm_names import ArmNames, couplings_of
from aacmm_pin.data.columns import BUILT_IN, column, file_order
from aacmm_pin.data.csv_table import DISPLACEMENT, POINT, q_names
from aacmm_pin.data.logs import NOISE_FILE, Campaign, LengthBarLog, PointLog, SpatLog
from aacmm_pin.data.output_claim import remove_leftovers, temp_prefix, umask
from aacmm_pin.data.spreadsheet import neutralise_formulas
from aacmm_pin.errors import AcquisitionError


def _write_csv(path: Path, columns: Mapping[str, Iterable[Any]]) -> None:
    """Write named columns of cells (floats with 9 decimals) under a header row."""
    cells = [[f"{v:.9f}" if isinstance(v, float) else str(v) for v in c] for c in columns.values()]
    with path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(columns)
        writer.writerows(zip(*cells))


def _file_columns(log: SpatLog | LengthBarLog | PointLog,
                  before: Mapping[str, list[int] | list[float] | list[str]],
                  after: Mapping[str, list[int] | list[float] | list[str]],
                  arm: ArmNames | None = None) -> dict[str, Any]:
    """Return a log's file columns: ``before``, q1_deg..qn_deg, ``after``, per-sample columns.

    The per-sample columns in their file units: ``sigma_um``, ``t_s``, ``temp_c``, then the others
    in the log's order. With the arm: ``<joint name>_deg`` readout columns, a coupled joint's
    left out (the readers fill it from its coupling).
    """
    names = q_names(log.q.shape[1]) if arm is None else [f"{n}_deg" for n in arm.axis_names]
    coupled = {c.axis for c in couplings_of(arm)}
    q_deg = {name: values for k, (name, values) in enumerate(zip(names, np.degrees(log.q).T.tolist()))
             if k not in coupled}
    extra = {name: _cells(name, column(name).from_si(log.columns[name]).tolist())
             for name in file_order(list(log.columns))}
    return {**before, **q_deg, **after, **extra}


BUILT_IN_NAMES = frozenset(c.name for c in BUILT_IN)
"""The per-sample columns the package itself reads (written with 9 decimals, as ever)."""


def _cells(name: str, values: list[float]) -> list[float] | list[str]:
    """Return a per-sample column's cells: the package's own with 9 decimals, others exactly.

    Any other column's values are written with 12 significant digits, whatever their size: a
    1e-10 strain is not written as 0.
    """
    return values if name in BUILT_IN_NAMES else [format(v, ".12g") for v in values]


def _mm(names: tuple[str, ...], xyz: Any) -> dict[str, list[float]]:
    """Return points, shape (N, 3) in m, as named columns in mm."""
    return dict(zip(names, (np.asarray(xyz, dtype=float).reshape(-1, 3) * 1e3).T.tolist()))


def write_campaign(campaign: Campaign, folder: str | Path, arm: ArmNames | None = None) -> None:
    """Write ``campaign`` into ``folder`` (created if needed): the files of the parts present.

    Lengths are written in mm and angles in degrees, with 9 decimals; every per-sample column of a
    log (t_s, temp_c, sigma_um, any other) in its file unit; the stated noise, when set, in
    ``campaign.json``. Readout columns are ``q1_deg..qn_deg``, or, with ``arm``, ``<joint
    name>_deg`` without the coupled joints' (read back with the arm).

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
                                                      _mm(DISPLACEMENT, spat.displacement), arm))
        ids = sorted(campaign.locations)
        _write_csv(folder / "locations.csv", {"location": ids, **_mm(
            POINT, [campaign.locations[k] for k in ids])})
    if (log := campaign.lengthbar) is not None:
        before = {"placement": log.placement.tolist(), "socket": log.socket.tolist()}
        _write_csv(folder / "lengthbar.csv", _file_columns(log, before, {}, arm))
        _write_csv(folder / "bar.csv", {"from": [a for a, _ in campaign.bar],
                                        "to": [b for _, b in campaign.bar],
                                        "length_mm": [v * 1e3 for v in campaign.bar.values()]})
    if (pts := campaign.points) is not None:
        first: dict[str, Any] = {"group": pts.group.tolist()}
        if pts.tool is not None:
            first["tool"] = pts.tool.tolist()
        _write_csv(folder / "points.csv", _file_columns(pts, first, _mm(POINT, pts.point), arm))
    if campaign.noise is not None:
        instrument = {"instrument": campaign.noise.instrument} if campaign.noise.instrument else {}
        (folder / NOISE_FILE).write_text(json.dumps({**instrument, "noise_um":
                                                     campaign.noise.to_um()}, indent=2) + "\n")


def write_points(path: str | Path, points: np.ndarray,
                 keep: Mapping[str, list[str]] | None = None) -> None:
    """Write points, shape (N, 3) in m, to a CSV file with columns x_mm,y_mm,z_mm (9 decimals).

    ``keep``: further columns (name -> N cells, as read) written first, e.g. the id columns of
    the readouts the points were predicted from (:func:`read_id_columns`); a cell a spreadsheet
    would run as a formula (``=...``, ``@...``) gets a ``'`` in front
    (:func:`~aacmm_pin.data.spreadsheet.neutralise_formula`; numbers are left as they are).

    Raises:
        ValueError: if ``points`` does not have shape (N, 3) or a kept column another length.
    """
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points: shape (N, 3) expected, got {points.shape}")
    keep = dict(keep or {})
    if bad := [k for k, v in keep.items() if len(v) != len(points)]:
        raise ValueError(f"keep: columns {bad} do not have {len(points)} cells")
    keep = {name: neutralise_formulas(cells) for name, cells in keep.items()}
    _write_csv(Path(path), {**keep, **_mm(POINT, points)})


LOCATION_COLUMNS = ("location", "x_mm", "y_mm", "z_mm")
"""Header of locations.csv."""


def spat_columns(n_axes: int) -> list[str]:
    """Return the columns acquire writes: location, q1_deg..qn_deg, dx_mm, dy_mm, dz_mm, t_s."""
    return ["location", *(f"q{i}_deg" for i in range(1, n_axes + 1)), "dx_mm", "dy_mm", "dz_mm",
            "t_s"]


def _read_header(path: Path) -> tuple[list[str] | None, int, int]:
    """Return (header or None, byte offset after the last complete line, number of data lines)."""
    data = path.read_bytes()
    end = data.rfind(b"\n") + 1
    lines = data[:end].decode("utf-8-sig", errors="replace").splitlines()
    if not lines:
        return None, end, 0
    header = [c.strip() for c in next(csv.reader(io.StringIO(lines[0])))]
    return header, end, sum(1 for line in lines[1:] if line.strip())


class SpatWriter:
    """Append SPAT rows of one location to ``folder/spat.csv``, one flushed line per row.

    Args:
        folder: campaign folder (created if needed).
        location: R-Test location of the rows, >= 1.
        n_axes: number of readouts per row.
        zero: zero position of the nest in the MT-CS, shape (3,), m, written to locations.csv
            with the first row; None leaves locations.csv alone.
        fsync_interval: seconds between fsyncs of the file.

    Raises:
        AcquisitionError: if spat.csv has other columns, or locations.csv another zero position
            for ``location`` (both checked before anything is written).
    """

    def __init__(self, folder: str | Path, location: int, n_axes: int = 7,
                 zero: np.ndarray | None = None, fsync_interval: float = 1.0):
        if location < 1:
            raise ValueError(f"location: an integer >= 1 expected, got {location}")
        self.folder = Path(folder)
        self.path = self.folder / "spat.csv"
        self.location = int(location)
        self.zero = None if zero is None else np.asarray(zero, dtype=float).reshape(3)
        self.fsync_interval = fsync_interval
        self.rows_written = 0
        """Rows written by this writer."""
        self.rows_before = 0
        """Data rows the file held before (all locations)."""
        self.location_rows_before = 0
        """Data rows of ``location`` the file held before."""
        self.repaired_bytes = 0
        """Bytes of an incomplete last line removed when the file was opened."""
        self._columns = spat_columns(n_axes)
        self._order: list[int] | None = None
        self._file: BinaryIO | None = None
        self._last_sync = time.monotonic()
        self._check()
        self.locations_message = _check_zero(self.folder, self.location, self.zero)

    def _check(self) -> None:
        """Check an existing spat.csv: same columns; count its rows; note an incomplete line."""
        if not self.path.exists():
            return
        header, end, n_rows = _read_header(self.path)
        if header is None:
            return
        if sorted(header) != sorted(self._columns):
            raise AcquisitionError(
                f"{self.path} has the columns {','.join(header)}; acquire writes "
                f"{','.join(self._columns)}: record into another campaign folder")
        self._order = [self._columns.index(name) for name in header]
        self.rows_before = n_rows
        self.repaired_bytes = self.path.stat().st_size - end
        with self.path.open(encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            k = header.index("location")
            self.location_rows_before = sum(1 for row in reader if len(row) > k
                                            and row[k].strip() == str(self.location))

    def _open(self) -> BinaryIO:
        """Open the file for appending (header first if new), repairing an incomplete last line."""
        self.folder.mkdir(parents=True, exist_ok=True)
        f = self.path.open("r+b" if self.path.exists() else "w+b")
        size = f.seek(0, os.SEEK_END)
        if size:
            f.seek(0)
            end = f.read().rfind(b"\n") + 1
            if end < size:
                f.truncate(end)
            f.seek(end)
        if f.tell() == 0:
            f.write((",".join(self._columns) + "\n").encode())
            self._order = None
        if self.zero is not None:
            write_zero(self.folder, self.location, self.zero)
        return f

    def write(self, t: float, q: list[float] | np.ndarray, displacement: np.ndarray) -> None:
        """Write one row and flush it.

        Args:
            t: time of the sample, s (written as t_s, e.g. Unix time).
            q: readouts, n values, rad.
            displacement: sphere displacement in the MT-CS, shape (3,), m.
        """
        if self._file is None:
            self._file = self._open()
        cells = [str(self.location), *(f"{math.degrees(v):.9f}" for v in q),
                 *(f"{v * 1e3:.9f}" for v in displacement), f"{t:.6f}"]
        if self._order is not None:
            cells = [cells[k] for k in self._order]
        self._file.write((",".join(cells) + "\n").encode())
        self._file.flush()
        self.rows_written += 1
        now = time.monotonic()
        if now - self._last_sync >= self.fsync_interval:
            os.fsync(self._file.fileno())
            self._last_sync = now

    def close(self) -> None:
        """Flush, fsync and close the file (if a row was written)."""
        if self._file is not None:
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            self._file = None

    def __enter__(self) -> SpatWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _read_locations(folder: Path) -> dict[int, np.ndarray]:
    """Return the zero positions of locations.csv (location -> (3,) in m); {} if absent.

    Raises:
        AcquisitionError: if the file is there but unreadable as location,x_mm,y_mm,z_mm.
    """
    path = folder / "locations.csv"
    if not path.exists():
        return {}
    out: dict[int, np.ndarray] = {}
    with path.open(encoding="utf-8-sig") as f:
        rows = [[c.strip() for c in row] for row in csv.reader(f) if any(c.strip() for c in row)]
    if not rows or rows[0] != list(LOCATION_COLUMNS):
        raise AcquisitionError(f"{path}: header {','.join(LOCATION_COLUMNS)} expected")
    for line, row in enumerate(rows[1:], start=2):
        try:
            out[int(row[0])] = np.array([float(v) for v in row[1:4]]) * 1e-3
        except (ValueError, IndexError):
            raise AcquisitionError(f"{path}:{line}: not a location,x_mm,y_mm,z_mm row") from None
    return out


def _check_zero(folder: Path, location: int, zero: np.ndarray | None) -> str:
    """Check ``zero`` against locations.csv; return what will happen, in one sentence.

    Raises:
        AcquisitionError: if locations.csv holds another zero position for ``location``.
    """
    known = _read_locations(folder)
    path = folder / "locations.csv"
    if zero is None:
        if location in known:
            return f"{path} has the zero position of location {location}"
        return (f"{path} has no zero position for location {location}: add the line "
                f"'{location},<x_mm>,<y_mm>,<z_mm>' (the nest's zero in the MT-CS) before "
                f"identify, or record again with --zero x,y,z")
    if location in known:
        if np.allclose(known[location], zero, rtol=0, atol=1e-9):
            return f"{path} already has this zero position for location {location}"
        raise AcquisitionError(
            f"{path} holds the zero position {np.round(known[location] * 1e3, 6).tolist()} mm "
            f"for location {location}, not {np.round(zero * 1e3, 6).tolist()} mm: edit the file "
            f"or leave out --zero")
    return f"{path}: zero position of location {location} added"


def write_zero(folder: str | Path, location: int, zero: np.ndarray) -> None:
    """Add (or confirm) a location's zero position (shape (3,), m) in ``folder/locations.csv``.

    The file is rewritten whole through a temporary file and an atomic rename, sorted by location.

    Raises:
        AcquisitionError: if the file holds another zero position for ``location``.
    """
    folder = Path(folder)
    zero = np.asarray(zero, dtype=float).reshape(3)
    _check_zero(folder, location, zero)
    known = _read_locations(folder)
    known[int(location)] = zero
    lines = [",".join(LOCATION_COLUMNS)] + [
        f"{k}," + ",".join(f"{v * 1e3:.9f}" for v in known[k]) for k in sorted(known)]
    _replace_text(folder / "locations.csv", "\n".join(lines) + "\n")


def _replace_text(path: Path, text: str) -> None:
    """Replace ``path`` by ``text`` (UTF-8) through a temporary file beside it and one rename.

    A killed run's temporary file of ``path`` is removed first
    (:func:`~aacmm_pin.data.output_claim.remove_leftovers`).
    """
    remove_leftovers(path)
    fd, name = tempfile.mkstemp(prefix=temp_prefix(path), suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.chmod(name, 0o666 & ~umask())
        os.replace(name, path)
    finally:
        Path(name).unlink(missing_ok=True)
