"""predict --frame GROUP: predicted points in an instrument's frame, as the calibration fitted it."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import aacmm_pin as ap
from aacmm_pin.cli import main
from aacmm_pin.data.campaign import PointLog, write_campaign
from tests.helpers import run_cli

SIGMA = 20e-6  # tracker noise per coordinate, m
N = 40  # poses per instrument group


def _two_stations(tmp_path):
    """A UR5 seen by two tracker stations: group 1 in the calibration's frame (the arm's base
    moved and turned), group 2 in a frame of its own (turned 30 deg, 2 m away)."""
    arm = ap.load_arm("ur5")
    rng = np.random.default_rng(3)
    nominal = ap.Parameters.nominal(arm, 5.0)
    truth = nominal.replace(dh={k: v + rng.normal(0.0, 3e-4) for k, v in nominal.dh.items()},
                            rotation_abc=np.array([0.01, -0.02, 0.4]),
                            translation=np.array([0.5, -1.0, 0.2]))
    lim = arm.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (2 * N, arm.n_axes))
    p_mt = ap.stylus_positions(arm, truth, q, frame="mt")
    rot2 = Rotation.from_euler("zyx", [30.0, 2.0, -1.0], degrees=True).as_matrix()
    t2 = np.array([2.0, 0.3, -0.1])
    measured = p_mt.copy()
    measured[N:] = (p_mt[N:] - t2) @ rot2  # p_mt = R2 m + t2
    measured += rng.normal(0.0, SIGMA, measured.shape)
    group = np.repeat([1, 2], N)
    write_campaign(ap.Campaign(None, {}, None, {}, points=PointLog(group, q, measured)),
                   tmp_path / "campaign")
    return measured, group


def _predicted(path):
    data = np.genfromtxt(path, delimiter=",", names=True)
    return np.column_stack([data["x_mm"], data["y_mm"], data["z_mm"]]) * 1e-3


def test_predict_frame_writes_points_in_the_fitted_instrument_frame(tmp_path, capsys):
    """Each group's predicted points differ from its measured ones exactly by the fit's residual
    (the fitted frame, not a refit), and the fitted frame is near the true one."""
    measured, group = _two_stations(tmp_path)
    cal_dir, campaign = tmp_path / "cal", tmp_path / "campaign"
    status, out = run_cli(["identify", str(campaign), "--arm", "ur5", "--model", "dh",
                           "--out", str(cal_dir)])
    assert status == 0, out
    cal = ap.identify(ap.read_campaign(campaign), ap.load_arm("ur5"), model="dh")
    report = json.loads((cal_dir / "report.json").read_text())
    frame2 = report["instrument_frames"]["2"]
    rot, trans = cal.problem.frames(cal.x)
    np.testing.assert_allclose(frame2["rotation"], rot[0], atol=1e-12)
    np.testing.assert_allclose(np.array(frame2["translation_mm"]) * 1e-3, trans[0], atol=1e-12)
    true2 = Rotation.from_euler("zyx", [30.0, 2.0, -1.0], degrees=True).as_matrix()
    assert np.degrees(Rotation.from_matrix(rot[0] @ true2.T).magnitude()) < 0.01  # 40 points
    for g in (1, 2):
        status = main(["predict", str(cal_dir), str(campaign / "points.csv"), "--frame", str(g),
                       "--out", str(tmp_path / f"g{g}.csv")])
        assert status == 0 and f"instrument group {g}" in capsys.readouterr().out
        sel = group == g
        error = np.linalg.norm(_predicted(tmp_path / f"g{g}.csv")[sel] - measured[sel], axis=1)
        fit = np.linalg.norm(cal.fun[sel], axis=1)  # predicted - measured, in the MT-CS
        np.testing.assert_allclose(error, fit, rtol=0, atol=1e-9)  # 9 decimals of mm
        assert np.sqrt(np.mean(error ** 2) / 3) < 2 * SIGMA  # the noise, not the frame's offset
    status, out = run_cli(["predict", str(cal_dir), str(campaign / "points.csv"), "--frame", "3",
                           "--out", str(tmp_path / "g3.csv")])
    assert status != 0 and "no instrument group 3" in out and "1, 2" in out


def test_validate_help_says_what_it_does_for_points(capsys):
    with pytest.raises(SystemExit):
        main(["validate", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "points.csv" in out and "frame of its own, which is fitted" in out


@pytest.mark.parametrize("key", ["rotation", "translation_mm"])
def test_a_broken_frame_is_named(tmp_path, key):
    """A report.json frame that is not a rotation and translation is refused in one line."""
    from aacmm_pin.errors import AacmmError
    from aacmm_pin.outputs.instrument_frames import frame_of

    report = {"instrument_frames": {"1": {"rotation": np.eye(3).tolist(),
                                          "translation_mm": [0.0, 0.0, 0.0]}}}
    report["instrument_frames"]["1"][key] = [1.0, 2.0]
    with pytest.raises(AacmmError, match="group 1 is not a rotation"):
        frame_of(report, 1, "cal")
