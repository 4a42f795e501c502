"""Absolute tool points (points.csv): reading, identification against simulated truth, real data."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.analyses.validation import validate_points
from aacmm_pin.data.campaign import PointLog
from aacmm_pin.model.samples import Samples

ROOT = Path(__file__).resolve().parents[1]
UR5 = ROOT / "urdf" / "ur5.urdf"
DATA = ROOT.parent / "shared" / "real-data" / "jacobi2025-laser-tracker"
SIGMA = 20e-6  # tracker noise per coordinate, m


def _points_campaign(arm: ap.Arm, params: ap.Parameters, n: int, seed: int,
                     sigma: float = SIGMA) -> ap.Campaign:
    """Points of ``params``' tool at n random poses, in its instrument frame, with noise."""
    rng = np.random.default_rng(seed)
    lim = np.clip(arm.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, arm.n_axes))
    point = ap.stylus_positions(arm, params, q, frame="mt") + rng.normal(0.0, sigma, (n, 3))
    return ap.Campaign(spat=None, locations={}, lengthbar=None, bar={},
                       points=PointLog(group=np.ones(n, dtype=np.int64), q=q, point=point))


def _truth(arm: ap.Arm, seed: int) -> ap.Parameters:
    """Nominal parameters with robot-sized DH errors (0.3 mm, 0.03 deg) and a tracker frame."""
    rng = np.random.default_rng(seed)
    nominal = ap.Parameters.nominal(arm, 5.0)
    dh = {f.name: v + rng.normal(0.0, np.radians(0.03) if f.is_angle else 3e-4)
          for f, v in zip(arm.error_frames, nominal.dh.values())}
    return nominal.replace(dh=dh, tool=nominal.tool + rng.normal(0.0, 3e-4, 3),
                           rotation_abc=rng.normal(0.0, 0.2, 3),
                           translation=rng.uniform(-2.0, 2.0, 3))


def test_points_round_trip_through_files(tmp_path):
    """points.csv written and read back gives the same groups, readouts, points and sigmas."""
    arm = ap.load_arm(UR5)
    campaign = _points_campaign(arm, _truth(arm, 0), 20, 0)
    pts = campaign.points
    assert pts is not None
    campaign = ap.Campaign(spat=None, locations={}, lengthbar=None, bar={}, points=PointLog(
        group=pts.group, q=pts.q, point=pts.point, sigma=np.full(20, 15e-6)))
    ap.write_campaign(campaign, tmp_path)
    back = ap.read_campaign(tmp_path).points
    assert back is not None and back.sigma is not None and back.lines is not None
    np.testing.assert_array_equal(back.group, pts.group)
    np.testing.assert_allclose(back.q, pts.q, atol=1e-11)  # 9 decimals of a degree
    np.testing.assert_allclose(back.point, pts.point, atol=1e-12)  # 9 decimals of a mm
    np.testing.assert_allclose(back.sigma, 15e-6)
    assert back.lines.tolist() == list(range(2, 22))


@pytest.mark.parametrize("cells, line, column, reason", [
    ({"x_mm": "abc"}, 3, "x_mm", "is not a number"),
    ({"sigma_um": "0"}, 2, "sigma_um", "not a positive standard uncertainty"),
    ({"group": "0"}, 4, "group", "is not an integer >= 1"),
    ({"q2_deg": "900"}, 2, "q2_deg", "outside"),
])
def test_bad_point_cells_are_named_with_file_line_and_column(tmp_path, cells, line, column, reason):
    """A bad cell of points.csv is reported with the file, its line and its column."""
    header = ["group", "q1_deg", "q2_deg", "x_mm", "y_mm", "z_mm", "sigma_um"]
    rows = [["1", "10", "20", "1", "2", "3", "15"] for _ in range(4)]
    name, value = next(iter(cells.items()))
    rows[line - 2][header.index(name)] = value
    (tmp_path / "points.csv").write_text("\n".join(",".join(r) for r in [header, *rows]) + "\n")
    with pytest.raises(ap.CampaignFormatError) as info:
        ap.read_campaign(tmp_path)
    text = str(info.value)
    assert f"points.csv:{line}: column '{column}'" in text and reason in text


def test_missing_point_column_is_named(tmp_path):
    """A points.csv without z_mm says which column is missing."""
    (tmp_path / "points.csv").write_text("q1_deg,x_mm,y_mm\n1,2,3\n")
    with pytest.raises(ap.CampaignFormatError, match=r"z_mm.*missing column"):
        ap.read_campaign(tmp_path)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dh_identified_from_points_matches_the_truth(seed):
    """A DH fit to simulated tracker points recovers the truth within its stated uncertainty."""
    arm = ap.load_arm(UR5)
    truth = _truth(arm, seed)
    cal = ap.identify(_points_campaign(arm, truth, 400, seed), arm, model="dh")
    assert cal.success and cal.problem.n_loc == 0
    # the residual is the tracker noise: 1200 coordinates less ~25 parameters, its std ~2 %
    assert abs(cal.fit_rms / SIGMA - 1) < 0.1
    equivalent, _ = cal.equivalent(truth)
    u = cal.unknowns
    std = np.sqrt(np.diag(cal.covariance))[:len(u.names)]
    z = ((u.vector(cal.parameters) - u.vector(equivalent)) / std)[cal.identifiable]
    assert z.size >= 20 and np.all(np.abs(z) < 4.5), z.round(2)  # P(any > 4.5) ~ 2e-4
    fresh = _points_campaign(arm, truth, 200, seed + 100, sigma=0.0)
    err = validate_points(arm, cal.parameters, fresh)
    assert err.rms < 3 * SIGMA  # predictions at new poses within the noise of the fit


def test_points_are_weighted_by_their_stated_noise():
    """Half the points 10 um, half 100 um (stated so): the weighted fit is right and much better."""
    arm = ap.load_arm(UR5)
    truth = _truth(arm, 5)
    noisy = _points_campaign(arm, truth, 400, 5, sigma=0.0)
    pts = noisy.points
    assert pts is not None
    sigma = np.where(np.arange(400) % 2, 100e-6, 10e-6)
    point = pts.point + np.random.default_rng(6).normal(0.0, 1.0, (400, 3)) * sigma[:, None]

    def fit(stated: np.ndarray | None) -> ap.Calibration:
        log = PointLog(group=pts.group, q=pts.q, point=point, sigma=stated)
        campaign = ap.Campaign(spat=None, locations={}, lengthbar=None, bar={}, points=log)
        return ap.identify(campaign, arm, model="dh")

    weighted, plain = fit(sigma), fit(None)
    # the reference noise is the median stated one (55 um here): the estimate agrees within ~4 %
    assert abs(weighted.sigma / np.median(sigma) - 1) < 0.15
    fresh = _points_campaign(arm, truth, 200, 50, sigma=0.0)
    better, worse = (validate_points(arm, c.parameters, fresh).rms for c in (weighted, plain))
    assert better < 0.6 * worse  # GLS against OLS: the 10 um points carry the fit


def test_a_group_too_small_for_its_own_frame_is_refused():
    """Each group has a frame of its own: 3 points of group 2 cannot fix it; the message names it."""
    arm = ap.load_arm(UR5)
    c = _points_campaign(arm, _truth(arm, 0), 40, 0)
    pts = c.points
    assert pts is not None
    two = ap.Campaign(spat=None, locations={}, lengthbar=None, bar={}, points=PointLog(
        group=np.r_[np.ones(37, dtype=np.int64), [2, 2, 2]], q=pts.q, point=pts.point))
    with pytest.raises(ap.IdentificationError, match="group 2 .3 points"):
        ap.identify(two, arm, model="dh")

@pytest.mark.skipif(not DATA.is_dir(), reason="../shared/real-data is not beside the project")
def test_ur5_and_wam_real_tracker_data(tmp_path):
    """UR5: CLI DH calibration on 1000 grid poses, <= 0.105 mm mean on 20 random poses; WAM shrinks."""
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "03_laser_tracker_ur5_wam.py"),
                          "--out", str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    rows = {m[1]: (float(m[2]), float(m[3]), float(m[4])) for m in re.finditer(
        r"^(UR5|WAM)\s+\(.*?\)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+|nan)", out.stdout, flags=re.M)}
    ur5_before, ur5_after, ur5_found = rows["UR5"]
    assert abs(ur5_before - 2.5664) < 0.01  # the thesis' uncalibrated figure on the same poses
    assert ur5_after <= 0.105
    assert ur5_found < ur5_after  # what discovery adds helps on poses it never saw
    wam_before, wam_after, _ = rows["WAM"]
    assert wam_after < 0.2 * wam_before  # DH explains most of the cable-driven arm's error
    assert "converged" in out.stdout and (tmp_path / "ur5_dh" / "parameters.json").is_file()


def test_discovery_names_compliance_from_tracker_points():
    """Hidden gravity compliance of A2 and A3 in simulated tracker points: discover names exactly it."""
    arm = ap.load_arm(UR5)
    truth = _truth(arm, 3)
    truth = truth.replace(extensions={"compliance[A2]": np.array([8e-6]),
                                      "compliance[A3]": np.array([1.2e-5])})
    rng = np.random.default_rng(3)
    lim = np.clip(arm.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (400, arm.n_axes))
    point = (ap.stylus_positions(arm, truth, q, frame="mt", samples=Samples(arm, q))
             + rng.normal(0.0, SIGMA, (400, 3)))
    campaign = ap.Campaign(spat=None, locations={}, lengthbar=None, bar={}, points=PointLog(
        group=np.ones(400, dtype=np.int64), q=q, point=point))
    result = ap.discover(campaign, arm, "dh", effects=["compliance", "backlash", "crosstalk"])
    assert result.named == [("compliance", [2, 3])], result.stopped_because
    assert result.heldout_rms[-1] < 0.5 * result.heldout_rms[0]  # k-fold held out over the poses
    cal = result.calibration
    for axis, true_k in ((2, 8e-6), (3, 1.2e-5)):  # within 4 of the fit's standard uncertainties
        estimate = cal.parameters.extensions[f"compliance[A{axis}]"][0]
        z = (estimate - true_k) / cal.std[f"compliance[A{axis}].k"]
        assert abs(z) < 4, (axis, z)
