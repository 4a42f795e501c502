"""CPU time of starting the command line: `aacmm-pin --help`, `--version`, a command's help.

Each is run as a whole process (as a user starts it); CPU from RUSAGE_CHILDREN, median of 5,
beside `python -c pass` and `python -c "import numpy"` in the same run (ratios: noisy machines).
"""

from __future__ import annotations

import resource
import subprocess
import sys

import numpy as np
from _report import compile_package, machine, write_section

RUNS = 5
CASES = [
    ("`python -c pass` (the interpreter alone)", [sys.executable, "-c", "pass"]),
    ("`python -c \"import numpy\"`", [sys.executable, "-c", "import numpy"]),
    ("`aacmm-pin --help`", [sys.executable, "-m", "aacmm_pin", "--help"]),
    ("`aacmm-pin --version`", [sys.executable, "-m", "aacmm_pin", "--version"]),
    ("`aacmm-pin identify --help`", [sys.executable, "-m", "aacmm_pin", "identify", "--help"]),
    ("`aacmm-pin axes` (loads the default arm: Pinocchio, yourdfpy)",
     [sys.executable, "-m", "aacmm_pin", "axes"]),
]


def cpu_of(cmd: list[str]) -> float:
    """Return the median CPU seconds (user + system) of RUNS runs of ``cmd``."""
    times = []
    for _ in range(RUNS):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run(cmd, check=True, capture_output=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        times.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return float(np.median(times))


def main() -> None:
    compile_package()
    rows = [(label, cpu_of(cmd)) for label, cmd in CASES]
    base = rows[0][1]
    table = "\n".join(f"| {label} | {t:.3f} | {t / base:.1f}x |" for label, t in rows)
    write_section("cli", f"""## Command-line start (`python benchmarks/cli.py`)

{machine()}. Whole processes, CPU seconds (user + system), median of {RUNS}; issue targets:
`--help` <= 0.3 s CPU. The CLI imports only argparse-level modules until a command runs. The
package's bytecode is written first, as `pip install` does.

| command | CPU (s) | vs the bare interpreter |
|---|---|---|
{table}""")


if __name__ == "__main__":
    main()
