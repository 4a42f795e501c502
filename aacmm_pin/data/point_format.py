"""Which columns of an instrument's point file hold what, in which units: :class:`PointFormat`.

Given by the user (:func:`parse_columns`, :func:`parse_point`) or a preset recognised from the
header (:func:`detect_format`; :data:`PRESETS`: ``jacobi2025``, the laser-tracker data of
P. Jacobi's thesis shipped in ``shared/real-data``); read by
:func:`aacmm_pin.data.point_import.read_point_file`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

from aacmm_pin.data.csv_table import MAX_COLUMNS
from aacmm_pin.units import MM, UM

LENGTH_UNITS = {"mm": MM, "m": 1.0}
"""Length unit of a file -> metres per unit."""
ANGLE_UNITS = {"deg": math.pi / 180.0, "rad": 1.0}
"""Angle unit of a file -> radians per unit."""


@dataclass(frozen=True)
class PointFormat:
    """Which columns of an instrument's CSV hold what, in which units."""

    joints: tuple[str, ...]
    """Joint-angle columns in axis order (readout order of the arm: ``aacmm-pin axes``)."""
    point: tuple[tuple[str, str | None], ...]
    """For x, y, z: the column holding the coordinate, and a column subtracted from it or None
    (``x_t - x_dif``: a nominal point and its deviation)."""
    length_unit: str = "mm"
    """Unit of the point columns, a key of :data:`LENGTH_UNITS`."""
    angle_unit: str = "deg"
    """Unit of the joint columns, a key of :data:`ANGLE_UNITS`."""
    name: str = ""
    """Preset name (empty: given column by column)."""
    noise: float | None = None
    """Stated standard uncertainty of a point per coordinate, m, or None (not known)."""
    angles_stated: bool = False
    """True when the user stated the angle unit (``--angles deg``): no guess that degree columns
    are radians (an arm that moves a few degrees only)."""
    instrument: str = ""
    """The instrument and its stated accuracy, as its maker states them."""
    source: str = ""
    """Where the data come from (publication, repository, licence)."""
    tool: str | None = None
    """Column naming the tool (marker) each row measures, or None (the arm's only tool)."""
    pose: str | None = None
    """Column naming the pose of each row (rows with one label are one pose: several markers), or
    None (identical readouts in consecutive rows are one pose)."""

    def __post_init__(self) -> None:
        if not self.joints:
            raise ValueError("joints: one column per axis expected, got none")
        if len(self.point) != 3:
            raise ValueError(f"point: three columns (x, y, z) expected, got {len(self.point)}")
        if self.length_unit not in LENGTH_UNITS or self.angle_unit not in ANGLE_UNITS:
            raise ValueError(f"units: length one of {', '.join(LENGTH_UNITS)} and angle one of "
                             f"{', '.join(ANGLE_UNITS)} expected, got {self.length_unit!r}, "
                             f"{self.angle_unit!r}")

    @property
    def columns(self) -> tuple[str, ...]:
        """Every numeric column the format reads, without repeats, joints first."""
        named = [*self.joints, *(c for pair in self.point for c in pair if c is not None)]
        return tuple(dict.fromkeys(named))

    @property
    def labels(self) -> tuple[str, ...]:
        """The text columns the format reads: the tool's and the pose's, those given."""
        return tuple(c for c in (self.tool, self.pose) if c is not None)

    def describe(self) -> str:
        """Return one line: the joint and point columns and their units."""
        joints = (f"{self.joints[0]}..{self.joints[-1]}" if len(self.joints) > 2
                  else ",".join(self.joints))
        point = ",".join(a if b is None else f"{a}-{b}" for a, b in self.point)
        name = f"{self.name}: " if self.name else ""
        labels = "".join(f", {what} {c}" for what, c in (("tool", self.tool), ("pose", self.pose))
                         if c is not None)
        return (f"{name}joints {joints} ({self.angle_unit}), point {point} ({self.length_unit})"
                f"{labels}")


_RANGE_END = re.compile(r"(.*?)(\d+)(\D*)")


def parse_columns(text: str) -> tuple[str, ...]:
    """Return the column names of a comma-separated list; ``q1..q6`` stands for q1, q2, ..., q6.

    A range's ends differ only in their last number (``joint_1..joint_7``, ``a1_deg..a6_deg``).

    Raises:
        ValueError: for an empty list or name, a range whose ends do not match, or more names
            than a file's columns (:data:`~aacmm_pin.data.csv_table.MAX_COLUMNS`).
    """
    names: list[str] = []
    for item in (part.strip() for part in text.split(",")):
        if ".." not in item:
            names.append(item)
            continue
        first, _, last = item.partition("..")
        a, b = _RANGE_END.fullmatch(first.strip()), _RANGE_END.fullmatch(last.strip())
        if not (a and b and a[1] == b[1] and a[3] == b[3] and int(a[2]) <= int(b[2])):
            raise ValueError(f"{item!r}: a range is <name><first number>..<name><last number>, "
                             "e.g. q1..q6 or joint_1..joint_7")
        count = int(b[2]) - int(a[2]) + 1
        if len(names) + count > MAX_COLUMNS:  # a file has no more: never a million names
            raise ValueError(f"{item!r}: a range of {count:,} columns; a file is read with at "
                             f"most {MAX_COLUMNS} columns (e.g. q1..q6 or joint_1..joint_7)")
        width = len(a[2]) if a[2].startswith("0") else 1  # q01..q06 keeps its zero padding
        names += [f"{a[1]}{k:0{width}d}{a[3]}" for k in range(int(a[2]), int(b[2]) + 1)]
    if not names or not all(names):
        raise ValueError(f"{text!r}: comma-separated column names expected (e.g. q1..q6)")
    return tuple(names)


def parse_point(text: str, header: Sequence[str] = ()) -> tuple[tuple[str, str | None], ...]:
    """Return the x, y, z point columns of ``x,y,z`` or ``x_t-x_dif,y_t-y_dif,z_t-z_dif``.

    ``A-B`` is column A minus column B, unless the header has a column named ``A-B``.

    Raises:
        ValueError: unless three columns are given.
    """
    items = [part.strip() for part in text.split(",")]
    if len(items) != 3 or not all(items):
        raise ValueError(f"{text!r}: three comma-separated columns x,y,z expected (each a "
                         "column or column-column)")
    out: list[tuple[str, str | None]] = []
    for item in items:
        a, minus, b = item.partition("-")
        out.append((a.strip(), b.strip()) if minus and a.strip() and b.strip()
                   and item not in header else (item, None))
    return tuple(out)


def _jacobi2025(header: Sequence[str]) -> PointFormat | None:
    """Return the jacobi2025 format of a header that is one, else None."""
    joints = [h for h in header if h.startswith("joint_")]
    fixed = ["step_order", "x_t", "y_t", "z_t", "x_dif", "y_dif", "z_dif"]
    if not joints or list(header) != fixed + [f"joint_{k}" for k in range(1, len(joints) + 1)]:
        return None
    return PointFormat(
        tuple(joints), tuple((f"{c}_t", f"{c}_dif") for c in "xyz"), "mm", "deg", "jacobi2025",
        noise=20 * UM,
        instrument="GTS3800 laser tracker, stated volumetric accuracy 15 um + 6 um/m; taken as "
                   "20 um per coordinate (15 um + 6 um/m at about 1 m)",
        source="P. Jacobi, A Hybrid Error Compensation Method for Enhancing the Pose Accuracy of "
               "Serial Industrial Robots, Master's thesis, Tsinghua University, 2025; "
               "github.com/pauljac7700/serial_robots_datasets, MIT licence (keep its LICENSE "
               "with the data)")


PRESETS = {"jacobi2025": _jacobi2025}
"""Preset name -> function of a file's header returning its format, or None if it is not one.

``jacobi2025``: ``step_order, x_t, y_t, z_t, x_dif, y_dif, z_dif, joint_1..joint_n``; the
commanded point ``x_t..`` (mm) and ``dif = commanded - measured`` (mm), joint angles in degrees;
the measured point is ``x_t - x_dif``."""
JACOBI2025 = "jacobi2025"
"""Name of the preset of the shipped laser-tracker data."""


def detect_format(header: Sequence[str]) -> PointFormat | None:
    """Return the preset format a header is, or None."""
    return next((fmt for preset in PRESETS.values() if (fmt := preset(header)) is not None), None)
