"""The verdict on a fit: ``success`` and ``message`` from the solve, the residual and the noise.

The last solve's convergence, outliers and suspects, too few samples, a stated noise far above
the residual's, a fit RMS no arm leaves, parts without degrees of freedom to spare, and the
residual judged against the stated noise (:mod:`aacmm_pin.fit.noise_judgement`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.special import chdtrc

from aacmm_pin.data.campaign import Campaign
from aacmm_pin.fit import robust as rob
from aacmm_pin.fit.fit_options import FitOptions
from aacmm_pin.fit.fit_setup import FitSetup, point_rows
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.fit.measurements import Measurements
from aacmm_pin.fit.noise_judgement import (
    MAX_POINTS_FIT_RMS,
    NOISE_P,
    Judgement,
    judge_residual,
    p_text,
)
from aacmm_pin.fit.robust import Outlier
from aacmm_pin.fit.solver import Problem

if TYPE_CHECKING:  # the solver is imported where a fit runs
    from scipy.optimize import OptimizeResult

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


def noise_consistency(cal: Calibration, stated: float) -> tuple[float, float]:
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


def budget_message(options: FitOptions) -> str:
    """Return the message of a fit that spent its evaluations before converging."""
    return (f"did not converge within {options.max_nfev} evaluations (max_nfev, --max-nfev: the "
            "cap of all the fit's solves together); raise it or check the inputs")


def verdict(res: OptimizeResult, robust: bool, settled: bool, outliers: tuple[Outlier, ...],
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
    estimate = noise_estimate(data_res, n_det, None)
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


def parts_dof(success: bool, message: str, problem: Problem, x_full: np.ndarray, setup: FitSetup,
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


def judgement(campaign: Campaign, setup: FitSetup, residual: np.ndarray, kept: np.ndarray,
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
    points = point_rows(campaign, meas)
    spat = np.zeros(len(points), dtype=bool)
    if campaign.spat is not None:
        spat[:len(campaign.spat.location)] = True
    out: np.ndarray = np.where(spat, 2 * np.abs(meas.group), -1)
    return np.where(points, 2 * np.abs(meas.group) + 1, out)


def _sample_line(campaign: Campaign, meas: Measurements, sample: int) -> str:
    """Return ``"points.csv line 42"`` (or ``"spat.csv row 41"``) for a SPAT sample or a point."""
    points = point_rows(campaign, meas)
    log = campaign.points if points[sample] else campaign.spat
    assert log is not None
    row = sample - int(np.flatnonzero(points)[0]) if points[sample] else sample
    name = "points.csv" if points[sample] else "spat.csv"
    if log.lines is not None:
        return f"{name} line {int(log.lines[row])}"
    return f"{name} row {row + 1}"


def points_rms(campaign: Campaign, setup: FitSetup, residual: np.ndarray,
                kept: np.ndarray) -> float | None:
    """Return the RMS residual of the kept absolute points (m), None without points."""
    rows = point_rows(campaign, setup.meas) & kept
    return float(np.sqrt(np.mean(residual[rows] ** 2))) if rows.any() else None


def with_judgement(success: bool, message: str, judged: Judgement, robust: bool, campaign: Campaign,
            setup: FitSetup, points_rms: float | None) -> tuple[bool, str]:
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


def noise_estimate(data_residuals: np.ndarray, n_params: int, given: float | None) -> float:
    """Return the given noise, or the residual-based estimate sqrt(SSR / (m - p))."""
    if given is not None:
        return float(given)
    dof = max(data_residuals.size - n_params, 1)
    return float(np.sqrt(np.sum(data_residuals ** 2) / dof))
