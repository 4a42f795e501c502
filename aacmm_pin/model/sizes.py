r"""Plausible sizes of an arm's errors: the scale of every parameter's prior, from the arm.

A plausible size is how large an error of one parameter may be on this arm. The sizes scale the
identification's Jacobian columns (a direction is *determined* when a plausible change along it
moves the data by more than twice the noise, :mod:`aacmm_pin.fit.identifiability`) and are the
standard deviations of the Gaussian priors of discovery's held-out scores, of the linearised length
bar and of measurement planning. An AACMM's errors are about 0.1 mm and 0.02 deg; a cable-driven
robot's are ten to a hundred times larger, and priors of an AACMM's size would shrink its real
errors to nothing.

**The file.** An arm's sizes live in a JSON file beside its URDF, named after it
(``wam7.urdf`` -> ``wam7.sizes.json``), all values SI (m, rad, rad per N m, ...)::

    {"units": "SI",
     "source": "where the sizes come from (physics, makers' figures), in words",
     "dh_angle": 3.5e-4, "dh_length": 1e-4, "tool": 1e-4, "map_node": 1e-4,
     "x0_angle": 1e-2, "x0_translation": 1e-2,
     "effects": {"compliance": 1e-5, "backlash": 4.8e-5, "crosstalk": 4.8e-5,
                 "encoder": 9.7e-5, "thermal": 2.3e-5}}

**Couplings.** The sizes file is the arm's sidecar: besides sizes, it may state coupled joints that
a URDF ``<mimic>`` cannot (a sum of several joints), ``"couplings": {"T4": {"of": {"T2": -1,
"T3": -1}, "offset": 0.0}}`` for :math:`q_{T4} = -(q_{T2} + q_{T3})` (joint names, offset in rad;
:mod:`aacmm_pin.data.couplings`, checked against the URDF by :class:`aacmm_pin.model.arm.Arm`).

Every key is optional: a missing one takes the default arm's value (:data:`DEFAULT`), and an arm
without a file has exactly the default sizes. ``effects`` maps an effect name of the library
(:mod:`aacmm_pin.effects`) to the size of each of its terms' parameters; an effect not listed
keeps its terms' own ``plausible`` sizes (:meth:`aacmm_pin.effects.Term.sizes`). A calibration
folder carries its arm's sizes beside
``calibrated.urdf`` (``calibrated.sizes.json``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import MappingProxyType
from typing import Any

from aacmm_pin.data.json_file import read_json
from aacmm_pin.data.problem_log import ProblemLog, close_match
from aacmm_pin.errors import FileFormatError, Problem
from aacmm_pin.units import ARCSEC

MAX_SIZES_BYTES = 2**20
"""Largest sizes file read, bytes (one is about 1 kB)."""
SUFFIX = ".sizes.json"
"""A URDF's sizes file is the URDF's path with this suffix instead of ``.urdf``."""
DEFAULT_EFFECTS: Mapping[str, float] = MappingProxyType({
    "compliance": 1e-5, "lateral_compliance": 1e-5, "backlash": 10 * ARCSEC,
    "crosstalk": 10 * ARCSEC, "encoder": 20 * ARCSEC, "thermal": 2.3e-5})
"""The default arm's size of each effect's parameters, SI: compliance 1e-5 rad/(N m) (20 arcsec at
10 N m), lateral compliance the same about each lateral axis, backlash and crosstalk 10 arcsec,
encoder harmonics 20 arcsec, thermal expansion 2.3e-5 /K (aluminium)."""


@dataclass(frozen=True, eq=True)
class Sizes:
    """Plausible sizes of an arm's parameters (SI); the defaults are the default AACMM's."""

    dh_angle: float = 3.5e-4
    """DH angle errors (rotational error frames), rad (0.02 deg)."""
    dh_length: float = 1e-4
    """DH length errors (translational error frames), m (0.1 mm)."""
    tool: float = 1e-4
    """Each tool vector coordinate, m."""
    map_node: float = 1e-4
    """Each encoder map node, rad (about 20 arcsec)."""
    x0_angle: float = 1e-2
    """Each angle of X0 (r-CS -> MT-CS or instrument frame rotation), rad."""
    x0_translation: float = 1e-2
    """Each coordinate of the r-CS -> MT-CS (instrument) translation, m."""
    effects: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_EFFECTS))
    """Effect name -> size of each parameter of its terms, SI; the built-in effects not given keep
    the default arm's (:data:`DEFAULT_EFFECTS`), other effects not given their terms' own size."""
    source: str = "default AACMM sizes (aacmm_pin.model.sizes.DEFAULT)"
    """Where the sizes come from, in words."""
    couplings: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Coupled joint name -> ``{"of": {joint name: coefficient}, "offset": rad}`` (the file's
    ``couplings`` block; see the module)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "effects", {**DEFAULT_EFFECTS, **self.effects})

    def to_dict(self) -> dict[str, Any]:
        """Return the sizes file's content (plain JSON types, SI)."""
        out: dict[str, Any] = {"units": "SI", "source": self.source}
        out |= {f.name: getattr(self, f.name) for f in fields(self)
                if f.name not in ("effects", "source", "couplings")}
        out["effects"] = dict(self.effects)
        if self.couplings:
            out["couplings"] = {k: dict(v) for k, v in self.couplings.items()}
        return out


DEFAULT = Sizes()
"""The default arm's sizes (``urdf/aacmm7.urdf`` has no sizes file)."""
_NUMBERS = tuple(f.name for f in fields(Sizes) if f.name not in ("effects", "source", "couplings"))


def sizes_path(urdf: str | Path) -> Path:
    """Return the sizes file that belongs to a URDF path (``x.urdf`` -> ``x.sizes.json``)."""
    path = Path(urdf)
    return path.with_name(path.name.removesuffix(".urdf") + SUFFIX)


def sizes_from_dict(data: Any, path: Path | str = "<sizes>") -> Sizes:
    """Build sizes from a sizes file's content, checking every key.

    Raises:
        FileFormatError: listing every problem, each naming the file and the key.
    """
    problems: list[Problem] = []

    log = ProblemLog(problems, path, unit="keys")

    def bad(key: str, reason: str) -> None:
        log.add(None, key, reason)

    def positive(value: Any, key: str) -> float | None:
        ok = (isinstance(value, (int, float)) and not isinstance(value, bool)
              and math.isfinite(value) and value > 0)
        if not ok:
            bad(key, f"must be a positive finite number (SI), got {value!r}")
            return None
        return float(value)

    if not isinstance(data, dict):
        raise FileFormatError([Problem(path, None, None, "the top level must be a JSON object")])
    values: dict[str, Any] = {}
    for key, value in data.items():
        if key == "units":
            if value != "SI":
                bad("units", f"must be 'SI', got {value!r}")
        elif key == "source":
            if not isinstance(value, str):
                bad("source", f"must be a string, got {value!r}")
            else:
                values["source"] = value
        elif key == "effects":
            if not isinstance(value, dict):
                bad("effects", "must be an object of effect name: size")
                continue
            effects = {}
            for name, size in value.items():
                number = positive(size, f"effects.{name}")
                if number is not None:
                    effects[str(name)] = number
            values["effects"] = effects
        elif key == "couplings":
            values["couplings"] = _couplings(value, bad)
        elif key in _NUMBERS:
            number = positive(value, key)
            if number is not None:
                values[key] = number
        else:
            meant = close_match(key, ("units", "source", *_NUMBERS, "effects", "couplings"))
            log.add(None, key, f"unknown key{f'; did you mean {meant}?' if meant else ''}; the "
                               f"keys are units, source, {', '.join(_NUMBERS)}, effects, couplings",
                    kind="unknown")
    log.close()
    if problems:
        raise FileFormatError(problems)
    return Sizes(**values)


def _couplings(value: Any, bad: Callable[[str, str], None]) -> dict[str, dict[str, Any]]:
    """Check a ``couplings`` block's form (names are checked by the arm); return the good entries."""
    out: dict[str, dict[str, Any]] = {}
    if not isinstance(value, dict):
        bad("couplings", 'must be an object of joint: {"of": {joint: coefficient}, "offset": rad}')
        return out

    def finite(x: Any) -> bool:
        return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

    for joint, entry in value.items():
        where = f"couplings.{joint}"
        if not isinstance(entry, dict) or not isinstance(entry.get("of"), dict) or not entry["of"]:
            bad(where, 'must be {"of": {joint: coefficient, ...}, "offset": rad}')
            continue
        if extra := sorted(set(entry) - {"of", "offset"}):
            bad(f"{where}.{extra[0]}", "unknown key; a coupling has of and offset")
            continue
        terms = entry["of"]
        offset = entry.get("offset", 0.0)
        wrong = [k for k, a in terms.items() if not finite(a)]
        if wrong:
            bad(f"{where}.of.{wrong[0]}", f"must be a finite number, got {terms[wrong[0]]!r}")
        elif not finite(offset):
            bad(f"{where}.offset", f"must be a finite number of rad, got {offset!r}")
        else:
            out[str(joint)] = {"of": {str(k): float(a) for k, a in terms.items()},
                               "offset": float(offset)}
    return out


def read_sizes(path: str | Path) -> Sizes:
    """Read a sizes file (see module doc).

    Raises:
        FileFormatError: for a missing file, invalid JSON (with line and column) or bad keys.
    """
    path = Path(path)
    return sizes_from_dict(read_json(path, MAX_SIZES_BYTES, "a sizes file"), path)


def sizes_file(urdf: str | Path) -> Path | None:
    """Return the sizes file an arm's URDF uses, or None when it has none (the defaults)."""
    path = sizes_path(urdf)
    return path if path.is_file() else None


def sizes_label(urdf: str | Path) -> str:
    """Return which sizes an arm uses, for a line or a report: the file's path or the defaults."""
    path = sizes_file(urdf)
    return str(path) if path is not None else "built-in defaults"


def sizes_of_urdf(urdf: str | Path) -> Sizes:
    """Return the sizes of the arm of a URDF: its sizes file if there is one, else the defaults."""
    path = sizes_path(urdf)
    return read_sizes(path) if path.is_file() else DEFAULT


def write_sizes(sizes: Sizes, path: str | Path) -> None:
    """Write a sizes file (indented, full float precision)."""
    Path(path).write_text(json.dumps(sizes.to_dict(), indent=2) + "\n")
