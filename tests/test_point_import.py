"""``aacmm-pin import-points``: tracker and mocap CSV files to a points campaign (issue 26 item 7)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.data.campaign import read_campaign
from tests.helpers import SHARED, run_cli

DATA = SHARED / "real-data" / "jacobi2025-laser-tracker"
UR5_RANDOM = DATA / "UR5" / "3D_UR5_uncalibrated_random_cleaned.csv"
UR5_GRID = DATA / "UR5" / "3D_UR5_uncalibrated_grid_cleaned.csv"
ROUNDING_MM = 5e-10
"""Half the last of the 9 decimals points.csv is written with, mm (and deg)."""


def _poses(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Return n random UR5 joint readouts (N, 6) rad and their nominal tool points (N, 3) m."""
    arm = ap.load_arm("ur5")
    rng = np.random.default_rng(seed)
    q = rng.uniform(-np.pi, np.pi, (n, arm.n_axes))
    return q, ap.stylus_positions(arm, ap.Parameters.nominal(arm, 5.0), q, frame="mt")


def _write(path: Path, header: list[str], rows: list[list[object]]) -> Path:
    with path.open("w", newline="") as f:
        out = csv.writer(f)
        out.writerow(header)
        out.writerows(rows)
    return path


def _mocap(path: Path, n: int = 30, seed: int = 0) -> tuple[Path, np.ndarray, np.ndarray]:
    """Write a mocap-style file (pose id, a1..a6 in rad, X, Y, Z in m, a text column)."""
    q, p = _poses(n, seed)
    rows = [[f"pose{i}", *qi.tolist(), *pi.tolist(), "ok"] for i, (qi, pi) in enumerate(zip(q, p))]
    return _write(path, ["pose", *(f"a{k}" for k in range(1, 7)), "X", "Y", "Z", "status"],
                  rows), q, p


def test_columns_and_units_by_options(tmp_path: Path) -> None:
    """--joints/--point/--units/--angles: the campaign holds the file's values, converted to SI."""
    source, q, p = _mocap(tmp_path / "mocap.csv")
    out = tmp_path / "campaign"
    status, err = run_cli(["import-points", str(source), "--out", str(out), "--joints", "a1..a6",
                           "--point", "X,Y,Z", "--units", "m", "--angles", "rad",
                           "--sigma-um", "35"])
    assert status == 0, err
    campaign = read_campaign(out)
    assert campaign.points is not None
    np.testing.assert_allclose(campaign.points.q, q, rtol=0, atol=np.radians(ROUNDING_MM))
    np.testing.assert_allclose(campaign.points.point, p, rtol=0, atol=ROUNDING_MM * 1e-3)
    assert campaign.noise is not None and campaign.noise.point == pytest.approx(35e-6)
    provenance = json.loads((out / "campaign.json").read_text())["provenance"]
    assert provenance["files"][0]["file"] == "../mocap.csv"  # relative to the campaign folder
    assert provenance["files"][0]["rows"] == len(q)


def test_preset_recognised_from_header(tmp_path: Path) -> None:
    """The jacobi2025 header: measured point = commanded - dif, angles deg, mm, stated noise."""
    q, p = _poses(12, 1)
    dif = np.random.default_rng(2).normal(0.0, 2.0, p.shape)  # commanded - measured, mm
    commanded = p * 1e3 + dif
    rows = [[i, *commanded[i], *dif[i], *np.degrees(q[i])] for i in range(len(q))]
    header = ["step_order", "x_t", "y_t", "z_t", "x_dif", "y_dif", "z_dif",
              *(f"joint_{k}" for k in range(1, 7))]
    source = _write(tmp_path / "tracker.csv", header, rows)
    out = tmp_path / "campaign"
    assert run_cli(["import-points", str(source), "--out", str(out)]) == (0, "")
    campaign = read_campaign(out)
    assert campaign.points is not None
    np.testing.assert_allclose(campaign.points.point, p, rtol=0, atol=2 * ROUNDING_MM * 1e-3)
    assert campaign.noise is not None  # the preset states its tracker's accuracy


def test_shared_ur5_file_is_the_commanded_minus_deviation(tmp_path: Path) -> None:
    """The real UR5 test file (20 rows): each point is x_t - x_dif, read here independently."""
    if not UR5_RANDOM.is_file():
        pytest.skip("shared real data not present")
    out = tmp_path / "ur5_random"
    assert run_cli(["import-points", str(UR5_RANDOM), "--out", str(out)]) == (0, "")
    with UR5_RANDOM.open(newline="") as f:
        rows = list(csv.DictReader(f))
    expected = np.array([[float(r[f"{c}_t"]) - float(r[f"{c}_dif"]) for c in "xyz"] for r in rows])
    q = np.array([[float(r[f"joint_{k}"]) for k in range(1, 7)] for r in rows])
    points = read_campaign(out).points
    assert points is not None
    np.testing.assert_allclose(points.point * 1e3, expected, rtol=0, atol=2 * ROUNDING_MM)
    np.testing.assert_allclose(np.degrees(points.q), q, rtol=0, atol=2 * ROUNDING_MM)
    licence = json.loads((out / "campaign.json").read_text())["provenance"]["files"][0]
    assert "MIT" in licence["licence_file"]


def test_imported_folder_goes_to_identify(tmp_path: Path) -> None:
    """Round trip: an imported folder is read by identify as it is, and the fit finds the truth.

    Points of a UR5 with a 0.5 mm link error, 20 um tracker noise: identify's residual RMS is the
    noise (within its chi-square spread for a few hundred residuals), not the 0.5 mm error.
    """
    arm = ap.load_arm("ur5")
    nominal = ap.Parameters.nominal(arm, 5.0)
    truth = nominal.replace(dh={**nominal.dh, "dx2": nominal.dh["dx2"] + 5e-4})
    rng = np.random.default_rng(3)
    q = rng.uniform(-np.pi, np.pi, (80, 6))
    p = ap.stylus_positions(arm, truth, q, frame="mt") + rng.normal(0.0, 20e-6, (80, 3))
    rows = [[*np.degrees(qi), *(pi * 1e3)] for qi, pi in zip(q, p)]
    source = _write(tmp_path / "tracker.csv", [*(f"q{k}" for k in range(1, 7)), "x", "y", "z"],
                    rows)
    folder, cal = tmp_path / "campaign", tmp_path / "cal"
    assert run_cli(["import-points", str(source), "--out", str(folder), "--joints", "q1..q6",
                    "--point", "x,y,z", "--sigma-um", "20"]) == (0, "")
    status, err = run_cli(["identify", str(folder), "--arm", "ur5", "--model", "dh",
                           "--out", str(cal)])
    assert status == 0, err
    report = json.loads((cal / "report.json").read_text())
    assert report["fit_rms_um"] < 20 * 1.2  # 3 * 80 residuals: the RMS of pure noise is 20 um within ~10 %


def test_bad_cell_names_file_line_column(tmp_path: Path) -> None:
    """One bad cell: exit 2, one error naming the file, its line and column; nothing written."""
    source, _, _ = _mocap(tmp_path / "mocap.csv", n=8)
    lines = source.read_text().splitlines()
    cells = lines[3].split(",")
    cells[3] = "1,5".replace(",", ";")  # a decimal comma pasted from a spreadsheet
    lines[3] = ",".join(cells)
    source.write_text("\n".join(lines) + "\n")
    out = tmp_path / "campaign"
    status, err = run_cli(["import-points", str(source), "--out", str(out), "--joints", "a1..a6",
                           "--point", "X,Y,Z", "--units", "m", "--angles", "rad"])
    assert status == 2
    assert f"{source}:4: column 'a3': '1;5' is not a number" in err
    assert not out.exists()


def test_missing_column_says_what_it_likely_means(tmp_path: Path) -> None:
    source, _, _ = _mocap(tmp_path / "mocap.csv", n=4)
    status, err = run_cli(["import-points", str(source), "--out", str(tmp_path / "c"),
                           "--joints", "a1..a6", "--point", "x,Y,Z", "--units", "m",
                           "--angles", "rad"])
    assert status == 2
    assert f"{source}:1: column 'x': missing column; did you mean X?" in err


def test_wrong_units_are_named(tmp_path: Path) -> None:
    """Radians read as degrees, and lengths far beyond a workspace, are named with the option."""
    source, _, _ = _mocap(tmp_path / "mocap.csv", n=25)
    status, err = run_cli(["import-points", str(source), "--out", str(tmp_path / "c"),
                           "--joints", "a1..a6", "--point", "X,Y,Z", "--units", "m"])
    assert status == 2 and "look like radians (--angles rad;" in err
    # the same small angles with the unit stated: degrees of an arm that moves a few degrees only
    status, err = run_cli(["import-points", str(source), "--out", str(tmp_path / "small"),
                           "--joints", "a1..a6", "--point", "X,Y,Z", "--units", "m",
                           "--angles", "deg"])
    assert status == 0, err
    q, p = _poses(5, 4)
    rows = [[*np.degrees(qi), *(pi * 1e6)] for qi, pi in zip(q, p)]  # um written, read as mm...
    big = _write(tmp_path / "um.csv", ["q1", "q2", "q3", "q4", "q5", "q6", "x", "y", "z"], rows)
    status, err = run_cli(["import-points", str(big), "--out", str(tmp_path / "d"), "--joints",
                           "q1..q6", "--point", "x,y,z", "--units", "m"])  # ... and as m
    assert status == 2 and "in mm? (--units)" in err


def test_header_no_preset_knows(tmp_path: Path) -> None:
    source, _, _ = _mocap(tmp_path / "mocap.csv", n=4)
    status, err = run_cli(["import-points", str(source), "--out", str(tmp_path / "c")])
    assert status == 2 and f"{source}:1: no preset format" in err and "--joints" in err


def test_refuses_to_overwrite(tmp_path: Path) -> None:
    """A folder with files is replaced only with --force; the source's own folder never."""
    source, _, _ = _mocap(tmp_path / "mocap.csv", n=4)
    out = tmp_path / "campaign"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    args = ["import-points", str(source), "--out", str(out), "--joints", "a1..a6", "--point",
            "X,Y,Z", "--units", "m", "--angles", "rad"]
    status, err = run_cli(args)
    assert status == 2 and "--force" in err
    assert (out / "notes.txt").read_text() == "mine" and not (out / "points.csv").exists()
    assert run_cli([*args, "--force"]) == (0, "")
    assert (out / "points.csv").is_file() and not (out / "notes.txt").exists()
    status, err = run_cli([*args[:3], str(tmp_path), *args[4:], "--force"])
    assert status == 2 and "input" in err and source.is_file()


def test_folder_of_instrument_files_points_to_the_import(tmp_path: Path) -> None:
    """identify on a folder of tracker files (not a campaign) names them and the import command."""
    source, _, _ = _mocap(tmp_path / "mocap.csv", n=4)
    status, err = run_cli(["identify", str(tmp_path), "--arm", "ur5", "--out",
                           str(tmp_path / "cal")])
    assert status == 2 and source.name in err and "aacmm-pin import-points" in err


def test_other_separator_is_named_once(tmp_path: Path) -> None:
    """A semicolon-separated export with decimal commas: one line saying so, not a flood."""
    source = tmp_path / "export.csv"
    source.write_text("q1;q2;q3;q4;q5;q6;x;y;z\n" + "1,5;2;3;4;5;6;100,25;200;300\n" * 50)
    status, err = run_cli(["import-points", str(source), "--out", str(tmp_path / "c"),
                           "--joints", "q1..q6", "--point", "x,y,z"])
    assert status == 2 and "separated by ';'" in err and len(err.splitlines()) <= 2, err


def test_shared_ur5_data_to_identify_in_two_commands(tmp_path: Path) -> None:
    """import-points, then identify (the README's recipe); validate on the 20 poses never fitted.

    The calibration removes most of the 2.6 mm uncalibrated error: what is left on held-out poses
    is of the order of the UR5's repeatability (+-0.1 mm), far below a tenth of the start.
    """
    if not UR5_GRID.is_file():
        pytest.skip("shared real data not present")
    grid, test, cal = tmp_path / "ur5_grid", tmp_path / "ur5_random", tmp_path / "ur5_dh"
    assert run_cli(["import-points", str(UR5_GRID), "--out", str(grid)]) == (0, "")
    assert run_cli(["import-points", str(UR5_RANDOM), "--out", str(test)]) == (0, "")
    status, err = run_cli(["identify", str(grid), "--arm", "ur5", "--model", "dh",
                           "--out", str(cal)])
    assert status == 0, err
    errors = tmp_path / "errors.json"
    assert run_cli(["validate", str(cal), str(test), "--json", str(errors)])[0] == 0
    after_mm = json.loads(errors.read_text())["points"]["mean_mm"]
    with UR5_RANDOM.open(newline="") as f:
        commanded_mm = [[float(r[f"{c}_t"]) for c in "xyz"] for r in csv.DictReader(f)]
    points = read_campaign(test).points
    assert points is not None
    before_mm = np.mean(np.linalg.norm(points.point * 1e3 - commanded_mm, axis=1))
    assert after_mm < 0.1 * before_mm


def test_each_file_is_an_instrument_set_up_unless_one_frame(tmp_path: Path) -> None:
    """Two files: groups 1 and 2 (a frame each), or one group with --one-frame; rows in order."""
    a, qa, _ = _mocap(tmp_path / "a.csv", n=3, seed=5)
    b, qb, _ = _mocap(tmp_path / "b.csv", n=4, seed=6)
    options = ["--joints", "a1..a6", "--point", "X,Y,Z", "--units", "m", "--angles", "rad"]
    for extra, groups in (([], [1] * 3 + [2] * 4), (["--one-frame"], [1] * 7)):
        out = tmp_path / f"c{len(extra)}"
        assert run_cli(["import-points", str(a), str(b), "--out", str(out), *options,
                        *extra]) == (0, "")
        points = read_campaign(out).points
        assert points is not None and points.group.tolist() == groups
        np.testing.assert_allclose(points.q, np.r_[qa, qb], rtol=0,
                                   atol=np.radians(ROUNDING_MM))


def test_a_preset_named_must_fit_the_header(tmp_path: Path) -> None:
    source, _, _ = _mocap(tmp_path / "mocap.csv", n=4)
    status, err = run_cli(["import-points", str(source), "--out", str(tmp_path / "c"),
                           "--format", "jacobi2025"])
    assert status == 2 and "not the jacobi2025 format" in err
    status, err = run_cli(["import-points", str(source), "--out", str(tmp_path / "c"),
                           "--units", "m"])
    assert status == 2 and "--joints" in err


def test_a_zero_padded_range_keeps_its_padding_and_the_header_is_listed_once(tmp_path: Path) -> None:
    from aacmm_pin.data.point_import import parse_columns

    assert parse_columns("q01..q06") == ("q01", "q02", "q03", "q04", "q05", "q06")
    assert parse_columns("joint_1..joint_3") == ("joint_1", "joint_2", "joint_3")
    source, _, _ = _mocap(tmp_path / "mocap.csv", n=4)
    status, err = run_cli(["import-points", str(source), "--out", str(tmp_path / "c"),
                           "--joints", "b1..b6", "--point", "X,Y,Z", "--units", "m",
                           "--angles", "rad"])
    assert status == 2 and err.count("the header has:") == 1 and err.count("missing column") == 6


def test_point_read_against_every_file_header(tmp_path: Path) -> None:
    """--point X-D,...: a column named ``X-D`` in the second file only would be read as a difference
    there by the first file's header; the second file is named (line 1) and nothing is written."""
    q, p = _poses(3, 7)
    header = [*(f"a{k}" for k in range(1, 7)), "X", "D", "Y", "Z"]
    rows = [[*qi.tolist(), pi[0] + 0.5, 0.5, pi[1], pi[2]] for qi, pi in zip(q, p)]
    a = _write(tmp_path / "a.csv", header, rows)
    b = _write(tmp_path / "b.csv", [*header[:6], "X-D", "Y", "Z"],
               [[*qi.tolist(), *pi.tolist()] for qi, pi in zip(q, p)])
    options = ["--joints", "a1..a6", "--point", "X-D,Y,Z", "--units", "m", "--angles", "rad"]
    out = tmp_path / "c"
    status, err = run_cli(["import-points", str(a), str(b), "--out", str(out), *options])
    assert status == 2 and f"{b}:1: --point 'X-D,Y,Z' reads as X-D, Y, Z here" in err, err
    assert "X minus D, Y, Z" in err and not (out / "points.csv").exists()
    status, err = run_cli(["import-points", str(a), "--out", str(out), *options])  # alone: fine
    assert status == 0, err
    points = read_campaign(out).points
    assert points is not None
    np.testing.assert_allclose(points.point, p, rtol=0, atol=ROUNDING_MM * 1e-3)
