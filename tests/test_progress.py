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
    assert main(["simulate", str(tmp_path / "c"), "--seed", "1", "--samples-per-location", "15",
                 "--samples-per-socket", "5"]) == 0  # a small campaign: progress at any size
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


def _read_until(capsys, beat, done, timeout_s: float = 10.0) -> tuple[str, str]:
    """What the test has printed (stdout, stderr), read under ``beat``'s lock every 20 ms until
    ``done(err)`` holds or ``timeout_s`` has passed (a loaded machine may stall a thread ~0.5 s)."""
    import time

    out = err = ""
    deadline = time.monotonic() + timeout_s
    while not done(err) and time.monotonic() < deadline:
        time.sleep(0.02)
        with beat.lock:  # not in the middle of a heartbeat's line
            captured = capsys.readouterr()
        out, err = out + captured.out, err + captured.err
    return out, err


def test_heartbeat_speaks_after_a_silence_and_gives_the_streams_back(monkeypatch, capsys):
    """A silent stretch longer than HEARTBEAT_S gets a "still working" line with the phase, and
    another after each further HEARTBEAT_S; a line left open on stderr is ended first."""
    import sys

    from aacmm_pin.progress import Heartbeat, phase

    monkeypatch.setattr(progress_module, "HEARTBEAT_S", 0.2)
    monkeypatch.setattr(progress_module, "FIRST_BEAT_S", 0.2)
    before = sys.stdout, sys.stderr
    with Heartbeat("aacmm-pin demo") as beat:
        print("table", flush=True)
        print("reading ...", end="", file=sys.stderr)  # an open line
        phase("writing figures")
        out, err = _read_until(capsys, beat, lambda err: err.count("still working") >= 2)
    assert (sys.stdout, sys.stderr) == before
    captured = capsys.readouterr()
    out, err = out + captured.out, err + captured.err
    assert out == "table\n"
    first, *beats = err.split("\n")
    assert first == "reading ..." and beats[-1] == "" and len(beats) >= 3, err
    assert all(re.fullmatch(r"aacmm-pin demo: still working, writing figures, [0-9.]+ s", b)
               for b in beats[:-1]), beats


def test_heartbeat_is_quiet_while_the_command_talks_or_counts(monkeypatch, capsys):
    """Writes, and a Progress that counts work (its log line comes first), leave no heartbeat
    line.

    Each stretch lasts 1 s, longer than HEARTBEAT_S = 0.6 s (a heartbeat that missed the writes
    or spoke before the Progress would speak in it); the writes and updates come every 0.05 s, so
    a stall of the test's thread shorter than 0.55 s leaves no silence of HEARTBEAT_S.
    """
    import time

    from aacmm_pin.progress import Heartbeat

    monkeypatch.setattr(progress_module, "HEARTBEAT_S", 0.6)
    monkeypatch.setattr(progress_module, "FIRST_BEAT_S", 0.6)
    monkeypatch.setattr(progress_module, "LOG_EVERY_S", 0.1)  # after 0.1 s of silence
    with Heartbeat("aacmm-pin plan"):
        start = time.monotonic()
        while time.monotonic() - start < 1.0:
            print("candidate", flush=True)
            time.sleep(0.05)
        start = time.monotonic()
        with Progress("identify", "evaluation") as bar:  # its stream: the wrapped stderr
            while time.monotonic() - start < 1.0:
                bar.update(rms_um=2.0)
                time.sleep(0.05)
    captured = capsys.readouterr()
    assert "still working" not in captured.err + captured.out
    assert "identify: " in captured.err  # the log lines themselves


def test_idle_stops_the_heartbeat_and_heartbeats_nest(monkeypatch, capsys):
    import time

    from aacmm_pin.progress import Heartbeat, idle, phase

    monkeypatch.setattr(progress_module, "HEARTBEAT_S", 0.1)
    monkeypatch.setattr(progress_module, "FIRST_BEAT_S", 0.1)
    with Heartbeat("aacmm-pin view"):
        idle()
        time.sleep(0.4)
    assert "still working" not in capsys.readouterr().err
    with Heartbeat("outer") as outer:
        with Heartbeat("inner"):
            pass
        phase("after the inner one")
        assert outer.phase == "after the inner one" and progress_module._current is outer
    assert progress_module._current is None


def _child_streams() -> tuple[str, bool]:
    import sys

    print("a worker may print", file=sys.stderr)
    return type(sys.stderr).__name__, progress_module._current is None


def test_a_forked_worker_starts_without_the_heartbeat(monkeypatch):
    """A worker process forked while the heartbeat runs gets the plain streams and no lock."""
    import multiprocessing

    from aacmm_pin.progress import Heartbeat

    monkeypatch.setattr(progress_module, "HEARTBEAT_S", 0.05)
    with Heartbeat("aacmm-pin uncertainty"), \
            multiprocessing.get_context("fork").Pool(1) as pool:
        name, none = pool.apply(_child_streams)
    assert name != "_Stamped" and none
