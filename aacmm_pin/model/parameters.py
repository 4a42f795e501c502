"""Parameters of a calibrated arm and their file, ``parameters.json``.

``parameters.json`` fully defines a calibrated arm together with the URDF it names::

    {"arm": "<urdf path or embedded name>", "units": "SI",
     "dh": {"dx21": 0.0, ...},                 # every error frame of the arm, m or rad
     "tool": [x, y, z],                        # tool vector in the last axis' frame, m
     # or, for an arm with several tools (a tree): "tools": {"tool_left": [x, y, z], ...}
     "base_to_mt": {"rotation_abc": [alpha0, beta0, gamma0], "translation": [x, y, z]},
     "encoder_maps": {"step_deg": 5.0, "axes": {"1": [72 values, rad], ...}},
     "extensions": {"compliance[A2]": [k], "thermal": [alpha], ...}}   # optional, SI

Extensions are terms of the effect library (:mod:`aacmm_pin.effects`) added by discovery. The
parameters carry each extension's term with its values (:attr:`Parameters.extension_terms`): a key
becomes its term once, where the parameters are made (read from the file, or built), through the
lookup the effect library registers (:data:`TERM_LOOKUP`; this layer cannot import it).

Missing maps mean zero error. The r-CS -> MT-CS transform is
``p_mt = D_b(beta0) D_a(alpha0) D_c(gamma0) p_r + translation`` (paper Eq. 4). Keys this file does
not know (e.g. ``effects`` in a simulator's truth) are kept in ``extra`` and written back.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import pinocchio as pin

from aacmm_pin.data.json_file import read_json
from aacmm_pin.data.problem_log import ProblemLog, close_match, key_problems
from aacmm_pin.errors import FileFormatError, Problem
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.encoder_map import DEFAULT_STEP_DEG, EncoderMap, step_problem
from aacmm_pin.units import MAX_PARAMETER

_IMPLAUSIBLE = f"beyond +-{MAX_PARAMETER:g} (m or rad): not a calibration value"


def rotation_abc(abc: np.ndarray) -> np.ndarray:
    """Return D_b(beta0) D_a(alpha0) D_c(gamma0) (Eq. 4) as a 3x3 matrix; abc in rad."""
    a, b, c = np.asarray(abc, dtype=float)
    rot: np.ndarray = pin.rpy.rotate("y", b) @ pin.rpy.rotate("x", a) @ pin.rpy.rotate("z", c)
    return rot


class ExtensionTerm(Protocol):
    """What the model layer knows of an extension's term (an :class:`aacmm_pin.effects.Term`)."""

    @property
    def key(self) -> str:
        """The term's key in ``parameters.json`` ``extensions``, e.g. ``compliance[A2]``."""

    @property
    def names(self) -> tuple[str, ...]:
        """Names of its parameters (one value each)."""


TERM_LOOKUP: list[Callable[[str], ExtensionTerm]] = []
"""The effect library's key -> term lookup (registered by :mod:`aacmm_pin.effects.registry`
when it is imported); it raises a ``KeyError`` for a key no registered effect knows."""


def _terms_of(keys: Any, known: dict[str, ExtensionTerm]) -> dict[str, ExtensionTerm]:
    """Return key -> term for ``keys``: the ``known`` terms, the others looked up (once, here).

    A key no registered effect knows has no term (the file's check names it,
    :func:`aacmm_pin.effects.check_extensions`; evaluating it raises the lookup's error).
    """
    out = {}
    for key in keys:
        if key in known:
            out[key] = known[key]
        elif TERM_LOOKUP:
            try:
                out[key] = TERM_LOOKUP[0](key)
            except KeyError:
                continue
    return out


@dataclass(frozen=True, eq=False)
class Parameters:
    """Every value that turns the nominal arm into a calibrated one (SI units)."""

    arm: str
    """The arm's URDF path or embedded name, as written in the file."""
    dh: dict[str, float]
    """Error frame name -> value (m or rad), one entry per error frame of the arm."""
    tool: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    """Tool vector (stylus centre in the last axis' frame), shape (3,), in m, absolute; with
    several tools, the first one's (taken from ``tools`` when not given)."""
    rotation_abc: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """X0 = (alpha0, beta0, gamma0): r-CS -> MT-CS rotation angles (Eq. 4), shape (3,), in rad."""
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """r-CS origin in the MT-CS, shape (3,), in m."""
    encoder_maps: dict[int, EncoderMap] = field(default_factory=dict)
    """Axis number (1-based) -> encoder error map; axes not listed have zero error."""
    step_deg: float = DEFAULT_STEP_DEG
    """Node step of the maps, in degrees."""
    extensions: dict[str, np.ndarray] = field(default_factory=dict)
    """Effect-library term key (e.g. ``compliance[A2]``) -> its parameter values (SI)."""
    extra: dict[str, Any] = field(default_factory=dict)
    """Top-level keys of the file that this class does not interpret, kept as read."""
    tools: dict[str, np.ndarray] = field(default_factory=dict)
    """Tool joint name -> tool vector (in its parent's frame), shape (3,), in m, for arms with
    several tools (every tool, in the arm's tool order); empty for a single-tool arm (``tool``)."""
    extension_terms: dict[str, ExtensionTerm] = field(default_factory=dict, repr=False)
    """Extension key -> its term (an :class:`aacmm_pin.effects.Term`), for every key of
    ``extensions`` that a registered effect knows: given (the terms a fit estimated, or of the
    parameters replaced) or looked up when the parameters are made, never on evaluation."""

    def __post_init__(self) -> None:
        tools = {str(k): np.array(v, dtype=float).reshape(-1) for k, v in self.tools.items()}
        if bad := [k for k, v in tools.items() if v.shape != (3,)]:
            raise ValueError(f"tools: needs 3 values per tool, not for {bad}")
        object.__setattr__(self, "tools", tools)
        if tools and np.all(np.isnan(np.asarray(self.tool, dtype=float))):
            object.__setattr__(self, "tool", next(iter(tools.values())).copy())
        elif tools and not np.array_equal(np.asarray(self.tool, dtype=float).reshape(-1),
                                          next(iter(tools.values()))):
            raise ValueError("tool: differs from the first entry of tools (give one of them, or "
                             "both equal)")
        if np.any(np.isnan(np.asarray(self.tool, dtype=float))):
            raise ValueError("tool: needs 3 values (or give tools)")
        for name in ("tool", "rotation_abc", "translation"):
            value = np.array(getattr(self, name), dtype=float).reshape(-1)
            if value.shape != (3,):
                raise ValueError(f"{name}: needs 3 values, got {value.size}")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "dh", {k: float(v) for k, v in self.dh.items()})
        object.__setattr__(self, "extensions", {k: np.array(v, dtype=float).reshape(-1)
                                                for k, v in self.extensions.items()})
        object.__setattr__(self, "extension_terms",
                           _terms_of(self.extensions, dict(self.extension_terms)))
        for axis, emap in self.encoder_maps.items():
            if emap.step_deg != self.step_deg:
                raise ValueError(f"encoder_maps: axis {axis} has step {emap.step_deg} deg, "
                                 f"the parameters {self.step_deg} deg")

    @classmethod
    def nominal(cls, arm: Arm, step_deg: float = DEFAULT_STEP_DEG) -> Parameters:
        """Return the values the arm's URDF holds, with no maps and identity X0."""
        return cls(arm=arm.name, dh=arm.nominal_errors, tool=arm.nominal_tool, step_deg=step_deg,
                   tools=dict(arm.nominal_tools) if arm.n_tools > 1 else {})

    def replace(self, **changes: Any) -> Parameters:
        """Return a copy with some fields changed.

        Changing ``tools`` alone sets ``tool`` to its first entry; changing ``tool`` alone (with
        several tools) changes the first entry of ``tools``.
        """
        if "tools" in changes and "tool" not in changes:
            changes["tool"] = np.full(3, np.nan)
        elif "tool" in changes and "tools" not in changes and self.tools:
            first = next(iter(self.tools))
            changes["tools"] = {**self.tools, first: changes["tool"]}
        return replace(self, **changes)

    def tool_vectors(self, arm: Arm) -> dict[str, np.ndarray]:
        """Return every tool's vector by tool joint name, in the arm's tool order, m.

        Raises:
            ValueError: if these parameters do not hold the arm's tools.
        """
        if not self.tools and arm.n_tools == 1:
            return {arm.tool_joints[0]: self.tool}
        if set(self.tools) != set(arm.tool_joints) or (not self.tools and arm.n_tools > 1):
            raise ValueError(f"tools: the arm's tools are {', '.join(arm.tool_joints)}; the "
                             f"parameters hold {', '.join(self.tools) or 'one tool vector'}")
        return {name: self.tools[name] for name in arm.tool_joints}

    def term_values(self) -> list[tuple[ExtensionTerm, np.ndarray]]:
        """Return every extension's term with its values, shape (k,) each, SI, in key order.

        Raises:
            KeyError: (the effect library's error) for a key no registered effect knows.
        """
        return [(self.extension_terms[k] if k in self.extension_terms else _looked_up(k), v)
                for k, v in self.extensions.items()]

    def rotation(self) -> np.ndarray:
        """Return the r-CS -> MT-CS rotation matrix, shape (3, 3)."""
        return rotation_abc(self.rotation_abc)

    def map(self, axis: int) -> EncoderMap:
        """Return the map of an axis (1-based), a zero map where none is set."""
        return self.encoder_maps.get(axis) or EncoderMap.zero(self.step_deg)

    def to_dict(self) -> dict[str, Any]:
        """Return the ``parameters.json`` content (plain JSON types)."""
        return {
            "arm": self.arm,
            "units": "SI",
            "dh": dict(self.dh),
            **({"tools": {k: v.tolist() for k, v in self.tools.items()}} if len(self.tools) > 1
               else {"tool": self.tool.tolist()}),
            "base_to_mt": {"rotation_abc": self.rotation_abc.tolist(),
                           "translation": self.translation.tolist()},
            "encoder_maps": {"step_deg": self.step_deg,
                             "axes": {str(k): self.encoder_maps[k].values.tolist()
                                      for k in sorted(self.encoder_maps)}},
            **({"extensions": {k: v.tolist() for k, v in self.extensions.items()}}
               if self.extensions else {}),
            **self.extra,
        }


def _looked_up(key: str) -> ExtensionTerm:
    """Return the term of a key unknown when the parameters were made (or raise its error)."""
    if not TERM_LOOKUP:
        raise KeyError(f"{key!r}: no effect library loaded (import aacmm_pin.effects)")
    return TERM_LOOKUP[0](key)


_KNOWN = ("arm", "units", "dh", "tool", "tools", "base_to_mt", "encoder_maps", "extensions")
_WRITTEN = ("plugins", "effects")
"""Keys the package writes beside :data:`_KNOWN`, carried in ``extra`` (the effects' plugins, a
simulation's hidden effects)."""


def parameters_from_dict(data: Any, path: Path | str = "<parameters>") -> Parameters:
    """Build parameters from ``parameters.json`` content, checking every field.

    Raises:
        FileFormatError: listing every problem, each with the JSON path of the bad field.
    """
    problems: list[Problem] = []
    log = ProblemLog(problems, path, unit="keys")

    def bad(key: str, reason: str) -> None:
        log.add(None, key, reason)

    if not isinstance(data, dict):
        raise FileFormatError([Problem(path, None, None, "the top level must be a JSON object")])
    for key in ("arm", "dh"):
        if key not in data:
            bad(key, "missing")
    if "tool" not in data and "tools" not in data:
        bad("tool", "missing (or give 'tools': {tool joint: [x, y, z]} for several tools)")
    if data.get("units", "SI") != "SI":
        bad("units", f"must be 'SI', got {data.get('units')!r}")
    dh = _dh(data, bad)
    base = data.get("base_to_mt", {})
    if not isinstance(base, dict):
        bad("base_to_mt", "must be an object")
        base = {}
    rot = _vector(base.get("rotation_abc", [0, 0, 0]), "base_to_mt.rotation_abc", 3, bad)
    trans = _vector(base.get("translation", [0, 0, 0]), "base_to_mt.translation", 3, bad)
    tool, tools = _tools(data, bad)
    step, maps = _maps(data.get("encoder_maps") or {}, bad)
    extensions = _extensions(data.get("extensions") or {}, bad)
    for problem in key_problems(path, data, (*_KNOWN, *_WRITTEN), strict=False):
        bad(str(problem.column), problem.reason)  # a misspelt key; others are carried (extra)
    log.close()
    if problems:
        raise FileFormatError(problems)
    return Parameters(arm=str(data["arm"]), dh=dh, tool=tool, tools=tools, rotation_abc=rot,
                      translation=trans, encoder_maps=maps, extensions=extensions,
                      step_deg=float(step) if step is not None else DEFAULT_STEP_DEG,
                      extra={k: v for k, v in data.items() if k not in _KNOWN})


_Bad = Callable[[str, str], None]
"""Reports a bad field: ``bad(JSON path, reason)``."""


def _vector(value: Any, key: str, n: int, bad: _Bad) -> np.ndarray:
    """Return ``value`` as n finite, plausible numbers, or zeros with the problem reported."""
    if not _numbers(value):  # numpy would take "0.001" and True for numbers
        bad(key, f"needs a list of {n} numbers, got {value!r}")
        return np.zeros(n)
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        bad(key, f"needs {n} numbers, got {value!r}")
        return np.zeros(n)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        bad(key, f"needs {n} finite numbers, got {value!r}")
        return np.zeros(n)
    if np.any(np.abs(arr) > MAX_PARAMETER):
        bad(key, f"{value!r} is {_IMPLAUSIBLE}")
        return np.zeros(n)
    return arr


def _dh(data: dict[str, Any], bad: _Bad) -> dict[str, float]:
    """Return the checked ``dh`` entries (m or rad); report bad ones."""
    dh: dict[str, float] = {}
    if isinstance(data.get("dh"), dict):
        for name, value in data["dh"].items():
            if not (isinstance(value, (int, float)) and not isinstance(value, bool)
                    and np.isfinite(value)):
                bad(f"dh.{name}", f"must be a finite number, got {value!r}")
            elif abs(value) > MAX_PARAMETER:
                bad(f"dh.{name}", f"{value!r} is {_IMPLAUSIBLE}")
            else:
                dh[name] = float(value)
    elif "dh" in data:
        bad("dh", "must be an object of name: value")
    return dh


def _tools(data: dict[str, Any], bad: _Bad) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Return the tool vector (3,) and the tools by joint name (m); report bad ones."""
    tools: dict[str, np.ndarray] = {}
    if isinstance(data.get("tools", {}), dict):
        tools = {str(k): _vector(v, f"tools.{k}", 3, bad) for k, v in data.get("tools", {}).items()}
    else:
        bad("tools", "must be an object of tool joint: [x, y, z]")
    tool = (_vector(data["tool"], "tool", 3, bad) if "tool" in data
            else next(iter(tools.values())) if tools else np.zeros(3))
    if tools and "tool" in data and not np.array_equal(tool, next(iter(tools.values()))):
        bad("tool", "differs from the first entry of 'tools' (give one of them)")
    return tool, tools


def _maps(maps_data: Any, bad: _Bad) -> tuple[Any, dict[int, EncoderMap]]:
    """Return the maps' node step (deg, as written) and the checked maps by axis; report bad ones."""
    step = maps_data.get("step_deg", DEFAULT_STEP_DEG) if isinstance(maps_data, dict) else None
    maps: dict[int, EncoderMap] = {}
    axes_data = maps_data.get("axes") or {} if isinstance(maps_data, dict) else {}
    if not isinstance(axes_data, dict):
        bad("encoder_maps.axes", "must be an object of axis: [values]")
        axes_data = {}
    if not isinstance(step, (int, float)) or step <= 0 or 360.0 / step != round(360.0 / step):
        bad("encoder_maps.step_deg", f"must divide 360, got {step!r}")
    elif (why := step_problem(step)) is not None:
        bad("encoder_maps.step_deg", why)
    else:
        for key, values in axes_data.items():
            if not _numbers(values):
                bad(f"encoder_maps.axes.{key}", f"needs a list of numbers, got {values!r:.80}")
                continue
            try:
                maps[int(key)] = EncoderMap(np.asarray(values, dtype=float), float(step))
            except (TypeError, ValueError) as exc:
                bad(f"encoder_maps.axes.{key}", str(exc))
                continue
            if np.any(np.abs(maps[int(key)].values) > MAX_PARAMETER):
                bad(f"encoder_maps.axes.{key}", f"a value {_IMPLAUSIBLE}")
    return step, maps


def _numbers(value: Any) -> bool:
    """Return whether ``value`` is a JSON list of numbers (not strings, booleans or lists)."""
    return isinstance(value, list) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)


def _extensions(data: Any, bad: _Bad) -> dict[str, np.ndarray]:
    """Return the checked ``extensions`` entries; report bad ones through ``bad(key, reason)``.

    Only the form is checked here (a list of finite, plausible numbers per key); whether a key is a
    term of a registered effect, with that many values, is the effect library's
    (:func:`aacmm_pin.effects.check_extensions`).
    """
    if not isinstance(data, dict):
        bad("extensions", "must be an object of term: [values]")
        return {}
    out = {}
    for key, values in data.items():
        try:
            arr = np.asarray(values if _numbers(values) else [], dtype=float).reshape(-1)
        except (TypeError, ValueError):
            arr = np.zeros(0)
        if arr.size == 0 or not np.all(np.isfinite(arr)):
            bad(f"extensions.{key}", f"needs a list of finite numbers, got {values!r}")
            continue
        if np.any(np.abs(arr) > MAX_PARAMETER):
            bad(f"extensions.{key}", f"{values!r} is {_IMPLAUSIBLE}")
            continue
        out[key] = arr
    return out


MAX_PARAMETERS_BYTES = 16 * 2**20
"""Largest parameters.json read, bytes."""
MAX_JSON_DEPTH = 8
"""Deepest nesting of objects and lists in parameters.json (it needs 4)."""


def _depth(value: Any) -> int:
    """Return the nesting depth of JSON ``value`` (a scalar: 0), without recursion."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        item, level = stack.pop()
        if isinstance(item, (dict, list)):
            deepest = max(deepest, level + 1)
            if level + 1 > MAX_JSON_DEPTH:
                break
            stack.extend((v, level + 1) for v in (item.values() if isinstance(item, dict) else item))
    return deepest


def read_parameters(path: str | Path) -> Parameters:
    """Read ``parameters.json`` (or a calibration folder holding one).

    A relative ``arm`` path (a ``.urdf`` name or one with a folder in it) is taken relative to the
    file's folder, never the current directory: a calibration folder names its own
    ``calibrated.urdf``, and a missing one is an error naming that path, not another arm's URDF
    that happens to be in the current directory. Embedded arm names (``aacmm7``) stay names.

    Raises:
        FileFormatError: for unreadable JSON (with line and column) or bad fields.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "parameters.json"
    data = read_json(path, MAX_PARAMETERS_BYTES, "a parameters file")
    if _depth(data) > MAX_JSON_DEPTH:
        raise FileFormatError([Problem(path, None, None, f"JSON nested deeper than "
                                       f"{MAX_JSON_DEPTH} levels: not a parameters file")])
    params = parameters_from_dict(data, path)
    is_path = params.arm.endswith(".urdf") or "/" in params.arm or os.sep in params.arm
    if is_path and not Path(params.arm).is_absolute():
        params = params.replace(arm=str(path.parent / params.arm))
    return params


def write_parameters(params: Parameters, path: str | Path) -> None:
    """Write ``parameters.json`` (indented, full float precision)."""
    Path(path).write_text(json.dumps(params.to_dict(), indent=2) + "\n")


def check_against_arm(params: Parameters, arm: Arm) -> None:
    """Check that the parameters name exactly the arm's error frames, tools and axes.

    Raises:
        FileFormatError: naming the unknown or missing parameters.
    """
    problems: list[Problem] = []
    log = ProblemLog(problems, params.arm, unit="keys")
    known = set(arm.error_names)
    for n in (unknown := [n for n in params.dh if n not in known]):
        meant = close_match(n, arm.error_names)
        listing = (f"; did you mean {meant}?" if meant else "") + (
            f" (error frames: {', '.join(arm.error_names)})" if n == unknown[0] else "")
        log.add(None, f"dh.{n}", f"not an error frame of the arm{listing}", kind="unknown")
    for n in arm.error_names:
        if n not in params.dh:
            log.add(None, f"dh.{n}", "missing", kind="missing")
    log.close()
    if params.tools and set(params.tools) != set(arm.tool_joints):
        problems.append(Problem(params.arm, None, "tools", f"the arm's tools are "
                                f"{', '.join(arm.tool_joints)}; got {', '.join(params.tools)}"))
    elif not params.tools and arm.n_tools > 1:
        problems.append(Problem(params.arm, None, "tool", f"the arm has {arm.n_tools} tools "
                                f"({', '.join(arm.tool_joints)}): give 'tools'"))
    problems += [Problem(params.arm, None, f"encoder_maps.axes.{k}",
                         f"the arm has axes 1..{arm.n_axes}")
                 for k in params.encoder_maps if not 1 <= k <= arm.n_axes]
    problems += [Problem(params.arm, None, f"encoder_maps.axes.{k}",
                         f"A{k} ({arm.axis_names[k - 1]}) is a coupled joint: it has no encoder, "
                         "so no map") for k in params.encoder_maps
                 if 1 <= k <= arm.n_axes and arm.coupled[k - 1]]
    if problems:
        raise FileFormatError(problems)
