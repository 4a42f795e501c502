#!/usr/bin/env python3
"""Run the acquisition tests N times in a row with every core busy; stop at the first failure.

Usage (from the repository root, in the project's environment)::

    python .ci/acquire_under_load.py [--runs 10] [--busy-per-core 2] [pytest options ...]

The acquisition tests read pseudo-terminals with threads, stamp lines with the host clock and pair
them by time: an idle machine hides what a busy one shows (lines read in fragments and late,
readers behind their ports, threads not run for tens of ms). This script starts
``busy-per-core`` busy-loop processes per core (default 2: on 2 cores, with the tests and what
else runs, about the load of 7 at which the garbled lines of issue 24 were seen; the load average
is printed after each run), runs ``tests/test_acquire*.py`` (the default selection, slow tests
skipped) ``runs`` times, prints one line per run and ends every busy loop it started (by its pid),
whatever happens. Exit status: 0 if every run passed, else pytest's status of the first failing
run.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TESTS = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "tests").glob("test_acquire*.py"))


def main(argv: list[str] | None = None) -> int:
    """Start the busy loops, run the tests ``--runs`` times, end the loops; return the status."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--runs", type=int, default=10, help="runs in a row (default 10)")
    parser.add_argument("--busy-per-core", type=int, default=2,
                        help="busy-loop processes per core (default 2)")
    args, pytest_args = parser.parse_known_args(argv)
    cores = os.cpu_count() or 1
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(args.busy_per_core * cores)]
    try:
        time.sleep(2.0)  # let the load build up
        print(f"{len(busy)} busy loops on {cores} cores; tests: {' '.join(TESTS)}", flush=True)
        for run in range(1, args.runs + 1):
            tic = time.monotonic()
            result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-n0", "-p",
                                     "no:cacheprovider", *TESTS, *pytest_args], cwd=ROOT,
                                    capture_output=True, text=True)
            tail = (result.stdout.strip().splitlines() or ["(no output)"])[-1]
            print(f"run {run}/{args.runs}: {'passed' if result.returncode == 0 else 'FAILED'} in "
                  f"{time.monotonic() - tic:.0f} s, load {os.getloadavg()[0]:.1f}: {tail}",
                  flush=True)
            if result.returncode:
                print(result.stdout[-20000:], result.stderr[-5000:], sep="\n")
                return result.returncode
        print(f"{args.runs} of {args.runs} runs passed under load")
        return 0
    finally:
        for proc in busy:
            proc.kill()
        for proc in busy:
            proc.wait()


if __name__ == "__main__":
    sys.exit(main())
