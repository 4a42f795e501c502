"""Nothing silently wrong (issue 39): inputs that were taken with a wrong meaning are refused or
named in one line, with the file, line, column, key or term that is wrong."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import aacmm_pin as ap
from aacmm_pin import cli

ROOT = Path(__file__).resolve().parents[1]
COUPLED = ROOT / "urdf" / "torso_coupled.urdf"


# ----------------------------------------------------------------------------- URDF <mimic>
def _with(tmp_path: Path, pattern: str, added: str) -> Path:
    """Return a copy of the coupled torso with ``added`` after the first match of ``pattern``."""
    text, n = re.subn(pattern, lambda m: m.group(0) + added, COUPLED.read_text(), count=1)
    assert n == 1
    path = tmp_path / "arm.urdf"
    path.write_text(text)
    return path


def test_a_second_mimic_in_one_joint_is_refused_with_its_line(tmp_path):
    """Two <mimic> in T4: the second was dropped without a word (T4 followed the first)."""
    path = _with(tmp_path, r'<joint name="T4" type="revolute">',
                 '\n    <mimic joint="T2" multiplier="-1.5"/>\n    <mimic joint="T3"/>')
    line = path.read_text().splitlines().index('    <mimic joint="T3"/>') + 1
    with pytest.raises(ap.ArmModelError, match=rf"arm\.urdf: line {line}: joint 'T4': a second "
                                               r"<mimic> \(the first is on line"):
        ap.load_arm(path)


def test_a_mimic_on_a_fixed_joint_is_refused_with_its_line(tmp_path):
    """A <mimic> on a fixed joint (no angle to follow another) was dropped without a word."""
    path = _with(tmp_path, r'<joint name="dx1" type="fixed">', '\n    <mimic joint="T2"/>')
    line = path.read_text().splitlines().index('    <mimic joint="T2"/>') + 1
    with pytest.raises(ap.ArmModelError, match=rf"arm\.urdf: line {line}: joint 'dx1': a <mimic> "
                                               "on a fixed joint"):
        ap.load_arm(path)


# ----------------------------------------------------------------------------- term keys and axes
@pytest.fixture(scope="module")
def ur5_points(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A simulated points campaign of the embedded UR5 (6 axes), 60 points."""
    out = tmp_path_factory.mktemp("ur5") / "pts"
    assert cli.main(["simulate", "--arm", "ur5", "--points", "60", "--effects", "dh",
                     str(out)]) == 0
    return out


@pytest.mark.parametrize("key, axis", [
    ("compliance[A7]", 7), ("lateral_compliance[A7]", 7), ("backlash[A8]", 8),
    ("encoder_harmonic[A9]", 9), ("encoder_harmonic5[A7]", 7), ("crosstalk[A2<-A9]", 9),
    ("crosstalk[A7<-A2]", 7), ("compliance[A0]", 0)])
def test_a_term_beyond_the_arms_axes_is_one_line(tmp_path, capsys, ur5_points, key, axis):
    """`--terms` on an axis the 6-axis UR5 lacks: an IndexError's traceback (or numpy's matmul
    message for A0) before; now exit 2 and one line naming the option, the term and the axes."""
    status = cli.main(["identify", str(ur5_points), "--arm", "ur5", "--terms", key,
                       "--out", str(tmp_path / "cal")])
    err = capsys.readouterr().err.strip()
    assert status == 2
    assert err == (f"aacmm-pin identify: error: --terms: {key!r} acts on axis {axis}; the arm "
                   "ur5 has 6 axes, A1..A6")
    assert not (tmp_path / "cal").exists()
