"""One arm-match check for every command that takes an arm and readouts (issue 26, item 5).

* Readout files with another number of axes than the arm's are refused by the reader with file,
  line (the header) and "in degrees", in every command: ``validate`` and ``predict`` said
  "readouts: need shape (N, 7) in rad, got (30, 6)", naming no file and the wrong unit.
* A URDF with a ``continuous`` joint (a revolute without limits) works in every command: it passed
  ``axes`` and ``identify`` and then failed in ``predict``, ``validate``, ``view``...
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.data.campaign import read_readouts
from aacmm_pin.errors import CampaignWarning
from tests.helpers import ROOT, run_cli


def _drop_column(src: Path, dst: Path, name: str) -> None:
    rows = list(csv.reader(src.open(newline="")))
    k = rows[0].index(name)
    with dst.open("w", newline="") as f:
        csv.writer(f, lineterminator="\n").writerows(r[:k] + r[k + 1:] for r in rows)


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory, small_sim: ap.Simulation) -> Path:
    """campaign/ (7 axes), six/ (its copy without q7_deg), q7.csv, q6.csv and cal/ (aacmm7)."""
    root = tmp_path_factory.mktemp("arm_match")
    ap.write_campaign(small_sim.campaign, root / "campaign")
    (root / "six").mkdir()
    for name in ("spat.csv", "locations.csv", "lengthbar.csv", "bar.csv"):
        src = root / "campaign" / name
        if name in ("spat.csv", "lengthbar.csv"):
            _drop_column(src, root / "six" / name, "q7_deg")
        else:
            (root / "six" / name).write_bytes(src.read_bytes())
    _drop_column(root / "campaign" / "lengthbar.csv", root / "q7.csv", "socket")
    _drop_column(root / "six" / "lengthbar.csv", root / "q6.csv", "socket")
    arm = ap.load_arm()
    ap.write_calibration(ap.identify(small_sim.campaign, arm, "dh"), arm, root / "cal")
    return root


def test_seven_columns_against_a_six_axis_arm_name_file_line_and_degrees(files: Path) -> None:
    """The issue's case: a 7-column readouts file read for the UR5 (6 axes)."""
    with pytest.raises(ap.AacmmError) as info:
        read_readouts(files / "q7.csv", ap.load_arm("ur5"))
    text = str(info.value)
    assert f"{files / 'q7.csv'}:1: column 'q7_deg': 7 readout columns in degrees" in text, text
    assert "the arm has 6 axes (q1_deg..q6_deg" in text and "rad" not in text


SIX = "six"
ARM_MATCH_COMMANDS = [
    ["identify", SIX, "--out", "x"], ["discover", SIX, "--out", "x"],
    ["uncertainty", SIX, "--out", "x"], ["plan", SIX], ["validate", "cal", SIX],
    ["predict", "cal", "q6.csv", "--out", "x.csv"], ["view", "cal", SIX, "--html", "x.html"],
    ["iso10360", "spat", "--params", "cal", SIX], ["iso10360", "euni", "--params", "cal", SIX],
    ["iso10360", "sphere", "--params", "cal", "q6.csv", "--diameter-mm", "25"],
    ["iso10360", "ldia", "--params", "cal", "q6.csv"],
]


@pytest.mark.parametrize("argv", ARM_MATCH_COMMANDS, ids=lambda a: " ".join(a[:2]))
def test_every_command_refuses_another_arms_readouts_alike(argv: list[str], files: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """Six readout columns for the 7-axis arm: the same message, file and line, in every command."""
    monkeypatch.chdir(files)
    status, err = run_cli(argv)
    assert status == 2, err
    first = "q6.csv" if "q6.csv" in argv else "six/spat.csv"
    assert f"{first}:1: 6 readout columns in degrees (q1_deg..q6_deg), but the arm has 7 axes" in err
    assert "Traceback" not in err and "in rad" not in err
    assert not (files / "x").exists()


@pytest.fixture(scope="module")
def continuous(files: Path, small_sim: ap.Simulation) -> Path:
    """aacmm7 with A7 a ``continuous`` joint (no limits): cont.urdf and its calibration ccal/."""
    text = (ROOT / "urdf" / "aacmm7.urdf").read_text()
    head, tail = text.split('<joint name="A7" type="revolute">', 1)
    limit = tail.index("<limit")
    tail = tail[:limit] + tail[tail.index("/>", limit) + 2:]
    (files / "cont.urdf").write_text(head + '<joint name="A7" type="continuous">' + tail)
    arm = ap.load_arm(files / "cont.urdf")
    ap.write_calibration(ap.identify(small_sim.campaign, arm, "dh"), arm, files / "ccal")
    return files


def test_a_continuous_joint_is_one_readout_in_every_model(continuous: Path) -> None:
    arm = ap.load_arm(continuous / "cont.urdf")
    assert arm.n_axes == 7 and arm.runtime_model().nq == 7
    assert np.allclose(np.degrees(arm.joint_limits[6]), [-180, 180])


@pytest.mark.parametrize("argv", [
    ["predict", "ccal", "q7.csv", "--out", "p.csv"], ["validate", "ccal", "campaign"],
    ["iso10360", "euni", "--params", "ccal", "campaign"],
    ["iso10360", "spat", "--params", "ccal", "campaign"],
    ["view", "ccal", "campaign", "--html", "v.html"],
], ids=lambda a: " ".join(a[:2]))
def test_a_continuous_joint_works_in_every_command(argv: list[str], continuous: Path,
                                                   tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """identify made ccal/ above; every command that reads a calibration works on it."""
    for name in ("ccal", "campaign", "q7.csv"):
        (tmp_path / name).symlink_to(continuous / name)
    monkeypatch.chdir(tmp_path)
    status, err = run_cli(argv)
    assert status == 0, err


def _swap_columns(src: Path, dst: Path, a: str, b: str, shift_deg: float = 0.0) -> None:
    rows = list(csv.reader(src.open(newline="")))
    i, j = rows[0].index(a), rows[0].index(b)
    for row in rows[1:]:
        row[i], row[j] = row[j], f"{float(row[i]) + shift_deg:.9f}"
    with dst.open("w", newline="") as f:
        csv.writer(f, lineterminator="\n").writerows(rows)


def test_readouts_beyond_the_arms_limits_are_one_warning(continuous: Path, tmp_path: Path) -> None:
    """q2_deg and q3_deg swapped in lengthbar.csv: A2 (limits -100..100 deg) reads up to 150 deg.

    One warning for the file, naming its first line beyond and the count; the campaign as written
    and the same readouts on an axis without stated limits (A7 continuous, +360 deg) give none.
    """
    import warnings

    from aacmm_pin.data.campaign import read_campaign

    files = continuous
    camp = tmp_path / "camp"
    camp.mkdir()
    for name in ("spat.csv", "locations.csv", "bar.csv", "lengthbar.csv"):
        (camp / name).write_bytes((files / "campaign" / name).read_bytes())
    arm = ap.load_arm()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # as written: within the limits, no warning
        read_campaign(camp, arm=arm)
    _swap_columns(files / "campaign" / "lengthbar.csv", camp / "lengthbar.csv", "q2_deg", "q3_deg")
    with pytest.warns(CampaignWarning) as caught:
        read_campaign(camp, arm=arm)
    text = [str(w.message) for w in caught if "limits" in str(w.message)]
    assert len(text) == 1 and "column 'q2_deg'" in text[0] and "A2's limits (-100..100 deg)" in text[0]
    assert "more readouts beyond" in text[0]
    # A7 one turn on, on the continuous A7 of cont.urdf: no stated limit, no warning
    _swap_columns(files / "campaign" / "lengthbar.csv", camp / "lengthbar.csv", "q7_deg", "q7_deg",
                  360.0)
    with pytest.warns(CampaignWarning, match="A7's limits"):
        read_campaign(camp, arm=arm)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_campaign(camp, arm=ap.load_arm(files / "cont.urdf"))
