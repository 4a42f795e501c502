r"""Identification of the arm from SPATs with the R-Test (paper Section 3.2, Eq. 3-6): the fit.

Unknowns: X0 (r-CS -> MT-CS rotation), the DH errors, the tool vector, and for the ``proposed``
model the encoder maps of the axes the data can see. Measured sphere position: R-Test zero position
plus R-Test displacement (Eq. 3); with ``use_rtest=False``, the location's mean displacement for
every sample (the conventional SPAT). Instead of differencing against a reference sample (Eq. 4, 6)
the translation between the frames is an unknown too: it removes the reference sample's noise from
every residual.

SciPy's ``least_squares`` minimises the residuals with the analytic, sparse Jacobian of
:class:`aacmm_pin.fit.unknowns.Unknowns`; see :mod:`aacmm_pin.fit.identifiability` for the rules on what the
data cannot determine. What is fitted and its stated noise are :mod:`aacmm_pin.fit.measurements`; the
result, :class:`~aacmm_pin.fit.identification_result.Calibration`, is
:mod:`aacmm_pin.fit.identification_result`. Here: :func:`identify` (its options one
:class:`FitOptions`), the rounds that decide the held directions and solve, the robust loop, the
nuisance unknowns (nests, instrument frames) and :func:`refit`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
from scipy.optimize import OptimizeResult
from scipy.special import chdtrc

from aacmm_pin._blas import single_threaded_blas
from aacmm_pin.data.campaign import Campaign, StatedNoise
from aacmm_pin.effects.base import Term
from aacmm_pin.effects.calibrated import stylus_positions
from aacmm_pin.effects.term_axes import check_terms
from aacmm_pin.fit import identifiability as ident
from aacmm_pin.fit import plausibility
from aacmm_pin.fit import robust as rob
from aacmm_pin.fit.fit_rounds import Fit, fit_rounds, reject_outliers
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.fit.measurements import Measurements, measurements, stated_noise
from aacmm_pin.fit.noise_judgement import (
    MAX_POINTS_FIT_RMS,
    NOISE_P,
    Judgement,
    judge_residual,
    p_text,
)
from aacmm_pin.fit.robust import Outlier
from aacmm_pin.fit.solver import Factor, Nuisance, Problem, SolverSettings
from aacmm_pin.fit.solver_values import Budget, BudgetSpent, Counted
from aacmm_pin.fit.unknowns import FrameKey, NestKey, UnknownKey, Unknowns
from aacmm_pin.model.arm import Arm, load_arm
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.progress import Progress
from aacmm_pin.units import (
    SIGMA_BAR,
    STEP_DEG,
    noise_problem,
)

__all__ = ["MAX_FIT_RMS", "MAX_NFEV_PER_SOLVE", "MIN_DOF_FRACTION", "MODELS", "NESTS", "NOISE_P",
           "FitOptions", "identify", "refit"]

MODELS = ("dh", "proposed")
MAX_NFEV_PER_SOLVE = 200
"""Most residual evaluations of one solve of a fit when no cap of the whole fit is given."""
NESTS = ("auto", "estimate", "fixed")
"""How :func:`identify` treats the R-Test nests' offsets."""
MIN_DOF_FRACTION = 0.1
"""An identification whose degrees of freedom are fewer than this fraction of its residual
coordinates reports ``success`` False: its residual cannot estimate the noise."""
MIN_NOISE_RATIO = 0.1
"""A fit with a stated noise (``sigma``) whose residual's noise estimate is below this fraction
of it reports ``success`` False: a noise stated ten times what the measurements scatter lets the
plausible sizes outweigh them (fewer parameters determined) and widens every uncertainty as
many times."""
MAX_FIT_RMS = 0.2e-3
"""A fit of R-Test SPATs whose RMS residual exceeds this (m) reports ``success`` False: no
articulated arm CMM leaves that after calibration, so the inputs disagree (units, R-Test zero
positions, readouts). Fits of absolute points alone (robots on a laser tracker: a DH model leaves
1 mm on real UR5 and WAM data) are not judged by it but by
:data:`~aacmm_pin.fit.noise_judgement.MAX_POINTS_FIT_RMS`; every fit's residual is judged against
its stated noise (:mod:`aacmm_pin.fit.noise_judgement`)."""


@dataclass(frozen=True)
class FitOptions:
    """How :func:`identify` fits: its keyword arguments, checked once (see there)."""

    model: str = "proposed"
    """``"dh"`` or ``"proposed"``."""
    use_rtest: bool = True
    """Each sample's R-Test displacement (True) or each location's mean (False)."""
    start: Parameters | None = None
    """Start values; None: nominal, X0 and translation fitted to the location centres."""
    step_deg: float = STEP_DEG
    """Map node step, deg."""
    map_axes: tuple[int, ...] | None = None
    """Axes whose maps are estimated (None: all, for ``proposed``)."""
    loss: str = "linear"
    """scipy loss of every solve."""
    f_scale: float | None = None
    """Residual scale of a robust loss, m (None: 3 x the solve's sigma)."""
    sigma: float | None = None
    """Noise per coordinate of the campaign's main kind (R-Test readings, else points without a
    ``sigma_um`` column), m; None: :attr:`noise`'s."""
    sigma_location: float | None = None
    """Prior standard deviation of each R-Test zero position per coordinate, m; None:
    :attr:`noise`'s."""
    noise: StatedNoise | None = None
    """The stated noise per kind of measurement; None: the campaign's (``campaign.json``: its
    ``noise_um``, else its instrument's), else the defaults. Every solve weighs its rows and
    priors with it and the residual is judged against it (:func:`solve_noise`)."""
    max_nfev: int | None = None
    """Most residual evaluations of the whole fit (every solve of it together); None: each solve
    stops after :data:`MAX_NFEV_PER_SOLVE` (see :attr:`solve_nfev`)."""
    jac: str = "analytic"
    """``"analytic"`` or a scipy finite-difference scheme."""
    progress: bool = False
    """Show progress."""
    extensions: tuple[Term, ...] = ()
    """Further terms of the effect library to estimate."""
    use_bar: bool = False
    """Fit the length-bar readouts too."""
    robust: bool = False
    """Reject outliers."""
    nests: str = "auto"
    """The R-Test nests' offsets: ``"auto"``, ``"estimate"`` or ``"fixed"``."""

    @property
    def solve_nfev(self) -> int:
        """Most residual evaluations of one solve: ``max_nfev``, else :data:`MAX_NFEV_PER_SOLVE`."""
        return MAX_NFEV_PER_SOLVE if self.max_nfev is None else self.max_nfev

    def __post_init__(self) -> None:
        if self.jac not in ("analytic", "2-point", "3-point", "cs"):
            raise ValueError(f"jac: choose 'analytic', '2-point' or '3-point', got {self.jac!r}")
        if self.model not in MODELS:
            raise ValueError(f"model: choose from {', '.join(MODELS)}, got {self.model!r}")
        for name, value in (("sigma", self.sigma), ("sigma_location", self.sigma_location)):
            if value is not None and (why := noise_problem(value)) is not None:
                raise ValueError(f"{name}: {why}")
        if self.nests not in NESTS:
            raise ValueError(f"nests: choose from {', '.join(NESTS)}, got {self.nests!r}")


def _kabsch(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return R (3, 3), t (3,) minimising |R a + t - b| over point pairs a, b (N, 3)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((b - cb).T @ (a - ca))
    rot = u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt
    return rot, cb - rot @ ca


def _initial_frame(arm: Arm, start: Parameters, q: np.ndarray, measured: np.ndarray,
                   group: np.ndarray, tool: np.ndarray | None) -> Parameters:
    """Return start parameters with X0 and translation from a Kabsch fit of the group centres.

    ``tool``: the tool index of every sample, shape (N,), or None (the arm's only tool).
    """
    ids = np.unique(group)
    pred = stylus_positions(arm, start, q, frame="r", tool=tool)
    if ids.size > 1:
        p_r = np.array([pred[group == m].mean(axis=0) for m in ids])
        p_mt = np.array([measured[group == m].mean(axis=0) for m in ids])
    else:  # one group of absolute points: every point
        p_r, p_mt = pred, measured
    a = p_r - p_r.mean(axis=0)
    if len(p_r) < 3 or np.linalg.matrix_rank(a, tol=1e-3) < 2:
        return start.replace(translation=p_mt.mean(axis=0) - p_r.mean(axis=0))
    rot, trans = _kabsch(p_r, p_mt)  # maps r-CS to MT-CS
    # rot = Ry(beta) Rx(alpha) Rz(gamma): row 1 is (ca sg, ca cg, -sa)
    alpha = np.arctan2(-rot[1, 2], np.hypot(rot[1, 0], rot[1, 1]))
    gamma = np.arctan2(rot[1, 0], rot[1, 1])
    beta = np.arctan2(rot[0, 2], rot[2, 2])
    return start.replace(rotation_abc=[alpha, beta, gamma], translation=trans)


def _without_rtest_nests(meas: Measurements) -> Measurements:
    """Return the measurements with the R-Test nests held at their measured positions.

    The R-Test locations' offsets are no longer unknowns (their samples keep their measured zero
    positions); other nests (length-bar sockets, whose positions are unknown) stay.
    """
    if meas.nest is None:
        return meas
    keep = meas.nest_sigma > 0  # R-Test nests carry 0: their prior is sigma_location
    index = np.cumsum(keep) - 1
    nest = np.where((meas.nest >= 0) & keep[np.maximum(meas.nest, 0)], index[meas.nest], -1)
    lengths = meas.lengths.copy()
    lengths[:, :2] = index[lengths[:, :2].astype(int)]
    return meas._replace(nest=nest if keep.any() else None, nest_sigma=meas.nest_sigma[keep],
                         nest_keys=tuple(k for k, on in zip(meas.nest_keys, keep) if on),
                         lengths=lengths)


def _nuisance(arm: Arm, start: Parameters, meas: Measurements, sigma_class: float,
              sigma_location: float) -> tuple[Nuisance, np.ndarray, list[UnknownKey]]:
    """Return the problem's nests, frames and lengths, measured points and nuisance keys.

    The measured points are completed with the bar sockets' start positions (the mean of their
    readouts' start-model points); the frames start from a Kabsch fit to the start model.
    """
    measured = meas.measured.copy()
    socket = np.isnan(measured[:, 0])
    frame_start = np.zeros((len(meas.frame_groups), 3, 4))
    if socket.any() or meas.frame_groups:
        pred = stylus_positions(arm, start, meas.q, frame="mt", samples=meas.samples)
        if meas.nest is not None:  # sockets are nests
            for j in np.unique(meas.nest[socket]):
                rows = meas.nest == j
                measured[rows] = pred[rows].mean(axis=0)
        if meas.frame is not None:  # frame_groups come with a frame per sample
            for f in range(len(meas.frame_groups)):
                rows = meas.frame == f
                rot, trans = _kabsch(measured[rows], pred[rows])
                frame_start[f] = np.column_stack([rot, trans])
    nest_sigma = np.where(meas.nest_sigma > 0, meas.nest_sigma, sigma_location)
    keys: list[UnknownKey] = [NestKey(m, c, label) for m, label in meas.nest_keys for c in "xyz"]
    keys += [FrameKey(g, c) for g in meas.frame_groups for c in ("rx", "ry", "rz", "tx", "ty", "tz")]
    nuisance = Nuisance(nest=meas.nest, nest_sigma=nest_sigma, frame=meas.frame,
                        frame_start=frame_start, lengths=meas.lengths,
                        length_weight=sigma_class / SIGMA_BAR)
    return nuisance, measured, keys

def identify(campaign: Campaign, arm: Arm | None = None, model: str = "proposed",
             use_rtest: bool = True, *, start: Parameters | None = None, step_deg: float = STEP_DEG,
             map_axes: tuple[int, ...] | None = None, loss: str = "linear",
             f_scale: float | None = None, sigma: float | None = None,
             sigma_location: float | None = None, noise: StatedNoise | None = None,
             max_nfev: int | None = None,
             jac: str = "analytic",
             progress: bool = False, extensions: tuple[Term, ...] = (),
             use_bar: bool = False, robust: bool = False, nests: str = "auto") -> Calibration:
    """Identify the arm's parameters from the SPATs of a campaign.

    The keyword arguments are checked once into a :class:`FitOptions`, which every fit receives.

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
        map_axes: axes whose maps are estimated (default: all with an encoder, for ``proposed``).
        loss: scipy loss of every solve, e.g. ``"linear"`` (default). For outliers use ``robust``:
            scipy's ``"soft_l1"`` / ``"huber"`` weigh coordinates, not samples, with a fixed
            scale, and do not reach their tolerance on these problems.
        f_scale: residual scale of a scipy robust loss, m (default 3 x sigma).
        sigma: noise per coordinate of the campaign's main kind (R-Test readings, else points
            without a ``sigma_um`` column), m, stated (not estimated); None: ``noise``'s, and the
            noise is estimated from the residuals.
        sigma_location: standard uncertainty of each R-Test zero position per coordinate, m
            (default: ``noise``'s, paper Section 5: 3 um); each nest's offset is estimated with
            this prior.
        noise: the stated noise per kind of measurement (default: the campaign's
            ``campaign.json``, else the defaults); ``sigma`` and ``sigma_location`` override its
            R-Test (or point) and nest values.
        max_nfev: most residual evaluations of the whole fit (the rounds, the robust passes and
            the refit with fixed nests together: ``nfev`` reports what was used; not converged
            within it: ``success`` False, ``status`` 0, the message names the cap). None: no cap
            on the whole fit, each solve stops at its tolerance or after
            :data:`MAX_NFEV_PER_SOLVE` evaluations (a robust fit makes up to a dozen solves).
        jac: ``"analytic"`` (Pinocchio, sparse in the map nodes) or a scipy finite-difference
            scheme (``"2-point"``, ``"3-point"``) on the same problem, for comparison.
        progress: show progress (evaluations and residual RMS; log lines when stderr is not a
            terminal).
        extensions: further terms of the effect library (:mod:`aacmm_pin.effects`) to estimate
            (angle, scale or measurement kind; map terms are ``map_axes``).
        nests: the R-Test nests' offsets: ``"estimate"`` (each with the prior
            ``sigma_location``), ``"fixed"`` (held at the measured positions) or ``"auto"``:
            estimated only when the model's residual matches the stated R-Test noise (chi-square,
            p >= 0.001; ``sigma`` or 2 um), else fixed, since the offsets of an incomplete model
            take up its error (the choice and why are in :attr:`Calibration.nests`).
        use_bar: fit the length-bar readouts too (a calibration input, not only a check): every
            socket's position is estimated from its readouts and the calibrated distances
            between a placement's sockets are residuals (stated noise per readout coordinate:
            ``campaign.json``'s socket, else ``units.SIGMA_SOCKET``; ``units.SIGMA_BAR`` per
            length).
        robust: reject outliers (:mod:`aacmm_pin.fit.robust`): iteratively reweighted least squares,
            Huber then hard rejection of every sample (its three coordinates together) whose
            whitened residual norm exceeds ``robust.OUTLIER_K`` robust sigmas; they are listed in
            ``outliers`` and left out of the final fit, its noise and its covariance. Without
            it, such samples are listed in ``suspects`` and named in ``message`` (``success``
            stays the solver's: the DH model on an arm with encoder errors has such residuals on
            clean data, and they are not a failure to converge).

    Returns:
        The calibration; ``success`` is False (with a message) when the solver did not converge
        or the robust fit's outlier set did not settle.

    Raises:
        IdentificationError: for campaigns that cannot be identified.
        ValueError: for an unknown ``model``, or a ``sigma`` / ``sigma_location`` not > 0.
        ArgumentError: for an extension term on an axis beyond the arm (one line naming it).
    """
    options = FitOptions(model=model, use_rtest=use_rtest, start=start, step_deg=step_deg,
                         map_axes=map_axes, loss=loss, f_scale=f_scale, sigma=sigma,
                         sigma_location=sigma_location, noise=noise, max_nfev=max_nfev, jac=jac,
                         progress=progress, extensions=extensions, use_bar=use_bar,
                         robust=robust, nests=nests)
    # every evaluation of every fit below (none given: each solve's own cap only)
    budget = None if max_nfev is None else Budget(max_nfev)
    arm = arm or load_arm()
    check_terms(extensions, arm, "extensions")
    with single_threaded_blas():  # products of a few hundred columns: BLAS threads only spin
        cal = _identify(campaign, arm, options, budget, fixed_nests=nests == "fixed")
        rtest_nests = "spat" in cal.inputs
        if not rtest_nests:
            return cal
        if nests != "auto":
            return replace(cal, nests=f"{nests} (asked)")
        p_value, ratio = _noise_consistency(cal, solve_noise(campaign, options).rtest)
        if p_value >= NOISE_P:
            return replace(cal, nests=f"estimated: the fit's residual matches the stated R-Test "
                                      f"noise (RMS {ratio:.2f} x, p = {p_value:.2g})")
        if budget is not None and budget.spent:
            return cal  # no evaluation left for the refit with fixed nests: it did not converge
        try:
            fixed = _identify(campaign, arm, options, budget, fixed_nests=True)
        except BudgetSpent:
            return replace(cal, success=False, status=0, message=_budget_message(options))
        return replace(fixed, nests=(
            f"fixed at their measured positions: the model's residual is {ratio:.1f} x the stated "
            f"R-Test noise (p = {p_value:.2g}), so nest offsets estimated with it would take up "
            "model error"))


def _noise_consistency(cal: Calibration, stated: float) -> tuple[float, float]:
    """Return the chi-square p-value of the residual against the stated noise, and RMS/noise.

    ``stated``: the R-Test noise per coordinate, m; other kinds (points, bar sockets) count with
    their own stated noise relative to it (the row weights). Degrees of freedom: the residual
    coordinates less the determined parameters.
    """
    res = cal.fun.ravel() / stated
    if cal.problem.row_weight is not None:  # weight = (the solve's sigma) / (the row's noise)
        res = res * cal.problem.row_weight * stated / cal.problem.sigma_class
    if cal.inlier is not None:  # rejected outliers are not the model's residual
        res = res[np.repeat(cal.inlier, 3)]
    dof = max(res.size - cal.n_determined, 1)
    stat = float(np.sum(res ** 2))
    return float(chdtrc(dof, stat)), float(np.sqrt(stat / res.size))  # = scipy.stats.chi2.sf

class _Setup(NamedTuple):
    """What every fit of one identification shares."""

    meas: Measurements
    """The measurements (R-Test nests dropped when they are held fixed)."""
    full_u: Unknowns
    """Every unknown of the model, before the unvisited nodes are fixed."""
    start: Parameters
    """Start values."""
    has_spat: bool
    """Whether SPATs are fitted."""
    sigma_class: float
    """The noise per coordinate the solves assume, m (a row of weight 1 has it)."""
    stated: np.ndarray | None
    """Stated noise of every sample, shape (N,), m (:func:`~aacmm_pin.fit.measurements.stated_noise`);
    None: every sample has ``sigma_class`` and the rows are not weighted."""
    base_w: np.ndarray
    """Weight of every sample, ``sigma_class / stated``, shape (N,)."""
    nuisance: Nuisance
    """Nests, instrument frames and length rows."""
    measured: np.ndarray
    """Measured points, bar sockets at their start positions, shape (N, 3), m."""
    nuisance_keys: list[UnknownKey]
    """What each entry after the arm's is."""
    settings: SolverSettings
    """How every solve minimises."""
    sources: tuple[list[str], np.ndarray, np.ndarray]
    """The campaign file (the kind), line and log row of every sample (:func:`rob.sample_sources`)."""
    noise: StatedNoise
    """The stated noise per kind the solves use (:func:`solve_noise`)."""


def _identify(campaign: Campaign, arm: Arm, options: FitOptions, budget: Budget | None,
              fixed_nests: bool) -> Calibration:
    """One identification with the R-Test nests' offsets estimated or held (``fixed_nests``).

    ``budget``: the evaluations left to the whole fit (None: ``max_nfev`` per solve only).
    """
    tic = time.perf_counter()
    setup = _setup(campaign, arm, options, budget, fixed_nests)
    now, inlier, settled = _fits(setup, options)
    return _calibration(campaign, options, setup, now, inlier, settled, tic)


def solve_noise(campaign: Campaign, options: FitOptions) -> StatedNoise:
    """Return the stated noise per kind that every solve of an identification uses.

    The one policy, from the sources :func:`aacmm_pin.data.logs.noise_summary` prints: the
    options' ``sigma`` (the campaign's main kind: R-Test readings, else points) and
    ``sigma_location``, over ``options.noise`` (a caller's, e.g. discover's ``--sigma-*-um``),
    over the campaign's ``campaign.json`` (``noise_um``, else its instrument's), over the defaults.
    Points with a ``sigma_um`` column keep it (:func:`~aacmm_pin.fit.measurements.stated_noise`).
    """
    noise = options.noise or campaign.noise or StatedNoise()
    if options.sigma is not None:
        spat = campaign.spat is not None or campaign.points is None
        noise = replace(noise, rtest=options.sigma) if spat else replace(noise, point=options.sigma)
    if options.sigma_location is not None:
        noise = replace(noise, location=options.sigma_location)
    return noise


def _setup(campaign: Campaign, arm: Arm, options: FitOptions, budget: Budget | None,
           fixed_nests: bool) -> _Setup:
    """Return the measurements, unknowns, noise and nuisance shared by the fits."""
    noise = solve_noise(campaign, options)
    meas = measurements(campaign, arm, options.use_rtest, options.use_bar, noise)
    if fixed_nests:
        meas = _without_rtest_nests(meas)
    q, group, samples, stated = meas.q, meas.group, meas.samples, meas.sigma
    main = ~np.isnan(meas.measured[:, 0]) & (True if meas.frame is None else meas.frame < 0)
    if campaign.points is not None:  # points in other units, or not this arm's: before the fit
        pts = _point_rows(campaign, meas) & ~np.isnan(meas.measured[:, 0])
        nominal = stylus_positions(arm, Parameters.nominal(arm, options.step_deg), q[pts], "r",
                                   tool=None if samples.tool is None else samples.tool[pts])
        plausibility.check_point_spread(meas.measured[pts], nominal, group[pts],
                                        arm.sizes_label)
    start = options.start or _initial_frame(arm, Parameters.nominal(arm, options.step_deg),
                                            q[main], meas.measured[main], group[main],
                                            None if samples.tool is None else samples.tool[main])
    axes = tuple(arm.measured_axes) if options.map_axes is None else tuple(options.map_axes)
    if coupled := [a for a in axes if 1 <= a <= arm.n_axes and arm.coupled[a - 1]]:
        raise ValueError(f"map_axes: A{coupled[0]} ({arm.axis_names[coupled[0] - 1]}) is a coupled "
                         "joint: it has no encoder, so no map")
    full_u = Unknowns.full(arm, start, axes if options.model == "proposed" else (),
                           tuple(t for t in options.extensions if t.is_extension), samples)
    has_spat = campaign.spat is not None or campaign.points is None
    sigma_class = (noise.rtest if has_spat else noise.point if stated is None
                   else float(np.median(stated)))
    if stated is not None:  # per-sample noise stated
        stated = stated_noise(campaign, meas, noise)
    nuisance, measured, nuisance_keys = _nuisance(arm, start, meas, sigma_class, noise.location)
    base_w = np.ones(len(q)) if stated is None else sigma_class / stated
    settings = SolverSettings(loss=options.loss, f_scale=options.f_scale or 3 * sigma_class,
                              max_nfev=options.solve_nfev, budget=budget)
    return _Setup(meas, full_u, start, has_spat, sigma_class, stated, base_w, nuisance, measured,
                  nuisance_keys, settings, rob.sample_sources(campaign, options.use_bar), noise)


def _fits(setup: _Setup, options: FitOptions) -> tuple[Fit, np.ndarray | None, bool]:
    """Fit all samples; with ``robust``, reject outliers (:func:`_robust`).

    Returns the final fit, the samples kept (None: all) and whether the outlier set settled.
    """
    s, q = setup, setup.meas.q
    with Progress(f"identify {options.model}", "evaluation", enabled=options.progress) as bar:
        def shown(rms: float) -> None:
            bar.update(rms_um=rms * 1e6)

        budget = s.settings.budget
        evaluated = shown if budget is None else Counted(budget, shown)

        def fit(keep: np.ndarray | None) -> Fit:
            return fit_rounds(s.full_u, s.start, q, s.measured, s.nuisance, s.sigma_class,
                               None if s.stated is None and keep is None else
                               s.base_w * (1.0 if keep is None else keep), keep, s.settings,
                               options.jac, evaluated)

        def reweight(f: Fit, w: np.ndarray) -> Fit:
            prob = Problem(f.unknowns, q, s.measured, s.nuisance, f.constraints, f.obs.scale,
                           f.problem.x_ref, f.x, s.sigma_class, s.base_w * np.sqrt(w))
            out = prob.solve(prob.z(f.x), s.settings, options.jac, on_evaluation=evaluated).result
            return f._replace(problem=prob, res=out, x=prob.x(out.x), nfev=int(out.nfev),
                              jac=None)

        now = fit(None)
        if not options.robust:
            return now, None, True
        # the first fit's Jacobian is not held through the refits
        inlier, settled, now = reject_outliers(now._replace(jac=None), fit, reweight, s.base_w,
                                               s.sources[0], lambda: s.settings.budget is not None
                                               and s.settings.budget.spent)
        return now, inlier, settled


def _calibration(campaign: Campaign, options: FitOptions, setup: _Setup, now: Fit,
                 inlier: np.ndarray | None, settled: bool, tic: float) -> Calibration:
    """Return the calibration of the final fit: its noise, covariance, outliers and verdict."""
    unknowns, unvisited, gauges, obs = now.unknowns, now.unvisited, now.gauges, now.obs
    problem, res, x_full = now.problem, now.res, now.x
    n, robust = len(setup.meas.q), options.robust
    # a noise given (not estimated) is the one a row of weight 1 has: the solve's, which holds
    # the option (and a sigma_um column where the rows state their own)
    sigma = None if options.sigma is None else setup.sigma_class
    n_det = max(problem.n_arm - ident.held_rank(now.constraints), 0) + problem.n_frame
    kept = np.ones(n, bool) if inlier is None else inlier
    dof_fraction = max(3 * int(kept.sum()) + problem.n_lengths - n_det, 1) / (3 * int(kept.sum()))
    residual = problem.data_residuals(x_full)
    norms = rob.whitened_norms(residual, setup.base_w)
    # as the IRLS judged: each kind's median over all its samples
    scale = rob.kind_scales(norms, setup.sources[0], dof_fraction, setup.sigma_class)
    flagged = rob.describe(residual, norms, scale, ~kept if robust else rob.flag(norms, scale),
                           setup.sources)
    data_res = res.fun[:3 * n][np.repeat(kept, 3)]  # weighted: the noise in units of sigma_class
    dof = data_res.size + problem.n_lengths - n_det
    enough = dof >= MIN_DOF_FRACTION * data_res.size
    # too few residuals: the residual says nothing about the noise; the stated noise stands
    sig = _sigma(data_res, n_det, sigma) if enough else float(sigma or setup.sigma_class)
    covariance = problem.covariance(x_full, sig, now.jac)
    lines = ident.describe(unknowns, unvisited, obs)
    if gauges:
        lines.append("map constants: " + ", ".join(f"A{a}" for a in gauges) + " maps have zero "
                     "mean over their free nodes; a constant encoder error is indistinguishable "
                     "from the axis offset (dth), gamma0 (A1), the tool (A7) or DH errors, which "
                     "carry it")
    identifiable = np.zeros_like(unvisited)
    identifiable[np.flatnonzero(unknowns.free)] = obs.identifiable
    node_ok = {a: identifiable[unknowns.map_slice(a)].copy() for a in unknowns.map_axes}
    outliers = flagged if robust else ()
    suspects = () if robust else flagged
    rms = float(np.sqrt(np.mean(residual[kept] ** 2)))
    success, message = _verdict(res, robust, settled, outliers, suspects, enough,
                                (n_det, data_res.size, dof, sig),
                                rms if setup.has_spat else None, (data_res, sigma))
    if (units := plausibility.implausible_values(unknowns, x_full[:problem.n_arm], obs.scale,
                                                  unknowns.arm.sizes_label,
                                                  unknowns.arm.source)) is not None:
        success, message = False, f"{units}; {message}"
    if not success and setup.settings.budget is not None and setup.settings.budget.spent:
        message = _budget_message(options) + message.removeprefix(
            f"did not converge: {res.message}")
    checked = success
    if enough and success:
        success, message = _parts_dof(success, message, problem, x_full, setup, kept)
    if enough:
        judged = _judgement(campaign, setup, residual, kept, n_det)
        success, message = _judged(success, message, judged, robust, campaign, setup,
                                   _points_rms(campaign, setup, residual, kept))
    if robust and (whole := rob.whole_kind(norms, setup.sources[0], setup.sigma_class,
                                           dof_fraction)) is not None:
        success, message = False, f"robust fit refused: {whole}; {message}"
    return Calibration(parameters=unknowns.parameters(x_full[:problem.n_arm]), model=options.model,
                       use_rtest=options.use_rtest,
                       names=unknowns.names + [str(k) for k in setup.nuisance_keys],
                       x=x_full, covariance=covariance, sigma=sig,
                       fun=residual, location=setup.meas.group.copy(), success=success,
                       status=int(res.status), message=str(message),
                       nfev=int(now.nfev), unidentifiable=lines, node_identifiable=node_ok,
                       runtime_s=time.perf_counter() - tic,
                       raw=OptimizeResult({k: v for k, v in res.items() if k != "jac"}),
                       unknowns=unknowns, constraints=now.constraints,
                       identifiable=obs.identifiable, q=setup.meas.q, problem=problem,
                       settings=replace(setup.settings, budget=None),
                       nuisance_keys=tuple(setup.nuisance_keys),
                       inputs=tuple(k for k, on in (("spat", setup.has_spat),
                                                    ("points", campaign.points is not None),
                                                    ("bar", options.use_bar)) if on),
                       robust=robust, outliers=outliers, suspects=suspects, inlier=inlier,
                       stated_noise=setup.noise, judged=checked and not success)


def _budget_message(options: FitOptions) -> str:
    """Return the message of a fit that spent its evaluations before converging."""
    return (f"did not converge within {options.max_nfev} evaluations (max_nfev, --max-nfev: the "
            "cap of all the fit's solves together); raise it or check the inputs")


def _verdict(res: OptimizeResult, robust: bool, settled: bool, outliers: tuple[Outlier, ...],
             suspects: tuple[Outlier, ...], enough: bool,
             counts: tuple[int, int, int, float], spat_rms: float | None,
             noise: tuple[np.ndarray, float | None]) -> tuple[bool, str]:
    """Return ``success`` and ``message``: the last solve's, then outliers, too few samples, RMS.

    ``counts``: determined parameters, residual coordinates kept, degrees of freedom, the noise
    used (m); ``spat_rms``: the fit RMS of a fit with SPATs (m), None without; ``noise``: the
    kept data residuals (m) and the stated noise (m, None when estimated), judged against
    :data:`MIN_NOISE_RATIO`.
    """
    success = bool(res.success)  # the last round's: earlier ones only set the held directions
    message = res.message if success else f"did not converge: {res.message}"
    limit = f"{rob.OUTLIER_K:g} robust sigmas of their kind"
    if robust:
        message = (f"{message}; robust fit: {len(outliers)} outlier samples beyond {limit} "
                   f"rejected" + (_where(outliers) if outliers else ""))
        if not settled:
            success = False
            message += (f"; the outlier set still changed after {rob.MAX_REJECT_ITERATIONS} "
                        "refits (outliers and model errors of similar size?)")
    elif suspects:  # reported, not failed: a model that misses an effect has them on clean data
        message = (f"{message}; but {len(suspects)} samples lie beyond {limit}: outliers or a "
                   f"model that misses an effect{_where(suspects)}; refit with robust=True "
                   "(aacmm-pin identify --robust) to reject them")
    n_det, n_res, dof, sig = counts
    data_res, stated = noise
    if not enough:
        more = int(np.ceil((n_det / (1 - MIN_DOF_FRACTION) - n_res) / 3))
        success = False
        message = (f"too few samples: {n_res} residual coordinates for {n_det} determined "
                   f"parameters ({dof} degrees of freedom, fewer than "
                   f"{MIN_DOF_FRACTION:.0%} of the residuals), so neither the noise nor the "
                   f"uncertainty can be estimated from the fit (the stated noise "
                   f"{sig * 1e6:.2g} um is used); measure at least about {more} more postures")
    estimate = _sigma(data_res, n_det, None)
    if enough and stated is not None and estimate < MIN_NOISE_RATIO * stated:
        success = False
        message = (f"the stated noise {stated * 1e6:.4g} um is {stated / estimate:.3g} x the "
                   f"residual's noise ({estimate * 1e6:.3g} um over {dof} degrees of freedom): "
                   f"the plausible sizes outweigh the measurements ({n_det} parameters "
                   f"determined) and every uncertainty is as many times too wide; state the "
                   f"instrument's noise (sigma, --sigma-um); " + message)
    if enough and spat_rms is not None and spat_rms > MAX_FIT_RMS:
        success = False
        message = (f"fit RMS {spat_rms * 1e6:.4g} um is beyond {MAX_FIT_RMS * 1e6:.3g} um, more "
                   "than any articulated arm leaves after calibration: the inputs disagree (units "
                   "of a column, R-Test zero positions in locations.csv, readouts); " + message)
    return success, message


def _parts_dof(success: bool, message: str, problem: Problem, x_full: np.ndarray, setup: _Setup,
               kept: np.ndarray) -> tuple[bool, str]:
    """Return ``success`` False with a message where a tool's or group's points have no dof to spare.

    A part (the samples of one tool of a tree, or of one instrument group with a frame of its own)
    determines ``rank(J) - rank(J without its rows)`` parameters that no other sample does (its
    branch's DH errors, its tool vector, its frame); fewer than :data:`MIN_DOF_FRACTION` of its
    residual coordinates left over (3 points of a tool for its 9 parameters: none) means its fit
    passes through its points whatever their noise, and its uncertainty is not known.
    """
    meas = setup.meas
    parts: list[tuple[str, np.ndarray]] = []
    tool = meas.samples.tool
    if tool is not None and np.unique(tool).size > 1:
        names = setup.meas.samples.arm.tool_names
        parts += [(f"tool '{names[t]}'", (tool == t) & kept) for t in np.unique(tool)]
    if meas.frame is not None:
        parts += [(f"instrument group {g}", (meas.frame == f) & kept)
                  for f, g in enumerate(meas.frame_groups)]
    if not parts:
        return success, message
    jac = problem.jac(problem.z(x_full))
    jac = jac / np.maximum(np.linalg.norm(jac, axis=0), 1e-300)
    rows = np.ones(jac.shape[0], dtype=bool)
    rows[:3 * len(kept)] = np.repeat(kept, 3)

    def rank(sel: np.ndarray) -> int:
        sv = np.linalg.svd(jac[sel], compute_uv=False)
        return int(np.sum(sv > sv[0] * 1e-8)) if sv.size else 0

    full = rank(rows)
    for label, part in parts:
        others = rows.copy()
        others[:3 * len(kept)] &= ~np.repeat(part, 3)
        own, coords = full - rank(others), 3 * int(part.sum())
        if coords - own < MIN_DOF_FRACTION * coords:
            return False, (f"{label}: {part.sum()} points ({coords} coordinates) for {own} "
                           f"parameters that only they determine: {coords - own} degrees of "
                           f"freedom, fewer than {MIN_DOF_FRACTION:.0%} of them, so the fit passes "
                           "through those points whatever their noise and its uncertainty is not "
                           f"known; measure at least about "
                           f"{int(np.ceil(own / (1 - MIN_DOF_FRACTION) / 3)) - int(part.sum())}"
                           f" more poses with it; {message}")
    return success, message


def _point_rows(campaign: Campaign, meas: Measurements) -> np.ndarray:
    """Return which samples are absolute points, shape (N,) (as :func:`stated_noise` tells them)."""
    if campaign.points is None:
        return np.zeros(len(meas.q), dtype=bool)
    if campaign.spat is not None:  # the points' groups are negative beside SPAT
        out: np.ndarray = meas.group < 0
        return out
    return np.ones(len(meas.q), dtype=bool) if meas.nest is None else meas.nest < 0


def _judgement(campaign: Campaign, setup: _Setup, residual: np.ndarray, kept: np.ndarray,
               n_det: int) -> Judgement:
    """Return the kept residual judged against the stated noise (:mod:`~aacmm_pin.fit.noise_judgement`).

    ``residual``: every sample's residual, shape (N, 3), m; ``kept``: the samples fitted, (N,).
    The noise is the one the solves used (:func:`solve_noise`; ``sigma_um`` cells per sample).
    """
    stated = setup.stated if setup.stated is not None else np.full(len(kept), setup.sigma_class)
    white = residual[kept] / stated[kept, None]
    time = setup.meas.samples.t
    variables = [values for name, values in setup.meas.samples.columns.items()
                 if name.endswith("_c")]  # an arm that warms drifts: a temperature's order
    state = np.column_stack([setup.meas.q[kept], *(v[kept] for v in variables)])  # kept rows only
    judged = judge_residual(white, n_det, _segments(campaign, setup.meas)[kept],
                            None if time is None else time[kept], state)
    if judged.row_order is None:
        return judged
    return judged._replace(row_order=judged.row_order._replace(  # a sample of the campaign
        row=int(np.flatnonzero(kept)[judged.row_order.row])))


def _segments(campaign: Campaign, meas: Measurements) -> np.ndarray:
    """Return the instrument set-up of every sample, shape (N,).

    2 m for R-Test location m's SPAT samples, 2 g + 1 for instrument group g's points, -1 for
    length-bar readouts.
    """
    points = _point_rows(campaign, meas)
    spat = np.zeros(len(points), dtype=bool)
    if campaign.spat is not None:
        spat[:len(campaign.spat.location)] = True
    out: np.ndarray = np.where(spat, 2 * np.abs(meas.group), -1)
    return np.where(points, 2 * np.abs(meas.group) + 1, out)


def _sample_line(campaign: Campaign, meas: Measurements, sample: int) -> str:
    """Return ``"points.csv line 42"`` (or ``"spat.csv row 41"``) for a SPAT sample or a point."""
    points = _point_rows(campaign, meas)
    log = campaign.points if points[sample] else campaign.spat
    assert log is not None
    row = sample - int(np.flatnonzero(points)[0]) if points[sample] else sample
    name = "points.csv" if points[sample] else "spat.csv"
    if log.lines is not None:
        return f"{name} line {int(log.lines[row])}"
    return f"{name} row {row + 1}"


def _points_rms(campaign: Campaign, setup: _Setup, residual: np.ndarray,
                kept: np.ndarray) -> float | None:
    """Return the RMS residual of the kept absolute points (m), None without points."""
    rows = _point_rows(campaign, setup.meas) & kept
    return float(np.sqrt(np.mean(residual[rows] ** 2))) if rows.any() else None


def _judged(success: bool, message: str, judged: Judgement, robust: bool, campaign: Campaign,
            setup: _Setup, points_rms: float | None) -> tuple[bool, str]:
    """Return ``success`` and ``message`` with the residual's judgement against the stated noise.

    Fails a residual that follows the points' row order, a gross points residual and a robust fit
    whose kept residual is above the noise; notes any other residual above the noise.
    """
    noise = (f"{judged.ratio:.3g} x the stated noise (chi-square {p_text(judged.p_value)}, "
             f"{judged.dof} degrees of freedom)")
    if points_rms is not None and points_rms > MAX_POINTS_FIT_RMS:
        return False, (f"points fit RMS {points_rms * 1e3:.4g} mm is beyond "
                       f"{MAX_POINTS_FIT_RMS * 1e3:.3g} mm, more than any arm leaves after "
                       "calibration: the inputs disagree (units of a column, the tool, the pairing "
                       f"of readouts and points); {message}")
    order = judged.row_order
    if order is not None:
        at = _sample_line(campaign, setup.meas, order.row)
        where = (f"group {order.group // 2}" if order.group % 2 else
                 f"R-Test location {order.group // 2}")
        shape = (f"a step at {at}" if order.shape == "step" else f"a drift from {at} on")
        return False, (f"the residual of {where} follows row order (time): {shape} "
                       f"of {order.size:.3g} noise sigmas explains {order.fraction:.0%} of it "
                       f"({p_text(order.p_value)}), residual {noise}; no kinematic model explains "
                       "that: the instrument or the arm's base moved during the measurement "
                       f"(measure again, or split the samples into groups); {message}")
    if judged.p_value >= NOISE_P:
        return success, message
    if robust:
        return False, (f"robust fit: the kept samples' residual is {noise}: the rejection "
                       "threshold is set by that residual, so outliers below it are kept "
                       "(breakdown: about half the samples off?) or the model misses an effect "
                       "that rejection mistakes for outliers; check the inputs, or fit without "
                       f"robust and run discover; {message}")
    return success, (f"{message}; the residual is {noise}: the model misses an effect or the "
                     "noise is understated; aacmm-pin discover names what is missing")


def _where(flagged: tuple[Outlier, ...]) -> str:
    """Return ``" (largest: spat.csv line 12, 1000 um; ...)"`` for the first few flagged samples."""
    def one(o: Outlier) -> str:
        at = f"line {o.line}" if o.line is not None else f"row {o.row + 1}"
        return f"{o.file} {at}, {o.residual * 1e6:.4g} um"
    more = f"; {len(flagged) - 3} more" if len(flagged) > 3 else ""
    return f" (largest: {'; '.join(one(o) for o in flagged[:3])}{more})"


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
    res = problem.solve(z, cal.settings).result
    return problem.x(res.x), bool(res.success)
