"""Tests of aacmm_pin.analyses.iso10360: sphere fit (NIST pairs), point articulation, P_Size/P_Form, L_Dia,
E_UNI, each against a hand-computed case, and the iso10360 subcommands."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from aacmm_pin.analyses import iso10360 as iso
from aacmm_pin.cli.iso10360 import add_parsers
from aacmm_pin.errors import FileFormatError

NIST = Path(__file__).resolve().parents[2] / "shared" / "nist-l2-reference-pairs" / "Sphere"
SAMPLE = Path(__file__).resolve().parents[2] / "shared" / "sample-campaign"
PAIRS = sorted(NIST.glob("*.ds")) if NIST.is_dir() else []


def run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser()
    add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.handler(args)


@pytest.mark.skipif(not PAIRS, reason="NIST reference pairs not found beside the project")
@pytest.mark.parametrize("data", PAIRS, ids=[p.stem for p in PAIRS])
def test_sphere_fit_reproduces_nist_reference(data):
    """The least-squares sphere matches NIST's reference centre and diameter to 1e-6."""
    lines = data.read_text().split("\n")
    n = int(lines[0])
    points = np.array([[float(v) for v in line.split()] for line in lines[1:n + 1]])
    reference = np.array([float(v) for v in data.with_suffix(".fit").read_text().split()])
    fit = iso.fit_sphere(points)
    assert fit.success
    np.testing.assert_allclose(fit.centre, reference[:3], rtol=0, atol=1e-6)
    assert abs(fit.diameter - reference[3]) < 1e-6


def test_sphere_fit_exact_points_any_origin_and_unit():
    """Points exactly on a sphere give its centre and radius, whatever the origin and unit."""
    rng = np.random.default_rng(1)
    u = rng.normal(size=(25, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u[:, 2] = np.abs(u[:, 2])  # a hemisphere, as probed
    for centre, radius in (([0.0, 0.0, 0.0], 1.0), ([512.3, -20.0, 1e3], 12.7e-3)):
        fit = iso.fit_sphere(np.array(centre) + radius * u)
        np.testing.assert_allclose(fit.centre, centre, rtol=0, atol=1e-12 * max(1.0, radius))
        assert fit.radius == pytest.approx(radius, rel=1e-12)
        assert np.abs(fit.fun).max() < 1e-12 * max(1.0, radius) * 1e3
    with pytest.raises(ValueError, match="4 or more"):
        iso.fit_sphere(u[:3])


def test_point_articulation_hand_case():
    """Max deviation, ranges and 2-sigma of four centres, computed by hand."""
    um = 1e-6
    p = np.array([[1, 0, 0], [-1, 0, 0], [0, 2, 0], [0, -2, 0]]) * um + [0.5, 0.2, -0.1]
    r = iso.point_articulation(p)
    np.testing.assert_allclose(r.mean, [0.5, 0.2, -0.1], atol=1e-15)
    assert r.max_deviation == pytest.approx(2 * um)
    np.testing.assert_allclose(r.ranges, [2 * um, 4 * um, 0], atol=1e-15)
    assert r.two_sigma == pytest.approx(2 * np.sqrt((1 + 1 + 4 + 4) / 3) * um)
    assert r.to_dict()["range_um"]["y"] == pytest.approx(4.0)


def test_probing_errors_hand_case():
    """P_Size and P_Form of six points whose least-squares sphere is known by symmetry."""
    radius, e, d_cal = 10e-3, 3e-6, 20.001e-3
    # antipodal pairs on x, y, z at radial distances R+e, R-e, R: the residuals sum to zero and
    # cancel in every direction, so the centre is 0 and the radius R.
    p = np.array([[1, 0, 0], [-1, 0, 0]]) * (radius + e)
    p = np.vstack([p, np.array([[0, 1, 0], [0, -1, 0]]) * (radius - e),
                   np.array([[0, 0, 1], [0, 0, -1]]) * radius]) + [0.3, 0.1, 0.0]
    r = iso.probing_errors(p, d_cal)
    np.testing.assert_allclose(r.fit.centre, [0.3, 0.1, 0.0], atol=1e-15)
    assert r.p_size == pytest.approx(2 * radius - d_cal, abs=1e-15)
    assert r.p_form == pytest.approx(2 * e, abs=1e-15)


def test_probing_errors_25_points():
    """On 25 points with residuals orthogonal to (1, u_i), the fit is exact and P_Form = max - min."""
    rng = np.random.default_rng(2)
    u = rng.normal(size=(25, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u[:, 2] = np.abs(u[:, 2])
    a = np.column_stack([np.ones(25), u])  # the fit's stationarity conditions
    e = rng.normal(0, 1e-6, 25)
    e -= a @ np.linalg.lstsq(a, e, rcond=None)[0]  # residuals that leave centre and radius alone
    radius = 12.5e-3
    r = iso.probing_errors((radius + e)[:, None] * u, 25.0e-3)
    assert r.p_size == pytest.approx(2 * radius - 25.0e-3, abs=1e-13)
    assert r.p_form == pytest.approx(e.max() - e.min(), abs=1e-13)


def test_min_enclosing_sphere_hand_cases():
    """Smallest enclosing spheres of hand-solvable point sets."""
    c, r = iso.min_enclosing_sphere([[0, 0, 0], [2, 0, 0]])
    np.testing.assert_allclose(c, [1, 0, 0])
    assert r == pytest.approx(1)
    c, r = iso.min_enclosing_sphere([[0, 0, 0], [2, 0, 0], [1, 0.1, 0]])  # obtuse: the long side
    assert r == pytest.approx(1)
    tri = [[1, 0, 0], [-0.5, np.sqrt(3) / 2, 0], [-0.5, -np.sqrt(3) / 2, 0]]  # equilateral
    c, r = iso.min_enclosing_sphere(tri)
    np.testing.assert_allclose(c, 0, atol=1e-15)
    assert r == pytest.approx(1)
    tetra = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    c, r = iso.min_enclosing_sphere(np.vstack([tetra, [[0.1, 0.2, 0.3]]]))  # plus an inside point
    np.testing.assert_allclose(c, 0, atol=1e-15)
    assert r == pytest.approx(np.sqrt(3))
    assert iso.min_enclosing_sphere([[5, 5, 5]])[1] == 0


def test_articulated_location_hand_case():
    """L_Dia of five articulations whose sphere centres span 2a (the enclosing diameter)."""
    a = 4e-6
    centres = np.array([[a, 0, 0], [-a, 0, 0], [0, a, 0], [0, -a, 0], [0, 0, 0.5 * a]]) + 0.4
    u = np.array([[0, 0, 1], [1, 0, 0.2], [-1, 0, 0.2], [0, 1, 0.2], [0, -1, 0.2]], float)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    points = np.vstack([c + 10e-3 * u for c in centres])  # 5 x 5 points, radius 10 mm
    r = iso.articulated_location(points)
    np.testing.assert_allclose(r.centres, centres, rtol=0, atol=1e-12)
    assert r.l_dia == pytest.approx(2 * a, rel=1e-6)
    groups = np.repeat([7, 3, 9, 1, 5], 5)
    assert iso.articulated_location(points, groups=groups).l_dia == pytest.approx(r.l_dia)
    with pytest.raises(ValueError, match="multiple of group_size"):
        iso.articulated_location(points[:-1])


def test_e_uni_hand_case():
    """E_UNI is the largest absolute length error, NaN (unmeasured) ignored."""
    assert iso.e_uni([[3e-6, -5e-6], [np.nan, 2e-6]]) == pytest.approx(5e-6)
    with pytest.raises(ValueError):
        iso.e_uni([np.nan])


@pytest.mark.skipif(not SAMPLE.is_dir(), reason="shared sample campaign not found")
def test_figures_on_the_sample_campaign_with_its_truth(tmp_path):
    """With the true parameters, SPAT deviations are R-Test noise and E_UNI matches validate."""
    from aacmm_pin.analyses.validation import validate
    from aacmm_pin.data.campaign import read_campaign
    from aacmm_pin.model.arm import load_arm
    from aacmm_pin.model.parameters import read_parameters

    arm, truth = load_arm(), read_parameters(SAMPLE / "truth.json")
    campaign = read_campaign(SAMPLE)
    centres = iso.spat_centres(arm, truth, campaign)
    for m, p in centres.items():
        r = iso.point_articulation(p)
        # centre - displacement = nest zero + R-Test noise: 2 sigma ~ 2 sqrt(3) x (1-4 um)
        assert 2 * np.sqrt(3) * 0.5e-6 < r.two_sigma < 2 * np.sqrt(3) * 4e-6, (m, r.two_sigma)
        np.testing.assert_allclose(r.mean, campaign.locations[m], atol=2e-5)
    raw = iso.point_articulation(iso.spat_centres(arm, truth, campaign, use_rtest=False)[1])
    assert raw.two_sigma > iso.point_articulation(centres[1]).two_sigma
    errors = iso.length_errors(arm, truth, campaign)
    assert errors.e_uni == pytest.approx(validate(arm, truth, campaign).max_abs)
    assert run(["iso10360", "euni", str(SAMPLE), "--params", str(SAMPLE / "truth.json"), "--json",
                str(tmp_path / "e.json")]) == 0
    assert json.loads((tmp_path / "e.json").read_text())["e_uni_um"] == pytest.approx(
        errors.e_uni * 1e6)
    assert run(["iso10360", "spat", str(SAMPLE), "--params", str(SAMPLE / "truth.json"),
                "--json", str(tmp_path / "s.json")]) == 0
    saved = json.loads((tmp_path / "s.json").read_text())["locations"]
    assert saved["1"]["two_sigma_um"] == pytest.approx(iso.point_articulation(
        centres[1]).two_sigma * 1e6)


def test_sphere_and_ldia_subcommands(tmp_path, capsys):
    """iso10360 sphere and ldia read points in mm and report P_Size, P_Form and L_Dia."""
    p = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]) * 10.0
    csv = tmp_path / "points.csv"
    csv.write_text("x_mm,y_mm,z_mm\n" + "".join(f"{x},{y},{z}\n" for x, y, z in p))
    assert run(["iso10360", "sphere", str(csv), "--diameter-mm", "19.998", "--json",
                str(tmp_path / "p.json")]) == 0
    out = json.loads((tmp_path / "p.json").read_text())
    assert out["p_size_um"] == pytest.approx(2.0, abs=1e-6) and out["p_form_um"] < 1e-6
    assert "P_Size +2.00 um" in capsys.readouterr().out
    groups = np.repeat([1, 2], 6)
    pts = np.vstack([p, p + [0.003, 0, 0]])  # second articulation 3 um away
    csv.write_text("group,x_mm,y_mm,z_mm\n" + "".join(
        f"{g},{x},{y},{z}\n" for g, (x, y, z) in zip(groups, pts)))
    assert run(["iso10360", "ldia", str(csv), "--json", str(tmp_path / "l.json")]) == 0
    assert json.loads((tmp_path / "l.json").read_text())["l_dia_um"] == pytest.approx(3.0)
    csv.write_text("x_mm,y_mm,z_mm\n1,2,abc\n")
    with pytest.raises(FileFormatError, match="line 2|:2"):
        iso.read_points(csv)


def test_read_points_is_bounded(tmp_path, monkeypatch):
    """A points file over the readers' size bound is refused before it is parsed, as a campaign's is."""
    csv = tmp_path / "points.csv"
    csv.write_text("x_mm,y_mm,z_mm\n" + "1,2,3\n" * 10)
    assert iso.read_points(csv)[0].shape == (10, 3)
    monkeypatch.setattr(iso, "MAX_FILE_BYTES", csv.stat().st_size - 1)
    with pytest.raises(FileFormatError, match="points.csv: larger than 0 MiB"):
        iso.read_points(csv)
    with pytest.raises(FileFormatError, match="No such file"):
        iso.read_points(tmp_path / "missing.csv")
