"""Length-bar validation flags what makes its errors doubtful (issue 14's fuzz found them)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.analyses.bar_scatter import CAUSES
from aacmm_pin.cli import main
from aacmm_pin.outputs.calibration_folder import read_calibration
from tests import fuzz
from tests.conftest import SMALL
from tests.helpers import SAMPLE


def test_clean_validation_has_no_warnings(arm: ap.Arm, small_sim: ap.Simulation,
                                          small_cal: ap.Calibration) -> None:
    for cal in (small_cal, ap.identify(small_sim.campaign, arm, "dh")):
        result = ap.validate(arm, cal.parameters, small_sim.campaign, cal.accuracy)
        assert result.warnings == ()
        assert result.to_dict()["warnings"] == []
        assert result.scatter is not None and result.scatter.ratio is not None


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


@pytest.mark.parametrize(("factor", "words"), [
    (1 / 25.4, "look like inches (measured / stated = 25.4)"),
    (0.1, "look like cm"),
    (np.pi / 180, "off by the same factor 57.3"),  # x pi/180: still a plausible 1 mm..10 m
])
def test_bar_lengths_in_other_units_are_refused(arm: ap.Arm, small_sim: ap.Simulation,
                                                small_cal: ap.Calibration, factor: float,
                                                words: str) -> None:
    """Every bar.csv length off by one factor: an error naming the file, column and unit (issue 26).

    (It was one warning per placement and pair, 14 for the paper's bar, and exit status 0.)
    """
    bar = {k: v * factor for k, v in small_sim.campaign.bar.items()}
    with pytest.raises(ap.AacmmError) as info:
        ap.validate(arm, small_cal.parameters, replace(small_sim.campaign, bar=bar))
    text = str(info.value)
    assert "bar.csv: column 'length_mm'" in text and words in text, text


def test_one_wrong_bar_length_is_one_warning(arm: ap.Arm, small_sim: ap.Simulation,
                                             small_cal: ap.Calibration) -> None:
    """One pair's length 5 % off (beyond the 1 % no arm errs by): one line for all its placements."""
    bar = dict(small_sim.campaign.bar)
    first = next(iter(bar))
    bar[first] *= 1.05
    result = ap.validate(arm, small_cal.parameters, replace(small_sim.campaign, bar=bar))
    placements = np.isfinite(result.errors[:, result.pairs.index(first)]).sum()
    assert placements > 1
    assert len(result.warnings) == 1, result.warnings
    assert f"{first[0]}-{first[1]}" in result.warnings[0] and "units?" in result.warnings[0]
    assert f"and {placements - 1} more like it" in result.warnings[0]


def scatter_ratios(arm: ap.Arm, campaign: ap.Campaign
                   ) -> dict[str, tuple[float, float, tuple[str, ...]]]:
    """Per model (DH, proposed): the socket-scatter ratio, its limit and the warnings."""
    out = {}
    for model in ("dh", "proposed"):
        cal = ap.identify(campaign, arm, model)
        result = ap.validate(arm, cal.parameters, campaign, cal.accuracy)
        assert result.scatter is not None and result.scatter.ratio is not None
        out[model] = (result.scatter.ratio, result.scatter.limit, result.warnings)
    return out


CONFIGS = {"paper": {}, "small": SMALL}
"""Paper-sized campaigns (4 x 200 SPATs, 7 bar placements, 40 readouts per socket) and the small
one (4 x 50 SPATs, 2 placements, 5 per socket), both with DH and encoder errors."""


@pytest.mark.parametrize(("config", "seed"), [
    ("paper", 0), ("small", 0), ("small", 1),
    *(pytest.param("paper", s, marks=pytest.mark.slow) for s in range(1, 10)),
    *(pytest.param("small", s, marks=pytest.mark.slow) for s in range(2, 10))])
def test_clean_socket_scatter_is_within_the_limit(arm: ap.Arm, config: str, seed: int) -> None:
    """Clean simulated campaigns calibrated by either model and validated with their own accuracy:
    no scatter warning. Measured (bar_scatter.MODEL_ALLOWANCE), seeds 0-9: paper DH 1.02-1.23,
    proposed 0.44-0.55 (limit 2.65); small DH 0.72-1.21, proposed 1.01-2.42 (limit 3.38)."""
    sim = ap.simulate_campaign(arm, ap.SimulationConfig(seed=seed, **CONFIGS[config]))
    ratios = scatter_ratios(arm, sim.campaign)
    print(f"{config} seed {seed}: " + ", ".join(f"{m} ratio {r:.3f} (limit {lim:.3f})"
                                                for m, (r, lim, _) in ratios.items()))
    # only the scatter warning: the per-readout check flags a few readouts of clean proposed
    # calibrations (paper seeds 2 and 5: 124-155 um from their socket's median, limit 120-138
    # um, in sockets whose postures use encoder-map nodes the SPATs left undetermined)
    assert not any(CAUSES in w for _, _, warnings in ratios.values() for w in warnings)


@pytest.mark.skipif(not SAMPLE.is_dir(), reason="shared sample campaign not beside the project")
def test_sample_campaign_socket_scatter_is_within_the_limit(arm: ap.Arm) -> None:
    """The independent sample campaign: its own DH and proposed calibrations raise no warning
    (ratios 1.14 and 0.42, limit 2.72), and its truth moves the stylus centre by nothing while it
    sits in a socket."""
    campaign = ap.read_campaign(SAMPLE, arm=arm)
    ratios = scatter_ratios(arm, campaign)
    print("sample: " + ", ".join(f"{m} ratio {r:.3f} (limit {lim:.3f})"
                                 for m, (r, lim, _) in ratios.items()))
    assert all(warnings == () for _, _, warnings in ratios.values())
    truth = ap.validate(arm, ap.read_parameters(SAMPLE / "truth.json"), campaign, 2e-6)
    assert truth.warnings == () and truth.scatter is not None and truth.scatter.scatter < 1e-9


@pytest.mark.parametrize("axis", [7, 6])
def test_a_readout_column_in_radians_is_flagged(arm: ap.Arm, small_sim: ap.Simulation,
                                                small_cal: ap.Calibration, axis: int) -> None:
    """A lengthbar.csv column given in radians (values x pi/180): A7 moves the stylus centre only
    by the tool's off-axis offset (no readout is far from its socket), A6 by centimetres; both
    scatter far beyond the calibration's accuracy."""
    log = small_sim.campaign.lengthbar
    assert log is not None
    q = log.q.copy()
    q[:, axis - 1] *= np.pi / 180
    result = ap.validate(arm, small_cal.parameters,
                         replace(small_sim.campaign, lengthbar=replace(log, q=q)), small_cal.accuracy)
    scatter = [w for w in result.warnings if CAUSES in w]
    assert len(scatter) == 1 and "times the" in scatter[0]
    assert result.scatter is not None and result.scatter.ratio is not None
    assert result.scatter.ratio > 3 * result.scatter.limit
    if axis == 7:
        assert result.warnings == tuple(scatter)


def test_cli_validate_compares_the_scatter_with_report_json(small_sim: ap.Simulation,
                                                            small_cal: ap.Calibration,
                                                            tmp_path: Path, capsys) -> None:
    """aacmm-pin validate reads the accuracy from report.json: q7 in radians -> a warning (printed
    and in the JSON); without report.json it says once that the scatter is not compared."""
    arm = ap.load_arm()
    ap.write_campaign(small_sim.campaign, tmp_path / "camp")
    ap.write_calibration(small_cal, arm, tmp_path / "cal")
    assert read_calibration(tmp_path / "cal" / "parameters.json").accuracy == pytest.approx(
        small_cal.accuracy)
    (tmp_path / "cal" / "parameters.json").rename(tmp_path / "cal" / "other.json")
    assert read_calibration(tmp_path / "cal" / "other.json").accuracy is None  # not the neighbour's
    (tmp_path / "cal" / "other.json").rename(tmp_path / "cal" / "parameters.json")
    header = (tmp_path / "camp" / "lengthbar.csv").read_text().splitlines()[0].split(",")
    fuzz.scale_column(tmp_path / "camp" / "lengthbar.csv", header.index("q7_deg"), np.pi / 180)
    out = tmp_path / "v.json"
    assert main(["validate", str(tmp_path / "cal"), str(tmp_path / "camp"), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "WARNING: lengthbar.csv: the readouts scatter" in printed and CAUSES in printed
    data = json.loads(out.read_text())
    assert data["socket_scatter"]["ratio"] > data["socket_scatter"]["limit"]
    assert any(CAUSES in w for w in data["warnings"])
    (tmp_path / "cal" / "report.json").unlink()
    assert main(["validate", str(tmp_path / "cal"), str(tmp_path / "camp"), "--json", str(out),
                 "--force"]) == 0  # the file of the run above: replaced only when asked
    printed = capsys.readouterr().out
    assert printed.count("not compared with the calibration's accuracy") == 1
    assert CAUSES not in printed and json.loads(out.read_text())["socket_scatter"]["ratio"] is None


def test_cli_validate_says_when_the_bar_was_an_input_of_the_fit(small_sim: ap.Simulation,
                                                               tmp_path: Path, capsys) -> None:
    """A calibration fitted with the bar (--use-bar): validate says its test is not independent."""
    arm = ap.load_arm()
    ap.write_campaign(small_sim.campaign, tmp_path / "camp")
    for use_bar in (False, True):
        cal = ap.identify(small_sim.campaign, arm, "dh", use_bar=use_bar)
        ap.write_calibration(cal, arm, tmp_path / f"cal{use_bar}")
        out = tmp_path / f"v{use_bar}.json"
        assert main(["validate", str(tmp_path / f"cal{use_bar}"), str(tmp_path / "camp"),
                     "--json", str(out)]) == 0
        noted = "not an independent test" in capsys.readouterr().out
        assert noted == use_bar and ("note" in json.loads(out.read_text())) == use_bar


def test_far_readouts_are_a_few_lines_and_a_count(arm: ap.Arm, small_sim: ap.Simulation,
                                                  small_cal: ap.Calibration) -> None:
    """Every bar readout far from its socket (A2 and A3 swapped): a few lines and one count, not
    one line per readout (303 lines for the sample campaign against another arm's calibration)."""
    from aacmm_pin.data.problem_log import MAX_LIKE

    log = small_sim.campaign.lengthbar
    assert log is not None
    q = log.q.copy()
    q[:, [1, 2]] = q[:, [2, 1]]
    result = ap.validate(arm, small_cal.parameters,
                         replace(small_sim.campaign, lengthbar=replace(log, q=q)))
    far = [w for w in result.warnings if w.startswith("lengthbar.csv line")]
    assert len(far) == MAX_LIKE + 1 and "more readouts like it" in far[-1], far
