"""Tests of aacmm_pin.data.columns and the per-sample columns by name: readers, logs, samples, writers."""

from __future__ import annotations

import ast
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.cli import main
from aacmm_pin.data import columns as columns_module
from aacmm_pin.data.campaign import (
    read_campaign,
    read_readout_columns,
    read_sample_columns,
    read_tool_column,
    write_campaign,
)
from aacmm_pin.data.columns import Column, column, file_order, register_column
from aacmm_pin.data.logs import LengthBarLog, SpatLog
from aacmm_pin.errors import AacmmError, CampaignFormatError
from aacmm_pin.model.samples import Samples
from tests.test_campaign import GOOD, found, make, problems_of

PACKAGE = Path(__file__).resolve().parents[1] / "aacmm_pin"
BASE_C = {"spat.csv": [21.5, 21.75, 22.0, 22.25, 22.5, 22.75], "lengthbar.csv": [19.0, 19.5, 20, 20.5]}


def _with_column(name: str, header: str, values: list[float] | list[str]) -> str:
    """Return GOOD[name] with a column ``header`` appended, one value per data row."""
    lines = GOOD[name].splitlines()
    return "\n".join([f"{lines[0]},{header}", *(f"{row},{v}" for row, v in
                                                zip(lines[1:], values))]) + "\n"


@pytest.fixture()
def registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """Leave the column registry as it was after the test."""
    monkeypatch.setattr(columns_module, "_REGISTERED", dict(columns_module._REGISTERED))


def test_unknown_column_survives_read_samples_write_read(tmp_path: Path, arm: ap.Arm) -> None:
    """temp_base_c, which no package file names, is read into the logs and samples and written back."""
    folder = make(tmp_path / "a", {name: _with_column(name, "temp_base_c", values)
                                   for name, values in BASE_C.items()})
    first = read_campaign(folder)
    assert first.spat is not None and first.lengthbar is not None
    np.testing.assert_array_equal(first.spat.columns["temp_base_c"], BASE_C["spat.csv"])
    np.testing.assert_array_equal(first.lengthbar.columns["temp_base_c"], BASE_C["lengthbar.csv"])
    assert first.spat.temp is None and first.spat.t is None  # not taken for the arm's temperature
    samples = Samples.of_spat(arm, first.spat)
    np.testing.assert_array_equal(samples.column("temp_base_c"), BASE_C["spat.csv"])
    np.testing.assert_array_equal(Samples.of_log(arm, first.lengthbar).column("temp_base_c"),
                                  BASE_C["lengthbar.csv"])
    write_campaign(first, tmp_path / "b")
    assert (tmp_path / "b" / "spat.csv").read_text().splitlines()[0].endswith(",temp_base_c")
    again = read_campaign(tmp_path / "b")
    assert again.spat is not None and again.lengthbar is not None
    np.testing.assert_array_equal(again.spat.columns["temp_base_c"], BASE_C["spat.csv"])
    np.testing.assert_array_equal(again.lengthbar.columns["temp_base_c"], BASE_C["lengthbar.csv"])


def test_extra_columns_are_converted_to_si_by_unit_suffix(tmp_path: Path) -> None:
    """Extra columns in mm, um, deg, s are read in m, rad, s and written back in their units."""
    values = {"probe_mm": [1.5] * 6, "gap_um": [-3.0] * 6, "tilt_deg": [0.25] * 6, "dwell_s": [2] * 6,
              "load_n": [9.81] * 6, "torque_n_m": [-1.0] * 6, "count": [7] * 6}
    lines = GOOD["spat.csv"].splitlines()
    text = "\n".join([",".join([lines[0], *values]), *(
        ",".join([row, *(str(v[k]) for v in values.values())]) for k, row in enumerate(lines[1:]))])
    spat = read_campaign(make(tmp_path / "a", spat_csv=text)).spat
    assert spat is not None
    expect = {"probe_mm": 1.5e-3, "gap_um": -3e-6, "tilt_deg": math.radians(0.25), "dwell_s": 2.0,
              "load_n": 9.81, "torque_n_m": -1.0, "count": 7.0}
    assert list(spat.columns) == list(values)
    for name, si in expect.items():
        np.testing.assert_allclose(spat.columns[name], si, rtol=1e-15, err_msg=name)
    assert (column("probe_mm").unit, column("tilt_deg").unit, column("count").unit) == ("mm", "deg",
                                                                                       "")
    assert column("temp_base_c").field == "temp_base" and column("temp_c").field == "temp"
    write_campaign(read_campaign(tmp_path / "a"), tmp_path / "b")
    header = (tmp_path / "b" / "spat.csv").read_text().splitlines()
    assert header[0].endswith(",dz_mm," + ",".join(values))
    assert header[1].split(",")[-7:] == ["1.5", "-3", "0.25", "2", "9.81", "-1", "7"]


@pytest.mark.parametrize("cell, words", [("abc", "'abc' is not a number"),
                                         ("nan", "not a finite number"),
                                         ("500", "deg C is outside -50 to 150 deg C"),
                                         ("", "empty cell")])
def test_a_bad_cell_of_an_extra_column_names_file_line_and_column(tmp_path: Path, cell: str,
                                                                  words: str) -> None:
    """An out-of-range, non-numeric or empty cell of temp_base_c is reported at its line."""
    cells = [21.0, 21.0, 21.0, cell, 21.0, 21.0]
    problems = problems_of(make(tmp_path, spat_csv=_with_column("spat.csv", "temp_base_c", cells)))
    assert found(problems, "spat.csv", 5, "temp_base_c", words), problems
    assert len(problems) == 1


def test_a_text_column_of_a_campaign_log_is_refused_cell_by_cell(tmp_path: Path) -> None:
    """A non-numeric extra column of lengthbar.csv is an error at file, line and column."""
    text = _with_column("lengthbar.csv", "note", ["1", "ok", "2", "3"])
    problems = problems_of(make(tmp_path, lengthbar_csv=text))
    assert [(Path(p.path).name, p.line, p.column) for p in problems] == [("lengthbar.csv", 3,
                                                                         "note")]
    assert "'ok' is not a number" in problems[0].reason


def _points(z: str, poses: list[str]) -> str:
    """A points.csv with the documented columns sigma_um and pose; ``z``: the z column's name."""
    return f"q1_deg,q2_deg,q3_deg,x_mm,y_mm,{z},sigma_um,pose\n" + "".join(
        f"{k},2,3,{k}0,0,0,20,{pose}\n" for k, pose in enumerate(poses, 1))


def test_the_pose_column_is_known_where_a_column_is_missing(tmp_path: Path) -> None:
    """A misspelt required column of points.csv names itself as unknown, not the documented pose
    and sigma_um columns beside it; the expected columns list pose."""
    text = _points("zmm", ["1", "1", "2", "2"])
    problems = problems_of(make(tmp_path, points_csv=text))
    assert found(problems, "points.csv", 1, "zmm", "unknown column; did you mean z_mm?")
    unknown = next(p.reason for p in problems if "unknown" in p.reason)
    assert "pose" not in unknown.split(";")[0] and "sigma_um" not in unknown.split(";")[0]
    assert unknown.endswith(", pose"), unknown
    assert len(problems) == 2, problems  # z_mm missing, zmm unknown


def test_a_pose_that_is_no_number_is_named_as_the_pose(tmp_path: Path) -> None:
    """A text pose label in points.csv: the pose column's meaning, not "further columns"."""
    text = _points("z_mm", ["a", "a", "b", "b"])
    problems = problems_of(make(tmp_path, points_csv=text))
    assert [p.line for p in problems] == [2, 3, 4, 5]
    assert all(p.column == "pose" and "numbers each row's pose" in p.reason
               and "further columns" not in p.reason for p in problems), problems
    points = read_campaign(make(tmp_path / "good", points_csv=_points("z_mm", ["7", "7", "8", "8"]))
                           ).points
    assert points is not None
    np.testing.assert_array_equal(points.columns["pose"], [7, 7, 8, 8])


def test_reference_files_still_refuse_unknown_columns(tmp_path: Path) -> None:
    """locations.csv and bar.csv have no per-sample columns: an extra one is an unknown column."""
    locations = GOOD["locations.csv"].replace("z_mm", "z_mm,temp_c").replace(",0\n", ",0,20\n")
    locations = locations.replace("-5.5\n", "-5.5,20\n")
    problems = problems_of(make(tmp_path, locations_csv=locations))
    assert found(problems, "locations.csv", 1, "temp_c", "unknown column"), problems


def test_a_registered_column_range_is_enforced(tmp_path: Path, registry: None) -> None:
    """A plugin's column declares its unit and range; the readers check it and convert to SI."""
    load = register_column(Column("payload_kg", "payload", "kg", 1.0, 0.0, 50.0, "tool payload"))
    assert register_column(load) is load  # again: harmless
    with pytest.raises(ValueError, match="payload_kg"):
        register_column(Column("payload_kg", "payload", "g", 1e-3, 0.0, 5e4))
    with pytest.raises(ValueError, match="temp_c"):
        register_column(Column("temp_c", "temp", "K", 1.0))
    good = make(tmp_path / "good", spat_csv=_with_column("spat.csv", "payload_kg", [1, 2, 3, 4, 5, 6]))
    spat = read_campaign(good).spat
    assert spat is not None
    np.testing.assert_array_equal(spat.columns["payload_kg"], [1, 2, 3, 4, 5, 6])
    bad = make(tmp_path / "bad", spat_csv=_with_column("spat.csv", "payload_kg", [1, 2, 80, 4, 5, 6]))
    problems = problems_of(bad)
    assert found(problems, "spat.csv", 4, "payload_kg", "80 kg is outside 0 to 50 kg"), problems


def test_column_values_convert_both_ways() -> None:
    """to_si and from_si are inverse; the built-in columns are written first."""
    col = column("reach_mm")
    values = np.array([-12.5, 0.0, 1e4])
    np.testing.assert_allclose(col.to_si(values), values * 1e-3)
    np.testing.assert_allclose(col.from_si(col.to_si(values)), values, rtol=1e-15)
    assert col.check(2e5) == "mm is outside -100000 to 100000 mm"
    assert column("sigma_um").check(0.0) == "um is not a positive standard uncertainty"
    assert file_order(["temp_base_c", "temp_c", "t_s"]) == ["t_s", "temp_c", "temp_base_c"]
    with pytest.raises(ValueError, match="factor"):
        Column("x_mm", "x", "mm", 0.0)


def test_readouts_files_carry_extra_columns_to_predict_samples(tmp_path: Path, arm: ap.Arm,
                                                               monkeypatch: pytest.MonkeyPatch
                                                               ) -> None:
    """predict's readouts: numeric extra columns reach its samples in SI; a text id column does not."""
    q = np.random.default_rng(0).uniform(-90, 90, (3, 7))
    header = ["pose", *(f"q{i}_deg" for i in range(1, 8)), "temp_base_c", "temp_c", "note"]
    rows = [[f"p{k}", *(f"{v:.6f}" for v in q[k]), f"{20 + k}", "21", "text"] for k in range(3)]
    readouts = tmp_path / "readouts.csv"
    readouts.write_text("\n".join(",".join(r) for r in [header, *rows]) + "\n")
    got, cols = read_sample_columns(readouts, arm)
    np.testing.assert_allclose(got, np.radians(q), atol=1e-12)
    assert list(cols) == ["temp_base_c", "temp_c"]
    np.testing.assert_array_equal(cols["temp_base_c"], [20, 21, 22])
    assert read_readout_columns(readouts)[1] is not None  # (q, temp, t) as before
    ap.write_parameters(ap.Parameters.nominal(arm), tmp_path / "parameters.json")
    seen: list[Samples] = []
    import aacmm_pin.model.kinematics as kinematics

    real = kinematics.predict

    def spy(*args: object, **kwargs: object) -> np.ndarray:
        seen.append(args[3])  # type: ignore[arg-type]
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(kinematics, "predict", spy)
    assert main(["predict", str(tmp_path / "parameters.json"), str(readouts),
                 "--out", str(tmp_path / "p.csv")]) == 0
    np.testing.assert_array_equal(seen[0].column("temp_base_c"), [20, 21, 22])
    np.testing.assert_array_equal(seen[0].temp, [21, 21, 21])
    with pytest.raises(AacmmError, match=r"no column 'wind_c'.*readouts\.csv"):
        seen[0].column("wind_c")
    assert (tmp_path / "p.csv").read_text().splitlines()[0] == "pose,temp_base_c,temp_c,note,x_mm,y_mm,z_mm"


def test_a_bad_cell_of_a_readouts_file_extra_column_is_named(tmp_path: Path) -> None:
    """A readouts file's column with a unit is checked: a bad cell names file, line, column."""
    path = tmp_path / "readouts.csv"
    path.write_text("q1_deg,q2_deg,temp_base_c,id\n1,2,20,a\n3,4,hot,b\n")
    with pytest.raises(CampaignFormatError) as info:
        read_sample_columns(path)
    assert [(p.line, p.column) for p in info.value.problems] == [(3, "temp_base_c")]


def test_samples_name_a_missing_column_and_join_their_columns(arm: ap.Arm) -> None:
    """Samples.column names the missing column and files; concatenate keeps the shared columns."""
    spat = SpatLog([1, 1], np.zeros((2, 7)), np.zeros((2, 3)), t=[0.0, 1.0],
                   columns={"temp_base_c": [20.0, 21.0], "only_spat": [1.0, 2.0]})
    bar = LengthBarLog([1], ["A"], np.ones((1, 7)), t=[5.0], columns={"temp_base_c": [22.0]})
    a, b = Samples.of_spat(arm, spat), Samples.of_log(arm, bar)
    with pytest.raises(AacmmError, match=r"^no column 'temp_c' in the samples: add it to spat.csv"):
        a.column("temp_c")
    joined = Samples.concatenate([a, b])
    assert list(joined.columns) == ["temp_base_c", "t_s"] and joined.files == ("spat.csv",
                                                                               "lengthbar.csv")
    np.testing.assert_array_equal(joined.column("temp_base_c"), [20.0, 21.0, 22.0])
    np.testing.assert_array_equal(joined.t, [0.0, 1.0, 5.0])
    np.testing.assert_array_equal(joined.displacement, np.zeros((3, 3)))
    with pytest.raises(AacmmError, match="only_spat.*spat.csv or lengthbar.csv"):
        joined.column("only_spat")
    picked = joined.select(np.array([2, 0]))
    np.testing.assert_array_equal(picked.column("temp_base_c"), [22.0, 20.0])
    np.testing.assert_array_equal(picked.q, joined.q[[2, 0]])


def test_logs_keep_columns_through_take_replace_and_with_spat(tmp_path: Path) -> None:
    """Row selection keeps every column; temp=None removes temp_c; shapes are checked by name."""
    import dataclasses

    folder = make(tmp_path, spat_csv=_with_column("spat.csv", "temp_base_c", BASE_C["spat.csv"]))
    c = read_campaign(folder)
    one = c.select([2])
    assert one.spat is not None
    np.testing.assert_array_equal(one.spat.columns["temp_base_c"], BASE_C["spat.csv"][3:])
    warm = c.with_spat(temp=np.full(6, 25.0))
    assert warm.spat is not None and list(warm.spat.columns) == ["temp_base_c", "temp_c"]
    cold = dataclasses.replace(warm.spat, temp=None)
    assert cold.temp is None and list(cold.columns) == ["temp_base_c"]
    with pytest.raises(ValueError, match=r"SpatLog.columns\['temp_base_c'\]: shape \(2\) expected"):
        SpatLog([1, 1], np.zeros((2, 3)), np.zeros((2, 3)), columns={"temp_base_c": [1.0]})
    with pytest.raises(ValueError):
        warm.spat.columns["temp_c"][0] = 1.0  # read-only, as every log array


def test_readers_are_told_names_not_given_an_arm(tmp_path: Path) -> None:
    """Any object with axis_names and tool_names, or the keywords, replaces the arm."""
    header = "tool,J1_deg,J2_deg,J3_deg,x_mm,y_mm,z_mm\n"
    rows = "".join(f"{'left' if k % 2 else 'right'},{k},{2 * k},{3 * k},{k},0,0\n" for k in range(6))
    (tmp_path / "points.csv").write_text(header + rows)
    names = SimpleNamespace(axis_names=["J1", "J2", "J3"], tool_names=["left", "right"])
    by_arm = read_campaign(tmp_path, arm=names).points
    by_keywords = read_campaign(tmp_path, axis_names=["J1", "J2", "J3"],
                                tool_names=["left", "right"]).points
    assert by_arm is not None and by_keywords is not None
    np.testing.assert_array_equal(by_arm.q, by_keywords.q)
    np.testing.assert_allclose(by_arm.q[:, 2], np.radians(3 * np.arange(6)))
    assert read_tool_column(tmp_path / "points.csv", names).tolist() == ["right", "left"] * 3
    with pytest.raises(CampaignFormatError, match="unknown tool 'left'"):
        read_campaign(tmp_path, axis_names=["J1", "J2", "J3"], tool_names=["right"])


def test_the_readers_import_no_arm() -> None:
    """The data modules import neither the arm nor anything above them, not even for types."""
    data = ("columns", "csv_table", "csv_rows", "logs", "campaign", "campaign_writer", "arm_names",
            "problem_log", "json_file", "bounded_read", "spreadsheet", "output_claim", "couplings",
            "poses")
    allowed = {f"aacmm_pin.data.{m}" for m in data} | {  # and the foundations they use
        "aacmm_pin.errors", "aacmm_pin.units", "aacmm_pin.interrupts"}
    for name in data:
        tree = ast.parse((PACKAGE / "data" / f"{name}.py").read_text())
        imported = {node.module for node in ast.walk(tree)
                    if isinstance(node, ast.ImportFrom) and node.module}
        imported |= {a.name for node in ast.walk(tree) if isinstance(node, ast.Import)
                     for a in node.names}
        assert not {m for m in imported if m.startswith("aacmm_pin")} - allowed, name


def test_the_residual_scan_offers_every_varying_column(arm: ap.Arm) -> None:
    """An extra column that varies beyond its min_spread is a scan variable, in its file unit."""
    from aacmm_pin.analyses.residual_scan import _variables

    q = np.random.default_rng(1).uniform(-1, 1, (30, 7))
    samples = Samples(arm, q, columns={"temp_base_c": np.linspace(20, 21, 30),
                                       "flat_c": np.full(30, 20.0) + np.linspace(0, 0.04, 30),
                                       "tilt_deg": np.radians(np.linspace(0, 5, 30))})
    found = {v[0]: v for v in _variables(samples)}
    assert "the column temp_base_c" in found and "the column flat_c" not in found
    np.testing.assert_allclose(found["the column tilt_deg"][3], np.linspace(0, 5, 30))
    assert found["the column tilt_deg"][2] == "tilt_deg (deg)"


def test_points_keep_sigma_and_extra_columns_in_their_order(tmp_path: Path) -> None:
    """points.csv: sigma_um, t_s, temp_c keep their places; an extra column follows, all round trip."""
    header = "group,q1_deg,q2_deg,q3_deg,x_mm,y_mm,z_mm,temp_base_c,sigma_um,t_s\n"
    rows = "".join(f"1,{k},{2 * k},{3 * k},{k},{k % 3},0,{20 + k / 10},{10 + k},{k}\n"
                   for k in range(6))
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "points.csv").write_text(header + rows)
    points = read_campaign(tmp_path / "a").points
    assert points is not None and points.sigma is not None
    assert list(points.columns) == ["temp_base_c", "sigma_um", "t_s"]
    np.testing.assert_allclose(points.sigma, (10 + np.arange(6)) * 1e-6, rtol=1e-15)
    write_campaign(read_campaign(tmp_path / "a"), tmp_path / "b")
    written = (tmp_path / "b" / "points.csv").read_text().splitlines()[0]
    assert written == "group,q1_deg,q2_deg,q3_deg,x_mm,y_mm,z_mm,sigma_um,t_s,temp_base_c"
    again = read_campaign(tmp_path / "b").points
    assert again is not None
    for name, values in points.columns.items():
        np.testing.assert_allclose(again.columns[name], values, rtol=1e-12, err_msg=name)


def test_small_values_of_an_unknown_column_are_written_back_whole(tmp_path: Path) -> None:
    """A dimensionless column of 1e-10-sized values (a strain) is not rounded to 0 on write."""
    strain = [1.25e-10, -3.5e-11, 2e-10, 0.0, 7.75e-9, -1e-12]
    first = read_campaign(make(tmp_path / "a", {"spat.csv": _with_column("spat.csv", "strain",
                                                                         strain)}))
    write_campaign(first, tmp_path / "b")
    again = read_campaign(tmp_path / "b")
    assert again.spat is not None
    np.testing.assert_allclose(again.spat.columns["strain"], strain, rtol=1e-12, atol=0)


def test_nm_is_nanometres_and_n_m_newton_metres() -> None:
    """A metrologist's nm is a length; a torque column ends with _n_m."""
    assert column("runout_nm").unit == "nm" and column("runout_nm").to_si(np.array([5.0]))[0] == 5e-9
    assert column("load_n_m").unit == "N m"
