"""The output claim loses nothing: no link followed, no file written it did not make (issue 39).

A lock path that holds something else (a link to a campaign file, a hard link) is refused and left
as it is; a lock whose holder is gone, even one its orphaned children keep, is taken over in one
line; what a killed run left beside an output (hidden ``.<name>.<pid>.*.tmp``) is removed.
"""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import aacmm_pin as ap
from aacmm_pin.data.output_claim import OutputExistsError, claim_output, lock_path
from aacmm_pin.data.output_file import output_file
from aacmm_pin.errors import StaleOutputWarning
from tests.helpers import run_cli

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="links, flock and fork are POSIX")


def _dead_pid() -> int:
    """Return the process id of a process that has ended (and was reaped)."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


@pytest.fixture
def campaign(tmp_path: Path, small_sim: ap.Simulation) -> Path:
    """A small simulated campaign folder."""
    folder = tmp_path / "camp"
    ap.write_campaign(small_sim.campaign, folder)
    return folder


def test_a_link_at_the_lock_path_is_refused_and_its_target_kept(campaign, tmp_path):
    """``.cal.lock -> camp/spat.csv``: identify refuses in one line naming the lock; the campaign
    file it points to keeps every byte and the link stays (main truncated it, then removed it)."""
    spat = campaign / "spat.csv"
    before = spat.read_bytes()
    link = tmp_path / ".cal.lock"
    link.symlink_to(spat)
    status, err = run_cli(["identify", str(campaign), "--out", str(tmp_path / "cal")])
    lines = [line for line in err.strip().splitlines() if "still working" not in line]
    assert status == 2 and len(lines) == 1, err
    assert str(link) in lines[0] and "is a link" in lines[0] and "Traceback" not in err
    assert spat.read_bytes() == before
    assert link.is_symlink() and not (tmp_path / "cal").exists()


def test_a_hard_link_at_the_lock_path_is_refused_and_kept(tmp_path):
    """A second name of a user's file at the lock path: refused, the file unchanged."""
    mine = tmp_path / "notes.txt"
    mine.write_text("1234\n")  # a process id's shape, even
    os.link(mine, lock_path(tmp_path / "out"))
    with pytest.raises(OutputExistsError, match="hard link"), claim_output(tmp_path / "out"):
        pytest.fail("claimed through a hard link")
    assert mine.read_text() == "1234\n" and lock_path(tmp_path / "out").exists()


def test_a_lock_file_with_other_data_is_refused_and_kept(tmp_path):
    """A plain file at the lock path that holds no process id is not ours: refused, unchanged."""
    lock = lock_path(tmp_path / "out.json")
    lock.write_text("x_mm,y_mm\n1,2\n")
    with pytest.raises(OutputExistsError, match="other data"), \
            claim_output(tmp_path / "out.json", folder=False):
        pytest.fail("claimed over another file")
    assert lock.read_text() == "x_mm,y_mm\n1,2\n"


def test_a_lock_kept_by_the_orphans_of_a_dead_run_is_taken_over_in_one_line(tmp_path):
    """The lock file names a dead process, but another process (its orphaned worker) still holds
    the flock: the claim takes it over and says so (main refused, naming the dead pid)."""
    out = tmp_path / "out"
    lock = lock_path(out)
    dead = _dead_pid()
    lock.write_text(f"{dead}\n")
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, os, sys; fd = os.open(sys.argv[1], os.O_RDONLY); "
         "fcntl.flock(fd, fcntl.LOCK_EX); print('held', flush=True); sys.stdin.readline()",
         str(lock)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            with claim_output(out):
                assert lock.read_text() == f"{os.getpid()}\n"
        said = [str(w.message) for w in seen if issubclass(w.category, StaleOutputWarning)]
        assert said == [f"took over the stale lock {lock} of process {dead} (no longer running)"]
    finally:
        holder.communicate("\n", timeout=10)
    assert not lock.exists()


def test_a_lock_held_by_a_live_run_is_still_refused_naming_it(tmp_path):
    """The other side: a lock whose holder runs stays its holder's."""
    out = tmp_path / "out"
    lock = lock_path(out)
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, os, sys; fd = os.open(sys.argv[1], os.O_RDWR | "
         "os.O_CREAT); fcntl.flock(fd, fcntl.LOCK_EX); os.write(fd, b'%d\\n' % os.getpid()); "
         "print('held', flush=True); sys.stdin.readline()", str(lock)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        with pytest.raises(OutputExistsError, match=f"process {holder.pid}"), claim_output(out):
            pytest.fail("claimed a held output")
    finally:
        holder.communicate("\n", timeout=10)


def test_leftovers_of_killed_runs_are_removed_by_the_next_claim(tmp_path):
    """Hidden temporary files and folders of the output whose process is gone are removed, in one
    line; those of a live process, and of other outputs, stay (main left them for ever)."""
    out = tmp_path / "points.csv"
    dead, live = _dead_pid(), os.getppid()
    left_file = tmp_path / f".points.csv.{dead}.ab_cd123.tmp"
    left_file.write_bytes(b"x" * 2_000_000)
    left_folder = tmp_path / f".points.csv.{dead}.k9z8y7x6.tmp"
    (left_folder / "sub").mkdir(parents=True)
    (left_folder / "sub" / "a.csv").write_bytes(b"y" * 1_000_000)
    alive = tmp_path / f".points.csv.{live}.abcdefgh.tmp"
    other = tmp_path / f".points.csv.1.{dead}.abcdefgh.tmp"  # of the output "points.csv.1"
    for path in (alive, other):
        path.write_text("keep")
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        with output_file(out) as tmp:
            assert tmp.name.startswith(f".points.csv.{os.getpid()}.")  # its owner, recognisable
            tmp.write_text("new\n")
    said = [str(w.message) for w in seen if issubclass(w.category, StaleOutputWarning)]
    assert len(said) == 1 and "removed 2 leftovers of killed runs" in said[0], said
    assert "3.0 MB" in said[0]
    assert not left_file.exists() and not left_folder.exists()
    assert alive.read_text() == "keep" and other.read_text() == "keep"
    assert out.read_text() == "new\n"
