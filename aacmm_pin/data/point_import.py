"""Tracker and motion-capture point files to a points campaign: :func:`import_points`.

An instrument's export is a CSV file with one row per pose: the arm's joint angles in some
columns, the measured tool point in others, in the instrument's units. A :class:`PointFormat`
says which columns and units: given by the user (:func:`parse_columns`, :func:`parse_point`) or a
preset recognised from the header (:func:`detect_format`; :data:`PRESETS`: ``jacobi2025``, the
laser-tracker data of P. Jacobi's thesis shipped in ``shared/real-data``). :func:`read_point_file`
reads one file into a :class:`~aacmm_pin.data.logs.PointLog` in SI, every cell checked (file,
line, column, a few of each kind: :mod:`aacmm_pin.data.problem_log`); :func:`import_points` writes
the campaign folder whole or not at all: ``points.csv`` in the package's format (mm, degrees) and
``campaign.json`` with the instrument's stated noise, when known, and the provenance (source files,
their rows, the licence found beside them).
"""

from __future__ import annotations

import csv
import hashlib
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aacmm_pin.data.arm_names import ArmNames, couplings_of
from aacmm_pin.data.bounded_read import read_bounded
from aacmm_pin.data.campaign_writer import write_campaign
from aacmm_pin.data.columns import MAX_ANGLE_DEG
from aacmm_pin.data.couplings import fill_coupled
from aacmm_pin.data.csv_table import MAX_FILE_BYTES, radian_like_column, read_table
from aacmm_pin.data.logs import NOISE_FILE, Campaign, PointLog, StatedNoise
from aacmm_pin.data.output_folder import output_folder
from aacmm_pin.data.point_format import (
    ANGLE_UNITS,
    JACOBI2025,
    LENGTH_UNITS,
    PRESETS,
    PointFormat,
    detect_format,
    parse_columns,
    parse_point,
)
from aacmm_pin.data.poses import POSE_COLUMN, pose_ids
from aacmm_pin.data.problem_log import ProblemLog, close_match
from aacmm_pin.errors import ArgumentError, CampaignFormatError, Problem
from aacmm_pin.units import MAX_COORDINATE, RADIAN_MIN_ROWS, UM

__all__ = ["ANGLE_UNITS", "JACOBI2025", "LENGTH_UNITS", "PRESETS", "ImportResult", "PointFormat",
           "detect_format", "import_points", "parse_columns", "parse_point", "read_point_file"]


def read_header(path: Path) -> list[str] | None:
    """Return the stripped cells of a CSV file's first row, or None if it cannot be read."""
    try:
        with path.open(newline="", encoding="utf-8-sig") as f:
            row = next(csv.reader(f), None)
    except (OSError, UnicodeDecodeError, csv.Error):
        return None  # read_table says why
    return None if row is None else [c.strip() for c in row]


def _missing(path: Path, header: list[str], fmt: PointFormat) -> list[Problem]:
    """Return a problem per column of the format the header lacks, with the name it likely means."""
    problems: list[Problem] = []
    shown = ", ".join(header[:16]) + (f" and {len(header) - 16} more" if len(header) > 16 else "")
    for name in (n for n in (*fmt.columns, *fmt.labels) if n not in header):
        meant = close_match(name, header)
        hint = f"; did you mean {meant}?" if meant else ""
        listing = f" (the header has: {shown})" if not problems else ""  # the header once
        problems.append(Problem(path, 1, name, f"missing column{hint}{listing}"))
    return problems


def _check_values(path: Path, lines: Sequence[int], fmt: PointFormat, q: np.ndarray,
                  point: np.ndarray, out: list[Problem]) -> None:
    """Add a problem for each angle or coordinate beyond what an arm or instrument gives.

    ``q`` (N, n) rad and ``point`` (N, 3) m as read: an angle beyond two turns or a coordinate
    beyond :data:`~aacmm_pin.units.MAX_COORDINATE` is most likely a wrong unit; so are degree
    columns that all lie within +-2 pi over many rows while the arm moves.
    """
    log = ProblemLog(out, path, "cells")
    other_angle = "rad" if fmt.angle_unit == "deg" else "deg"
    other_length = "m" if fmt.length_unit == "mm" else "mm"
    for k, name in enumerate(fmt.joints):
        for i in np.flatnonzero(np.abs(np.degrees(q[:, k])) > MAX_ANGLE_DEG):
            log.add(lines[int(i)], name, f"{q[i, k] / ANGLE_UNITS[fmt.angle_unit]:g} {fmt.angle_unit} "
                                    f"is beyond +-{MAX_ANGLE_DEG:g} deg: in {other_angle}? "
                                    "(--angles)", "angle")
    for k, (name, _) in enumerate(fmt.point):
        for i in np.flatnonzero(np.abs(point[:, k]) > MAX_COORDINATE):
            log.add(lines[int(i)], name, f"{point[i, k] / LENGTH_UNITS[fmt.length_unit]:g} "
                                    f"{fmt.length_unit} is beyond +-{MAX_COORDINATE:g} m: in "
                                    f"{other_length}? (--units)", "coordinate")
    moving = (radian_like_column(q / ANGLE_UNITS[fmt.angle_unit])
             if fmt.angle_unit == "deg" and not fmt.angles_stated and len(q) >= RADIAN_MIN_ROWS
             else None)
    if moving is not None:
        log.add(lines[0], fmt.joints[moving],
                f"every joint column lies within +-6.29 over {len(q)} rows: these look like "
                "radians (--angles rad; --angles deg if they are degrees)")
    log.close()


@dataclass(frozen=True)
class PointFile:
    """One instrument file read: its points and where they came from."""

    path: Path
    """The file."""
    log: PointLog
    """Its points (group 1), q rad, point m, ``lines`` the source file's lines."""
    offset: np.ndarray | None
    """Length of each subtracted vector (``x_dif, y_dif, z_dif``: nominal minus measured), (N,)
    m, or None when the format subtracts nothing."""
    labels: dict[str, list[str]] = field(default_factory=dict)
    """The text columns read (:attr:`PointFormat.labels`), each cell as written, by column."""


def read_point_file(path: str | Path, fmt: PointFormat | None = None) -> tuple[PointFile,
                                                                              PointFormat]:
    """Read an instrument's CSV file; return its points and the format used.

    Args:
        path: the CSV file (comma separated, header row).
        fmt: its columns and units; None: a preset recognised from the header (:data:`PRESETS`).

    Raises:
        CampaignFormatError: naming file, line and column of each problem: a missing column
            (with the name it likely means), a bad cell, an angle or coordinate in the wrong unit,
            a header no preset recognises when ``fmt`` is None.
    """
    path = Path(path)
    header = read_header(path)
    problems: list[Problem] = []
    if header is None or len(header) < 2:  # unreadable, empty, another separator: the reader says
        read_table(path, (), False, (), problems, extras="readouts")
        raise CampaignFormatError(problems or [Problem(path, 1, None, "a single column; joint "
                                                       "and point columns expected")])
    if fmt is None:
        fmt = detect_format(header)
        if fmt is None:
            presets = ", ".join(PRESETS)
            raise CampaignFormatError([Problem(path, 1, None, f"no preset format ({presets}) has "
                                               "this header; give the joint and point columns "
                                               "(--joints, --point)")])
    if problems := _missing(path, header, fmt):
        raise CampaignFormatError(problems)
    columns = fmt.columns
    table = read_table(path, columns, False, (), problems, extras="readouts")
    if problems or table is None:
        raise CampaignFormatError(problems or [Problem(path, None, None, "cannot be read")])
    cells = {name: np.array(table.cols[name], dtype=float) for name in columns}
    q = np.stack([cells[n] for n in fmt.joints], axis=1) * ANGLE_UNITS[fmt.angle_unit]
    scale = LENGTH_UNITS[fmt.length_unit]
    point = np.stack([cells[a] - (0.0 if b is None else cells[b]) for a, b in fmt.point],
                     axis=1) * scale
    _check_values(path, table.lines, fmt, q, point, problems)
    if problems:
        raise CampaignFormatError(problems)
    subtracted = [b for _, b in fmt.point if b is not None]
    offset = (np.linalg.norm(np.stack([cells[b] for b in subtracted], axis=1), axis=1) * scale
              if len(subtracted) == 3 else None)
    log = PointLog(np.ones(len(q), dtype=np.int64), q, point,
                   lines=np.array(table.lines, dtype=np.int64))
    return PointFile(path, log, offset, _text_columns(path, fmt.labels, table.lines)), fmt


def _text_columns(path: Path, names: Sequence[str], lines: Sequence[int]) -> dict[str, list[str]]:
    """Return the cells of text columns ``names`` on the file's ``lines`` (1-based), stripped."""
    if not names:
        return {}
    wanted = set(lines)
    out: dict[str, list[str]] = {name: [] for name in names}
    with path.open(newline="", encoding="utf-8-sig") as f:
        rows = csv.reader(f)
        index = {c.strip(): k for k, c in enumerate(next(rows))}
        for row in rows:
            if rows.line_num in wanted:  # the rows read_table kept (lines as it numbers them)
                for name in names:
                    out[name].append(row[index[name]].strip())
    return out


def licence_note(path: Path, folder: Path | None = None) -> str | None:
    """Return ``<LICENSE file>: <its first line>`` found beside a data file or up to 2 folders up.

    ``folder``: the LICENSE file's path is given relative to it (:func:`relative_to`); None: absolute.
    """
    for where in [path.absolute().parent, *path.absolute().parent.parents][:3]:
        for candidate in sorted(where.glob("LICEN[CS]E*")):
            if candidate.is_file():
                try:
                    with candidate.open(encoding="utf-8", errors="replace") as f:
                        first = next((line.strip() for line in f if line.strip()), "")
                except OSError:
                    continue
                return f"{candidate if folder is None else relative_to(candidate, folder)}: {first}"
    return None


@dataclass(frozen=True)
class ImportResult:
    """What :func:`import_points` read and wrote."""

    campaign: Campaign
    """The campaign written (points in SI; ``noise`` the stated one, or None)."""
    files: tuple[PointFile, ...]
    """Each source file read, in order."""
    format: PointFormat
    """The format used (the first file's preset, when recognised)."""
    provenance: dict[str, Any] = field(default_factory=dict)
    """The ``provenance`` object written to ``campaign.json``."""

    @property
    def mean_offset(self) -> float | None:
        """Mean length of the subtracted vectors over all points (nominal - measured), m, or None."""
        offsets = [f.offset for f in self.files]
        if any(o is None for o in offsets):
            return None
        return float(np.mean(np.concatenate([o for o in offsets if o is not None])))


def _refuse_repeated(sources: Sequence[str | Path]) -> None:
    """Refuse a source given twice, by its resolved path or its content (SHA-256 of its bytes).

    Imported twice, its points would count twice as another instrument set-up, and the fit's
    uncertainties shrink as if they were independent measurements (by 0.71 x for a file doubled).

    Raises:
        ArgumentError: one line naming both sources.
    """
    seen: dict[object, Path] = {}
    for source in sources:
        path = Path(source)
        try:
            raw = read_bounded(path, MAX_FILE_BYTES)
        except OSError:
            continue  # the reader names a missing or unreadable file
        digest = None if raw is None else hashlib.sha256(raw).hexdigest()  # too large: named later
        for key, how in ((path.resolve(), "the same file"), (digest, "the same content")):
            if key is None:
                continue
            if key in seen:
                raise ArgumentError(f"sources: {path} is {how} as {seen[key]}: imported twice, its "
                                    "points would count twice as another instrument set-up and "
                                    "shrink the uncertainties; give each file once")
            seen[key] = path


def _read_sources(sources: Sequence[str | Path], fmt: PointFormat | None
                  ) -> tuple[list[PointFile], list[PointFormat]]:
    """Read every instrument file (:func:`read_point_file`): the files and the formats used.

    Raises:
        CampaignFormatError: every problem of every file.
    """
    files: list[PointFile] = []
    formats: list[PointFormat] = []
    problems: list[Problem] = []
    for source in sources:
        try:
            read, used = read_point_file(source, fmt)
        except CampaignFormatError as exc:
            problems += exc.problems
            continue
        files.append(read)
        formats.append(used)
    if problems:
        raise CampaignFormatError(problems)
    return files, formats


def import_points(sources: Sequence[str | Path], folder: str | Path,
                  fmt: PointFormat | None = None, *, sigma: float | None = None,
                  one_frame: bool = False, force: bool = False,
                  instrument: str | None = None, arm: ArmNames | None = None) -> ImportResult:
    """Convert instrument point files into a points campaign folder (written whole or not at all).

    Args:
        sources: the instrument's CSV files; each is one instrument set-up (``group`` 1, 2, ...)
            unless ``one_frame``.
        folder: the campaign folder to write (``points.csv``, ``campaign.json``).
        fmt: columns and units of the files; None: each file's preset, from its header.
        sigma: stated standard uncertainty of a point per coordinate, m (overrides the preset's);
            None: the preset's, else none stated (the package's default applies).
        one_frame: all files share one instrument frame (one group).
        force: replace a folder that holds files.
        instrument: the kind of instrument (``laser tracker``, ``motion capture``: a key of
            :data:`aacmm_pin.units.INSTRUMENT_NOISE`), written to ``campaign.json``; its noise is
            the stated one unless ``sigma`` or the preset's is given. None: not named.
        arm: the arm the points are of (an :class:`~aacmm_pin.model.arm.Arm`, or any
            :class:`~aacmm_pin.data.campaign.ArmNames`): the joint columns are its independent
            axes in order (a coupled joint has no column; it is set by its coupling), may be one
            per axis (a coupled one then checked when read), ``points.csv`` names its readout
            columns ``<joint name>_deg`` (coupled ones left out) and the tool column's values
            are checked against its tools. None: the columns are axes 1..n (``q<k>_deg``).

    Returns:
        What was read and written; ``campaign.points.lines`` are the lines of ``points.csv``.

    Raises:
        CampaignFormatError: every problem of every file (file, line, column).
        OutputExistsError: if ``folder`` holds files (without ``force``) or is a source.
        ValueError: for no sources, files with different numbers of axes, a bad ``sigma`` or an
            unknown ``instrument``.
    """
    if not sources:
        raise ValueError("sources: give one or more point files")
    _refuse_repeated(sources)
    files, formats = _read_sources(sources, fmt)
    if len(axes := {f.log.q.shape[1] for f in files}) > 1:
        raise ValueError(f"sources: the files have {sorted(axes)} axes; one arm's files expected")
    q = np.concatenate([f.log.q for f in files])
    if arm is not None:
        q = _arm_readouts(q, arm)
        _check_tools(files, formats, arm)
    noise = sigma if sigma is not None else formats[0].noise
    group = np.concatenate([np.full(len(f.log.q), 1 if one_frame else k, dtype=np.int64)
                            for k, f in enumerate(files, start=1)])
    tools = [f.labels.get(fmt_.tool) for f, fmt_ in zip(files, formats) if fmt_.tool is not None]
    if tools and len(tools) < len(files):
        raise ValueError("sources: some files have a tool column and some none; one format expected")
    points = PointLog(group, q, np.concatenate([f.log.point for f in files]),
                      lines=np.arange(2, 2 + len(group), dtype=np.int64),
                      tool=np.array([t for cells in tools for t in cells or []], dtype=str)
                      if tools else None,
                      columns=_pose_column(files, formats))
    given = {} if noise is None else {"point": noise}
    stated = (StatedNoise.of_instrument(instrument, **given) if instrument is not None
              else None if noise is None else StatedNoise(point=noise))
    campaign = Campaign(None, {}, None, {}, points=points, noise=stated)
    provenance = _provenance(files, formats, Path(folder), "none stated: the package's default applies"
                             if stated is None else f"the {stated.instrument}'s default"
                             if noise is None else "as given" if sigma is not None
                             else "the preset's instrument accuracy")
    with output_folder(folder, force, [f.path for f in files]) as tmp:
        write_campaign(campaign, tmp, arm)
        content: dict[str, Any] = {} if stated is None else {"noise_um": {"point": stated.point / UM}}
        if stated is not None and stated.instrument:
            content = {"instrument": stated.instrument, **content}
        content["provenance"] = provenance
        (tmp / NOISE_FILE).write_text(json.dumps(content, indent=2) + "\n", encoding="utf-8")
    return ImportResult(campaign, tuple(files), formats[0], provenance)


def _arm_readouts(q: np.ndarray, arm: ArmNames) -> np.ndarray:
    """Return readouts (N, n_axes) of the arm from the joint columns read (N, k), rad.

    k = the arm's independent axes: placed in axis order, the coupled ones set by their couplings;
    k = every axis: as read (the reader checks a coupled column against its coupling).

    Raises:
        ValueError: for another number of joint columns, naming the arm's axes.
    """
    names = list(arm.axis_names)
    coupled = {c.axis for c in couplings_of(arm)}
    free = [k for k in range(len(names)) if k not in coupled]
    if q.shape[1] == len(names):  # a coupled joint's column too: it must follow its coupling
        for c in couplings_of(arm):
            off = np.abs(q[:, c.axis] - c.values(q))
            if (bad := np.flatnonzero(~(off <= c.tolerance))).size:
                raise ValueError(
                    f"--joints: the column of the coupled joint {names[c.axis]} is "
                    f"{np.degrees(q[bad[0], c.axis]):.6g} deg in data row {bad[0] + 1}, its coupling "
                    f"{c.coupling.formula()} gives {np.degrees(c.values(q)[bad[0]]):.6g} deg "
                    f"({bad.size} rows beyond {np.degrees(c.tolerance):.3g} deg): leave the column "
                    "out (the coupling fills it) or check which column is which")
        return q
    if q.shape[1] != len(free):
        left = f" (its coupled {', '.join(names[k] for k in sorted(coupled))} need no column)"
        raise ValueError(f"--joints: {q.shape[1]} joint columns for the arm's {len(free)} "
                         f"independent axes {', '.join(names[k] for k in free)}"
                         f"{left if coupled else ''}")
    out = np.zeros((len(q), len(names)))
    out[:, free] = q
    return fill_coupled(out, couplings_of(arm))


def _check_tools(files: list[PointFile], formats: list[PointFormat], arm: ArmNames) -> None:
    """Raise CampaignFormatError for a tool column cell that names none of the arm's tools."""
    known = list(arm.tool_names)
    problems = []
    for f, fmt in zip(files, formats):
        cells = f.labels.get(fmt.tool) if fmt.tool is not None else None
        lines = f.log.lines if f.log.lines is not None else np.arange(2, 2 + len(f.log.q))
        bad = [(int(line), c) for line, c in zip(lines, cells or []) if c not in known]
        if bad:
            meant = close_match(bad[0][1], known)
            hint = f"; did you mean {meant}?" if meant else ""
            problems.append(Problem(f.path, bad[0][0], fmt.tool, f"unknown tool {bad[0][1]!r} "
                                    f"({len(bad)} rows){hint}; the arm's tools: {', '.join(known)}"))
    if problems:
        raise CampaignFormatError(problems)


def _pose_column(files: list[PointFile], formats: list[PointFormat]) -> dict[str, np.ndarray]:
    """Return the ``pose`` column (1, 2, ... over all files) where a pose has several points.

    Several points of one pose: the rows of one label in the format's pose column, else
    identical readouts in consecutive rows (several markers). Without any, nothing (``{}``).
    """
    ids, first = [], 1
    for f, fmt in zip(files, formats):
        if fmt.pose is not None:  # labels numbered in the order they first appear
            labels = f.labels[fmt.pose]
            order = {label: k for k, label in enumerate(dict.fromkeys(labels))}
            own = np.array([order[label] for label in labels], dtype=np.int64)
        else:
            own = pose_ids(f.log.q)
        ids.append(own + first)
        first += int(own.max()) + 1 if own.size else 0
    pose = np.concatenate(ids)
    return {POSE_COLUMN: pose.astype(float)} if len(np.unique(pose)) < len(pose) else {}


def relative_to(path: Path, folder: Path) -> str:
    """Return ``path`` relative to ``folder`` (``../data/tracker.csv``), else as given.

    A campaign folder moved with its sources, or read on another machine, still names them; a
    path that has no relative form (another drive) is kept as the user gave it.
    """
    try:
        return Path(os.path.relpath(path.absolute(), folder.absolute())).as_posix()
    except ValueError:
        return str(path)


def _provenance(files: list[PointFile], formats: list[PointFormat], folder: Path, noise: str
                ) -> dict[str, Any]:
    """Return campaign.json's ``provenance``: per source file its rows, format and licence.

    ``folder``: the campaign folder, which the source paths are relative to; ``noise``: where the
    stated noise comes from, in a few words.
    """
    out: list[dict[str, Any]] = []
    first = 2
    for f, fmt in zip(files, formats):
        n = len(f.log.q)
        lines = f.log.lines if f.log.lines is not None else np.arange(2, 2 + n)
        entry: dict[str, Any] = {
            "file": relative_to(f.path, folder), "rows": n,
            "source_lines": f"{int(lines[0])}..{int(lines[-1])}",
            "points_csv_lines": f"{first}..{first + n - 1}", "format": fmt.describe()}
        if fmt.instrument:
            entry["instrument"] = fmt.instrument
        if fmt.source:
            entry["source"] = fmt.source
        if (note := licence_note(f.path, folder)) is not None:
            entry["licence_file"] = note
        out.append(entry)
        first += n
    return {"imported_by": "aacmm-pin import-points", "files": out, "noise": noise}
