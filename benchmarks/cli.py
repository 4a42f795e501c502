"""CPU time of starting the command line: `aacmm-pin --help`, `--version`, a command's help.

Each is run as a whole process (as a user starts it); CPU from RUSAGE_CHILDREN, median (range) of
9 interleaved rounds (each round runs every command once), beside `python -c pass` and `python -c
"import numpy"` in the same rounds; ratios to the bare interpreter per round (noisy machines).
A start-up cost: the baselines are the interpreter and its imports, not another implementation.

``python benchmarks/cli.py --floors`` (about two minutes; section ``floors``): ``identify`` as a
whole process against its floor, measured in the same rounds: the interpreter with the imports
its work cannot avoid (:data:`FLOOR_IMPORTS`, one BLAS thread) as a whole process, plus its
evaluations (``identify`` in this process, after a warm-up call); on the UR5 grid also against
the careful hand-written fit (``benchmarks/ur5_handwritten.py``) as a whole process.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np
from _report import compile_package, cpu_runs, machine, ratio, spread, write_section

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


ROOT = Path(__file__).resolve().parents[1]
UR5 = ROOT.parent / "shared" / "real-data" / "jacobi2025-laser-tracker" / "UR5"
HAND = ROOT / "benchmarks" / "ur5_handwritten.py"
FLOOR_IMPORTS = ("numpy, scipy.linalg, scipy.optimize, scipy.sparse.linalg, scipy.special, "
                 "pinocchio, lxml.etree, threadpoolctl")
"""What an identification cannot avoid importing (``tests/test_imports.py``'s floor): arrays,
the solver and its sparse operators, the noise tests' special functions, the kinematics, the URDF
tree, the BLAS thread limit."""
HEADER = ("| campaign | CLI CPU (s) | floor imports (s) | evaluations in-process (s) | floor (s) | "
          "CLI / floor | careful fit, whole process (s) | CLI / careful fit | careful fit under "
          "the CLI's collector policy (s) | CLI / that |\n"
          "|---|---|---|---|---|---|---|---|---|---|")
FLOOR_RUNS = 11
"""Interleaved rounds of the floors section."""
IN_PROCESS = 5
"""identify calls per round in this process (their mean is the round's evaluations)."""


COMMAND_HEADER = ("| command | CLI CPU (s) | floor imports (s) | the command in-process, warm (s) | "
                  "floor (s) | CLI / floor |\n|---|---|---|---|---|---|")
PREDICT_IMPORTS = "numpy, pinocchio, lxml.etree"
"""What ``predict`` cannot avoid importing: arrays, the kinematics, the URDF tree (no SciPy:
``tests/test_imports.py``)."""
FIGURE_IMPORTS = "matplotlib.figure, matplotlib.backends.backend_agg"
"""What ``discover``'s figures cannot avoid importing beside :data:`FLOOR_IMPORTS`."""


COLLECTOR = ROOT / "aacmm_pin" / "cli" / "_collector.py"
"""The collector policy of ``aacmm-pin`` (imports without the collector, their objects frozen to
the exit), loaded by path in the floors' processes (no package import)."""


def as_the_program(body: str) -> list[str]:
    """A whole-process command running the Python ``body`` under ``aacmm-pin``'s collector policy.

    ``aacmm-pin`` imports with the garbage collector off and keeps what the imports made frozen to
    its exit (:mod:`aacmm_pin.cli._collector`); a floor run the plain way would pay collections and
    an exit the program does not (~0.1-0.2 s), so the floors and the careful fit's second column
    are run the same way.
    """
    prelude = ("import importlib.util as u\n"
               f"s = u.spec_from_file_location('collector', {str(COLLECTOR)!r})\n"
               "m = u.module_from_spec(s)\ns.loader.exec_module(m)\n"
               "with m.imports_uncollected(keep_frozen=True):\n")
    return [sys.executable, "-c", prelude + textwrap.indent(body, "    ")]


def _in_process(argv: list[str]) -> float:
    """Return the CPU seconds of ``aacmm-pin ARGV`` run in this process (output discarded)."""
    import contextlib
    import io
    import time

    from aacmm_pin.cli import main as cli_main

    tic = time.process_time()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        status = cli_main(argv)
    elapsed = time.process_time() - tic
    if status not in (0, 1):  # 1: a finding (e.g. discover's unexplained residual), not a failure
        raise RuntimeError(f"aacmm-pin {' '.join(argv)} exited {status}")
    return elapsed


def _command_rows(cli: list[str], tmp: Path) -> list[str]:
    """Rows of ``predict`` and ``discover`` on the paper campaign: CLI against its floor."""
    from aacmm_pin._blas import single_threaded_blas

    subprocess.run([*cli, "identify", str(tmp / "c"), "--out", str(tmp / "cc")], check=True,
                   capture_output=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    cases = [("`aacmm-pin predict` (the paper campaign's calibration, its 800 SPAT readouts)",
              ["predict", str(tmp / "cc"), str(tmp / "c" / "spat.csv"), "--force", "--out"],
              "points.csv", PREDICT_IMPORTS),
             ("`aacmm-pin discover` (the simulated paper campaign, default options)",
              ["discover", str(tmp / "c"), "--force", "--out"], "disc",
              f"{FLOOR_IMPORTS}, {FIGURE_IMPORTS}")]
    rows = []
    for label, argv, out, imports in cases:
        runs: dict[str, list[float]] = {"cli": [], "imports": [], "work": []}
        with single_threaded_blas():
            _in_process([*argv, str(tmp / f"warm-{out}")])
            for k in range(FLOOR_RUNS):
                runs["cli"].append(cpu_of([*cli, *argv, str(tmp / f"cli{k}-{out}")], {}))
                runs["imports"].append(cpu_of(as_the_program(f"import {imports}"), ONE))
                runs["work"].append(_in_process([*argv, str(tmp / f"in{k}-{out}")]))
        floor = np.add(runs["imports"], runs["work"])
        rows.append(f"| {label} | {spread(runs['cli'])} | {spread(runs['imports'])} | "
                    f"{spread(runs['work'], '.3f')} | {spread(floor)} | "
                    f"{ratio(runs['cli'], floor, name=label + ': CLI / floor')} |")
    return rows


def floors() -> None:
    """Write the ``floors`` section: identify as a whole process against its floor."""
    import aacmm_pin as ap
    from aacmm_pin._blas import single_threaded_blas

    compile_package()
    cli = [sys.executable, "-m", "aacmm_pin"]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    rows, notes = [], []
    with tempfile.TemporaryDirectory() as folder:
        tmp = Path(folder)
        subprocess.run([*cli, "simulate", str(tmp / "c")], check=True, capture_output=True,
                       env=env)
        subprocess.run([*cli, "import-points", str(UR5 / "3D_UR5_uncalibrated_grid_cleaned.csv"),
                        "--out", str(tmp / "g")], check=True, capture_output=True, env=env)
        cases = [("the UR5 grid (1000 laser-tracker points), `--arm ur5 --model dh`", tmp / "g",
                  ["--arm", "ur5", "--model", "dh"], "ur5", "dh", True),
                 ("the simulated paper campaign (`aacmm-pin simulate c`: 4 x 200 SPAT samples, "
                  "7 bar placements), `--model proposed`", tmp / "c", ["--model", "proposed"],
                  None, "proposed", False)]
        for label, campaign, options, arm_name, model, hand in cases:
            arm = ap.load_arm(arm_name) if arm_name else ap.load_arm()
            data = ap.read_campaign(campaign, arm=arm)
            runs: dict[str, list[float]] = {"cli": [], "imports": [], "work": [], "hand": [],
                                            "hand_as_program": []}
            with single_threaded_blas():  # as the CLI: one BLAS thread
                ap.identify(data, arm, model=model)  # warm-up: caches built once per process
                for k in range(FLOOR_RUNS):
                    runs["cli"].append(cpu_of([*cli, "identify", str(campaign), *options, "--out",
                                               str(tmp / f"cal{k}"), "--force"], {}))
                    runs["imports"].append(cpu_of(as_the_program(f"import {FLOOR_IMPORTS}"),
                                                  ONE))
                    runs["work"].append(float(np.mean(cpu_runs(
                        lambda: ap.identify(data, arm, model=model), IN_PROCESS)[0])))
                    if hand:
                        files = [str(UR5 / f"3D_UR5_uncalibrated_{s}_cleaned.csv")
                                 for s in ("grid", "random")]
                        runs["hand"].append(cpu_of([sys.executable, str(HAND), *files], ONE))
                        runs["hand_as_program"].append(cpu_of(as_the_program(
                            f"import runpy, sys\nsys.argv = {[str(HAND), *files]!r}\n"
                            f"runpy.run_path({str(HAND)!r}, run_name='__main__')"), ONE))
            floor = np.add(runs["imports"], runs["work"])
            as_program = label + ": CLI / hand as the program"
            rows.append(f"| {label} | {spread(runs['cli'])} | {spread(runs['imports'])} | "
                        f"{spread(runs['work'], '.3f')} | {spread(floor)} | "
                        f"{ratio(runs['cli'], floor, name=label + ': CLI / floor')} | "
                        + (f"{spread(runs['hand'])} | "
                           f"{ratio(runs['cli'], runs['hand'], name=label + ': CLI / hand')} | "
                           f"{spread(runs['hand_as_program'])} | "
                           f"{ratio(runs['cli'], runs['hand_as_program'], name=as_program)} |"
                           if hand else "- | - | - | - |"))
            notes.append(label)
        commands = _command_rows(cli, tmp)
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    write_section("floors", f"""## Commands against their floor (`python benchmarks/cli.py --floors`)

{machine()}. `aacmm-pin identify` as a whole process (`python -m aacmm_pin identify CAMPAIGN ...
--out DIR`: interpreter start, imports, reading and checking the campaign, the fit, writing the
calibration folder), CPU = user + system, against its floor measured in the same rounds: the
interpreter with the imports its work cannot avoid (`python -c "import {FLOOR_IMPORTS}"`, one
BLAS thread, as a whole process, under the CLI's collector policy: imports without the garbage
collector, their objects frozen to the exit, `aacmm_pin/cli/_collector.py`, as `aacmm-pin` runs;
`tests/test_imports.py` fails if `identify` imports any other
third-party module) plus its evaluations (`identify(campaign, arm)` in-process, the mean of
{IN_PROCESS} calls after a warm-up: the fit alone, its caches built). On the UR5 grid also against
the careful hand-written fit (`benchmarks/ur5_handwritten.py`: numpy and scipy's optimizer, no
Pinocchio; whole process, one BLAS thread), as written (Python's default collection) and run under
the CLI's collector policy (the like-for-like comparison: the policy saves either process its
collections during imports and most of its exit). Median (range) of {FLOOR_RUNS} interleaved rounds;
ratios of the medians, their range over the rounds of this run and of the earlier runs named below.
Issue 41's targets: the UR5 grid at most 1.2x the careful fit, the paper campaign at most 1.3x its
floor. The load average (1, 5 and 15 min) when this table was written: {load}.

{HEADER}
{chr(10).join(rows)}

What lies between the CLI and its floor: the package's own modules (~0.09 s, of which ~0.04 s
creates its ~40 dataclasses), the first call's set-up (the arm's identification model, caches a
warm call finds built: ~0.02-0.04 s), reading and checking the campaign (~0.01 s) and writing the
calibration folder (parameters, URDF, compact URDF and its loss, report: ~0.05 s). The command line
builds only the named command's parser and loads no effect plugin for a campaign whose columns
are the package's.

Other commands, each against the same command run in this process after a warm-up (its
modules loaded, its caches built: the work itself, files written and printing included) plus
the imports its work cannot avoid as a whole process (`predict`: `{PREDICT_IMPORTS}`, no SciPy;
`discover`: the identify floor's and matplotlib's figure and Agg canvas, which its figures
need); same rounds, median (range):

{COMMAND_HEADER}
{chr(10).join(commands)}""")


if __name__ == "__main__":
    if sys.argv[1:] == ["--floors"]:
        floors()
    else:
        main()
