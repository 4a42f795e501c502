"""A careful hand-written UR5 DH calibration from laser-tracker points: numpy + scipy only.

An independent baseline for ``benchmarks/robots.py``: it imports neither aacmm_pin nor Pinocchio.
Classic DH (``Rz(theta) Tz(d) Tx(a) Rx(alpha)``, UR's published UR5 table), a tool point in the
last frame and the tracker frame (Euler angles and a translation; the data are registered to the
base, so it starts at the identity): 6 x 4 + 3 + 6 = 33 entries, of which the points determine 24.
The 24 independent columns are chosen once at the start by a column-pivoted QR of the analytic
Jacobian (the others stay at their nominal values); ``scipy.optimize.least_squares(method="lm")``
with the analytic Jacobian (rotation steps ``z x (p - o)``, translation steps ``z`` and ``x``).

Run: ``python benchmarks/ur5_handwritten.py GRID.csv RANDOM.csv`` (jacobi2025 files: commanded
joint angles in degrees, commanded position and its difference from the measured one in mm).
Prints one JSON line: fit RMS per coordinate (mm), mean error on the second file's poses (mm),
evaluations, free columns, and the CPU time of the fit alone (after imports).
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
from scipy.linalg import qr
from scipy.optimize import least_squares

# UR5 (CB3) classic DH: theta offset (rad), d (m), a (m), alpha (rad) per joint; SMR 31 mm on z6
DH = np.array([[0.0, 0.089159, 0.0, np.pi / 2], [0.0, 0.0, -0.425, 0.0],
               [0.0, 0.0, -0.39225, 0.0], [0.0, 0.10915, 0.0, np.pi / 2],
               [0.0, 0.09465, 0.0, -np.pi / 2], [0.0, 0.0823, 0.0, 0.0]])
TOOL = np.array([0.0, 0.0, 0.031])


def read(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles (N, 6) rad and measured points (N, 3) m of a jacobi2025 CSV."""
    raw = np.genfromtxt(path, delimiter=",", names=True)
    q = np.radians(np.column_stack([raw[f"joint_{k}"] for k in range(1, 7)]))
    measured = np.column_stack([raw[f"{c}_t"] - raw[f"{c}_dif"] for c in "xyz"]) / 1e3
    return q, measured


def rot(axis: int, t: np.ndarray) -> np.ndarray:
    """Rotations about a coordinate axis by angles t (N,), shape (N, 3, 3)."""
    c, s = np.cos(t), np.sin(t)
    out = np.zeros((t.size, 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    out[:, axis, axis] = 1.0
    out[:, i, i], out[:, i, j], out[:, j, i], out[:, j, j] = c, -s, s, c
    return out


def model(x: np.ndarray, q: np.ndarray, jac: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """Points (N, 3) and d(points)/d(x) (N, 3, 33) for x = [DH (24), tool (3), Euler (3), t (3)]."""
    dh, tool, euler, t = x[:24].reshape(6, 4), x[24:27], x[27:30], x[30:33]
    n = q.shape[0]
    r, o = np.broadcast_to(np.eye(3), (n, 3, 3)).copy(), np.zeros((n, 3))
    frames = []  # per joint: origin and z before it, x axis and origin after Rz Tz Tx
    for k in range(6):
        rz = r @ rot(2, q[:, k] + dh[k, 0])
        z = r[:, :, 2]
        o_new = o + dh[k, 1] * z + dh[k, 2] * rz[:, :, 0]
        frames.append((o, z, rz[:, :, 0], o_new))
        r, o = rz @ rot(0, np.full(n, dh[k, 3])), o_new
    p0 = o + r @ tool
    rb = rot(2, euler[2:3])[0] @ rot(1, euler[1:2])[0] @ rot(0, euler[0:1])[0]
    point = p0 @ rb.T + t
    if not jac:
        return point, None
    j = np.zeros((n, 3, 33))
    for k, (o_k, z, xa, o_after) in enumerate(frames):
        j[:, :, 4 * k] = np.cross(z, p0 - o_k)
        j[:, :, 4 * k + 1] = z
        j[:, :, 4 * k + 2] = xa
        j[:, :, 4 * k + 3] = np.cross(xa, p0 - o_after)
    j[:, :, 24:27] = r
    j[:, :, :27] = np.einsum("ij,njk->nik", rb, j[:, :, :27])
    ex, ey, ez = np.eye(3)
    rz_, ry_, rx_ = rot(2, euler[2:3])[0], rot(1, euler[1:2])[0], rot(0, euler[0:1])[0]
    for col, d_r in ((27, rz_ @ ry_ @ np.cross(ex, rx_.T).T),
                     (28, rz_ @ np.cross(ey, ry_.T).T @ rx_),
                     (29, np.cross(ez, (rz_ @ ry_ @ rx_).T).T)):
        j[:, :, col] = p0 @ d_r.T
    j[:, :, 30:33] = np.eye(3)
    return point, j


def main() -> None:
    q, measured = read(sys.argv[1])
    q_test, measured_test = read(sys.argv[2])
    tic = time.process_time()
    x0 = np.concatenate([DH.ravel(), TOOL, np.zeros(6)])
    _, j0 = model(x0, q, True)
    assert j0 is not None
    a = j0.reshape(-1, 33)
    a = a / np.linalg.norm(a, axis=0)
    _, rr, piv = qr(a, mode="economic", pivoting=True)
    diag = np.abs(np.diag(rr))
    free = np.sort(piv[:int(np.sum(diag > diag[0] * 1e-8))])

    def fun(y: np.ndarray) -> np.ndarray:
        x = x0.copy()
        x[free] = y
        return (model(x, q, False)[0] - measured).ravel()

    def jac(y: np.ndarray) -> np.ndarray:
        x = x0.copy()
        x[free] = y
        j = model(x, q, True)[1]
        assert j is not None
        return j.reshape(-1, 33)[:, free]

    res = least_squares(fun, x0[free], jac=jac, method="lm", xtol=1e-12, ftol=1e-12)
    cpu = time.process_time() - tic
    x = x0.copy()
    x[free] = res.x
    test = np.linalg.norm(model(x, q_test, False)[0] - measured_test, axis=1)
    print(json.dumps({"free": int(free.size), "fit_rms_mm": float(np.sqrt(np.mean(res.fun ** 2))
                                                                  * 1e3),
                      "test_mean_mm": float(test.mean() * 1e3), "nfev": int(res.nfev),
                      "fit_cpu": cpu, "status": int(res.status)}))


if __name__ == "__main__":
    main()
