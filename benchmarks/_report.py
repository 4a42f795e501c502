"""Write one section of BENCHMARKS.md (between markers), keeping the other sections."""

from __future__ import annotations

import platform
import re
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"
HEAD = ("# Benchmarks\n\nEach section is written by the script it names; rerun it to refresh. "
        "Ratios compare methods in the same run (the machines are noisy).\n")


def best_of(f, repeat: int):
    """Return the best wall time of ``repeat`` calls of ``f`` and the last result."""
    import time

    best, out = np.inf, None
    for _ in range(repeat):
        tic = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - tic)
    return best, out


def cpu_runs(f, repeat: int):
    """Return the CPU seconds of ``repeat`` calls of ``f`` (this process) and the last result."""
    import time

    out, times = None, []
    for _ in range(repeat):
        tic = time.process_time()
        out = f()
        times.append(time.process_time() - tic)
    return times, out


def spread(values, fmt: str = ".2f") -> str:
    """Median (min - max) of ``values``, each formatted with ``fmt``."""
    v = np.asarray(values)
    return f"{np.median(v):{fmt}} ({v.min():{fmt}} - {v.max():{fmt}})"


def ratio(num, den, fmt: str | None = None) -> str:
    """The ratio of the medians and its range over the rounds: ``num`` over ``den``, paired by
    round (interleaved runs; ``den``'s first ``len(num)`` rounds when ``num`` ran in fewer).

    ``fmt``: the numbers' format (default: two decimals below 10, none above).
    """
    n = np.asarray(num, dtype=float)
    d = np.asarray(den, dtype=float)[:len(n)]
    per = n / d
    fmt = fmt or (".2f" if per.max() < 10 else ".0f")
    return f"{np.median(n) / np.median(d):{fmt}}x ({per.min():{fmt}} - {per.max():{fmt}})"


def compile_package() -> None:
    """Write aacmm_pin's bytecode (``__pycache__``), as ``pip install`` does, so that whole-process
    timings do not include compiling the package's sources (this machine sets
    ``PYTHONDONTWRITEBYTECODE``: without it every process compiles them again)."""
    import compileall

    compileall.compile_dir(str(BENCH.parent / "aacmm_pin"), quiet=1)


def machine() -> str:
    """One line describing this machine."""
    import os

    return (f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"numpy {np.__version__}")


def write_section(name: str, body: str) -> None:
    """Replace (or append) the section ``name`` of BENCHMARKS.md with ``body``."""
    text = BENCH.read_text() if BENCH.exists() else HEAD
    start, end = f"<!-- {name} -->", f"<!-- /{name} -->"
    block = f"{start}\n{body.rstrip()}\n{end}"
    if start in text:
        text = re.sub(re.escape(start) + ".*?" + re.escape(end), lambda _: block, text, flags=re.S)
    else:
        text = text.rstrip() + "\n\n" + block + "\n"
    BENCH.write_text(text)
    print(body)
