"""What the figures cost in ``aacmm-pin discover`` on the paper campaign: CPU of the whole process
and of its figures, split in the same run.

Run: ``python benchmarks/figures.py`` (about a minute; writes its section of BENCHMARKS.md).
Campaigns: the sample campaign (``../shared/sample-campaign``: 4 R-Test locations x 200 SPAT
samples and 7 length-bar placements; skipped where it is absent) and the simulated paper campaign
(``aacmm-pin simulate``, seed 0, the same sizes). Each run is a whole
process (``python benchmarks/figures.py --child CAMPAIGN OUT``) that runs the CLI's ``main``
(``aacmm-pin discover CAMPAIGN --out OUT``) with the discovery's figure functions wrapped in a
CPU clock: the figures' share includes importing matplotlib (only the figures need it). CPU is
user + system of the process (``RUSAGE_SELF``, interpreter start included). Median and range of
5 runs per campaign.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT.parent / "shared" / "sample-campaign"
REPEAT = 5
FIGURES = ("gap_figure", "step_figure", "unexplained_figure")
"""The figure functions ``write_discovery`` calls (module attributes of discovery_figures), inside
``figure_batch`` (clocked too: it imports matplotlib)."""


def child(campaign: str, out: str) -> None:
    """Run ``aacmm-pin discover`` in this process; print its CPU and its figures' as JSON."""
    sys.path.insert(0, str(ROOT))
    import aacmm_pin.outputs.discovery_figures as figures
    from aacmm_pin.cli import main as cli

    spent = [0.0]

    def clocked(f):
        def run(*args, **kwargs):
            tic = time.process_time()
            try:
                return f(*args, **kwargs)
            finally:
                spent[0] += time.process_time() - tic
        return run

    for name in FIGURES:
        setattr(figures, name, clocked(getattr(figures, name)))
    batch = figures.figure_batch

    @contextmanager
    def clocked_batch():
        """figure_batch with its entry (it imports matplotlib) and exit clocked."""
        tic = time.process_time()
        with batch():
            spent[0] += time.process_time() - tic
            yield
            tic = time.process_time()
        spent[0] += time.process_time() - tic

    figures.figure_batch = clocked_batch
    with open(os.devnull, "w") as sink:
        stdout, sys.stdout = sys.stdout, sink
        try:
            status = cli(["discover", campaign, "--out", out])
        finally:
            sys.stdout = stdout
    use = resource.getrusage(resource.RUSAGE_SELF)
    pngs = sorted(p.name for p in Path(out).glob("*.png"))
    print(json.dumps({"status": status, "cpu": use.ru_utime + use.ru_stime, "figures": spent[0],
                      "pngs": pngs}))


def run_once(campaign: Path, out: Path) -> dict:
    """One whole process; its measurements."""
    text = subprocess.run([sys.executable, __file__, "--child", str(campaign), str(out)],
                          check=True, capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(ROOT))).stdout
    return dict(json.loads(text.strip().splitlines()[-1]))


def main() -> None:
    sys.path.insert(0, str(ROOT))
    from benchmarks._report import compile_package, machine, write_section

    compile_package()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        simulated = Path(tmp) / "c"
        subprocess.run([sys.executable, "-m", "aacmm_pin", "simulate", str(simulated)],
                       check=True, capture_output=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
        cases = [("the sample campaign (`../shared/sample-campaign`: 4 x 200 SPAT samples, "
                  "7 bar placements)", SAMPLE),
                 ("the simulated paper campaign (`aacmm-pin simulate c`, seed 0: 4 x 200 SPAT "
                  "samples, 7 bar placements)", simulated)]
        for label, campaign in cases:
            if not (campaign / "spat.csv").exists():
                continue
            runs = [run_once(campaign, Path(tmp) / f"d{len(rows)}{k}") for k in range(REPEAT)]
            assert all(r["status"] == 0 for r in runs), runs
            cpu = np.array([r["cpu"] for r in runs])
            fig = np.array([r["figures"] for r in runs])
            rows.append(f"| {label} | {stat(cpu, '.2f')} | {stat(fig, '.2f')} | "
                        f"{stat(100 * fig / cpu, '.0f')} | {', '.join(runs[0]['pngs'])} |")
    table = "\n".join(rows)
    body = f"""## Figures of `discover` (`python benchmarks/figures.py`)

{machine()}. `aacmm-pin discover CAMPAIGN --out DIR`, whole processes (interpreter start included),
CPU = user + system; the figures' CPU is measured in the same process around the figure functions
`write_discovery` calls (importing matplotlib included, about 0.4 s: only the figures need it).
The figures are drawn after the results are printed, with fixed margins (no constrained layout)
and one legend per step figure. Median (range) of {REPEAT} runs per campaign; issue 28's target:
figures <= 25 % of the command's CPU. Before issue 28 (constrained layout, a legend per panel;
the same runs on that code): 36 - 37 % on the sample campaign (3 runs, load 0.8; 37 - 42 % in 5
runs at load 1.5), 27 % on the simulated one (2 runs, load 5).

| campaign | command CPU (s) | figures CPU (s) | figures' share (%) | PNGs written |
|---|---|---|---|---|
{table}
"""
    write_section("figures", body)


def stat(v: np.ndarray, fmt: str) -> str:
    """Median (min - max) of v."""
    return f"{np.median(v):{fmt}} ({v.min():{fmt}} - {v.max():{fmt}})"


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--child":
        child(sys.argv[2], sys.argv[3])
    else:
        main()
