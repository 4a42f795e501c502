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
     errors, normalised by their predicted covariance (:mod:`aacmm_pin.analyses.bar_linear`: what the SPATs
     leave unknown, e.g. the nests' scale or map nodes only the bar visits, weighs little);
   * an F test of the fit improvement against the noise level (Bonferroni over the candidates at
     the search's share of the false-alarm rate, :class:`~aacmm_pin.analyses.false_alarm.FalseAlarm`)
     and the BIC change, with the term's effective number of parameters;
3. the best term (largest held-out improvement: leave-one-location-out plus length bar, both in
   chi-square units) that is significant and improves the BIC is named, unless the held-out
   groups or the length bar contradict it (:data:`CONFIRM`: confirmations, not gates); further
   axes of the same effect join it while they stay significant given the ones already in
   (forward selection; a map replaces a harmonic of its axis only where it also predicts the
   held-out data better); the model is refitted with them (nonlinear);
   where the fit's residual is far beyond the stated noise on a campaign of points
   (:func:`aacmm_pin.analyses.refit_check.refit_rule`), the step is taken only if its k-fold
   refit error falls (each fold's poses predicted by the model fitted without them), else the
   next significant candidate is tried;
4. stop when no candidate is significant: "nothing is missing";
5. scan the final model's residual (:func:`aacmm_pin.analyses.residual_scan.scan_residuals`): against the
   campaign's stated noise (:class:`aacmm_pin.data.campaign.StatedNoise`) and for structure along every
   per-sample variable (time, temperature, angles, gravity torques, displacement, motion): what
   no effect of the library explains (:attr:`Discovery.unexplained`), at the scan's shares of the
   false-alarm rate.

The family-wise false-alarm rate (default 1 %, ``false_alarm``) is spent once over the steps, the
candidates and the scan (:mod:`aacmm_pin.analyses.false_alarm`): on a campaign where nothing is
missing, at most that share of runs names anything or calls the residual unexplained.

Held-out RMS after a step is measured on the refitted model, and so are the length-bar errors (when
the campaign has a bar): their RMS (as :func:`aacmm_pin.validate`), their RMS over the bar readouts
inside the SPATs' coverage, and their normalised size (at most about 1 when the model explains
the bar).
"""

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from aacmm_pin._blas import single_threaded_blas
from aacmm_pin.analyses.bar_linear import LinearBar
from aacmm_pin.analyses.discovery_results import Discovery, Score, Step
from aacmm_pin.analyses.false_alarm import FALSE_ALARM, FalseAlarm
from aacmm_pin.analyses.linear_scorer import LinearScorer
from aacmm_pin.analyses.refit_check import REFIT_FOLDS, refit_error, refit_rule
from aacmm_pin.analyses.residual_scan import TIME, Scan, scan_residuals
from aacmm_pin.analyses.term_elimination import Dropped, eliminate
from aacmm_pin.data.campaign import Campaign, StatedNoise
from aacmm_pin.effects.base import TIME_OVERALL, TIME_WITHIN_LOCATION, ModelSpec, Term
from aacmm_pin.effects.contract import usable_effects
from aacmm_pin.effects.registry import default_effects, library
from aacmm_pin.errors import AacmmError, MissingColumn
from aacmm_pin.fit.identification import identify
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.fit.measurements import Measurements, measurements, stated_noise
from aacmm_pin.model.arm import Arm, load_arm
from aacmm_pin.model.samples import Samples
from aacmm_pin.progress import Progress

STARTS = ("dh", "proposed")
StartReport = Callable[[float, float, "float | None", dict[str, float]], None]
"""``(held-out RMS m, fit RMS m, length-bar RMS m or None, size factors)`` of the start model,
called once it is fitted."""
StepReport = Callable[[int, Step], None]
"""``(k, step)``: step k (1-based), called as soon as it is found (before any figure)."""


MAX_NFEV_PER_FIT = 200
"""Default evaluation budget of discovery per fit it may make: ``max_nfev`` defaults to this
times ``max_steps + 1`` (the start and one refit a step; refits after a dropped term share it)."""


class FitCapReached(AacmmError):
    """The start model's fit spent discovery's evaluation budget (``max_nfev``): no step to report."""


class _CapReached(Exception):
    """A fit of a step spent the rest of discovery's evaluation budget (the loop ends)."""


class _FitFailed(Exception):
    """A fit was refused or did not converge (the loop ends; the message says which and why)."""


def _linear_bar(arm: Arm, cal: Calibration, campaign: Campaign) -> LinearBar | None:
    if campaign.lengthbar is None or not campaign.bar:
        return None
    try:
        bar = LinearBar(cal, campaign, arm)
    except MissingColumn:  # e.g. a thermal term and no temp_c in lengthbar.csv
        return None
    return bar if bar.n else None


def discover(campaign: Campaign, arm: Arm | None = None, start: str = "dh", *,
             effects: list[str] | None = None, use_rtest: bool = True, max_steps: int = 6,
             false_alarm: float = FALSE_ALARM, max_nfev: int | None = None, progress: bool = False,
             noise: StatedNoise | None = None, on_start: StartReport | None = None,
             on_step: StepReport | None = None) -> Discovery:
    """Find the effects the ``start`` model is missing on a campaign, add them and refit.

    Args:
        campaign: SPAT campaign (with ``temp_c`` / ``t_s`` columns where the effects need them;
            a length bar, when present, joins the held-out score and is reported before and after
            every step).
        arm: the arm (default: the embedded default arm).
        start: ``"dh"`` (DH errors, tool) or ``"proposed"`` (also every axis' encoder map).
        effects: names of library effects to try (default: every registered effect tried by
            default, :attr:`aacmm_pin.effects.Effect.by_default`, i.e. all but
            ``lateral_compliance`` and plugins' opt-in effects, and, when none of them is
            significant and the residual is still larger than the stated noise while following
            no variable of the effects tried, those others too, by the same tests
            (:attr:`Discovery.widened`); ``["all"]``: every registered effect).
        use_rtest: whether the start model uses each sample's R-Test displacement.
        max_steps: most effects to add.
        false_alarm: family-wise false-alarm rate of the whole discovery (the steps' searches
            and the residual scan; :class:`~aacmm_pin.analyses.false_alarm.FalseAlarm`): on a
            campaign where nothing is missing, the chance that anything is named or called
            unexplained.
        max_nfev: most residual evaluations of all the discovery's fits together (the start, each
            step's refit, the refits after dropped terms; each fit stops at its tolerance);
            None: :data:`MAX_NFEV_PER_FIT` x (``max_steps`` + 1). A step's fit that spends it
            ends the loop: the steps before it stand, and :attr:`Discovery.capped` and
            :attr:`Discovery.stopped_because` say which fit.
        progress: show progress bars.
        noise: the measurement noise stated per kind (default: the campaign's ``campaign.json``,
            else the paper's values); the nest offsets' prior is its ``location``, and the final
            residual is judged against it (:attr:`Discovery.unexplained`).
        on_start: called with the start model's held-out, fit and length-bar RMS (m) and size
            factors as soon as it is fitted (to print results as they are found, see
            :data:`StartReport`).
        on_step: called with each step's number (1-based) and the step as soon as it is found.

    Returns:
        The steps, the final calibration, why the loop stopped and what the final residual shows
        that no effect explains.

    Raises:
        ValueError: for an unknown start or effect name, or a false-alarm rate outside (0, 1).
        IdentificationError: if the campaign cannot be identified (see :func:`identify`).
        FitCapReached: if the start model's fit spends ``max_nfev``.
    """
    rate = FalseAlarm(false_alarm)
    if start not in STARTS:
        raise ValueError(f"start: choose from {', '.join(STARTS)}, got {start!r}")
    known = library()
    names = default_effects() if effects is None else list(effects)
    if names == ["all"]:
        names = list(known)
    if unknown := [n for n in names if n not in known]:
        raise ValueError(f"effects: unknown {unknown}; the library has {', '.join(known)}")
    with single_threaded_blas():  # many small products: threads only spin
        budget = MAX_NFEV_PER_FIT * (max_steps + 1) if max_nfev is None else max_nfev
        return _discover(campaign, arm, start, names, use_rtest, max_steps, rate, budget,
                         progress, noise or campaign.noise or StatedNoise(),
                         (on_start or _quiet_start, on_step or _quiet_step), effects is None)


def _quiet_start(heldout_rms: float, fit_rms: float, bar_rms: float | None,
                 size_factors: dict[str, float]) -> None:
    """Report nothing (the default of :func:`discover`'s ``on_start``)."""


def _quiet_step(k: int, step: Step) -> None:
    """Report nothing (the default of :func:`discover`'s ``on_step``)."""


def _discover(campaign: Campaign, arm: Arm | None, start: str, names: list[str], use_rtest: bool,
              max_steps: int, rate: FalseAlarm, max_nfev: int, progress: bool, noise: StatedNoise,
              report: tuple[StartReport, StepReport], widen: bool = False) -> Discovery:
    tic = time.perf_counter()
    search = _Search(campaign, arm or load_arm(), start, names, use_rtest, rate, max_nfev, noise)
    search.begin(report[0])
    ticker = Progress("discover", "step", total=max_steps, enabled=progress)
    while True:
        search.steps_up_to(max_steps, report[1], ticker)
        if not widen or search.widened or search.capped or search.failed \
                or len(search.steps) >= max_steps or search.missing or not search.widen():
            break
    ticker.close()
    return search.result(time.perf_counter() - tic)


class _Search:
    """The state of one discovery: the model so far, its scorer, the steps, the fits' budget.

    Only the effects whose declared columns the samples have are asked anything
    (:func:`aacmm_pin.effects.contract.usable_effects`); the others are listed in ``left_out``.
    """

    def __init__(self, campaign: Campaign, arm: Arm, start: str, names: list[str],
                 use_rtest: bool, rate: FalseAlarm, max_nfev: int, noise: StatedNoise):
        self.campaign, self.arm, self.start, self.names = campaign, arm, start, names
        self.rate, self.alpha = rate, rate.search  # the search's share, spent once over the steps
        self.max_nfev, self.noise = max_nfev, noise
        self.meas = measurements(campaign, arm, use_rtest, noise=noise)
        self.samples = self.meas.samples
        self.spec = ModelSpec((), tuple(arm.measured_axes) if start == "proposed" else (),
                              use_rtest)
        self.effects, self.left_out = usable_effects(
            [library()[n] for n in names if not library()[n].in_start], self.samples)
        self.left = max_nfev  # evaluations left to all the fits below together
        self.steps: list[Step] = []
        self.n_candidates: list[int] = []
        self.searched: set[str] = set()  # keys of every candidate scored
        self.named_in: dict[str, int] = {}  # term key -> step that named it
        self.missing: list[dict[str, Any]] = []
        self.stopped, self.capped, self.failed = "", False, False
        self.widened: list[str] = []
        self.refit_why = ""  # why steps are checked by refits (refit_rule), "" where they are not
        self.refit_dropped = ""  # why the refit check stopped (a fold's fit refused), "" if it did not
        self.refits: list[float] = []  # k-fold refit error of the start and each step's model, m
        self.refused: dict[str, dict[str, Any]] = {}  # candidate -> its step's refit errors (um)

    def fit(self, model: ModelSpec | None = None) -> Calibration:
        """Return the fit of ``model`` (default: the start model) within the budget left.

        Raises:
            _CapReached: the budget is spent, or the fit spent it.
            _FitFailed: the fit was refused or did not converge.
        """
        model = model or self.spec
        if self.left <= 0:
            raise _CapReached
        cal = identify(self.campaign, self.arm, model="proposed" if model.map_axes else "dh",
                       use_rtest=model.use_rtest, map_axes=model.map_axes or None,
                       extensions=model.terms, max_nfev=self.left,
                       nests="estimate",  # one treatment for every model
                       noise=self.noise)
        self.left -= cal.nfev
        if _capped(cal):  # the caller ends the loop
            raise _CapReached
        if not (cal.success or cal.judged):  # a residual judged against the noise: examined
            what = "did not converge" if cal.status <= 0 else "was refused"  # scipy: > 0 converged
            raise _FitFailed(f"the fit with {', '.join(t.key for t in model.terms) or self.start} "
                             f"{what}: {cal.message}")
        return cal

    def begin(self, on_start: StartReport) -> None:
        """Fit and score the start model, and report it.

        Raises:
            FitCapReached: the start model's fit spent the budget.
            AacmmError: the start model's fit failed.
        """
        try:
            self.cal = self.first = self.fit()
        except _CapReached:
            raise FitCapReached(f"discover: the fit of the start model ({self.start}) reached the "
                                f"cap of {self.max_nfev} evaluations before converging: raise "
                                "--max-nfev (max_nfev)") from None
        except _FitFailed as exc:  # nothing found yet to keep
            raise AacmmError(f"discover: {exc}") from None
        self.bar_now = _linear_bar(self.arm, self.cal, self.campaign)
        self.lin = LinearScorer(self.cal, self.samples, self.bar_now)
        self.held, self.fits = [self.lin.heldout_rms], [self.cal.fit_rms]
        self.bars, self.factors = [self.bar_now], [self.lin.size_factors]
        self.refit_why = refit_rule(self.campaign, self.cal, self.noise)
        if self.refit_why:
            start = self._refit(self.spec)
            self.refits = [] if start is None else [start]
        on_start(self.lin.heldout_rms, self.cal.fit_rms,
                 None if self.bar_now is None else self.bar_now.rms, self.lin.size_factors)

    def candidates(self) -> list[Term]:
        """Return the terms to try: offered, not in the model, not named before (nor dropped)."""
        out = [t for e in self.effects for t in e.offered(self.arm, self.samples)
               if not t.in_model(self.spec) and t.key not in self.named_in
               and t.key not in self.refused]
        self.n_candidates.append(len(out))
        self.searched.update(t.key for t in out)
        return out

    def steps_up_to(self, max_steps: int, on_step: StepReport, ticker: Progress) -> None:
        """Take steps until none is significant, a fit ends the loop, or ``max_steps`` are taken."""
        for _ in range(max_steps - len(self.steps)):
            terms_now = self.candidates()
            if not terms_now:
                self.stopped = ("no candidate to try: every effect asked for is in the model or "
                                "has no term these data can show")
                return
            if not self._step(terms_now, on_step):
                return
            ticker.update(1)
        terms_now = self.candidates()
        still = _scored(self.lin, terms_now, self.alpha / max(len(terms_now), 1))
        self.missing = [s.to_dict() for s in still if s.significant]
        self.stopped = (f"reached max_steps = {max_steps}" + (
            f"; {len(self.missing)} candidates are still significant (see missing)"
            if self.missing else "; nothing else is significant"))

    def _step(self, terms_now: list[Term], on_step: StepReport) -> bool:
        """Score the candidates, name the best with its effect's further axes and refit.

        Where steps are checked by refits (:attr:`refit_why`), a step whose refit error does not
        fall is refused and the next significant candidate tried.

        Returns whether a step was taken (else :attr:`stopped` says why).
        """
        lin, threshold = self.lin, self.alpha / len(terms_now)
        scores = _scored(lin, terms_now, threshold)
        good = [s for s in scores if s.significant]
        if not good:
            best = scores[0]
            self.stopped = (f"no candidate is significant against the noise "
                            f"({lin.sigma * 1e6:.2f} um): the best, {best.term.key}, changes the "
                            f"held-out RMS by {(best.heldout_rms - lin.heldout_rms) * 1e6:+.3f} um, "
                            f"p = {best.p_value:.2g} (needed < {threshold:.2g}), BIC gain "
                            f"{best.bic_gain:.1f}")
            return False
        for best in good:
            if best.term.key not in self.refused:  # else refused with an earlier one's group
                pool = [t for t in terms_now if t.key not in self.refused]
                taken = self._try(best, (good, scores), pool, threshold, on_step)
                if taken is not None:
                    return taken
        self.stopped = (f"{len(good)} candidates are significant by the linearised score, but "
                        f"none lowers the {REFIT_FOLDS}-fold refit error "
                        f"({self.refits[-1] * 1e3:.4f} mm; refused: see refits)")
        return False

    def _try(self, best: Score, scored: tuple[list[Score], list[Score]], pool: list[Term],
             threshold: float, on_step: StepReport) -> bool | None:
        """Name ``best`` with its effect's further axes in ``pool``, refit and record the step.

        ``scored``: the significant candidates and all, best first. Returns True (taken), False
        (a fit ended the loop) or None (refused by refits: the model stays as it was).
        """
        chosen = _forward(self.lin, best, pool, threshold)
        new_terms = [s.term for s in chosen]
        spec_before, named_before = self.spec, dict(self.named_in)
        for t in new_terms:
            self.spec = t.added_to(self.spec)
            self.named_in[t.key] = len(self.steps) + 1
        # every term of the model earned given all the others (a term may have stood in for an
        # effect named later): the least significant dropped and the model refitted, until none
        try:
            new_cal, self.spec, dropped = eliminate(self.fit(), self.spec, self.fit, self.alpha,
                                                    self.named_in)
            refit = self._refit(self.spec)
        except (_CapReached, _FitFailed, AacmmError) as exc:  # AacmmError: a fit that raised
            self._ended(exc, new_terms)
            self.spec = spec_before  # the model of the steps that stand
            return False
        new_terms = [t for t in new_terms if t.in_model(self.spec)]
        if refit is not None and refit >= self.refits[-1]:  # the linearised gain does not hold
            self.spec, self.named_in = spec_before, named_before
            self.refused[best.term.key] = {"terms": [t.key for t in new_terms],
                                           "refit_error_before_um": self.refits[-1] * 1e6,
                                           "refit_error_um": refit * 1e6}
            return None
        new_bar = _linear_bar(self.arm, new_cal, self.campaign)
        new_lin = LinearScorer(new_cal, self.samples, new_bar)
        step = _step(new_terms, best, scored[1], (self.cal, self.lin, self.bar_now),
                     (new_cal, new_lin, new_bar), self.samples, (chosen, dropped))
        if refit is not None:
            step.refit_error_before, step.refit_error_after = self.refits[-1], refit
            self.refits.append(refit)
        self.steps.append(step)
        on_step(len(self.steps), step)
        self.cal, self.lin, self.bar_now = new_cal, new_lin, new_bar
        self.held.append(new_lin.heldout_rms)
        self.factors.append(new_lin.size_factors)
        self.fits.append(new_cal.fit_rms)
        self.bars.append(new_bar)
        return True

    def _refit(self, model: ModelSpec) -> float | None:
        """Return the model's k-fold refit error (m) where steps are checked by refits, else None."""
        if not self.refit_why:
            return None
        try:
            return refit_error(self.campaign, self.arm, model, noise=self.noise)
        except AacmmError as exc:  # a fold's fit refused (e.g. a group left with too few rows)
            self.refit_why = ""  # steps are taken on the linearised scores, as elsewhere
            why = str(exc).strip().splitlines()
            self.refit_dropped = (f"refits stopped, not possible on these folds "
                                  f"({why[0] if why else type(exc).__name__})")
            return None

    def _ended(self, exc: Exception, new_terms: list[Term]) -> None:
        """Record why a step's fit ended the loop: the budget spent, or the fit failed.

        ``exc``: :class:`_CapReached`, :class:`_FitFailed` (a fit returned refused or not
        converged) or the :class:`AacmmError` a fit raised (e.g. ``InputsDisagree``).
        """
        keys, k = ", ".join(t.key for t in new_terms), len(self.steps)
        if isinstance(exc, AacmmError):
            exc = _FitFailed(f"the fit with {keys} was refused ({type(exc).__name__}): {exc}")
        if isinstance(exc, _CapReached):
            self.capped = True
            self.stopped = (f"the fit of step {k + 1} ({keys}) reached the cap of {self.max_nfev} "
                            f"evaluations of all the discovery's fits before converging: the {k} "
                            "steps before it stand; raise --max-nfev (max_nfev)")
        else:
            self.failed = True
            self.stopped = (f"the fit of step {k + 1} ({keys}) failed, the {k} steps before it "
                            f"stand: {exc}")

    def widen(self) -> bool:
        """Take on the effects not offered by default where the scan would blame the noise.

        Returns whether it did (the search then goes on with them).
        """
        others, left_out = usable_effects([e for e in library().values()
                                           if e.name not in self.names and not e.in_start],
                                          self.samples)
        scan_now = self.scan() if others else None
        if scan_now is None or scan_now.noise_consistent or scan_now.structure:
            return False
        # the residual is larger than the noise and follows no variable of the effects tried:
        # the scan would blame the noise for an effect never tried. The effects not offered by
        # default may be what it asks for; scored by the same tests, named only if they pass.
        # (A residual that follows a variable is named by the scan as it is: on the UR5 grid,
        # widening there named lateral_compliance[A1], held-out 33.47 -> 33.33 um, test poses
        # 0.05998 -> 0.06009 mm: no gain the data can show.)
        self.widened = [e.name for e in others]
        self.left_out += left_out  # the others that these samples cannot show
        self.effects += others
        self.names = [*self.names, *self.widened]
        return True

    def scan(self) -> Scan:
        """Return the residual scan of the model so far (:func:`_residual_scan`)."""
        return _residual_scan(self.arm, self.cal, self.lin, self.samples, self.campaign,
                              self.meas, self.noise, self.names, self.rate)

    def result(self, runtime_s: float) -> Discovery:
        """Return the discovery: the steps, the final model and its scanned residual."""
        scan = self.scan()
        if scan.structure:  # library terms on a variable the residual follows, not named
            followed = {s.variable for s in scan.structure}
            if TIME in followed:  # the scan reports time once: either of its two variables
                followed |= {TIME_WITHIN_LOCATION, TIME_OVERALL}
            scan = dataclasses.replace(scan, suspects=tuple(
                t.key for e in self.effects for t in e.offered(self.arm, self.samples)
                if not t.in_model(self.spec) and followed.intersection(t.follows)))
        bars, lin, bar_now = self.bars, self.lin, self.bar_now
        return Discovery(
            start=self.start, steps=self.steps, missing=self.missing,
            stopped_because=self.stopped, calibration=self.cal, start_calibration=self.first,
            heldout_rms=self.held, fit_rms=self.fits, bar_rms=[None if b is None else b.rms
                                                               for b in bars],
            bar_covered_rms=[None if b is None else b.covered_rms for b in bars],
            bar_normalised=[None if b is None else lin.bar_normalised(b.errors) for b in bars],
            bar_covered_fraction=None if bar_now is None else float(np.mean(bar_now.covered)),
            noise=self.cal.sigma, n_candidates=self.n_candidates, runtime_s=runtime_s,
            size_factors=self.factors, scan=scan, stated_noise=self.noise, capped=self.capped,
            failed=self.failed, widened=tuple(self.widened), left_out=tuple(self.left_out),
            false_alarm=self.rate, searched=len(self.searched),
            refit_rule=self.refit_why or self.refit_dropped, refit_errors=self.refits,
            refused=self.refused)


def _residual_scan(arm: Arm, cal: Calibration, lin: LinearScorer, samples: Samples,
                   campaign: Campaign, meas: Measurements, noise: StatedNoise, names: list[str],
                   rate: FalseAlarm) -> Scan:
    """Return the residual of ``cal`` scanned against the stated noise (:func:`scan_residuals`).

    Every variable of the effects ``names`` and of the default ones is tested, at the scan's
    shares of the false-alarm ``rate``.
    """
    tools = np.concatenate(list(cal.parameters.tool_vectors(arm).values()))
    return scan_residuals(cal, samples, stated_noise(campaign, meas, noise),
                          np.einsum("nij,j->ni", lin.stylus.tool, tools),
                          [library()[n] for n in dict.fromkeys(default_effects() + names)],
                          (rate.noise, rate.structure))


def _capped(cal: Calibration) -> bool:
    """Whether a fit stopped at its evaluation cap (scipy's status 0) without converging."""
    return not cal.success and cal.status == 0


def _step(new_terms: list[Term], best: Score, scores: list[Score],
          before: tuple[Calibration, LinearScorer, LinearBar | None],
          after: tuple[Calibration, LinearScorer, LinearBar | None], samples: Samples,
          selection: tuple[list[Score], list[Dropped]] = ([], [])) -> Step:
    """Return the record of one step: what was added, and the model before and after it.

    ``selection``: the terms the step tried (as they joined) and the terms dropped after its refit.
    """
    (cal, lin, bar_now), (new_cal, new_lin, new_bar) = before, after
    views = []
    for t in sorted(new_terms, key=lambda t: t.axes):
        label, values = t.variable(samples)
        res_label, residual = lin.view(t)
        views.append({"term": t.key, "variable": label, "x": values, "residual": res_label,
                      "before": residual, "after": new_lin.view(t)[1]})
    effect = best.term.effect
    return Step(
        effect=effect, terms=new_terms,
        description="; ".join(t.describe() for t in new_terms),
        fit_rms_before=cal.fit_rms, fit_rms_after=new_cal.fit_rms,
        heldout_rms_before=lin.heldout_rms, heldout_rms_after=new_lin.heldout_rms,
        bar_rms_before=None if bar_now is None else bar_now.rms,
        bar_rms_after=None if new_bar is None else new_bar.rms,
        score=best, runners_up=[s for s in scores if s.term.effect != effect][:5],
        values={n: float(v) for t in new_terms if t.key in new_cal.parameters.extensions
                for n, v in zip(t.names, new_cal.parameters.extensions[t.key])},
        views=views,
        bar_covered_rms_before=None if bar_now is None else bar_now.covered_rms,
        bar_covered_rms_after=None if new_bar is None else new_bar.covered_rms,
        bar_normalised_before=None if bar_now is None else lin.bar_normalised(bar_now.errors),
        bar_normalised_after=None if new_bar is None else lin.bar_normalised(new_bar.errors),
        tried=selection[0], dropped=selection[1])


def _forward(lin: LinearScorer, best: Score, candidates: list[Term], threshold: float
             ) -> list[Score]:
    """Return the best term and the further axes of its effect that are significant given it.

    Forward selection on the linearised model over every candidate of the effect (one masked by a
    larger error at the start may be significant once that is explained); an encoder map may
    replace a harmonic term of the same axis (the map holds every harmonic its nodes resolve)
    where it also predicts the held-out data better (locations plus bar: a choice of form, not a
    detection).
    """
    chosen = [best]
    pool = [t for t in candidates if t.effect == best.term.effect and t != best.term]
    while True:
        cols = np.hstack([lin.columns(c.term) for c in chosen])
        taken = {c.term.axes: c.term for c in chosen}
        pool = [t for t in pool if t.axes not in taken or t.replaces(taken[t.axes])]
        # a form replacing a chosen term of its axis (a map for a harmonic) is a choice between
        # two forms of an effect already found: the one that predicts left-out data better
        rescored = [s for s in _scored(lin, pool, threshold, (cols, lin.evaluate(cols)))
                    if s.significant and (s.term.axes not in taken or s.total_gain > 0)]
        if not rescored:
            return chosen
        nxt = max(rescored, key=lambda s: s.total_gain)
        chosen = [c for c in chosen if c.term.axes != nxt.term.axes] + [nxt]
        pool = [t for t in pool if t != nxt.term]


def _scored(lin: LinearScorer, terms: list[Term], threshold: float,
            given: tuple[np.ndarray, dict[str, float]] | None = None) -> list[Score]:
    """Return every term's score, marked significant or not, best held-out gain first."""
    scores = [_mark(lin.score(t, given), threshold) for t in terms]
    return sorted(scores, key=lambda s: -s.total_gain)


MIN_K_EFF = 0.1
"""A term the data determine less than this (effective parameters) is not named: its columns are
(near) zero on these samples, e.g. an axis that does not move the measured point."""


CONFIRM = 0.01
"""A candidate the held-out groups or the length bar contradict at this one-sided level is not
named (:attr:`Score.heldout_against`, :attr:`Score.bar_against`): where it is real, each check
rejects it about this often, so the two cost at most 2 % of the search's power."""


def _mark(score: Score, threshold: float) -> Score:
    """Return the score marked significant: the F test (``threshold``) and the BIC pass.

    The held-out groups and the length bar confirm: they remove a candidate only where they
    contradict it (:data:`CONFIRM`), not where they are merely less sure than the F test.
    """
    ok = (score.p_value < threshold and score.bic_gain > 0 and score.k_eff >= MIN_K_EFF
          and min(score.heldout_against, score.bar_against) >= CONFIRM)
    return dataclasses.replace(score, significant=bool(ok))
