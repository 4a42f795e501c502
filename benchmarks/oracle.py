"""Discovery against the oracle: the power of ``discover`` next to that of the best possible test.

Run: ``python benchmarks/oracle.py`` (about 10 min of CPU; writes its section of BENCHMARKS.md),
``--quick`` for development (fewer seeds, one size; prints only).

For every effect kind of the library that discovery tries by default (encoder, compliance,
thermal, backlash, crosstalk; not ``rtest``: with the R-Test reading ignored the residual holds no
R-Test noise, so its detection is not noise-limited; not ``lateral_compliance``: tried only when
named; not ``tool``: in every start model) and for the two out-of-library
effects of ``tests/test_residual_scan.py`` (a fixture creeping in time within every location, a
link sagging with the A6 angle), on small campaigns (4 x 100 SPAT samples, 2 s apart, no bar):

* the **oracle** is the likelihood-ratio test that knows the effect's exact form: the start model
  fitted (discovery's own start fit, linearised: :class:`~aacmm_pin.analyses.linear_scorer.LinearScorer`)
  plus the effect's columns (no prior on them: scaled x 1000), F test of the fit improvement at
  level :data:`ORACLE_LEVEL`. Its power at a size is computed from the noncentrality
  ``|P d|^2 / sigma^2`` (d the effect's true change of the points, P the projection off the start
  model's columns, sigma the simulator's 2 um), and measured on the same campaigns as discovery;
* **discovery** is right when the final model adds exactly the hidden term(s) (library effects,
  nothing else named) or, out of the library, names nothing and reports "unexplained" with the
  right variable first;
* the **absorbed** share is ``1 - |P d|^2 / |d|^2``: the part of the effect the start model's own
  parameters take (the oracle cannot see it either);
* the **searching oracle** is the oracle's test over the m candidates discovery's first step
  scores at the same family-wise rate (Bonferroni: level :data:`ORACLE_LEVEL` / m): the power
  a search of those candidates can have at the rate discovery runs at;
* the **false-alarm rate** is measured on null campaigns (the case's start and campaign with the
  effect at size 0, :data:`NULL_SEEDS`): anything named or "unexplained".

The sizes tried are the factors of :data:`SEEDS` x the size where the oracle's power is 0.9 (from the seed-0
campaign's noncentrality).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import optimize, stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import aacmm_pin as ap  # noqa: E402
from aacmm_pin.analyses.discovery_results import Discovery  # noqa: E402
from aacmm_pin.analyses.false_alarm import FALSE_ALARM, FalseAlarm  # noqa: E402
from aacmm_pin.analyses.linear_scorer import LinearScorer  # noqa: E402
from aacmm_pin.analyses.residual_scan import TIME  # noqa: E402
from aacmm_pin.analyses.simulate import TrueArm  # noqa: E402
from aacmm_pin.effects.base import Term  # noqa: E402
from aacmm_pin.effects.builtin.encoder import encoder_map  # noqa: E402
from aacmm_pin.effects.registry import library  # noqa: E402
from aacmm_pin.fit.measurements import measurements  # noqa: E402
from aacmm_pin.model.samples import Samples  # noqa: E402
from aacmm_pin.units import ARCSEC, SIGMA_RTEST  # noqa: E402
from benchmarks._report import machine, write_section  # noqa: E402
from tests.test_residual_scan import creeping_fixture, sagging_link  # noqa: E402

N_PER_LOCATION = 100
DT_S = 2.0
ORACLE_LEVEL = FALSE_ALARM
"""The oracle's false-alarm rate: the family-wise rate discovery runs at (its default
``false_alarm``, spent over its steps' candidates and the residual scan)."""
NULL_SEEDS = range(1000, 1040)
SEEDS = {0.5: range(10), 1.0: range(20), 1.5: range(10)}
QUICK_SEEDS = {1.0: range(4)}
"""``--quick``: the 0.9 size only, these seeds, and the first :data:`QUICK_NULLS` null seeds."""
QUICK_NULLS = 5
"""Factor of the size where the oracle's power is 0.9 -> seeds of the campaigns at that size."""
BIG = 1e3
"""The oracle's columns are the term's scaled by this: its prior (the plausible size x BIG) is nil."""
CROSSTALK_DIRECTION = np.array([6.0, -4.0]) / np.hypot(6.0, 4.0)


@dataclass(frozen=True)
class Case:
    """One effect: how to hide it at a size, its exact form, and what discovery must say."""

    name: str
    library: bool
    """Whether the effect is one of the library's (else out of it: "unexplained" is right)."""
    start: str
    use_rtest: bool
    unit: str
    scale: float
    """SI per display unit."""
    make: Callable[[ap.Arm, int, float], tuple[ap.Campaign, np.ndarray]]
    """(arm, seed, size SI) -> campaign and the effect's true change of every point (N, 3), m."""
    oracle: Callable[[], Term]
    """The term of the effect's exact form."""
    expected: frozenset[str] = frozenset()
    """Library effects: the terms discovery must add (``encoder[A<n>]`` for a map or harmonic)."""
    variable: str = ""
    """Out of the library: the variable the residual scan must put first."""
    reference: float = 1.0
    """A size (SI) at which the noncentrality is computed (it scales with the size squared)."""


def _config(seed: int, effects: tuple[str, ...], **extra: object) -> ap.SimulationConfig:
    return ap.SimulationConfig(seed=seed, effects=effects, samples_per_location=N_PER_LOCATION,
                               bar_placements=0, **extra)  # type: ignore[arg-type]


def _timed(campaign: ap.Campaign) -> ap.Campaign:
    return campaign.with_spat(t=np.arange(len(campaign.spat.location)) * DT_S)


def _positions(true_arm: TrueArm, campaign: ap.Campaign) -> np.ndarray:
    """True points of every sample (MT-CS), location by location (the motion, as simulated)."""
    spat, out = campaign.spat, np.zeros((len(campaign.spat.location), 3))
    for m in np.unique(spat.location):
        sel = spat.location == m
        out[sel] = true_arm.positions(spat.q[sel], None if spat.temp is None else spat.temp[sel],
                                      frame="mt")
    return out


def simulated(effect: str, base: tuple[str, ...] = ("dh", "encoder", "rtest"),
              change: Callable[[ap.SimulationConfig, float], dict[str, object]] | None = None
              ) -> Callable[[ap.Arm, int, float], tuple[ap.Campaign, np.ndarray]]:
    """Return a maker of campaigns with a simulator effect at a size (``change``: config fields)."""

    def make(arm: ap.Arm, seed: int, size: float) -> tuple[ap.Campaign, np.ndarray]:
        effects = base + (effect,) if size else base
        config = _config(seed, effects)
        if change is not None:
            config = dataclasses.replace(config, **change(config, size))  # type: ignore[arg-type]
        sim = ap.simulate_campaign(arm, config)
        campaign = _timed(sim.campaign)
        if not size:
            return campaign, np.zeros((len(campaign.spat.location), 3))
        without = sim.truth.replace(
            extensions={k: v for k, v in sim.truth.extensions.items()
                        if not k.startswith(effect)},
            encoder_maps={} if effect == "encoder" else sim.truth.encoder_maps)
        d = (_positions(TrueArm(arm, sim.truth, config), campaign)
             - _positions(TrueArm(arm, without, dataclasses.replace(config, effects=base)),
                          campaign))
        return campaign, d

    return make


def out_of_library(change: Callable[[ap.Campaign, int, float], ap.Campaign]
                   ) -> Callable[[ap.Arm, int, float], tuple[ap.Campaign, np.ndarray]]:
    """Return a maker of campaigns of the paper's model with a change of the displacements."""

    def make(arm: ap.Arm, seed: int, size: float) -> tuple[ap.Campaign, np.ndarray]:
        campaign = _timed(ap.simulate_campaign(arm, _config(seed, ("dh", "encoder", "rtest")))
                          .campaign)
        if not size:
            return campaign, np.zeros((len(campaign.spat.location), 3))
        changed = change(campaign, seed, size)
        return changed, changed.spat.displacement - campaign.spat.displacement

    return make


def _creep_basis(samples: Samples) -> np.ndarray:
    out = np.zeros((samples.n, 3, 3))
    for c in range(3):
        out[:, c, c] = samples.time_in_location()
    return out


def _sag_basis(samples: Samples) -> np.ndarray:
    out = np.zeros((samples.n, 3, 1))
    out[:, 2, 0] = np.cos(samples.q[:, 5])
    return out


def _no_variable(samples: Samples) -> tuple[str, np.ndarray]:
    return "sample", np.arange(samples.n, dtype=float)


def _measurement(key: str, basis: Callable[[Samples], np.ndarray], k: int) -> Callable[[], Term]:
    return lambda: ap.MeasurementTerm(key, key, tuple(f"{key}.{i}" for i in range(k)), (1e-6,) * k,
                                      key, basis_of=basis, variable_of=_no_variable)


def _library_term(effect: str, key: str) -> Callable[[], Term]:
    def term() -> Term:
        out = library()[effect].term(key)
        assert out is not None
        return out
    return term


CASES = [
    Case("encoder error, A3 (from dh)", True, "dh", True, "arcsec", ARCSEC,
         simulated("encoder", ("dh", "rtest"),
                   lambda c, s: {"encoder_axes": (3,), "encoder_max": s}),
         lambda: encoder_map(3), frozenset({"encoder[A3]"}),
         reference=2 * ARCSEC),
    Case("gravity compliance, A2", True, "proposed", True, "urad/(N m)", 1e-6,
         simulated("compliance", change=lambda c, s: {"compliance": {2: s}}),
         _library_term("compliance", "compliance[A2]"), frozenset({"compliance[A2]"}),
         reference=1e-6),
    Case("thermal expansion (20-24 C)", True, "proposed", True, "ppm/K", 1e-6,
         simulated("thermal", change=lambda c, s: {"thermal_alpha": s}),
         _library_term("thermal", "thermal"), frozenset({"thermal"}), reference=1e-6),
    Case("backlash, A2", True, "proposed", True, "arcsec", ARCSEC,
         simulated("backlash", change=lambda c, s: {"backlash": {2: s}}),
         _library_term("backlash", "backlash[A2]"), frozenset({"backlash[A2]"}),
         reference=ARCSEC),
    Case("crosstalk, A4<-A3", True, "proposed", True, "arcsec", ARCSEC,
         simulated("crosstalk",
                   change=lambda c, s: {"crosstalk": {(4, 3): tuple(s * CROSSTALK_DIRECTION)}}),
         _library_term("crosstalk", "crosstalk[A4<-A3]"), frozenset({"crosstalk[A4<-A3]"}),
         reference=ARCSEC),
    Case("fixture creep (out of library)", False, "proposed", True, "um", 1e-6,
         out_of_library(creeping_fixture), _measurement("oracle_creep", _creep_basis, 3),
         variable=TIME, reference=1e-6),
    Case("A6 link sag (out of library)", False, "proposed", True, "um", 1e-6,
         out_of_library(sagging_link), _measurement("oracle_sag", _sag_basis, 1),
         variable="the A6 angle", reference=1e-6),
]


def added(result: Discovery) -> set[str]:
    """Return the terms the final model adds to its start (maps and harmonics as ``encoder[An]``)."""
    cal, start = result.calibration, result.start_calibration
    out = {("encoder[" + k[len("encoder_harmonic["):] if k.startswith("encoder_harmonic[") else k)
           for k in cal.parameters.extensions}
    return out | {f"encoder[A{a}]" for a in set(cal.unknowns.map_axes)
                  - set(start.unknowns.map_axes)}


def discovery_right(case: Case, result: Discovery) -> bool:
    """Whether discovery said what the case hides (see the module's docstring)."""
    if case.library:
        return added(result) == set(case.expected)
    report = result.unexplained
    return (not added(result) and report is not None and bool(report["structure"])
            and report["structure"][0]["variable"] == case.variable)


def false_alarm(result: Discovery) -> bool:
    """Whether a null campaign's discovery named anything or called the residual unexplained."""
    return bool(added(result)) or result.unexplained is not None


@dataclass
class Oracle:
    """The oracle on one campaign: its F test, and the effect's noncentrality and absorbed share."""

    p_value: float
    noncentrality: float
    absorbed: float
    k: int
    dof: float


def oracle(case: Case, result: Discovery, campaign: ap.Campaign, arm: ap.Arm,
           d: np.ndarray) -> Oracle:
    """Return the oracle's test on the campaign discovery ran on (its start fit, linearised)."""
    cal = result.start_calibration
    lin = LinearScorer(cal, measurements(campaign, arm, case.use_rtest).samples)
    cols = BIG * lin.columns(case.oracle())
    base, new = lin.base, lin.evaluate(cols)
    k = new["k_eff"]
    dof = max(lin.n_data - lin.jac.shape[1] - k, 1.0)
    f_stat = max(base["fit_ssr"] - new["fit_ssr"], 0.0) / k / (new["fit_ssr"] / dof)
    # the effect's change d off the start model's columns (with their prior), and off both
    data = np.zeros(len(lin.r))
    data[:lin.n_data] = d.ravel()

    def left(extra: np.ndarray) -> float:
        jac = np.hstack([lin.jac, extra[:len(lin.r)]])
        ridge = np.zeros((jac.shape[1],) * 2)
        ridge[:lin.jac.shape[1], :lin.jac.shape[1]] = lin.ridge
        coef = np.linalg.solve(jac.T @ jac + ridge, jac.T @ data)
        return float(np.sum((data - jac @ coef)[:lin.n_data] ** 2))

    off_model, off_both = left(cols[:, :0]), left(cols)
    total = float(np.sum(d ** 2))
    return Oracle(float(stats.f.sf(f_stat, k, dof)), (off_model - off_both) / SIGMA_RTEST ** 2,
                  1.0 - off_model / total if total else 0.0, int(round(k)), dof)


def oracle_power(noncentrality: float, k: int, dof: float, level: float = ORACLE_LEVEL) -> float:
    """Return the power of the F test at ``level`` for a noncentrality."""
    crit = stats.f.isf(level, k, dof)
    return float(stats.ncf.sf(crit, k, dof, noncentrality))


def run(case: Case, arm: ap.Arm, seed: int, size: float) -> tuple[Discovery, Oracle]:
    """Return discovery and the oracle on the case's campaign of one seed at one size (SI)."""
    campaign, d = case.make(arm, seed, size)
    result = ap.discover(campaign, arm, case.start, use_rtest=case.use_rtest)
    return result, oracle(case, result, campaign, arm, d)


def size_at_power(case: Case, arm: ap.Arm, power: float = 0.9, seed: int = 0) -> tuple[float, float]:
    """Return the size (SI) where the oracle's power is ``power`` and the absorbed share there."""
    _, ref = run(case, arm, seed, case.reference)

    def gap(log_factor: float) -> float:
        return oracle_power(ref.noncentrality * np.exp(2 * log_factor), ref.k, ref.dof) - power

    log_factor = optimize.brentq(gap, -8.0, 8.0)
    return case.reference * float(np.exp(log_factor)), ref.absorbed


def _seed_text(seeds: dict[float, range], show) -> str:
    """The campaigns' seeds per size factor in words, e.g. ``10 at 0.5 x, 20 at 1 x the 0.9
    size`` (``show``: a range's words)."""
    return ", ".join(f"{show(r)} at {f:g} x" for f, r in seeds.items()) + " the 0.9 size"


def false_alarms(case: Case, arm: ap.Arm, seeds: range = NULL_SEEDS) -> tuple[int, int]:
    """Return (false alarms, campaigns) of discovery on the case's null campaigns."""
    hits = sum(false_alarm(run(case, arm, s, 0.0)[0]) for s in seeds)
    return hits, len(seeds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="4 seeds at the 0.9 size only, 5 null seeds; print, do not write")
    args = parser.parse_args()
    arm = ap.load_arm()
    seeds = QUICK_SEEDS if args.quick else SEEDS
    nulls = NULL_SEEDS[:QUICK_NULLS] if args.quick else NULL_SEEDS
    tic = time.process_time()
    rows, null_rows, done = [], [], set()
    for case in CASES:
        if (case.start, case.use_rtest) not in done:  # the nulls of one start are the same
            done.add((case.start, case.use_rtest))
            hits, n = false_alarms(case, arm, nulls)
            null_rows.append(f"| {case.start}{'' if case.use_rtest else ', R-Test ignored'} "
                             f"(as for {case.name}) | {hits}/{n} |")
            print(null_rows[-1], flush=True)
        s90, absorbed = size_at_power(case, arm)
        for factor, factor_seeds in seeds.items():
            size = factor * s90
            runs = [run(case, arm, s, size) for s in factor_seeds]
            right = sum(discovery_right(case, r) for r, _ in runs)
            o_hits = sum(o.p_value < ORACLE_LEVEL for _, o in runs)
            o_mean = np.mean([oracle_power(o.noncentrality, o.k, o.dof) for _, o in runs])
            m = int(np.median([r.n_candidates[0] for r, _ in runs]))  # the first step's family
            searched = np.mean([oracle_power(o.noncentrality, o.k, o.dof, ORACLE_LEVEL / m)
                                for _, o in runs])
            rows.append(f"| {case.name} | {size / case.scale:.3g} {case.unit} "
                        f"({factor:g} x) | {o_mean:.2f} | {o_hits}/{len(runs)} | {searched:.2f} ({m}) | "
                        f"{right}/{len(runs)} | {right / len(runs) / searched:.2f} | "
                        f"{100 * absorbed:.0f} % |")
            print(rows[-1], flush=True)
    cpu = time.process_time() - tic
    body = "\n".join([
        "## Discovery against the oracle (`python benchmarks/oracle.py`)", "",
        f"{machine()}; {cpu / 60:.1f} min of CPU. Campaigns of 4 x {N_PER_LOCATION} SPAT samples, "
        f"{DT_S:g} s apart, no bar, the simulator's noise (2 um R-Test, 3 um nests); "
        f"seeds: {_seed_text(seeds, len)}. The oracle: F test of the start model plus the effect's "
        f"exact columns, level {ORACLE_LEVEL}; its power predicted from the noncentrality (mean "
        "over the campaigns) and counted. Discovery: the final model adds exactly the hidden "
        "term, or (out of the library) names nothing and reports \"unexplained\" with the right "
        "variable first. Sizes: 0.5, 1 and 1.5 x the size where the oracle's predicted power is "
        "0.9 (seed 0). Absorbed: the share of the effect's sum of squares that the start model's "
        "own parameters take. \"Oracle searching m candidates\": the oracle's test at level "
        f"{ORACLE_LEVEL} / m, m the candidates discovery's first step scores (Bonferroni): the "
        "power of a search over m candidates with a union bound at that family-wise rate "
        f"(discovery runs at {FalseAlarm().split_text()}). Counts from fixed seeds (campaigns: "
        f"{_seed_text(seeds, lambda r: f'seeds {r.start}-{r.stop - 1}')}; null campaigns: seeds "
        f"{nulls.start}-{nulls.stop - 1}): a rerun of "
        "the same code gives the same table, only the CPU time differs; "
        f"`--quick` ({len(QUICK_SEEDS[1.0])} seeds at the 0.9 size, {QUICK_NULLS} null seeds) "
        "prints a check (about 2 min of CPU).", "",
        "| effect | size | oracle power (predicted) | oracle (counted) | oracle searching m "
        "candidates (predicted; m) | discovery | discovery / searching oracle | absorbed |",
        "|---|---|---|---|---|---|---|---|", *rows, "",
        "False alarms of discovery (anything named, or \"unexplained\") on null campaigns:", "",
        "| start | false alarms |", "|---|---|", *null_rows])
    if args.quick:
        print(body)
    else:
        write_section("oracle", body)


if __name__ == "__main__":
    main()
