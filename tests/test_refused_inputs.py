"""Nothing silently wrong (issue 39): inputs that were taken with a wrong meaning are refused or
named in one line, with the file, line, column, key or term that is wrong."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import aacmm_pin as ap
from aacmm_pin import cli
from aacmm_pin.errors import CampaignWarning

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


# ----------------------------------------------------------------------------- misspelt columns
def _with_column(source: Path, folder: Path, name: str, cells: list[str] | str) -> Path:
    """Copy the points campaign ``source`` into ``folder`` with one more column of points.csv."""
    folder.mkdir()
    rows = (source / "points.csv").read_text().splitlines()
    cells = [cells] * (len(rows) - 1) if isinstance(cells, str) else cells
    (folder / "points.csv").write_text("\n".join(
        [f"{rows[0]},{name}", *(f"{r},{c}" for r, c in zip(rows[1:], cells))]) + "\n")
    return folder


@pytest.mark.parametrize("name, meant, value", [
    ("sigma_mm", "sigma_um", "0.035"), ("sigma", "sigma_um", "35"), ("Sigma_um", "sigma_um", "35"),
    ("sigam_um", "sigma_um", "35"), ("tmp_c", "temp_c", "23.5"), ("temp", "temp_c", "23.5")])
def test_a_misspelt_column_is_refused_naming_the_one_meant(tmp_path, ur5_points, name, meant,
                                                            value):
    """A name close to a column the package reads (case, unit suffix, a letter off) was carried
    as an unknown column while the defaults stood in for the one meant (35 um points judged at
    20 um, a temperature the thermal effect never saw): now the file, column and name meant."""
    folder = _with_column(ur5_points, tmp_path / "c", name, value)
    with pytest.raises(ap.CampaignFormatError) as caught:
        ap.read_campaign(folder, arm=ap.load_arm("ur5"))
    assert str(caught.value).splitlines()[1] == (
        f"  {folder / 'points.csv'}:1: column '{name}': close to '{meant}' "
        f"({ap.data.columns.column(meant).description}, in "
        f"{ap.data.columns.column(meant).unit}), which is read; this one would be carried unused: "
        f"rename it '{meant}', or a column of its own another name")


def test_a_numbered_or_own_column_is_carried_with_one_note(tmp_path, ur5_points, recwarn):
    """`temp2_c` (a second sensor) and `humidity_pct` are not misspellings: carried, named once
    for the file as used by no effect."""
    import aacmm_pin.effects.registry  # noqa: F401  (the readers learn the effects' columns)

    folder = _with_column(ur5_points, tmp_path / "c", "temp2_c", "21.0")
    rows = (folder / "points.csv").read_text().splitlines()
    (folder / "points.csv").write_text("\n".join([rows[0] + ",humidity_pct",
                                                  *(r + ",40" for r in rows[1:])]) + "\n")
    campaign = ap.read_campaign(folder, arm=ap.load_arm("ur5"))
    assert set(campaign.points.columns) == {"temp2_c", "humidity_pct"}
    notes = [str(w.message) for w in recwarn if issubclass(w.category, CampaignWarning)]
    assert notes == [f"{folder / 'points.csv'}: columns 'temp2_c', 'humidity_pct' carried, not used "
                     "by any effect (discover tests it as a variable; an effect that reads it "
                     "uses it)"]


def test_a_column_an_effect_reads_is_not_noted(tmp_path, ur5_points, recwarn, monkeypatch):
    """A plugin's effect that reads `humidity_pct` (Effect.reads) uses it: no note; a name one
    letter off it is then refused as its misspelling."""
    from aacmm_pin.effects import registry
    from aacmm_pin.effects.builtin.thermal import Thermal

    class Humidity(Thermal):
        name = "humidity"
        reads = ("humidity_pct",)

    monkeypatch.setitem(registry.LIBRARY, "humidity", Humidity())
    folder = _with_column(ur5_points, tmp_path / "c", "humidity_pct", "40")
    ap.read_campaign(folder, arm=ap.load_arm("ur5"))
    assert not [w for w in recwarn if issubclass(w.category, CampaignWarning)]
    folder = _with_column(ur5_points, tmp_path / "d", "humidty_pct", "40")
    with pytest.raises(ap.CampaignFormatError, match="column 'humidty_pct': close to "
                                                     "'humidity_pct'"):
        ap.read_campaign(folder, arm=ap.load_arm("ur5"))


def test_a_misspelt_column_of_a_readouts_file_is_refused(tmp_path, ur5_points):
    """predict's input: `tmp_c` was carried, the thermal term evaluated at 20 deg C."""
    folder = _with_column(ur5_points, tmp_path / "c", "tmp_c", "30")
    with pytest.raises(ap.CampaignFormatError, match="column 'tmp_c': close to 'temp_c'"):
        ap.read_readouts(folder / "points.csv", ap.load_arm("ur5"))


# ----------------------------------------------------------------------------- misspelt JSON keys
def test_a_misspelt_campaign_json_key_is_refused(tmp_path, ur5_points):
    """{"instrumnet": "motion capture"} was ignored: points judged at 20 um instead of 100 um."""
    folder = tmp_path / "c"
    folder.mkdir()
    (folder / "points.csv").write_text((ur5_points / "points.csv").read_text())
    (folder / "campaign.json").write_text('{"instrumnet": "motion capture", "noise_um": '
                                          '{"Point": 90}, "notes": "lab 2"}')
    with pytest.raises(ap.CampaignFormatError) as caught:
        ap.read_campaign(folder)
    path = folder / "campaign.json"
    keys = "instrument, noise_um, provenance"
    assert str(caught.value).splitlines()[1:] == [
        f"  {path}: column 'instrumnet': unknown key; did you mean 'instrument'? (the keys: {keys})",
        f"  {path}: column 'notes': unknown key (the keys: {keys})",
        f"  {path}: column 'noise_um.Point': unknown key; did you mean 'point'? (the keys: rtest, "
        "location, point, socket)"]


def test_a_misspelt_parameters_json_key_is_refused(tmp_path):
    """"extenions" was carried as an unknown key and the extensions left out of every prediction;
    keys of one's own (not close to one the package reads) are still carried."""
    import json

    from aacmm_pin.model.parameters import read_parameters

    params = ap.Parameters.nominal(ap.load_arm("ur5")).to_dict()
    (tmp_path / "own.json").write_text(json.dumps({**params, "operator": "J. Doe"}))
    assert read_parameters(tmp_path / "own.json").extra == {"operator": "J. Doe"}
    (tmp_path / "p.json").write_text(json.dumps({**params, "extenions": {"thermal": [1e-6]}}))
    with pytest.raises(ap.FileFormatError, match=r"p\.json: column 'extenions': unknown key; did "
                                                 r"you mean 'extensions'\?"):
        read_parameters(tmp_path / "p.json")


def test_a_misspelt_nest_file_key_is_named(tmp_path):
    """{"direction": ...}: the key meant is named (was: "three finite 3-vectors expected")."""
    from aacmm_pin.acquire.nest import read_nest

    (tmp_path / "nest.json").write_text('{"direction": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}')
    with pytest.raises(ap.FileFormatError, match="column 'direction': unknown key; did you mean "
                                                 "'directions'"):
        read_nest(tmp_path / "nest.json")


# ----------------------------------------------------------------------------- stated noise
@pytest.mark.parametrize("sigma_um", [1e5, 1e4])
def test_a_noise_stated_far_above_the_residual_fails_with_numbers(arm, small_sim, sigma_um):
    """sigma 100 mm (or 10 mm): "-3 parameters determined" (held rows counted twice) and
    "residual matches the stated noise" with success true; now the determined count is the held
    rows' rank (never below 0) and the fit fails naming both noises."""
    cal = ap.identify(small_sim.campaign, arm, model="dh", sigma=sigma_um * 1e-6)
    assert 0 <= cal.n_determined <= len(cal.unknowns.names)
    assert not cal.success
    found = re.search(re.escape(f"the stated noise {sigma_um:.4g} um is ") + r"([\d.e+]+) x the "
                      r"residual's noise \(([\d.e+]+) um over (\d+) degrees of freedom\)",
                      cal.message)
    assert found is not None, cal.message
    ratio, estimate = float(found.group(1)), float(found.group(2))
    assert ratio > 10 and ratio * estimate == pytest.approx(sigma_um, rel=0.01)


def test_a_noise_stated_near_the_residual_is_judged_as_before(arm, small_sim):
    """30 um stated where the DH model leaves about 28 um: no such failure."""
    cal = ap.identify(small_sim.campaign, arm, model="dh", sigma=30e-6)
    assert "x the residual's noise" not in cal.message


# ----------------------------------------------------------------------------- a source twice
@pytest.mark.parametrize("how", ["same file", "same content"])
def test_a_source_imported_twice_is_refused(tmp_path, capsys, ur5_points, how):
    """import-points A A (or A and a copy of it): two instrument set-ups of the same points,
    the uncertainties shrunk to 0.71 x; now exit 2 and one line naming both."""
    rows = (ur5_points / "points.csv").read_text().splitlines()
    source = tmp_path / "tracker.csv"
    source.write_text("\n".join(rows[0].split(",", 1)[1:] + [r.split(",", 1)[1] for r in rows[1:]])
                      + "\n")
    second = source if how == "same file" else tmp_path / "copy.csv"
    second.write_bytes(source.read_bytes())
    status = cli.main(["import-points", str(source), str(tmp_path / "." / second.name),
                       "--joints", "q1_deg..q6_deg", "--point", "x_mm,y_mm,z_mm",
                       "--out", str(tmp_path / "c")])
    err = capsys.readouterr().err.strip()
    assert status == 2 and len(err.splitlines()) == 1, err
    assert f"is the {how} as {source}: imported twice" in err
    assert not (tmp_path / "c").exists()


def test_a_campaign_files_own_columns_are_not_called_carried(recwarn):
    """A readouts file cut from a campaign (lengthbar.csv, points.csv given to predict) carries its
    placement, socket and group columns without a note: they are the campaign's, not unknowns."""
    import aacmm_pin as ap
    from aacmm_pin.data.campaign import read_sample_columns
    from tests.helpers import SHARED

    bar = SHARED / "sample-campaign" / "lengthbar.csv"
    if not bar.is_file():
        pytest.skip("needs ../shared/sample-campaign")
    read_sample_columns(bar, ap.load_arm())
    assert not [w for w in recwarn if "carried" in str(w.message)]
