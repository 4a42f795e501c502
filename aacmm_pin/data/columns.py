"""The per-sample columns of campaign and readouts files: name, unit, plausible range, in one table.

Besides its readouts (``q1_deg..qn_deg``) and its fixed columns (ids, points, displacements), every
row of ``spat.csv``, ``lengthbar.csv``, ``points.csv`` and a readouts file may carry further numeric
columns: the time ``t_s``, the arm temperature ``temp_c``, a point's ``sigma_um``, and any column a
user or a plugin adds (say ``temp_wrist_c``). The readers carry each one by its file name to the
logs and the samples, in SI units, after checking every cell against the range stated here.

A column's unit comes from this table: the built-in columns below, the columns a plugin declares
with :func:`register_column`, and for any other name its unit suffix (:data:`SUFFIXES`: ``_c`` deg C,
``_s`` s, ``_mm`` and ``_um`` m, ``_deg`` rad, ``_nm`` N m, ``_n`` N); a name without one of these
suffixes is a plain number, kept as written. Temperatures stay in deg C inside the package (the
thermal terms are relative to 20 deg C, :data:`aacmm_pin.units.REFERENCE_TEMPERATURE_C`).

A carried column named close to one that is read (:func:`meant_column`: ``sigma_mm``, ``tmp_c``)
is refused, and the carried columns no effect reads are named once per file
(:func:`check_names`; the effects' columns come from the registry, :func:`set_effect_reads`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from aacmm_pin.data.poses import POSE_COLUMN
from aacmm_pin.errors import Problem
from aacmm_pin.units import MAX_COORDINATE, MM, NOISE_MAX, NOISE_MIN, TEMPERATURE_RANGE_C, UM

MAX_ANGLE_DEG = 720.0
"""Largest angle accepted in a file, deg (two turns either way): readouts and ``_deg`` columns."""


@dataclass(frozen=True)
class Column:
    """One per-sample column of the files: how it is written and what values are plausible.

    A file value ``v`` is ``v * factor`` in SI (:meth:`to_si`); the range is checked in file units
    (:meth:`check`).
    """

    name: str
    """Column name as in the files' header, e.g. ``temp_c``."""
    field: str
    """Name of the quantity inside the package, e.g. ``temp`` (``SpatLog.temp``)."""
    unit: str
    """Unit as written in the file, e.g. ``deg C``; empty for a plain number."""
    factor: float = 1.0
    """File value times this is the SI value (``_mm``: 1e-3)."""
    low: float = -math.inf
    """Smallest plausible value, file units (inclusive)."""
    high: float = math.inf
    """Largest plausible value, file units (inclusive)."""
    description: str = ""
    """What the column holds, in a few words."""
    positive: bool = False
    """Whether the value must be above zero (a standard uncertainty)."""
    noun: str = ""
    """What a value is called in messages ("standard uncertainty"); empty: the range is given."""
    min_spread: float = 0.0
    """Smallest spread over the samples, file units, for which the column is a variable worth
    testing (the residual scan, the effects' candidates): 0.05 deg C, 1 deg, 0.01 N m."""

    def __post_init__(self) -> None:
        if not self.name or not self.name.strip() == self.name or "," in self.name:
            raise ValueError(f"name: a column header without commas or surrounding spaces "
                             f"expected, got {self.name!r}")
        if not (math.isfinite(self.factor) and self.factor > 0):
            raise ValueError(f"factor: a positive finite number expected, got {self.factor!r}")
        if not (self.low <= self.high and self.min_spread >= 0):
            raise ValueError(f"low, high, min_spread: low <= high and min_spread >= 0 expected, "
                             f"got {self.low!r}, {self.high!r}, {self.min_spread!r}")

    def check(self, value: float) -> str | None:
        """Return why a file value is not plausible (after the cell text), or None if it is."""
        unit = f"{self.unit} " if self.unit else ""
        if not math.isfinite(value):
            return "is not a finite number"
        if self.positive and value <= 0:
            return f"{unit}is not a positive {self.noun or 'value'}"
        if self.low <= value <= self.high:
            return None
        if self.noun:
            return f"{unit}is not a plausible {self.noun} ({self.low:g} to {self.high:g} {self.unit})"
        if math.isinf(self.low) or math.isinf(self.high):
            bound = f"below {self.low:g}" if value < self.low else f"above {self.high:g}"
            return f"{unit}is {bound} {self.unit}".rstrip()
        return f"{unit}is outside {self.low:g} to {self.high:g} {self.unit}".rstrip()

    def varies(self, values: np.ndarray) -> bool:
        """Tell whether SI values spread by more than :attr:`min_spread` (a variable to test)."""
        shown = self.from_si(values)
        return bool(shown.size and np.ptp(shown) > self.min_spread)

    def to_si(self, values: np.ndarray | list[float]) -> np.ndarray:
        """Return file values in SI, as floats."""
        out: np.ndarray = np.asarray(values, dtype=float) * self.factor
        return out

    def from_si(self, values: np.ndarray) -> np.ndarray:
        """Return SI values in the file's unit."""
        out: np.ndarray = np.asarray(values, dtype=float) * (1.0 / self.factor)
        return out


BUILT_IN: tuple[Column, ...] = (
    Column("sigma_um", "sigma", "um", UM, NOISE_MIN / UM, NOISE_MAX / UM,
           "stated standard uncertainty of a point per coordinate", positive=True,
           noun="standard uncertainty"),
    Column("t_s", "t", "s", 1.0, description="time of the sample"),
    Column("temp_c", "temp", "deg C", 1.0, *TEMPERATURE_RANGE_C, "arm temperature",
           min_spread=0.05),
)
"""The per-sample columns the package itself reads (in this order when written)."""

SUFFIXES: dict[str, Column] = {
    "_c": Column("_c", "", "deg C", 1.0, *TEMPERATURE_RANGE_C, "a temperature", min_spread=0.05),
    "_s": Column("_s", "", "s", 1.0, description="a time"),
    "_mm": Column("_mm", "", "mm", MM, -MAX_COORDINATE * 1e3, MAX_COORDINATE * 1e3, "a length"),
    "_um": Column("_um", "", "um", UM, -MAX_COORDINATE * 1e6, MAX_COORDINATE * 1e6, "a length"),
    "_deg": Column("_deg", "", "deg", math.pi / 180.0, -MAX_ANGLE_DEG, MAX_ANGLE_DEG, "an angle",
                   min_spread=1.0),
    "_nm": Column("_nm", "", "nm", 1e-9, -MAX_COORDINATE * 1e9, MAX_COORDINATE * 1e9,
                  "a length"),
    "_n_m": Column("_n_m", "", "N m", 1.0, description="a torque", min_spread=1e-2),
    "_n": Column("_n", "", "N", 1.0, description="a force"),
}
"""Unit of a column no table names, by the end of its name (longest suffix first when matched):
``_nm`` is nanometres (a length, as a metrologist reads it), ``_n_m`` newton metres."""

_REGISTERED: dict[str, Column] = {c.name: c for c in BUILT_IN}


def register_column(column: Column) -> Column:
    """Declare a per-sample column (a plugin's), its unit and plausible range, for every reader.

    Registering the same column again is harmless.

    Raises:
        ValueError: if ``column.name`` is registered with another definition (a built-in column
            cannot be redefined).
    """
    known = _REGISTERED.get(column.name)
    if known is not None and known != column:
        raise ValueError(f"column: '{column.name}' is already registered as {known}")
    _REGISTERED[column.name] = column
    return column


def registered_columns() -> tuple[Column, ...]:
    """Return the columns declared so far: the built-in ones, then those registered, in order."""
    return tuple(_REGISTERED.values())


def column(name: str) -> Column:
    """Return the column of that name: declared, else by unit suffix, else a plain number.

    Args:
        name: a column header, e.g. ``temp_wrist_c``.
    """
    if (known := _REGISTERED.get(name)) is not None:
        return known
    for suffix in sorted(SUFFIXES, key=len, reverse=True):
        if name.endswith(suffix) and len(name) > len(suffix):
            return replace(SUFFIXES[suffix], name=name, field=name[:-len(suffix)])
    return Column(name, name, "", 1.0, description="a number, as written")


def has_unit(name: str) -> bool:
    """Tell whether a column name is declared or ends with a unit suffix (a measured quantity)."""
    return name in _REGISTERED or any(name.endswith(s) and len(name) > len(s) for s in SUFFIXES)


def file_order(names: list[str] | tuple[str, ...]) -> list[str]:
    """Return column names in the order they are written: the built-in ones first, then as given."""
    built_in = [c.name for c in BUILT_IN]
    return sorted(names, key=lambda n: built_in.index(n) if n in built_in else len(built_in))


_EFFECT_READS: list[Callable[[], Iterable[str]]] = []


def set_effect_reads(source: Callable[[], Iterable[str]]) -> None:
    """Tell the readers how to learn the columns the registered effects read (``Effect.reads``).

    The effect registry calls it once, at import (the readers never import the effects); the
    source loads the installed plugins before answering.
    """
    _EFFECT_READS[:] = [source]


def read_by_effects() -> frozenset[str] | None:
    """Return the columns some registered effect reads, or None when no registry is loaded."""
    return frozenset(_EFFECT_READS[0]()) if _EFFECT_READS else None


def _split_unit(name: str) -> tuple[str, str]:
    """Return ``(stem, unit suffix)`` of a lower-case column name; the suffix "" without one."""
    for suffix in sorted(SUFFIXES, key=len, reverse=True):
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[:-len(suffix)], suffix
    return name, ""


def _one_edit(a: str, b: str) -> bool:
    """Tell whether ``a`` and ``b`` differ by one letter inserted, left out, changed or two swapped.

    A difference in digits only (``temp2`` and ``temp``: a second sensor) is not a typo.
    """
    if abs(len(a) - len(b)) > 1 or a == b or a.translate(_NO_DIGITS) == b.translate(_NO_DIGITS):
        return False
    if len(a) == len(b):
        diff = [k for k in range(len(a)) if a[k] != b[k]]
        return len(diff) == 1 or (len(diff) == 2 and diff[1] == diff[0] + 1
                                  and a[diff[0]] == b[diff[1]] and a[diff[1]] == b[diff[0]])
    short, long = sorted((a, b), key=len)
    return any(long[:k] + long[k + 1:] == short for k in range(len(long)))


_NO_DIGITS = str.maketrans("", "", "0123456789")


def meant_column(name: str, known: Iterable[str]) -> str | None:
    """Return the known column a per-sample column's name most likely misspells, or None.

    ``name`` means a known column ``k`` (and is not ``k``) when it is ``k`` in another case
    (``Sigma_um``), ``k``'s quantity with another unit suffix or none (``sigma_mm``, ``sigma``),
    or ``k`` with one letter off in a name part of 3 letters or more (``tmp_c``, ``sigam_um``);
    numbered names are others (``temp2_c`` is a second temperature, not ``temp_c``).

    Args:
        name: a column header the file carries.
        known: the column names the package and the effects read.
    """
    lower = name.lower()
    stem, suffix = _split_unit(lower)
    for k in known:
        if k == name:
            return None
    for k in known:
        k_stem, k_suffix = _split_unit(k.lower())
        if k.lower() == lower or (stem == k_stem and suffix != k_suffix):
            return k
        if (suffix in (k_suffix, "") and min(len(stem), len(k_stem)) >= 3
                and _one_edit(stem, k_stem)):
            return k
    return None


def check_names(path: Path | str, names: Sequence[str], optional: Sequence[str],
                problems: list[Problem]) -> str | None:
    """Refuse carried columns whose names misspell a known one; return a note on the others.

    A per-sample column the package does not read, named close to one it or a registered effect
    reads (:func:`meant_column`: ``sigma_mm``, ``Sigma_um``, ``tmp_c``), would be carried while
    the defaults stand in for the column meant: a problem naming the file, its header line, the
    column and the known name. The other carried columns that no effect reads are named in one
    note for the file (None if there is none, or no effect registry is loaded to say).

    Args:
        path: the file.
        names: its per-sample columns, by header name.
        optional: the file's optional columns (``group``, ``tool``, ``t_s`` ...).
        problems: where a misspelt name is added.
    """
    used = {c.name for c in BUILT_IN} | {POSE_COLUMN}
    if all(name in used or name in optional or name in _REGISTERED for name in names):
        return None  # every column is the package's: no need to load the installed plugins
    effects = read_by_effects()
    used |= set(effects or ())
    known = list(dict.fromkeys([*optional, *used, *_REGISTERED]))
    carried = []
    for name in names:
        if name in known:
            continue
        if (meant := meant_column(name, known)) is not None:
            what = column(meant)
            unit = f", in {what.unit}" if what.unit else ""
            problems.append(Problem(path, 1, name, f"close to '{meant}' ({what.description}{unit}), "
                                    "which is read; this one would be carried unused: rename it "
                                    f"'{meant}', or a column of its own another name"))
        elif name not in used:
            carried.append(name)
    if not carried or effects is None:
        return None
    listing = ", ".join(f"'{n}'" for n in carried)
    return (f"{path}: column{'s' if len(carried) > 1 else ''} {listing} carried, not used by any "
            "effect (discover tests it as a variable; an effect that reads it uses it)")
