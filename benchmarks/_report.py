"""Write one section of BENCHMARKS.md (between markers), keeping the other sections."""

from __future__ import annotations

import functools
import platform
import re
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"
HEAD = ("# Benchmarks\n\nEach section is written by the script it names; rerun it to refresh. "
        "Ratios compare methods in the same run (the machines are noisy); a ratio's range is over "
        "the rounds of its run and of the latest earlier runs of the same code on the same machine "
        "(`benchmarks/history.json`), each section says which.\n")


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


def ratio(num, den, fmt: str | None = None, *, name: str) -> str:
    """The ratio of the medians and its range: ``num`` over ``den``, paired by round (interleaved
    runs; ``den``'s first ``len(num)`` rounds when ``num`` ran in fewer).

    ``fmt``: the numbers' format (default: two decimals below 10, none above). ``name``: what the
    ratio compares, unique within the script's run. The range is over the rounds of this run and
    of the earlier runs of the same code on this machine (:func:`pooled`).
    """
    n = np.asarray(num, dtype=float)
    d = np.asarray(den, dtype=float)[:len(n)]
    return pooled(float(np.median(n) / np.median(d)), n / d, fmt, name=name)


HISTORY = BENCH.parent / "benchmarks" / "history.json"
"""Every ratio's rounds of the latest runs, by script, code and machine (:func:`pooled`)."""
KEEP = 5
"""Runs of the same script, code and machine whose rounds a stated range pools."""
_THIS_RUN: dict[str, dict] = {}
"""This run's ratios so far, by name, in the order the script states them."""


def _named_sources(text: str) -> list[Path]:
    """The repository's benchmark and test modules that ``text`` (a script's source) names: as a
    file (``x.py``), a module (``benchmarks.x``, ``tests.x``) or an import (``from x import``)."""
    root = BENCH.parent
    found = []
    for folder in ("benchmarks", "tests"):
        for path in (root / folder).glob("*.py"):
            stem = path.stem
            if (f"{stem}.py" in text or f"{folder}.{stem}" in text
                    or re.search(rf"\b(from|import) {re.escape(stem)}\b", text)):
                found.append(path)
    return found


@functools.cache
def _code() -> str:
    """A digest of the sources a script's ratios depend on, taken once (at this module's import):
    the package's, the script's, the benchmark and test modules it names (its baselines, this
    module), and the package of any folder given as an argument (``figures.py --before DIR``)."""
    import hashlib
    import sys

    digest = hashlib.sha256()
    root = BENCH.parent
    script = Path(sys.argv[0]).resolve()
    text = script.read_text() if script.suffix == ".py" and script.is_file() else ""
    trees = [root] + [Path(a).resolve() for a in sys.argv[1:] if (Path(a) / "aacmm_pin").is_dir()]
    for tree in trees:
        files = {*(tree / "aacmm_pin").rglob("*.py")}
        if tree == root:
            files |= {*_named_sources(text), *([script] if text else [])}
        for path in sorted(files):
            name = path.relative_to(tree) if path.is_relative_to(tree) else path.name
            digest.update(str(name).encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:16]


def _cpu_model() -> str:
    """The processor's model name (Linux), or the platform's processor string."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


@functools.cache
def _machine_key() -> str:
    """The machine as a run key states it: its description, processor model and the versions of
    the libraries the timings depend on (taken once: reading them costs about 10 ms)."""
    from importlib import metadata

    versions = []
    for dist in ("scipy", "pin", "matplotlib"):
        try:
            versions.append(f"{dist} {metadata.version(dist)}")
        except metadata.PackageNotFoundError:
            pass
    return ", ".join([machine(), _cpu_model(), *versions])


def _run_key() -> dict:
    """What a run must share with an earlier one for their rounds to be pooled: the script and
    its arguments, the code (:func:`_code`) and the machine (:func:`_machine_key`)."""
    import sys

    return {"script": " ".join([Path(sys.argv[0]).stem, *sys.argv[1:]]), "code": _code(),
            "machine": _machine_key()}


def _load_history() -> list[dict]:
    """The recorded runs; an unreadable file is reported on stderr and read as empty."""
    import json
    import sys

    if not HISTORY.exists():
        return []
    try:
        runs = json.loads(HISTORY.read_text())
        if not (isinstance(runs, list) and all(isinstance(r, dict) and isinstance(
                r.get("ratios"), dict) for r in runs)):
            raise ValueError("not a list of runs")
    except (OSError, ValueError) as err:
        print(f"{HISTORY}: unreadable ({err}); no earlier run is pooled", file=sys.stderr)
        return []
    return runs


def _same_key(run: dict, key: dict, fields=("script", "code", "machine")) -> bool:
    return all(run.get(k) == key[k] for k in fields)


def _earlier_runs() -> list[dict]:
    """The latest :data:`KEEP` - 1 recorded runs with this run's key, oldest first."""
    key = _run_key()
    runs = [r for r in _load_history() if _same_key(r, key)]
    return runs[max(len(runs) - (KEEP - 1), 0):]


def pooled(value: float, per_round, fmt: str | None = None, suffix: str = "x", *,
           name: str) -> str:
    """``value`` (this run's ratio) and the range of the per-round ratios, pooled over this run's
    rounds and those of the earlier runs of the same script, code and machine
    (:data:`HISTORY`, the latest :data:`KEEP` runs in all): a range within one run understates
    how much a ratio moves between runs (the machine's speed drifts, and not by the same factor
    for every workload). :func:`write_section` records this run and says whether each value fell
    within the earlier runs' range.

    ``per_round``: shape (rounds,), this run's ratio in each round. ``fmt``: the numbers' format
    (default: two decimals below 10, none above). ``name``: what the ratio compares, unique within
    the run (the earlier runs' rounds are looked up by it).
    """
    if name in _THIS_RUN:
        raise ValueError(f"ratio {name!r} stated twice in one run")
    per = np.asarray(per_round, dtype=float)
    earlier = [np.asarray(r["ratios"][name], dtype=float) for r in _earlier_runs()
               if name in r["ratios"]]
    every = np.concatenate([per, *earlier])
    fmt = fmt or (".2f" if every.max() < 10 else ".0f")
    before = np.concatenate(earlier) if earlier else None
    _THIS_RUN[name] = {"value": value, "rounds": per.tolist(), "fmt": fmt, "suffix": suffix,
                       "earlier": None if before is None else (before.min(), before.max())}
    return f"{value:{fmt}}{suffix} ({every.min():{fmt}} - {every.max():{fmt}})"


def _record() -> str:
    """Record this run's ratios in :data:`HISTORY`; print, per ratio, whether its value fell
    within the earlier runs' range; return the paragraph that says so in the section."""
    import datetime
    import fcntl
    import json
    import os
    import sys
    import tempfile

    if not _THIS_RUN:
        return ""
    earlier = _earlier_runs()
    checked, outside = 0, []
    for name, r in _THIS_RUN.items():
        if r["earlier"] is None:
            continue
        f, x = r["fmt"], r["suffix"]
        lo, hi = (float(format(v, f)) for v in r["earlier"])
        inside = lo <= float(format(r["value"], f)) <= hi
        checked += 1
        if not inside:
            outside.append(f"{name}: {r['value']:{f}}{x} against {lo:{f}} - {hi:{f}}")
        print(f"{name}: {r['value']:{f}}{x}, earlier runs {lo:{f}} - {hi:{f}}: "
              f"{'reproduced' if inside else 'NOT reproduced'}", file=sys.stderr)
    key = _run_key()
    lock = Path(tempfile.gettempdir()) / "aacmm_pin-benchmarks-history.lock"
    with open(lock, "w") as held:
        fcntl.flock(held, fcntl.LOCK_EX)  # scripts run side by side: one update at a time
        runs = _load_history()
        # another code's runs of this script on this machine are dropped; of this key the latest
        runs = [r for r in runs
                if not _same_key(r, key, ("script", "machine")) or _same_key(r, key)]
        runs.append({**key, "date": datetime.date.today().isoformat(),
                     "ratios": {n: [round(v, 6) for v in r["rounds"]]
                                for n, r in _THIS_RUN.items()}})
        same = [r for r in runs if _same_key(r, key)]
        runs = [r for r in runs if not any(r is old for old in same[:-KEEP])]
        tmp = HISTORY.with_suffix(".json.tmp")
        tmp.write_text("[\n" + ",\n".join(json.dumps(r) for r in runs) + "\n]\n")  # a run a line
        os.replace(tmp, HISTORY)
    _THIS_RUN.clear()
    if not earlier:
        return ("Ratio ranges: this run's rounds only (no earlier run of the same code on this "
                "machine in `benchmarks/history.json`; a rerun pools its rounds with these).")
    dates = ", ".join(r["date"] for r in earlier)
    runs_text, whose = ("run", "run's") if len(earlier) == 1 else ("runs", "runs'")
    return (f"Ratio ranges: the rounds of this run and of {len(earlier)} earlier {runs_text} of "
            f"the same code on this machine ({dates}; `benchmarks/history.json`): within one run "
            f"the rounds understate how far a ratio moves between runs. The values are this "
            f"run's; "
            + (f"{'the one value' if checked == 1 else f'all {checked}'} fell within the "
               f"earlier {whose} range." if checked and not outside else
               "none of them was stated by the earlier runs." if not checked else
               f"{checked - len(outside)} of {checked} fell within the earlier {whose} "
               f"range, not: " + "; ".join(outside) + " (the ranges above include them)."))


def compile_package(root: Path | None = None) -> None:
    """Write aacmm_pin's bytecode (``__pycache__``), as ``pip install`` does, so that whole-process
    timings do not include compiling the package's sources (this machine sets
    ``PYTHONDONTWRITEBYTECODE``: without it every process compiles them again).

    ``root``: the checkout whose package to compile (default: this one)."""
    import compileall

    compileall.compile_dir(str((root or BENCH.parent) / "aacmm_pin"), quiet=1)


def machine() -> str:
    """One line describing this machine."""
    import os

    return (f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"numpy {np.__version__}")


def write_section(name: str, body: str) -> None:
    """Replace (or append) the section ``name`` of BENCHMARKS.md with ``body``, followed by how
    its ratios compare with the earlier runs' (:func:`pooled`)."""
    note = _record()
    body = body.rstrip() + (f"\n\n{note}" if note else "")
    text = BENCH.read_text() if BENCH.exists() else HEAD
    start, end = f"<!-- {name} -->", f"<!-- /{name} -->"
    block = f"{start}\n{body.rstrip()}\n{end}"
    if start in text:
        text = re.sub(re.escape(start) + ".*?" + re.escape(end), lambda _: block, text, flags=re.S)
    else:
        text = text.rstrip() + "\n\n" + block + "\n"
    BENCH.write_text(text)
    print(body)


_code()  # taken when a script imports this module: the code its run measures
