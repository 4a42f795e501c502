"""Reproduce the paper's experiment (Ibaraki & Saito 2023, Figs. 5, 6 and 9) on the default arm.

Simulates a SPAT + length-bar campaign, identifies the three models of Fig. 9, validates them on
the length bar and writes the figures; then copies the figures to ``examples/figures/`` for the
README. Run: ``python examples/01_reproduce_paper.py [OUT] [--figures DIR]`` (about 15 s).

``OUT`` is the demo's folder (default ``aacmm-pin-demo``); ``--figures`` is where the three figures
are copied (default ``examples/figures``, the README's pictures; the test suite, which runs this
script, copies them into its own temporary folder instead).
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from aacmm_pin.outputs.demo import run_demo

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("out", nargs="?", default="aacmm-pin-demo", help="output folder of the demo")
parser.add_argument("--figures", help="where to copy the figures (default: examples/figures)")
args = parser.parse_args()

out = Path(args.out)
run_demo(out, seed=0)
figures = Path(args.figures) if args.figures else Path(__file__).resolve().parent / "figures"
figures.mkdir(parents=True, exist_ok=True)
for name in ("fig5_rtest_displacement.png", "fig6_encoder_maps.png", "fig9_length_errors.png"):
    shutil.copy(out / name, figures / name)
print(f"copied the figures to {figures}")
