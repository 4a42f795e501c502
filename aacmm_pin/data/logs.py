"""The campaign's values: the readout logs with their per-sample columns, the campaign, its noise.

A log (:class:`SpatLog`, :class:`LengthBarLog`, :class:`PointLog`) holds one row per readout: the
fixed fields of its file (ids, readouts, displacements, points) and, in ``columns``, every other
per-sample column by its file name in SI units (``t_s``, ``temp_c``, ``sigma_um``, a user's
``temp_wrist_c``; units from :mod:`aacmm_pin.data.columns`). ``log.t``, ``log.temp`` and ``PointLog.sigma``
read ``columns``. The readers and writers are :mod:`aacmm_pin.data.campaign`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from aacmm_pin.data.columns import BUILT_IN
from aacmm_pin.data.json_file import read_json
from aacmm_pin.data.problem_log import key_problems
from aacmm_pin.errors import CampaignFormatError, FileFormatError, Problem
from aacmm_pin.units import (
    INSTRUMENT_NOISE,
    SIGMA_LOCATION,
    SIGMA_POINT,
    SIGMA_RTEST,
    SIGMA_SOCKET,
    UM,
    noise_problem,
)

# Log field -> (dtype, shape after the row axis); None: any length.
_ARRAYS: dict[str, tuple[Any, tuple[int | None, ...]]] = {
    "location": (np.int64, ()), "placement": (np.int64, ()), "socket": (str, ()),
    "q": (float, (None,)), "displacement": (float, (3,)), "lines": (np.int64, ()),
    "group": (np.int64, ()), "point": (float, (3,)), "tool": (str, ())}
_FIELD_OF = {c.name: c.field for c in BUILT_IN}  # t_s -> t, for messages


class _Keep:
    """Default of a log's ``t``, ``temp``, ``sigma``: keep the column of ``columns``."""

    def __repr__(self) -> str:
        return "<keep>"


_KEEP: Any = _Keep()


MAX_NOISE_BYTES = 2**20
"""Largest campaign.json read, bytes (one is about 100 bytes)."""
NOISE_FILE = "campaign.json"
"""Optional file beside the CSVs stating the campaign's noise: ``{"noise_um": {"rtest": 2.0,
"location": 3.0, "point": 20.0, "socket": 2.0}}`` (any subset of the keys; the others keep the paper's
values), and/or its instrument, ``{"instrument": "motion capture"}`` (one of
:data:`aacmm_pin.units.INSTRUMENT_NOISE`: laser tracker, motion capture, R-Test), whose defaults the
kinds ``noise_um`` does not give take."""
NOISE_KINDS = ("rtest", "location", "point", "socket")
"""The kinds of measurement a campaign states a noise for (``campaign.json`` ``noise_um``)."""
NOISE_KEYS = ("instrument", "noise_um", "provenance")
"""The keys of ``campaign.json`` (``provenance``: what ``import-points`` read, not read back)."""
KIND_NAMES = {"rtest": "R-Test", "location": "R-Test nest", "point": "points",
              "socket": "bar sockets"}
"""How output names each kind of :data:`NOISE_KINDS`."""


def instrument_name(text: str) -> str | None:
    """Return the :data:`~aacmm_pin.units.INSTRUMENT_NOISE` key ``text`` names, or None.

    Case, ``-`` and ``_`` are ignored: ``Motion-Capture`` is ``motion capture``.
    """
    key = " ".join(text.lower().replace("_", " ").replace("-", " ").split())
    return "r-test" if key == "r test" else key if key in INSTRUMENT_NOISE else None


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
    instrument: str = ""
    """The instrument ``campaign.json`` names (a key of :data:`~aacmm_pin.units.INSTRUMENT_NOISE`),
    whose defaults these are where ``noise_um`` gives none; empty: none named."""

    @classmethod
    def of_instrument(cls, instrument: str, **given: float) -> StatedNoise:
        """Return the noise an instrument implies, the kinds in ``given`` (m) as given.

        The instrument's defaults: :data:`~aacmm_pin.units.INSTRUMENT_NOISE`.

        Raises:
            ValueError: for an instrument not in the table.
        """
        if (key := instrument_name(instrument)) is None:
            raise ValueError(f"instrument: choose from {', '.join(INSTRUMENT_NOISE)}, got "
                             f"{instrument!r}")
        return cls(**{**INSTRUMENT_NOISE[key], **given}, instrument=key)

    def describe(self, kinds: Iterable[str]) -> str:
        """Return the noise of these kinds (of :data:`NOISE_KINDS`) for output: ``points 100 um``."""
        return ", ".join(f"{KIND_NAMES[k]} {getattr(self, k) / UM:.4g} um" for k in kinds)

    def __post_init__(self) -> None:
        for name in NOISE_KINDS:
            if (why := noise_problem(getattr(self, name))) is not None:
                raise ValueError(f"{name}: {why}")

    def to_um(self) -> dict[str, float]:
        """Return the ``campaign.json`` form: kind -> noise, um."""
        return {"rtest": self.rtest / UM, "location": self.location / UM, "point": self.point / UM,
                "socket": self.socket / UM}


def read_noise(path: str | Path) -> StatedNoise:
    """Read a ``campaign.json``'s stated noise (see :data:`NOISE_FILE`).

    Raises:
        CampaignFormatError: if the file is not JSON, has a key not in :data:`NOISE_KEYS` (a
            misspelt one named with the key meant), or ``noise_um`` is not an object of positive
            numbers with the keys rtest, location, point, socket (each one optional).
    """
    path = Path(path)
    try:
        content = read_json(path, MAX_NOISE_BYTES, "a campaign.json")
    except FileFormatError as exc:
        raise CampaignFormatError(exc.problems) from None
    noise = content.get("noise_um", {}) if isinstance(content, dict) else None
    if not isinstance(noise, dict):
        raise CampaignFormatError([Problem(path, None, "noise_um", "an object {\"rtest\": 2.0, "
                                           "\"location\": 3.0, \"point\": 20.0} (um) expected")])
    instrument = content.get("instrument")
    kinds = NOISE_KINDS
    problems = [] if instrument is None or (isinstance(instrument, str) and instrument_name(
        instrument) is not None) else [Problem(path, None, "instrument", f"unknown instrument "
                                               f"{instrument!r}; choose from "
                                               f"{', '.join(INSTRUMENT_NOISE)}")]
    problems += key_problems(path, content, NOISE_KEYS)
    problems += key_problems(path, noise, kinds, "noise_um.")
    problems += [Problem(path, None, f"noise_um.{key}", f"a positive number (um) expected, got "
                         f"{value!r}") for key, value in noise.items() if key in kinds and not (
                             isinstance(value, (int, float)) and not isinstance(value, bool)
                             and math.isfinite(value) and value > 0)]
    problems += [Problem(path, None, f"noise_um.{key}", why) for key, value in noise.items()
                 if key in kinds and isinstance(value, (int, float)) and not isinstance(value, bool)
                 and math.isfinite(value) and value > 0
                 and (why := noise_problem(float(value) * UM)) is not None]
    if problems:
        raise CampaignFormatError(problems)
    given: dict[str, Any] = {key: float(value) * UM for key, value in noise.items()}
    if instrument is None:
        return StatedNoise(**given)
    return StatedNoise.of_instrument(instrument, **given)


_L = TypeVar("_L", bound="_Log")


class _Log:
    """Base of the logs: each field is a read-only array with one row per readout.

    ``columns`` holds the per-sample columns by file name (SI), each of shape (N,).
    """

    columns: dict[str, np.ndarray]
    lines: np.ndarray | None

    def _fill(self, values: dict[str, Any], columns: Mapping[str, Any] | None,
              **named: Any) -> None:
        """Set the fields from ``values`` and ``columns``, checking every shape.

        ``named``: columns by file name, which override those of ``columns`` (None removes one,
        :data:`_KEEP` keeps it).
        """
        kind = type(self).__name__
        n_rows = None
        for name, value in values.items():
            if value is None and name in ("lines", "tool"):
                object.__setattr__(self, name, None)
                continue
            dtype, trailing = _ARRAYS[name]
            arr = np.array(value, dtype=dtype)
            n_rows = len(arr) if n_rows is None and arr.ndim else n_rows
            object.__setattr__(self, name, _checked(arr, (n_rows, *trailing), f"{kind}.{name}"))
        merged = {str(k): v for k, v in (columns or {}).items() if v is not None}
        merged.update((k, v) for k, v in named.items() if v is not _KEEP)
        merged = {k: v for k, v in merged.items() if v is not None}
        out = {}
        for name, value in merged.items():
            label = f"{kind}.{_FIELD_OF[name]} ({name})" if name in _FIELD_OF else (
                f"{kind}.columns['{name}']")
            out[name] = _checked(np.array(value, dtype=float), (n_rows,), label)
        object.__setattr__(self, "columns", out)

    @property
    def t(self) -> np.ndarray | None:
        """Time of each readout, shape (N,), in s, or None (column ``t_s``)."""
        return self.columns.get("t_s")

    @property
    def temp(self) -> np.ndarray | None:
        """Arm temperature at each readout, shape (N,), in deg C, or None (column ``temp_c``)."""
        return self.columns.get("temp_c")

    def take(self: _L, rows: np.ndarray) -> _L:
        """Return the log with only these rows (a boolean mask or indices), columns included."""
        picked = {f.name: getattr(self, f.name) for f in fields(self)  # type: ignore[arg-type]
                  if f.name != "columns" and getattr(self, f.name) is not None}
        return replace(self, **{k: v[rows] for k, v in picked.items()},  # type: ignore[type-var]
                       columns={k: v[rows] for k, v in self.columns.items()})


def _checked(arr: np.ndarray, shape: tuple[int | None, ...], label: str) -> np.ndarray:
    """Return ``arr`` made read-only, or raise ValueError if its shape is not ``shape``."""
    if arr.ndim != len(shape) or any(s not in (None, a) for s, a in zip(shape, arr.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{label}: shape {want} expected, got {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False, init=False)
class SpatLog(_Log):
    """Readouts of a SPAT (single point articulation test) with the R-Test, one row per sample.

    Args (besides the fields): ``t``, ``temp``: the ``t_s`` and ``temp_c`` columns (s, deg C).
    """

    location: np.ndarray
    """R-Test location (nest) of each sample, shape (N,), integers >= 1."""
    q: np.ndarray
    """Encoder readouts, shape (N, n), in rad."""
    displacement: np.ndarray
    """Sphere displacement measured by the R-Test, shape (N, 3), in m (zero without R-Test)."""
    lines: np.ndarray | None = None
    """1-based line of each sample in spat.csv, shape (N,), or None when built in code."""
    columns: dict[str, np.ndarray] = field(default_factory=dict)
    """Per-sample columns by file name (``t_s``, ``temp_c``, ...), each shape (N,), in SI."""

    def __init__(self, location: Any, q: Any, displacement: Any, t: Any = _KEEP,
                 temp: Any = _KEEP, lines: Any = None, *, columns: Mapping[str, Any] | None = None) -> None:
        self._fill({"location": location, "q": q, "displacement": displacement, "lines": lines},
                   columns, t_s=t, temp_c=temp)


@dataclass(frozen=True, eq=False, init=False)
class LengthBarLog(_Log):
    """Readouts with the stylus in the sockets of a length bar, one row per readout.

    Args (besides the fields): ``t``, ``temp``: the ``t_s`` and ``temp_c`` columns (s, deg C).
    """

    placement: np.ndarray
    """Bar placement of each readout, shape (M,), integers >= 1."""
    socket: np.ndarray
    """Socket label of each readout (e.g. "A"), shape (M,), str."""
    q: np.ndarray
    """Encoder readouts, shape (M, n), in rad."""
    lines: np.ndarray | None = None
    """1-based line of each readout in lengthbar.csv, shape (M,), or None when built in code."""
    columns: dict[str, np.ndarray] = field(default_factory=dict)
    """Per-sample columns by file name (``t_s``, ``temp_c``, ...), each shape (M,), in SI."""

    def __init__(self, placement: Any, socket: Any, q: Any, t: Any = _KEEP, temp: Any = _KEEP,
                 lines: Any = None, *, columns: Mapping[str, Any] | None = None) -> None:
        self._fill({"placement": placement, "socket": socket, "q": q, "lines": lines}, columns,
                   t_s=t, temp_c=temp)


@dataclass(frozen=True, eq=False, init=False)
class PointLog(_Log):
    """Absolute positions of the tool point measured by an instrument, one row per pose.

    The instrument (a laser tracker station, a motion-capture system) has its own frame; its
    transform to the arm's base is unknown and identified, one per ``group``.

    Args (besides the fields): ``sigma``, ``t``, ``temp``: the ``sigma_um``, ``t_s`` and
    ``temp_c`` columns (m, s, deg C).
    """

    group: np.ndarray
    """Instrument set-up (frame) of each point, shape (N,), integers >= 1."""
    q: np.ndarray
    """Joint readouts, shape (N, n), in rad."""
    point: np.ndarray
    """Measured tool point in the instrument frame, shape (N, 3), in m."""
    lines: np.ndarray | None = None
    """1-based line of each pose in points.csv, shape (N,), or None when built in code."""
    tool: np.ndarray | None = None
    """Name of the tool each point measures (``Arm.tool_names``), shape (N,), str, or None (the
    arm's only tool)."""
    columns: dict[str, np.ndarray] = field(default_factory=dict)
    """Per-sample columns by file name (``sigma_um``, ``t_s``, ``temp_c``, ...), each shape (N,),
    in SI."""

    def __init__(self, group: Any, q: Any, point: Any, sigma: Any = _KEEP, t: Any = _KEEP,
                 temp: Any = _KEEP, lines: Any = None, tool: Any = None, *,
                 columns: Mapping[str, Any] | None = None) -> None:
        self._fill({"group": group, "q": q, "point": point, "lines": lines, "tool": tool},
                   columns, sigma_um=sigma, t_s=t, temp_c=temp)

    @property
    def sigma(self) -> np.ndarray | None:
        """Stated standard uncertainty of each point per coordinate, (N,), m, or None: ``sigma_um``."""
        return self.columns.get("sigma_um")


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
    notes: tuple[str, ...] = ()
    """What the reader noticed without refusing (rows that repeat others cell for cell), one line
    each with file and line; also emitted as :class:`~aacmm_pin.errors.CampaignWarning`."""

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
        return replace(self, spat=self.spat.take(keep),
                       locations={k: self.locations[k] for k in wanted})

    def with_spat(self, *, q: np.ndarray | None = None, displacement: np.ndarray | None = None,
                  t: np.ndarray | None = None, temp: np.ndarray | None = None) -> Campaign:
        """Return the campaign with these SPAT fields replaced (shapes and units as in SpatLog).

        Raises:
            ValueError: if the campaign has no SPAT or a shape does not fit.
        """
        if self.spat is None:
            raise ValueError("with_spat: the campaign has no SPAT")
        columns = dict(self.spat.columns)
        columns.update((name, v) for name, v in (("t_s", t), ("temp_c", temp)) if v is not None)
        spat = replace(self.spat, q=self.spat.q if q is None else q, columns=columns,
                       displacement=self.spat.displacement if displacement is None else displacement)
        return replace(self, spat=spat)


def noise_summary(campaign: Campaign, noise: StatedNoise | None = None, use_bar: bool = False
                  ) -> str:
    """Return the stated noise per coordinate of the campaign's kinds of data, and where from.

    E.g. ``points 100 um (campaign.json, motion capture)`` or ``R-Test 2 um, R-Test nest 3 um
    (defaults)``; points with a ``sigma_um`` column say so.

    Args:
        campaign: the campaign (its parts decide the kinds; its ``noise`` the values).
        noise: the noise to state instead of the campaign's (the command line's over it), or None.
        use_bar: the length bar is a calibration input (its sockets' noise counts).
    """
    stated = noise or campaign.noise or StatedNoise()
    kinds = ["rtest", "location"] if campaign.spat is not None else []
    if campaign.points is not None and campaign.points.sigma is None:
        kinds.append("point")
    if use_bar and campaign.lengthbar is not None:
        kinds.append("socket")
    source = ("defaults" if noise is None and campaign.noise is None else
              "as given" if noise is not None and noise != campaign.noise else
              f"{NOISE_FILE}, {stated.instrument}" if stated.instrument else NOISE_FILE)
    parts = [f"{stated.describe(kinds)} ({source})"] if kinds else []
    if campaign.points is not None and campaign.points.sigma is not None:
        parts.append("points: their sigma_um column")
    return ", ".join(parts)
