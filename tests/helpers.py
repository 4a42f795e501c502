"""Shared test helpers: an independent plain-numpy transcription of the paper's equations.

Written from Ibaraki & Saito, CIRP Annals 2023, Eq. (1)-(4) and Section 2.2, not from aacmm_pin's
code: homogeneous transforms D_x, D_y, D_z (translations) and D_a, D_b, D_c (right-handed rotations
about X, Y, Z), multiplied left to right.
"""

from __future__ import annotations

import contextlib
import io
import os
from pathlib import Path

import numpy as np

SHARED = Path(__file__).resolve().parents[2] / "shared"
SAMPLE = SHARED / "sample-campaign"
ROOT = Path(__file__).resolve().parents[1]
"""The project's folder."""
ENV = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
"""Environment of a subprocess that imports this checkout's aacmm_pin."""

# Nominal link lengths of the default arm (issue text), m.
L2Z, L3X, L3Z, L5X, L5Z, L7X = 0.200, 0.600, 0.050, 0.050, 0.550, 0.100
DH_NAMES = ["dx21", "a21", "dy32", "dz32", "b32", "c32", "dth30", "dx43", "dz43", "c43", "dth40",
            "dx54", "dy54", "a54", "dth50", "dx65", "dz65", "a65", "dth60", "dx76", "dy76", "a76"]


def d_x(v: float) -> np.ndarray:
    t = np.eye(4)
    t[0, 3] = v
    return t


def d_y(v: float) -> np.ndarray:
    t = np.eye(4)
    t[1, 3] = v
    return t


def d_z(v: float) -> np.ndarray:
    t = np.eye(4)
    t[2, 3] = v
    return t


def d_a(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def d_b(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def d_c(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def map_error(table: np.ndarray, readout: float) -> float:
    """Linear interpolation of a periodic table with nodes at -180, -180+s, ... deg (Section 2.2)."""
    n = len(table)
    step = 2 * np.pi / n
    theta = (readout + np.pi) % (2 * np.pi)  # position along the table from -180 deg
    i = int(theta // step)
    f = theta / step - i
    return (1 - f) * table[i % n] + f * table[(i + 1) % n]


def paper_stylus(readouts: np.ndarray, dh: dict[str, float], tool: np.ndarray,
                 maps: dict[int, np.ndarray] | None = None) -> np.ndarray:
    """Eq. (1)-(2): stylus centre in the r-CS for one set of readouts (rad), m."""
    th = [readouts[n] + (map_error(maps[n + 1], readouts[n]) if maps and n + 1 in maps else 0.0)
          for n in range(7)]
    g = dh.__getitem__
    r_t_1 = d_c(th[0])
    t12 = d_x(g("dx21")) @ d_z(L2Z) @ d_a(g("a21")) @ d_b(th[1])
    t23 = (d_x(L3X) @ d_y(g("dy32")) @ d_z(L3Z + g("dz32")) @ d_b(g("b32")) @ d_c(g("c32"))
           @ d_a(th[2] + g("dth30")))
    t34 = d_x(g("dx43")) @ d_z(g("dz43")) @ d_c(g("c43")) @ d_b(th[3] + g("dth40"))
    t45 = (d_x(L5X + g("dx54")) @ d_y(g("dy54")) @ d_z(-L5Z) @ d_a(g("a54"))
           @ d_c(th[4] + g("dth50")))
    t56 = d_x(g("dx65")) @ d_z(g("dz65")) @ d_a(g("a65")) @ d_b(th[5] + g("dth60"))
    t67 = d_x(L7X + g("dx76")) @ d_y(g("dy76")) @ d_a(g("a76")) @ d_c(th[6])
    r_t_7 = r_t_1 @ t12 @ t23 @ t34 @ t45 @ t56 @ t67
    return (r_t_7 @ np.append(tool, 1.0))[:3]


def paper_to_mt(p_r: np.ndarray, abc: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Eq. (4) without the differencing: D_b(beta0) D_a(alpha0) D_c(gamma0) p + translation."""
    rot = (d_b(abc[1]) @ d_a(abc[0]) @ d_c(abc[2]))[:3, :3]
    return rot @ p_r + translation


def random_dh(rng: np.random.Generator, length: float = 1e-3, angle: float = 1e-2
              ) -> dict[str, float]:
    """Random DH errors, larger than real ones so that every term matters."""
    return {n: rng.normal(0, angle if n[0] in "abc" or n.startswith("dth") else length)
            for n in DH_NAMES}


def central_differences(f, x: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Jacobian of ``f`` at ``x`` by central differences, shape (f(x).size, x.size).

    Column j is ``(f(x + h_j e_j) - f(x - h_j e_j)) / (2 h_j)`` with ``h_j = steps[j]``; ``f`` may
    return any shape (flattened). Its error is ``h_j^2 |f'''| / 6`` (truncation) plus about
    ``eps |f| / h_j`` (rounding of f): choose the steps from those two.
    """
    x = np.asarray(x, dtype=float)
    steps = np.broadcast_to(np.asarray(steps, dtype=float), x.shape)
    columns = []
    for j, h in enumerate(steps):
        e = np.zeros_like(x)
        e[j] = h
        columns.append((np.ravel(f(x + e)) - np.ravel(f(x - e))) / (2 * h))
    return np.column_stack(columns)


def run_cli(argv: list[str]) -> tuple[int, str]:
    """Run ``aacmm-pin argv`` in-process; return (status, stderr)."""
    from aacmm_pin.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            status = main(argv)
        except SystemExit as exc:  # argparse
            status = int(exc.code or 0)
    return status, err.getvalue()
