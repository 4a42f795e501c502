r"""Where model and data disagree: the residual against its stated noise and every per-sample variable.

After discovery's last step (:func:`aacmm_pin.discover`) the residual of the final model is judged
in two ways (:func:`scan_residuals`):

* **against the stated noise** (:class:`aacmm_pin.data.campaign.StatedNoise`, the paper's values by
  default): :math:`\chi^2 = \mathrm{SSR} / \sigma^2` with the fit's residual degrees of freedom
  :math:`3N - \mathrm{tr}\,H` (H: the hat matrix of the linearised fit, nest offsets and held
  directions included);
* **for structure**, variable by variable: time within each location, time overall, temperature,
  each axis angle, the gravity torque on each axis, the R-Test displacement per coordinate, the
  stylus' inclination and azimuth, each axis' direction of motion, and the location itself
  (spread). For a continuous variable the
  whitened residual's three coordinates are fitted smoothly (Legendre polynomials of the
  variable's rank, of degree 1 and of degrees 1-3, :data:`DEGREES`, the better with a Bonferroni
  factor; within each location for time within a location) on top
  of a constant per location (the nest offsets absorb those), a discrete one by its levels, and
  the fit improvement is F-tested against the residual's own variance with its degrees of freedom
  (so a wrong stated noise does not look like structure); the location's spread is Bartlett's
  test of equal variances. The p-values are Holm-corrected over the variables; the significant
  ones are ranked by p-value (time is reported once, see :func:`_within_better`).

The residual is *unexplained* when its chi-square exceeds the stated noise's (level
:data:`ALPHA_NOISE`) or a variable carries structure (family-wise level :data:`ALPHA_STRUCTURE`);
discovery passes its own shares of its false-alarm rate
(:class:`aacmm_pin.analyses.false_alarm.FalseAlarm`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aacmm_pin.data.columns import column
from aacmm_pin.data.poses import POSE_COLUMN
from aacmm_pin.distributions import bartlett_p, chi2_sf, f_logsf, f_sf
from aacmm_pin.effects.base import TIME_OVERALL, TIME_WITHIN_LOCATION, Effect, Variable
from aacmm_pin.effects.contract import usable_effects
from aacmm_pin.effects.registry import default_effects, library
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.model.samples import Samples

DEGREES = (1, 3)
"""Degrees of the smooth fits of a continuous variable (per location for the within-location
ones): a trend (few degrees of freedom, the power for a drift) and a curve; the better p-value,
times their number (Bonferroni), is the variable's."""
ALPHA_NOISE = 0.005
"""Level of the chi-square test of the residual against the stated noise."""
ALPHA_STRUCTURE = 0.005
"""Family-wise level of the structure tests (Holm over the variables)."""


@dataclass(frozen=True)
class Structure:
    """What one variable explains of the residual."""

    variable: str
    """Plain-language name, e.g. ``"time within each location"``."""
    where: str
    """Where it acts: ``"each location"``, an axis ``"A3"``, a coordinate, ``"all"``."""
    explained_rms: float
    """RMS of the residual coordinates the variable explains (less what noise would), m."""
    p_value: float
    """Holm-corrected p-value of its test."""
    log_p: float
    """Natural log of the uncorrected p-value (ranks variables whose p-values underflow)."""
    dof: int
    """Degrees of freedom of its fit (numerator of the F test)."""
    values: np.ndarray = field(repr=False)
    """The variable per sample, shape (N,) (figures)."""
    label: str = ""
    """Axis label with unit (figures)."""

    def to_dict(self) -> dict[str, Any]:
        """Return the ``discovery.json`` form (um)."""
        return {"variable": self.variable, "where": self.where,
                "explained_rms_um": self.explained_rms * 1e6, "p_value": self.p_value}


@dataclass(frozen=True)
class Scan:
    """Result of :func:`scan_residuals`."""

    fit_rms: float
    """RMS of the residual coordinates, m."""
    noise: float
    """Stated noise per coordinate, m (the RMS over the samples when they state their own)."""
    chi2: float
    """Residual sum of squares over the stated noise variance."""
    dof: float
    """Residual degrees of freedom (3N less the hat matrix' trace)."""
    p_value: float
    """Chi-square p-value of the residual against the stated noise (small: larger than stated)."""
    variables: list[Structure]
    """Every variable tested, best first."""
    residual: np.ndarray = field(repr=False)
    """Residual less each location's mean, shape (N, 3), m (figures)."""
    location: np.ndarray = field(repr=False)
    """Location of each residual row, shape (N,)."""
    location_ratio: dict[int, float] = field(default_factory=dict)
    """Residual RMS per location in units of the stated noise (1: as stated)."""
    suspects: tuple[str, ...] = ()
    """Keys of library terms not in the model whose variable the residual follows (set by
    :func:`aacmm_pin.discover`): they use it, yet were not named."""
    alpha_noise: float = ALPHA_NOISE
    """Level of the chi-square test against the stated noise."""
    alpha_structure: float = ALPHA_STRUCTURE
    """Family-wise level of the structure tests (Holm over the variables)."""

    @property
    def noise_ratio(self) -> float:
        """sqrt(chi2 / dof): the residual's size in units of the stated noise (1: as stated)."""
        return float(np.sqrt(self.chi2 / self.dof))

    @property
    def structure(self) -> list[Structure]:
        """The variables that carry structure (Holm), best first."""
        return [v for v in self.variables if v.p_value < self.alpha_structure]

    @property
    def noise_consistent(self) -> bool:
        """Whether the residual is consistent with the stated noise (chi-square test)."""
        return self.p_value >= self.alpha_noise

    @property
    def unexplained(self) -> bool:
        """Whether something is missing: residual above the stated noise or following a variable."""
        return not self.noise_consistent or bool(self.structure)

    def hint(self) -> str:
        """Return what the scan says, in one line."""
        if self.structure:
            top = self.structure[0]
            where = f" {top.where}" if top.variable == TIME else ""
            follows = (f"the residual follows {top.variable}{where} ({top.explained_rms * 1e6:.1f} "
                       f"um of {self.fit_rms * 1e6:.1f} um), p = {top.p_value:.2g}")
            if self.suspects:
                return (f"something is missing: {follows}; the library's "
                        f"{', '.join(self.suspects)} uses a variable it follows but did not pass "
                        f"discovery's tests (it may explain a part)")
            return f"something is missing that no effect in the library explains: {follows}"
        if not self.noise_consistent:
            above = sum(v > 1.0 for v in self.location_ratio.values())
            everywhere = ("at every location" if above == len(self.location_ratio)
                          else f"at {above} of {len(self.location_ratio)} locations")
            return (f"the residual ({self.fit_rms * 1e6:.2f} um, {self.noise_ratio:.2f} x the "
                    f"stated noise {self.noise * 1e6:.2f} um, p = {self.p_value:.2g}) is larger "
                    f"than the stated noise {everywhere} and follows no variable: the noise is "
                    f"larger than stated (check the stated noise) rather than an effect missing")
        return (f"the residual ({self.fit_rms * 1e6:.2f} um) is consistent with the stated noise "
                f"({self.noise * 1e6:.2f} um) and follows no variable")

    def to_dict(self) -> dict[str, Any] | None:
        """Return ``discovery.json``'s ``"unexplained"``: None when nothing is, else its summary."""
        if not self.unexplained:
            return None
        return {"fit_rms_um": self.fit_rms * 1e6, "noise_um": self.noise * 1e6,
                "noise_ratio": self.noise_ratio, "dof": self.dof, "p_value": self.p_value,
                "structure": [s.to_dict() for s in self.structure],
                "library_terms": list(self.suspects), "hint": self.hint()}


def residual_dof(cal: Calibration) -> float:
    """Return the residual degrees of freedom 3N - tr(H) of a calibration's linearised fit."""
    problem = cal.problem
    jac = problem.jac(problem.z(cal.x))
    n_data = 3 * len(cal.location)
    gram = jac.T @ jac
    data = jac[:n_data].T @ jac[:n_data]
    ridge = 1e-12 * np.trace(gram) / max(gram.shape[0], 1) * np.eye(gram.shape[0])
    return float(n_data - np.trace(np.linalg.solve(gram + ridge, data)))


WITHIN = TIME_WITHIN_LOCATION
OVERALL = TIME_OVERALL
TIME = "time"


def _variables(samples: Samples, stylus: np.ndarray | None = None,
               effects: Iterable[Effect] | None = None) -> list[Variable]:
    """Return every variable worth a test: time, what each registered effect follows, the stylus.

    The effects declare their variables (:meth:`aacmm_pin.effects.Effect.variables`: each axis'
    angle, gravity torque and direction of motion, the temperature, the R-Test displacement...),
    with the same thresholds as their candidates; a variable two effects follow is tested once.
    Kinds: ``"within"`` (fitted within each location), ``"global"`` (over all samples),
    ``"levels"`` (a few discrete values), ``"own"``: a measured displacement, fitted over all
    samples to the residual of the other two coordinates only (its own coordinate's residual holds
    the gauge's noise, which the displacement holds too: a regression on it would find that noise;
    a gain of the gauge is the library's ``rtest`` effect).
    """
    unit = "s" if samples.t is not None else "rows"
    t = samples.t if samples.t is not None else np.arange(samples.n, dtype=float)
    out = [Variable(WITHIN, "within each location", f"time within its location ({unit})",
                    samples.time_in_location(), "within"),
           Variable(OVERALL, "all", f"time ({unit})", t, "global")]
    chosen = effects if effects is not None else [library()[n] for n in default_effects()]
    for effect in usable_effects(chosen, samples)[0]:  # those whose columns the samples have
        out += effect.variables(samples.arm, samples)
    read = {c for effect in library().values() for c in effect.reads} | {"t_s", "sigma_um",
                                                                          POSE_COLUMN}  # a label
    for name, values in samples.columns.items():  # every other per-sample column, by name
        if name not in read and (col := column(name)).varies(values):
            out.append(Variable(f"the column {name}", "all", f"{name} ({col.unit or 'as written'})",
                                col.from_si(values)))
    if stylus is not None:  # the stylus' inclination from pointing down, and its azimuth
        unit_vec = stylus / np.maximum(np.linalg.norm(stylus, axis=1, keepdims=True), 1e-12)
        tilt = np.degrees(np.arccos(np.clip(-unit_vec[:, 2], -1.0, 1.0)))
        azimuth = np.degrees(np.arctan2(unit_vec[:, 1], unit_vec[:, 0]))
        if np.ptp(tilt) > 1.0:
            out.append(Variable("the stylus inclination", "stylus", "stylus inclination from "
                                "pointing down (deg)", tilt))
        if np.ptp(azimuth) > 1.0 and np.median(tilt) > 5.0:
            out.append(Variable("the stylus azimuth", "stylus", "stylus azimuth (deg)", azimuth))
    first = {v.name: v for v in reversed(out)}  # a name two effects follow: its first entry
    return [v for v in out if first[v.name] is v]


def _design(values: np.ndarray, location: np.ndarray, kind: str, degree: int = 3) -> np.ndarray:
    """Return the smooth fit's columns of a variable, shape (N, k).

    Continuous variables: Legendre polynomials of degree 1..``degree`` of the variable's rank
    mapped onto [-1, 1] (a smooth fit robust to a skewed spread), per location for ``"within"``;
    ``"levels"``: one indicator per level.
    """
    if kind == "levels":
        return _indicators(values)
    groups = [location == m for m in np.unique(location)] if kind == "within" \
        else [np.ones(values.size, dtype=bool)]
    cols = []
    for sel in groups:
        rank = np.argsort(np.argsort(values[sel], kind="stable"), kind="stable")
        u = 2.0 * rank / max(int(sel.sum()) - 1, 1) - 1.0
        for d in range(1, degree + 1):
            col = np.zeros(values.size)
            col[sel] = np.polynomial.legendre.Legendre.basis(d)(u)
            cols.append(col)
    return np.column_stack(cols)


def _projected_ss(white: np.ndarray, design: np.ndarray) -> tuple[float, int]:
    """Return the sum of squares of the whitened residual (N, 3) in span(design) and its rank."""
    u, s, _ = np.linalg.svd(design, full_matrices=False)
    rank = int(np.sum(s > s.max(initial=0.0) * 1e-10))
    coef = u[:, :rank].T @ white
    return float(np.sum(coef ** 2)), rank


def _indicators(index: np.ndarray) -> np.ndarray:
    levels = np.unique(index, return_inverse=True)[1].reshape(-1)
    out = np.zeros((index.size, int(levels.max(initial=-1)) + 1))
    out[np.arange(index.size), levels] = 1.0
    return out


def _within_better(designs: dict[str, np.ndarray], white: np.ndarray, loc_design: np.ndarray,
                   ssr: float, dof: float, alpha: float = ALPHA_STRUCTURE) -> bool:
    """Whether time within each location explains significantly more than time over the campaign.

    With the locations measured one after the other and each nest's offset free, a creep at one
    rate in every location *is* a drift over the campaign (the offsets take the steps), so a fit of
    time over the campaign follows either; one within each location is said only if its extra fit
    is significant (extra-sum-of-squares F test at ``alpha``, the structure tests' level): a creep
    of its own shape or direction per location.
    """
    small = np.hstack([loc_design, designs[OVERALL]])
    ss_small, rank_small = _projected_ss(white, small)
    ss_big, rank_big = _projected_ss(white, np.hstack([small, designs[WITHIN]]))
    ss_loc, rank_loc = _projected_ss(white, loc_design)
    k, dof_rest = 3 * (rank_big - rank_small), dof - 3 * (rank_big - rank_loc)
    if k <= 0 or dof_rest <= 0:
        return False
    rest = max(ssr - (ss_big - ss_loc), 1e-300)
    return bool(f_sf(((ss_big - ss_small) / k) / (rest / dof_rest), k, dof_rest)
                < alpha)


def _merge_time(ranked: list[Structure], within_better: bool) -> list[Structure]:
    """Report time once: within each location, or over the campaign (see :func:`_within_better`)."""
    times = {s.variable: s for s in ranked if s.variable in (WITHIN, OVERALL)}
    if len(times) < 2:
        return ranked
    keep = times[WITHIN] if within_better else times[OVERALL]
    where = ("within each location" if within_better else
             "over the campaign (or within each location at one rate: with the nest offsets free "
             "the two look the same)")
    merged = Structure(TIME, where, keep.explained_rms, min(s.p_value for s in times.values()),
                       min(s.log_p for s in times.values()), keep.dof, keep.values, keep.label)
    out, done = [], False
    for s in ranked:
        if s.variable in times:
            if not done:
                out.append(merged)
                done = True
        else:
            out.append(s)
    return out


def _location_spread(white: np.ndarray, sigma: np.ndarray, location: np.ndarray
                     ) -> tuple[Structure, float] | None:
    """Return the spread per location as a structure and its log p-value (Bartlett), or None.

    The spread is in units of each sample's stated noise (white, (N, 3)): points (20 um) beside
    SPATs (2 um) differ by what was stated, not by structure; its excess is in um of the worst
    location's own stated noise (sigma, (N, 1), m).
    """
    white_centred = white.copy()
    for m in np.unique(location):
        white_centred[location == m] -= white_centred[location == m].mean(axis=0)
    ids = np.unique(location)
    groups = [white_centred[location == m].reshape(-1) for m in ids]
    if len(groups) <= 1 or not all(g.size > 1 for g in groups):
        return None
    bartlett_pvalue = bartlett_p(groups)
    var = [float(np.mean(g ** 2)) for g in groups]
    worst = int(np.argmax(var))
    excess_var = max(var[worst] - float(np.mean(white_centred ** 2)), 0.0)
    worst_noise = float(np.sqrt(np.mean(sigma[location == ids[worst]] ** 2)))
    log_p = float(np.log(max(bartlett_pvalue, 1e-300)))
    return (Structure("the location (its spread)", "each location",
                      float(np.sqrt(excess_var)) * worst_noise, 1.0, log_p, len(groups) - 1,
                      location.astype(float), "location"), log_p)


def _holm(found: list[tuple[Structure, float]]) -> list[Structure]:
    """Return the structures by p-value, each p adjusted by Holm's step-down (monotone)."""
    found.sort(key=lambda item: item[1])
    ranked: list[Structure] = []
    for i, (s, log_p) in enumerate(found):  # the i-th smallest times (m - i)
        adjusted = min(1.0, float(np.exp(log_p)) * (len(found) - i))
        if ranked:
            adjusted = max(adjusted, ranked[-1].p_value)
        ranked.append(Structure(s.variable, s.where, s.explained_rms, adjusted, log_p, s.dof,
                                s.values, s.label))
    return ranked


def scan_residuals(cal: Calibration, samples: Samples, noise: float | np.ndarray,
                   stylus: np.ndarray | None = None, effects: Iterable[Effect] | None = None,
                   levels: tuple[float, float] = (ALPHA_NOISE, ALPHA_STRUCTURE)) -> Scan:
    """Judge a calibration's residual against the stated noise and test it for structure.

    Args:
        cal: the (final) calibration; its residual ``cal.fun`` and locations.
        samples: its samples (readouts, time, temperature, displacement, motion).
        noise: the stated noise of its measurements per coordinate, m (e.g. the R-Test's), or
            one per sample, shape (N,) (the residual is whitened row by row; the scan reports
            their RMS).
        stylus: the stylus vector (last joint to stylus centre) of every sample in the residual's
            frame, shape (N, 3), m, or None: its inclination and azimuth are variables too.
        effects: the effects whose variables are tested (default: those tried by default,
            :attr:`aacmm_pin.effects.Effect.by_default`; discovery adds those it was asked to try).
        levels: the levels of the test against the stated noise and of the structure tests
            (family-wise, Holm): discovery's shares of its false-alarm rate
            (:class:`aacmm_pin.analyses.false_alarm.FalseAlarm`).

    Returns:
        The scan (see the module doc); :attr:`Scan.unexplained` says whether something is missing.
    """
    residual, location = np.asarray(cal.fun, dtype=float), np.asarray(cal.location)
    n = residual.shape[0]
    dof = max(residual_dof(cal), 1.0)
    sigma = np.broadcast_to(np.asarray(noise, dtype=float), (n,))[:, None]
    white = residual / sigma
    ssr_stated = total = float(np.sum(white ** 2))
    noise_rms = float(np.sqrt(np.mean(sigma ** 2)))
    loc_design = _indicators(location)
    ss_loc, rank_loc = _projected_ss(white, loc_design)  # ~0: the nest offsets took the means
    centred = residual.copy()
    for m in np.unique(location):
        centred[location == m] -= centred[location == m].mean(axis=0)
    found: list[tuple[Structure, float]] = []
    designs: dict[str, np.ndarray] = {}
    for variable, where, label, values, kind in _variables(samples, stylus, effects):
        coords = [c for c in range(3) if kind != "own" or c != "xyz".index(where)]
        kind = "global" if kind == "own" else kind
        ss_base = _projected_ss(white[:, coords], loc_design)[0]
        fits = []
        for degree in (DEGREES if kind != "levels" else (0,)):
            designs[variable] = _design(values, location, kind, degree)  # the last: the curve
            ss, rank = _projected_ss(white[:, coords], np.hstack([loc_design, designs[variable]]))
            k = len(coords) * (rank - rank_loc)
            if k <= 0 or dof - k <= 0:
                continue
            explained = max(ss - ss_base, 0.0)
            rest = max(total - ss_loc - explained, 1e-300)
            log_p = float(f_logsf((explained / k) / (rest / (dof - k)), k, dof - k))
            excess = max(explained - k * rest / (dof - k), 0.0)  # less what noise would explain
            fits.append((log_p, k, excess))
        if not fits:
            continue
        log_p, k, excess = min(fits)
        log_p = min(log_p + float(np.log(len(fits))), 0.0)
        found.append((Structure(variable, where, float(np.sqrt(excess / (3 * n))) * noise_rms,
                                1.0, log_p, k, values, label), log_p))
    spread = _location_spread(white, sigma, location)
    if spread is not None:
        found.append(spread)
    ranked = _holm(found)
    if WITHIN in designs and OVERALL in designs:
        ranked = _merge_time(ranked, _within_better(designs, white, loc_design, total - ss_loc,
                                                    dof, levels[1]))
    return Scan(fit_rms=float(np.sqrt(np.mean(residual ** 2))), noise=noise_rms, chi2=ssr_stated,
                dof=dof, p_value=float(chi2_sf(ssr_stated, dof)), variables=ranked,
                residual=centred, location=location,
                location_ratio={int(m): float(np.sqrt(np.mean(white[location == m] ** 2)))
                              for m in np.unique(location)},
                alpha_noise=levels[0], alpha_structure=levels[1])
