"""Every time the README states or a command prints, measured: CPU and wall of whole processes.

Each command runs as a user runs it (a whole process, ``python -m aacmm_pin ...`` or ``python
examples/NN_*.py``, output piped) in a temporary folder, in the README's order: a simulated
campaign first, then what reads it. CPU is user + system of the process and its children
(RUSAGE_CHILDREN; the fair figure on a shared machine), wall from the start to the exit. The load
average (1 min) is read before and after each command and stated with it. A stated time is kept
when the measured CPU is within 1.5x of it (issue 26); a range ``lo-hi`` is kept when the CPU lies
within ``lo / 1.5 .. hi * 1.5``.

Not measured here: the test runs and ``.ci/run`` (minutes; their times are the README's own
measurements in a fresh clone) and ``pip install`` (a fresh environment downloads ~1 GB: not a
cheap benchmark; the issue measured 4 min 41 s).
"""

from __future__ import annotations

import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _report import BENCH, compile_package, machine, write_section

ROOT = BENCH.parent
EXAMPLES = ROOT / "examples"
CLI = [sys.executable, "-m", "aacmm_pin"]
Stated = tuple[float, float] | None
"""The stated time as a range of seconds (lo, hi); None where nothing is stated."""



def example(name: str, args: list[str]) -> tuple[str, list[str], str, Stated]:
    """Return the case of an example, with the time its docstring states ("(about N s)")."""
    said = re.search(r"\(about (\d+(?:\.\d+)?) s[;)]", (EXAMPLES / name).read_text())
    seconds = None if said is None else float(said.group(1))
    return (f"`python examples/{name}`", [sys.executable, str(EXAMPLES / name), *args],
            "-" if seconds is None else f"its docstring: \"about {seconds:g} s\"",
            None if seconds is None else (seconds, seconds))


CASES: list[tuple[str, list[str], str, Stated]] = [
    ("`aacmm-pin simulate c`", [*CLI, "simulate", "c"],
     "\"a few seconds\" (its first line)", (1.0, 5.0)),
    ("`aacmm-pin demo`", [*CLI, "demo", "--out", "demo"],
     "docs/install.md: \"the demo about 7 s of CPU\", \"about 5-8 s of CPU\"", (5.0, 8.0)),
    ("`aacmm-pin identify c --model proposed`",
     [*CLI, "identify", "c", "--model", "proposed", "--out", "cal"], "-", None),
    ("`aacmm-pin validate cal c`", [*CLI, "validate", "cal", "c"], "-", None),
    ("`aacmm-pin discover c`", [*CLI, "discover", "c", "--out", "disc"], "-", None),
    ("`aacmm-pin uncertainty c` (default trials)", [*CLI, "uncertainty", "c", "--out", "unc"],
     "-", None),
    ("`aacmm-pin plan c`", [*CLI, "plan", "c"], "-", None),
    *(example(name, args) for name, args in [
        ("01_reproduce_paper.py", ["ex1", "--figures", "ex1-figures"]),
        ("02_discover_compliance.py", ["--out", "ex2"]),
        ("03_laser_tracker_ur5_wam.py", ["--out", "ex3"]),
        ("04_unexplained_drift.py", ["--out", "ex4"]),
        ("05_plugin.py", ["--out", "ex5"])]),
]


def run(cmd: list[str], cwd: Path) -> tuple[float, float, float, float]:
    """Run ``cmd`` in ``cwd``; return (CPU s, wall s, first line s, load average after).

    Raises:
        SystemExit: if the command fails.
    """
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # a pipe buffers
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT)
    assert proc.stdout is not None
    first = None
    tail: list[str] = []
    for line in proc.stdout:
        first = time.monotonic() - start if first is None else first
        tail = (tail + [line])[-20:]
    if proc.wait() != 0:
        raise SystemExit(f"{' '.join(cmd)} failed (exit {proc.returncode}):\n{''.join(tail)}")
    wall = time.monotonic() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return cpu, wall, wall if first is None else first, os.getloadavg()[0]


def verdict(cpu: float, stated: Stated) -> str:
    """Whether the measured CPU is within 1.5x of the stated time (or its range)."""
    if stated is None:
        return "-"
    lo, hi = stated
    if cpu > hi * 1.5:
        return f"**no** ({cpu / hi:.1f}x the stated)"
    if cpu < lo / 1.5:
        return f"**no** ({cpu / lo:.2f}x the stated)"
    return "yes"


def main() -> None:
    compile_package()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, cmd, where, stated in CASES:
            load_before = os.getloadavg()[0]
            cpu, wall, first, load_after = run(cmd, Path(tmp))
            rows.append(f"| {label} | {where} | {cpu:.1f} | {wall:.1f} | {first:.1f} | "
                        f"{load_before:.1f} / {load_after:.1f} | {verdict(cpu, stated)} |")
            print(rows[-1], flush=True)
    write_section("times", f"""## Stated times (`python benchmarks/times.py`)

{machine()}. Every time the README or a command states, measured as a user runs it: whole
processes in a temporary folder (output piped), one after the other, CPU = user + system of the
process and its children, wall to the exit, first line = wall to its first output line; the load
average (1 min) before / after each command says how busy the 2 cores were (other jobs included).
Within 1.5x: the CPU within 1.5x of the stated time (issue 26; the stated time is the baseline,
one run each). Not measured: the test runs and `.ci/run` (minutes; the README gives its own
fresh-clone measurements) and `pip install`
(a fresh environment downloads ~1 GB).

| command | stated | CPU (s) | wall (s) | first line (s) | load before / after | within 1.5x |
|---|---|---|---|---|---|---|
{chr(10).join(rows)}""")


if __name__ == "__main__":
    main()
