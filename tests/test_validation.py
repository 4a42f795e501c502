"""Length-bar validation flags what makes its errors doubtful (issue 14's fuzz found both)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

import aacmm_pin as ap


def test_clean_validation_has_no_warnings(arm: ap.Arm, small_sim: ap.Simulation,
                                          small_cal: ap.Calibration) -> None:
    for params in (small_cal.parameters, ap.identify(small_sim.campaign, arm, "dh").parameters):
        result = ap.validate(arm, params, small_sim.campaign)
        assert result.warnings == ()
        assert result.to_dict()["warnings"] == []


def test_a_wrong_bar_readout_is_flagged_with_its_line(arm: ap.Arm, small_sim: ap.Simulation,
                                                      small_cal: ap.Calibration) -> None:
    """Two readouts swapped in one lengthbar.csv row moved the bar errors by 29 mm, unflagged."""
    log = small_sim.campaign.lengthbar
    assert log is not None
    q = log.q.copy()
    q[3, [5, 6]] = q[3, [6, 5]]
    bad = replace(small_sim.campaign, lengthbar=replace(log, q=q))
    result = ap.validate(arm, small_cal.parameters, bad)
    readouts = [w for w in result.warnings if w.startswith("lengthbar.csv")]
    assert len(readouts) == 1 and "lengthbar.csv line 5:" in readouts[0]  # row 4 of the body
    assert "WARNING: lengthbar.csv line 5" in result.table()


def test_a_bar_length_in_other_units_is_flagged(arm: ap.Arm, small_sim: ap.Simulation,
                                                small_cal: ap.Calibration) -> None:
    """A bar.csv length given in the wrong unit (x pi/180, still a plausible 1 mm..10 m)."""
    bar = {k: v * np.pi / 180 for k, v in small_sim.campaign.bar.items()}
    result = ap.validate(arm, small_cal.parameters, replace(small_sim.campaign, bar=bar))
    assert result.warnings and all("bar.csv" in w and "units?" in w for w in result.warnings)
    assert len(result.warnings) == np.isfinite(result.errors).sum()
