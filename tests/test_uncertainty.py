"""Uncertainty: calibrated against simulated truth, Monte Carlo vs linearised, executors, files."""

from __future__ import annotations

import json
import warnings
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

import numpy as np
import pytest

from aacmm_pin.analyses.simulate import SimulationConfig, simulate_campaign
from aacmm_pin.analyses.uncertainty import monte_carlo
from aacmm_pin.cli import main
from aacmm_pin.data.campaign import write_campaign
from aacmm_pin.fit.identification import identify
from aacmm_pin.model.arm import load_arm


def _coverage_z(seed: int) -> np.ndarray:
    """z-scores of one small simulated campaign's identifiable values (truth in the fit's gauge)."""
    arm = load_arm()
    sim = simulate_campaign(arm, SimulationConfig(seed=seed, samples_per_location=100,
                                                  bar_placements=0))
    cal = identify(sim.campaign, arm)
    equivalent, _ = cal.equivalent(sim.truth)
    u = cal.unknowns
    std = np.sqrt(np.diag(cal.covariance))[:len(u.names)]
    return ((u.vector(cal.parameters) - u.vector(equivalent)) / std)[cal.identifiable]


# One campaign has ~335 identifiable values, whose k=2 coverage was 93-98 % on each of seeds
# 100-111 (binomial std 1.1 % about the Gaussian 95.4 %): two campaigns already put 90 % and 99 %
# more than 3 std away; the 50 behind `slow` make the statistic sharp.
@pytest.mark.parametrize("seeds", [pytest.param(range(100, 102), id="2-campaigns"),
                                   pytest.param(range(100, 150), id="50-campaigns",
                                                marks=pytest.mark.slow)])
def test_uncertainty_is_calibrated_over_campaigns(seeds):
    """Over simulated campaigns, 90-99% of identifiable values have their truth within k=2."""
    with ProcessPoolExecutor(2) as pool:
        zs = list(pool.map(_coverage_z, seeds))
    z = np.concatenate(zs)
    inside = np.mean(np.abs(z) <= 2)
    print(f"k=2 coverage over {len(seeds)} campaigns: {100 * inside:.2f}% of {z.size} identifiable "
          "values")
    assert 0.90 <= inside <= 0.99


@pytest.fixture(scope="module")
def paper_sized(arm):
    sim = simulate_campaign(arm, SimulationConfig(seed=7, samples_per_location=400))
    return sim, identify(sim.campaign, arm)


@pytest.fixture(scope="module")
def small(small_sim, small_cal):
    """The shared small campaign (4 x 50 SPAT samples, 2 bar placements) and its calibration."""
    return small_sim, small_cal


@pytest.mark.parametrize("problem", ["small", pytest.param("paper_sized", marks=pytest.mark.slow)])
def test_monte_carlo_agrees_with_linearised(problem, request):
    """On a small and the paper-sized problem MC and linearised std agree within 20% (200 trials:
    5% noise)."""
    sim, cal = request.getfixturevalue(problem)
    mc = monte_carlo(cal, sim.campaign, 200, workers=1, seed=1)
    ratio = mc.ratio()
    ratio = ratio[np.isfinite(ratio)]
    print(f"MC/linear std: median {np.median(ratio):.3f}, "
          f"{100 * np.mean(np.abs(ratio - 1) <= 0.2):.1f}% of {ratio.size} within 20%")
    assert mc.converged == 200
    assert abs(np.median(ratio) - 1) < 0.05
    # the std of 200 trials scatters by 5% (1/sqrt(2 x 199)); 20% is 4 of those
    assert np.mean(np.abs(ratio - 1) <= 0.2) >= 0.98
    length = mc.length_std / mc.length_linear_std
    assert np.all(np.abs(length - 1) <= 0.2), length


def test_trials_are_reproducible_through_any_executor(small):
    """The same seeds give the same trials in-process, on threads and on processes (on the small
    problem: what an executor changes does not depend on the campaign's size; the paper-sized
    calibration is shipped to workers by the Dask test below)."""
    sim, cal = small
    serial = monte_carlo(cal, sim.campaign, 6, workers=1, seed=3)
    with ThreadPoolExecutor(2) as pool:
        threads = monte_carlo(cal, sim.campaign, 6, executor=pool, seed=3)
    processes = monte_carlo(cal, sim.campaign, 6, workers=2, seed=3)
    np.testing.assert_allclose(threads.samples, serial.samples, rtol=0, atol=1e-15)
    np.testing.assert_allclose(processes.samples, serial.samples, rtol=0, atol=1e-15)


def test_trials_run_on_a_local_dask_cluster(paper_sized):
    """A Dask cluster's executor runs the trials with no change to the code."""
    distributed = pytest.importorskip("dask.distributed", reason="Dask is an optional extra")
    sim, cal = paper_sized
    serial = monte_carlo(cal, sim.campaign, 4, workers=1, seed=5)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            remote = monte_carlo(cal, sim.campaign, 4, executor=client.get_executor(), seed=5)
    np.testing.assert_allclose(remote.samples, serial.samples, rtol=0, atol=1e-15)
    large = [str(w.message) for w in caught if "large graph" in str(w.message)]
    assert not large, large  # a batch ships the calibration, not its 7.8 MB factor as well


def test_uncertainty_cli_writes_json_csv_and_figure(tmp_path, capsys):
    """`aacmm-pin uncertainty` writes uncertainty.json, maps CSV with std_arcsec, and Fig. 6."""
    arm = load_arm()
    sim = simulate_campaign(arm, SimulationConfig(seed=2, samples_per_location=120,
                                                  samples_per_socket=5, bar_placements=2))
    write_campaign(sim.campaign, tmp_path / "c")
    assert main(["uncertainty", str(tmp_path / "c"), "--trials", "8", "--workers", "1",
                 "--out", str(tmp_path / "u")]) == 0
    printed = capsys.readouterr().out
    assert "placement 1: A-B " in printed and "placement 2: A-B " in printed  # labelled, not bare
    report = json.loads((tmp_path / "u" / "uncertainty.json").read_text())
    assert report["trials"] == 8 and "dx21" in report["parameters"]
    assert {"std_mc", "std_linear"} <= set(report["parameters"]["dx21"])
    assert len(report["maps"]["3"]["std_mc_arcsec"]) == len(report["maps"]["3"]["node_deg"])
    assert len(report["length_errors_std_um"]["mc"]) == 2
    lines = (tmp_path / "u" / "encoder_maps.csv").read_text().splitlines()
    assert lines[0].endswith("std_arcsec") and lines[1].split(",")[-1] != ""
    assert (tmp_path / "u" / "fig6_encoder_maps.png").stat().st_size > 20_000


@pytest.mark.parametrize("seed", [20, 21])
def test_covariance_right_for_other_noise_levels(seed):
    """With 5 um R-Test noise (sigma estimated from the residuals) the uncertainty stays calibrated.

    The nests are estimated as asked: against the paper's stated 2 um the 5 um residual would read
    as an incomplete model and `nests="auto"` would fix them (state the noise to avoid that).
    """
    arm = load_arm()
    sim = simulate_campaign(arm, SimulationConfig(seed=seed, samples_per_location=150,
                                                  bar_placements=0, sigma_rtest=5e-6))
    cal = identify(sim.campaign, arm, nests="estimate")
    assert identify(sim.campaign, arm, sigma=5e-6).nests.startswith("estimated")
    equivalent, _ = cal.equivalent(sim.truth)
    u = cal.unknowns
    std = np.sqrt(np.diag(cal.covariance))
    z = ((u.vector(cal.parameters) - u.vector(equivalent)) / std[:len(u.names)])[cal.identifiable]
    print(f"sigma estimated {cal.sigma * 1e6:.2f} um; z std {z.std():.2f} over {z.size} values")
    assert abs(cal.sigma - 5e-6) < 0.3e-6
    assert 0.8 < z.std() < 1.25
    nest = std[len(u.names):]
    assert np.all(nest <= 3e-6)  # the posterior of a nest offset cannot exceed its 3 um prior


def test_large_campaign_path_pickles_and_runs_monte_carlo(monkeypatch):
    """The LSMR (operator) path gives the dense path's estimate and its calibration runs MC in workers."""
    import pickle

    from aacmm_pin.fit import solver

    arm = load_arm()
    sim = simulate_campaign(arm, SimulationConfig(seed=3, samples_per_location=80,
                                                  bar_placements=0))
    dense = identify(sim.campaign, arm)
    monkeypatch.setattr(solver, "DENSE_LIMIT", 0)
    large = identify(sim.campaign, arm)
    assert large.success
    np.testing.assert_allclose(large.x, dense.x, rtol=0, atol=1e-9)
    pickle.dumps(large)
    mc = monte_carlo(large, sim.campaign, 4, workers=2, seed=0)
    assert mc.converged == 4


def test_bad_argument_is_a_message_not_a_traceback(tmp_path, capsys):
    """`--trials 1` is refused with the argument named and exit status 2."""
    arm = load_arm()
    sim = simulate_campaign(arm, SimulationConfig(seed=4, samples_per_location=60, bar_placements=0))
    write_campaign(sim.campaign, tmp_path / "c")
    assert main(["uncertainty", str(tmp_path / "c"), "--trials", "1", "--out",
                 str(tmp_path / "u")]) == 2
    err = capsys.readouterr().err
    assert "trials" in err and "Traceback" not in err


def test_monte_carlo_perturbs_points_by_their_stated_noise():
    """Points stated 10 and 60 um (alternately, and so drawn): Monte Carlo agrees with the
    linearised std, which weighs each point by its stated noise; perturbing every point alike
    would be ~3.5x off."""
    from aacmm_pin.data.campaign import Campaign, PointLog

    arm = load_arm()
    sim = simulate_campaign(arm, SimulationConfig(points=150, effects=("dh",), sigma_point=0.0))
    pts = sim.campaign.points
    assert pts is not None
    sigma = np.where(np.arange(150) % 2, 60e-6, 10e-6)
    point = pts.point + np.random.default_rng(3).normal(size=(150, 3)) * sigma[:, None]
    campaign = Campaign(spat=None, locations={}, lengthbar=None, bar={},
                        points=PointLog(group=pts.group, q=pts.q, point=point, sigma=sigma))
    cal = identify(campaign, arm, model="dh")
    mc = monte_carlo(cal, campaign, 100, workers=1)
    ratio = mc.ratio()[mc.identifiable]
    ratio = ratio[np.isfinite(ratio)]
    assert mc.converged == 100 and ratio.size > 20
    # a std from 100 trials scatters by 1/sqrt(2 * 99) = 7 %; the median of 29 entries less
    assert abs(np.median(ratio) - 1) < 0.15, np.median(ratio)


@pytest.mark.parametrize("trials", [20, 200])
def test_disagreement_is_judged_against_what_the_trials_resolve(trials):
    """A Monte Carlo std 25 % above the linearised one (issue 26, item 9).

    From n trials a std is known to about 1/sqrt(2(n-1)) (20: 16 %, 200: 5 %): with 20 trials a
    25 % difference is within two of that and no disagreement, with 200 it is one. The drawn
    samples are scaled to the exact std so that the ratio is the one the test is about.
    """
    from aacmm_pin.analyses.uncertainty import AGREE, MonteCarloResult

    rng = np.random.default_rng(0)
    draws = rng.standard_normal((trials, 3))
    draws /= draws.std(axis=0, ddof=1)
    linear = np.array([1.0, 1.0, 1.0])
    samples = draws * np.array([1.25, 1.05, 0.95])
    mc = MonteCarloResult(keys=["a", "b", "c"], samples=samples,  # type: ignore[arg-type]
                          std=samples.std(axis=0, ddof=1), linear_std=linear, length_std=None,
                          length_linear_std=None, identifiable=np.ones(3, dtype=bool),
                          converged=trials, sigma_rtest=2e-6, sigma_location=3e-6)
    resolved = 2 / np.sqrt(2 * (trials - 1)) <= 0.25
    assert mc.disagreements() == (["a"] if resolved else [])
    note = mc.resolution_note()
    if 2 / np.sqrt(2 * (trials - 1)) <= AGREE:
        assert note is None and mc.agree_limit == AGREE
    else:
        assert note is not None and f"{trials} trials resolve a std to +-16%" in note
        assert "--trials 51 or more" in note  # 2 / sqrt(2 * 50) = 20 %
