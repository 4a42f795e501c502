"""identify with the length bar as an input (--use-bar): each kind of samples judged by its own scale.

A simulated bar seats its stylus exactly (its residual, 0.3 um, is the model's own error) while its
stated noise is 2 um: one robust scale pooled over SPATs and bar readouts flagged 320-367 of 800
clean SPATs as suspects, and the robust fit rejected all of them. Each kind now has its own scale
(never below its stated noise), and a kind that disagrees as a whole refuses the robust fit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.cli import main
from aacmm_pin.data.campaign import Campaign, write_campaign


def corrupt_readings(campaign: Campaign, seed: int, n: int = 8, size: float = 50e-6
                     ) -> tuple[Campaign, np.ndarray]:
    """Return the campaign with one R-Test coordinate of ``n`` SPAT rows ``size`` m off, and the rows.

    50 um is 25 times the R-Test noise: an outlier beyond doubt that does not drag the
    least-squares fit (1 mm does: the bar readouts then follow the dragged model).
    """
    spat = campaign.spat
    assert spat is not None
    rng = np.random.default_rng(2000 + seed)
    rows = np.sort(rng.choice(len(spat.q), n, replace=False))
    disp = spat.displacement.copy()
    disp[rows, rng.integers(0, 3, n)] += size * rng.choice([-1.0, 1.0], n)
    return campaign.with_spat(displacement=disp), rows


def check_clean_and_corrupted(arm: ap.Arm, campaign: Campaign, seed: int) -> None:
    """A clean campaign: no suspect, nests estimated, robust rejects nothing; 8 SPAT rows 50 um
    off in an R-Test reading: exactly those suspects, exactly those rejected."""
    plain = ap.identify(campaign, arm, "proposed", use_bar=True)
    assert plain.success, plain.message
    assert plain.suspects == (), [(o.file, o.row, o.sigmas) for o in plain.suspects]
    assert plain.nests.startswith("estimated"), plain.nests
    robust = ap.identify(campaign, arm, "proposed", use_bar=True, robust=True)
    assert robust.success and robust.outliers == (), robust.message
    bad, rows = corrupt_readings(campaign, seed)
    assert len(rows) == 8
    plain = ap.identify(bad, arm, "proposed", use_bar=True)
    assert sorted((o.file, o.row) for o in plain.suspects) == [("spat.csv", int(r)) for r in rows]
    robust = ap.identify(bad, arm, "proposed", use_bar=True, robust=True)
    assert robust.success, robust.message
    assert sorted((o.file, o.row) for o in robust.outliers) == [("spat.csv", int(r)) for r in rows]


def test_use_bar_flags_no_clean_sample_and_exactly_the_corrupted_ones(
        arm: ap.Arm, paper_sim: ap.Simulation) -> None:
    """Seed 0's paper campaign with its bar as an input: 0 suspects clean, the 8 corrupted exactly."""
    check_clean_and_corrupted(arm, paper_sim.campaign, 0)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_use_bar_over_seeds(arm: ap.Arm, seed: int) -> None:
    """The same on the paper campaigns of seeds 1-4 (with seed 0: five clean campaigns)."""
    check_clean_and_corrupted(arm, ap.simulate_campaign(arm, ap.SimulationConfig(seed=seed)).campaign,
                              seed)


def test_robust_fit_refuses_to_reject_a_whole_kind(arm: ap.Arm, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """Bar sockets that scatter 30 um (stated 2 um) beside clean SPATs: the robust fit exits 1
    with one line naming the length-bar readouts, instead of rejecting them or the SPATs."""
    sim = ap.simulate_campaign(arm, ap.SimulationConfig(seed=0, sigma_socket=30e-6,
                                                        samples_per_location=100,
                                                        samples_per_socket=10))
    write_campaign(sim.campaign, tmp_path / "campaign")
    capsys.readouterr()
    assert main(["identify", str(tmp_path / "campaign"), "--use-bar", "--robust", "--out",
                 str(tmp_path / "cal")]) == 1
    refused = [line for line in capsys.readouterr().out.splitlines()
               if "robust fit refused" in line]
    assert len(refused) == 1, refused
    assert refused[0].lstrip().startswith("robust fit refused: the length-bar readouts "
                                          "(lengthbar.csv, 210 samples) scatter")
    ratio = float(refused[0].split(" scatter ")[1].split(" times")[0])
    assert ratio > 5, refused[0]
    assert np.isfinite(ratio)
