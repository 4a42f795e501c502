"""Output folders written whole or not at all, refused without --force; limits and OS errors."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.data.output_folder import OutputExistsError, output_folder
from aacmm_pin.errors import ArmModelError, FileFormatError
from aacmm_pin.model.arm import resolve_arm_path
from tests.helpers import ENV, run_cli


def tree(folder: Path) -> dict[str, bytes]:
    """Return relative path -> bytes of every file under ``folder``."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def test_output_folder_refuses_replaces_and_cleans_up(tmp_path):
    """Absent or empty: written; non-empty: refused unless force; a failed write leaves the old."""
    out = tmp_path / "out"
    with output_folder(out) as tmp:
        (tmp / "a.txt").write_text("old")
    assert tree(out) == {"a.txt": b"old"}
    with pytest.raises(OutputExistsError, match="exists and is not empty; give --force"):
        with output_folder(out):
            pass
    with pytest.raises(RuntimeError), output_folder(out, force=True) as tmp:
        (tmp / "b.txt").write_text("half")
        raise RuntimeError("killed mid-write")
    assert tree(out) == {"a.txt": b"old"}
    with output_folder(out, force=True) as tmp:
        (tmp / "b.txt").write_text("new")
    assert tree(out) == {"b.txt": b"new"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no temporary left
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputExistsError, match="not a folder"):
        with output_folder(tmp_path / "file", force=True):
            pass


WRITER = """
import shutil, sys
from pathlib import Path
from aacmm_pin.data.output_folder import output_folder
refs, out = [Path(p) for p in sys.argv[1:3]], Path(sys.argv[3])
k = 0
while True:
    with output_folder(out, force=True) as tmp:
        for f in sorted(refs[k % 2].iterdir()):
            (tmp / f.name).write_bytes(f.read_bytes())
    if k == 0:
        print("ready", flush=True)
    k += 1
"""


def kill_writes(tmp_path: Path, small_sim: ap.Simulation, n: int, seed: int) -> None:
    """SIGKILL a process rewriting a campaign folder in a loop ``n`` times at random moments."""
    refs = [tmp_path / "ref0", tmp_path / "ref1"]
    ap.write_simulation(small_sim, refs[0])
    ap.write_simulation(small_sim.__class__(small_sim.campaign.select([1, 2]), small_sim.truth,
                                            small_sim.sphere_mt[small_sim.campaign.spat.location
                                                                <= 2],
                                            small_sim.sockets_r), refs[1])
    expected = [tree(r) for r in refs]
    assert expected[0] != expected[1]
    rng = np.random.default_rng(seed)
    out = tmp_path / "out"
    for _ in range(n):
        proc = subprocess.Popen([sys.executable, "-c", WRITER, *map(str, refs), str(out)],
                                stdout=subprocess.PIPE, env=ENV, text=True)
        assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
        time.sleep(rng.uniform(0.0, 0.05))
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        assert tree(out) in expected  # the old or the new folder, never a mix
        assert ap.read_campaign(out).spat is not None


def test_killed_writes_leave_old_or_new_folder(tmp_path, small_sim):
    """A writer killed at 5 random moments leaves a complete, loadable folder each time."""
    kill_writes(tmp_path, small_sim, 5, seed=1)


@pytest.mark.slow
def test_killed_writes_leave_old_or_new_folder_many(tmp_path, small_sim):
    """The same, 40 kills."""
    kill_writes(tmp_path, small_sim, 40, seed=2)


def test_simulate_refuses_existing_output_without_force(tmp_path):
    """simulate into a campaign folder: exit 2 with a message; --force replaces it whole."""
    out = tmp_path / "camp"
    args = ["simulate", str(out), "--samples-per-location", "5", "--samples-per-socket", "2"]
    assert run_cli(args)[0] == 0
    (out / "notes.txt").write_text("mine")
    status, err = run_cli(args)
    assert status == 2 and f"{out}: exists and is not empty; give --force" in err
    assert (out / "notes.txt").exists()
    assert run_cli([*args, "--force", "--seed", "1"])[0] == 0
    assert not (out / "notes.txt").exists() and ap.read_campaign(out).spat is not None


@pytest.mark.parametrize("argv", [
    ["identify", "camp", "--step-deg", "0"], ["identify", "camp", "--step-deg", "nan"],
    ["identify", "camp", "--sigma-um", "-1"], ["simulate", "x", "--samples-per-location", "0"],
    ["uncertainty", "camp", "--trials", "0"], ["identify", "camp", "--max-nfev", "0"],
])
def test_nonsensical_numbers_are_refused_by_the_parser(argv):
    """--step-deg 0, NaN, negative sigmas, zero counts: exit 2 with a message, nothing runs."""
    status, err = run_cli(argv)
    assert status == 2 and "expected a finite number" in err


def test_os_errors_are_one_line_with_the_path(tmp_path):
    """A path under a file, a folder where a file should be: exit 2, one line naming the path."""
    blocker = tmp_path / "file"
    blocker.write_text("x")
    status, err = run_cli(["simulate", str(blocker / "camp"), "--samples-per-location", "5"])
    assert status == 2 and str(blocker) in err and len(err.strip().splitlines()) == 1
    readouts = tmp_path / "readouts.csv"
    readouts.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg\n0,0,0,0,0,0,0\n")
    params = tmp_path / "parameters.json"
    ap.write_parameters(ap.Parameters.nominal(ap.load_arm()), params)
    (tmp_path / "points_dir").mkdir()
    status, err = run_cli(["predict", str(params), str(readouts), "--out",
                           str(tmp_path / "points_dir")])
    assert status == 2 and str(tmp_path / "points_dir") in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_folder_is_one_line(tmp_path):
    """A read-only parent folder: exit 2, one line naming the path."""
    tmp_path.chmod(0o500)
    try:
        status, err = run_cli(["simulate", str(tmp_path / "camp"), "--samples-per-location", "5"])
    finally:
        tmp_path.chmod(0o700)
    assert status == 2 and str(tmp_path) in err and len(err.strip().splitlines()) == 1


def test_parameters_json_size_and_depth_are_capped(tmp_path):
    """/dev/zero, a huge file and deep nesting fail fast with a message naming the file."""
    tic = time.monotonic()
    with pytest.raises(FileFormatError, match="larger than 16 MiB"):
        ap.read_parameters("/dev/zero")
    assert time.monotonic() - tic < 5
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(FileFormatError, match=f"{deep}.*nested"):
        ap.read_parameters(deep)
    deep.write_text(json.dumps({"arm": "aacmm7", "dh": {}, "x": [[[[[[[[[[1]]]]]]]]]]}))
    with pytest.raises(FileFormatError, match="nested deeper than 8"):
        ap.read_parameters(deep)


def test_campaign_header_width_and_file_size_are_capped(tmp_path, monkeypatch):
    """A q1000000_deg column, a 10,000-column header and an oversized file: one message each."""
    from aacmm_pin.data import csv_table as cm

    folder = tmp_path / "camp"
    folder.mkdir()
    (folder / "locations.csv").write_text("location,x_mm,y_mm,z_mm\n1,0,0,0\n")
    (folder / "spat.csv").write_text("location,q1000000_deg,dx_mm,dy_mm,dz_mm\n1,0,0,0,0\n")
    tic = time.monotonic()
    with pytest.raises(FileFormatError, match="beyond q256_deg") as info:
        ap.read_campaign(folder)
    assert time.monotonic() - tic < 5 and len(str(info.value)) < 2000
    (folder / "spat.csv").write_text(",".join(f"c{k}" for k in range(10_000)) + "\n")
    with pytest.raises(FileFormatError, match="10000 columns in the header; at most 256"):
        ap.read_campaign(folder)
    monkeypatch.setattr(cm, "MAX_FILE_BYTES", 10)
    with pytest.raises(FileFormatError, match="spat.csv: larger than"):
        ap.read_campaign(folder)


def test_urdf_entities_are_refused(tmp_path):
    """An internal XML entity in a URDF (it could move a link unseen) is refused, with its line."""
    text = resolve_arm_path("aacmm7").read_text()
    head, rest = text.split("<robot", 1)
    rest = rest.replace('<origin xyz="0 0 0.1"', '<origin xyz="0 0 &off;"', 1)  # a link moves
    path = tmp_path / "entity.urdf"
    path.write_text(head + '<!DOCTYPE robot [<!ENTITY off "0.2">]>\n<robot' + rest)
    with pytest.raises(ArmModelError, match=r"line \d+, column \d+: the XML entity 'off' is "
                                            "declared"):
        ap.load_arm(path)


def test_calibration_urdf_is_resolved_in_its_folder_only(tmp_path, monkeypatch):
    """A calibration whose calibrated.urdf is missing fails; another URDF in the cwd is not used."""
    arm = ap.load_arm()
    cal = tmp_path / "cal"
    cal.mkdir()
    ap.write_parameters(ap.Parameters.nominal(arm).replace(arm="calibrated.urdf"),
                        cal / "parameters.json")
    cwd = tmp_path / "elsewhere"
    cwd.mkdir()
    (cwd / "calibrated.urdf").write_text(resolve_arm_path("aacmm7").read_text())
    monkeypatch.chdir(cwd)
    params = ap.read_parameters(cal)
    assert params.arm == str(cal / "calibrated.urdf")
    with pytest.raises(ArmModelError, match=str(cal / "calibrated.urdf")):
        ap.load_arm(params.arm)


def test_validate_checks_parameters_against_the_arm(tmp_path, small_sim):
    """validate refuses a map for axis 8 and a missing DH key, as predict does (exit 2)."""
    arm = ap.load_arm()
    ap.write_simulation(small_sim, tmp_path / "camp")
    data = ap.Parameters.nominal(arm).to_dict()
    data["dh"].pop(next(iter(data["dh"])))
    (tmp_path / "parameters.json").write_text(json.dumps(data))
    status, err = run_cli(["validate", str(tmp_path / "parameters.json"), str(tmp_path / "camp")])
    assert status == 2 and "missing" in err
