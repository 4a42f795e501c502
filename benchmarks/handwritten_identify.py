"""A hand-written identification of the proposed model (paper Eq. 1-4) with plain numpy and
``scipy.optimize.least_squares``, as a user without aacmm_pin would write it: the baseline of
``benchmarks/identify.py`` (it imports neither aacmm_pin nor Pinocchio).

Run: ``python benchmarks/handwritten_identify.py CAMPAIGN OUT.json [--method trf|lm]
[--jac analytic|2-point]`` (spat.csv and locations.csv of a campaign; writes the identified values,
the fit RMS and the solver's evaluations); ``--check CAMPAIGN`` prints the analytic Jacobian's largest
error against central differences.

The model: the chain of docs/model.md's table (22 DH errors, tool vector), X0 and a translation to the
MT-CS, one 5-degree encoder map per axis (linear interpolation, periodic), and every R-Test nest's
offset estimated with a 3 um prior (as ``aacmm-pin identify`` does when the residual matches the
noise). Map nodes that no readout touches are left out (held at zero); each map's mean is held at
zero by one residual row (a constant map error is an axis offset) and every node has a 100 urad
prior (without it the directions the SPATs do not see wander: the fit is as good, the length bar
off by 10 um to 1 mm depending on the solver's path). Analytic Jacobian, dense, vectorised over
the samples: a rotation step about the unit axis a through o moves the stylus by a x (p - o) per
radian, a translation step by its axis per metre (a, o of the frame before the step); a map node
acts through its axis' column times its interpolation weight. Or scipy's finite differences
(``--jac 2-point``). scipy's defaults for a dense Jacobian otherwise (``trf`` with the exact
trust-region solver, an SVD per iteration; or MINPACK's ``lm``), the same tolerances as aacmm_pin
(1e-12).
"""

from __future__ import annotations

import argparse
import json
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


def chain_steps(q: np.ndarray, dh: dict[str, float], maps: np.ndarray) -> list[tuple]:
    """Eq. (1)-(2) as elementary steps, base first: ``("r", k, angle (N,) or float, names)`` a
    rotation about local axis k (x 0, y 1, z 2) whose angle depends on ``names`` (one unit each:
    a DH angle or axis ``"A<n>"``), ``("t", (x, y, z), {name: k})`` a translation whose local
    component k is the DH length ``name``."""
    th = [q[:, n] + map_error(maps[n], q[:, n]) for n in range(7)]
    g = dh.__getitem__
    return [
        ("r", 2, th[0], ("A1",)),
        ("t", (g("dx21"), 0.0, L2Z), {"dx21": 0}), ("r", 0, g("a21"), ("a21",)),
        ("r", 1, th[1], ("A2",)),
        ("t", (L3X, g("dy32"), L3Z + g("dz32")), {"dy32": 1, "dz32": 2}),
        ("r", 1, g("b32"), ("b32",)), ("r", 2, g("c32"), ("c32",)),
        ("r", 0, th[2] + g("dth30"), ("A3", "dth30")),
        ("t", (g("dx43"), 0.0, g("dz43")), {"dx43": 0, "dz43": 2}), ("r", 2, g("c43"), ("c43",)),
        ("r", 1, th[3] + g("dth40"), ("A4", "dth40")),
        ("t", (L5X + g("dx54"), g("dy54"), -L5Z), {"dx54": 0, "dy54": 1}),
        ("r", 0, g("a54"), ("a54",)), ("r", 2, th[4] + g("dth50"), ("A5", "dth50")),
        ("t", (g("dx65"), 0.0, g("dz65")), {"dx65": 0, "dz65": 2}), ("r", 0, g("a65"), ("a65",)),
        ("r", 1, th[5] + g("dth60"), ("A6", "dth60")),
        ("t", (L7X + g("dx76"), g("dy76"), 0.0), {"dx76": 0, "dy76": 1}),
        ("r", 0, g("a76"), ("a76",)), ("r", 2, th[6], ("A7",)),
    ]


def stylus(q: np.ndarray, dh: dict[str, float], tool: np.ndarray, maps: np.ndarray,
           jacobian: bool = False) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Stylus centres in the r-CS, shape (N, 3), and (``jacobian``) their derivatives, name ->
    shape (N, 3): every DH error, ``"A<n>"`` (the angle of axis n), ``"tool"`` (N, 3, 3).

    A rotation about a unit axis a through the point o moves p by a x (p - o) per radian; a
    translation along a by a per metre (a, o of the frame before the step)."""
    steps = chain_steps(q, dh, maps)
    t = np.tile(np.eye(4), (len(q), 1, 1))
    before = []
    for step in steps:
        before.append(t)
        t = t @ (rot(step[1], step[2]) if step[0] == "r" else trans(*step[1]))
    p = t[:, :3, :3] @ tool + t[:, :3, 3]
    if not jacobian:
        return p, {}
    cols: dict[str, np.ndarray] = {"tool": t[:, :3, :3]}
    for step, pre in zip(steps, before):
        if step[0] == "r":
            col = np.cross(pre[:, :3, step[1]], p - pre[:, :3, 3])
            for name in step[3]:
                cols[name] = cols.get(name, 0.0) + col
        else:
            for name, k in step[2].items():
                cols[name] = pre[:, :3, k]
    return p, cols


def to_mt(p: np.ndarray, abc: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Eq. (4): D_b(beta0) D_a(alpha0) D_c(gamma0) p + t."""
    r = (rot(1, abc[1]) @ rot(0, abc[0]) @ rot(2, abc[2]))[0, :3, :3]
    return p @ r.T + translation


def to_mt_jacobian(p: np.ndarray, abc: np.ndarray) -> np.ndarray:
    """Derivatives of Eq. (4) w.r.t. (alpha0, beta0, gamma0), shape (N, 3, 3) (last: the angle)."""
    ra, rb, rc = (rot(k, abc[i])[0, :3, :3] for k, i in ((0, 0), (1, 1), (2, 2)))
    e = np.eye(3)
    pc = p @ rc.T
    pac = pc @ ra.T
    d_alpha = np.cross(e[0], pac) @ rb.T
    d_beta = np.cross(e[1], pac @ rb.T)
    d_gamma = np.cross(e[2], pc) @ (rb @ ra).T
    return np.stack([d_alpha, d_beta, d_gamma], axis=2)


def kabsch(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and translation with b ~ R a + t (least squares)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1, 1, d]) @ u.T
    return r, cb - r @ ca


class Problem:
    """The campaign's residuals (m, scaled priors) and their analytic Jacobian."""

    def __init__(self, folder: str):
        spat = np.genfromtxt(f"{folder}/spat.csv", delimiter=",", names=True)
        locs = np.genfromtxt(f"{folder}/locations.csv", delimiter=",", names=True)
        self.q = np.radians(np.column_stack([spat[f"q{i}_deg"] for i in range(1, 8)]))
        self.loc_ids = list(locs["location"].astype(int))
        self.nest = np.array([self.loc_ids.index(int(m)) for m in spat["location"]])
        zero = np.column_stack([locs["x_mm"], locs["y_mm"], locs["z_mm"]]) / 1e3
        self.measured = zero[self.nest] + np.column_stack(
            [spat["dx_mm"], spat["dy_mm"], spat["dz_mm"]]) / 1e3
        # visited map nodes: the two nodes around every readout, and their interpolation weights
        u = np.mod(self.q + np.pi, 2 * np.pi) / STEP
        self.low = np.floor(u).astype(int) % N_NODES
        self.frac = u - np.floor(u)
        self.visited = np.zeros((7, N_NODES), bool)
        for n in range(7):
            self.visited[n, self.low[:, n]] = True
            self.visited[n, (self.low[:, n] + 1) % N_NODES] = True
        self.n_map = int(self.visited.sum())
        self.n_nest = 3 * len(self.loc_ids)
        self.column = np.full((7, N_NODES), -1)  # map node -> its column in x
        self.column[self.visited] = 31 + np.arange(self.n_map)
        self.n_x = 31 + self.n_map + self.n_nest

    def unpack(self, x: np.ndarray) -> tuple:
        """x -> (abc, translation, dh, tool, maps (7, 72), nest offsets (n_loc, 3))."""
        dh = dict(zip(DH, x[6:28]))
        maps = np.zeros((7, N_NODES))
        maps[self.visited] = x[31:31 + self.n_map]
        return x[:3], x[3:6], dh, x[28:31], maps, x[31 + self.n_map:].reshape(-1, 3)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """Predicted - measured (N * 3), then the nests' priors, zero-mean rows, the maps' priors."""
        abc, t, dh, tool, maps, offsets = self.unpack(x)
        pred = to_mt(stylus(self.q, dh, tool, maps)[0], abc, t)
        data = (pred - self.measured - offsets[self.nest]).ravel()
        mean = [maps[n, self.visited[n]].mean() for n in range(7)]  # gauge: zero-mean maps
        return np.concatenate([data, (SIGMA / SIGMA_NEST) * offsets.ravel(), mean,
                               (SIGMA / SIGMA_MAP) * x[31:31 + self.n_map]])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Dense Jacobian of :meth:`residuals`, shape (3 N + n_nest + 7 + n_map, n_x)."""
        abc, _, dh, tool, maps, _ = self.unpack(x)
        p, cols = stylus(self.q, dh, tool, maps, jacobian=True)
        n = len(self.q)
        r0 = (rot(1, abc[1]) @ rot(0, abc[0]) @ rot(2, abc[2]))[0, :3, :3]
        jac = np.zeros((3 * n + self.n_nest + 7 + self.n_map, self.n_x))
        data = jac[:3 * n].reshape(n, 3, self.n_x)
        data[:, :, :3] = to_mt_jacobian(p, abc)
        data[:, :, 3:6] = np.eye(3)
        for k, name in enumerate(DH):
            data[:, :, 6 + k] = cols[name] @ r0.T
        data[:, :, 28:31] = r0 @ cols["tool"]
        rows = np.arange(n)
        for a in range(7):
            d_axis = cols[f"A{a + 1}"] @ r0.T
            low = self.low[:, a]
            data[rows, :, self.column[a, low]] = (1 - self.frac[:, a])[:, None] * d_axis
            data[rows, :, self.column[a, (low + 1) % N_NODES]] = self.frac[:, a][:, None] * d_axis
        first = 31 + self.n_map
        for c in range(3):
            data[rows, c, first + 3 * self.nest + c] = -1.0
        row = 3 * n
        jac[row:row + self.n_nest, first:] = (SIGMA / SIGMA_NEST) * np.eye(self.n_nest)
        row += self.n_nest
        for a in range(7):
            free = self.column[a, self.visited[a]]
            jac[row + a, free] = 1.0 / free.size
        row += 7
        jac[row:, 31:first] = (SIGMA / SIGMA_MAP) * np.eye(self.n_map)
        return jac

    def start(self) -> np.ndarray:
        """Nominal arm; X0 and translation from the nests' mean points (Kabsch)."""
        tool0 = np.array([0.0, 0.0, -0.12])
        p_nom = stylus(self.q, dict.fromkeys(DH, 0.0), tool0, np.zeros((7, N_NODES)))[0]
        m = len(self.loc_ids)
        centres = np.array([p_nom[self.nest == j].mean(axis=0) for j in range(m)])
        targets = np.array([self.measured[self.nest == j].mean(axis=0) for j in range(m)])
        r, t0 = kabsch(centres, targets)
        # r = D_b(beta) D_a(alpha) D_c(gamma): row 1 is (ca sg, ca cg, -sa), column 2 (sb ca, ., cb ca)
        alpha = -np.arcsin(np.clip(r[1, 2], -1, 1))
        beta = np.arctan2(r[0, 2], r[2, 2])
        gamma = np.arctan2(r[1, 0], r[1, 1])
        return np.concatenate([[alpha, beta, gamma], t0, np.zeros(22), tool0,
                               np.zeros(self.n_map), np.zeros(self.n_nest)])


def check_jacobian(folder: str) -> float:
    """Largest difference between the analytic Jacobian and central differences (step 1e-7) at a
    perturbed start, relative to the largest entry of its column."""
    prob = Problem(folder)
    x = prob.start() + np.random.default_rng(0).normal(0.0, 1e-4, prob.n_x)
    jac = prob.jacobian(x)
    worst = 0.0
    for k in range(prob.n_x):
        dx = np.zeros(prob.n_x)
        dx[k] = 1e-7
        fd = (prob.residuals(x + dx) - prob.residuals(x - dx)) / 2e-7
        worst = max(worst, np.abs(fd - jac[:, k]).max() / max(np.abs(jac[:, k]).max(), 1e-300))
    return float(worst)


def main(folder: str, out_path: str, jac: str, method: str) -> None:
    tic = time.process_time()
    prob = Problem(folder)
    x0 = prob.start()
    res = least_squares(prob.residuals, x0, jac=prob.jacobian if jac == "analytic" else jac,
                        method=method, ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=200)
    abc, t, dh, tool, maps, offsets = prob.unpack(res.x)
    fit = res.fun[:3 * len(prob.q)]
    out = {"rotation_abc": abc.tolist(), "translation": t.tolist(), "dh": dh,
           "tool": tool.tolist(), "maps": maps.tolist(), "nests": offsets.tolist(),
           "fit_rms": float(np.sqrt(np.mean(fit ** 2))), "nfev": int(res.nfev),
           "njev": int(res.njev or 0), "success": bool(res.success), "unknowns": int(x0.size),
           "jac": jac, "method": method, "fit_cpu": time.process_time() - tic}
    with open(out_path, "w") as f:
        json.dump(out, f)


if __name__ == "__main__":
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("campaign")
    cli.add_argument("out", nargs="?", help="JSON file of the result (not with --check)")
    cli.add_argument("--jac", choices=("analytic", "2-point"), default="analytic")
    cli.add_argument("--method", choices=("trf", "lm"), default="trf")
    cli.add_argument("--check", action="store_true",
                     help="print the analytic Jacobian's largest error against central differences")
    args = cli.parse_args()
    if args.check:
        print(json.dumps({"jacobian_error": check_jacobian(args.campaign)}))
    else:
        main(args.campaign, args.out, args.jac, args.method)
