r"""The extension point: what an effect is, and one small class per way a term acts on the model.

An *effect* (:class:`Effect`) is a physical cause of measurement error with a plain-language
description. On an arm and its samples it proposes *terms* (:class:`Term`), one per axis where the
effect is per-axis, each with a few parameters that the model is linear in, their plausible sizes
and how they move the modelled point. A term acts in one of these ways (one subclass each):

* :class:`AngleTerm`: an error of the true angle of one axis,
  :math:`\Delta\theta_n = B(\text{samples}) \, v` with a basis B of shape (N, k);
* :class:`ScaleTerm`: a uniform scale of every length of the arm (r-CS positions times
  :math:`1 + B v`);
* :class:`TiltTerm`: a small rotation of one joint about the two axes perpendicular to its own
  (lateral deflection), :math:`(\delta_x, \delta_y) = B(\text{samples}) \, v` with B of shape
  (N, 2, k); the point moves by :math:`\delta_x \, u_x \times (p - o) + \delta_y \, u_y \times
  (p - o)` about the joint's origin o and lateral axes u (first order in the tilt);
* :class:`FrameTerm`: a small motion of any frame of the arm's Pinocchio model (the tool, the
  base, a link, a joint's or an error frame), a twist :math:`(v, \omega) = B(\text{samples}) \, v`
  in the frame's own axes with B of shape (N, 6, k) (linear part first, m; angular, rad);
  everything hanging from the frame moves with it, so the point moves by
  :math:`R_f v + R_f \omega \times (p - o_f)` and the columns come from the frame Jacobian
  (first order in the twist). A stylus that grows with its temperature, a base that drifts, a
  link that bends, a probe that deflects along its axis are terms of this kind;
* :class:`MeasurementTerm`: a change of the *measured* point (e.g. the R-Test's), not of the arm;
* :class:`MapTerm`: the paper's encoder error map of one axis (its nodes are the parameters).

An effect also declares the per-sample columns it reads (:attr:`Effect.reads`, e.g. ``temp_c``)
and the per-sample variables it offers the residual scan (:meth:`Effect.variables`); each term
names the variables it follows (:attr:`Term.follows`), so a residual that follows a variable
points at the terms on it. Register an effect with :func:`aacmm_pin.effects.register_effect`;
installed packages offer theirs through the ``aacmm_pin.effects`` entry-point group.
"""

from __future__ import annotations

import re
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import KW_ONLY, dataclass, field, replace
from typing import TYPE_CHECKING, NamedTuple, Protocol

import numpy as np

from aacmm_pin.errors import AacmmError, FrameNotFound
from aacmm_pin.model.kinematics import Adjustment as Adjustment  # re-exported: terms fill it
from aacmm_pin.model.kinematics import frame_ids

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm
    from aacmm_pin.model.parameters import Parameters
    from aacmm_pin.model.samples import Samples
    from aacmm_pin.model.sizes import Sizes


class StylusDerivatives(Protocol):
    """What a term's columns need of :class:`aacmm_pin.model.kinematics.StylusJacobians`."""

    @property
    def position(self) -> np.ndarray:
        """Stylus centres, shape (N, 3), m."""

    @property
    def angles(self) -> np.ndarray:
        """d(position)/d(true joint angle), shape (N, 3, n_axes), m/rad."""

    @property
    def tilts(self) -> np.ndarray | None:
        """d(position)/d(lateral tilts), shape (N, 3, n_axes, 2), m/rad, or None."""

    def twist(self, frame: str) -> np.ndarray:
        """d(position)/d(a small twist of a frame in its own axes), shape (N, 3, 6)."""


TIME_WITHIN_LOCATION = "time within each location"
"""The residual scan's name of the time since each location's first sample (a term that follows
it names it in :attr:`Term.follows`)."""
TIME_OVERALL = "time over the campaign"
"""The residual scan's name of the time over the whole campaign."""


class Variable(NamedTuple):
    """A per-sample variable the residual scan tests the residual against."""

    name: str
    """What it is, in words: ``the gravity torque on A2`` (unique; terms name it)."""
    where: str
    """Where it acts: an axis (``A2``), ``all``, a coordinate, ``stylus``."""
    label: str
    """Axis label with unit, for figures: ``gravity torque on A2 (N m)``."""
    values: np.ndarray
    """Its value at every sample, shape (N,), in the label's unit."""
    kind: str = "global"
    """How the scan fits it: ``global`` (over all samples), ``within`` (within each location),
    ``levels`` (a few discrete values) or ``own`` (a measured displacement, tested on the other
    coordinates' residual only)."""


@dataclass(frozen=True, eq=False)
class Term(ABC):
    """One extension of the model: a few parameters, linear in their effect (see module doc).

    ``key``, ``effect``, ``names``, ``plausible`` and ``description`` may be given by position;
    the other fields only by keyword.

    Terms are equal when their keys are. ``basis_of`` and ``variable_of`` (in the subclasses that
    take them) should be module-level functions or ``functools.partial`` of them, so that
    calibrations pickle.
    """

    key: str
    """Unique name, e.g. ``compliance[A2]`` (the key in ``parameters.json``)."""
    effect: str
    """Name of the effect this term belongs to."""
    names: tuple[str, ...]
    """Names of the parameters, e.g. ``compliance[A2].k``."""
    plausible: tuple[float, ...]
    """Plausible size of every parameter on the default arm (SI): the scale of its prior, unless
    the arm's sizes name the term's effect (:meth:`aacmm_pin.model.sizes.Sizes.size_of`)."""
    description: str
    """Plain-language description."""
    _: KW_ONLY
    axes: tuple[int, ...] = ()
    """Axes the term acts on (empty for arm-wide terms); an angle term changes ``axes[0]``."""
    follows: tuple[str, ...] = ()
    """The :attr:`Variable.name` of each per-sample variable the term follows (residual scan)."""
    slot: str = ""
    """Terms of one slot describe the same thing and replace each other (default: the key)."""

    def __post_init__(self) -> None:
        if not self.slot:
            object.__setattr__(self, "slot", self.key)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Term) and other.key == self.key

    def __hash__(self) -> int:
        return hash(self.key)

    @property
    def axis(self) -> int:
        """The axis the term changes (1-based): ``axes[0]``."""
        return self.axes[0]

    @property
    def form(self) -> str:
        """How the term describes its effect, in one word (``map``, ``harmonic``, ``gain``)."""
        return "term"

    @property
    def is_extension(self) -> bool:
        """Whether its values live in ``Parameters.extensions`` (maps live in the maps)."""
        return True

    def describe(self) -> str:
        """Return the plain-language description."""
        return self.description

    def sizes(self, sizes: Sizes) -> np.ndarray:
        """Return the plausible size of every parameter, shape (k,), SI (the prior's scale).

        The arm's size of the term's effect where it has one, else the term's own ``plausible``.
        """
        own = np.asarray(self.plausible, dtype=float)
        size = sizes.effects.get(self.effect)
        return own if size is None else np.full(own.shape, float(size))

    @property
    def size_key(self) -> str:
        """The sizes-file key whose factor scales this term's prior (``effects.<name>``)."""
        return f"effects.{self.effect}"

    def adjust(self, values: np.ndarray, samples: Samples, out: Adjustment) -> None:
        """Add the term's change of the arm, with parameter values ``values`` (k,), to ``out``.

        Terms that change the measured point, not the arm, add nothing (the default).
        """

    def shift(self, values: np.ndarray, samples: Samples) -> np.ndarray | None:
        """Return the term's change of the *measured* point, shape (N, 3), m; None: it has none."""
        return None

    @abstractmethod
    def columns(self, samples: Samples, stylus: StylusDerivatives, params: Parameters,
                touched: np.ndarray | None = None) -> np.ndarray:
        """Return d(model point)/d(term parameters), shape (N, 3, k), at ``params``.

        Args:
            samples: the samples' readouts and per-sample columns (N).
            stylus: stylus Jacobians in the output frame at ``params``.
            params: the parameters (translation, the term's current value, the maps' grids).
            touched: for a map term, the nodes that are its parameters, shape (n_axes, n_nodes).
        """

    @abstractmethod
    def variable(self, samples: Samples) -> tuple[str, np.ndarray]:
        """Return the label (with unit) and per-sample values of the term's variable (figures)."""

    @abstractmethod
    def residual_along(self, residuals: np.ndarray, samples: Samples, stylus: StylusDerivatives,
                       origin: np.ndarray) -> tuple[str, np.ndarray]:
        """Return a label and every sample's residual seen along the term's direction (figures).

        Args:
            residuals: model - measured, shape (N, 3), m.
            samples: the samples (N).
            stylus: stylus Jacobians at the samples, in the residuals' frame.
            origin: r-CS origin in that frame, shape (3,), m.
        """

    # ------------------------------------------------------------ discovery's model state
    def in_model(self, model: ModelSpec) -> bool:
        """Whether the model already holds this term (or one that describes the same thing)."""
        return any(t.slot == self.slot for t in model.terms)

    def added_to(self, model: ModelSpec) -> ModelSpec:
        """Return the model with this term added (replacing a term of its slot)."""
        return replace(model, terms=tuple(t for t in model.terms if t.slot != self.slot) + (self,))

    def replaces(self, other: Term) -> bool:
        """Whether this term may replace ``other`` (same axes) in one discovery step."""
        return False


@dataclass(frozen=True)
class ModelSpec:
    """What a model holds beyond DH, tool and X0: extension terms, encoder maps, the R-Test."""

    terms: tuple[Term, ...] = ()
    """Extension terms (values in ``Parameters.extensions``)."""
    map_axes: tuple[int, ...] = ()
    """Axes with an encoder map."""
    use_rtest: bool = True
    """Whether the measured R-Test displacement is added to the nest positions."""


def _angle_along(axis: int, residuals: np.ndarray, stylus: StylusDerivatives
                 ) -> tuple[str, np.ndarray]:
    j = stylus.angles[:, :, axis - 1]
    angle = np.sum(j * residuals, axis=1) / np.maximum(np.sum(j * j, axis=1), 1e-30)
    return f"A{axis} angle residual (arcsec)", np.degrees(angle) * 3600


SOURCE_OF: list[Callable[[str], str]] = []
"""Where an effect comes from (set by :mod:`aacmm_pin.effects.registry`: its ``plugin_of``)."""


class PluginOutputError(AacmmError):
    """A term's output (its basis) is not usable: raised, wrong shape, or not finite."""

    def __init__(self, term: Term, why: str):
        source = SOURCE_OF[0](term.effect) if SOURCE_OF else ""
        where = f" of {source!r}" if source else ""
        super().__init__(f"term {term.key} (effect {term.effect!r}{where}): {why}")


Basis = Callable[["Samples"], np.ndarray]
VariableOf = Callable[["Samples"], "tuple[str, np.ndarray]"]


@dataclass(frozen=True, eq=False)
class BasisTerm(Term):
    """A term whose parameters multiply a per-sample basis (every way of acting but the map)."""

    basis_of: Basis = field(repr=False, kw_only=True)
    """Samples -> basis: (N, k) for angle and scale terms, (N, 2, k) for tilt terms, (N, 3, k)
    for measurement terms, (N, 6, k) for frame terms."""
    variable_of: VariableOf = field(repr=False, kw_only=True)
    """Samples -> (label with unit, per-sample values) of the term's variable (figures)."""

    def basis(self, samples: Samples) -> np.ndarray:
        """Return the basis on these samples (see :attr:`basis_of`), checked.

        Raises:
            PluginOutputError: one line naming the term, its effect and where the effect comes
                from, for a basis that raises (other than the package's own errors, e.g. a missing
                column), is not an array of N rows or holds a value that is not finite.
        """
        try:
            out = np.asarray(self.basis_of(samples), dtype=float)
        except AacmmError:
            raise
        except Exception as exc:  # noqa: BLE001 - a plugin's code: named, in one line
            raise PluginOutputError(self, f"its basis raised {type(exc).__name__}: {exc}") from None
        if out.ndim not in (2, 3) or out.shape[0] != samples.n:
            raise PluginOutputError(self, f"its basis has shape {out.shape}, expected ({samples.n}, "
                                          "k) or (N, 2, 3 or 6, k) for these samples")
        if not np.all(np.isfinite(out)):
            bad = int(np.flatnonzero(~np.isfinite(out).reshape(samples.n, -1).all(axis=1))[0])
            raise PluginOutputError(self, f"its basis is not finite (NaN or inf) at sample "
                                          f"{bad + 1} of {samples.n}")
        return out

    def variable(self, samples: Samples) -> tuple[str, np.ndarray]:
        """Return the label and per-sample values of the term's variable."""
        return self.variable_of(samples)


@dataclass(frozen=True, eq=False)
class AngleTerm(BasisTerm):
    """An error of the true angle of axis ``axes[0]``: basis (N, k) times the values, rad."""

    def adjust(self, values: np.ndarray, samples: Samples, out: Adjustment) -> None:
        """Add the angle error to the axis' offsets."""
        out.offsets[:, self.axis - 1] += self.basis(samples) @ values

    def columns(self, samples: Samples, stylus: StylusDerivatives, params: Parameters,
                touched: np.ndarray | None = None) -> np.ndarray:
        """d(point)/d(values): the axis' angle column times the basis, (N, 3, k)."""
        cols: np.ndarray = stylus.angles[:, :, self.axis - 1, None] * self.basis(samples)[:, None, :]
        return cols

    def residual_along(self, residuals: np.ndarray, samples: Samples, stylus: StylusDerivatives,
                       origin: np.ndarray) -> tuple[str, np.ndarray]:
        """The residual as an angle error of the axis (arcsec, least squares on its column)."""
        return _angle_along(self.axis, residuals, stylus)


@dataclass(frozen=True, eq=False)
class ScaleTerm(BasisTerm):
    """A uniform scale of every length of the arm: ``1 + basis @ values``."""

    def adjust(self, values: np.ndarray, samples: Samples, out: Adjustment) -> None:
        """Add to the length scale."""
        out.scale += self.basis(samples) @ values

    def columns(self, samples: Samples, stylus: StylusDerivatives, params: Parameters,
                touched: np.ndarray | None = None) -> np.ndarray:
        """d(point)/d(values): the unscaled radius from the r-CS origin times the basis."""
        basis = self.basis(samples)
        scale = 1.0 + basis @ params.extensions.get(self.key, np.zeros(basis.shape[1]))
        radial = (stylus.position - params.translation) / scale[:, None]
        cols: np.ndarray = radial[:, :, None] * basis[:, None, :]
        return cols

    def residual_along(self, residuals: np.ndarray, samples: Samples, stylus: StylusDerivatives,
                       origin: np.ndarray) -> tuple[str, np.ndarray]:
        """The residual along the radius from ``origin`` (um)."""
        radial = stylus.position - origin
        radial /= np.linalg.norm(radial, axis=1, keepdims=True)
        return "radial residual (um)", np.sum(residuals * radial, axis=1) * 1e6


def _tilt_columns(stylus: StylusDerivatives, axis: int) -> np.ndarray:
    if stylus.tilts is None:
        raise ValueError("a tilt term needs the stylus Jacobians' tilt columns: "
                         "stylus_jacobians(..., tilts=True)")
    return stylus.tilts[:, :, axis - 1, :]


@dataclass(frozen=True, eq=False)
class TiltTerm(BasisTerm):
    """A lateral tilt of joint ``axes[0]`` about its two lateral axes: basis (N, 2, k), rad."""

    def adjust(self, values: np.ndarray, samples: Samples, out: Adjustment) -> None:
        """Add the tilt to the joint's lateral tilts."""
        out.tilts[:, self.axis - 1] += self.basis(samples) @ values

    def columns(self, samples: Samples, stylus: StylusDerivatives, params: Parameters,
                touched: np.ndarray | None = None) -> np.ndarray:
        """d(point)/d(values): the joint's two tilt columns times the basis, (N, 3, k)."""
        tilt = _tilt_columns(stylus, self.axis)  # (N, 3, 2)
        cols: np.ndarray = np.einsum("nij,njk->nik", tilt, self.basis(samples))
        return cols

    def residual_along(self, residuals: np.ndarray, samples: Samples, stylus: StylusDerivatives,
                       origin: np.ndarray) -> tuple[str, np.ndarray]:
        """The residual as a lateral tilt of the joint (arcsec, least squares, its magnitude)."""
        tilt = _tilt_columns(stylus, self.axis)
        gram = np.einsum("nij,nik->njk", tilt, tilt) + 1e-30 * np.eye(2)
        rhs = np.einsum("nij,ni->nj", tilt, residuals)
        angle = np.linalg.solve(gram, rhs[:, :, None])[:, :, 0]
        return f"A{self.axis} lateral tilt residual (arcsec)", np.degrees(
            np.linalg.norm(angle, axis=1)) * 3600


@dataclass(frozen=True, eq=False)
class FrameTerm(BasisTerm):
    """A small motion of the frame ``frame``: basis (N, 6, k) times the values is its twist.

    The twist (linear, then angular; m, rad) is in the frame's own axes (Pinocchio's ``LOCAL``);
    ``frame`` names a frame of the arm's Pinocchio model: a link (``link6``), the tool
    (``stylus``), a joint's frame (its child side) or an error frame.
    """

    frame: str = field(kw_only=True)
    """Name of the moved frame in the arm's Pinocchio model."""

    def adjust(self, values: np.ndarray, samples: Samples, out: Adjustment) -> None:
        """Add the twist to the frame's."""
        out.twist(self.frame)[:] += self._twist_basis(samples) @ values

    def _twist_basis(self, samples: Samples) -> np.ndarray:
        """Return the basis, (N, 6, k), its frame checked against the arm's URDF.

        Raises:
            PluginOutputError: naming the term, its effect and its plugin, for a frame the arm's
                URDF has not (its links and joints listed) or a basis of another shape.
        """
        try:
            frame_ids(samples.arm, samples.arm.nominal_model, [self.frame])
        except FrameNotFound as exc:
            raise PluginOutputError(self, f"it moves the frame {exc}") from None
        basis = self.basis(samples)
        if basis.ndim != 3 or basis.shape[1] != 6:
            raise PluginOutputError(self, f"its basis has shape {basis.shape}, expected "
                                          f"({samples.n}, 6, k) for a frame term")
        return basis

    def columns(self, samples: Samples, stylus: StylusDerivatives, params: Parameters,
                touched: np.ndarray | None = None) -> np.ndarray:
        """d(point)/d(values): the frame's twist columns times the basis, (N, 3, k)."""
        basis = self._twist_basis(samples)  # first: its frame checked
        cols: np.ndarray = np.einsum("nij,njk->nik", stylus.twist(self.frame), basis)
        return cols

    def residual_along(self, residuals: np.ndarray, samples: Samples, stylus: StylusDerivatives,
                       origin: np.ndarray) -> tuple[str, np.ndarray]:
        """The residual along the point's motion by the term's first parameter (um)."""
        first = self._twist_basis(samples)[:, :, 0]
        cols = np.einsum("nij,nj->ni", stylus.twist(self.frame), first)
        unit = cols / np.maximum(np.linalg.norm(cols, axis=1, keepdims=True), 1e-30)
        return (f"residual along the motion of {self.frame} (um)",
                np.sum(residuals * unit, axis=1) * 1e6)


@dataclass(frozen=True, eq=False)
class MeasurementTerm(BasisTerm):
    """A change of the measured point, not of the arm: basis (N, 3, k) times the values, m."""

    def shift(self, values: np.ndarray, samples: Samples) -> np.ndarray | None:
        """Return the change of the measured point, (N, 3), m."""
        shifted: np.ndarray = self.basis(samples) @ values
        return shifted

    def columns(self, samples: Samples, stylus: StylusDerivatives, params: Parameters,
                touched: np.ndarray | None = None) -> np.ndarray:
        """d(point)/d(values): the basis itself."""
        return self.basis(samples)

    def residual_along(self, residuals: np.ndarray, samples: Samples, stylus: StylusDerivatives,
                       origin: np.ndarray) -> tuple[str, np.ndarray]:
        """The residual along the R-Test displacement (um)."""
        disp = samples.displacement
        unit = np.zeros_like(residuals) if disp is None else disp / np.maximum(
            np.linalg.norm(disp, axis=1, keepdims=True), 1e-12)
        return "residual along the displacement (um)", np.sum(residuals * unit, axis=1) * 1e6


@dataclass(frozen=True, eq=False)
class MapTerm(Term):
    """The encoder error map of axis ``axes[0]``: its nodes are the parameters (in the maps)."""

    @property
    def form(self) -> str:
        """``map``."""
        return "map"

    @property
    def is_extension(self) -> bool:
        """No: a map's values live in ``Parameters.encoder_maps``."""
        return False

    def sizes(self, sizes: Sizes) -> np.ndarray:
        """Every node's plausible size, the arm's ``map_node`` (a 0-d array: one for all nodes)."""
        return np.asarray(sizes.map_node)

    @property
    def size_key(self) -> str:
        """``map_node``."""
        return "map_node"

    def columns(self, samples: Samples, stylus: StylusDerivatives, params: Parameters,
                touched: np.ndarray | None = None) -> np.ndarray:
        """d(point)/d(nodes): the axis' angle column times the interpolation weights."""
        cols = params.map(self.axis).node_columns(samples.q[:, self.axis - 1],
                                                  stylus.angles[:, :, self.axis - 1],
                                                  None if touched is None else touched[self.axis - 1])
        dense: np.ndarray = cols.toarray().reshape(samples.n, 3, -1)
        return dense

    def variable(self, samples: Samples) -> tuple[str, np.ndarray]:
        """The axis' readout (deg)."""
        return f"A{self.axis} readout (deg)", np.degrees(samples.q[:, self.axis - 1])

    def residual_along(self, residuals: np.ndarray, samples: Samples, stylus: StylusDerivatives,
                       origin: np.ndarray) -> tuple[str, np.ndarray]:
        """The residual as an angle error of the axis (arcsec)."""
        return _angle_along(self.axis, residuals, stylus)

    def in_model(self, model: ModelSpec) -> bool:
        """Whether the axis has a map."""
        return self.axis in model.map_axes

    def added_to(self, model: ModelSpec) -> ModelSpec:
        """The axis gets a map, which replaces the other terms of its slot."""
        axes = model.map_axes if self.axis in model.map_axes else model.map_axes + (self.axis,)
        return replace(model, terms=tuple(t for t in model.terms if t.slot != self.slot),
                       map_axes=axes)

    def replaces(self, other: Term) -> bool:
        """A map replaces any other term of its slot (it holds every harmonic its nodes resolve)."""
        return other.slot == self.slot and not isinstance(other, MapTerm)


class Effect(ABC):
    """A named physical effect: which terms it proposes, and what it reads and offers the scan.

    Subclass it (one small class per effect, see the built-ins in :mod:`aacmm_pin.effects`) and
    register an instance with :func:`aacmm_pin.effects.register_effect`.
    """

    name: str = ""
    """Name, e.g. ``"compliance"`` (the key of its size in the sizes file)."""
    description: str = ""
    """Plain-language description."""
    reads: tuple[str, ...] = ()
    """Per-sample columns of the campaign files it reads (e.g. ``("temp_c",)``): on samples without
    one of them it is asked nothing, left out and listed
    (:func:`aacmm_pin.effects.contract.usable_effects`)."""
    in_start: bool = False
    """Whether every start model already has it (e.g. the tool vector)."""
    by_default: bool = True
    """Whether discovery tries it, and the residual scan tests its variables, when no list of
    effects is given (False: only when named, e.g. ``lateral_compliance``)."""
    needs_encoder: bool = False
    """Whether its per-axis terms are errors of an axis' encoder (its readout): True for encoder
    maps and harmonics, backlash and crosstalk of the readout. Such terms are offered only on axes
    with an encoder, not on coupled joints (:meth:`offered`); an effect of the joint itself (its
    compliance: the torque passes through it) is offered on every axis."""

    @abstractmethod
    def candidates(self, arm: Arm, samples: Samples) -> list[Term]:
        """Return the terms worth trying on these samples (one per axis for per-axis effects)."""

    def offered(self, arm: Arm, samples: Samples) -> list[Term]:
        """Return the terms discovery may try: :meth:`candidates`, less coupled axes' if encoder.

        An effect that :attr:`needs_encoder` is not offered on a coupled joint (``term.axis``
        among ``arm.coupled``): it has no encoder.
        """
        terms = self.candidates(arm, samples)
        if not self.needs_encoder or not arm.couplings:
            return terms
        return [t for t in terms if not t.axes or not arm.coupled[t.axis - 1]]

    @abstractmethod
    def term(self, key: str) -> Term | None:
        """Return the term a ``parameters.json`` extensions key names, or None if not its key."""

    def variables(self, arm: Arm, samples: Samples) -> list[Variable]:
        """Return the per-sample variables this effect follows, worth a residual test here."""
        return []


def varies(values: np.ndarray, tol: float) -> bool:
    """Return whether ``values`` span more than ``tol`` (peak to peak)."""
    return bool(values.size and np.ptp(values) > tol)


def axis_key(prefix: str, key: str) -> int | None:
    """Return n of a ``<prefix>[A<n>]`` key, else None."""
    match = re.fullmatch(rf"{re.escape(prefix)}\[A(\d+)\]", key)
    return int(match.group(1)) if match else None


def per_axis(arm: Arm) -> Sequence[int]:
    """Return the arm's axis numbers, 1-based."""
    return range(1, arm.n_axes + 1)
