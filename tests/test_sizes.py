"""Plausible sizes from the arm: the sizes file, its defaults, and the priors that follow it."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.analyses.linear_scorer import LinearScorer, size_factors
from aacmm_pin.data.campaign import PointLog
from aacmm_pin.effects import backlash, compliance, crosstalk, encoder_harmonic, thermal
from aacmm_pin.fit.identifiability import plausible_sizes
from aacmm_pin.fit.measurements import measurements
from aacmm_pin.fit.unknowns import Unknowns
from aacmm_pin.model.samples import Samples
from aacmm_pin.model.sizes import DEFAULT, Sizes, read_sizes, sizes_path, write_sizes
from aacmm_pin.units import ARCSEC

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "real-data" / "jacobi2025-laser-tracker"


def test_defaults_are_the_aacmm_constants():
    """The default sizes (and the default arm's) are exactly the former hard-coded AACMM values."""
    assert (DEFAULT.dh_angle, DEFAULT.dh_length, DEFAULT.tool, DEFAULT.map_node,
            DEFAULT.x0_angle, DEFAULT.x0_translation) == (3.5e-4, 1e-4, 1e-4, 1e-4, 1e-2, 1e-2)
    assert ap.load_arm().sizes == DEFAULT
    for term in (compliance(2), backlash(3), crosstalk(2, 3), encoder_harmonic(4), thermal()):
        np.testing.assert_array_equal(term.sizes(DEFAULT), np.asarray(term.plausible))
    assert compliance(1).sizes(DEFAULT)[0] == 1e-5 and backlash(1).sizes(DEFAULT)[0] == 10 * ARCSEC


def test_embedded_robots_have_their_own_sizes():
    """ur5 and wam7 load their sizes files (with a source); an effect not listed keeps its own size."""
    wam, ur5 = ap.load_arm("wam7"), ap.load_arm("ur5")
    assert wam.sizes.effects["compliance"] > ur5.sizes.effects["compliance"] > 1e-5
    assert wam.sizes.dh_length > ur5.sizes.dh_length > DEFAULT.dh_length
    assert "not fitted" in wam.sizes.source and "not fitted" in ur5.sizes.source
    np.testing.assert_array_equal(thermal().sizes(wam.sizes), [2.3e-5])
    unknowns = Unknowns.full(wam, ap.Parameters.nominal(wam), (), (compliance(2), backlash(1)),
                             Samples(wam, np.zeros((2, 7))))
    sizes = plausible_sizes(unknowns)
    n_dh = len(wam.error_frames)
    expected_dh = [wam.sizes.dh_angle if f.is_angle else wam.sizes.dh_length for f in wam.error_frames]
    np.testing.assert_array_equal(sizes[6:6 + n_dh], expected_dh)
    np.testing.assert_array_equal(sizes[6 + n_dh:9 + n_dh], [wam.sizes.tool] * 3)
    np.testing.assert_array_equal(sizes[9 + n_dh:11 + n_dh], [3e-4, 1e-3])


def test_sizes_round_trip_and_missing_keys_default(tmp_path):
    """A written sizes file reads back equal; a file with one key keeps every other default."""
    sizes = Sizes(dh_angle=2e-3, effects={"compliance": 4e-4, "mine": 0.5}, source="test")
    write_sizes(sizes, tmp_path / "a.sizes.json")
    assert read_sizes(tmp_path / "a.sizes.json") == sizes
    (tmp_path / "b.sizes.json").write_text('{"dh_length": 0.002, "effects": {"backlash": 1e-4}}')
    back = read_sizes(tmp_path / "b.sizes.json")
    assert back.dh_length == 0.002 and back.dh_angle == DEFAULT.dh_angle
    assert back.effects["backlash"] == 1e-4 and back.effects["compliance"] == 1e-5


def test_bad_sizes_file_names_file_and_every_key(tmp_path):
    """Unknown keys, non-positive or non-numeric sizes and wrong units are all reported by key."""
    path = tmp_path / "arm.sizes.json"
    path.write_text(json.dumps({"units": "mm", "dh_angel": 1e-3, "dh_length": -1.0,
                                "effects": {"compliance": "big"}}))
    with pytest.raises(ap.FileFormatError) as info:
        read_sizes(path)
    text = str(info.value)
    assert "4 problems" in text and str(path) in text
    for key in ("'units'", "'dh_angel'", "'dh_length'", "'effects.compliance'"):
        assert key in text
    path.write_text('{"dh_angle": 1e-3,\n "tool": }')
    with pytest.raises(ap.FileFormatError, match=r"arm.sizes.json:2"):
        read_sizes(path)


def test_arm_reads_the_sizes_file_beside_its_urdf(tmp_path):
    """A URDF's ``<name>.sizes.json`` sets its arm's sizes; a broken one is an error naming it."""
    urdf = tmp_path / "robot.urdf"
    shutil.copy(ROOT / "urdf" / "wam7.urdf", urdf)
    assert ap.load_arm(urdf).sizes == DEFAULT
    assert sizes_path(urdf) == tmp_path / "robot.sizes.json"
    sizes_path(urdf).write_text('{"map_node": 5e-4}')
    assert ap.load_arm(urdf).sizes.map_node == 5e-4
    sizes_path(urdf).write_text('{"map_nodes": 5e-4}')
    with pytest.raises(ap.FileFormatError, match="robot.sizes.json: column 'map_nodes'"):
        _ = ap.load_arm(urdf).sizes


def test_embedded_sizes_files_ship_in_the_wheel():
    """Every embedded arm's sizes file is force-included next to its URDF in the wheel."""
    text = (ROOT / "pyproject.toml").read_text()
    for name in ap.model.arm.EMBEDDED:
        if sizes_path(ROOT / "urdf" / f"{name}.urdf").is_file():
            assert f'"urdf/{name}.sizes.json" = "aacmm_pin/urdf/{name}.sizes.json"' in text


def _wam_points(arm: ap.Arm, seed: int, n: int, sigma: float, dh_scale: float = 1.0,
                compliance_a2: float = 3e-4) -> ap.Campaign:
    """Points of a simulated WAM: DH errors of dh_scale x its stated sizes, compliance on A2."""
    rng = np.random.default_rng(seed)
    nominal = ap.Parameters.nominal(arm, 5.0)
    s = ap.load_arm("wam7").sizes
    dh = {f.name: v + dh_scale * rng.normal(0.0, s.dh_angle if f.is_angle else s.dh_length)
          for f, v in zip(arm.error_frames, nominal.dh.values())}
    truth = nominal.replace(dh=dh, tool=nominal.tool + rng.normal(0.0, s.tool, 3),
                            rotation_abc=rng.normal(0.0, 0.2, 3), translation=rng.uniform(-2, 2, 3),
                            extensions={"compliance[A2]": np.array([compliance_a2])})
    lim = np.clip(arm.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, arm.n_axes))
    point = (ap.stylus_positions(arm, truth, q, frame="mt", samples=Samples(arm, q))
             + rng.normal(0.0, sigma, (n, 3)))
    return ap.Campaign(spat=None, locations={}, lengthbar=None, bar={}, points=PointLog(
        group=np.ones(n, dtype=np.int64), q=q, point=point))


def test_term_prior_follows_the_arms_sizes(tmp_path):
    """A WAM-sized compliance is recovered under the WAM's sizes and shrunk under the AACMM's.

    Same simulated points (DH errors of the WAM's sizes, compliance 3e-4 rad/(N m) on A2, noise
    0.2 mm), same URDF, DH fit without compliance: scored as a candidate, compliance[A2] brings the
    k-fold held-out RMS down to the noise (a right linear model: sqrt(1 + p/n) ~ 1.05 sigma; the
    RMS of 900 coordinates scatters by 2.4%) only when its prior is of the arm's size. Under the
    default AACMM sizes (the same URDF without a sizes file) the compliance's prior holds it near
    zero (the DH priors are widened to what the fit shows, :func:`size_factors`; compliance is not
    in the model yet), and the held-out RMS stays several times the noise.
    """
    sigma = 2e-4
    wam = ap.load_arm("wam7")
    shutil.copy(ROOT / "urdf" / "wam7.urdf", tmp_path / "bare.urdf")
    bare = ap.load_arm(tmp_path / "bare.urdf")
    campaign = _wam_points(wam, 0, 300, sigma)
    held = {}
    for arm in (wam, bare):
        cal = ap.identify(campaign, arm, model="dh")
        score = LinearScorer(cal, measurements(campaign, arm, True).samples).score(compliance(2))
        held[arm.name] = (score.heldout_rms, score.k_eff)
    assert held["wam7"][0] < 1.2 * sigma, held
    assert held["wam7"][1] > 0.95, held  # the data determine it: the prior does not shrink it
    assert held[str(tmp_path / "bare.urdf")][0] > 3 * sigma, held


def test_sizes_the_fit_rejects_are_widened_to_what_the_data_show():
    """Errors of the stated sizes keep them; DH errors 10x the stated sizes are rejected by the fit
    (chi-square at 0.1% per group) and their prior widened, and the DH model's k-fold held-out RMS
    comes nearer to a right model's than with the stated sizes (noise 1 mm, as the real WAM's
    residuals: there the prior matters)."""
    sigma = 1e-3
    wam = ap.load_arm("wam7")
    right = ap.identify(_wam_points(wam, 2, 300, sigma, 1.0, 0.0), wam, model="dh")
    assert not {"dh_angle", "dh_length"} & set(size_factors(right)), size_factors(right)
    for seed in (2, 3, 4, 5):
        campaign = _wam_points(wam, seed, 300, sigma, 10.0, 0.0)
        cal = ap.identify(campaign, wam, model="dh")
        factors = size_factors(cal)
        # identifiable DH values absorb redundant combinations: their scale is right within ~2x
        assert 3.0 < max(factors["dh_angle"], factors["dh_length"]) < 30.0, factors
        samples = measurements(campaign, wam, True).samples
        widened = LinearScorer(cal, samples)
        stated = LinearScorer(cal, samples, widen_sizes=False)
        assert widened.size_factors == factors and not stated.size_factors
        # a right model's held-out RMS is about sqrt(1 + p/n) ~ 1.03 sigma (n = 900, p ~ 25)
        assert widened.heldout_rms < min(stated.heldout_rms, 1.1 * sigma), (
            seed, widened.heldout_rms, stated.heldout_rms)


def test_calibration_folder_carries_the_arms_sizes(tmp_path):
    """write_calibration puts the arm's sizes beside calibrated.urdf; the folder's arm has them."""
    wam = ap.load_arm("wam7")
    cal = ap.identify(_wam_points(wam, 1, 60, 2e-4), wam, model="dh")
    folder = ap.write_calibration(cal, wam, tmp_path / "cal")
    assert (folder / "calibrated.sizes.json").is_file()
    assert ap.load_arm(folder / "calibrated.urdf").sizes == wam.sizes
    assert ap.load_arm(folder / "compact.urdf").sizes == wam.sizes  # compact.sizes.json


def _tracker_campaign(source: Path, folder: Path) -> ap.Campaign:
    """The jacobi2025 rows as a points campaign (measured = commanded - dif, mm)."""
    with source.open(newline="") as f:
        rows = list(csv.DictReader(f))
    n = sum(1 for key in rows[0] if key.startswith("joint_"))
    q = np.radians([[float(r[f"joint_{i}"]) for i in range(1, n + 1)] for r in rows])
    point = np.array([[float(r[f"{c}_t"]) - float(r[f"{c}_dif"]) for c in "xyz"] for r in rows])
    return ap.Campaign(spat=None, locations={}, lengthbar=None, bar={}, points=PointLog(
        group=np.ones(len(q), dtype=np.int64), q=q, point=point * 1e-3))


@pytest.mark.skipif(not DATA.is_dir(), reason="../shared/real-data is not beside the project")
def test_wam_discovery_names_effects_beyond_dh(tmp_path):
    """Real WAM grid: with its own sizes, discovery names effects beyond DH and every step shrinks
    the k-fold held-out RMS; the DH model's held-out RMS is near its fit (a right linear model's is
    1.02x on 1000 poses; 1.07x with the WAM's sizes widened by the fit, 1.12x with its stated
    sizes, 1.86x with the AACMM sizes, whose priors held mm-sized DH errors near zero)."""
    campaign = _tracker_campaign(DATA / "WAM" / "3D_WAM_uncalibrated_grid_cleaned.csv", tmp_path)
    result = ap.discover(campaign, ap.load_arm("wam7"), "dh")
    assert result.steps, result.stopped_because
    assert all(axes for _, axes in result.named)
    held = np.array(result.heldout_rms)
    assert np.all(np.diff(held) < 0), held
    assert held[0] < 1.3 * result.fit_rms[0], (held[0], result.fit_rms[0])
    assert len(result.size_factors) == len(held) and "dh_angle" in result.size_factors[0]
