r"""A calibration linearised at its solution, for scoring candidate terms on its residuals.

:class:`LinearScorer` works in the identification's reduced coordinates
(:class:`aacmm_pin.fit.solver.Problem`:
constraints met, columns preconditioned) with a Gaussian prior of the arm's plausible sizes on the
arm directions (widened where the fit rejects them, :func:`size_factors`), and scores a candidate
term of the effect library by its leave-one-location-out held-out gain, the F test of its fit
improvement, its BIC change and, with a length bar, the linearised change of the normalised bar
errors (:mod:`aacmm_pin.analyses.bar_linear`). The loop that uses
it is :func:`aacmm_pin.discover`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import scipy.linalg as sla

from aacmm_pin.analyses.bar_linear import LinearBar, scaled_columns
from aacmm_pin.analyses.discovery_results import Score
from aacmm_pin.data.poses import POSE_COLUMN, pose_ids
from aacmm_pin.distributions import chi2_ppf, f_sf
from aacmm_pin.effects.base import Term
from aacmm_pin.effects.calibrated import needs_tilts, stylus_jacobians
from aacmm_pin.errors import MissingColumn
from aacmm_pin.fit.identifiability import plausible_groups, plausible_sizes
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.model.encoder_map import touched_nodes
from aacmm_pin.model.kinematics import StylusJacobians
from aacmm_pin.model.samples import Samples

FOLDS = 5
"""Folds of the held-out score for absolute points (k-fold over the poses)."""
SIZE_ALPHA = 1e-3
"""A group of the arm's plausible sizes is rejected by its fit when the fitted values' sum of
squares (in sizes) exceeds the chi-square quantile 1 - SIZE_ALPHA of a right size."""


def size_factors(cal: Calibration) -> dict[str, float]:
    r"""Return, per group of the arm's sizes that the fit rejects, how much larger its errors are.

    Under the arm's sizes (:mod:`aacmm_pin.model.sizes`) a fitted value :math:`\hat x_i` (from the
    start) of an identifiable entry of size :math:`s_i` and linearised variance :math:`v_i` is
    about :math:`N(0, s_i^2 + v_i)`, so :math:`\sum_i \hat x_i^2 / (s_i^2 + v_i)` over a group's n
    entries is chi-square with n degrees of freedom. Where it exceeds the 1 - :data:`SIZE_ALPHA`
    quantile the stated size is too small for this arm, and the group's factor is the size the
    data show, :math:`\sqrt{\sum_i (\hat x_i^2 - v_i) / \sum_i s_i^2}` (empirical Bayes; at least
    1). Groups the fit does not reject are left out (factor 1).

    Args:
        cal: a calibration (its layout, start values, covariance and identifiable entries).
    """
    problem, u = cal.problem, cal.unknowns
    n_arm = problem.n_arm
    size2 = plausible_sizes(u)[u.free] ** 2  # as the identification scaled its columns
    value2 = (cal.x[:n_arm] - problem.x_ref[:n_arm]) ** 2
    var = np.clip(np.diag(cal.covariance)[:n_arm], 0.0, None)
    groups = np.array(plausible_groups(u))[u.free]
    out = {}
    for group in dict.fromkeys(groups.tolist()):
        sel = (groups == group) & cal.identifiable
        n = int(sel.sum())
        if n and np.sum(value2[sel] / (size2[sel] + var[sel])) > chi2_ppf(1 - SIZE_ALPHA, n):
            out[group] = float(np.sqrt(max(np.sum(value2[sel] - var[sel]) / np.sum(size2[sel]), 1.0)))
    return out


def heldout_against(gains: np.ndarray) -> float:
    r"""Return how strongly a candidate's held-out gains speak against it: a one-sided p-value.

    ``gains``: the held-out SSR decrease of every held-out group (chi-square units), shape (J,).
    Student's t of their mean, :math:`t = \bar g \sqrt{J} / s`, against a mean of 0 on J - 1
    degrees of freedom: the probability of a t this low were the candidate no worse on left-out
    data than without it. Small: the groups agree that it predicts them worse. 1 with fewer than
    two groups; with gains that do not vary, 0 if they are all losses (every group agrees
    exactly) and 1 otherwise.
    """
    n = len(gains)
    spread = float(np.std(gains, ddof=1)) if n > 1 else 0.0
    if spread <= 0.0:
        return 0.0 if n > 1 and float(np.mean(gains)) < 0.0 else 1.0
    t = float(np.mean(gains)) * np.sqrt(n) / spread
    tail = 0.5 * f_sf(t * t, 1.0, n - 1.0)  # P(T > |t|)
    return tail if t < 0 else 1.0 - tail


def bar_against(gain: float, change2: float, fit_chi2: float) -> float:
    r"""Return how strongly the length bar speaks against a candidate: a one-sided p-value.

    The bar's whitened errors a (their covariance the model's prediction's, so a is N(0, I) under
    the model) change by b with the candidate fitted to the SPATs; the bar's chi-square decrease
    is :math:`\text{gain} = |a|^2 - |a + b|^2`. Were the bar's errors a shifted by t b
    (:math:`a = -t b + n`, t = 1: the SPATs' change is the bar's, t = 0: the bar sees none of
    it), the gain's mean would be :math:`|b|^2 (2t - 1)`: negative where the bar holds less than
    half the change. Its standard error is :math:`2 |b|` from the bar's noise, times
    :math:`\sqrt{1 + |b|^2 / \chi^2}` for the SPATs' uncertainty of the change (:math:`\chi^2`
    the fit's gain); the p-value is :math:`\Phi(z)` of the gain over it: small where the bar is
    significantly worse with the candidate than without. 1 where the bar does not see the change.

    Args:
        gain: the bar's chi-square decrease with the candidate.
        change2: :math:`|b|^2`, the bar's chi-square of the change itself.
        fit_chi2: the fit's chi-square decrease with the candidate (SPATs).
    """
    if change2 <= 1e-12 or fit_chi2 <= 0.0:
        return 1.0
    z = gain / (2.0 * np.sqrt(change2) * np.sqrt(1.0 + change2 / fit_chi2))
    return float(0.5 * math.erfc(-z / math.sqrt(2.0)))


def held_out_groups(cal: Calibration, pose: np.ndarray | None = None
                    ) -> tuple[list[np.ndarray], list[bool]]:
    """Return the held-out groups of a calibration's samples and whether each is centred.

    A group is the data residual rows (3 per sample) left out together. Samples with a nest
    (R-Test locations, bar sockets) are left out per nest id and centred (the left-out nest's
    offset is unknown); absolute tool points are split into :data:`FOLDS` folds (seeded) of whole
    poses (the points of one pose, several markers or tools, are left out together), stratified by
    instrument group so that every fold keeps most points of every group and a group's frame stays
    fixed by the rest (left out whole, its six unknowns would be free). Without nests every sample
    is a point of the folds.

    Args:
        cal: the calibration.
        pose: pose of every sample, shape (N,) (:func:`aacmm_pin.data.poses.pose_ids`); None:
            identical readouts in consecutive rows are one pose.
    """
    problem = cal.problem
    n = len(cal.location)
    point = np.ones(n, dtype=bool)
    if problem.n_loc > 0:
        nest = problem.nuisance.nest
        point = cal.location < 0 if "spat" in cal.inputs else (
            np.ones(n, dtype=bool) if nest is None else nest < 0)
    groups = [np.flatnonzero(cal.location == m) for m in np.unique(cal.location[~point])]
    centred = [True] * len(groups)
    if point.any():
        unit = pose_ids(cal.q) if pose is None else np.asarray(pose, dtype=np.int64)
        unit = np.where(point, unit, -1)  # a pose is a unit of its points only
        fold = np.full(n, -1, dtype=np.int64)
        unit_fold: dict[int, int] = {}
        seen: dict[int, int] = {}
        for i in np.random.default_rng(0).permutation(n):  # as before for one point per pose
            if point[i]:
                if (u := int(unit[i])) not in unit_fold:  # a pose's fold: its first point's group
                    k = seen.get(int(cal.location[i]), 0)
                    unit_fold[u], seen[int(cal.location[i])] = k % FOLDS, k + 1
                fold[i] = unit_fold[u]
        groups += [np.flatnonzero(fold == f) for f in range(FOLDS) if np.any(fold == f)]
        centred += [False] * (len(groups) - len(centred))
    return [(3 * g[:, None] + np.arange(3)).ravel() for g in groups], centred


class LinearScorer:
    """A calibration linearised at its solution, for scoring candidate terms on the residuals.

    All in the identification's reduced coordinates (constraints met, columns preconditioned) with
    a Gaussian prior of the plausible sizes on the arm directions (and the nest offsets' own prior
    rows): held-out refits are then well posed even where one location alone saw a direction.

    Args:
        cal: the calibration to linearise.
        samples: its samples (readouts, temperature, motion, displacement).
        bar: the linearised length bar, or None.
        widen_sizes: widen each group of the arm's sizes that the fit rejects to the scale the
            data show (:func:`size_factors`), for the prior and for the candidates of its effect;
            False keeps the arm's sizes.
    """

    def __init__(self, cal: Calibration, samples: Samples, bar: LinearBar | None = None, *,
                 widen_sizes: bool = True):
        problem = cal.problem
        z = problem.z(cal.x)
        self.cal, self.samples = cal, samples
        self.r = problem.fun(z)
        self.jac = problem.jac(z)
        self.n_data = 3 * len(cal.location)
        self.sigma = float(cal.sigma)
        # prior of the plausible sizes on the arm directions (y = plausible-scaled null-space
        # coordinates, z = R y), centred at the start values, not at this fit: a left-out
        # location's refit must not keep what only that location determined; the nest offsets
        # have their own prior rows in the residual already
        # where the fit rejects a group of the arm's sizes, that group's prior is its fitted scale
        self.size_factors = size_factors(cal) if widen_sizes else {}
        """Group of the arm's sizes -> factor its prior (and its candidates') is widened by."""
        arm_rows = problem.r_inv[:problem.n_arm_y]
        if self.size_factors:
            groups = np.array(plausible_groups(cal.unknowns))[cal.unknowns.free]
            factor = np.array([self.size_factors.get(g, 1.0) for g in groups])
            scale = plausible_sizes(cal.unknowns)[cal.unknowns.free]
            null = problem.basis[:problem.n_arm, :problem.n_arm_y] / scale[:, None]  # orthonormal
            cov_y = null.T @ (factor[:, None] ** 2 * null)  # prior of y: sizes x factors
            self.ridge = self.sigma ** 2 * (arm_rows.T @ np.linalg.solve(cov_y, arm_rows))
        else:
            self.ridge = self.sigma ** 2 * (arm_rows.T @ arm_rows)
        self.offset = self.ridge @ (z - problem.z(problem.x_ref))  # prior pull back to the start
        # held-out groups: the R-Test locations and bar sockets (each left out less its mean: its
        # nest offset is unknown); absolute points: FOLDS folds of whole poses, seeded
        pose = samples.columns.get(POSE_COLUMN) if samples.n == len(cal.location) else None
        self.groups, self.centred = held_out_groups(cal, pose_ids(cal.q, pose))
        """Rows (data residual indices) of each held-out group; whether each is centred."""
        self.n_held = self.n_data - 3 * int(np.sum(self.centred))
        self.prior_rows = np.arange(self.n_data, len(self.r))
        self.stylus: StylusJacobians = stylus_jacobians(cal.unknowns.arm, cal.parameters,
                                                        samples.q, frame="mt", samples=samples)
        self.touched = touched_nodes(samples.q, cal.parameters.step_deg)
        # the model's own blocks per location and for the prior rows, shared by every candidate
        jac, r = self.jac, self.r
        self._base_grams = [(jac[g].T @ jac[g], jac[g].T @ r[g])
                            for g in [*self.groups, self.prior_rows]]
        self.bar = bar
        self._bar_white: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        if bar is not None and bar.n:
            # bar errors whitened by their predicted covariance (posterior of this model + what
            # the SPATs leave unknown): e^T C^-1 e = |L^-1 e|^2
            p_loc = problem.p[problem.n_arm:problem.n_arm + problem.n_loc]
            info = (sum(g for g, _ in self._base_grams[:-1]) + self.ridge) / self.sigma ** 2
            info += p_loc.T @ (p_loc / problem.nest_sigma[:, None] ** 2)  # the nests' own prior
            cov = bar.covariance(info, self.jac[:self.n_data], self.sigma)
            chol = np.linalg.cholesky(cov + 1e-12 * np.trace(cov) / bar.n * np.eye(bar.n))
            self._bar_white = (chol, sla.solve_triangular(chol, bar.errors, lower=True),
                               sla.solve_triangular(chol, bar.jac_z, lower=True))
        self.base = self.evaluate(self._empty())

    def _empty(self) -> np.ndarray:
        return np.zeros((len(self.r) + (0 if self.bar is None else self.bar.n), 0))

    def _stylus(self, term: Term) -> StylusJacobians:
        """Return the stylus Jacobians, with the tilt columns (computed once) if the term needs them."""
        if self.stylus.tilts is None and needs_tilts([term]):
            self.stylus = stylus_jacobians(self.cal.unknowns.arm, self.cal.parameters,
                                           self.samples.q, frame="mt", samples=self.samples,
                                           tilts=True)
        return self.stylus

    def bar_normalised(self, errors: np.ndarray) -> float | None:
        """Return sqrt(e^T C^-1 e / n) for bar errors e (n,) with this model's bar covariance C."""
        if self._bar_white is None:
            return None
        white = sla.solve_triangular(self._bar_white[0], errors, lower=True)
        return float(np.sqrt(np.mean(white ** 2)))

    def columns(self, term: Term) -> np.ndarray:
        """Return the term's columns, scaled by the plausible sizes, shape (rows, k).

        Rows: the residual's (data, then prior), then the whitened bar errors (with a bar).
        """
        factor = self.size_factors.get(term.size_key, 1.0)
        cols = factor * scaled_columns(term, self.samples, self._stylus(term), self.cal.parameters,
                                       self.touched, self.cal.unknowns.arm.sizes)
        out = np.zeros((len(self._empty()), cols.shape[2]))
        out[:self.n_data] = cols.reshape(self.n_data, -1)
        if self.bar is not None and self._bar_white is not None:
            try:
                out[len(self.r):] = factor * sla.solve_triangular(
                    self._bar_white[0], self.bar.columns(term, self.touched), lower=True)
            except MissingColumn:  # e.g. thermal without temp_c in lengthbar.csv: the bar abstains
                out[len(self.r):] = np.nan
        return out

    def evaluate(self, extra: np.ndarray) -> dict[str, Any]:
        """Fit the residuals with the model's directions plus ``extra`` columns (prior sigma^2).

        Returns fit SSR (``fit_ssr``), held-out SSR (``held_ssr``) and per held-out group
        (``held_groups``, shape (groups,)), the effective parameter count of ``extra``
        (``k_eff``), the normalised bar SSR (``bar_chi2``, chi-square, NaN without a bar) and
        the whitened bar errors (``bar_residual``, shape (bar readouts,), empty without a bar).
        """
        jac, r, k = self.jac, self.r, extra.shape[1]
        p = jac.shape[1]
        ridge = sla.block_diag(self.ridge, self.sigma ** 2 * np.eye(k))

        def gram(rows: np.ndarray, base: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
            e = extra[rows]
            cross = jac[rows].T @ e
            return (np.block([[base[0], cross], [cross.T, e.T @ e]]),
                    np.concatenate([base[1], e.T @ r[rows]]))

        grams = [gram(g, b) for g, b in zip(self.groups, self._base_grams)]
        g_prior, b_prior = gram(self.prior_rows, self._base_grams[-1])
        g_all = sum((g for g, _ in grams), g_prior)
        b_all = sum((b for _, b in grams), b_prior)
        b_all[:p] += self.offset

        def solve(g: np.ndarray, b: np.ndarray) -> np.ndarray:
            d: np.ndarray = -sla.solve(g + ridge, b, assume_a="pos")
            return d

        def residual(rows: np.ndarray, d: np.ndarray) -> np.ndarray:
            res: np.ndarray = r[rows] + jac[rows] @ d[:p] + extra[rows] @ d[p:]
            return res

        d_all = solve(g_all, b_all)
        fit_ssr = float(np.sum(residual(np.arange(self.n_data), d_all) ** 2))
        held = np.zeros(len(self.groups))
        for i, (rows, centred, (g, b)) in enumerate(zip(self.groups, self.centred, grams)):
            e = residual(rows, solve(g_all - g, b_all - b)).reshape(-1, 3)
            held[i] = np.sum((e - e.mean(axis=0) if centred else e) ** 2)
        bar_res = np.full(0 if self.bar is None else self.bar.n, np.nan)
        if self._bar_white is not None:
            _, e_bar, j_bar = self._bar_white
            bar_res = e_bar + j_bar @ d_all[:p] + extra[len(r):] @ d_all[p:]
        k_eff = 0.0
        if k:
            schur = g_all[p:, p:] - g_all[p:, :p] @ sla.solve(g_all[:p, :p] + self.ridge,
                                                             g_all[:p, p:], assume_a="pos")
            eig = np.clip(np.linalg.eigvalsh(schur), 0.0, None)
            k_eff = float(np.sum(eig / (eig + self.sigma ** 2)))
        return {"fit_ssr": fit_ssr, "held_ssr": float(held.sum()), "k_eff": k_eff,
                "bar_chi2": float(np.sum(bar_res ** 2)) if len(bar_res) else float("nan"),
                "held_groups": held, "bar_residual": bar_res}

    def score(self, term: Term, given: tuple[np.ndarray, dict[str, Any]] | None = None
              ) -> Score:
        """Return the score of ``term`` added to the model.

        ``given``: columns already chosen (added to the model too) and their :meth:`evaluate`.
        """
        base_cols, base = given or (self._empty(), self.base)
        cols = self.columns(term)
        new = self.evaluate(np.hstack([base_cols, cols]))
        k_eff = max(new["k_eff"] - base["k_eff"], 1e-9)
        dof = max(self.n_data - self.jac.shape[1] - new["k_eff"], 1.0)
        var = new["fit_ssr"] / dof
        gain = base["fit_ssr"] - new["fit_ssr"]
        f_stat = max(gain, 0.0) / k_eff / var
        n_held = self.n_held
        bar = self.bar is not None and bool(np.isfinite(new["bar_chi2"]))
        bar_gain = float(base["bar_chi2"] - new["bar_chi2"]) if bar else 0.0
        change2 = float(np.sum((new["bar_residual"] - base["bar_residual"]) ** 2)) if bar else 0.0
        return Score(term=term, n_parameters=cols.shape[1], k_eff=k_eff, bar_gain=bar_gain,
                     heldout_against=heldout_against((base["held_groups"]
                                                      - new["held_groups"]) / var),
                     bar_against=bar_against(bar_gain, change2, max(gain, 0.0) / var),
                     bar_normalised=float(np.sqrt(new["bar_chi2"] / self.bar.n))
                     if bar and self.bar is not None else None,
                     fit_rms=float(np.sqrt(new["fit_ssr"] / self.n_data)),
                     heldout_rms=float(np.sqrt(new["held_ssr"] / n_held)),
                     heldout_gain=float((base["held_ssr"] - new["held_ssr"]) / var),
                     p_value=float(f_sf(f_stat, k_eff, dof)),
                     bic_gain=float(gain / var - k_eff * np.log(self.n_data)))

    @property
    def heldout_rms(self) -> float:
        """Leave-one-location-out RMS of the model itself, m."""
        return float(np.sqrt(self.base["held_ssr"] / self.n_held))

    def view(self, term: Term) -> tuple[str, np.ndarray]:
        """Return a label and the residual of every sample seen along the term's direction.

        See :meth:`aacmm_pin.effects.Term.residual_along`.
        """
        return term.residual_along(self.cal.fun, self.samples, self._stylus(term),
                              self.cal.parameters.translation)
