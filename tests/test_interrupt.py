"""Ctrl-C (SIGINT) in a working command: one line on stderr, exit 130, nothing partial (issue 26, 8).

``aacmm-pin identify`` and ``aacmm-pin discover`` run as subprocesses on a small campaign; SIGINT
is sent once the command has claimed its output folder (its ``.<name>.lock`` beside it exists: the
work has started). The command must end with ``aacmm-pin <command>: interrupted`` as the one line
on stderr that is not a heartbeat, exit status 130 (128 + SIGINT), no output folder and no lock
file left.
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

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.usefixtures("sigint_as_from_a_terminal")

ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory, process_sim: ap.Simulation) -> Path:
    """A small simulated campaign folder."""
    root = tmp_path_factory.mktemp("interrupt")
    ap.write_campaign(process_sim.campaign, root / "campaign")
    return root / "campaign"


@pytest.mark.parametrize("command", ["identify", "discover"])
def test_ctrl_c_ends_with_one_line_and_130(command: str, campaign: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    lock = tmp_path / ".out.lock"
    proc = subprocess.Popen([sys.executable, "-m", "aacmm_pin", command, str(campaign),
                             "--out", str(out)], cwd=tmp_path, env=ENV,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not lock.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert lock.exists(), f"{command} never claimed its output (exit {proc.poll()})"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    lines = [line for line in err.splitlines() if "still working" not in line]
    assert lines == [f"aacmm-pin {command}: interrupted"], err
    assert proc.returncode == 130
    assert not out.exists()
    assert not lock.exists()
    assert [p.name for p in tmp_path.iterdir()] == []  # no temporary folder beside it either


def test_ctrl_c_turned_into_another_error_is_still_an_interrupt(monkeypatch, capsys) -> None:
    """Ctrl-C inside an import of a C extension can surface as another error (numpy raises an
    ImportError about a bad install): the command still says "interrupted" and exits 130. An
    error without Ctrl-C is not taken for one."""
    from aacmm_pin import cli

    def interrupted_import(args, name, beat):  # noqa: ANN001, ANN202
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1)  # the signal is handled at the next bytecode
        except KeyboardInterrupt as exc:
            raise ImportError("Importing the numpy C-extensions failed.") from exc
        raise AssertionError("SIGINT did not raise KeyboardInterrupt")

    monkeypatch.setattr(cli, "_run", interrupted_import)
    before = signal.getsignal(signal.SIGINT)
    assert cli.main(["axes"]) == 130
    assert capsys.readouterr().err == "aacmm-pin axes: interrupted\n"
    assert signal.getsignal(signal.SIGINT) is before  # restored

    def plain_error(args, name, beat):  # noqa: ANN001, ANN202
        raise ImportError("a real one")

    monkeypatch.setattr(cli, "_run", plain_error)
    with pytest.raises(ImportError, match="a real one"):
        cli.main(["axes"])


def test_an_ignored_ctrl_c_stays_ignored(monkeypatch) -> None:
    """A command started with SIGINT ignored (a script's background job) keeps it ignored: the
    CLI puts no handler of its own in its place."""
    from aacmm_pin import cli

    seen = []
    monkeypatch.setattr(cli, "_run", lambda args, name, beat: seen.append(
        signal.getsignal(signal.SIGINT)) or 0)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    assert cli.main(["axes"]) == 0
    assert seen == [signal.SIG_IGN]
    assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN
