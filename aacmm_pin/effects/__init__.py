r"""The effect library: named extensions of the arm model, for :func:`aacmm_pin.discover`.

An *effect* (:class:`Effect`) is a physical cause of measurement error with a plain-language
description; it proposes *terms* (:class:`Term`), one per axis where the effect is per-axis, each
with a few parameters, their plausible sizes and the Jacobian of the model with respect to them.
Terms are linear in their parameters and act in one of four ways (:attr:`Term.kind`):

* ``"angle"``: an error of the true angle of one axis,
  :math:`\Delta\theta_n = B(\text{samples}) \, v` with a basis B of shape (N, k);
* ``"scale"``: a uniform scale of every length of the arm (r-CS positions times
  :math:`1 + B v`);
* ``"measurement"``: a change of the *measured* point (R-Test), not of the arm;
* ``"map"``: the paper's encoder error map of one axis (its nodes are the parameters).

Built-in effects: ``encoder`` (map or low-order harmonics), ``compliance`` (gravity torque from the
URDF inertias by Pinocchio's generalized gravity), ``thermal`` (``temp_c``), ``backlash`` (direction
of motion), ``crosstalk`` (angle of a neighbouring axis), ``rtest`` (the sphere moving in its seat)
and ``tool`` (in every start model). Register your own with :func:`register_effect` (and
:func:`register_term` so that ``parameters.json`` can name its terms).

Calibrated values of the terms live in ``Parameters.extensions`` (``parameters.json``
``"extensions": {"compliance[A2]": [k], ...}``, SI units) and are applied by
:func:`aacmm_pin.stylus_positions` and :func:`aacmm_pin.predict`.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from enum import Enum
from functools import partial
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from aacmm_pin.errors import AacmmError
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.samples import Samples
from aacmm_pin.units import ARCSEC, REFERENCE_TEMPERATURE_C

if TYPE_CHECKING:
    from aacmm_pin.model.parameters import Parameters


class Kind(str, Enum):
    """How a term acts on the model (see module doc); equal to its string value."""

    ANGLE = "angle"
    """An error of the true angle of one axis."""
    SCALE = "scale"
    """A uniform scale of every length of the arm."""
    MEASUREMENT = "measurement"
    """A change of the measured point (R-Test), not of the arm."""
    MAP = "map"
    """The encoder error map of one axis (its nodes are the parameters, in the maps)."""


class StylusDerivatives(Protocol):
    """What :func:`term_columns` needs of :class:`aacmm_pin.model.kinematics.StylusJacobians`."""

    @property
    def position(self) -> np.ndarray:
        """Stylus centres, shape (N, 3), m."""

    @property
    def angles(self) -> np.ndarray:
        """d(position)/d(true joint angle), shape (N, 3, n_axes), m/rad."""


@dataclass(frozen=True, eq=False)
class Term:
    """One extension of the model: a few parameters, linear in their effect (see module doc).

    Terms are equal when their keys are. Build them with the constructors below (e.g.
    :func:`compliance`) or your own; ``basis_of`` and ``variable_of`` should be module-level
    functions or ``functools.partial`` of them, so that calibrations pickle.
    """

    key: str
    """Unique name, e.g. ``compliance[A2]`` (the key in ``parameters.json``)."""
    effect: str
    """Name of the effect this term belongs to."""
    kind: Kind
    """How the term acts: :class:`Kind` (a plain ``"angle"`` etc. is converted)."""
    names: tuple[str, ...]
    """Names of the parameters, e.g. ``compliance[A2].k``."""
    plausible: tuple[float, ...]
    """Plausible size of every parameter on the default arm (SI): the scale of its prior, unless
    the arm's sizes name the term's effect (:meth:`aacmm_pin.model.sizes.Sizes.term`)."""
    description: str
    """Plain-language description."""
    basis_of: Callable[[Samples], np.ndarray] = field(repr=False)
    """Samples -> basis: (N, k) for angle and scale terms, (N, 3, k) for measurement terms."""
    variable_of: Callable[[Samples], tuple[str, np.ndarray]] = field(repr=False)
    """Samples -> (label with unit, per-sample values) of the term's variable (figures)."""
    axes: tuple[int, ...] = ()
    """Axes the term acts on (empty for arm-wide terms); an angle term changes ``axes[0]``."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", Kind(self.kind))
        _MADE[self.key] = self  # any term made in this process can be found by its key

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Term) and other.key == self.key

    def __hash__(self) -> int:
        return hash(self.key)

    @property
    def axis(self) -> int:
        """The axis whose angle an ``angle`` or ``map`` term changes (1-based)."""
        return self.axes[0]

    def basis(self, samples: Samples) -> np.ndarray:
        """Return the basis on these samples (see :attr:`basis_of`)."""
        return self.basis_of(samples)

    def variable(self, samples: Samples) -> tuple[str, np.ndarray]:
        """Return the label and per-sample values of the term's variable."""
        return self.variable_of(samples)

    def describe(self) -> str:
        """Return the plain-language description."""
        return self.description


def _readout(axis: int, samples: Samples) -> tuple[str, np.ndarray]:
    return f"A{axis} readout (deg)", np.degrees(samples.q[:, axis - 1])


def _no_basis(samples: Samples) -> np.ndarray:
    return np.zeros((samples.n, 0))


def _harmonics(axis: int, order: int, samples: Samples) -> np.ndarray:
    theta = samples.q[:, axis - 1]
    return np.column_stack([f(h * theta) for h in range(1, order + 1) for f in (np.cos, np.sin)])


def _gravity(axis: int, samples: Samples) -> np.ndarray:
    return samples.gravity[:, axis - 1:axis]


def _gravity_variable(axis: int, samples: Samples) -> tuple[str, np.ndarray]:
    return f"gravity torque on A{axis} (N m)", samples.gravity[:, axis - 1]


def _temperature(samples: Samples) -> np.ndarray:
    if samples.temp is None:
        raise AacmmError("the model has a thermal term: the readouts need a temp_c column")
    return (samples.temp - REFERENCE_TEMPERATURE_C)[:, None]


def _temperature_variable(samples: Samples) -> tuple[str, np.ndarray]:
    return "arm temperature (deg C)", _temperature(samples)[:, 0] + REFERENCE_TEMPERATURE_C


def _direction(axis: int, samples: Samples) -> np.ndarray:
    return samples.direction[:, axis - 1:axis]


def _direction_variable(axis: int, samples: Samples) -> tuple[str, np.ndarray]:
    return f"A{axis} direction of motion", samples.direction[:, axis - 1]


def _neighbour(source: int, samples: Samples) -> np.ndarray:
    theta = samples.q[:, source - 1]
    return np.column_stack([np.cos(theta), np.sin(theta)])


def _displacement(samples: Samples) -> np.ndarray:
    out = np.zeros((samples.n, 3, 3))
    if samples.displacement is not None:
        for c in range(3):
            out[:, c, c] = -samples.displacement[:, c]  # residual = model - measured
    return out


def _displacement_variable(samples: Samples) -> tuple[str, np.ndarray]:
    disp = samples.displacement if samples.displacement is not None else np.zeros((samples.n, 3))
    return "R-Test displacement from its mean (um)", np.linalg.norm(disp, axis=1) * 1e6


def encoder_map(axis: int) -> Term:
    """The paper's encoder error map of one axis (its nodes are the parameters, in the maps)."""
    return Term(f"encoder_map[A{axis}]", "encoder", Kind.MAP, (), (),
                f"angular position measurement error of axis A{axis}: an error that depends on the "
                f"A{axis} angle (encoder map, nodes every few degrees)",
                _no_basis, partial(_readout, axis), (axis,))


def encoder_harmonic(axis: int, order: int = 3) -> Term:
    """Encoder error of one axis as harmonics 1..order of its angle (for sparse data)."""
    key = f"encoder_harmonic[A{axis}]" if order == 3 else f"encoder_harmonic{order}[A{axis}]"
    return Term(key, "encoder", Kind.ANGLE,
                tuple(f"{key}.{f}{h}" for h in range(1, order + 1) for f in ("cos", "sin")),
                (20 * ARCSEC,) * (2 * order),
                f"angular position measurement error of axis A{axis}: harmonics 1..{order} of the "
                f"A{axis} angle", partial(_harmonics, axis, order), partial(_readout, axis), (axis,))


def compliance(axis: int) -> Term:
    """Gravity-induced deflection of one joint: ``k * gravity torque`` (k in rad per N m)."""
    key = f"compliance[A{axis}]"
    return Term(key, "compliance", Kind.ANGLE, (f"{key}.k",), (1e-5,),  # 20 arcsec at 10 N m
                f"gravity compliance of joint A{axis}: the arm's own weight bends it by k x the "
                f"gravity torque on A{axis} (torque from the URDF inertias)",
                partial(_gravity, axis), partial(_gravity_variable, axis), (axis,))


def thermal() -> Term:
    """Uniform thermal expansion of every length: scale ``1 + alpha (T - 20 deg C)``."""
    return Term("thermal", "thermal", Kind.SCALE, ("thermal.alpha",), (2.3e-5,),
                "thermal expansion: every length of the arm scales with its temperature "
                "(1 + alpha (T - 20 deg C))", _temperature, _temperature_variable)


def backlash(axis: int) -> Term:
    """Direction-dependent angular error of one axis: ``+-half`` by the direction of motion."""
    key = f"backlash[A{axis}]"
    return Term(key, "backlash", Kind.ANGLE, (f"{key}.half",), (10 * ARCSEC,),
                f"backlash of axis A{axis}: an angular error whose sign follows the direction in "
                f"which A{axis} last moved", partial(_direction, axis),
                partial(_direction_variable, axis), (axis,))


def crosstalk(axis: int, source: int) -> Term:
    """Angular error of one axis depending on a neighbouring axis' angle (first harmonic)."""
    key = f"crosstalk[A{axis}<-A{source}]"
    return Term(key, "crosstalk", Kind.ANGLE, (f"{key}.cos", f"{key}.sin"), (10 * ARCSEC,) * 2,
                f"crosstalk: the A{axis} angle reads wrong by an amount that depends on the "
                f"A{source} angle (e.g. bearing or encoder runout coupled across axes)",
                partial(_neighbour, source), partial(_readout, source), (axis, source))


def rtest() -> Term:
    """The stylus moving in its seat: the R-Test displacement enters with a gain per coordinate.

    With the displacement ignored (``use_rtest=False``) the gains come out near 1.
    """
    return Term("rtest", "rtest", Kind.MEASUREMENT, ("rtest.gain_x", "rtest.gain_y", "rtest.gain_z"),
                (1.0, 1.0, 1.0), "the stylus sphere moves in its seat: the R-Test's measured "
                "displacement must be added to the nest position (Eq. 3)",
                _displacement, _displacement_variable)


@dataclass(frozen=True)
class Effect:
    """A named physical effect and how it proposes terms for an arm and its samples."""

    name: str
    """Name, e.g. ``"compliance"``."""
    description: str
    """Plain-language description."""
    candidates: Callable[[Arm, Samples], list[Term]]
    """Return the terms worth trying on these samples (one per axis for per-axis effects)."""
    in_start: bool = False
    """Whether every start model already has it (e.g. the tool vector)."""


def _varies(values: np.ndarray, tol: float) -> bool:
    return bool(values.size and np.ptp(values) > tol)


def _encoder(arm: Arm, s: Samples) -> list[Term]:
    out: list[Term] = []
    for a in range(1, arm.n_axes + 1):
        if _varies(s.q[:, a - 1], np.radians(1.0)):
            out += [encoder_map(a), encoder_harmonic(a)]
    return out


def _compliance(arm: Arm, s: Samples) -> list[Term]:
    return [compliance(a) for a in range(1, arm.n_axes + 1) if _varies(s.gravity[:, a - 1], 1e-2)]


def _thermal(arm: Arm, s: Samples) -> list[Term]:
    return [thermal()] if s.temp is not None and _varies(s.temp, 0.05) else []


def _backlash(arm: Arm, s: Samples) -> list[Term]:
    d = s.direction
    return [backlash(a) for a in range(1, arm.n_axes + 1)
            if (d[:, a - 1] > 0).sum() >= 3 and (d[:, a - 1] < 0).sum() >= 3]


def _crosstalk(arm: Arm, s: Samples) -> list[Term]:
    return [crosstalk(a, b) for a in range(1, arm.n_axes + 1) for b in (a - 1, a + 1)
            if 1 <= b <= arm.n_axes and _varies(s.q[:, b - 1], np.radians(5.0))
            and _varies(s.q[:, a - 1], np.radians(1.0))]


def _rtest(arm: Arm, s: Samples) -> list[Term]:
    disp = s.displacement
    return [rtest()] if disp is not None and np.abs(disp).max(initial=0.0) > 0 else []


_MADE: dict[str, Term] = {}
LIBRARY: dict[str, Effect] = {}
"""Registered effects by name (built-ins first); :func:`register_effect` adds more."""
_TERMS: dict[str, Callable[[str], Term | None]] = {}


def register_effect(effect: Effect) -> None:
    """Add (or replace) an effect of the library."""
    LIBRARY[effect.name] = effect


def register_term(parse: Callable[[str], Term | None], name: str) -> None:
    """Register a parser from a ``parameters.json`` key to a term (None if not its key)."""
    _TERMS[name] = parse


def term_from_key(key: str) -> Term:
    """Return the term a ``parameters.json`` extensions key names.

    Raises:
        KeyError: if no registered term has this key.
    """
    for parse in _TERMS.values():
        term = parse(key)
        if term is not None:
            return term
    if key in _MADE:  # a user's term, made in this process but not registered for files
        return _MADE[key]
    raise KeyError(key)


def _axis_key(key: str, prefix: str) -> int | None:
    match = re.fullmatch(rf"{re.escape(prefix)}\[A(\d+)\]", key)
    return int(match.group(1)) if match else None


def _harmonic_parse(key: str) -> Term | None:
    match = re.fullmatch(r"encoder_harmonic(\d*)\[A(\d+)\]", key)
    if not match:
        return None
    return encoder_harmonic(int(match.group(2)), int(match.group(1) or 3))


def _cross_parse(key: str) -> Term | None:
    match = re.fullmatch(r"crosstalk\[A(\d+)<-A(\d+)\]", key)
    return crosstalk(int(match.group(1)), int(match.group(2))) if match else None


def _axis_parser(prefix: str, cls: Callable[[int], Term]) -> Callable[[str], Term | None]:
    def parse(key: str) -> Term | None:
        axis = _axis_key(key, prefix)
        return None if axis is None else cls(axis)
    return parse


for _name, _description, _candidates in (
        ("encoder", "angular position measurement error of an axis (encoder map or harmonics)",
         _encoder),
        ("compliance", "gravity-induced joint deflection: k x gravity torque (URDF inertias)",
         _compliance),
        ("thermal", "thermal expansion of the arm's lengths with the temp_c column", _thermal),
        ("backlash", "direction-dependent angular error of an axis", _backlash),
        ("crosstalk", "angular error of an axis that depends on a neighbouring axis' angle",
         _crosstalk),
        ("rtest", "the stylus moving in its seat (measured R-Test displacement)", _rtest)):
    register_effect(Effect(_name, _description, _candidates))
register_effect(Effect("tool", "stylus/tool vector error (part of every start model)",
                       lambda arm, s: [], in_start=True))
register_term(_harmonic_parse, "encoder_harmonic")
register_term(_axis_parser("compliance", compliance), "compliance")
register_term(_axis_parser("backlash", backlash), "backlash")
register_term(_cross_parse, "crosstalk")
register_term(lambda key: thermal() if key == "thermal" else None, "thermal")
register_term(lambda key: rtest() if key == "rtest" else None, "rtest")


def terms_of(extensions: dict[str, Any]) -> list[Term]:
    """Return the terms named by a parameters' extensions (keys of ``Parameters.extensions``)."""
    return [term_from_key(k) for k in extensions]


def apply_terms(extensions: dict[str, np.ndarray], samples: Samples, n_axes: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """Return the angle offsets (N, n_axes) rad and the length scale (N,) of the extensions.

    Measurement terms change the measured point, not the arm: they are left out here.
    """
    offsets = np.zeros((samples.n, n_axes))
    scale = np.ones(samples.n)
    for key, values in extensions.items():
        term = term_from_key(key)
        if term.kind is Kind.ANGLE:
            offsets[:, term.axis - 1] += term.basis(samples) @ np.asarray(values, dtype=float)
        elif term.kind is Kind.SCALE:
            scale += term.basis(samples) @ np.asarray(values, dtype=float)
    return offsets, scale


def measurement_shift(terms: Iterable[Term], extensions: dict[str, np.ndarray], samples: Samples
                      ) -> np.ndarray:
    """Return the measurement terms' change of the modelled point, shape (N, 3), m."""
    out = np.zeros((samples.n, 3))
    for t in terms:
        if t.kind is Kind.MEASUREMENT:
            out += t.basis(samples) @ extensions[t.key]
    return out


def residual_along(term: Term, residuals: np.ndarray, samples: Samples,
                   stylus: StylusDerivatives, origin: np.ndarray) -> tuple[str, np.ndarray]:
    """Return a label and every sample's residual seen along the term's direction (figures).

    Angle and map terms: the residual as an angle error of the term's axis (arcsec, least squares
    on d(position)/d(angle)); scale terms: along the radius from ``origin`` (the r-CS origin in
    the residuals' frame, um); measurement terms: along the R-Test displacement (um).

    Args:
        term: the term.
        residuals: model - measured, shape (N, 3), m.
        samples: the samples (N).
        stylus: stylus Jacobians at the samples, in the residuals' frame.
        origin: r-CS origin in that frame, shape (3,), m.
    """
    if term.kind in (Kind.ANGLE, Kind.MAP):
        j = stylus.angles[:, :, term.axis - 1]
        angle = np.sum(j * residuals, axis=1) / np.maximum(np.sum(j * j, axis=1), 1e-30)
        return f"A{term.axis} angle residual (arcsec)", np.degrees(angle) * 3600
    if term.kind is Kind.SCALE:
        radial = stylus.position - origin
        radial /= np.linalg.norm(radial, axis=1, keepdims=True)
        return "radial residual (um)", np.sum(residuals * radial, axis=1) * 1e6
    disp = samples.displacement
    unit = np.zeros_like(residuals) if disp is None else disp / np.maximum(
        np.linalg.norm(disp, axis=1, keepdims=True), 1e-12)
    return "residual along the displacement (um)", np.sum(residuals * unit, axis=1) * 1e6


def term_columns(term: Term, samples: Samples, stylus: StylusDerivatives, params: Parameters,
                 touched: np.ndarray | None = None) -> np.ndarray:
    """Return d(model point)/d(term parameters), shape (N, 3, k), at ``params``.

    The one place where a term's kind decides how it moves the modelled point.

    Args:
        term: a term of any kind.
        samples: the samples' readouts, temperature, motion and displacement (N).
        stylus: stylus Jacobians in the output frame at ``params`` (:func:`aacmm_pin.stylus_jacobians`).
        params: the parameters (translation, a scale term's current value, the maps' grids).
        touched: for a map term, the nodes that are its parameters, shape (n_axes, n_nodes)
            (default: every node).
    """
    if term.kind is Kind.MAP:
        cols = params.map(term.axis).node_columns(samples.q[:, term.axis - 1],
                                                  stylus.angles[:, :, term.axis - 1],
                                                  None if touched is None else touched[term.axis - 1])
        dense: np.ndarray = cols.toarray().reshape(samples.n, 3, -1)
        return dense
    basis = term.basis(samples)
    if term.kind is Kind.ANGLE:
        angle_cols: np.ndarray = stylus.angles[:, :, term.axis - 1, None] * basis[:, None, :]
        return angle_cols
    if term.kind is Kind.SCALE:
        scale = 1.0 + basis @ params.extensions.get(term.key, np.zeros(basis.shape[1]))
        radial = (stylus.position - params.translation) / scale[:, None]
        scale_cols: np.ndarray = radial[:, :, None] * basis[:, None, :]
        return scale_cols
    return basis  # Kind.MEASUREMENT: the basis is the change of the measured point


def effect_names(terms: Iterable[Term]) -> list[str]:
    """Return the distinct effect names of some terms, in order."""
    return list(dict.fromkeys(t.effect for t in terms))
