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
from dataclasses import replace

import numpy as np
from scipy.optimize import OptimizeResult

from aacmm_pin._blas import single_threaded_blas
from aacmm_pin.data.campaign import Campaign, StatedNoise
from aacmm_pin.effects.base import Term
from aacmm_pin.effects.term_axes import check_terms
from aacmm_pin.fit import identifiability as ident
from aacmm_pin.fit import plausibility
from aacmm_pin.fit import robust as rob
from aacmm_pin.fit.fit_options import MAX_NFEV_PER_SOLVE, MODELS, NESTS, FitOptions
from aacmm_pin.fit.fit_rounds import Fit, fit_rounds, reject_outliers
from aacmm_pin.fit.fit_setup import FitSetup, fit_setup, solve_noise
from aacmm_pin.fit.fit_verdict import (
    MAX_FIT_RMS,
    MIN_DOF_FRACTION,
    MIN_NOISE_RATIO,
    budget_message,
    judgement,
    noise_consistency,
    noise_estimate,
    parts_dof,
    points_rms,
    verdict,
    with_judgement,
)
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.fit.measurements import measurements as measurements
from aacmm_pin.fit.noise_judgement import NOISE_P
from aacmm_pin.fit.solver import Factor, Problem
from aacmm_pin.fit.solver_values import Budget, BudgetSpent, Counted
from aacmm_pin.model.arm import Arm, load_arm
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.progress import Progress
from aacmm_pin.units import STEP_DEG

__all__ = ["MAX_FIT_RMS", "MAX_NFEV_PER_SOLVE", "MIN_DOF_FRACTION", "MIN_NOISE_RATIO", "MODELS",
           "NESTS", "NOISE_P", "FitOptions", "identify", "refit", "solve_noise"]


def identify(campaign: Campaign, arm: Arm | None = None, model: str = "proposed",
             use_rtest: bool = True, *, start: Parameters | None = None, step_deg: float = STEP_DEG,
             map_axes: tuple[int, ...] | None = None, loss: str = "linear",
             f_scale: float | None = None, sigma: float | None = None,
             sigma_location: float | None = None, noise: StatedNoise | None = None,
             max_nfev: int | None = None, jac: str = "analytic", progress: bool = False,
             extensions: tuple[Term, ...] = (), use_bar: bool = False, robust: bool = False,
             nests: str = "auto") -> Calibration:
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
        jac: ``"analytic"`` (Pinocchio, sparse in map nodes) or scipy's ``"2-point"``, ``"3-point"``.
        progress: show progress (evaluations, residual RMS; log lines when stderr is no terminal).
        extensions: further terms of the effect library (:mod:`aacmm_pin.effects`) to estimate
            (angle, scale or measurement kind; map terms are ``map_axes``).
        nests: the R-Test nests' offsets: ``"estimate"`` (each with the prior
            ``sigma_location``), ``"fixed"`` (held at the measured positions) or ``"auto"``:
            estimated only when the model's residual matches the stated R-Test noise (chi-square,
            p >= 0.001; ``sigma`` or 2 um), else fixed, since the offsets of an incomplete model
            take up its error (the choice and why are in :attr:`Calibration.nests`).
        use_bar: fit the length-bar readouts too (a calibration input, not only a check): every
            socket's position is estimated from its readouts and the calibrated distances between
            a placement's sockets are residuals (stated noise per readout coordinate:
            ``campaign.json``'s socket, else ``units.SIGMA_SOCKET``; per length ``SIGMA_BAR``).
        robust: reject outliers (:mod:`aacmm_pin.fit.robust`: IRLS, Huber then hard rejection of
            every sample whose whitened residual norm exceeds ``robust.OUTLIER_K`` robust sigmas),
            listed in ``outliers`` and left out of the final fit, its noise and its covariance.
            Without it they are ``suspects``, named in ``message`` (``success`` stays the
            solver's: a DH model on an arm with encoder errors has them on clean data).

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
    budget = None if max_nfev is None else Budget(max_nfev)  # every evaluation of every fit below
    arm = arm or load_arm()
    check_terms(extensions, arm, "extensions")
    with single_threaded_blas():  # products of a few hundred columns: BLAS threads only spin
        cal = _identify(campaign, arm, options, budget, fixed_nests=nests == "fixed")
        return _nests_chosen(cal, campaign, arm, options, budget)


def _nests_chosen(cal: Calibration, campaign: Campaign, arm: Arm, options: FitOptions,
                  budget: Budget | None) -> Calibration:
    """Return the calibration with the R-Test nests as asked, or (``auto``) as the residual says.

    ``auto``: estimated when the fit's residual matches the stated R-Test noise, else fitted again
    with the nests fixed (within the budget's evaluations left).
    """
    if "spat" not in cal.inputs:
        return cal
    if options.nests != "auto":
        return replace(cal, nests=f"{options.nests} (asked)")
    p_value, ratio = noise_consistency(cal, solve_noise(campaign, options).rtest)
    if p_value >= NOISE_P:
        return replace(cal, nests=f"estimated: the fit's residual matches the stated R-Test "
                                  f"noise (RMS {ratio:.2f} x, p = {p_value:.2g})")
    if budget is not None and budget.spent:
        return cal  # no evaluation left for the refit with fixed nests: it did not converge
    try:
        fixed = _identify(campaign, arm, options, budget, fixed_nests=True)
    except BudgetSpent:
        return replace(cal, success=False, status=0, message=budget_message(options))
    return replace(fixed, nests=(
        f"fixed at their measured positions: the model's residual is {ratio:.1f} x the stated "
        f"R-Test noise (p = {p_value:.2g}), so nest offsets estimated with it would take up "
        "model error"))


def _identify(campaign: Campaign, arm: Arm, options: FitOptions, budget: Budget | None,
              fixed_nests: bool) -> Calibration:
    """One identification with the R-Test nests' offsets estimated or held (``fixed_nests``).

    ``budget``: the evaluations left to the whole fit (None: ``max_nfev`` per solve only).
    """
    tic = time.perf_counter()
    setup = fit_setup(campaign, arm, options, budget, fixed_nests)
    now, inlier, settled = _fits(setup, options)
    return _calibration(campaign, options, setup, now, inlier, settled, tic)


def _fits(setup: FitSetup, options: FitOptions) -> tuple[Fit, np.ndarray | None, bool]:
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


def _calibration(campaign: Campaign, options: FitOptions, setup: FitSetup, now: Fit,
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
    sig = noise_estimate(data_res, n_det, sigma) if enough else float(sigma or setup.sigma_class)
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
    success, message = verdict(res, robust, settled, outliers, suspects, enough,
                                (n_det, data_res.size, dof, sig),
                                rms if setup.has_spat else None, (data_res, sigma))
    if (units := plausibility.implausible_values(unknowns, x_full[:problem.n_arm], obs.scale,
                                                  unknowns.arm.sizes_label,
                                                  unknowns.arm.source)) is not None:
        success, message = False, f"{units}; {message}"
    if not success and setup.settings.budget is not None and setup.settings.budget.spent:
        message = budget_message(options) + message.removeprefix(
            f"did not converge: {res.message}")
    checked = success
    if enough and success:
        success, message = parts_dof(success, message, problem, x_full, setup, kept)
    if enough:
        judged = judgement(campaign, setup, residual, kept, n_det)
        success, message = with_judgement(success, message, judged, robust, campaign, setup,
                                   points_rms(campaign, setup, residual, kept))
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
