r"""Identification of the arm from SPATs with the R-Test (paper Section 3.2, Eq. 3-6).

Unknowns: X0 (r-CS -> MT-CS rotation), the DH errors, the tool vector, and for the ``proposed``
model the encoder maps of the axes the data can see. Measured sphere position: R-Test zero position
plus R-Test displacement (Eq. 3); with ``use_rtest=False``, the location's mean displacement for
every sample (the conventional SPAT). Instead of differencing against a reference sample (Eq. 4, 6)
the translation between the frames is an unknown too: it removes the reference sample's noise from
every residual.

SciPy's ``least_squares`` minimises the residuals with the analytic, sparse Jacobian of
:class:`aacmm_pin.unknowns.Unknowns`; see :mod:`aacmm_pin.identifiability` for the rules on what the
data cannot determine.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.optimize import OptimizeResult
from tqdm.auto import tqdm

from aacmm_pin import identifiability as ident
from aacmm_pin.arm import Arm, load_arm
from aacmm_pin.campaign import Campaign, PointLog, SpatLog
from aacmm_pin.effects import Kind, Term
from aacmm_pin.errors import AacmmError
from aacmm_pin.kinematics import stylus_positions
from aacmm_pin.parameters import Parameters
from aacmm_pin.samples import Samples
from aacmm_pin.solver import Factor, Problem, SolverSettings
from aacmm_pin.units import SIGMA_LOCATION, SIGMA_POINT, SIGMA_RTEST, STEP_DEG
from aacmm_pin.unknowns import NestKey, NodeKey, UnknownKey, Unknowns

MODELS = ("dh", "proposed")


class IdentificationError(AacmmError):
    """The campaign cannot be identified (too few locations, no motion, non-finite values)."""


@dataclass(frozen=True)
class Calibration:
    """Result of :func:`identify`: the calibrated parameters and how well they are known."""

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
    """The solved least-squares problem (structure and preconditioner), for :func:`refit`."""
    settings: SolverSettings = field(repr=False)
    """Solver settings (loss, f_scale, max_nfev) for :func:`refit`."""

    def equivalent(self, other: Parameters) -> tuple[Parameters, float]:
        """Return ``other`` (e.g. the truth) moved into this calibration's gauge and held values.

        See :func:`aacmm_pin.identifiability.equivalent_vector`. Returns the parameters and the RMS
        change of the predictions on the campaign's postures (m).
        """
        full = self.unknowns.with_free(np.ones_like(self.unknowns.free))
        _, jac = full.jacobian(full.full_vector(self.parameters), self.q)
        vec, rms = ident.equivalent_vector(self.unknowns, jac.sparse(), self.constraints,
                                           full.full_vector(other))
        return full.parameters(vec), rms

    @property
    def keys(self) -> list[UnknownKey]:
        """What each entry of ``x`` is (typed; ``names`` are their strings), in order."""
        return [*self.unknowns.keys, *(nest_keys(self.location) if self.problem.n_loc else [])]

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
        return int(len(self.unknowns.names) - self.constraints.shape[0])

    @property
    def fit_rms(self) -> float:
        """RMS of the residual coordinates, m."""
        return float(np.sqrt(np.mean(self.fun ** 2)))

    def fit_rms_by_location(self) -> dict[int, float]:
        """RMS of the residual coordinates per R-Test location, m."""
        return {int(m): float(np.sqrt(np.mean(self.fun[self.location == m] ** 2)))
                for m in np.unique(self.location)}

    def report(self) -> dict[str, Any]:
        """Return the ``report.json`` content."""
        return {
            "model": self.model, "use_rtest": self.use_rtest, "n_samples": int(len(self.fun)),
            "n_parameters": self.n_determined, "n_unknowns": int(len(self.x)),
            "fit_rms_um": self.fit_rms * 1e6,
            "fit_rms_um_by_location": {str(k): v * 1e6 for k, v in
                                       self.fit_rms_by_location().items()},
            "sigma_um": self.sigma * 1e6, "runtime_s": self.runtime_s, "success": self.success,
            "status": self.status, "message": self.message, "nfev": self.nfev,
            "unidentifiable": list(self.unidentifiable),
            "std": {n: float(s) for n, s in self.std.items()},
        }


def nest_keys(location: np.ndarray) -> list[NestKey]:
    """Return the keys of the nest offsets (3 per R-Test location, in location order)."""
    return [NestKey(int(m), c) for m in np.unique(location) for c in "xyz"]


def measured_positions(campaign: Campaign, use_rtest: bool = True) -> np.ndarray:
    """Return the measured sphere centres in the MT-CS (Eq. 3), shape (N, 3), m."""
    spat = campaign.spat
    assert spat is not None
    disp = spat.displacement.copy()
    if not use_rtest:
        for m in np.unique(spat.location):
            sel = spat.location == m
            disp[sel] = disp[sel].mean(axis=0)
    measured: np.ndarray = np.array([campaign.locations[int(m)] for m in spat.location]) + disp
    return measured


def check_campaign(campaign: Campaign, arm: Arm) -> SpatLog:
    """Return the campaign's SPAT log, or raise IdentificationError if it cannot be identified."""
    spat = campaign.spat
    if spat is None or len(spat.location) == 0:
        raise IdentificationError("the campaign has no SPAT samples (spat.csv)")
    if spat.q.shape[1] != arm.n_axes:
        raise IdentificationError(f"the campaign has {spat.q.shape[1]} axes, the arm "
                                  f"{arm.n_axes} ({arm.source})")
    bad = [name for name, arr in (("readouts", spat.q), ("displacements", spat.displacement),
                                  ("locations", np.array(list(campaign.locations.values()))))
           if not np.all(np.isfinite(arr))]
    if bad:
        raise IdentificationError(f"non-finite values (NaN or inf) in the {', '.join(bad)}")
    ids = np.unique(spat.location)
    if ids.size < 2:
        raise IdentificationError(
            f"the campaign has one R-Test location ({ids[0]}): SPATs at a single point cannot fix "
            "the arm's scale or its orientation in the MT-CS; measure at 2 or more locations "
            "(the paper uses 4)")
    for m in ids:
        q = spat.q[spat.location == m]
        if np.ptp(q, axis=0).max() < 1e-6:
            raise IdentificationError(
                f"all {len(q)} postures at location {m} are identical: a SPAT needs the arm moved "
                "through many postures with the stylus in the nest")
    return spat


def check_points(campaign: Campaign, arm: Arm) -> PointLog:
    """Return the campaign's absolute points, or raise IdentificationError if they cannot be used.

    One instrument frame (``group``) is identified with the arm (as X0 and the translation).
    """
    points = campaign.points
    if points is None or len(points.group) == 0:
        raise IdentificationError("the campaign has no absolute points (points.csv)")
    if points.q.shape[1] != arm.n_axes:
        raise IdentificationError(f"the campaign has {points.q.shape[1]} axes, the arm "
                                  f"{arm.n_axes} ({arm.source})")
    if not (np.all(np.isfinite(points.q)) and np.all(np.isfinite(points.point))):
        raise IdentificationError("non-finite values (NaN or inf) in the points or readouts")
    _check_point_tools(points, arm, "points.csv" if campaign.source is None
                       else str(campaign.source / "points.csv"))
    groups = np.unique(points.group)
    if groups.size != 1:
        raise IdentificationError(
            f"points.csv has {groups.size} groups ({', '.join(str(g) for g in groups)}): one "
            "instrument frame per identification is supported; identify each group on its own")
    if np.linalg.matrix_rank(points.point - points.point.mean(axis=0), tol=1e-4) < 3:
        raise IdentificationError("the measured points lie on a line or a plane: they cannot fix "
                                  "the instrument's frame")
    return points


def _check_point_tools(points: PointLog, arm: Arm, path: str) -> None:
    """Raise IdentificationError if the points' tools are missing (several tools) or unknown."""
    listing = ", ".join(arm.tool_names)
    if points.tool is None:
        if arm.n_tools > 1:
            raise IdentificationError(f"{path}: line 1: column 'tool': missing; the arm has "
                                      f"{arm.n_tools} tools ({listing}): say which one each point "
                                      "measures")
        return
    known = set(arm.tool_names) | set(arm.tool_joints)
    bad = [k for k, name in enumerate(points.tool.tolist()) if name not in known]
    if bad:
        k = bad[0]
        line = f"line {points.lines[k]}" if points.lines is not None else f"row {k + 1}"
        raise IdentificationError(f"{path}: {line}: column 'tool': unknown tool "
                                  f"'{points.tool[k]}' ({len(bad)} such points); the arm's tools: "
                                  f"{listing}")


class Measurements(NamedTuple):
    """What an identification fits: one row per sample."""

    q: np.ndarray
    """Readouts, shape (N, n), rad."""
    measured: np.ndarray
    """Measured points, shape (N, 3), m (sphere centres in the MT-CS, or tool points)."""
    group: np.ndarray
    """R-Test location or instrument group of each sample, shape (N,)."""
    nests: bool
    """Whether each group is an R-Test nest whose offset is estimated."""
    samples: Samples
    """What effects depend on, per sample."""
    sigma: np.ndarray | None
    """Stated noise of each sample per coordinate, shape (N,), m, or None."""


def measurements(campaign: Campaign, arm: Arm, use_rtest: bool) -> Measurements:
    """Return what an identification of ``campaign`` fits (checked; see :class:`Measurements`).

    SPAT campaigns: the measured sphere centres (Eq. 3), the R-Test locations, whose nest offsets
    are estimated. Point campaigns (no SPAT): the measured tool points and their instrument group.
    """
    if campaign.spat is not None or campaign.points is None:
        spat = check_campaign(campaign, arm)
        return Measurements(spat.q, measured_positions(campaign, use_rtest), spat.location, True,
                            Samples.of_spat(arm, spat), None)
    points = check_points(campaign, arm)
    return Measurements(points.q, points.point, points.group, False, Samples.of_log(arm, points),
                        points.sigma)


def _initial_frame(arm: Arm, start: Parameters, q: np.ndarray, measured: np.ndarray,
                   group: np.ndarray, samples: Samples) -> Parameters:
    """Return start parameters with X0 and translation from a Kabsch fit of the group centres."""
    ids = np.unique(group)
    pred = stylus_positions(arm, start, q, frame="r", samples=samples)
    if ids.size > 1:
        p_r = np.array([pred[group == m].mean(axis=0) for m in ids])
        p_mt = np.array([measured[group == m].mean(axis=0) for m in ids])
    else:  # one group of absolute points: every point
        p_r, p_mt = pred, measured
    a, b = p_r - p_r.mean(axis=0), p_mt - p_mt.mean(axis=0)
    if len(p_r) < 3 or np.linalg.matrix_rank(a, tol=1e-3) < 2:
        return start.replace(translation=p_mt.mean(axis=0) - p_r.mean(axis=0))
    u, _, vt = np.linalg.svd(b.T @ a)
    rot = u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt  # maps r-CS to MT-CS
    # rot = Ry(beta) Rx(alpha) Rz(gamma): row 1 is (ca sg, ca cg, -sa)
    alpha = np.arctan2(-rot[1, 2], np.hypot(rot[1, 0], rot[1, 1]))
    gamma = np.arctan2(rot[1, 0], rot[1, 1])
    beta = np.arctan2(rot[0, 2], rot[2, 2])
    return start.replace(rotation_abc=[alpha, beta, gamma],
                         translation=p_mt.mean(axis=0) - rot @ p_r.mean(axis=0))


def identify(campaign: Campaign, arm: Arm | None = None, model: str = "proposed",
             use_rtest: bool = True, *, start: Parameters | None = None, step_deg: float = STEP_DEG,
             map_axes: tuple[int, ...] | None = None, loss: str = "linear",
             f_scale: float | None = None, sigma: float | None = None,
             sigma_location: float = SIGMA_LOCATION, max_nfev: int = 200, jac: str = "analytic",
             progress: bool = False, extensions: tuple[Term, ...] = ()) -> Calibration:
    """Identify the arm's parameters from the SPATs of a campaign.

    Args:
        campaign: campaign with SPAT samples and R-Test zero positions, or (without SPAT) with
            absolute tool points (``points.csv``, one instrument frame identified as X0 and the
            translation; no nest offsets).
        arm: the arm (default: the embedded default arm).
        model: ``"dh"`` (X0, DH errors, tool) or ``"proposed"`` (also the encoder maps).
        use_rtest: use each sample's R-Test displacement (True) or each location's mean (False).
        start: start values (default: the URDF's nominal values; X0 and translation from a fit of
            the location centres).
        step_deg: map node step, deg.
        map_axes: axes whose maps are estimated (default: all, for ``proposed``).
        loss: scipy loss, e.g. ``"linear"``, ``"soft_l1"``, ``"huber"`` (robust to outliers).
        f_scale: residual scale of a robust loss, m (default 3 x sigma).
        sigma: R-Test noise per coordinate, m; None estimates it from the residuals.
        sigma_location: standard uncertainty of each R-Test zero position per coordinate, m
            (paper Section 5: 3 um); each nest's offset is estimated with this prior.
        max_nfev: most residual evaluations per solve, a cap well above what a solve needs to
            reach its tolerance (``nfev`` reports what was used; not converged within it:
            ``success`` False).
        jac: ``"analytic"`` (Pinocchio, sparse in the map nodes) or a scipy finite-difference
            scheme (``"2-point"``, ``"3-point"``) on the same problem, for comparison.
        progress: show a progress bar.
        extensions: further terms of the effect library (:mod:`aacmm_pin.effects`) to estimate
            (angle, scale or measurement kind; map terms are ``map_axes``).

    Returns:
        The calibration; ``success`` is False (with a message) when the solver did not converge.

    Raises:
        IdentificationError: for campaigns that cannot be identified.
        ValueError: for an unknown ``model``.
    """
    if jac not in ("analytic", "2-point", "3-point", "cs"):
        raise ValueError(f"jac: choose 'analytic', '2-point' or '3-point', got {jac!r}")
    if model not in MODELS:
        raise ValueError(f"model: choose from {', '.join(MODELS)}, got {model!r}")
    tic = time.perf_counter()
    arm = arm or load_arm()
    q, measured, group, nests, samples, stated = measurements(campaign, arm, use_rtest)
    start = start or _initial_frame(arm, Parameters.nominal(arm, step_deg), q, measured, group,
                                    samples)
    axes = tuple(range(1, arm.n_axes + 1)) if map_axes is None else tuple(map_axes)
    unknowns = Unknowns.full(arm, start, axes if model == "proposed" else (),
                             tuple(t for t in extensions if t.kind is not Kind.MAP), samples)
    unvisited = ident.unvisited_nodes(unknowns, q)
    unknowns = unknowns.with_fixed(unvisited)
    x_arm = unknowns.vector(start)
    _, jac_now = unknowns.jacobian(x_arm, q)
    gauges = ident.gauge_axes(unknowns, jac_now)
    gauge = ident.gauge_rows(unknowns, gauges)
    sigma_class = sigma or (SIGMA_RTEST if nests else SIGMA_POINT if stated is None
                            else float(np.median(stated)))
    n = len(q)
    scale = f_scale or 3 * sigma_class
    x_loc = np.zeros(3 * np.unique(group).size if nests else 0)
    nfev = 0
    settings = SolverSettings(loss=loss, f_scale=scale, max_nfev=max_nfev)
    with tqdm(total=2 * max_nfev, desc=f"identify {model}", unit="eval",
              disable=not progress, leave=False) as bar:
        held = -1
        for _round in range(3):  # observability at the start, then at the solution
            obs = ident.observability(unknowns, jac_now, gauge, sigma_class)
            if obs.hold.shape[0] == held:
                break
            held = obs.hold.shape[0]
            used = obs  # the observability the constraints (and the results below) come from
            constraints = sp.csr_matrix(sp.vstack([gauge, obs.hold_rows()]))
            x_start = np.concatenate([unknowns.vector(start), np.zeros_like(x_loc)])
            x_now = np.concatenate([x_arm, x_loc])
            problem = Problem(unknowns, q, measured, group if nests else None, constraints, obs.scale,
                              x_start, x_now, sigma_class, sigma_location,
                              None if stated is None else sigma_class / stated)
            z0 = problem.z(x_now)
            res = problem.solve(z0, settings, jac, on_evaluation=bar.update)
            nfev += res.nfev
            x_full = problem.x(res.x)
            x_arm, x_loc = x_full[:problem.n_arm], x_full[problem.n_arm:]
            _, jac_now = unknowns.jacobian(x_arm, q)

    obs = used
    data_res = res.fun[:3 * n]  # weighted: the noise in units of sigma_class
    residual = data_res if problem.row_weight is None else data_res / problem.row_weight
    sig = _sigma(data_res, problem.n_arm - obs.hold.shape[0] - len(gauges), sigma)
    covariance = problem.covariance(x_full, sig)
    names = unknowns.names + [str(k) for k in (nest_keys(group) if nests else [])]
    params = unknowns.parameters(x_arm)
    lines = ident.describe(unknowns, unvisited, obs)
    if gauges:
        lines.append("map constants: " + ", ".join(f"A{a}" for a in gauges) + " maps have zero "
                     "mean over their free nodes; a constant encoder error is indistinguishable "
                     "from the axis offset (dth), gamma0 (A1), the tool (A7) or DH errors, which "
                     "carry it")
    identifiable = np.zeros_like(unvisited)
    identifiable[np.flatnonzero(unknowns.free)] = obs.identifiable
    final_u = unknowns
    node_ok = {a: identifiable[final_u.map_slice(a)].copy() for a in final_u.map_axes}
    success = bool(res.success)  # the last round's: earlier ones only set the held directions
    message = res.message if success else f"did not converge: {res.message}"
    return Calibration(parameters=params, model=model, use_rtest=use_rtest, names=names,
                       x=x_full, covariance=covariance, sigma=sig,
                       fun=residual.reshape(n, 3), location=group.copy(), success=success,
                       status=int(res.status), message=str(message),
                       nfev=int(nfev), unidentifiable=lines, node_identifiable=node_ok,
                       runtime_s=time.perf_counter() - tic,
                       raw=OptimizeResult({k: v for k, v in res.items() if k != "jac"}),
                       unknowns=final_u,
                       constraints=constraints, identifiable=obs.identifiable, q=q,
                       problem=problem, settings=settings)


def _sigma(data_residuals: np.ndarray, n_params: int, given: float | None) -> float:
    """Return the given noise, or the residual-based estimate sqrt(SSR / (m - p))."""
    if given is not None:
        return float(given)
    dof = max(data_residuals.size - n_params, 1)
    return float(np.sqrt(np.sum(data_residuals ** 2) / dof))


def refit(cal: Calibration, measured: np.ndarray, iterations: int = 10,
          factor: Factor | None = None) -> tuple[np.ndarray, bool]:
    """Re-identify with other measured sphere centres, keeping the calibration's structure.

    The unknowns, gauges, held directions and preconditioner of ``cal`` are kept and the solve
    starts from its solution: what a Monte Carlo trial needs. Gauss-Newton steps on the nonlinear
    residual with the Jacobian at the calibration's solution (factored once: pass ``factor`` from
    ``cal.problem.factor(cal.problem.z(cal.x))`` to share it between trials) until the step is
    below 1e-12 of the reduced scale; ``least_squares`` takes over where that does not converge
    (or for a robust loss).

    Args:
        cal: a calibration from :func:`identify`.
        measured: measured sphere centres in the MT-CS, shape (N, 3), m (e.g. perturbed).
        iterations: most Gauss-Newton steps.
        factor: the factored Jacobian at the calibration's solution (computed when None).

    Returns:
        The full solution vector (arm entries then nest offsets, as ``cal.x``) and whether it
        converged.
    """
    problem = cal.problem.with_measured(measured)
    z = problem.z(cal.x)
    if cal.settings.loss == "linear" and problem.dense(z.size):
        z_gn, ok = problem.gauss_newton(z, cal.problem.factor(z) if factor is None else factor, iterations)
        if ok:
            return problem.x(z_gn), True
        z = z_gn
    res = problem.solve(z, cal.settings)
    return problem.x(res.x), bool(res.success)
