"""Reproduce the paper's experiment (Ibaraki & Saito 2023, Figs. 5, 6 and 9) on the default arm.

Simulates a SPAT + length-bar campaign, identifies the three models of Fig. 9, validates them on
the length bar and writes the figures. Run: ``python examples/01_reproduce_paper.py [OUT]
[--figures DIR]`` (about 7 s).

``OUT`` is the demo's folder (default ``examples/out/aacmm-pin-demo``, which git ignores; a rerun
replaces it); ``--figures DIR`` also copies the three figures to DIR
(``--figures examples/figures`` refreshes the README's pictures, on purpose only: they are tracked).
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from aacmm_pin.outputs.demo import run_demo

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("out", nargs="?", help="output folder of the demo "
                    "(default: examples/out/aacmm-pin-demo, replaced by a rerun)")
parser.add_argument("--figures", help="also copy the figures there (examples/figures: the "
                    "README's pictures)")
args = parser.parse_args()

# the default folder is this example's own (git ignores it): a rerun replaces it
out = Path(args.out) if args.out else Path(__file__).resolve().parent / "out" / "aacmm-pin-demo"
run_demo(out, seed=0, force=args.out is None)
if args.figures:
    figures = Path(args.figures)
    figures.mkdir(parents=True, exist_ok=True)
    for name in ("fig5_rtest_displacement.png", "fig6_encoder_maps.png", "fig9_length_errors.png"):
        shutil.copy(out / name, figures / name)
    print(f"copied the figures to {figures}")
