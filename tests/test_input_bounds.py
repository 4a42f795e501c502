"""Bounded readers (issue 24 items 7 and 11, issue 26 item 4): capped errors with a hint, bounded
memory, JSON keys named once and few enough, copied measurement rows refused."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.acquire.nest import read_nest
from aacmm_pin.data.campaign import NOISE_FILE, read_campaign
from aacmm_pin.data.json_file import MAX_OBJECT_KEYS
from aacmm_pin.data.logs import read_noise
from aacmm_pin.data.problem_log import MAX_LIKE, MAX_SHOWN
from aacmm_pin.errors import CampaignFormatError, CampaignWarning, FileFormatError
from aacmm_pin.model.parameters import check_against_arm, read_parameters
from aacmm_pin.model.sizes import read_sizes
from aacmm_pin.outputs.calibration_folder import read_report

SAMPLE = Path(__file__).resolve().parents[2] / "shared" / "sample-campaign"


@pytest.fixture
def sample(tmp_path: Path) -> Path:
    """A copy of the sample campaign (800 SPAT samples, 420 length-bar readouts)."""
    return Path(shutil.copytree(SAMPLE, tmp_path / "campaign",
                                ignore=shutil.ignore_patterns("truth.json")))


def _problems(folder: Path) -> list[ap.errors.Problem]:
    with pytest.raises(CampaignFormatError) as info:
        read_campaign(folder)
    return info.value.problems


def _of(problems: list[ap.errors.Problem], name: str) -> list[ap.errors.Problem]:
    return [p for p in problems if Path(p.path).name == name]


def _bad_rows(folder: Path, n: int) -> int:
    """Replace spat.csv's rows by ``n`` one-cell rows; return the file's size, bytes."""
    path = folder / "spat.csv"
    path.write_text(path.read_text().splitlines()[0] + "\n" + "x\n" * n)
    return path.stat().st_size


def test_a_flood_of_bad_rows_gives_a_few_lines_and_a_count(sample: Path) -> None:
    """20,000 rows of one bad kind: the first few shown, the others counted in one line."""
    n = 20_000
    size = _bad_rows(sample, n)
    tracemalloc.start()
    try:
        problems = _problems(sample)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(problems) == MAX_LIKE + 1, problems[:10]
    assert all("1 cells, but the header has 11 columns" in p.reason for p in problems[:MAX_LIKE])
    assert problems[-1].line == MAX_LIKE + 2  # the first row left out
    assert f"{n - MAX_LIKE:,} more rows like it (to line {n + 1})" in problems[-1].reason
    assert str(CampaignFormatError(problems)).startswith(
        f"{n:,} problems in input files ({MAX_LIKE + 1} lines):")  # the count is every row
    # Nothing kept per row: the file's bytes, its text, the csv reader's buffer (a few times
    # the size) and the other files of the campaign, read whole (1 MB of the sample); storing
    # a problem per row takes about 300 bytes a row, 150 times this file's 2 bytes a row.
    assert peak < 16 * size + 4 * 2**20, f"peak {peak / 2**20:.1f} MiB for a {size} byte file"


def test_a_file_separated_by_semicolons_gives_one_line_naming_the_separator(sample: Path) -> None:
    """A spreadsheet's export with ';' and decimal commas: one line that says so (807 on main)."""
    path = sample / "spat.csv"
    path.write_text(path.read_text().replace(",", ";").replace(".", ","))
    problems = _of(_problems(sample), "spat.csv")
    assert len(problems) == 1 and problems[0].line == 1
    assert "separated by ';'" in problems[0].reason and "12.5, not 12,5" in problems[0].reason


def test_displacements_in_um_give_a_few_lines_with_the_unit_hint(sample: Path) -> None:
    """dx_mm..dz_mm written in um: a few cells shown with 'in um?', the rest counted (1,755 lines
    on main)."""
    path = sample / "spat.csv"
    with path.open() as f:
        rows = list(csv.reader(f))
    cols = [rows[0].index(c) for c in ("dx_mm", "dy_mm", "dz_mm")]
    for row in rows[1:]:
        for k in cols:
            row[k] = repr(float(row[k]) * 1e3)
    with path.open("w", newline="") as f:
        csv.writer(f).writerows(rows)
    problems = _problems(sample)
    assert len(problems) == MAX_LIKE + 1, problems
    assert all("in um? write mm" in p.reason for p in problems[:MAX_LIKE])
    assert "more cells like it (dx_mm, dy_mm, dz_mm; to line 801)" in problems[-1].reason


def test_readout_columns_without_their_unit_are_named_once_with_a_guess(sample: Path) -> None:
    """q1..q7 instead of q1_deg..q7_deg: 'did you mean', and the expected list once per file."""
    for name in ("spat.csv", "lengthbar.csv"):
        path = sample / name
        head, rest = path.read_text().split("\n", 1)
        path.write_text(head.replace("_deg", "") + "\n" + rest)
    problems = _problems(sample)
    assert len(problems) == 4, problems  # per file: q1_deg missing, the unknown columns
    unknown = [p for p in problems if "unknown" in p.reason]
    assert len(unknown) == 2 and all(
        "did you mean q1_deg, q2_deg, q3_deg, q4_deg, q5_deg, q6_deg, q7_deg?" in p.reason
        and p.reason.count("expected:") == 1 for p in unknown), unknown


def test_many_bad_rows_of_many_kinds_stay_within_the_file_cap(sample: Path) -> None:
    """A bad value in every cell of every row: at most MAX_SHOWN problems and one count a kind."""
    path = sample / "spat.csv"
    lines = path.read_text().splitlines()
    width = len(lines[0].split(","))
    path.write_text("\n".join([lines[0]] + [",".join(["abc"] * width)] * 2000) + "\n")
    problems = _of(_problems(sample), "spat.csv")
    assert len(problems) <= MAX_SHOWN + 2, len(problems)
    assert "more cells like it" in problems[-1].reason


# ------------------------------------------------------------------ JSON files


def _write_json_text(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _parameters_text(folder: Path) -> str:
    arm = ap.load_arm()
    params = ap.Parameters.nominal(arm)
    ap.write_parameters(params, folder / "parameters.json")
    return (folder / "parameters.json").read_text()


def test_a_key_given_twice_in_parameters_json_is_refused(tmp_path: Path) -> None:
    """json keeps the last of two equal keys silently; the reader names the file and the key."""
    text = _parameters_text(tmp_path)
    first = text.index('"dh": {') + len('"dh": {')
    doubled = text[:first] + '\n    "dx21": 0.5,' + text[first:]  # dx21 is also further down
    path = _write_json_text(tmp_path / "parameters.json", doubled)
    with pytest.raises(FileFormatError) as info:
        read_parameters(path)
    assert len(info.value.problems) == 1
    problem = info.value.problems[0]
    assert problem.path == path and problem.column == "dx21" and "twice" in problem.reason


@pytest.mark.parametrize("reader, text", [
    (read_sizes, '{"units": "SI", "dh_angle": 1e-4, "dh_angle": 2e-4}'),
    (read_noise, '{"noise_um": {"rtest": 2.0, "rtest": 20.0}}'),
    (read_nest, '{"directions": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], '
                '"directions": [[0, 1, 0], [1, 0, 0], [0, 0, 1]]}'),
], ids=["sizes", "campaign.json", "nest"])
def test_a_key_given_twice_is_refused_in_every_json_file(tmp_path: Path, reader: object,
                                                          text: str) -> None:
    path = _write_json_text(tmp_path / "file.json", text)
    with pytest.raises(FileFormatError, match="file.json: column '[a-z_]+': key given twice"):
        reader(path)  # type: ignore[operator]


def test_a_key_given_twice_in_report_json_is_refused_not_ignored(tmp_path: Path) -> None:
    """report.json holds the accuracy validate judges by: an ambiguous one is refused."""
    _parameters_text(tmp_path)
    (tmp_path / "report.json").write_text('{"sigma_um": 2.0, "sigma_um": 200.0}')
    with pytest.raises(FileFormatError, match="report.json: column 'sigma_um': key given twice"):
        read_report(tmp_path)


def test_thousands_of_unknown_dh_keys_are_refused_at_once(tmp_path: Path) -> None:
    """More keys in one object than any file of the package needs: refused while reading."""
    text = _parameters_text(tmp_path)
    first = text.index('"dh": {') + len('"dh": {')
    junk = "".join(f'"junk{k}": 0.0, ' for k in range(2 * MAX_OBJECT_KEYS))
    path = _write_json_text(tmp_path / "parameters.json", text[:first] + junk + text[first:])
    with pytest.raises(FileFormatError) as info:
        read_parameters(path)
    assert len(info.value.problems) == 1 and "keys" in info.value.problems[0].reason


def test_unknown_dh_keys_are_listed_once_with_a_guess(tmp_path: Path) -> None:
    """A few hundred unknown keys: a few shown (the first with the arm's frames), then a count."""
    arm = ap.load_arm()
    params = ap.Parameters.nominal(arm)
    dh = {**params.dh, "dx_21": 0.0, **{f"junk{k}": 0.0 for k in range(300)}}
    with pytest.raises(FileFormatError) as info:
        check_against_arm(params.replace(dh=dh), arm)
    problems = info.value.problems
    assert len(problems) == MAX_LIKE + 1, problems
    assert problems[0].column == "dh.dx_21" and "did you mean dx21?" in problems[0].reason
    assert sum("error frames:" in p.reason for p in problems) == 1
    assert "296 more keys like it" in problems[-1].reason


@pytest.mark.slow
def test_a_million_unknown_dh_keys_are_refused_fast(tmp_path: Path) -> None:
    """The issue's case: 1,000,000 unknown dh keys took 32 s and 1.3 GB on main."""
    text = _parameters_text(tmp_path)
    first = text.index('"dh": {') + len('"dh": {')
    junk = "".join(f'"k{k}":0,' for k in range(1_000_000))
    path = _write_json_text(tmp_path / "parameters.json", text[:first] + junk + text[first:])
    start = time.process_time()
    with pytest.raises(FileFormatError, match="keys"):
        read_parameters(path)
    assert time.process_time() - start < 10.0  # parsing 10 MB of JSON takes about 1 s


# ------------------------------------------------------------------ copied rows


@pytest.mark.parametrize("name", ["spat.csv", "lengthbar.csv"])
def test_a_row_copied_ten_times_is_noted_with_its_lines(sample: Path, name: str) -> None:
    """The same row 10 times would shrink the claimed std silently: a note and a warning name the
    file, the lines and the count (not refused: a static arm read twice in one clock tick gives
    equal rows, as acquire writes them)."""
    assert read_campaign(sample).notes == ()
    path = sample / name
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:11] + [lines[10]] * 9 + lines[11:]) + "\n")
    with pytest.warns(CampaignWarning) as caught:
        campaign = read_campaign(sample)
    assert len(campaign.notes) == 1 and str(caught[0].message) == campaign.notes[0]
    note = campaign.notes[0]
    assert note.startswith(f"{path}:12: 9 row(s) repeat") and "line 11" in note
    assert "10 copies" in note


def test_a_copied_point_row_is_noted_and_equal_timed_rows_are_not(tmp_path: Path) -> None:
    """points.csv: a copy noted; equal readouts at distinct times are distinct readings."""
    rng = np.random.default_rng(0)
    rows = [[*rng.uniform(-90, 90, 6).round(6), *rng.uniform(-500, 500, 3).round(6)]
            for _ in range(30)]
    header = [f"q{i}_deg" for i in range(1, 7)] + ["x_mm", "y_mm", "z_mm"]
    folder = tmp_path / "copied"
    folder.mkdir()
    with (folder / "points.csv").open("w", newline="") as f:
        csv.writer(f).writerows([header, *rows, rows[4]])
    with pytest.warns(CampaignWarning, match=r"points.csv:32: 1 row\(s\) repeat .*line 6"):
        read_campaign(folder)
    timed = tmp_path / "timed"
    timed.mkdir()
    with (timed / "points.csv").open("w", newline="") as f:
        csv.writer(f).writerows([[*header, "t_s"], *[[*r, k] for k, r in enumerate(rows + [rows[4]])]])
    assert read_campaign(timed).notes == ()


@pytest.mark.slow
def test_three_million_bad_rows_in_bounded_memory(tmp_path: Path) -> None:
    """The issue's case: a 6 MB file of 3,000,000 bad rows (main: 1.48 GB, 3,000,001 lines)."""
    folder = Path(shutil.copytree(SAMPLE, tmp_path / "campaign"))
    _bad_rows(folder, 3_000_000)
    # peak RSS of this process alone: VmHWM (ru_maxrss would include pytest's, kept over fork)
    code = ("import sys, aacmm_pin as ap\n"
            "try:\n    ap.read_campaign(sys.argv[1])\n"
            "except ap.AacmmError as exc:\n    print(str(exc).count(chr(10)) + 1)\n"
            "print(next(line.split()[1] for line in open('/proc/self/status')\n"
            "           if line.startswith('VmHWM')))\n")
    out = subprocess.run([sys.executable, "-c", code, str(folder)], capture_output=True,
                         text=True, check=True).stdout.split()
    lines, rss_kib = int(out[0]), int(out[1])
    assert lines == MAX_LIKE + 2  # the head line, the shown problems, the count
    # the 6 MB file's bytes and text plus numpy and the package: about 60 MB measured
    assert rss_kib < 200 * 1024, f"max RSS {rss_kib / 1024:.0f} MiB"


def test_campaign_json_is_read_as_before(tmp_path: Path) -> None:
    """The strict reader reads a good campaign.json as json does."""
    path = tmp_path / NOISE_FILE
    path.write_text(json.dumps({"noise_um": {"rtest": 2.5, "point": 15.0}}))
    noise = read_noise(path)
    assert noise.rtest == pytest.approx(2.5e-6) and noise.point == pytest.approx(15e-6)


def test_the_cli_prints_a_copied_row_note_as_one_line(sample: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """On the command line the note is one line of its own, not Python's warning with a source line."""
    from aacmm_pin.cli import main

    path = sample / "spat.csv"
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:11] + [lines[10]] * 2 + lines[11:]) + "\n")
    assert main(["identify", str(sample), "--model", "dh", "--out", str(tmp_path / "cal")]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "repeat" in line]
    assert len(err) == 1 and err[0].startswith(f"aacmm-pin identify: warning: {path}:12: 2 row(s)")
