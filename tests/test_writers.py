"""Every file a command writes: claimed at its start, never an input, whole or not at all.

Issue 24 items 2, 6, 8, 9, 11 (writers) and issue 26 item 1 (the demo's folder).
"""

from __future__ import annotations

import csv
import errno
import os
import resource
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import aacmm_pin as ap
from aacmm_pin.data.output_claim import OutputExistsError, claim_output
from aacmm_pin.data.spreadsheet import neutralise_formula
from aacmm_pin.model.arm import resolve_arm_path
from tests.helpers import ENV, run_cli

BUSY = "another run is writing it"


def one_line(err: str) -> str:
    """Return the only error line of ``err`` (fails on a traceback or several lines).

    The heartbeat's "still working" lines of a subprocess on a busy machine are no error lines.
    """
    lines = [line for line in err.strip().splitlines() if ": still working" not in line]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture
def predict_inputs(tmp_path: Path) -> tuple[Path, Path]:
    """(parameters.json of the nominal arm, readouts.csv of 200 postures with id columns)."""
    params = tmp_path / "parameters.json"
    ap.write_parameters(ap.Parameters.nominal(ap.load_arm()), params)
    rng = np.random.default_rng(0)
    q = rng.uniform(-90, 90, size=(200, 7))
    rows = ["pose,t_s," + ",".join(f"q{k}_deg" for k in range(1, 8))]
    rows += [f"p{i},{-1.5 * i + 0.0:g}," + ",".join(f"{v:.6f}" for v in qi) for i, qi in enumerate(q)]
    readouts = tmp_path / "readouts.csv"
    readouts.write_text("\n".join(rows) + "\n")
    return params, readouts


def test_predict_refuses_an_existing_file_and_its_own_input(predict_inputs, tmp_path):
    """predict --out: an existing file needs --force; the readouts or parameters never (exit 2)."""
    params, readouts = predict_inputs
    before = readouts.read_bytes()
    for out in (readouts, params):
        status, err = run_cli(["predict", str(params), str(readouts), "--out", str(out),
                               "--force"])
        assert status == 2 and "is an input of this command" in one_line(err)
    assert readouts.read_bytes() == before
    out = tmp_path / "points.csv"
    out.write_text("mine\n")
    status, err = run_cli(["predict", str(params), str(readouts), "--out", str(out)])
    assert status == 2 and f"{out}: exists; give --force" in one_line(err)
    assert out.read_text() == "mine\n"
    assert run_cli(["predict", str(params), str(readouts), "--out", str(out), "--force"])[0] == 0
    assert len(out.read_text().splitlines()) == 201
    assert sorted(p.name for p in tmp_path.iterdir()) == ["parameters.json", "points.csv",
                                                          "readouts.csv"]  # no lock, no temp


def test_identify_refuses_to_replace_the_campaign_it_reads(tmp_path, small_sim):
    """identify C --out C --force, or --out a folder holding C: refused, the campaign intact."""
    camp = tmp_path / "data" / "camp"
    ap.write_campaign(small_sim.campaign, camp)
    before = {p.name: p.read_bytes() for p in camp.iterdir()}
    for out in (camp, tmp_path / "data"):
        status, err = run_cli(["identify", str(camp), "--out", str(out), "--force"])
        assert status == 2 and f"{out}: " in one_line(err) and "an input of this command" in err
    assert {p.name: p.read_bytes() for p in camp.iterdir()} == before


def test_json_and_html_outputs_are_claimed_before_the_work(tmp_path, small_sim):
    """validate/plan --json, view --html, iso10360 --json on an existing file: refused first, so
    before reading a campaign (here an empty folder: a path that does not exist is reported even
    before, at once) and before minutes of fitting."""
    taken = tmp_path / "taken.json"
    taken.write_text("{}")
    (tmp_path / "empty").mkdir()
    missing = str(tmp_path / "empty")
    for argv in (["validate", missing, missing, "--json", str(taken)],
                 ["plan", missing, "--json", str(taken)],
                 ["view", missing, missing, "--html", str(taken)],
                 ["iso10360", "euni", missing, "--json", str(taken)]):
        status, err = run_cli(argv)
        assert status == 2 and f"{taken}: exists; give --force" in one_line(err), argv
    assert taken.read_text() == "{}"
    camp = tmp_path / "camp"
    ap.write_campaign(small_sim.campaign, camp)
    params = tmp_path / "parameters.json"
    ap.write_parameters(ap.Parameters.nominal(ap.load_arm()), params)
    status, err = run_cli(["validate", str(params), str(camp), "--json", str(camp / "bar.csv"),
                           "--force"])
    assert status == 2 and "is an input of this command" in one_line(err)
    assert (camp / "bar.csv").read_text().startswith("from,to,length_mm")


def test_the_demo_refuses_a_folder_with_files(tmp_path):
    """Issue 26 item 1: demo --out DIR with a user's file in DIR/campaign: refused, file kept."""
    (tmp_path / "campaign").mkdir()
    (tmp_path / "campaign" / "notes.txt").write_text("mine")
    status, err = run_cli(["demo", "--out", str(tmp_path)])
    assert status == 2 and "exists and is not empty; give --force" in one_line(err)
    assert (tmp_path / "campaign" / "notes.txt").read_text() == "mine"


@pytest.mark.skipif(sys.platform == "win32", reason="flock is POSIX")
def test_a_file_system_without_flock_claims_by_exclusive_creation(tmp_path, monkeypatch):
    """flock refused (ENOLCK: some NFS and FUSE mounts): the claim is the lock file's exclusive
    creation, so commands still write and a second claim still fails at once."""
    import errno
    import fcntl

    def no_flock(fd: int, op: int) -> None:
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(fcntl, "flock", no_flock)
    out = tmp_path / "new"
    with claim_output(out):  # a second claim from another thread (this one's would be nested)
        failed: list[BaseException] = []
        other = threading.Thread(target=lambda: _claim_into(out, failed))
        other.start()
        other.join(10)
        assert len(failed) == 1 and isinstance(failed[0], OutputExistsError)
        assert "another run is writing it" in str(failed[0])
    with claim_output(out):
        pass
    assert list(tmp_path.iterdir()) == []  # the lock file is gone


def _claim_into(out: Path, failed: list[BaseException]) -> None:
    try:
        with claim_output(out):
            pass
    except OutputExistsError as exc:
        failed.append(exc)


def test_a_claim_is_exclusive_across_threads(tmp_path):
    """While one thread holds an output, another's claim fails at once; after it, it succeeds."""
    out = tmp_path / "new"
    held, release = threading.Event(), threading.Event()

    def hold() -> None:
        with claim_output(out):
            held.set()
            release.wait(10)

    worker = threading.Thread(target=hold)
    worker.start()
    try:
        assert held.wait(10)
        with pytest.raises(OutputExistsError, match=BUSY), claim_output(out):
            pass
    finally:
        release.set()
        worker.join()
    with claim_output(out):
        pass
    assert list(tmp_path.iterdir()) == []  # the lock file is gone


@pytest.mark.skipif(threading.current_thread() is not threading.main_thread(),
                    reason="Python runs signal handlers in the main thread only")
@pytest.mark.usefixtures("sigint_as_from_a_terminal")
def test_ctrl_c_as_the_lock_file_is_made_leaves_no_lock_file(tmp_path, monkeypatch):
    """A Ctrl-C that lands just after the lock file's creation (before the claim holds it) still
    interrupts, once the claim can clean up: no lock file and no folder made for it remain.
    Ctrl-C's outside the claim are untouched: the handler before it is back after."""
    from aacmm_pin.data import output_claim

    made = output_claim._lock

    def lock_then_ctrl_c(lock: Path, target: Path) -> int:
        fd = made(lock, target)
        os.kill(os.getpid(), signal.SIGINT)  # its handler runs at the next bytecode boundary
        return fd

    monkeypatch.setattr(output_claim, "_lock", lock_then_ctrl_c)
    handler = signal.getsignal(signal.SIGINT)
    out = tmp_path / "new" / "out"
    with pytest.raises(KeyboardInterrupt), claim_output(out):
        pytest.fail("the claim went on after a Ctrl-C")
    assert list(tmp_path.iterdir()) == []  # no lock file, no folder "new"
    assert signal.getsignal(signal.SIGINT) is handler


@pytest.mark.skipif(threading.current_thread() is not threading.main_thread(),
                    reason="Python runs signal handlers in the main thread only")
@pytest.mark.usefixtures("sigint_as_from_a_terminal")
def test_a_second_ctrl_c_as_the_lock_file_is_removed_leaves_no_lock_file(tmp_path, monkeypatch):
    """Ctrl-C pressed twice: the second lands as the claim removes its lock file, after the first
    ended the command. Both interrupt; the lock file is gone all the same."""
    from aacmm_pin.data import output_claim

    class SecondCtrlC(type(tmp_path)):  # type: ignore[misc]
        def unlink(self, missing_ok: bool = False) -> None:
            os.kill(os.getpid(), signal.SIGINT)  # its handler runs at the next bytecode boundary
            super().unlink(missing_ok)

    monkeypatch.setattr(output_claim, "lock_path",
                        lambda target: SecondCtrlC(Path(target).parent / f".{Path(target).name}.lock"))
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt) as raised, claim_output(out):
        raise KeyboardInterrupt  # the first Ctrl-C
    assert isinstance(raised.value.__context__, KeyboardInterrupt)  # the second, over the first
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(threading.current_thread() is not threading.main_thread(),
                    reason="Python runs signal handlers in the main thread only")
@pytest.mark.parametrize("disposition", [signal.SIG_IGN, signal.SIG_DFL])
def test_a_claim_leaves_an_ignored_or_system_ctrl_c_alone(tmp_path, monkeypatch, disposition):
    """Where SIGINT is ignored or left to the system, no Python handler is put in its place even
    for the claim's moment (a program started then would not inherit the ignore)."""
    from aacmm_pin.data import output_claim

    made, seen = output_claim._lock, []

    def lock_and_look(lock: Path, target: Path) -> int:
        seen.append(signal.getsignal(signal.SIGINT))
        return made(lock, target)

    monkeypatch.setattr(output_claim, "_lock", lock_and_look)
    previous = signal.signal(signal.SIGINT, disposition)
    try:
        with claim_output(tmp_path / "out"):
            pass
    finally:
        signal.signal(signal.SIGINT, previous)
    assert seen == [disposition]


@pytest.mark.skipif(sys.platform == "win32", reason="flock is POSIX")
def test_a_lock_file_that_cannot_be_written_names_the_output_and_leaves_nothing(tmp_path,
                                                                               monkeypatch):
    """The lock file is made and locked but cannot be written (an I/O error): the error names the
    output and no lock file stays behind."""
    from aacmm_pin.data import output_claim

    def failing(fd: int, length: int) -> None:
        raise OSError(errno.EIO, "Input/output error")

    monkeypatch.setattr(output_claim.os, "ftruncate", failing)  # called by the claim alone
    out = tmp_path / "out"
    with pytest.raises(OSError, match="Input/output error") as raised, claim_output(out):
        pass
    assert raised.value.filename == str(out)
    assert list(tmp_path.iterdir()) == []


SLOW = """
import sys
import aacmm_pin.data.campaign as campaign
from aacmm_pin.cli import main
read = campaign.read_campaign
def slow(*args, **kwargs):  # minutes of work, here: until the test says go
    print("working", flush=True)
    sys.stdin.readline()
    return read(*args, **kwargs)
campaign.read_campaign = slow
sys.exit(main(sys.argv[1:]))
"""


def test_two_identify_runs_into_one_new_out(tmp_path, small_sim):
    """Two processes into one new --out: the second, started while the first works, fails at once
    with one line; the first then succeeds."""
    camp, out = tmp_path / "camp", tmp_path / "cal"
    ap.write_campaign(small_sim.campaign, camp)
    argv = ["identify", str(camp), "--model", "dh", "--out", str(out)]
    first = subprocess.Popen([sys.executable, "-c", SLOW, *argv], env=ENV, text=True,
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert first.stdout is not None
        head = [first.stdout.readline() for _ in range(2)]  # "sizes: ..." is printed first
        assert "working\n" in head, head
        second = subprocess.run([sys.executable, "-m", "aacmm_pin", *argv], env=ENV,
                                capture_output=True, text=True, timeout=300)
        _, first_err = first.communicate("go\n", timeout=300)
    finally:
        first.kill()
    assert first.returncode == 0, first_err
    assert second.returncode == 2 and str(out) in one_line(second.stderr)
    assert BUSY in second.stderr
    assert ap.read_calibration(out).parameters is not None


KILLER = """
import csv, os, signal, sys
from aacmm_pin.cli import main
real = csv.writer
class Half:  # writes half of the rows, then the process is killed
    def __init__(self, f, **kw):
        self.f, self.w = f, real(f, **kw)
    def writerow(self, row):
        self.w.writerow(row)
    def writerows(self, rows):
        rows = list(rows)
        self.w.writerows(rows[: len(rows) // 2])
        self.f.flush()
        os.kill(os.getpid(), signal.SIGKILL)
csv.writer = Half
main(sys.argv[1:])
"""


def test_a_killed_predict_leaves_the_old_file(predict_inputs, tmp_path):
    """SIGKILL in the middle of writing predict's CSV: the old file is left whole, no fragment."""
    params, readouts = predict_inputs
    out = tmp_path / "points.csv"
    out.write_text("old\n")
    proc = subprocess.run([sys.executable, "-c", KILLER, "predict", str(params), str(readouts),
                           "--out", str(out), "--force"], env=ENV, capture_output=True, timeout=120)
    assert proc.returncode == -signal.SIGKILL
    assert out.read_text() == "old\n"


def _file_size_limit(limit: int) -> None:
    """In the child: writes beyond ``limit`` bytes fail (EFBIG), as on a full disk."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))


def test_a_write_that_fails_midway_names_the_file_and_keeps_the_old(predict_inputs, tmp_path):
    """A write failing after 4 kB (a full disk; here a file size limit): exit 2, one line naming
    the output, the old file intact, no temporary file left."""
    params, readouts = predict_inputs
    out = tmp_path / "points.csv"
    out.write_text("old\n")
    proc = subprocess.run([sys.executable, "-m", "aacmm_pin", "predict", str(params),
                           str(readouts), "--out", str(out), "--force"],
                          env={**ENV, "PYTHONDONTWRITEBYTECODE": "1"}, capture_output=True,
                          text=True, timeout=120, preexec_fn=lambda: _file_size_limit(4096))
    assert proc.returncode == 2 and str(out) in one_line(proc.stderr)
    assert out.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["parameters.json", "points.csv",
                                                          "readouts.csv"]


def test_no_space_left_names_the_output_folder(tmp_path, small_sim, monkeypatch):
    """ENOSPC while a folder is flushed (simulated): one line with the folder, the old one kept."""
    camp = tmp_path / "camp"
    ap.write_campaign(small_sim.campaign, camp)
    out = tmp_path / "cal"
    out.mkdir()
    (out / "old.txt").write_text("old")

    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", full)
    status, err = run_cli(["identify", str(camp), "--model", "dh", "--out", str(out), "--force"])
    assert status == 2 and one_line(err).endswith(f"{out}: No space left on device")
    assert [p.name for p in out.iterdir()] == ["old.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cal", "camp"]


def test_predict_neutralises_formulas_in_id_columns(predict_inputs, tmp_path):
    """An id cell a spreadsheet would run (= + - @, a tab) is written with a quote; numbers not."""
    params, readouts = predict_inputs
    lines = readouts.read_text().splitlines()
    ids = ["=HYPERLINK(A1)", "+cmd|' /C calc'!A0", "-2+3", "@SUM(A1)", "\t=1+1", "p5"]
    for i, cell in enumerate(ids, start=1):
        lines[i] = f'"{cell}"' + lines[i][lines[i].index(","):]
    readouts.write_text("\n".join(lines) + "\n")
    out = tmp_path / "points.csv"
    assert run_cli(["predict", str(params), str(readouts), "--out", str(out)])[0] == 0
    with out.open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["pose"] for r in rows[:6]] == ["'=HYPERLINK(A1)", "'+cmd|' /C calc'!A0",
                                             "'-2+3", "'@SUM(A1)", "'=1+1", "p5"]
    assert [r["t_s"] for r in rows[:3]] == ["0", "-1.5", "-3"]  # negative numbers are no formulas
    assert all(not r[k].startswith("'") for r in rows for k in ("x_mm", "y_mm", "z_mm"))


@pytest.mark.parametrize(("cell", "safe"), [
    ("=1+1", "'=1+1"), ("@A1", "'@A1"), ("+A1", "'+A1"), ("-A1", "'-A1"), ("\rx", "'\rx"),
    ("-1.5", "-1.5"), ("+2e-3", "+2e-3"), ("-.5", "-.5"), ("-inf", "'-inf"), ("a=b", "a=b"),
    ("", "")])
def test_neutralise_formula(cell, safe):
    """OWASP's CSV-injection rule; a plain number is no formula."""
    assert neutralise_formula(cell) == safe


STL = """solid t
facet normal 0 0 1
 outer loop
  vertex 0 0 0
  vertex 0.01 0 0
  vertex 0 0.01 0
 endloop
endfacet
endsolid t
"""


def test_calibrated_urdf_keeps_mesh_paths_valid(tmp_path, small_sim, small_cal):
    """An arm with relative mesh paths: calibrated.urdf reaches the same files from its folder;
    package:// and absolute paths are left as written; yourdfpy finds the meshes and view draws
    them (on main: "Mesh meshes/a.stl could not be found")."""
    yourdfpy = pytest.importorskip("yourdfpy")
    arm_dir = tmp_path / "arm" / "urdf"
    (tmp_path / "arm" / "meshes").mkdir(parents=True)
    arm_dir.mkdir()
    (arm_dir / "meshes").mkdir()
    (arm_dir / "meshes" / "a.stl").write_text(STL)
    (tmp_path / "arm" / "meshes" / "b.stl").write_text(STL)
    visuals = ('<visual><geometry><mesh filename="meshes/a.stl"/></geometry></visual>'
               '<visual><geometry><mesh filename="../meshes/b.stl"/></geometry></visual>'
               '<visual><geometry><mesh filename="package://pkg/c.stl"/></geometry></visual>'
               f'<visual><geometry><mesh filename="{tmp_path / "arm" / "meshes" / "b.stl"}"/>'
               '</geometry></visual>')
    text = resolve_arm_path("aacmm7").read_text()
    assert '<link name="base_link">' in text
    urdf = arm_dir / "arm.urdf"
    urdf.write_text(text.replace('<link name="base_link">', '<link name="base_link">' + visuals))
    arm = ap.load_arm(urdf)
    ap.write_calibration(small_cal, arm, tmp_path / "results" / "cal")
    written = (tmp_path / "results" / "cal" / "calibrated.urdf").read_text()
    names = [line.split('filename="')[1].split('"')[0] for line in written.split("<mesh")[1:]]
    assert names == ["../../arm/urdf/meshes/a.stl", "../../arm/meshes/b.stl", "package://pkg/c.stl",
                     str(tmp_path / "arm" / "meshes" / "b.stl")]
    assert (tmp_path / "results" / "cal" / names[0]).is_file()
    robot = yourdfpy.URDF.load(str(tmp_path / "results" / "cal" / "calibrated.urdf"),
                               load_meshes=False, build_scene_graph=False)
    handler = robot._filename_handler
    assert all(Path(handler(n)).is_file() for n in (names[0], names[1], names[3]))
    ap.write_campaign(small_sim.campaign, tmp_path / "camp")
    written = written.replace('"package://pkg/c.stl"', f'"{names[3]}"')  # no package here
    (tmp_path / "results" / "cal" / "calibrated.urdf").write_text(written)
    page = ap.view(tmp_path / "results" / "cal", tmp_path / "camp", html=tmp_path / "v.html").html
    assert page is not None and page.stat().st_size > 100_000


def test_a_refused_run_leaves_no_folders_behind(tmp_path):
    """identify of a missing campaign into new/sub/cal: exit 2, and new/ is not left behind."""
    status, err = run_cli(["identify", str(tmp_path / "missing"), "--out",
                           str(tmp_path / "new" / "sub" / "cal")])
    assert status == 2 and str(tmp_path / "missing") in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_pairs_of_identify_runs_started_together(tmp_path, small_sim):
    """6 pairs of identify runs started together into one new --out (the issue: both exit 0 in 3
    of 6 pairs): in every pair exactly one succeeds, and the other fails at once (before the
    first has finished, not after doing all the work) with one line."""
    camp = tmp_path / "camp"
    ap.write_campaign(small_sim.campaign, camp)
    for k in range(6):
        out = tmp_path / f"cal{k}"
        argv = [sys.executable, "-m", "aacmm_pin", "identify", str(camp), "--out", str(out)]
        procs = [subprocess.Popen(argv, env=ENV, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.PIPE, text=True) for _ in range(2)]
        seen: dict[int, int] = {}  # process -> the 10 ms poll at which it was seen ended
        poll = 0
        while len(seen) < 2:
            seen.update({i: poll for i, p in enumerate(procs) if i not in seen and p.poll() is not None})
            poll += 1
            time.sleep(0.01)
        done = [(p.returncode, p.communicate()[1]) for p in procs]
        assert sorted(status for status, _ in done) == [0, 2], done
        refused, ran = (0, 1) if done[0][0] == 2 else (1, 0)
        # the refused one ends first (both seen in one poll: they ended within 10 ms)
        assert seen[refused] <= seen[ran], (seen, done)
        assert str(out) in one_line(done[refused][1]) and BUSY in done[refused][1]


def test_predict_keeps_the_files_its_parameters_folder_and_effects_file_hold(predict_inputs,
                                                                             tmp_path):
    """A parameters.json stands for its calibration folder (its URDF, report, maps are read), and
    an --effects-file module is read: neither is an output, even with --force."""
    params, readouts = predict_inputs
    urdf = tmp_path / "calibrated.urdf"
    urdf.write_text("<robot name='kept'/>\n")
    plugin = tmp_path / "plugin.py"
    plugin.write_text("# no effect in it\n")
    for out in (urdf, plugin):
        before = out.read_bytes()
        status, err = run_cli(["predict", str(params), str(readouts), "--effects-file",
                               str(plugin), "--out", str(out), "--force"])
        assert status == 2 and "is an input of this command" in one_line(err)
        assert out.read_bytes() == before


def test_the_umask_is_read_without_changing_it(monkeypatch):
    """umask() gives the process's umask and never sets another one, even for a moment (threads
    creating files meanwhile would get it)."""
    from aacmm_pin.data import output_claim

    seen: list[int] = []
    real = os.umask

    def spy(mask: int) -> int:
        seen.append(mask)
        return real(mask)

    before = real(0o027)
    try:
        monkeypatch.setattr(os, "umask", spy)
        assert output_claim.umask() == 0o027
        if Path("/proc/self/status").exists():
            assert seen == []
    finally:
        real(before)


def test_a_written_file_and_folder_sync_the_folder_that_holds_them(tmp_path, monkeypatch):
    """After the rename, the folder holding the output is flushed too (else a power loss can
    undo the rename)."""
    from aacmm_pin.data.output_file import write_text_file
    from aacmm_pin.data.output_folder import output_folder

    synced: list[str] = []
    real = os.fsync

    def spy(fd: int) -> None:
        synced.append(os.readlink(f"/proc/self/fd/{fd}"))
        real(fd)

    if not Path("/proc/self/fd").exists():
        pytest.skip("needs /proc to name the flushed descriptors")
    monkeypatch.setattr(os, "fsync", spy)
    write_text_file(tmp_path / "a.json", "{}\n")
    assert synced[-1] == str(tmp_path)
    with output_folder(tmp_path / "cal") as tmp:
        (tmp / "x.txt").write_text("x")
    assert synced[-1] == str(tmp_path)
