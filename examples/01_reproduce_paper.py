"""Reproduce the paper's experiment (Ibaraki & Saito 2023, Figs. 5, 6 and 9) on the default arm.

Simulates a SPAT + length-bar campaign, identifies the three models of Fig. 9, validates them on
the length bar and writes the figures; then copies the figures to ``examples/figures/`` for the
README. Run: ``python examples/01_reproduce_paper.py [OUT]`` (about 15 s).
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

from aacmm_pin.demo import run_demo

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("aacmm-pin-demo")
run_demo(out, seed=0)
figures = Path(__file__).resolve().parent / "figures"
figures.mkdir(exist_ok=True)
for name in ("fig5_rtest_displacement.png", "fig6_encoder_maps.png", "fig9_length_errors.png"):
    shutil.copy(out / name, figures / name)
print(f"copied the figures to {figures}")
