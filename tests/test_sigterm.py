"""A stopped or killed command leaves no worker and no lock behind (issue 39, "a hang").

``aacmm-pin uncertainty --workers 2`` runs as a subprocess on a small campaign. Killed by SIGKILL,
its workers die with it (they kept working, and kept the output's lock, for minutes: the next run
was refused, naming a dead pid); sent SIGTERM, it stops as on Ctrl-C: one line, exit 143, workers
ended, no lock file, nothing written. ``identify`` stops the same way.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import aacmm_pin as ap
from aacmm_pin.data.output_claim import claim_output, lock_path
from aacmm_pin.errors import StaleOutputWarning

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}
pytestmark = pytest.mark.skipif(not Path(f"/proc/{os.getpid()}/task").is_dir(),
                                reason="reads a process's children from Linux /proc")


def _children(pid: int) -> set[int]:
    """Return the process ids of ``pid``'s children (empty once it is gone)."""
    out: set[int] = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out |= {int(c) for c in (task / "children").read_text().split()}
        except OSError:
            pass
    return out


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, ended but not reaped, does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory, process_sim: ap.Simulation) -> Path:
    """A small simulated campaign folder."""
    root = tmp_path_factory.mktemp("sigterm")
    ap.write_campaign(process_sim.campaign, root / "campaign")
    return root / "campaign"


def _start_uncertainty(campaign: Path, out: Path) -> tuple[subprocess.Popen[str], set[int]]:
    """Start uncertainty with 2 workers and many trials; return it and its workers once working."""
    proc = subprocess.Popen([sys.executable, "-m", "aacmm_pin", "uncertainty", str(campaign),
                             "--model", "dh", "--trials", "4000", "--workers", "2", "--out",
                             str(out)], cwd=out.parent, env=ENV, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    workers: set[int] = set()
    while len(workers) < 2 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
        workers = _children(proc.pid)
    assert len(workers) >= 2, f"no workers started (exit {proc.poll()})"
    time.sleep(1.0)  # the workers at their trials
    return proc, workers


def _gone_within(pids: set[int], seconds: float) -> set[int]:
    """Wait up to ``seconds`` for ``pids`` to end; return those still running."""
    deadline = time.monotonic() + seconds
    while (left := {p for p in pids if _alive(p)}) and time.monotonic() < deadline:
        time.sleep(0.05)
    return left


def test_killed_uncertainty_leaves_no_worker_and_the_output_free(campaign, tmp_path):
    """SIGKILL of uncertainty --workers 2: its workers end within 5 s (they ran on, each on its
    batch of 1,000 trials), and the next claim of its output succeeds at once."""
    out = tmp_path / "unc"
    proc, workers = _start_uncertainty(campaign, out)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    try:
        assert _gone_within(workers, 5.0) == set()
        with pytest.warns(StaleOutputWarning, match="took over the stale lock"), claim_output(out):
            pass  # refused on main: "another run is writing it (process <dead>)"
    finally:
        for pid in workers:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)


def test_sigterm_stops_uncertainty_as_ctrl_c_does(campaign, tmp_path):
    """SIGTERM: one line, exit 143, the workers ended, no lock file, no output (main: no word,
    the lock left behind)."""
    out = tmp_path / "unc"
    proc, workers = _start_uncertainty(campaign, out)
    proc.send_signal(signal.SIGTERM)
    try:
        _, err = proc.communicate(timeout=30)
        lines = [line for line in err.splitlines() if "still working" not in line
                 and not line.startswith(("Monte Carlo", "sizes:", "identif"))]
        assert lines == ["aacmm-pin uncertainty: terminated (SIGTERM)"], err
        assert proc.returncode == 143
        assert _gone_within(workers, 5.0) == set()
        assert not lock_path(out).exists() and not out.exists()
        assert [p.name for p in tmp_path.iterdir()] == []
    finally:
        for pid in workers:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)


def test_sigterm_stops_identify_as_ctrl_c_does(campaign, tmp_path):
    """SIGTERM once identify has claimed its output: one line, exit 143, nothing left."""
    out = tmp_path / "cal"
    proc = subprocess.Popen([sys.executable, "-m", "aacmm_pin", "identify", str(campaign),
                             "--out", str(out)], cwd=tmp_path, env=ENV,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not lock_path(out).exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert lock_path(out).exists(), f"identify never claimed its output (exit {proc.poll()})"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    lines = [line for line in err.splitlines() if "still working" not in line]
    assert lines == ["aacmm-pin identify: terminated (SIGTERM)"], err
    assert proc.returncode == 143
    assert [p.name for p in tmp_path.iterdir()] == []
