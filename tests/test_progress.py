"""Progress that tells the truth: counts and state, log lines when stderr is not a terminal."""

from __future__ import annotations

import io
import re

import aacmm_pin.progress as progress_module
from aacmm_pin.cli import main
from aacmm_pin.progress import Progress


def test_log_lines_count_without_a_fake_total(monkeypatch):
    """Not a terminal: a line per LOG_EVERY_S with the count and the state, and a last one."""
    monkeypatch.setattr(progress_module, "LOG_EVERY_S", 0.0)
    out = io.StringIO()
    with Progress("identify proposed", "evaluation", stream=out) as bar:
        for rms in (30.0, 2.5, 1.9):
            bar.update(rms_um=rms)
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("identify proposed: 1 evaluations, rms_um 30")
    assert lines[-1].startswith("identify proposed: 3 evaluations, rms_um 1.9")
    assert lines[-1].endswith("(done)")
    assert not any("/" in line.split(":")[1].split(",")[0] for line in lines)  # no total


def test_known_total_is_shown_and_disabled_is_silent(monkeypatch):
    monkeypatch.setattr(progress_module, "LOG_EVERY_S", 0.0)
    out = io.StringIO()
    with Progress("Monte Carlo", "trial", total=4, stream=out) as bar:
        bar.update(2)
    assert "Monte Carlo: 2/4 trials" in out.getvalue()
    quiet = io.StringIO()
    with Progress("x", "step", stream=quiet, enabled=False) as bar:
        bar.update(5)
    assert quiet.getvalue() == "" and bar.n == 5


def test_identify_command_logs_progress_when_piped(tmp_path, capsys, monkeypatch):
    """`aacmm-pin identify` into a pipe prints progress lines (evaluations, residual RMS)."""
    monkeypatch.setattr(progress_module, "LOG_EVERY_S", 0.0)
    assert main(["simulate", str(tmp_path / "c"), "--seed", "1"]) == 0
    capsys.readouterr()
    assert main(["identify", str(tmp_path / "c"), "--model", "dh", "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert re.search(r"identify dh: \d+ evaluations, rms_um [0-9.e+-]+, [0-9.]+ s", err), err


def test_a_reader_that_leaves_early_gets_no_traceback():
    """`aacmm-pin axes | head -0`: the pipe closes before the output; exit 1, stderr clean."""
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "aacmm_pin", "axes"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 1
    assert "Traceback" not in err and "BrokenPipe" not in err, err


def test_heartbeat_speaks_after_a_silence_and_gives_the_streams_back(monkeypatch, capsys):
    """A silent stretch longer than HEARTBEAT_S gets a "still working" line with the phase."""
    import sys
    import time

    from aacmm_pin.progress import Heartbeat, phase

    monkeypatch.setattr(progress_module, "HEARTBEAT_S", 0.2)
    monkeypatch.setattr(progress_module, "FIRST_BEAT_S", 0.2)
    before = sys.stdout, sys.stderr
    with Heartbeat("aacmm-pin demo"):
        print("started", end="")  # an open line: the heartbeat starts a new one
        phase("writing figures")
        time.sleep(0.7)
    assert (sys.stdout, sys.stderr) == before
    captured = capsys.readouterr()
    assert captured.out == "started"
    lines = captured.err.splitlines()
    assert lines and all(re.fullmatch(r"aacmm-pin demo: still working, writing figures, [0-9.]+ s",
                                      line) for line in lines if line), lines


def test_heartbeat_is_quiet_while_the_command_talks(monkeypatch, capsys):
    """Writes more often than HEARTBEAT_S (a progress log, prints) leave no heartbeat line."""
    import time

    from aacmm_pin.progress import Heartbeat

    monkeypatch.setattr(progress_module, "HEARTBEAT_S", 0.3)
    monkeypatch.setattr(progress_module, "FIRST_BEAT_S", 0.3)
    with Heartbeat("aacmm-pin plan"):
        for _ in range(10):
            print("candidate", flush=True)
            time.sleep(0.05)
    captured = capsys.readouterr()
    assert "still working" not in captured.err + captured.out


def test_idle_stops_the_heartbeat_before_a_server_waits(monkeypatch, capsys):
    import time

    from aacmm_pin.progress import Heartbeat, idle

    monkeypatch.setattr(progress_module, "HEARTBEAT_S", 0.1)
    monkeypatch.setattr(progress_module, "FIRST_BEAT_S", 0.1)
    with Heartbeat("aacmm-pin view"):
        idle()
        time.sleep(0.4)
    assert "still working" not in capsys.readouterr().err
