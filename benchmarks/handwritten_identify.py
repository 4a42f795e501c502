"""A hand-written identification of the proposed model (paper Eq. 1-4) with plain numpy and
``scipy.optimize.least_squares``, as a user without aacmm_pin would write it: the baseline of
``benchmarks/identify.py`` (it imports neither aacmm_pin nor Pinocchio).

Run: ``python benchmarks/handwritten_identify.py CAMPAIGN OUT.json`` (spat.csv and locations.csv of
a campaign; writes the identified values, the fit RMS and the solver's evaluations).

The model: the chain of the README's table (22 DH errors, tool vector), X0 and a translation to the
MT-CS, one 5-degree encoder map per axis (linear interpolation, periodic), and every R-Test nest's
offset estimated with a 3 um prior (as ``aacmm-pin identify`` does when the residual matches the
noise). Map nodes that no readout touches are left out (held at zero); each map's mean is held at
zero by one residual row (a constant map error is an axis offset) and every node has a 100 urad
prior (without it the directions the SPATs do not see wander: the fit is as good, the length bar
off by 10 um to 1 mm depending on the solver's path). Jacobian by finite differences
(scipy's ``"2-point"``), the same tolerances as aacmm_pin (1e-12).
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
from scipy.optimize import least_squares

DH = ("dx21", "a21", "dy32", "dz32", "b32", "c32", "dth30", "dx43", "dz43", "c43", "dth40", "dx54",
      "dy54", "a54", "dth50", "dx65", "dz65", "a65", "dth60", "dx76", "dy76", "a76")
L2Z, L3X, L3Z, L5X, L5Z, L7X = 0.2, 0.6, 0.05, 0.05, 0.55, 0.1
STEP = np.radians(5.0)
N_NODES = 72
SIGMA, SIGMA_NEST = 2e-6, 3e-6
SIGMA_MAP = 1e-4
"""Prior size of an encoder error, rad: keeps the directions the SPATs do not see near zero."""


def rot(axis: int, angle: np.ndarray) -> np.ndarray:
    """Homogeneous rotations about x (0), y (1) or z (2), shape (N, 4, 4)."""
    angle = np.atleast_1d(angle)
    c, s = np.cos(angle), np.sin(angle)
    out = np.tile(np.eye(4), (angle.size, 1, 1))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    out[:, i, i], out[:, i, j], out[:, j, i], out[:, j, j] = c, -s, s, c
    return out


def trans(x: float, y: float, z: float) -> np.ndarray:
    """Homogeneous translation, shape (1, 4, 4)."""
    out = np.eye(4)[None].copy()
    out[0, :3, 3] = x, y, z
    return out


def map_error(values: np.ndarray, readout: np.ndarray) -> np.ndarray:
    """Linear interpolation in a periodic table with nodes at -180, -175, ... deg."""
    u = np.mod(readout + np.pi, 2 * np.pi) / STEP
    lower = np.floor(u).astype(int) % N_NODES
    frac = u - np.floor(u)
    return (1 - frac) * values[lower] + frac * values[(lower + 1) % N_NODES]


def stylus(q: np.ndarray, dh: dict[str, float], tool: np.ndarray, maps: np.ndarray) -> np.ndarray:
    """Stylus centres in the r-CS, shape (N, 3): Eq. (1)-(2)."""
    th = [q[:, n] + map_error(maps[n], q[:, n]) for n in range(7)]
    g = dh.__getitem__
    t = rot(2, th[0])
    t = t @ trans(g("dx21"), 0, L2Z) @ rot(0, g("a21")) @ rot(1, th[1])
    t = (t @ trans(L3X, g("dy32"), L3Z + g("dz32")) @ rot(1, g("b32")) @ rot(2, g("c32"))
         @ rot(0, th[2] + g("dth30")))
    t = t @ trans(g("dx43"), 0, g("dz43")) @ rot(2, g("c43")) @ rot(1, th[3] + g("dth40"))
    t = (t @ trans(L5X + g("dx54"), g("dy54"), -L5Z) @ rot(0, g("a54"))
         @ rot(2, th[4] + g("dth50")))
    t = t @ trans(g("dx65"), 0, g("dz65")) @ rot(0, g("a65")) @ rot(1, th[5] + g("dth60"))
    t = t @ trans(L7X + g("dx76"), g("dy76"), 0) @ rot(0, g("a76")) @ rot(2, th[6])
    return t[:, :3, :3] @ tool + t[:, :3, 3]


def to_mt(p: np.ndarray, abc: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Eq. (4): D_b(beta0) D_a(alpha0) D_c(gamma0) p + t."""
    r = (rot(1, abc[1]) @ rot(0, abc[0]) @ rot(2, abc[2]))[0, :3, :3]
    return p @ r.T + translation


def kabsch(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and translation with b ~ R a + t (least squares)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1, 1, d]) @ u.T
    return r, cb - r @ ca


def main(folder: str, out_path: str) -> None:
    tic = time.process_time()
    spat = np.genfromtxt(f"{folder}/spat.csv", delimiter=",", names=True)
    locs = np.genfromtxt(f"{folder}/locations.csv", delimiter=",", names=True)
    q = np.radians(np.column_stack([spat[f"q{i}_deg"] for i in range(1, 8)]))
    loc_ids = list(locs["location"].astype(int))
    nest = np.array([loc_ids.index(int(m)) for m in spat["location"]])
    zero = np.column_stack([locs["x_mm"], locs["y_mm"], locs["z_mm"]]) / 1e3
    measured = zero[nest] + np.column_stack([spat["dx_mm"], spat["dy_mm"], spat["dz_mm"]]) / 1e3

    # visited map nodes: the two nodes around every readout
    u = np.mod(q + np.pi, 2 * np.pi) / STEP
    visited = np.zeros((7, N_NODES), bool)
    for n in range(7):
        low = np.floor(u[:, n]).astype(int) % N_NODES
        visited[n, low] = True
        visited[n, (low + 1) % N_NODES] = True
    n_map = int(visited.sum())
    n_nest = 3 * len(loc_ids)

    def unpack(x: np.ndarray):
        dh = dict(zip(DH, x[6:28]))
        maps = np.zeros((7, N_NODES))
        maps[visited] = x[31:31 + n_map]
        return x[:3], x[3:6], dh, x[28:31], maps, x[31 + n_map:].reshape(-1, 3)

    def residuals(x: np.ndarray) -> np.ndarray:
        abc, t, dh, tool, maps, offsets = unpack(x)
        pred = to_mt(stylus(q, dh, tool, maps), abc, t)
        data = (pred - measured - offsets[nest]).ravel()
        mean = [maps[n, visited[n]].mean() for n in range(7)]  # gauge: zero-mean maps
        return np.concatenate([data, (SIGMA / SIGMA_NEST) * offsets.ravel(), mean,
                               (SIGMA / SIGMA_MAP) * x[31:31 + n_map]])

    # start: nominal arm, X0 and translation from the nests' mean points
    tool0 = np.array([0.0, 0.0, -0.12])
    p_nom = stylus(q, dict.fromkeys(DH, 0.0), tool0, np.zeros((7, N_NODES)))
    centres = np.array([p_nom[nest == j].mean(axis=0) for j in range(len(loc_ids))])
    targets = np.array([measured[nest == j].mean(axis=0) for j in range(len(loc_ids))])
    r, t0 = kabsch(centres, targets)
    # r = D_b(beta) D_a(alpha) D_c(gamma): its row 1 is (ca sg, ca cg, -sa), column 2 (sb ca, ., cb ca)
    alpha = -np.arcsin(np.clip(r[1, 2], -1, 1))
    beta = np.arctan2(r[0, 2], r[2, 2])
    gamma = np.arctan2(r[1, 0], r[1, 1])
    x0 = np.concatenate([[alpha, beta, gamma], t0, np.zeros(22), tool0, np.zeros(n_map),
                         np.zeros(n_nest)])
    res = least_squares(residuals, x0, jac="2-point", method="trf", ftol=1e-12, xtol=1e-12,
                        gtol=1e-12, max_nfev=200)
    abc, t, dh, tool, maps, offsets = unpack(res.x)
    fit = res.fun[:3 * len(q)]
    out = {"rotation_abc": abc.tolist(), "translation": t.tolist(), "dh": dh,
           "tool": tool.tolist(), "maps": maps.tolist(), "nests": offsets.tolist(),
           "fit_rms": float(np.sqrt(np.mean(fit ** 2))), "nfev": int(res.nfev),
           "success": bool(res.success), "unknowns": int(x0.size),
           "fit_cpu": time.process_time() - tic}
    with open(out_path, "w") as f:
        json.dump(out, f)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
