"""Killing a write at a random moment leaves the old output or the new one, never a mix (issue 14).

``aacmm-pin identify`` and ``aacmm-pin simulate`` are run as subprocesses and killed with SIGKILL
after a seeded random delay (from before Python has started to after the write). Afterwards the
output folder is absent (when there was none), the old one exactly, or a complete new one that
loads; nothing but hidden ``.<name>.*.tmp`` folders is left beside it. ``aacmm-pin acquire``
against ``aacmm-pin fake-devices`` is killed the same way: ``spat.csv`` holds whole rows only, each
of a location ``locations.csv`` knows, and the campaign reads. A few kills run by default, more
with ``-m slow``.
"""

from __future__ import annotations

import filecmp
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import aacmm_pin as ap

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}


def _start(*args: str, cwd: Path) -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-m", "aacmm_pin", *args], cwd=cwd, env=ENV,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def _kill_after(proc: subprocess.Popen[bytes], delay: float | None) -> int | None:
    """Kill ``proc`` with SIGKILL after ``delay`` s (None: never) unless it ended; return its exit
    code then."""
    try:
        return proc.wait(timeout=delay)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        return None


def _delay(rng: np.random.Generator, full: float) -> float:
    """A kill moment: anywhere in the run, or (half the time) near its end, where it writes."""
    return full * float(rng.uniform(0.0, 1.1) if rng.random() < 0.5 else rng.uniform(0.85, 1.05))


def _same_tree(a: Path, b: Path) -> bool:
    cmp = filecmp.dircmp(a, b)
    return (not cmp.left_only and not cmp.right_only and not cmp.funny_files
            and all(filecmp.cmp(a / f, b / f, shallow=False) for f in cmp.common_files))


def _visible(parent: Path) -> set[str]:
    return {p.name for p in parent.iterdir() if not p.name.startswith(".")}


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory, arm: ap.Arm,
             process_sim: ap.Simulation) -> Path:
    """A small campaign folder and, beside it, a reference calibration (dh model)."""
    root = tmp_path_factory.mktemp("kill")
    ap.write_campaign(process_sim.campaign, root / "campaign")
    cal = ap.identify(ap.read_campaign(root / "campaign", arm=arm), arm, "dh")
    ap.write_calibration(cal, arm, root / "old_cal")  # the "old" output: another model
    return root / "campaign"


def _timed(args: list[str], cwd: Path) -> float:
    """Run a command to its end; return its wall time."""
    t0 = time.monotonic()
    proc = _start(*args, cwd=cwd)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode in (0, 1), err.decode()
    return time.monotonic() - t0


def _kill_over(old: Path, what: str, work: Path, name: str, command: Callable[[Path], list[str]],
               full: float, seed: int, n: int, check_new: Callable[[Path], None],
               codes: tuple[int | None, ...], ends: bool = False) -> list[str]:
    """Kill ``aacmm-pin command(out)`` n times at a random moment, over a copy of ``old`` (70 %)
    or into no folder; return each outcome ("old", "new" or "none"), never a mix.

    ``full`` is the uninterrupted run's time; ``check_new`` asserts that ``out`` is the new output,
    whole; ``codes`` are the exit statuses a run that was not killed may have. ``ends``: first two
    runs over ``old`` whose outcome does not depend on how fast the probe ran, one killed at once
    (must leave "old") and one not killed (must give "new"); then the n random ones.
    """
    rng = np.random.default_rng(seed)
    outcomes = []

    def one(i: int, existed: bool, delay: float | None) -> str:
        parent = work / f"{name}{i}"
        parent.mkdir()
        out = parent / name
        if existed:
            subprocess.run(["cp", "-a", str(old), str(out)], check=True)
        code = _kill_after(_start(*command(out), cwd=parent), delay)
        assert _visible(parent) <= {name}, f"stray output beside {out}: {_visible(parent)}"
        if not out.exists():
            assert not existed, f"kill #{i}: the old {what} is gone"
            outcome = "none"
        elif existed and _same_tree(out, old):
            outcome = "old"
        else:  # the new one, whole
            check_new(out)
            outcome = "new"
        assert code in codes
        return outcome

    if ends:
        assert one(n, True, 0.0) == "old", f"killed at once, the old {what} changed"
        assert one(n + 1, True, None) == "new", f"not killed, the old {what} stayed"
        outcomes += ["old", "new"]
    for i in range(n):
        existed = rng.random() < 0.7
        outcomes.append(one(i, existed, _delay(rng, full)))
    return outcomes


def kill_identify(campaign: Path, work: Path, seed: int, n: int, ends: bool = False) -> list[str]:
    """Kill ``identify --force`` over an old calibration (and into no folder) n times (``ends``:
    see :func:`_kill_over`)."""
    args = ["identify", str(campaign), "--model", "proposed", "--force"]

    def new_calibration(out: Path) -> None:
        params = ap.read_parameters(out)
        assert params.encoder_maps, f"{out} is not the new (proposed) calibration"
        assert {p.name for p in out.iterdir()} == {"parameters.json", "calibrated.urdf",
                                                   "compact.json", "compact.urdf",
                                                   "encoder_maps.csv", "report.json"}

    return _kill_over(campaign.parent / "old_cal", "calibration", work, "cal",
                      lambda out: [*args, "--out", str(out)],
                      _timed([*args, "--out", str(work / "probe")], work), seed, n,
                      new_calibration, (None, 0, 1), ends)


def kill_simulate(campaign: Path, work: Path, seed: int, n: int, ends: bool = False) -> list[str]:
    """Kill ``simulate --force`` over an old campaign (and into no folder) n times (``ends``: see
    :func:`_kill_over`)."""
    args = ["simulate", "--samples-per-location", "30", "--samples-per-socket", "5", "--seed",
            "7", "--force"]

    def new_campaign(out: Path) -> None:
        camp = ap.read_campaign(out)
        assert camp.spat is not None and len(camp.spat.location) == 4 * 30
        assert (out / "truth.json").is_file() and (out / "truth_sockets.csv").is_file()

    return _kill_over(campaign, "campaign", work, "camp", lambda out: [*args, str(out)],
                      _timed([*args, str(work / "probe_sim")], work), seed, n, new_campaign,
                      (None, 0), ends)


@pytest.fixture(scope="module")
def fake_devices(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """A fake-devices process (location 1, Heidenhain gauges); yields its JSON description."""
    folder = tmp_path_factory.mktemp("fakes")
    path = folder / "fake.json"
    with (folder / "fake.log").open("w") as log:
        proc = subprocess.Popen([sys.executable, "-m", "aacmm_pin", "fake-devices", "--location",
                                 "1", "--effects", "dh,rtest", "--rate-hz", "500", "--dwell-s",
                                 "0.1", "--seconds", "300", "--json", str(path)],
                                stdout=log, stderr=subprocess.STDOUT, env=ENV, cwd=ROOT)
    deadline = time.monotonic() + 30
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert path.exists(), "fake-devices did not start"
    time.sleep(0.2)  # the JSON is written whole before the ports play
    yield json.loads(path.read_text())
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=10)


def kill_acquire(devices: Any, work: Path, seed: int, n: int) -> list[int]:
    """Kill ``acquire`` into one campaign n times, each run appending to what the last left.

    After every kill spat.csv holds whole rows only (the kept file of the previous kill as its
    prefix, bar an incomplete last line the next run removes and reports), every row's location
    has its zero in locations.csv, and the campaign reads; returns the rows after each kill.
    """
    rng = np.random.default_rng(seed)
    folder = work / "acquired"
    spat = folder / "spat.csv"
    before = b""
    rows = []
    for i in range(n):
        proc = _start("acquire", str(folder), *devices["acquire_args"], "--timeout-s", "0.1",
                      "--poll-hz", "500", "--fsync-s", "0.05", "--quiet", cwd=work)
        code = _kill_after(proc, float(rng.uniform(0.0, 4.0)))
        assert code is None, proc.stderr.read().decode() if proc.stderr else code
        proc.stderr.close() if proc.stderr else None
        assert _visible(work) <= {"acquired"}
        if not spat.exists() or spat.stat().st_size == 0:
            assert not before, f"kill #{i}: spat.csv lost its rows"
            rows.append(0)
            continue
        now = spat.read_bytes()
        complete = now[:now.rfind(b"\n") + 1]
        assert complete.startswith(before), f"kill #{i}: earlier rows changed"
        lines = complete.decode().splitlines()
        width = len(lines[0].split(","))
        assert all(len(line.split(",")) == width for line in lines), f"kill #{i}: a broken row"
        if len(lines) > 1:
            camp = ap.read_campaign(folder, min_samples_per_location=1)
            assert camp.spat is not None and len(camp.spat.location) == len(lines) - 1
        before = complete
        rows.append(len(lines) - 1)
    return rows


def test_kill_acquire(fake_devices: Any, tmp_path: Path) -> None:
    rows = kill_acquire(fake_devices, tmp_path, seed=14, n=2)  # more in test_kill_acquire_many
    assert rows == sorted(rows)


def test_kill_identify(campaign: Path, tmp_path: Path) -> None:
    outcomes = kill_identify(campaign, tmp_path, seed=14, n=3)
    assert len(outcomes) == 3


def test_kill_simulate(campaign: Path, tmp_path: Path) -> None:
    outcomes = kill_simulate(campaign, tmp_path, seed=14, n=1)  # more in test_kill_many
    assert len(outcomes) == 1


@pytest.mark.slow
def test_kill_many(campaign: Path, tmp_path: Path) -> None:
    outcomes = kill_identify(campaign, tmp_path, seed=1, n=25, ends=True)
    outcomes += kill_simulate(campaign, tmp_path, seed=1, n=25, ends=True)
    print({k: outcomes.count(k) for k in set(outcomes)})
    assert {"old", "new"} <= set(outcomes)  # both ends were hit (whatever the probe's time)


@pytest.mark.slow
def test_kill_acquire_many(fake_devices: Any, tmp_path: Path) -> None:
    rows = kill_acquire(fake_devices, tmp_path, seed=1, n=20)
    print("rows after each kill:", rows)
    assert rows == sorted(rows) and rows[-1] > 0
