"""Cost per sample of stylus positions and full Jacobians (Pinocchio), against a plain numpy loop.

Run: ``python benchmarks/kinematics.py`` (writes its section of BENCHMARKS.md).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from aacmm_pin import Parameters, load_arm, stylus_jacobians, stylus_positions  # noqa: E402
from benchmarks._report import machine, write_section  # noqa: E402
from tests.helpers import paper_stylus  # noqa: E402


def best(f, repeat: int = 5) -> float:
    times = []
    for _ in range(repeat):
        tic = time.perf_counter()
        f()
        times.append(time.perf_counter() - tic)
    return min(times)


def main() -> None:
    arm = load_arm()
    params = Parameters.nominal(arm)
    n = 20_000
    q = np.random.default_rng(0).uniform(-3, 3, (n, 7))
    t_pos = best(lambda: stylus_positions(arm, params, q)) / n
    t_jac = best(lambda: stylus_jacobians(arm, params, q)) / n
    m = 2_000
    t_ref = best(lambda: [paper_stylus(qi, params.dh, params.tool) for qi in q[:m]], 3) / m
    body = f"""## Kinematics cost per sample (`python benchmarks/kinematics.py`)

{machine()}; {n} random readouts, best of 5.

| what | us per sample | vs plain numpy Eq. (2) positions |
|---|---|---|
| stylus position (Pinocchio FK) | {t_pos * 1e6:.2f} | {t_ref / t_pos:.1f}x faster |
| position + full Jacobian (38 columns: X0, translation, 7 axes, 22 DH, tool) | \
{t_jac * 1e6:.2f} | {t_ref / t_jac:.1f}x faster |
| plain numpy transcription of Eq. (2), position only (`tests/helpers.py`) | {t_ref * 1e6:.2f} | 1x |

Map-node columns follow from the axis columns by the interpolation weights (two per axis and
sample) and add no kinematics cost."""
    write_section("kinematics", body)


if __name__ == "__main__":
    main()
