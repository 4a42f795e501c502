"""Results of a discovery run (:func:`aacmm_pin.discover`): scores, steps and the whole run.

Plain values: the loop (:mod:`aacmm_pin.analyses.discovery`) makes them, the writer and the figures
(:mod:`aacmm_pin.outputs.discovery_figures`) read them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from aacmm_pin.analyses.false_alarm import FalseAlarm
from aacmm_pin.analyses.residual_scan import Scan
from aacmm_pin.analyses.term_elimination import Dropped
from aacmm_pin.data.campaign import StatedNoise
from aacmm_pin.effects.base import Term
from aacmm_pin.effects.contract import LeftOut
from aacmm_pin.effects.registry import BUILTIN, library, plugin_of
from aacmm_pin.fit.identification_result import Calibration


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
    heldout_against: float = 1.0
    """One-sided p-value of the held-out groups' gains against the candidate (small: they agree
    it predicts left-out data worse; :func:`~aacmm_pin.analyses.linear_scorer.heldout_against`)."""
    bar_against: float = 1.0
    """One-sided p-value of the length bar against the change the candidate makes (small: the bar
    contradicts it; :func:`~aacmm_pin.analyses.linear_scorer.bar_against`); 1 without a bar."""
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
                "bic_gain": self.bic_gain, "k_eff": self.k_eff,
                "heldout_against": self.heldout_against, "bar_against": self.bar_against,
                "significant": self.significant}


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
    tried: list[Score] = field(default_factory=list)
    """The terms the step's forward selection took, each scored as it joined (p given the ones
    before it); some may be dropped after the refit (:attr:`dropped`)."""
    dropped: list[Dropped] = field(default_factory=list)
    """Terms of the model (this step's or an earlier one's) not significant given the others after
    this step's refit, dropped (:mod:`aacmm_pin.analyses.term_elimination`)."""
    refit_error_before: float | None = None
    """k-fold refit error (mean position error, m) of the model before the step, where discovery
    checks steps by refits (:mod:`aacmm_pin.analyses.refit_check`), else None."""
    refit_error_after: float | None = None

    def selection_summary(self) -> str:
        """Return the terms tried and dropped with their p-values in one line (empty if none dropped)."""
        if not self.dropped:
            return ""
        tried = ", ".join(f"{s.term.key} (p = {s.p_value:.2g})" for s in self.tried)
        dropped = ", ".join(
            f"{d.term.key} (p = {d.p_value:.2g} given the others, needed < {d.threshold:.2g}"
            + (f"; named in step {d.named_in}" if d.named_in and not any(
                s.term.key == d.term.key for s in self.tried) else "") + ")"
            for d in self.dropped)
        return f"tried {tried}; dropped {dropped}"

    def bar_disagreement(self) -> str:
        """Return a line when the length-bar RMS and the held-out RMS move opposite ways, else ''."""
        if self.bar_rms_before is None or self.bar_rms_after is None:
            return ""
        bar = self.bar_rms_after - self.bar_rms_before
        held = self.heldout_rms_after - self.heldout_rms_before
        if bar * held >= 0:
            return ""
        return (f"the length bar and the held-out SPATs disagree: bar RMS "
                f"{self.bar_rms_before * 1e6:.2f} -> {self.bar_rms_after * 1e6:.2f} um "
                f"{'rose' if bar > 0 else 'fell'} while held-out RMS "
                f"{self.heldout_rms_before * 1e6:.2f} -> {self.heldout_rms_after * 1e6:.2f} um "
                f"{'rose' if held > 0 else 'fell'}")

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
        forms = sorted({t.form for t in self.terms} - {"term"})  # e.g. map, harmonic
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
            "tried": [{"term": s.term.key, "p_value": s.p_value} for s in self.tried],
            "dropped": [d.to_dict() for d in self.dropped],
        }
        if forms:
            out["form"] = forms
        if self.refit_error_after is not None:
            out["refit_error_before_um"] = _um(self.refit_error_before)
            out["refit_error_after_um"] = _um(self.refit_error_after)
        if self.bar_rms_before is not None:
            out["bar_rms_before_um"] = self.bar_rms_before * 1e6
            out["bar_rms_after_um"] = _um(self.bar_rms_after)  # None: the bar cannot say
            out["bar_covered_rms_before_um"] = _um(self.bar_covered_rms_before)
            out["bar_covered_rms_after_um"] = _um(self.bar_covered_rms_after)
            out["bar_normalised_before"] = self.bar_normalised_before
            out["bar_normalised_after"] = self.bar_normalised_after
            out["bar_heldout_disagree"] = self.bar_disagreement() or None
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
    size_factors: list[dict[str, float]] = field(default_factory=list)
    """Per model (start, then after every step): the groups of the arm's sizes its fit rejected
    and the factor the held-out prior widened them by
    (:func:`aacmm_pin.analyses.linear_scorer.size_factors`)."""
    scan: Scan | None = None
    """The final residual against the stated noise and every per-sample variable
    (:func:`aacmm_pin.analyses.residual_scan.scan_residuals`)."""
    stated_noise: StatedNoise | None = None
    """The measurement noise the run judged the residual against."""
    capped: bool = False
    """Whether a fit reached its evaluation cap (``max_nfev``) and ended the loop there
    (:attr:`stopped_because` names the fit); the steps before it stand."""
    widened: tuple[str, ...] = ()
    """Effects not offered by default that the search took on because the residual was still
    larger than the stated noise when none of the others was significant (empty: none)."""
    failed: bool = False
    """Whether a step's fit failed (refused, not converged, or raised an AacmmError) and ended
    the loop there (:attr:`stopped_because` names the step and why); the steps before it stand."""
    left_out: tuple[LeftOut, ...] = ()
    """Effects asked for but not tried: the samples lack a column they declare
    (:attr:`aacmm_pin.effects.Effect.reads`; :func:`aacmm_pin.effects.contract.usable_effects`)."""
    false_alarm: FalseAlarm = field(default_factory=FalseAlarm)
    """The family-wise false-alarm rate the discovery ran at, and its split."""
    searched: int = 0
    """Candidates scored over all the steps (each counted once)."""
    refit_rule: str = ""
    """Why each step was checked by k-fold refits (:func:`aacmm_pin.analyses.refit_check.refit_rule`),
    "" where the linearised scores alone decided."""
    refit_errors: list[float] = field(default_factory=list)
    """k-fold refit error (mean position error, m) of the start model and after every step, where
    steps were checked by refits."""
    refused: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Significant candidates whose step's refit error did not fall: key -> the step's terms and
    refit errors before and with it (um)."""

    def refits_to_dict(self) -> dict[str, Any] | None:
        """Return ``discovery.json``'s ``"refits"`` (um), None where steps were not refitted."""
        if not self.refit_rule:
            return None
        return {"rule": self.refit_rule, "error_um": [v * 1e6 for v in self.refit_errors],
                "refused": self.refused}

    def false_alarm_text(self) -> str:
        """Return ``searched 38 candidates at 1 % family-wise (...)``."""
        return self.false_alarm.text(self.searched)

    def left_out_text(self, named: bool = True) -> str:
        """Return ``left out: fixture_creep (no column strain_um), ...``, or "" when none is.

        Args:
            named: whether the effects were named (``--effects``); else the built-in effects left
                out are not listed (the R-Test's columns on a points campaign, the arm
                temperature where none was recorded: nothing was asked for that), only the
                plugins' (a plugin installed for a column these files lack).
        """
        listed = [e for e in self.left_out if named or plugin_of(e.effect) != BUILTIN]
        return "left out: " + ", ".join(map(str, listed)) if listed else ""

    @property
    def unexplained(self) -> dict[str, Any] | None:
        """Return ``discovery.json``'s ``"unexplained"`` (um).

        None when the final residual is consistent with the stated noise and follows no variable,
        else its size, the stated noise, the chi-square p-value, the variables it follows and a
        hint.
        """
        return None if self.scan is None else self.scan.to_dict()

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
            "capped": self.capped, "failed": self.failed, "widened": list(self.widened),
            "left_out": [x.to_dict() for x in self.left_out],
            "gap": {"heldout_rms_um": [v * 1e6 for v in self.heldout_rms],
                    "fit_rms_um": [v * 1e6 for v in self.fit_rms],
                    "bar_rms_um": [_um(v) for v in self.bar_rms],
                    "bar_covered_rms_um": [_um(v) for v in self.bar_covered_rms],
                    "bar_normalised": self.bar_normalised,
                    "bar_covered_fraction": self.bar_covered_fraction,
                    "size_factors": self.size_factors},
            "final": {"extensions": sorted(cal.parameters.extensions),
                      "map_axes": list(cal.unknowns.map_axes),
                      "noise_um": self.noise * 1e6},
            "unexplained": self.unexplained, "refits": self.refits_to_dict(),
            "stated_noise_um": None if self.stated_noise is None else self.stated_noise.to_um(),
            "candidates_scored": self.n_candidates,
            "false_alarm": self.false_alarm.to_dict(self.searched), "runtime_s": self.runtime_s,
            "library": {name: e.description for name, e in library().items()},
        }
