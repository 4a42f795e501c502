"""Tests of aacmm_pin.fit.robust and identify(..., robust=True): outliers rejected, listed, reported."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import aacmm_pin as ap
from aacmm_pin.analyses.simulate import SimulationConfig, simulate_campaign
from aacmm_pin.analyses.validation import validate_points
from aacmm_pin.cli import main
from aacmm_pin.data.campaign import Campaign, PointLog, write_campaign
from aacmm_pin.fit import robust as rob
from tests.test_points import UR5, _points_campaign, _truth


def corrupt(campaign: Campaign, kind: str, seed: int) -> tuple[Campaign, np.ndarray]:
    """Return the campaign with 1 % of its SPAT samples corrupted, and their sorted rows.

    ``angles``: one readout of A1..A6 5 deg off (A7 turns the stylus about itself: invisible);
    ``rtest``: one R-Test coordinate 1 mm off; ``720``: one readout replaced by 720 deg.
    """
    spat = campaign.spat
    assert spat is not None
    rng = np.random.default_rng(1000 + seed)
    n = len(spat.q)
    k = 1 if kind == "720" else max(1, n // 100)
    rows = np.sort(rng.choice(n, k, replace=False))
    sign = rng.choice([-1.0, 1.0], k)
    if kind == "rtest":
        disp = spat.displacement.copy()
        disp[rows, rng.integers(0, 3, k)] += 1e-3 * sign
        return campaign.with_spat(displacement=disp), rows
    q = spat.q.copy()
    axes = rng.integers(0, 6, k)
    q[rows, axes] = np.radians(720.0) if kind == "720" else q[rows, axes] + np.radians(5.0) * sign
    return campaign.with_spat(q=q), rows


@pytest.fixture(scope="module")
def clean(arm: ap.Arm, paper_sim: ap.Simulation, paper_cal: ap.Calibration) -> tuple[Campaign, float]:
    """Seed 0's paper campaign and the length-bar RMS of its least-squares calibration."""
    return paper_sim.campaign, ap.validate(arm, paper_cal.parameters, paper_sim.campaign).rms


def check_outlier_case(arm: ap.Arm, campaign: Campaign, clean_bar: float, kind: str,
                       seed: int) -> None:
    bad, rows = corrupt(campaign, kind, seed)
    plain = ap.identify(bad, arm, "proposed")
    assert set(rows) <= {o.row for o in plain.suspects}, "least squares: at least reported"
    assert "beyond 5 robust sigmas" in plain.message
    cal = ap.identify(bad, arm, "proposed", robust=True)
    assert cal.success, cal.message
    assert [o.row for o in sorted(cal.outliers, key=lambda o: o.row)] == list(rows)
    assert all(o.file == "spat.csv" for o in cal.outliers)
    assert cal.inlier is not None and np.array_equal(np.flatnonzero(~cal.inlier), rows)
    bar = ap.validate(arm, cal.parameters, bad).rms
    assert bar <= 1.2 * clean_bar, (bar, clean_bar)


@pytest.mark.parametrize("kind", ["angles", "rtest",
                                  pytest.param("720", marks=pytest.mark.slow)])
def test_robust_fit_rejects_exactly_the_corrupted_samples(arm: ap.Arm, clean: tuple[Campaign, float],
                                                          kind: str) -> None:
    """1 % angles 5 deg off / R-Test readings 1 mm off / one 720 deg readout: rejected exactly,
    success, bar within 1.2x of the clean campaign's; least squares lists them as suspects."""
    check_outlier_case(arm, clean[0], clean[1], kind, 0)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3, 4])
@pytest.mark.parametrize("kind", ["angles", "rtest", "720"])
def test_robust_fit_over_seeds(arm: ap.Arm, kind: str, seed: int) -> None:
    """The outlier cases on other simulated campaigns (seeds 1-4)."""
    campaign = simulate_campaign(arm, SimulationConfig(seed=seed)).campaign
    clean_bar = ap.validate(arm, ap.identify(campaign, arm, "proposed").parameters, campaign).rms
    check_outlier_case(arm, campaign, clean_bar, kind, seed)


def test_robust_fit_of_a_clean_campaign_is_the_least_squares_fit(
        arm: ap.Arm, clean: tuple[Campaign, float], paper_cal: ap.Calibration) -> None:
    """Without outliers the robust fit rejects nothing and returns the least-squares solution."""
    plain = paper_cal  # ap.identify(clean[0], arm, "proposed"), shared
    cal = ap.identify(clean[0], arm, "proposed", robust=True)
    assert cal.success and cal.outliers == () and plain.suspects == ()
    np.testing.assert_array_equal(cal.x, plain.x)
    report = cal.report()
    assert report["robust"] and report["outliers"] == [] and report["suspects"] == []


def test_robust_scale_estimates_the_noise_despite_gross_outliers() -> None:
    """The median-based scale of 3-D norms is the per-coordinate sigma, with or without 10 % junk."""
    rng = np.random.default_rng(0)
    sigma = 2e-6
    norms = np.linalg.norm(rng.normal(0, sigma, (20000, 3)), axis=1)
    # the median of 20000 samples: relative standard error about 1 %
    assert rob.robust_scale(norms) == pytest.approx(sigma, rel=0.04)
    junk = norms.copy()
    junk[:2000] = 1e-3
    assert rob.robust_scale(junk) == pytest.approx(sigma, rel=0.15)
    assert rob.flag(norms, sigma).mean() < 1e-3  # P(chi_3 > 5) = 1.5e-5
    w = rob.huber_weights(np.array([0.0, 1.0, 4.0]), 1.0, k=2.0)
    np.testing.assert_allclose(w, [1.0, 1.0, 0.5])


def test_unseen_variance_counts_nodes_no_other_kept_sample_touches() -> None:
    """A sample's residual is judged with the plausible size of the nodes only it touches."""
    rows = [0, 1, 4, 5, 3, 4, 6]  # coordinates (3 per sample) of the nonzero entries
    cols = [0, 1, 1, 2, 2, 2, 2]
    vals = [1.0, 2.0, 1.0, 1.0, 1.0, 1.0, 3.0]
    nodes = sp.csc_matrix((vals, (rows, cols)), shape=(9, 3))
    # sample 0 touches nodes 0 (|J|^2 = 1) and 1 (4), sample 1 nodes 1 (1) and 2 (2), sample 2 node 2 (9)
    np.testing.assert_allclose(rob.unseen_variance(nodes, np.ones(3, bool), 0.5), [0.25, 0, 0])
    np.testing.assert_allclose(rob.unseen_variance(nodes, np.array([True, False, True]), 1.0),
                               [5.0, 0.0, 9.0])
    flagged = rob.flag_unseen(np.array([30.0, 30.0]), 1.0, np.array([0.0, 100.0]))
    np.testing.assert_array_equal(flagged, [True, False])


def test_cli_lists_outliers_with_file_and_line(arm: ap.Arm, clean: tuple[Campaign, float],
                                               tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                               ) -> None:
    """identify --robust writes report.json outliers (file, line, residual_um) and prints them;
    without --robust the same lines are suspects with a printed warning."""
    bad, rows = corrupt(clean[0], "rtest", 0)
    write_campaign(bad, tmp_path / "campaign")
    lines = sorted(int(r) + 2 for r in rows)  # header on line 1
    assert main(["identify", str(tmp_path / "campaign"), "--robust", "--out",
                 str(tmp_path / "robust")]) == 0
    report = json.loads((tmp_path / "robust" / "report.json").read_text())
    assert report["success"] and report["robust"]
    assert sorted(o["line"] for o in report["outliers"]) == lines
    assert all(o["file"] == "spat.csv" and o["residual_um"] > 500 for o in report["outliers"])
    out = capsys.readouterr().out
    assert all(f"spat.csv line {line}" in out for line in lines)
    assert main(["identify", str(tmp_path / "campaign"), "--out", str(tmp_path / "plain")]) == 0
    report = json.loads((tmp_path / "plain" / "report.json").read_text())
    assert set(lines) <= {o["line"] for o in report["suspects"]} and report["outliers"] == []
    assert "WARNING" in capsys.readouterr().out


@pytest.mark.parametrize("value", ["0", "-2", "nan", "inf"])
def test_cli_refuses_a_noise_that_is_not_positive(tmp_path: Path, value: str,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """--sigma-um 0, negative, NaN or inf is refused by the parser (exit 2) with a message."""
    with pytest.raises(SystemExit) as info:
        main(["identify", str(tmp_path), f"--sigma-um={value}", "--out", str(tmp_path / "o")])
    assert info.value.code == 2
    assert "expected a finite number > 0" in capsys.readouterr().err


def test_identify_refuses_a_noise_that_is_not_positive(arm: ap.Arm,
                                                       clean: tuple[Campaign, float]) -> None:
    """identify(sigma=0) raises ValueError naming the argument."""
    with pytest.raises(ValueError, match="sigma"):
        ap.identify(clean[0], arm, "dh", sigma=0.0)


@pytest.mark.parametrize("seed", [0, 1])
def test_tracker_outliers_are_rejected_and_named_in_points_csv(seed: int) -> None:
    """UR5, 400 tracker points (20 um): 2 % of them 2 mm off are rejected exactly, as points.csv
    rows, and the predictions at fresh poses are as good as from the clean points (within 1.2x)."""
    arm = ap.load_arm(UR5)
    truth = _truth(arm, seed)
    campaign = _points_campaign(arm, truth, 400, seed)
    assert campaign.points is not None
    rng = np.random.default_rng(2000 + seed)
    rows = np.sort(rng.choice(400, 8, replace=False))
    point = campaign.points.point.copy()
    point[rows, rng.integers(0, 3, 8)] += 2e-3 * rng.choice([-1.0, 1.0], 8)
    bad = Campaign(spat=None, locations={}, lengthbar=None, bar={},
                   points=PointLog(group=campaign.points.group, q=campaign.points.q, point=point))
    fresh = _points_campaign(arm, truth, 200, seed + 100, sigma=0.0)
    clean = validate_points(arm, ap.identify(campaign, arm, "dh").parameters, fresh).rms
    cal = ap.identify(bad, arm, "dh", robust=True)
    assert cal.success, cal.message
    assert [(o.file, o.row) for o in sorted(cal.outliers, key=lambda o: o.row)] == [
        ("points.csv", int(r)) for r in rows]
    assert validate_points(arm, cal.parameters, fresh).rms <= 1.2 * clean


def test_a_spat_alone_is_judged_by_its_own_scale():
    """One kind of samples: its scale is its residuals' own, never the stated noise. A SPAT of
    0.3 um R-Test noise (stated at 2 um) with 8 rows 4 um off: those 8 suspected, and rejected by
    the robust fit (with the stated noise as a floor, none was)."""
    arm = ap.load_arm()
    sim = ap.simulate_campaign(arm, ap.SimulationConfig(seed=0, sigma_rtest=0.3e-6,
                                                        samples_per_location=100))
    spat = sim.campaign.spat
    rows = np.sort(np.random.default_rng(5).choice(len(spat.q), 8, replace=False))
    d = spat.displacement.copy()
    d[rows, 0] += 4e-6
    bad = sim.campaign.with_spat(displacement=d)
    plain, robust = ap.identify(bad, arm), ap.identify(bad, arm, robust=True)
    suspects = sorted(o.row for o in plain.suspects)
    assert len(suspects) == 8 and sorted(o.row for o in robust.outliers) == suspects
    assert robust.fit_rms < 0.3e-6 < plain.fit_rms
