"""Tests of aacmm_pin.data.campaign: the campaign CSV format, its readers, writers and validation."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from aacmm_pin.data.campaign import (
    Campaign,
    LengthBarLog,
    SpatLog,
    read_campaign,
    read_readouts,
    write_campaign,
    write_points,
)
from aacmm_pin.errors import CampaignFormatError, Problem

SAMPLE = Path(__file__).resolve().parents[2] / "shared" / "sample-campaign"
MM = 1e-12  # 1e-9 mm, in m
DEG = np.radians(1e-9)  # 1e-9 deg, in rad

# A small valid campaign with 3 axes; the comments give the file line of each row.
GOOD = {
    "spat.csv": """location,q1_deg,q2_deg,q3_deg,dx_mm,dy_mm,dz_mm
1,10.5,-20.25,30.125,0.001,-0.002,0.003
1,11,21,31,0,0,0
1,12,22,32,0,0,0
2,13,23,33,0,0,0
2,14,24,34,0,0,0
2,15,25,-719.5,0,0,0
""",  # lines 2-4: location 1, lines 5-7: location 2
    "locations.csv": "location,x_mm,y_mm,z_mm\n1,100,0,0\n2,0,100,-5.5\n",
    "lengthbar.csv": """placement,socket,q1_deg,q2_deg,q3_deg
1,A,1,2,3
1,B,4,5,6
2,A,7,8,9
2,B,10,11,12
""",
    "bar.csv": "from,to,length_mm\nA,B,361.775\n",
}


def make(folder: Path, files: dict[str, str | None] | None = None, **changes: str | None) -> Path:
    """Write GOOD into folder, with files replaced (name -> text, None = absent)."""
    texts = {**GOOD, **(files or {}), **{k.replace("_", "."): v for k, v in changes.items()}}
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in texts.items():
        if text is not None:
            (folder / name).write_text(text, encoding="utf-8")
    return folder


def set_cell(name: str, line: int, column: str, value: str) -> str:
    """Return GOOD[name] with one cell replaced."""
    rows = [row.split(",") for row in GOOD[name].splitlines()]
    rows[line - 1][rows[0].index(column)] = value
    return "\n".join(",".join(row) for row in rows) + "\n"


def drop_column(name: str, column: str) -> str:
    """Return GOOD[name] without one column."""
    rows = [row.split(",") for row in GOOD[name].splitlines()]
    k = rows[0].index(column)
    return "\n".join(",".join(row[:k] + row[k + 1:]) for row in rows) + "\n"


def problems_of(folder: Path, **kwargs: int) -> list[Problem]:
    with pytest.raises(CampaignFormatError) as info:
        read_campaign(folder, **kwargs)
    assert str(info.value).count("\n") == len(info.value.problems)
    return info.value.problems


def found(problems: list[Problem], name: str, line: int | None, column: str | None,
          words: str = "") -> bool:
    """Tell whether one problem has this file name, line, column and words in its reason."""
    return any(Path(p.path).name == name and p.line == line and p.column == column
               and words.lower() in p.reason.lower() for p in problems)


def random_campaign(rng: np.random.Generator, n_axes: int = 7, timed: bool = True) -> Campaign:
    n, m = 40, 18
    location = np.repeat([1, 2, 5, 3], n // 4)
    spat = SpatLog(location, rng.uniform(-4 * np.pi, 4 * np.pi, (n, n_axes)),
                   rng.normal(0, 1e-4, (n, 3)), np.sort(rng.uniform(0, 5e4, n)) if timed else None,
                   rng.uniform(15, 30, n) if timed else None)
    bar = LengthBarLog(np.repeat([1, 2, 3], m // 3), np.tile(["A", "B", "Ctr"], m // 3),
                       rng.uniform(-np.pi, np.pi, (m, n_axes)),
                       rng.uniform(0, 5e4, m) if timed else None)
    locations = {k: rng.uniform(-0.5, 0.5, 3) for k in (1, 2, 3, 5)}
    lengths = {("A", "B"): 0.361775, ("A", "Ctr"): rng.uniform(0.5, 1), ("B", "Ctr"): 0.3}
    return Campaign(spat, locations, bar, lengths)


def test_good_campaign_is_read_in_si_units(tmp_path: Path) -> None:
    """A valid folder is read with mm -> m, deg -> rad, ids, sockets and file lines kept."""
    c = read_campaign(make(tmp_path))
    assert c.n_axes == 3 and c.location_ids == (1, 2) and c.source == tmp_path
    np.testing.assert_array_equal(c.spat.location, [1, 1, 1, 2, 2, 2])
    np.testing.assert_allclose(c.spat.q[0], np.radians([10.5, -20.25, 30.125]), rtol=0, atol=DEG)
    np.testing.assert_allclose(c.spat.displacement[0], [1e-6, -2e-6, 3e-6], rtol=0, atol=MM)
    np.testing.assert_array_equal(c.spat.lines, [2, 3, 4, 5, 6, 7])
    assert c.spat.t is None and c.spat.temp is None
    np.testing.assert_allclose(c.locations[2], [0, 0.1, -0.0055], rtol=0, atol=MM)
    assert list(c.lengthbar.socket) == ["A", "B", "A", "B"]
    np.testing.assert_array_equal(c.lengthbar.placement, [1, 1, 2, 2])
    assert c.bar == {("A", "B"): pytest.approx(0.361775, abs=MM)}


@pytest.mark.parametrize("timed", [True, False])
def test_round_trip_keeps_every_value(tmp_path: Path, timed: bool) -> None:
    """write_campaign then read_campaign returns the same campaign to 1e-9 mm / 1e-9 deg."""
    c = random_campaign(np.random.default_rng(7), timed=timed)
    write_campaign(c, tmp_path / "new" / "folder")
    r = read_campaign(tmp_path / "new" / "folder")
    for got, want in ((r.spat, c.spat), (r.lengthbar, c.lengthbar)):
        np.testing.assert_allclose(got.q, want.q, rtol=0, atol=DEG)
        for field in ("t", "temp"):
            assert (getattr(got, field) is None) == (getattr(want, field) is None)
            if getattr(want, field) is not None:
                np.testing.assert_allclose(getattr(got, field), getattr(want, field), atol=1e-9)
    np.testing.assert_array_equal(r.spat.location, c.spat.location)
    np.testing.assert_allclose(r.spat.displacement, c.spat.displacement, rtol=0, atol=MM)
    np.testing.assert_array_equal(r.lengthbar.socket, c.lengthbar.socket)
    np.testing.assert_array_equal(r.lengthbar.placement, c.lengthbar.placement)
    assert r.locations.keys() == c.locations.keys() and r.bar.keys() == c.bar.keys()
    for k in c.locations:
        np.testing.assert_allclose(r.locations[k], c.locations[k], rtol=0, atol=MM)
    for k in c.bar:
        assert r.bar[k] == pytest.approx(c.bar[k], abs=MM)
    np.testing.assert_array_equal(r.spat.lines, np.arange(2, 42))


def test_writer_uses_sample_layout(tmp_path: Path) -> None:
    """Written files have the documented headers, 9 decimals, and t_s/temp_c only when present."""
    c = random_campaign(np.random.default_rng(1))
    write_campaign(c, tmp_path)
    spat = (tmp_path / "spat.csv").read_text().splitlines()
    assert spat[0] == ",".join(["location", *(f"q{i}_deg" for i in range(1, 8)), "dx_mm", "dy_mm",
                                "dz_mm", "t_s", "temp_c"])
    assert all(len(cell.split(".")[1]) == 9 for cell in spat[1].split(",")[1:])
    head = (tmp_path / "lengthbar.csv").read_text().splitlines()[0]
    assert head.endswith("q7_deg,t_s")
    assert (tmp_path / "bar.csv").read_text().splitlines()[1] == "A,B,361.775000000"


@pytest.mark.skipif(not SAMPLE.is_dir(), reason="shared sample campaign not present")
def test_reads_shared_sample_campaign() -> None:
    """The independently written sample campaign reads with its counts and its values in SI."""
    c = read_campaign(SAMPLE)
    assert (c.spat.q.shape, c.location_ids, c.lengthbar.q.shape, c.n_axes) == (
        (800, 7), (1, 2, 3, 4), (420, 7), 7)
    spat = np.loadtxt(SAMPLE / "spat.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(c.spat.location, spat[:, 0].astype(int))
    np.testing.assert_allclose(c.spat.q, np.radians(spat[:, 1:8]), rtol=0, atol=1e-15)
    np.testing.assert_allclose(c.spat.displacement, spat[:, 8:11] * 1e-3, rtol=0, atol=1e-18)
    locs = np.loadtxt(SAMPLE / "locations.csv", delimiter=",", skiprows=1)
    for row in locs:
        np.testing.assert_allclose(c.locations[int(row[0])], row[1:] * 1e-3, rtol=0, atol=1e-18)
    with open(SAMPLE / "lengthbar.csv", newline="") as f:
        rows = list(csv.reader(f))[1:]
    assert list(c.lengthbar.socket) == [r[1] for r in rows]
    np.testing.assert_array_equal(c.lengthbar.placement, [int(r[0]) for r in rows])
    np.testing.assert_allclose(c.lengthbar.q, np.radians([[float(v) for v in r[2:]] for r in rows]),
                               rtol=0, atol=1e-15)
    assert c.bar == pytest.approx({("A", "B"): 0.361775, ("A", "C"): 0.711211}, abs=1e-15)


@pytest.mark.parametrize("name, line, column, value, words", [
    ("spat.csv", 3, "q2_deg", "abc", "not a number"),
    ("spat.csv", 3, "dx_mm", "nan", "not a finite"),
    ("spat.csv", 3, "dy_mm", "NaN", "not a finite"),
    ("spat.csv", 4, "dz_mm", "inf", "not a finite"),
    ("spat.csv", 4, "q1_deg", "-Infinity", "not a finite"),
    ("spat.csv", 5, "q3_deg", "", "empty cell"),
    ("spat.csv", 6, "q3_deg", "720.5", "outside +-720"),
    ("spat.csv", 6, "q1_deg", "-1000", "outside +-720"),
    ("spat.csv", 2, "location", "1.5", "not an integer"),
    ("spat.csv", 2, "location", "0", "integer >= 1"),
    ("spat.csv", 2, "location", "99999999999999999999", "too large"),
    ("locations.csv", 2, "location", "one", "not an integer"),
    ("locations.csv", 3, "y_mm", "1,0e", "cells"),
    ("locations.csv", 3, "z_mm", "12..5", "not a number"),
    ("lengthbar.csv", 2, "placement", "-1", "integer >= 1"),
    ("lengthbar.csv", 3, "placement", "2.0", "not an integer"),
    ("lengthbar.csv", 4, "socket", " ", "empty cell"),
    ("lengthbar.csv", 5, "q2_deg", "nan", "not a finite"),
    ("bar.csv", 2, "length_mm", "0", "not a positive"),
    ("bar.csv", 2, "length_mm", "-361.775", "not a positive"),
    ("bar.csv", 2, "length_mm", "inf", "not a finite"),
    ("bar.csv", 2, "from", "", "empty cell"),
    # plausibility: magnitudes no instrument gives
    ("spat.csv", 3, "dx_mm", "2.5", "measuring range"),
    ("spat.csv", 4, "dz_mm", "-1e300", "measuring range"),
    ("locations.csv", 2, "x_mm", "1e300", "beyond +-100 m"),
    ("bar.csv", 2, "length_mm", "1e-9", "not a plausible bar length"),
    ("bar.csv", 2, "length_mm", "0.5", "not a plausible bar length"),
    ("bar.csv", 2, "length_mm", "20000", "not a plausible bar length"),
])
def test_bad_cell_is_reported_at_its_line_and_column(tmp_path: Path, name: str, line: int,
                                                     column: str, value: str, words: str) -> None:
    """A bad cell is reported with its file, 1-based line, column name and a clear reason."""
    problems = problems_of(make(tmp_path, {name: set_cell(name, line, column, value)}))
    expect_column = None if words == "cells" else column  # a comma in a cell adds a cell
    assert found(problems, name, line, expect_column, words), problems


@pytest.mark.parametrize("name, text, column, words", [
    ("spat.csv", drop_column("spat.csv", "dz_mm"), "dz_mm", "missing column"),
    ("spat.csv", drop_column("spat.csv", "location"), "location", "missing column"),
    ("lengthbar.csv", drop_column("lengthbar.csv", "socket"), "socket", "missing column"),
    ("bar.csv", drop_column("bar.csv", "length_mm"), "length_mm", "missing column"),
    ("spat.csv", GOOD["spat.csv"].replace("dy_mm", "dx_mm", 1), "dx_mm", "duplicated column"),
    ("spat.csv", GOOD["spat.csv"].replace("dy_mm", "dy_mm ", 1).replace("dz_mm", "dz", 1), "dz",
     "unknown column"),
    ("locations.csv", GOOD["locations.csv"].replace("z_mm", "z_mm,q1_deg").replace("\n", ",0\n")
     .replace("q1_deg,0", "q1_deg"), "q1_deg", "unknown column"),
    ("spat.csv", drop_column("spat.csv", "q2_deg"), "q2_deg", "without gaps"),
    ("spat.csv", GOOD["spat.csv"].replace("q3_deg", "q4_deg", 1), "q3_deg", "without gaps"),
    ("lengthbar.csv", drop_column(
        "lengthbar.csv", "q1_deg").replace("q2_deg", "x").replace("q3_deg", "y"), "q1_deg",
     "missing column"),
    ("bar.csv", "from,to,,length_mm\nA,B,,361.775\n", "3", "empty column name"),
])
def test_bad_header_is_reported_at_line_1(tmp_path: Path, name: str, text: str, column: str,
                                          words: str) -> None:
    """Missing, unknown, duplicated, empty and non-contiguous q headers are reported on line 1."""
    problems = problems_of(make(tmp_path, {name: text}))
    assert found(problems, name, 1, column, words), problems


def test_axes_count_must_agree_between_spat_and_lengthbar(tmp_path: Path) -> None:
    """A lengthbar.csv with fewer q columns than spat.csv is reported on its header line."""
    problems = problems_of(make(tmp_path, lengthbar_csv=drop_column("lengthbar.csv", "q3_deg")))
    assert found(problems, "lengthbar.csv", 1, None, "2 axes"), problems
    assert len(problems) == 1


@pytest.mark.parametrize("edit, line, words", [
    (lambda t: t.replace("1,11,21,31,0,0,0", "1,11,21,31,0,0"), 3, "6 cells"),
    (lambda t: t.replace("1,11,21,31,0,0,0", "1,11,21,31,0,0,0,9"), 3, "8 cells"),
    (lambda t: t.replace("1,11,21,31,0,0,0\n", "1,11,21,31,0,0,0\n\n"), 4, "blank line"),
])
def test_rows_of_wrong_length_and_inner_blank_lines_are_reported(tmp_path: Path, edit, line: int,
                                                                 words: str) -> None:
    """Rows with too few or too many cells, and blank lines between rows, are reported."""
    problems = problems_of(make(tmp_path, spat_csv=edit(GOOD["spat.csv"])))
    assert found(problems, "spat.csv", line, None, words), problems


def test_bom_whitespace_and_trailing_blank_lines_are_accepted(tmp_path: Path) -> None:
    """A UTF-8 BOM, spaces around cells and headers, and blank trailing lines are not errors."""
    spat = "\ufeff" + GOOD["spat.csv"].replace(",", " , ").replace("\n", " \r\n") + "\n  \n\n"
    folder = make(tmp_path, spat_csv=spat, bar_csv="\ufefffrom , to,length_mm\n A , B ,361.775\n")
    (folder / "locations.csv").write_bytes(GOOD["locations.csv"].encode("utf-8-sig"))
    c = read_campaign(folder)
    good = read_campaign(make(tmp_path / "good"))
    np.testing.assert_array_equal(c.spat.q, good.spat.q)
    np.testing.assert_array_equal(c.locations[2], good.locations[2])
    assert c.bar == good.bar


@pytest.mark.parametrize("name", ["spat.csv", "locations.csv", "lengthbar.csv", "bar.csv"])
@pytest.mark.parametrize("text, line, words", [
    ("", None, "empty file"),
    ("\n \n", None, "empty file"),
    ("\nlocation\n", 1, "blank first line"),
    (None, None, "header only"),
])
def test_empty_and_header_only_files_are_reported(tmp_path: Path, name: str, text: str | None,
                                                  line: int | None, words: str) -> None:
    """Empty files, a blank first line and files with a header but no rows are reported."""
    text = GOOD[name].splitlines()[0] + "\n" if text is None else text
    problems = problems_of(make(tmp_path, {name: text}))
    assert found(problems, name, line, None, words), problems


def test_location_without_zero_position(tmp_path: Path) -> None:
    """A SPAT location absent from locations.csv is reported at its first line in spat.csv."""
    spat = GOOD["spat.csv"] + "".join(f"7,1,2,{3 + k},0,0,0\n" for k in range(3))
    problems = problems_of(make(tmp_path, spat_csv=spat))
    assert found(problems, "spat.csv", 8, "location", "location 7 has no zero position")
    assert len(problems) == 1


def test_location_with_too_few_samples(tmp_path: Path) -> None:
    """A location with fewer samples than min_samples_per_location is reported once per location."""
    folder = make(tmp_path)
    problems = problems_of(folder, min_samples_per_location=4)
    assert found(problems, "spat.csv", 2, "location", "location 1 has 3 samples")
    assert found(problems, "spat.csv", 5, "location", "location 2 has 3 samples")
    assert len(problems) == 2
    assert read_campaign(folder, min_samples_per_location=3).location_ids == (1, 2)


def test_duplicated_and_unused_location_ids(tmp_path: Path) -> None:
    """A location id twice in locations.csv, and one with no SPAT sample, are both reported."""
    problems = problems_of(make(tmp_path, locations_csv=GOOD["locations.csv"] + "2,1,1,1\n"
                                "4,0,0,0\n"))
    assert found(problems, "locations.csv", 4, "location", "also on line 3")
    assert found(problems, "locations.csv", 5, "location", "location 4 has 0 samples")
    assert len(problems) == 2


def test_socket_not_named_in_bar(tmp_path: Path) -> None:
    """A socket measured in lengthbar.csv but absent from bar.csv is reported at its first line."""
    problems = problems_of(make(tmp_path, lengthbar_csv=GOOD["lengthbar.csv"] + "2,C,1,1,1\n"))
    assert found(problems, "lengthbar.csv", 6, "socket", "socket 'C' is not named in bar.csv")
    assert len(problems) == 1


@pytest.mark.parametrize("bar_rows, line, column, words", [
    ("A,B,361.775\nB,C,100\n", 3, "to", "socket 'C' is never measured"),
    ("A,B,361.775\nD,A,100\n", 3, "from", "socket 'D' is never measured"),
    ("A,B,361.775\nB,A,361.7\n", 3, "to", "also on line 2"),
    ("A,B,361.775\nA,A,1\n", 3, "to", "to itself"),
])
def test_bar_pairs_must_be_measured_and_unique(tmp_path: Path, bar_rows: str, line: int,
                                               column: str, words: str) -> None:
    """Each bar.csv pair must be measured in lengthbar.csv, and named once."""
    problems = problems_of(make(tmp_path, bar_csv="from,to,length_mm\n" + bar_rows))
    assert found(problems, "bar.csv", line, column, words), problems


def test_bar_pair_never_measured_in_one_placement(tmp_path: Path) -> None:
    """Sockets that are measured, but never in the same placement, make a pair with no use."""
    log = "placement,socket,q1_deg,q2_deg,q3_deg\n1,A,1,2,3\n2,B,4,5,6\n"
    problems = problems_of(make(tmp_path, lengthbar_csv=log))
    assert found(problems, "bar.csv", 2, None, "never measured in one placement"), problems


@pytest.mark.parametrize("absent, missing, words", [
    ("locations.csv", "locations.csv", "spat.csv needs it"),
    ("bar.csv", "bar.csv", "lengthbar.csv needs it"),
    ("spat.csv", "spat.csv", "locations.csv needs it"),
])
def test_files_come_in_pairs(tmp_path: Path, absent: str, missing: str, words: str) -> None:
    """spat.csv needs locations.csv and lengthbar.csv needs bar.csv (and the other way round)."""
    problems = problems_of(make(tmp_path, {absent: None}))
    assert found(problems, missing, None, None, words), problems


def test_either_pair_may_be_absent(tmp_path: Path) -> None:
    """A SPAT-only and a length-bar-only folder are both valid campaigns."""
    spat_only = read_campaign(make(tmp_path / "s", lengthbar_csv=None, bar_csv=None))
    bar_only = read_campaign(make(tmp_path / "b", spat_csv=None, locations_csv=None))
    assert spat_only.lengthbar is None and spat_only.bar == {} and spat_only.n_axes == 3
    assert bar_only.spat is None and bar_only.locations == {} and bar_only.location_ids == ()
    assert bar_only.n_axes == 3


def test_folder_missing_not_a_folder_or_without_logs(tmp_path: Path) -> None:
    """A missing folder, a file, and a folder without spat.csv or lengthbar.csv are reported."""
    (tmp_path / "file").write_text("x")
    (tmp_path / "empty").mkdir()
    make(tmp_path / "refs", spat_csv=None, lengthbar_csv=None)
    for folder, words in (("nope", "does not exist"), ("file", "is not a folder"),
                          ("empty", "neither"), ("refs", "neither")):
        problems = problems_of(tmp_path / folder)
        assert [(Path(p.path), p.line, p.column) for p in problems] == [(tmp_path / folder, None,
                                                                         None)]
        assert words in problems[0].reason


def test_all_problems_of_all_files_in_one_error(tmp_path: Path) -> None:
    """Problems in several files are collected and raised together, each with its place."""
    spat = set_cell("spat.csv", 3, "q2_deg", "x").replace("2,15,25,-719.5,0,0,0", "2,15,25,0,0")
    bar = "from,to,length_mm,note\nA,B,-1,x\n"
    problems = problems_of(make(tmp_path, spat_csv=spat, bar_csv=bar))
    assert found(problems, "spat.csv", 3, "q2_deg", "not a number")
    assert found(problems, "spat.csv", 7, None, "5 cells")
    assert found(problems, "spat.csv", 5, "location", "location 2 has 2 samples")
    assert found(problems, "bar.csv", 1, "note", "unknown column")
    assert found(problems, "bar.csv", 2, "length_mm", "not a positive")
    assert len(problems) == 5


def test_read_readouts_ignores_other_columns(tmp_path: Path) -> None:
    """read_readouts takes the q columns of any CSV (e.g. lengthbar.csv), in rad."""
    path = tmp_path / "lengthbar.csv"
    path.write_text(GOOD["lengthbar.csv"].replace("socket", "socket,note").replace(",A,", ",A,x,")
                    .replace(",B,", ",B,y,"))
    q = read_readouts(path)
    np.testing.assert_allclose(q, np.radians(np.arange(1, 13).reshape(4, 3)), rtol=0, atol=DEG)


@pytest.mark.parametrize("text, line, column, words", [
    ("a,q1_deg,q3_deg\nx,1,2\n", 1, "q2_deg", "without gaps"),
    ("a,b\nx,1\n", 1, "q1_deg", "missing column"),
    ("q1_deg,q2_deg\n1,nan\n", 2, "q2_deg", "not a finite"),
    ("q1_deg,q2_deg\n1,800\n", 2, "q2_deg", "outside"),
    ("q1_deg,q1_deg\n1,2\n", 1, "q1_deg", "duplicated"),
    ("q1_deg\n", None, None, "header only"),
])
def test_read_readouts_validates_q_cells(tmp_path: Path, text: str, line: int | None,
                                         column: str | None, words: str) -> None:
    """read_readouts checks its q columns and cells like the campaign reader."""
    path = tmp_path / "readouts.csv"
    path.write_text(text)
    with pytest.raises(CampaignFormatError) as info:
        read_readouts(path)
    assert found(info.value.problems, "readouts.csv", line, column, words), info.value.problems


def test_write_points_in_mm(tmp_path: Path) -> None:
    """write_points writes (N, 3) m as x_mm,y_mm,z_mm with 9 decimals and rejects other shapes."""
    points = np.array([[0.1, -0.2, 0.000000001], [1.5, 0, 2]])
    write_points(tmp_path / "p.csv", points)
    lines = (tmp_path / "p.csv").read_text().splitlines()
    assert lines[:2] == ["x_mm,y_mm,z_mm", "100.000000000,-200.000000000,0.000001000"]
    np.testing.assert_allclose(np.loadtxt(tmp_path / "p.csv", delimiter=",", skiprows=1) / 1e3,
                               points, rtol=0, atol=MM)
    with pytest.raises(ValueError, match="points"):
        write_points(tmp_path / "q.csv", np.zeros((2, 2)))


def test_select_keeps_only_chosen_locations(tmp_path: Path) -> None:
    """select() keeps the samples, lines and zero positions of the chosen locations only."""
    c = read_campaign(make(tmp_path))
    one = c.select([2])
    assert one.location_ids == (2,) and list(one.locations) == [2]
    np.testing.assert_array_equal(one.spat.q, c.spat.q[3:])
    np.testing.assert_array_equal(one.spat.lines, [5, 6, 7])
    assert one.lengthbar is c.lengthbar and one.bar == c.bar
    for bad in ([], [3], [1, 9]):
        with pytest.raises(ValueError, match="locations"):
            c.select(bad)


def test_with_spat_replaces_fields_and_checks_shapes(tmp_path: Path) -> None:
    """with_spat() returns a new campaign with new readouts; the original is unchanged."""
    c = read_campaign(make(tmp_path))
    q = c.spat.q + 1e-3
    new = c.with_spat(q=q, temp=np.full(6, 20.0))
    np.testing.assert_array_equal(new.spat.q, q)
    np.testing.assert_array_equal(new.spat.displacement, c.spat.displacement)
    assert c.spat.temp is None and new.spat.temp.shape == (6,)
    with pytest.raises(ValueError, match="SpatLog.q"):
        c.with_spat(q=q[:, :2].ravel())
    with pytest.raises(ValueError, match="no SPAT"):
        read_campaign(make(tmp_path / "b", spat_csv=None, locations_csv=None)).with_spat(q=q)


def test_values_are_read_only_arrays(tmp_path: Path) -> None:
    """Campaign arrays cannot be changed in place (a campaign is a value)."""
    c = read_campaign(make(tmp_path))
    with pytest.raises(ValueError):
        c.spat.q[0, 0] = 1.0
    with pytest.raises(ValueError):
        c.locations[1][0] = 1.0


def test_campaign_built_in_code_is_checked() -> None:
    """Building a Campaign with inconsistent shapes or references raises ValueError."""
    spat = SpatLog([1, 1, 1], np.zeros((3, 7)), np.zeros((3, 3)))
    log = LengthBarLog([1, 1], ["A", "B"], np.zeros((2, 7)))
    assert Campaign(spat, {1: [0, 0, 0]}, log, {("A", "B"): 0.3}).n_axes == 7
    with pytest.raises(ValueError, match="displacement"):
        SpatLog([1, 1, 1], np.zeros((3, 7)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="SpatLog.t"):
        SpatLog([1, 1, 1], np.zeros((3, 7)), np.zeros((3, 3)), t=np.zeros(4))
    with pytest.raises(ValueError, match="one zero position"):
        Campaign(spat, {2: [0, 0, 0]}, None, {})
    with pytest.raises(ValueError, match="axes"):
        Campaign(spat, {1: [0, 0, 0]}, LengthBarLog([1], ["A"], np.zeros((1, 6))), {("A", "B"): 1})
    with pytest.raises(ValueError, match="axes"):
        Campaign(None, {}, None, {})
    with pytest.raises(ValueError, match="bar"):
        Campaign(spat, {1: [0, 0, 0]}, None, {("A", "B"): 0.3})


def test_write_refuses_a_folder_with_files_of_absent_parts(tmp_path: Path) -> None:
    """Writing a SPAT-only campaign over an old lengthbar.csv would mix campaigns: refused."""
    c = read_campaign(make(tmp_path / "old"))
    spat_only = Campaign(c.spat, c.locations, None, {})
    with pytest.raises(FileExistsError, match="lengthbar.csv"):
        write_campaign(spat_only, tmp_path / "old")
    write_campaign(spat_only, tmp_path / "new")
    assert sorted(p.name for p in (tmp_path / "new").iterdir()) == ["locations.csv", "spat.csv"]


def _spat_text(q_deg: np.ndarray) -> str:
    rows = [f"{1 + k % 2}," + ",".join(f"{v:.6f}" for v in q) + ",0,0,0"
            for k, q in enumerate(q_deg)]
    return "location,q1_deg,q2_deg,q3_deg,dx_mm,dy_mm,dz_mm\n" + "\n".join(rows) + "\n"


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_readouts_in_radians_are_reported_with_file_line_and_column(tmp_path: Path,
                                                                    seed: int) -> None:
    """A SPAT whose readouts were written in rad is refused; the same postures in deg are read."""
    q = np.random.default_rng(seed).uniform(-np.pi, np.pi, (40, 3)) * [1.0, 0.5, 0.8]
    problems = problems_of(make(tmp_path / "rad", spat_csv=_spat_text(q)))
    column = f"q{int(np.argmax(np.ptp(q, axis=0))) + 1}_deg"
    assert found(problems, "spat.csv", 2, column, "look like radians"), problems
    campaign = read_campaign(make(tmp_path / "deg", spat_csv=_spat_text(np.degrees(q))))
    assert campaign.spat is not None and np.allclose(campaign.spat.q, q, atol=1e-6)


def test_small_motions_and_short_files_are_not_taken_for_radians(tmp_path: Path) -> None:
    """An arm that does not move (all readouts equal) or a short file is not flagged as radians."""
    still = np.tile([1.0, 2.0, 3.0], (40, 1))
    assert read_campaign(make(tmp_path / "still", spat_csv=_spat_text(still))).spat is not None
    short = np.random.default_rng(0).uniform(-3, 3, (10, 3))
    assert read_campaign(make(tmp_path / "short", spat_csv=_spat_text(short))).spat is not None


def test_points_and_temperatures_beyond_plausible_magnitudes(tmp_path: Path) -> None:
    """Tracker coordinates of 1e300 mm, a sigma_um of 1e300 and temp_c of 1e300 are each reported."""
    points = ("q1_deg,q2_deg,q3_deg,x_mm,y_mm,z_mm,sigma_um,temp_c\n"
              "1,2,3,1e300,0,0,20,20\n4,5,6,0,0,0,1e300,20\n7,8,9,0,0,0,20,1e300\n"
              "10,11,12,0,0,1,20,20\n")
    problems = problems_of(make(tmp_path, points_csv=points))
    assert found(problems, "points.csv", 2, "x_mm", "beyond")
    assert found(problems, "points.csv", 3, "sigma_um", "plausible")
    assert found(problems, "points.csv", 4, "temp_c", "outside")
