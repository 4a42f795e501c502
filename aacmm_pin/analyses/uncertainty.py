r"""Uncertainty of an identified arm: Monte Carlo (paper Section 5) and linearised covariance.

Monte Carlo: perturb the R-Test readings (sigma 2 um per coordinate and sample) and the R-Test
zero positions (sigma 3 um per coordinate and location), every other sample (absolute tool points,
length-bar readouts seated in a socket) by its stated noise, re-identify with the nominal
calibration's structure starting from its solution (:func:`aacmm_pin.fit.identification.refit`), and take
the standard deviation (k=1) of every parameter, map node and length error over the trials.
Trials run through any :class:`concurrent.futures.Executor`: local processes by default, or e.g.
a Dask cluster's ``client.get_executor()``.

Linearised: the covariance of :attr:`Calibration.covariance` propagated to the length errors.
"""

from __future__ import annotations

import os
import signal
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from aacmm_pin.analyses.validation import as_table, bar_pairs, pair_errors, pair_weights, validate
from aacmm_pin.data.campaign import Campaign
from aacmm_pin.fit.identification import refit
from aacmm_pin.fit.identification_result import Calibration
from aacmm_pin.fit.measurements import measured_positions
from aacmm_pin.fit.solver import Factor
from aacmm_pin.fit.unknowns import NodeKey, UnknownKey
from aacmm_pin.interrupts import die_with_parent
from aacmm_pin.machine import check_workers, usable_cores
from aacmm_pin.model.samples import Samples
from aacmm_pin.units import ARCSEC, SIGMA_LOCATION, SIGMA_RTEST

AGREE = 0.2
"""Relative difference of Monte Carlo and linearised standard uncertainty still called agreement
(when the trials resolve it: :meth:`MonteCarloResult.agree_limit`)."""


def std_resolution(trials: int) -> float:
    """Relative standard uncertainty of a standard deviation estimated from ``trials`` samples.

    ``1 / sqrt(2 (n - 1))`` for normal samples: 20 trials give a std to +-16 %, 100 to +-7 %.
    """
    return 1.0 / float(np.sqrt(2.0 * (trials - 1)))


def trials_to_resolve(relative: float) -> int:
    """Fewest trials whose std estimate is within ``relative`` at two sigmas (``2 x std_resolution``)."""
    return int(np.ceil(1.0 + 2.0 / relative ** 2))


@dataclass(frozen=True)
class MonteCarloResult:
    """Standard uncertainties (k=1) from Monte Carlo, beside the linearised ones."""

    keys: list[UnknownKey]
    """What the estimated entries are (as ``Calibration.keys``)."""
    samples: np.ndarray
    """Solution of every trial, shape (trials, n), SI."""
    std: np.ndarray
    """Monte Carlo standard uncertainty of every entry, shape (n,), SI."""
    linear_std: np.ndarray
    """Linearised standard uncertainty of every entry, shape (n,), SI."""
    length_std: np.ndarray | None
    """Monte Carlo std of each length error, shape (n_placements, n_pairs), m (None: no bar)."""
    length_linear_std: np.ndarray | None
    """Linearised std of each length error, shape (n_placements, n_pairs), m."""
    identifiable: np.ndarray
    """Per entry: determined by the data (nest offsets always), shape (n,)."""
    converged: int
    """Number of trials whose re-identification converged."""
    sigma_rtest: float
    """R-Test reading perturbation, m."""
    sigma_location: float
    """R-Test zero position perturbation, m."""

    @property
    def names(self) -> list[str]:
        """Names of the estimated entries (as ``Calibration.names``)."""
        return [str(k) for k in self.keys]

    @property
    def trials(self) -> int:
        """Number of trials."""
        return int(self.samples.shape[0])

    def ratio(self) -> np.ndarray:
        """Monte Carlo over linearised std per entry (NaN where not identifiable)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.identifiable, self.std / self.linear_std, np.nan)

    @property
    def agree_limit(self) -> float:
        """Relative difference beyond which the two stds disagree.

        :data:`AGREE`, or two :func:`std_resolution` of the trials where that is larger
        (20 trials: 32 %; a smaller difference is the chance of so few trials).
        """
        return max(AGREE, 2.0 * std_resolution(self.trials))

    def disagreements(self) -> list[str]:
        """Names of identifiable entries whose two uncertainties differ by more than :attr:`agree_limit`."""
        ratio = self.ratio()
        return [n for n, r in zip(self.names, ratio)
                if np.isfinite(r) and abs(r - 1) > self.agree_limit]

    def resolution_note(self) -> str | None:
        """One line when the trials cannot resolve :data:`AGREE` (else None): what they resolve."""
        if self.agree_limit <= AGREE:
            return None
        return (f"{self.trials} trials resolve a std to +-{std_resolution(self.trials):.0%} "
                f"(1/sqrt(2(n-1))): differences up to {self.agree_limit:.0%} are chance; "
                f"--trials {trials_to_resolve(AGREE)} or more resolve {AGREE:.0%}")

    def node_std(self, axis: int, nodes_deg: np.ndarray, linear: bool = False) -> np.ndarray:
        """Return the std of each node of a map, rad (NaN where not estimated)."""
        lookup = dict(zip(self.keys, self.linear_std if linear else self.std))
        return np.array([lookup.get(NodeKey.at(axis, d), np.nan) for d in nodes_deg])


@dataclass(frozen=True)
class Perturbation:
    """What a Monte Carlo trial perturbs: every sample of the calibration's problem.

    SPAT samples (the first ``location.size`` rows) get R-Test reading noise and their location's
    zero position error; every other sample (tool points, bar readouts) its stated noise.
    """

    base: np.ndarray
    """Measured points of the calibration's problem, shape (N, 3), m (as ``Problem.measured``)."""
    sigma: np.ndarray
    """Perturbation per coordinate of every sample, shape (N,), m (0: none, e.g. a rejected
    sample)."""
    location: np.ndarray
    """R-Test location of each SPAT sample, shape (n_spat,) (the first n_spat rows of ``base``)."""
    use_rtest: bool
    """Whether the R-Test displacements are used per sample (else their location mean)."""
    sigma_location: float
    """R-Test zero position perturbation per coordinate and location, m."""


def perturbation(cal: Calibration, campaign: Campaign, sigma_rtest: float = SIGMA_RTEST,
                 sigma_location: float = SIGMA_LOCATION) -> Perturbation:
    """Return what trials of ``cal`` (identified from ``campaign``) perturb, and by how much.

    SPAT samples come first in the problem (:func:`aacmm_pin.fit.measurements.measurements`); the
    others' stated noise is the problem's ``sigma_class / row weight`` (the weights the fit used).
    """
    problem = cal.problem
    base = problem.measured
    n_spat = 0 if campaign.spat is None else len(campaign.spat.location)
    sigma = np.full(len(base), problem.sigma_class)
    if problem.row_weight is not None:
        w = problem.row_weight[::3]
        with np.errstate(divide="ignore"):
            sigma = np.where(w > 0, problem.sigma_class / w, 0.0)
    sigma[:n_spat] = sigma_rtest
    if n_spat:
        base = base.copy()
        base[:n_spat] = measured_positions(campaign, cal.use_rtest)
    location = np.zeros(0) if campaign.spat is None else campaign.spat.location
    return Perturbation(base, sigma, location, cal.use_rtest, sigma_location)


def _trial_batch(cal: Calibration, factor: Factor | None, shake: Perturbation, seeds: list[int],
                 campaign: Campaign | None = None) -> tuple[np.ndarray, int, np.ndarray | None]:
    """Run trials with these seeds.

    Returns their solutions (k, n), how many converged, and their length errors
    (k, n_placements, n_pairs) on the campaign's bar (None without one).

    ``factor`` is the factored Jacobian at the calibration's solution; None: factor it here, once
    for the batch (a worker gets the calibration only: the factor's orthonormal block is larger
    than the calibration, e.g. 7.8 vs 6.7 MB on a paper-sized campaign, and would make every
    batch a "large graph" for Dask).

    BLAS runs single-threaded here: a trial's small products gain nothing from threads, and
    spinning BLAS threads of several workers on few cores slow everything down many times.
    """
    from aacmm_pin._blas import single_threaded_blas

    with single_threaded_blas():
        if factor is None:
            factor = cal.problem.factor(cal.problem.z(cal.x))
        x, ok = _trials(cal, factor, shake, seeds)
        lengths = None
        if campaign is not None and campaign.lengthbar is not None and campaign.bar:
            u = cal.unknowns
            n_arm = len(u.names)
            lengths = np.array([validate(u.arm, u.parameters(xi[:n_arm]), campaign).errors
                                for xi in x])
        return x, ok, lengths


def _trials(cal: Calibration, factor: Factor, shake: Perturbation, seeds: list[int]
            ) -> tuple[np.ndarray, int]:
    out, ok = [], 0
    n_spat = shake.location.size
    ids, index = np.unique(shake.location, return_inverse=True)
    for seed in seeds:
        rng = np.random.default_rng(seed)
        noise = rng.standard_normal(shake.base.shape) * shake.sigma[:, None]
        spat = noise[:n_spat]
        if not shake.use_rtest:  # the conventional SPAT uses each location's mean displacement
            for m in range(ids.size):
                spat[index == m] = spat[index == m].mean(axis=0)
        nest = np.zeros_like(noise)  # added last: SPAT-only trials as before, to the bit
        nest[:n_spat] = rng.normal(0.0, shake.sigma_location, (ids.size, 3))[index]
        x, good = refit(cal, shake.base + noise + nest, factor=factor)
        out.append(x)
        ok += good
    return np.array(out), ok


def length_jacobian(cal: Calibration, campaign: Campaign) -> tuple[np.ndarray, np.ndarray]:
    """Return the length errors (n_pl, n_pairs) and their Jacobian w.r.t. ``cal.x`` (.., n)."""
    log = campaign.lengthbar
    assert log is not None
    n_arm = len(cal.unknowns.names)
    bar = cal.unknowns.with_samples(Samples.of_log(cal.unknowns.arm, log))  # its terms' columns
    pos, jac = bar.jacobian(cal.x[:n_arm], log.q)
    pairs = bar_pairs(campaign)
    errors, unit = pair_errors(pos, pairs)
    grads = np.zeros((len(errors), cal.x.size))
    for row, w in zip(grads, pair_weights(pairs, unit, len(log.q))):
        row[:n_arm] = jac.rmatmul(w)
    grads = as_table(pairs, grads)
    return as_table(pairs, errors), np.nan_to_num(grads)  # pair not measured: no gradient


def length_linear_std(cal: Calibration, campaign: Campaign) -> np.ndarray:
    """Return the linearised std of each length error, shape (n_placements, n_pairs), m."""
    _, grads = length_jacobian(cal, campaign)
    g = grads.reshape(-1, grads.shape[-1])
    var = np.einsum("ij,jk,ik->i", g, cal.covariance, g)  # NaN-free: missing pairs have g = 0
    std: np.ndarray = np.sqrt(np.clip(var, 0, None)).reshape(grads.shape[:2])
    return std


def _start_worker(parent: int) -> None:
    """A worker's start: it dies with its parent (``parent``: its pid).

    Ctrl-C (SIGINT to the whole process group) is the main process's to handle.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent)


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """End a pool's workers at once (Ctrl-C): queued batches cancelled, running ones terminated."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()


def _run_batches(cal: Calibration, shake: Perturbation, batches: list[list[int]],
                 bar_only: Campaign | None, executor: Executor | None, workers: int,
                 progress: bool) -> list[tuple[np.ndarray, int, np.ndarray | None]]:
    """Run the trial batches (their seeds) here, on ``executor``, or on a pool of ``workers``.

    Returns each batch's (identified values, shape (trials, P); trials converged; bar length
    errors or None), in batch order.
    """
    from aacmm_pin.progress import Progress

    results: list[tuple[np.ndarray, int, np.ndarray | None]] = []
    own = executor is None and workers > 1
    pool = (ProcessPoolExecutor(workers, initializer=_start_worker, initargs=(os.getpid(),))
            if own else executor)
    with Progress("Monte Carlo", "trial", total=sum(len(b) for b in batches), enabled=progress) as bar:
        if pool is None:
            from aacmm_pin._blas import single_threaded_blas

            with single_threaded_blas():  # as in a worker's batch: the same bits either way
                factor = cal.problem.factor(cal.problem.z(cal.x))
            for batch in batches:
                results.append(_trial_batch(cal, factor, shake, batch, bar_only))
                bar.update(len(batch))
        else:
            try:
                futures = [pool.submit(_trial_batch, cal, None, shake, batch, bar_only)
                           for batch in batches]
                for future, batch in zip(futures, batches):
                    results.append(future.result())
                    bar.update(len(batch))
            except KeyboardInterrupt:  # Ctrl-C: stop the workers now, not after their batches
                if own:
                    assert isinstance(pool, ProcessPoolExecutor)
                    _stop_workers(pool)
                raise
            finally:
                if own:
                    pool.shutdown()
    return results


def monte_carlo(cal: Calibration, campaign: Campaign, trials: int = 100, *,
                sigma_rtest: float = SIGMA_RTEST, sigma_location: float = SIGMA_LOCATION, seed: int = 0,
                executor: Executor | None = None, workers: int | None = None,
                progress: bool = False) -> MonteCarloResult:
    """Monte Carlo standard uncertainties of a calibration (paper Section 5).

    Args:
        cal: the nominal calibration (from :func:`aacmm_pin.fit.identification.identify` on ``campaign``).
        campaign: the campaign it was identified from.
        trials: number of trials.
        sigma_rtest: R-Test reading perturbation per coordinate and sample, m.
        sigma_location: R-Test zero position perturbation per coordinate and location, m.
        seed: seed of the first trial (trial i uses seed + i: same seed, same result).
        executor: where trials run (any ``concurrent.futures.Executor``); default: a local
            process pool of ``workers`` processes (all cores), or in this process for ``workers=1``.
        workers: local worker processes when no executor is given (at most the cores and
            memory there are: :func:`aacmm_pin.machine.check_workers`).
        progress: show a progress bar.

    Raises:
        ArgumentError: for fewer than 2 trials or more workers than
            :func:`aacmm_pin.machine.check_workers` allows.
    """
    if trials < 2:
        raise ValueError(f"trials: need at least 2, got {trials}")
    shake = perturbation(cal, campaign, sigma_rtest, sigma_location)
    if executor is None and workers is not None and workers > 1:
        check_workers(workers)  # before any work, never a fork storm
    workers = workers or usable_cores()
    seeds = [seed + i for i in range(trials)]
    parallel = executor is not None or workers > 1
    # few large batches: each ships the calibration once and factors its Jacobian once
    n_batches = 2 * workers if parallel else max(1, trials // 10)
    chunk = max(1, -(-trials // n_batches))
    batches = [seeds[i:i + chunk] for i in range(0, trials, chunk)]
    has_bar = campaign.lengthbar is not None and bool(campaign.bar)
    bar_only = Campaign(spat=None, locations={}, lengthbar=campaign.lengthbar,
                        bar=campaign.bar) if has_bar else None
    results = _run_batches(cal, shake, batches, bar_only, executor, workers, progress)
    samples = np.concatenate([r[0] for r in results])
    converged = int(sum(r[1] for r in results))
    identifiable = np.ones(samples.shape[1], dtype=bool)
    identifiable[:cal.identifiable.size] = cal.identifiable
    length_std = length_lin = None
    if has_bar:
        length_std = np.concatenate([r[2] for r in results]).std(axis=0, ddof=1)
        length_lin = length_linear_std(cal, campaign)
    return MonteCarloResult(keys=cal.keys, samples=samples,
                            std=samples.std(axis=0, ddof=1),
                            linear_std=np.sqrt(np.clip(np.diag(cal.covariance), 0, None)),
                            length_std=length_std, length_linear_std=length_lin,
                            identifiable=identifiable, converged=converged,
                            sigma_rtest=sigma_rtest, sigma_location=sigma_location)


def uncertainty_report(cal: Calibration, mc: MonteCarloResult) -> dict[str, Any]:
    """Return the ``uncertainty.json`` content (SI, plus arcsec for map nodes and um for lengths)."""
    params = {}
    maps: dict[str, dict[str, list[float | bool]]] = {}
    for key, value, s_mc, s_lin, ok in zip(mc.keys, cal.x, mc.std, mc.linear_std,
                                           mc.identifiable):
        if isinstance(key, NodeKey):
            entry = maps.setdefault(str(key.axis), {"node_deg": [], "error_arcsec": [],
                                                    "std_mc_arcsec": [], "std_linear_arcsec": [],
                                                    "identifiable": []})
            entry["node_deg"].append(key.node_deg)
            entry["error_arcsec"].append(float(value / ARCSEC))
            entry["std_mc_arcsec"].append(float(s_mc / ARCSEC))
            entry["std_linear_arcsec"].append(float(s_lin / ARCSEC))
            entry["identifiable"].append(bool(ok))
        else:
            params[str(key)] = {"value": float(value), "std_mc": float(s_mc),
                            "std_linear": float(s_lin), "identifiable": bool(ok)}
    out: dict[str, Any] = {
        "trials": mc.trials, "converged": mc.converged, "sigma_rtest_um": mc.sigma_rtest * 1e6,
        "sigma_location_um": mc.sigma_location * 1e6, "units": "SI (m, rad) unless named",
        "parameters": params, "maps": maps,
        "disagreements": mc.disagreements(),
        "agreement_note": f"Monte Carlo and linearised std differ by more than "
                          f"{mc.agree_limit:.0%} for the entries listed in 'disagreements' (empty: "
                          "they agree everywhere)" + (f"; {note}" if (note := mc.resolution_note())
                                                     else ""),
    }
    if mc.length_std is not None and mc.length_linear_std is not None:
        out["length_errors_std_um"] = {"mc": (mc.length_std * 1e6).tolist(),
                                       "linear": (mc.length_linear_std * 1e6).tolist()}
    return out
