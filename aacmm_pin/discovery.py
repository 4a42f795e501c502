r"""Discovery of what a model is missing: score named effects on held-out data, add, refit, repeat.

The loop (:func:`discover`):

1. fit the current model (:func:`aacmm_pin.identify` with the current extension terms);
2. linearise it at the solution and, for every candidate term of the effect library
   (:mod:`aacmm_pin.effects`; one per axis where the effect is per-axis), fit the residuals with
   the model's own directions plus the term's columns (each parameter with a Gaussian prior of its
   plausible size, so terms the data cannot see are shrunk, not overfitted) and measure
   * the held-out RMS: leave one R-Test location out, refit on the others, predict the left-out
     SPAT (less its mean: its nest offset is unknown) and pool over the locations;
   * the length-bar error, when the campaign has a bar: the candidate's linearised change of the bar
     errors, normalised by their predicted covariance (:mod:`aacmm_pin.bar_linear`: what the SPATs
     leave unknown, e.g. the nests' scale or map nodes only the bar visits, weighs little);
   * an F test of the fit improvement against the noise level (Bonferroni over the candidates) and
     the BIC change, with the term's effective number of parameters;
3. the best term (largest held-out improvement: leave-one-location-out plus length bar, both in
   chi-square units) that is significant, improves the BIC and the held-out score is named;
   further axes of the same effect join it while they stay significant
   given the ones already in (forward selection); the model is refitted with them (nonlinear);
4. stop when no candidate is significant: "nothing is missing".

Held-out RMS after a step is measured on the refitted model, and so are the length-bar errors (when
the campaign has a bar): their RMS (as :func:`aacmm_pin.validate`), their RMS over the bar readouts
inside the SPATs' coverage, and their normalised size (at most about 1 when the model explains
the bar).
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.linalg as sla
from scipy import stats
from tqdm.auto import tqdm

from aacmm_pin._blas import single_threaded_blas
from aacmm_pin.arm import Arm, load_arm
from aacmm_pin.bar_linear import LinearBar, scaled_columns
from aacmm_pin.campaign import Campaign
from aacmm_pin.effects import LIBRARY, Samples, Term
from aacmm_pin.encoder_map import touched_nodes
from aacmm_pin.errors import AacmmError
from aacmm_pin.identification import Calibration, identify, spat_samples
from aacmm_pin.identification import _check as check_campaign
from aacmm_pin.kinematics import StylusJacobians, stylus_jacobians

STARTS = ("dh", "proposed")
ALPHA = 1e-3
"""Family-wise error rate of one step's F tests (Bonferroni over the candidates)."""


@dataclass(frozen=True)
class Score:
    """How much one candidate term (given the model) explains of the residuals."""

    term: Term
    """The candidate."""
    n_parameters: int
    """Number of parameters of the term."""
    k_eff: float
    """Effective number of parameters the data determines (trace of the term's hat matrix)."""
    fit_rms: float
    """Fit RMS with the term, m (linearised)."""
    heldout_rms: float
    """Leave-one-location-out RMS with the term, m (linearised)."""
    heldout_gain: float
    """Held-out SSR decrease over the noise variance (chi-square units); > 0 is better."""
    p_value: float
    """F test of the fit improvement (per candidate, before the Bonferroni correction)."""
    bic_gain: float
    """BIC decrease (positive: the term pays for its parameters)."""
    bar_gain: float = 0.0
    """Normalised length-bar SSR decrease (chi-square units, linearised); 0 without a bar."""
    bar_normalised: float | None = None
    """Normalised length-bar error with the term (linearised), or None without a bar."""
    significant: bool = False
    """Whether it passes all tests of a step (set by the loop)."""

    @property
    def total_gain(self) -> float:
        """Held-out gain on everything the fit did not use: left-out locations plus the bar."""
        return self.heldout_gain + self.bar_gain

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form (um)."""
        return {"effect": self.term.effect, "axes": list(self.term.axes), "term": self.term.key,
                "score": self.total_gain, "heldout_gain": self.heldout_gain,
                "bar_gain": self.bar_gain, "bar_normalised": self.bar_normalised,
                "heldout_rms_um": self.heldout_rms * 1e6,
                "fit_rms_um": self.fit_rms * 1e6, "p_value": self.p_value,
                "bic_gain": self.bic_gain, "k_eff": self.k_eff, "significant": self.significant}


class _Linearised:
    """A calibration linearised at its solution, for scoring candidate terms on the residuals.

    All in the identification's reduced coordinates (constraints met, columns preconditioned) with
    a Gaussian prior of the plausible sizes on the arm directions (and the nest offsets' own prior
    rows): held-out refits are then well posed even where one location alone saw a direction.
    """

    def __init__(self, cal: Calibration, samples: Samples, bar: LinearBar | None = None):
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
        arm_rows = problem.r_inv[:problem.n_arm_y]
        self.ridge = self.sigma ** 2 * (arm_rows.T @ arm_rows)
        self.offset = self.ridge @ (z - problem.z(problem.x_ref))  # prior pull back to the start
        rows_loc = np.repeat(cal.location, 3)
        self.groups = [np.flatnonzero(rows_loc == m) for m in np.unique(cal.location)]
        self.n_held = self.n_data - 3 * len(self.groups)  # each left-out SPAT less its mean
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
            p_loc = problem.p[problem.n_arm:]
            info = (sum(g for g, _ in self._base_grams[:-1]) + self.ridge) / self.sigma ** 2
            info += p_loc.T @ p_loc / problem.sigma_location ** 2  # the nests' own prior
            cov = bar.covariance(info, self.jac[:self.n_data], self.sigma)
            chol = np.linalg.cholesky(cov + 1e-12 * np.trace(cov) / bar.n * np.eye(bar.n))
            self._bar_white = (chol, sla.solve_triangular(chol, bar.errors, lower=True),
                               sla.solve_triangular(chol, bar.jac_z, lower=True))
        self.base = self.evaluate(self._empty())

    def _empty(self) -> np.ndarray:
        return np.zeros((len(self.r) + (0 if self.bar is None else self.bar.n), 0))

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
        cols = scaled_columns(term, self.samples, self.stylus, self.cal.parameters, self.touched)
        out = np.zeros((len(self._empty()), cols.shape[2]))
        out[:self.n_data] = cols.reshape(self.n_data, -1)
        if self.bar is not None and self._bar_white is not None:
            try:
                out[len(self.r):] = sla.solve_triangular(
                    self._bar_white[0], self.bar.columns(term, self.touched), lower=True)
            except AacmmError:  # e.g. thermal without temp_c in lengthbar.csv: the bar abstains
                out[len(self.r):] = np.nan
        return out

    def evaluate(self, extra: np.ndarray) -> dict[str, float]:
        """Fit the residuals with the model's directions plus ``extra`` columns (prior sigma^2).

        Returns fit SSR, held-out SSR, the effective parameter count of ``extra`` and the
        normalised bar SSR (chi-square, NaN without a bar).
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
            return -sla.solve(g + ridge, b, assume_a="pos")

        def residual(rows: np.ndarray, d: np.ndarray) -> np.ndarray:
            return r[rows] + jac[rows] @ d[:p] + extra[rows] @ d[p:]

        d_all = solve(g_all, b_all)
        fit_ssr = float(np.sum(residual(np.arange(self.n_data), d_all) ** 2))
        held = 0.0
        for rows, (g, b) in zip(self.groups, grams):
            e = residual(rows, solve(g_all - g, b_all - b)).reshape(-1, 3)
            held += float(np.sum((e - e.mean(axis=0)) ** 2))
        bar_chi2 = float("nan")
        if self._bar_white is not None:
            _, e_bar, j_bar = self._bar_white
            bar_chi2 = float(np.sum((e_bar + j_bar @ d_all[:p] + extra[len(r):] @ d_all[p:]) ** 2))
        k_eff = 0.0
        if k:
            schur = g_all[p:, p:] - g_all[p:, :p] @ sla.solve(g_all[:p, :p] + self.ridge,
                                                             g_all[:p, p:], assume_a="pos")
            eig = np.clip(np.linalg.eigvalsh(schur), 0.0, None)
            k_eff = float(np.sum(eig / (eig + self.sigma ** 2)))
        return {"fit_ssr": fit_ssr, "held_ssr": held, "k_eff": k_eff, "bar_chi2": bar_chi2}

    def score(self, term: Term, given: tuple[np.ndarray, dict[str, float]] | None = None
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
        return Score(term=term, n_parameters=cols.shape[1], k_eff=k_eff,
                     bar_gain=float(base["bar_chi2"] - new["bar_chi2"]) if bar else 0.0,
                     bar_normalised=float(np.sqrt(new["bar_chi2"] / self.bar.n))
                     if bar and self.bar is not None else None,
                     fit_rms=float(np.sqrt(new["fit_ssr"] / self.n_data)),
                     heldout_rms=float(np.sqrt(new["held_ssr"] / n_held)),
                     heldout_gain=float((base["held_ssr"] - new["held_ssr"]) / var),
                     p_value=float(stats.f.sf(f_stat, k_eff, dof)),
                     bic_gain=float(gain / var - k_eff * np.log(self.n_data)))

    @property
    def heldout_rms(self) -> float:
        """Leave-one-location-out RMS of the model itself, m."""
        return float(np.sqrt(self.base["held_ssr"] / self.n_held))

    def view(self, term: Term) -> tuple[str, np.ndarray]:
        """Return a label and the residual of every sample seen along the term's direction.

        Angle terms: the residual as an angle error of the term's axis (arcsec, least squares on
        d(position)/d(angle)); scale terms: along the r-CS radius (um); measurement terms: along the
        R-Test displacement (um).
        """
        res = self.cal.fun
        if term.kind in ("angle", "map"):
            j = self.stylus.angles[:, :, term.axis - 1]
            angle = np.sum(j * res, axis=1) / np.maximum(np.sum(j * j, axis=1), 1e-30)
            return f"A{term.axis} angle residual (arcsec)", np.degrees(angle) * 3600
        if term.kind == "scale":
            radial = self.stylus.position - self.cal.parameters.translation
            radial /= np.linalg.norm(radial, axis=1, keepdims=True)
            return "radial residual (um)", np.sum(res * radial, axis=1) * 1e6
        disp = self.samples.displacement
        unit = np.zeros_like(res) if disp is None else disp / np.maximum(
            np.linalg.norm(disp, axis=1, keepdims=True), 1e-12)
        return "residual along the displacement (um)", np.sum(res * unit, axis=1) * 1e6


@dataclass
class Step:
    """One named effect: what was added and how the gap changed."""

    effect: str
    terms: list[Term]
    description: str
    fit_rms_before: float
    fit_rms_after: float
    heldout_rms_before: float
    heldout_rms_after: float
    bar_rms_before: float | None
    bar_rms_after: float | None
    score: Score
    runners_up: list[Score]
    values: dict[str, float]
    views: list[dict[str, Any]] = field(default_factory=list, repr=False)
    """Per term: variable label and values, residual label, residuals before and after (figures)."""
    bar_covered_rms_before: float | None = None
    """Length-bar RMS from the bar readouts inside the SPATs' coverage, before, m."""
    bar_covered_rms_after: float | None = None
    bar_normalised_before: float | None = None
    """Length-bar error normalised by its predicted covariance (of the model before the step)."""
    bar_normalised_after: float | None = None

    def bar_summary(self) -> str:
        """Return the length-bar errors before -> after in one line (empty without a bar)."""
        if self.bar_rms_before is None or self.bar_rms_after is None:
            return ""

        def arrow(before: float | None, after: float | None, unit: float, fmt: str) -> str:
            if before is None or after is None:
                return "-"
            return f"{before * unit:{fmt}} -> {after * unit:{fmt}}"

        return (f"RMS {arrow(self.bar_rms_before, self.bar_rms_after, 1e6, '.2f')} um, "
                f"inside the SPAT coverage "
                f"{arrow(self.bar_covered_rms_before, self.bar_covered_rms_after, 1e6, '.2f')} um, "
                f"normalised {arrow(self.bar_normalised_before, self.bar_normalised_after, 1, '.2f')}")

    @property
    def axes(self) -> list[int]:
        """Axes named (sorted), empty for arm-wide effects."""
        return sorted({a for t in self.terms for a in t.axes})

    def to_dict(self) -> dict[str, Any]:
        """Return the step as in ``discovery.json`` (um)."""
        forms = sorted({"map" if t.kind == "map" else "harmonic" for t in self.terms})
        out: dict[str, Any] = {
            "effect": self.effect, "axes": self.axes, "terms": [t.key for t in self.terms],
            "description": self.description,
            "fit_rms_before_um": self.fit_rms_before * 1e6,
            "fit_rms_after_um": self.fit_rms_after * 1e6,
            "heldout_rms_before_um": self.heldout_rms_before * 1e6,
            "heldout_rms_after_um": self.heldout_rms_after * 1e6,
            "score": self.score.total_gain, "p_value": self.score.p_value,
            "bic_gain": self.score.bic_gain, "k_eff": self.score.k_eff,
            "runners_up": [s.to_dict() for s in self.runners_up],
            "values": self.values,
        }
        if self.effect == "encoder":
            out["form"] = forms
        if self.bar_rms_before is not None:
            out["bar_rms_before_um"] = self.bar_rms_before * 1e6
            out["bar_rms_after_um"] = _um(self.bar_rms_after)  # None: the bar cannot say
            out["bar_covered_rms_before_um"] = _um(self.bar_covered_rms_before)
            out["bar_covered_rms_after_um"] = _um(self.bar_covered_rms_after)
            out["bar_normalised_before"] = self.bar_normalised_before
            out["bar_normalised_after"] = self.bar_normalised_after
        return out


def _um(value: float | None) -> float | None:
    return None if value is None else value * 1e6


@dataclass
class Discovery:
    """Result of :func:`discover`."""

    start: str
    steps: list[Step]
    missing: list[dict[str, Any]]
    stopped_because: str
    calibration: Calibration
    """The final model's calibration (write it with :func:`aacmm_pin.write_calibration`)."""
    start_calibration: Calibration
    heldout_rms: list[float]
    """Held-out RMS of the start model and after every step, m."""
    fit_rms: list[float]
    bar_rms: list[float | None]
    """Length-bar RMS of the start model and after every step, m (None without a bar)."""
    bar_covered_rms: list[float | None]
    """The same from the bar readouts inside the SPATs' coverage, m."""
    bar_normalised: list[float | None]
    """Length-bar errors of every model normalised by the final model's predicted covariance."""
    bar_covered_fraction: float | None
    """Share of the bar readouts inside the SPATs' coverage."""
    noise: float
    """Noise level (sigma per coordinate) of the final model, m."""
    n_candidates: list[int]
    runtime_s: float

    @property
    def named(self) -> list[tuple[str, list[int]]]:
        """(effect, axes) of every step, in order."""
        return [(s.effect, s.axes) for s in self.steps]

    def to_dict(self) -> dict[str, Any]:
        """Return the ``discovery.json`` content."""
        cal = self.calibration
        return {
            "start": self.start, "steps": [s.to_dict() for s in self.steps],
            "missing": self.missing, "stopped_because": self.stopped_because,
            "gap": {"heldout_rms_um": [v * 1e6 for v in self.heldout_rms],
                    "fit_rms_um": [v * 1e6 for v in self.fit_rms],
                    "bar_rms_um": [_um(v) for v in self.bar_rms],
                    "bar_covered_rms_um": [_um(v) for v in self.bar_covered_rms],
                    "bar_normalised": self.bar_normalised,
                    "bar_covered_fraction": self.bar_covered_fraction},
            "final": {"extensions": sorted(cal.parameters.extensions),
                      "map_axes": list(cal.unknowns.map_axes),
                      "noise_um": self.noise * 1e6},
            "candidates_scored": self.n_candidates, "runtime_s": self.runtime_s,
            "library": {name: e.description for name, e in LIBRARY.items()},
        }


def _linear_bar(arm: Arm, cal: Calibration, campaign: Campaign) -> LinearBar | None:
    if campaign.lengthbar is None or not campaign.bar:
        return None
    try:
        bar = LinearBar(cal, campaign, arm)
    except AacmmError:  # e.g. a thermal term and no temp_c in lengthbar.csv
        return None
    return bar if bar.n else None


def _in_model(term: Term, terms: list[Term], map_axes: list[int], use_rtest: bool) -> bool:
    if term.effect == "rtest":  # the measured displacement is used, or not
        return use_rtest
    if term.kind == "map":  # a map may replace a harmonic term of its axis
        return term.axis in map_axes
    if term.effect == "encoder":
        return term.axis in map_axes or any(t.effect == "encoder" and t.axes == term.axes
                                            for t in terms)
    return any(t.key == term.key for t in terms)


def discover(campaign: Campaign, arm: Arm | None = None, start: str = "dh", *,
             effects: list[str] | None = None, use_rtest: bool = True, max_steps: int = 6,
             alpha: float = ALPHA, progress: bool = False) -> Discovery:
    """Find the effects the ``start`` model is missing on a campaign, add them and refit.

    Args:
        campaign: SPAT campaign (with ``temp_c`` / ``t_s`` columns where the effects need them;
            a length bar, when present, joins the held-out score and is reported before and after
            every step).
        arm: the arm (default: the embedded default arm).
        start: ``"dh"`` (DH errors, tool) or ``"proposed"`` (also every axis' encoder map).
        effects: names of library effects to try (default: all of :data:`aacmm_pin.effects.LIBRARY`).
        use_rtest: whether the start model uses each sample's R-Test displacement.
        max_steps: most effects to add.
        alpha: family-wise error rate of a step's significance tests (Bonferroni).
        progress: show progress bars.

    Returns:
        The steps, the final calibration and why the loop stopped.

    Raises:
        ValueError: for an unknown start or effect name.
        IdentificationError: if the campaign cannot be identified (see :func:`identify`).
    """
    if start not in STARTS:
        raise ValueError(f"start: choose from {', '.join(STARTS)}, got {start!r}")
    names = list(LIBRARY) if effects is None else list(effects)
    if unknown := [n for n in names if n not in LIBRARY]:
        raise ValueError(f"effects: unknown {unknown}; the library has {', '.join(LIBRARY)}")
    with single_threaded_blas():  # many small products: threads only spin
        return _discover(campaign, arm, start, names, use_rtest, max_steps, alpha, progress)


def _discover(campaign: Campaign, arm: Arm | None, start: str, names: list[str], use_rtest: bool,
              max_steps: int, alpha: float, progress: bool) -> Discovery:
    tic = time.perf_counter()
    arm = arm or load_arm()
    check_campaign(campaign, arm)
    samples = spat_samples(campaign, arm)
    map_axes = list(range(1, arm.n_axes + 1)) if start == "proposed" else []
    terms: list[Term] = []

    def fit() -> Calibration:
        cal = identify(campaign, arm, model="proposed" if map_axes else "dh", use_rtest=use_rtest,
                       map_axes=tuple(map_axes) or None, extensions=tuple(terms))
        if not cal.success:
            raise AacmmError(f"discovery: the fit with {', '.join(t.key for t in terms) or start} "
                             f"did not converge: {cal.message}")
        return cal

    cal = first = fit()
    bar_now = _linear_bar(arm, cal, campaign)
    lin = _Linearised(cal, samples, bar_now)
    steps: list[Step] = []
    held, fits, bars = [lin.heldout_rms], [cal.fit_rms], [bar_now]
    n_candidates: list[int] = []
    stopped, missing = "", []
    ticker = tqdm(total=max_steps, desc="discover", unit="step", disable=not progress, leave=False)
    def candidates() -> list[Term]:
        out = [t for n in names if not LIBRARY[n].in_start
               for t in LIBRARY[n].candidates(arm, samples)
               if not _in_model(t, terms, map_axes, use_rtest)]
        n_candidates.append(len(out))
        return out

    for _ in range(max_steps):
        terms_now = candidates()
        if not terms_now:
            stopped = ("no candidate to try: every effect asked for is in the model or has no "
                       "term these data can show")
            break
        threshold = alpha / len(terms_now)
        scores = _scored(lin, terms_now, threshold)
        good = [s for s in scores if s.significant]
        if not good:
            best = scores[0]
            stopped = (f"no candidate is significant against the noise "
                       f"({lin.sigma * 1e6:.2f} um): the best, {best.term.key}, changes the held-out "
                       f"RMS by {(best.heldout_rms - lin.heldout_rms) * 1e6:+.3f} um, "
                       f"p = {best.p_value:.2g} (needed < {threshold:.2g}), BIC gain "
                       f"{best.bic_gain:.1f}")
            break
        chosen = _forward(lin, good[0], terms_now, threshold)
        new_terms = [s.term for s in chosen]
        map_axes += [t.axis for t in new_terms if t.kind == "map"]
        terms = [t for t in terms if not (t.effect == "encoder" and t.axis in map_axes)]
        terms += [t for t in new_terms if t.kind != "map" and t.effect != "rtest"]
        use_rtest = use_rtest or any(t.effect == "rtest" for t in new_terms)
        new_cal = fit()
        new_bar = _linear_bar(arm, new_cal, campaign)
        new_lin = _Linearised(new_cal, samples, new_bar)
        views = []
        for t in sorted(new_terms, key=lambda t: t.axes)[:4]:
            label, values = t.variable(samples)
            res_label, before = lin.view(t)
            views.append({"term": t.key, "variable": label, "x": values, "residual": res_label,
                          "before": before, "after": new_lin.view(t)[1]})
        effect = good[0].term.effect
        step = Step(
            effect=effect, terms=new_terms,
            description="; ".join(t.describe() for t in new_terms),
            fit_rms_before=cal.fit_rms, fit_rms_after=new_cal.fit_rms,
            heldout_rms_before=lin.heldout_rms, heldout_rms_after=new_lin.heldout_rms,
            bar_rms_before=None if bar_now is None else bar_now.rms,
            bar_rms_after=None if new_bar is None else new_bar.rms,
            score=good[0], runners_up=[s for s in scores if s.term.effect != effect][:5],
            values={n: float(v) for t in new_terms if t.key in new_cal.parameters.extensions
                    for n, v in zip(t.names, new_cal.parameters.extensions[t.key])},
            views=views,
            bar_covered_rms_before=None if bar_now is None else bar_now.covered_rms,
            bar_covered_rms_after=None if new_bar is None else new_bar.covered_rms,
            bar_normalised_before=None if bar_now is None else lin.bar_normalised(bar_now.errors),
            bar_normalised_after=None if new_bar is None else lin.bar_normalised(new_bar.errors))
        steps.append(step)
        cal, lin, bar_now = new_cal, new_lin, new_bar
        held.append(lin.heldout_rms)
        fits.append(cal.fit_rms)
        bars.append(bar_now)
        ticker.update(1)
    else:
        terms_now = candidates()
        still = _scored(lin, terms_now, alpha / max(len(terms_now), 1))
        missing = [s.to_dict() for s in still if s.significant]
        stopped = (f"reached max_steps = {max_steps}" + (
            f"; {len(missing)} candidates are still significant (see missing)" if missing else
            "; nothing else is significant"))
    ticker.close()
    return Discovery(start=start, steps=steps, missing=missing, stopped_because=stopped,
                     calibration=cal, start_calibration=first, heldout_rms=held, fit_rms=fits,
                     bar_rms=[None if b is None else b.rms for b in bars],
                     bar_covered_rms=[None if b is None else b.covered_rms for b in bars],
                     bar_normalised=[None if b is None else lin.bar_normalised(b.errors) for b in bars],
                     bar_covered_fraction=None if bar_now is None else float(np.mean(bar_now.covered)),
                     noise=cal.sigma, n_candidates=n_candidates,
                     runtime_s=time.perf_counter() - tic)


def _forward(lin: _Linearised, best: Score, candidates: list[Term], threshold: float
             ) -> list[Score]:
    """Return the best term and the further axes of its effect that are significant given it.

    Forward selection on the linearised model over every candidate of the effect (one masked by a
    larger error at the start may be significant once that is explained); an encoder map may
    replace a harmonic term of the same axis (the map holds every harmonic its nodes resolve).
    """
    chosen = [best]
    pool = [t for t in candidates if t.effect == best.term.effect and t != best.term]
    while True:
        cols = np.hstack([lin.columns(c.term) for c in chosen])
        taken = {c.term.axes: c.term for c in chosen}
        pool = [t for t in pool if t.axes not in taken or (
            t.kind == "map" and taken[t.axes].kind != "map")]
        rescored = [s for s in _scored(lin, pool, threshold, (cols, lin.evaluate(cols)))
                    if s.significant]
        if not rescored:
            return chosen
        nxt = max(rescored, key=lambda s: s.total_gain)
        chosen = [c for c in chosen if c.term.axes != nxt.term.axes] + [nxt]
        pool = [t for t in pool if t != nxt.term]


def _scored(lin: _Linearised, terms: list[Term], threshold: float,
            given: tuple[np.ndarray, dict[str, float]] | None = None) -> list[Score]:
    """Return every term's score, marked significant or not, best held-out gain first."""
    scores = [_mark(lin.score(t, given), threshold) for t in terms]
    return sorted(scores, key=lambda s: -s.total_gain)


def _mark(score: Score, threshold: float) -> Score:
    """Return the score marked significant: F test, BIC and held-out (locations plus bar) pass."""
    ok = score.p_value < threshold and score.bic_gain > 0 and score.total_gain > 0
    return dataclasses.replace(score, significant=bool(ok))


def write_discovery(result: Discovery, arm: Arm, folder: str | Path) -> Path:
    """Write ``discovery.json``, the figures and the final model as a CALDIR in ``folder``.

    Files: ``discovery.json``, ``discovery_gap.png``, ``discovery_step<k>.png`` (residuals against
    the named effect's variable before and after), and the CALDIR files of
    :func:`aacmm_pin.write_calibration` (``parameters.json`` with the extensions, ...).
    """
    from aacmm_pin.discovery_figures import gap_figure, step_figure
    from aacmm_pin.export import write_calibration

    folder = Path(folder)
    write_calibration(result.calibration, arm, folder)
    (folder / "discovery.json").write_text(json.dumps(result.to_dict(), indent=2) + "\n")
    gap_figure(result, folder / "discovery_gap.png")
    for k, step in enumerate(result.steps, start=1):
        step_figure(step, k, folder / f"discovery_step{k}.png")
    return folder
