"""What the figures cost in ``aacmm-pin discover`` on the sample campaign, the simulated paper
campaign and the UR5 grid: CPU of the whole process and of its figures, split in the same run.

Run: ``python benchmarks/figures.py [--before DIR]`` (about a minute; writes its section of
BENCHMARKS.md). ``--before DIR``: a checkout of the code before a change (``git worktree add DIR
REF``), measured in the same runs, interleaved with this one's: on a loaded machine the CPU of
both grows, and only runs side by side compare.
Campaigns: the sample campaign (``../shared/sample-campaign``: 4 R-Test locations x 200 SPAT
samples and 7 length-bar placements; skipped where it is absent), the simulated paper campaign
(``aacmm-pin simulate``, seed 0, the same sizes) and the UR5 grid (1000 laser-tracker points,
``aacmm-pin import-points`` of the public file, ``--arm ur5``; skipped where absent): issue 41's
target is the figures at most 25 % of the command's CPU on the sample campaign and the UR5 grid.
Each run is a whole
process (``python benchmarks/figures.py --child CAMPAIGN OUT ROOT``) that runs the CLI's ``main``
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
UR5_GRID = (ROOT.parent / "shared" / "real-data" / "jacobi2025-laser-tracker" / "UR5"
            / "3D_UR5_uncalibrated_grid_cleaned.csv")
"""The UR5's grid poses (public laser-tracker data; skipped where absent)."""
FIGURES = ("gap_figure", "step_figure", "unexplained_figure")
"""The figure functions ``write_discovery`` calls (module attributes of discovery_figures), inside
``figure_batch`` (clocked too: it imports matplotlib)."""


def child(campaign: str, out: str, root: str, *options: str) -> None:
    """Run ``aacmm-pin discover`` of the package in ``root`` in this process; print its CPU and its
    figures' as JSON. ``options``: the command's further options (``--arm ur5``)."""
    sys.path.insert(0, root)
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
    batch = getattr(figures, "figure_batch", None)

    @contextmanager
    def clocked_batch():
        """figure_batch with its entry (it imports matplotlib) and exit clocked."""
        tic = time.process_time()
        with batch():
            spent[0] += time.process_time() - tic
            yield
            tic = time.process_time()
        spent[0] += time.process_time() - tic

    if hasattr(figures, "figure_batch"):  # a checkout before it has none
        figures.figure_batch = clocked_batch
    with open(os.devnull, "w") as sink:
        stdout, sys.stdout = sys.stdout, sink
        try:
            status = cli(["discover", campaign, "--out", out, *options])
        finally:
            sys.stdout = stdout
    use = resource.getrusage(resource.RUSAGE_SELF)
    pngs = sorted(p.name for p in Path(out).glob("*.png"))
    print(json.dumps({"status": status, "cpu": use.ru_utime + use.ru_stime, "figures": spent[0],
                      "pngs": pngs}))


def run_once(campaign: Path, out: Path, root: Path = ROOT, options: tuple[str, ...] = ()) -> dict:
    """One whole process running the package in ``root``; its measurements."""
    text = subprocess.run([sys.executable, __file__, "--child", str(campaign), str(out), str(root),
                           *options],
                          check=True, capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(root))).stdout
    return dict(json.loads(text.strip().splitlines()[-1]))


def main(before: Path | None = None) -> None:
    """Measure both campaigns and write the section; ``before``: a checkout of the package before
    a change, measured in the same runs (interleaved)."""
    sys.path.insert(0, str(ROOT))
    from benchmarks._report import compile_package, machine, pooled, ratio, spread, write_section

    compile_package()
    if before is not None:  # its bytecode too: else each of its runs compiles the whole package
        compile_package(before)
    rows: list[str] = []
    paired: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        simulated = Path(tmp) / "c"
        subprocess.run([sys.executable, "-m", "aacmm_pin", "simulate", str(simulated)],
                       check=True, capture_output=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
        grid = Path(tmp) / "g"
        if UR5_GRID.exists():
            subprocess.run([sys.executable, "-m", "aacmm_pin", "import-points", str(UR5_GRID),
                            "--out", str(grid)], check=True, capture_output=True,
                           env=dict(os.environ, PYTHONPATH=str(ROOT)))
        cases = [("the sample campaign (`../shared/sample-campaign`: 4 x 200 SPAT samples, "
                  "7 bar placements)", SAMPLE, ()),
                 ("the simulated paper campaign (`aacmm-pin simulate c`, seed 0: 4 x 200 SPAT "
                  "samples, 7 bar placements)", simulated, ()),
                 ("the UR5 grid (1000 laser-tracker points, `--arm ur5`)", grid,
                  ("--arm", "ur5"))]
        for label, campaign, options in cases:
            if not ((campaign / "spat.csv").exists() or (campaign / "points.csv").exists()):
                continue
            trees = [("", ROOT)] + ([(" (before, `--before`)", before)] if before else [])
            runs: dict[Path, list[dict]] = {root: [] for _, root in trees}
            for k in range(REPEAT):  # interleaved: both trees see the same load
                for i, (_, root) in enumerate(trees):
                    runs[root].append(run_once(campaign, Path(tmp) / f"d{len(rows)}{k}{i}", root,
                                               options))
            for name, root in trees:
                assert all(r["status"] == 0 for r in runs[root]), runs[root]
                cpu = np.array([r["cpu"] for r in runs[root]])
                fig = np.array([r["figures"] for r in runs[root]])
                share = 100 * fig / cpu  # per round, %
                rows.append(f"| {label}{name} | {spread(cpu)} | {spread(fig)} | "
                            f"{pooled(float(np.median(share)), share, '.0f', '', name=label + name)} | "
                            f"{', '.join(runs[root][0]['pngs'])} |")
            if before:  # the figures' CPU of this code over the code before, paired by round
                ours, old = ([r["figures"] for r in runs[root]] for root in (ROOT, before))
                paired.append(f"{label.split(' (')[0]}: {ratio(ours, old, name=label + ' against before')}")
    table = "\n".join(rows)
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())  # 1, 5 and 15 min
    rows_before = (" The rows marked \"before\" are the code before these changes, run in the "
                   "same runs, interleaved with this code's (`--before DIR`; its bytecode written "
                   "first, as this code's); the figures' CPU of "
                   "this code over the code before's, per round (median, range over the rounds "
                   "of this run and of the earlier runs named below): "
                   + "; ".join(paired) + " (a range that holds 1: within the runs' noise)."
                   if before else "")
    body = f"""## Figures of `discover` (`python benchmarks/figures.py`)

{machine()}. `aacmm-pin discover CAMPAIGN --out DIR`, whole processes (interpreter start included),
CPU = user + system; the figures' CPU is measured in the same process around the figure functions
`write_discovery` calls and the entry and exit of their `figure_batch` (importing matplotlib
included: only the figures need it). The figures are drawn after the results are
printed, with fixed margins (no constrained layout), by `outputs.figure_files`: text unhinted
(`text.hinting` "none") and each line of it laid out and rendered by FreeType in one call, once
(`outputs.text_canvas.StringCanvas`, the figures' Agg canvas: matplotlib 3.10's Agg text, where
3.11 draws glyph by glyph from Python; the glyphs within a pixel of 3.11's), written by
`outputs.png_files` (zlib level 3, rows unfiltered: Pillow chose a filter per row; RGB: an opaque
figure, the same pixels as matplotlib's RGBA file), no tick built outside the view
(`outputs.in_view_ticks`: the same pixels), and the objects the process holds, then matplotlib's,
frozen (`gc.freeze`) while the figures are written. The discovery figures
(`outputs.discovery_figures`) draw at most 4 intervals between ticks per axis (2 to 5 labelled
ticks, `TICKS`), at 120 dpi (`DPI`; the package's other figures 150), their legends as lines of
text (`figure_files.text_legend`: a legend box packs its entries anew at each draw), and the step
and unexplained figures share one figure's panels (`figure_files.PanelFigure`: built once, moved
and emptied for each figure, the same pixels as new panels; `figure_files.same_y`: sharey's one
range). Median (range) of {REPEAT} runs per
campaign (the figures' share: its range over the runs of this benchmark's run and of the earlier
ones named below); issue 41's target: figures <= 25 % of the command's CPU on the sample campaign
and the UR5 grid.{rows_before} The load average (1, 5 and 15 min) when this table was written: {load}:
CPU times grow with the load.

| campaign | command CPU (s) | figures CPU (s) | figures' share (%) | PNGs written |
|---|---|---|---|---|
{table}
"""
    write_section("figures", body)


if __name__ == "__main__":
    if len(sys.argv) >= 5 and sys.argv[1] == "--child":
        child(*sys.argv[2:])
    elif len(sys.argv) == 3 and sys.argv[1] == "--before":
        main(Path(sys.argv[2]).resolve())
    else:
        main()
