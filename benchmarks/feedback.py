"""How long each long command of the README leaves its user without a line: time to the first
line and the longest silence, with stdout and stderr piped (not a terminal, as in a log or CI).

Each command runs as a whole process in a temporary folder, in the README's order (a simulated
campaign first, then what uses it); a line is any line on stdout or stderr. The issue's target: a
line within 2 s of the start and never 2 s without one (the heartbeat speaks after 1.5 s).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _report import machine, write_section

STEPS = [
    ("demo", ["demo", "--out", "demo"]),
    ("simulate", ["simulate", "c", "--seed", "3"]),
    ("identify", ["identify", "c", "--model", "proposed", "--out", "cal"]),
    ("validate", ["validate", "cal", "c"]),
    ("predict", ["predict", "cal", "c/spat.csv", "--out", "points.csv"]),
    ("discover", ["discover", "c", "--start", "dh", "--out", "disc"]),
    ("uncertainty", ["uncertainty", "c", "--trials", "40", "--out", "unc"]),
    ("plan", ["plan", "c"]),
    ("view --html", ["view", "cal", "c", "--html", "view.html"]),
]


def silences(args: list[str], cwd: Path) -> tuple[float, float, float, int]:
    """Run ``aacmm-pin ARGS``; return (total s, first line s, longest silence s, lines)."""
    start = time.monotonic()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # a pipe buffers
    proc = subprocess.Popen([sys.executable, "-m", "aacmm_pin", *args], cwd=cwd, text=True, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, bufsize=1)
    assert proc.stdout is not None
    first, last, longest, lines = None, start, 0.0, 0
    for _ in proc.stdout:
        now = time.monotonic()
        first = now - start if first is None else first
        longest, last, lines = max(longest, now - last), now, lines + 1
    if proc.wait() != 0:
        raise SystemExit(f"aacmm-pin {' '.join(args)} failed (exit {proc.returncode})")
    end = time.monotonic()
    return end - start, first if first is not None else end - start, max(longest, end - last), lines


def main() -> None:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, args in STEPS:
            total, first, longest, lines = silences(args, Path(tmp))
            rows.append(f"| `aacmm-pin {label}` | {total:.1f} | {first:.2f} | {longest:.2f} | {lines} |")
            print(rows[-1], flush=True)
    write_section("feedback", f"""## Feedback of long commands (`python benchmarks/feedback.py`)

{machine()}. Each command a whole process with stdout and stderr piped (a log, not a terminal;
Python's output buffered as in a pipe, `PYTHONUNBUFFERED` unset):
wall seconds to its first line and its longest silence (the end of the run included); issue
target: a line within 2 s and no silence of 2 s. Identification, Monte Carlo, discovery and plan
log a line after 1 s without one; whatever else runs long is covered by the heartbeat
(`aacmm_pin.progress.Heartbeat`, "still working" after 1.5 s of silence). Wall times against
the issue's targets, no baseline; one run each (the silences are set by the 1 s and 1.5 s timers,
the totals vary with the machine's load).

| command | total (s) | first line (s) | longest silence (s) | lines |
|---|---|---|---|---|
{chr(10).join(rows)}""")


if __name__ == "__main__":
    main()
