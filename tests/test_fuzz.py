"""Fuzz: hundreds of seeded mutations of a campaign and of a calibration folder (issue 14).

Each mutation is run in-process the way a user runs the files (``tests/fuzz.py``) and must end
in a message (AacmmError or ValueError), the clean result, or a result the API flags; never a
traceback-type exception, a hang, or a silently different result. Meaning-preserving mutations
(CRLF, BOM, column order, layout) must give the clean result. The default run does a few hundred
mutations; ``-m slow`` runs many more seeds.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pytest

import aacmm_pin as ap
from tests import fuzz

CONFIG = {"samples_per_location": 40, "samples_per_socket": 5, "bar_placements": 2,
          "effects": ("dh", "rtest")}
"""A small campaign whose arm the DH model describes exactly: its clean fit flags nothing."""


class Clean(NamedTuple):
    """The clean folders (under ``root``) and their results."""

    root: Path
    errors: dict[Any, float]
    unidentifiable: list[str]
    campaign: ap.Campaign
    points: np.ndarray


@pytest.fixture(scope="module")
def clean(arm: ap.Arm, tmp_path_factory: pytest.TempPathFactory) -> Clean:
    """The clean campaign folder, its calibration folder and their results."""
    root = tmp_path_factory.mktemp("fuzz")
    sim = ap.simulate_campaign(arm, ap.SimulationConfig(seed=0, **CONFIG))  # type: ignore[arg-type]
    ap.write_campaign(sim.campaign, root / "campaign")
    cal, result = fuzz.run_campaign(root / "campaign", arm)
    assert cal.success and not cal.suspects and not cal.outliers and not result.warnings
    errors = fuzz.bar_errors(result)
    ap.write_calibration(cal, arm, root / "calibration")
    campaign = ap.read_campaign(root / "campaign", arm=arm)
    points, _ = fuzz.run_calibration(root / "calibration", campaign)
    return Clean(root, errors, cal.unidentifiable, campaign, points)


def fuzz_campaign(arm: ap.Arm, clean: Clean, seed: int, n: int) -> Counter[str]:
    """Run ``n`` mutations of the campaign; return the verdict counts; fail on any FAIL."""
    rng = np.random.default_rng(seed)
    root = clean.root
    verdicts: Counter[str] = Counter()
    failures = []
    for i in range(n):
        same = rng.random() < 0.15
        pool = fuzz.SAME if same else fuzz.OTHER
        folder = fuzz.copy_folder(root / "campaign", root / "mutated")
        labels = [pool[int(rng.integers(len(pool)))](folder, rng)]
        if not same and rng.random() < 0.2:  # sometimes two at once
            try:
                labels.append(pool[int(rng.integers(len(pool)))](folder, rng))
            except (OSError, IndexError, UnicodeDecodeError, ValueError):
                pass  # the first mutation left nothing to mutate (a file deleted, binary)
        verdict, detail = fuzz.judge_campaign(folder, arm, clean.errors, same,
                                              clean.unidentifiable)
        verdicts[verdict] += 1
        if verdict == "FAIL":
            failures.append(f"#{i} {' + '.join(labels)}: {detail}")
    assert not failures, "\n".join(failures)
    return verdicts


def fuzz_calibration(clean: Clean, seed: int, n: int) -> Counter[str]:
    """Run ``n`` mutations of the calibration folder; return the verdict counts."""
    rng = np.random.default_rng(seed)
    root = clean.root
    verdicts: Counter[str] = Counter()
    failures = []
    for i in range(n):
        u = rng.random()
        kind, pool = (("same", (fuzz.c_same,)) if u < 0.15 else
                      ("changed", (fuzz.c_value_change,)) if u < 0.2 else ("other", fuzz.C_OTHER))
        folder = fuzz.copy_folder(root / "calibration", root / "mutated_cal")
        label = pool[int(rng.integers(len(pool)))](folder, rng)
        verdict, detail = fuzz.judge_calibration(folder, clean.campaign, clean.points, kind)
        verdicts[verdict] += 1
        if verdict == "FAIL":
            failures.append(f"#{i} {label}: {detail}")
    assert not failures, "\n".join(failures)
    return verdicts


def test_fuzz_campaign(arm: ap.Arm, clean: Clean) -> None:
    verdicts = fuzz_campaign(arm, clean, seed=14, n=250)  # 5 x 400 more in the slow run
    print(f"campaign, seed 14: {dict(verdicts)}")
    assert verdicts["refused"] > 100 and verdicts["same"] > 40  # the mix is exercised


def test_fuzz_calibration(clean: Clean) -> None:
    verdicts = fuzz_calibration(clean, seed=14, n=400)
    print(f"calibration, seed 14: {dict(verdicts)}")
    assert verdicts["refused"] > 160 and verdicts["same"] > 40


@pytest.mark.parametrize("factor", [np.pi / 180, 180 / np.pi])
def test_the_stylus_axis_in_other_units_is_not_silent(arm: ap.Arm, clean: Clean,
                                                       factor: float) -> None:
    """The former known gap: lengthbar.csv's q7_deg column x pi/180 moves the bar errors by ~60 um
    with plausible readouts; the socket scatter against the fit RMS flags it (x 180/pi: refused)."""
    folder = fuzz.copy_folder(clean.root / "campaign", clean.root / "mutated")
    header = (folder / "lengthbar.csv").read_text().splitlines()[0].split(",")
    fuzz.scale_column(folder / "lengthbar.csv", header.index("q7_deg"), factor)
    verdict, detail = fuzz.judge_campaign(folder, arm, clean.errors, False, clean.unidentifiable)
    assert verdict == ("flagged" if factor < 1 else "refused"), detail


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(1, 6))
def test_fuzz_many_seeds(arm: ap.Arm, clean: Clean, seed: int) -> None:
    campaign = fuzz_campaign(arm, clean, seed=seed, n=400)
    calibration = fuzz_calibration(clean, seed=seed, n=400)
    print(f"seed {seed}: campaign {dict(campaign)}, calibration {dict(calibration)}")
