"""The result of an identification, :class:`Calibration`, and its report (``report.json``).

What :func:`aacmm_pin.fit.identification.identify` returns: the identified parameters, how well they
are known (covariance, what the data cannot determine), the fit's residuals and outliers, and the
solved problem for :func:`aacmm_pin.fit.identification.refit`. :meth:`Calibration.report` is the
content of a calibration folder's ``report.json`` (:func:`aacmm_pin.outputs.export.write_calibration`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from aacmm_pin.data.campaign import StatedNoise
from aacmm_pin.fit import identifiability as ident
from aacmm_pin.fit.robust import Outlier
from aacmm_pin.fit.solver import Problem, SolverSettings
from aacmm_pin.fit.unknowns import NestKey, NodeKey, UnknownKey, Unknowns
from aacmm_pin.model.parameters import Parameters

if TYPE_CHECKING:  # the solver is imported where a fit runs
    from scipy.optimize import OptimizeResult


@dataclass(frozen=True)
class Calibration:
    """Result of :func:`~aacmm_pin.fit.identification.identify`: parameters and how well they are known."""

    parameters: Parameters
    """Identified parameters (held entries at their start values)."""
    model: str
    """``"dh"`` or ``"proposed"``."""
    use_rtest: bool
    """Whether each sample's R-Test displacement was used (else each location's mean)."""
    names: list[str]
    """Names of the estimated entries, in the order of ``x`` and ``covariance``."""
    x: np.ndarray
    """Estimated values, shape (n,), SI."""
    covariance: np.ndarray
    """Linearised covariance of ``x``, shape (n, n), SI (sigma from ``sigma``)."""
    sigma: float
    """Noise standard deviation per coordinate used for the covariance, m (with per-point
    ``sigma_um``: that of a point whose stated noise is the median, the others scaled by theirs)."""
    fun: np.ndarray
    """Residuals predicted - measured, shape (N, 3), m."""
    location: np.ndarray
    """R-Test location of each residual row, shape (N,)."""
    success: bool
    """Whether the solver converged."""
    status: int
    """Solver status (scipy's meaning)."""
    message: str
    """Solver message, or why the identification failed."""
    nfev: int
    """Number of residual evaluations."""
    unidentifiable: list[str]
    """Plain-language list of what the data does not determine and how it was handled."""
    node_identifiable: dict[int, np.ndarray]
    """Axis -> mask of identified map nodes, shape (n_nodes,)."""
    runtime_s: float
    """Wall-clock time of the identification, s."""
    raw: OptimizeResult = field(repr=False)
    """The final raw scipy result."""
    unknowns: Unknowns = field(repr=False)
    """The final layout (free entries, start values)."""
    constraints: sp.csr_matrix = field(repr=False)
    """Rows C over the free arm entries held as ``C @ (x - x_start) = 0`` (gauges, held directions)."""
    identifiable: np.ndarray = field(repr=False)
    """Per free arm entry (``unknowns.names``): whether the data determines it."""
    q: np.ndarray = field(repr=False)
    """The SPAT readouts used, shape (N, n_axes), rad."""
    problem: Problem = field(repr=False)
    """The solved least-squares problem (structure, preconditioner), for
    :func:`~aacmm_pin.fit.identification.refit`."""
    settings: SolverSettings = field(repr=False)
    """Solver settings (loss, f_scale, max_nfev) for :func:`~aacmm_pin.fit.identification.refit`."""
    nuisance_keys: tuple[UnknownKey, ...] = ()
    """What each entry of ``x`` after the arm's is: nest offsets, then instrument frames."""
    inputs: tuple[str, ...] = ("spat",)
    """The measurement kinds fitted: ``"spat"``, ``"points"``, ``"bar"`` (the length bar)."""
    nests: str = ""
    """How the R-Test nests' offsets were treated (estimated or fixed) and why; empty without."""
    robust: bool = False
    """Whether outliers were rejected (``identify(..., robust=True)``, :mod:`aacmm_pin.fit.robust`)."""
    outliers: tuple[Outlier, ...] = ()
    """Samples the robust fit rejected (weight 0), largest first; empty without ``robust``."""
    suspects: tuple[Outlier, ...] = ()
    """Without ``robust``: samples beyond ``robust.OUTLIER_K`` robust sigmas, kept in the fit
    (named in ``message`` too)."""
    inlier: np.ndarray | None = field(default=None, repr=False)
    """Samples kept in the fit, shape (N,), bool; None: all."""
    stated_noise: StatedNoise | None = None
    """The stated noise per kind every solve used and the residual was judged against (points
    with a ``sigma_um`` column: theirs); see :func:`aacmm_pin.fit.identification.solve_noise`."""
    judged: bool = False
    """Whether ``success`` is False only by the residual's judgement against the stated noise or a
    tool's or group's degrees of freedom (:mod:`aacmm_pin.fit.noise_judgement`): the solver
    converged and the other checks passed, so the fit can still be examined (``discover``)."""

    def equivalent(self, other: Parameters) -> tuple[Parameters, float]:
        """Return ``other`` (e.g. the truth) moved into this calibration's gauge and held values.

        See :func:`aacmm_pin.fit.identifiability.equivalent_vector`. Returns the parameters and the RMS
        change of the predictions on the campaign's postures (m).
        """
        full = self.unknowns.with_free(np.ones_like(self.unknowns.free))
        _, jac = full.jacobian(full.full_vector(self.parameters), self.q)
        vec, rms = ident.equivalent_vector(self.unknowns, jac.sparse(), self.constraints,
                                           full.full_vector(other))
        return full.parameters(vec), rms

    @property
    def node_reached(self) -> dict[int, np.ndarray]:
        """Axis -> mask of the map nodes some posture's readout reached, shape (n_nodes,).

        The other nodes were held at their start values (zero): the data says nothing of them.
        """
        u = self.unknowns
        return {a: u.free[u.map_slice(a)].copy() for a in u.map_axes}

    def maps_in_gauge(self, other: Parameters) -> dict[int, np.ndarray]:
        """Return ``other``'s encoder maps (e.g. the truth) in this calibration's gauge, rad.

        Axis -> values at the nodes, shape (n_nodes,). A map is identified only up to what the
        other parameters absorb (a constant: the axis offset, gamma0, the tool, DH errors). On the
        reached nodes (:attr:`node_reached`) the values are :meth:`equivalent`'s: the best this
        fit can return if ``other`` is the truth. On the others, which the fit holds at zero,
        they are ``other``'s own values moved by the same constant: the mean of equivalent minus
        ``other`` over the reached, identifiable nodes (0 if there are none), so a true error
        where no posture went is shown, not zero.
        """
        moved, _ = self.equivalent(other)
        reached, ok = self.node_reached, self.node_identifiable
        out = {}
        for a in self.unknowns.map_axes:
            own, eq = other.map(a).values, moved.map(a).values
            seen = reached[a] & ok[a]
            shift = float(np.mean(eq[seen] - own[seen])) if seen.any() else 0.0
            out[a] = np.where(reached[a], eq, own + shift)
        return out

    @property
    def keys(self) -> list[UnknownKey]:
        """What each entry of ``x`` is (typed; ``names`` are their strings), in order."""
        return [*self.unknowns.keys, *self.nuisance_keys]

    @property
    def std(self) -> dict[str, float]:
        """Standard uncertainty (k=1) of every estimated entry by name, SI."""
        return dict(zip(self.names, np.sqrt(np.clip(np.diag(self.covariance), 0, None))))

    def node_std(self, axis: int) -> np.ndarray:
        """Standard uncertainty of each node of a map (rad), NaN where not identified."""
        std = dict(zip(self.keys, np.sqrt(np.clip(np.diag(self.covariance), 0, None))))
        return np.array([std.get(NodeKey.at(axis, node), np.nan)
                         for node in np.degrees(self.parameters.map(axis).nodes)])

    @property
    def n_determined(self) -> int:
        """Number of arm parameter directions the data determines (unknowns less held rows)."""
        return max(len(self.unknowns.names) - ident.held_rank(self.constraints), 0)

    @property
    def fit_rms(self) -> float:
        """RMS of the residual coordinates of the samples kept (all but :attr:`outliers`), m."""
        kept = self.fun if self.inlier is None else self.fun[self.inlier]
        return float(np.sqrt(np.mean(kept ** 2)))

    @property
    def accuracy(self) -> float:
        """Accuracy per coordinate the calibration claims, m.

        :attr:`sigma` (the fit RMS with the dof of the determined parameters removed, or the stated
        noise), at least :attr:`fit_rms`: what :func:`aacmm_pin.validate` compares the bar
        readouts' socket scatter with.
        """
        return max(self.sigma, self.fit_rms)

    def fit_rms_by_location(self) -> dict[int, float]:
        """RMS of the residual coordinates per R-Test location (samples kept), m."""
        keep = np.ones(len(self.fun), bool) if self.inlier is None else self.inlier
        return {int(m): float(np.sqrt(np.mean(self.fun[(self.location == m) & keep] ** 2)))
                for m in np.unique(self.location[keep])}

    def group_label(self, group: int) -> str:
        """Return the name of a group id of :attr:`location`.

        ``"2"`` for R-Test location 2 (or points group 2 alone), ``"bar3A"`` for a bar socket,
        ``"group 2"`` for points of group 2 beside SPATs.
        """
        labels = {k.location: k.label for k in self.nuisance_keys
                  if isinstance(k, NestKey) and k.label}
        return labels.get(group, f"group {-group}" if group < 0 else str(group))

    def nest_offsets_um(self) -> dict[str, list[float]]:
        """Return the estimated offset of every R-Test nest from its measured zero position, um.

        Location -> [dx, dy, dz] in the MT-CS; empty when the nests were held at their measured
        positions. The measured centres plus these offsets are what the fit's residual is against.
        """
        n_arm = len(self.unknowns.names)
        out: dict[str, list[float]] = {}
        for key, value in zip(self.nuisance_keys, self.x[n_arm:]):
            if isinstance(key, NestKey) and not key.label:
                out.setdefault(str(key.location), []).append(float(value) * 1e6)
        return out

    def report(self) -> dict[str, Any]:
        """Return the ``report.json`` content."""
        return {
            "model": self.model,
            "use_rtest": self.use_rtest if "spat" in self.inputs else None,  # of SPATs alone
            "inputs": list(self.inputs),
            "nests": self.nests,
            "n_samples": int(len(self.fun)),
            "n_parameters": self.n_determined, "n_unknowns": int(len(self.x)),
            "fit_rms_um": self.fit_rms * 1e6,
            "fit_rms_um_by_location": {self.group_label(k): v * 1e6 for k, v in
                                       self.fit_rms_by_location().items()},
            "sigma_um": self.sigma * 1e6,
            "stated_noise_um": None if self.stated_noise is None else self.stated_noise.to_um(),
            "runtime_s": self.runtime_s, "success": self.success,
            "status": self.status, "message": self.message, "nfev": self.nfev,
            "unidentifiable": list(self.unidentifiable),
            "std": {n: float(s) for n, s in self.std.items()},
            "nest_offsets_um": self.nest_offsets_um(),
            "robust": self.robust,
            "outliers": [o.to_dict() for o in self.outliers],
            "suspects": [o.to_dict() for o in self.suspects],
        }

