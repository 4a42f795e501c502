"""CPU time of starting the command line: `aacmm-pin --help`, `--version`, a command's help.

Each is run as a whole process (as a user starts it); CPU from RUSAGE_CHILDREN, median (range) of
9 interleaved rounds (each round runs every command once), beside `python -c pass` and `python -c
"import numpy"` in the same rounds; ratios to the bare interpreter per round (noisy machines).
A start-up cost: the baselines are the interpreter and its imports, not another implementation.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys

import numpy as np
from _report import compile_package, machine, ratio, write_section

from aacmm_pin.cli import BLAS_THREAD_VARIABLES

RUNS = 25
"""Interleaved rounds; each runs every case once."""
ONE = {"OPENBLAS_NUM_THREADS": "1"}
CASES: list[tuple[str, list[str], dict[str, str]]] = [
    ("`python -c pass` (the interpreter alone)", [sys.executable, "-c", "pass"], {}),
    ("`python -c \"import numpy\"`", [sys.executable, "-c", "import numpy"], {}),
    ("`python -c \"import numpy, scipy.linalg\"`",
     [sys.executable, "-c", "import numpy, scipy.linalg"], {}),
    ("the same with `OPENBLAS_NUM_THREADS=1` (as `aacmm-pin` starts)",
     [sys.executable, "-c", "import numpy, scipy.linalg"], ONE),
    ("`aacmm-pin --help`", [sys.executable, "-m", "aacmm_pin", "--help"], {}),
    ("`aacmm-pin --version`", [sys.executable, "-m", "aacmm_pin", "--version"], {}),
    ("`aacmm-pin identify --help`", [sys.executable, "-m", "aacmm_pin", "identify", "--help"], {}),
    ("`aacmm-pin axes` (loads the default arm: numpy, Pinocchio, lxml)",
     [sys.executable, "-m", "aacmm_pin", "axes"], {}),
]


def cpu_of(cmd: list[str], extra: dict[str, str]) -> float:
    """Return the CPU seconds (user + system) of one run of ``cmd``.

    The environment is this one without BLAS thread variables, plus ``extra``.
    """
    env = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES} | extra
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True, capture_output=True, env=env)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime


def main() -> None:
    compile_package()
    load = [os.getloadavg()[0]]
    runs = np.array([[cpu_of(cmd, extra) for _, cmd, extra in CASES] for _ in range(RUNS)])
    load.append(os.getloadavg()[0])
    med = np.median(runs, axis=0)
    table = "\n".join(
        f"| {label} | {med[k]:.3f} ({runs[:, k].min():.3f} - {runs[:, k].max():.3f}) | "
        f"{'1x' if k == 0 else ratio(runs[:, k], runs[:, 0], '.1f', name=label)} |"
        for k, (label, _, _) in enumerate(CASES))
    write_section("cli", f"""## Command-line start (`python benchmarks/cli.py`)

{machine()}. Whole processes, CPU seconds (user + system), median (range) of {RUNS} interleaved
rounds (each runs every command once); ratios of the medians, their range over
the rounds of this run and of the earlier runs named below (each round's command over its bare
interpreter); a start-up cost, so the baselines are the interpreter
and its imports, not another implementation. Load average (1 min) before / after: {load[0]:.1f} /
{load[1]:.1f}: a start's CPU grows with the machine's load, and not by the same factor for every
row, so a run at another load can fall outside these ranges. Issue targets:
`--help` <= 0.3 s CPU. The CLI imports only argparse-level modules until a command runs. The
package's bytecode is written first, as `pip install` does. Before a command imports numpy,
`aacmm-pin` starts OpenBLAS with one thread (unless the user set a BLAS thread variable: every
computation runs with one thread anyway); loading OpenBLAS with a thread pool, once in numpy and
once in scipy, costs the difference between the third and fourth rows. No command imports
yourdfpy or trimesh: the arm is read as an XML tree (`aacmm_pin.model.urdf_tree`).

| command | CPU (s) | vs the bare interpreter |
|---|---|---|
{table}""")


if __name__ == "__main__":
    main()
