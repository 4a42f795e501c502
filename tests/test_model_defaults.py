"""Defaults that fit the data (issue 25 item 5): the start model of points by held-out poses, the
stated noise per instrument kind, and help texts and report.json that speak of points."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.analyses.model_choice import choose_model
from aacmm_pin.analyses.simulate import SimulationConfig, simulate_campaign
from aacmm_pin.cli import main
from aacmm_pin.data.campaign import read_campaign, write_campaign
from aacmm_pin.units import ARCSEC, SIGMA_MOTION_CAPTURE

FRESH = 150  # poses never fitted, for the truth's verdict


def _points(effects: tuple[str, ...], n: int, encoder_arcsec: float = 20.0,
            sigma: float = 20e-6) -> tuple[ap.Campaign, np.ndarray, np.ndarray]:
    """A simulated UR5 points campaign of n poses, and FRESH other poses: readouts, true points."""
    sim = simulate_campaign(ap.load_arm("ur5"), SimulationConfig(
        seed=0, effects=effects, points=n + FRESH, encoder_max=encoder_arcsec * ARCSEC,
        sigma_point=sigma))
    points = sim.campaign.points
    assert points is not None
    fit = dataclasses.replace(sim.campaign, points=points.take(np.arange(n)))
    return fit, points.q[n:], sim.sphere_mt[n:]


def _fresh_rms(cal: ap.Calibration, q: np.ndarray, truth: np.ndarray) -> float:
    pred = ap.stylus_positions(ap.load_arm("ur5"), cal.parameters, q, frame="mt")
    return float(np.sqrt(np.mean((pred - truth) ** 2)))


@pytest.mark.parametrize(("effects", "n", "encoder", "better"), [
    (("dh",), 100, 20.0, "dh"),  # no encoder errors, few poses: the maps fit the noise
    (("dh", "encoder"), 200, 300.0, "proposed"),  # 300 arcsec encoder errors: the maps pay
])
def test_auto_chooses_the_model_that_predicts_fresh_poses_better(effects, n, encoder, better):
    """choose_model's held-out choice is the model the truth prefers on poses never fitted."""
    campaign, q, truth = _points(effects, n, encoder)
    choice = choose_model(campaign, ap.load_arm("ur5"))
    fresh = {m: _fresh_rms(ap.identify(campaign, ap.load_arm("ur5"), model=m), q, truth)
             for m in ("dh", "proposed")}
    assert min(fresh, key=fresh.__getitem__) == better  # the cases are what they claim
    assert choice.chosen == better and choice.calibration.model == better
    assert set(choice.heldout_rms) == {"dh", "proposed"}


def test_identify_default_on_points_is_chosen_and_a_losing_model_is_warned(tmp_path, capsys):
    """identify (no --model) on points alone writes the held-out choice (DH here) with both
    numbers; --model proposed, which loses on held-out poses, says so with the numbers."""
    campaign, _, _ = _points(("dh",), 100)
    write_campaign(campaign, tmp_path / "c")
    assert main(["identify", str(tmp_path / "c"), "--arm", "ur5", "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    report = json.loads((tmp_path / "a" / "report.json").read_text())
    assert report["model"] == "dh" and report["model_choice"]["better"] == "dh"
    held = report["model_choice"]["heldout_rms_um"]
    assert held["dh"] < held["proposed"]
    assert f"model dh chosen: held-out RMS (5 folds of poses): dh {held['dh']:.2f} um" in out
    assert report["use_rtest"] is None and report["inputs"] == ["points"]
    main(["identify", str(tmp_path / "c"), "--arm", "ur5", "--model", "proposed",
          "--out", str(tmp_path / "p")])
    out = capsys.readouterr().out
    assert "WARNING: the proposed model loses on poses it was not fitted to" in out
    assert f"proposed {held['proposed']:.2f} um" in out and "use --model dh" in out


def test_the_instruments_noise_is_the_stated_one_and_printed(tmp_path, capsys):
    """campaign.json {"instrument": "motion capture"}: points stated at 100 um, printed; a DH fit
    of motion-capture points (100 um noise) then matches its noise instead of being '5 x' it."""
    campaign, _, _ = _points(("dh",), 150, sigma=SIGMA_MOTION_CAPTURE)
    write_campaign(campaign, tmp_path / "c")
    (tmp_path / "c" / "campaign.json").write_text('{"instrument": "motion capture"}')
    assert read_campaign(tmp_path / "c").noise == ap.StatedNoise.of_instrument("motion capture")
    args = ["identify", str(tmp_path / "c"), "--arm", "ur5", "--model", "dh", "--force"]
    assert main([*args, "--out", str(tmp_path / "mocap")]) == 0
    out = capsys.readouterr().out
    assert "stated noise per coordinate: points 100 um (campaign.json, motion capture)" in out
    assert "x the stated noise" not in out
    (tmp_path / "c" / "campaign.json").unlink()
    main([*args, "--out", str(tmp_path / "tracker")])
    out = capsys.readouterr().out
    assert "points 20 um (defaults)" in out and "x the stated noise" in out


def test_help_speaks_of_points(capsys):
    with pytest.raises(SystemExit):
        main(["identify", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "points.csv" in out and "auto" in out and "R-Test readings or, on points alone" in out


def test_spat_reports_keep_use_rtest(small_cal):
    assert small_cal.report()["use_rtest"] is True


def test_import_points_names_the_instrument(tmp_path):
    """import-points --instrument motion-capture: campaign.json names it; its 100 um is the stated
    point noise; --sigma-um still overrides it."""
    from tests.helpers import run_cli

    source = tmp_path / "mocap.csv"
    rng = np.random.default_rng(0)
    rows = [",".join(f"{v:.6f}" for v in [*rng.uniform(-90, 90, 6), *rng.uniform(-500, 500, 3)])
            for _ in range(25)]
    source.write_text("a1,a2,a3,a4,a5,a6,x,y,z\n" + "\n".join(rows) + "\n")
    args = ["import-points", str(source), "--joints", "a1..a6", "--point", "x,y,z",
            "--instrument", "motion-capture"]
    assert run_cli([*args, "--out", str(tmp_path / "a")])[0] == 0
    content = json.loads((tmp_path / "a" / "campaign.json").read_text())
    assert content["instrument"] == "motion capture"
    assert read_campaign(tmp_path / "a").noise == ap.StatedNoise.of_instrument("motion capture")
    assert run_cli([*args, "--sigma-um", "250", "--out", str(tmp_path / "b")])[0] == 0
    noise = read_campaign(tmp_path / "b").noise
    assert noise is not None and noise.point == pytest.approx(250e-6)
    assert noise.instrument == "motion capture"
