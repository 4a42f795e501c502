r"""The least-squares problem of an identification, in reduced and preconditioned coordinates.

:class:`Problem` is the typed interface that the analyses above the solver use (uncertainty,
discovery, the linearised length bar): residuals, Jacobians, coordinates, covariance and the solve
itself. :func:`aacmm_pin.identify` builds one per round and keeps the last in
:attr:`aacmm_pin.Calibration.problem`.

The full vector is ``[arm unknowns, nest offsets]``: every R-Test location's zero position has an
unknown error (3 per location) with the stated prior ``sigma_location``, so the location
uncertainty enters the estimate and its covariance (generalised least squares).

Constraints ``C (x_arm - x_start) = 0`` (gauges, held directions) are met exactly by moving only in
their null space: ``x = x_ref + P z`` with ``P = T R^-1``, T a basis of the null space (scaled by
the plausible sizes) and R the Cholesky factor of ``T^T J^T J T`` at a nearby point. The columns of
``J P`` are then nearly orthonormal, which makes the dense and the iterative (LSMR) trust region
solvers converge in a few steps at any campaign size.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.optimize import OptimizeResult, least_squares
from scipy.sparse.linalg import LinearOperator

from aacmm_pin.unknowns import BlockJacobian, Unknowns

DENSE_LIMIT = 2e7
"""Above this many Jacobian entries (residuals x unknowns) the solver uses LSMR on an operator."""
RANK_TOL = 1e-10
"""Relative singular value below which a constraint row adds no rank."""


@dataclass(frozen=True)
class SolverSettings:
    """How :meth:`Problem.solve` minimises (scipy's ``least_squares`` vocabulary)."""

    loss: str
    """``"linear"`` or a robust loss (``"soft_l1"``, ``"huber"``, ...)."""
    f_scale: float
    """Residual scale of a robust loss, m."""
    max_nfev: int
    """Most residual evaluations of one solve."""


class Factor(NamedTuple):
    """Reduced QR factors of the dense Jacobian ``J P`` at one point (for Gauss-Newton refits)."""

    q: np.ndarray
    """Orthonormal factor, shape (n_residuals, n_z)."""
    r: np.ndarray
    """Upper triangular factor, shape (n_z, n_z)."""


class Problem:
    """The least-squares problem in reduced, preconditioned coordinates (see module doc).

    Args:
        unknowns: the layout of the arm unknowns (free entries, start values).
        q: SPAT readouts, shape (N, n_axes), rad.
        measured: measured sphere centres in the MT-CS, shape (N, 3), m.
        location: R-Test location of every sample, shape (N,), whose nest offset is estimated;
            None for measurements without nests (absolute points).
        constraints: rows C over the free arm entries held as ``C (x - x_start) = 0``,
            shape (k, n_arm).
        scale: plausible size of every free arm entry, shape (n_arm,), SI.
        x_ref: full vector (arm entries, then nest offsets) at which z = 0, shape (n_x,).
        x_lin: full vector near the solution, where the preconditioner is computed.
        sigma: noise per coordinate assumed by the solve, m (weights the nests' prior rows).
        sigma_location: prior standard deviation of each nest offset per coordinate, m.
        weight: per sample, ``sigma / (its stated noise)``, shape (N,); None: all 1 (generalised
            least squares with per-sample noise: the data rows are multiplied by it).
    """

    unknowns: Unknowns
    """The arm unknowns' layout."""
    q: np.ndarray
    """SPAT readouts, shape (N, n_axes), rad."""
    measured: np.ndarray
    """Measured sphere centres in the MT-CS, shape (N, 3), m."""
    n_arm: int
    """Number of free arm entries (the first ``n_arm`` entries of a full vector)."""
    n_loc: int
    """Number of nest offsets (3 per location; the last entries of a full vector)."""
    nest: sp.csr_matrix
    """d(data residuals)/d(nest offsets), shape (3N, n_loc) (weighted rows)."""
    row_weight: np.ndarray | None
    """Weight of every data row, shape (3N,), or None (all 1)."""
    prior: float
    """Weight of the nest offsets' prior rows in the residual, ``sigma / sigma_location``."""
    sigma_location: float
    """Prior standard deviation of each nest offset per coordinate, m."""
    x_ref: np.ndarray
    """Full vector at z = 0, shape (n_x,)."""
    basis: np.ndarray
    """T: plausible-scaled basis of the constraints' null space (arm) and of the nest offsets
    (scaled by ``sigma_location``), shape (n_x, n_y)."""
    held: np.ndarray
    """Directions of the free arm entries the constraints hold, plausible-scaled, SI,
    shape (n_arm, n_held)."""
    r_inv: np.ndarray
    """R^-1: scaled basis coordinates y of reduced coordinates z (``y = R^-1 z``), shape (n_y, n_z)."""
    p: np.ndarray
    """P = T R^-1: full-vector change per reduced coordinate (``x = x_ref + P z``), shape (n_x, n_z)."""

    def __init__(self, unknowns: Unknowns, q: np.ndarray, measured: np.ndarray,
                 location: np.ndarray | None, constraints: sp.csr_matrix, scale: np.ndarray,
                 x_ref: np.ndarray, x_lin: np.ndarray, sigma: float, sigma_location: float,
                 weight: np.ndarray | None = None):
        self.unknowns, self.q, self.measured = unknowns, q, measured
        n = len(q)
        self.n_arm = int(unknowns.free.sum())
        if location is None:
            self.n_loc = 0
            self.nest = sp.csr_matrix((3 * n, 0))
        else:
            ids, index = np.unique(location, return_inverse=True)
            self.n_loc = 3 * ids.size
            rows = np.arange(3 * n)
            cols = 3 * np.repeat(index, 3) + np.tile(np.arange(3), n)
            # d(residual)/d(nest offset): -1 on the rows of that location and coordinate
            self.nest = sp.csr_matrix((-np.ones(3 * n), (rows, cols)), shape=(3 * n, self.n_loc))
        self.row_weight = None if weight is None else np.repeat(np.asarray(weight, float), 3)
        if self.row_weight is not None:
            self.nest = sp.csr_matrix(sp.diags(self.row_weight) @ self.nest)
        self.prior = sigma / sigma_location
        self.sigma_location = sigma_location
        self.x_ref = x_ref
        cons = constraints.toarray() * scale[None, :]
        null = np.eye(self.n_arm)
        self.held = np.zeros((self.n_arm, 0))
        if cons.shape[0]:
            _, sv, vt = np.linalg.svd(cons, full_matrices=True)
            rank = int(np.sum(sv > sv.max() * RANK_TOL))
            null = vt[rank:].T
            self.held = (vt[:rank] * scale[None, :]).T
        t = np.zeros((self.n_arm + self.n_loc, null.shape[1] + self.n_loc))
        t[:self.n_arm, :null.shape[1]] = scale[:, None] * null
        t[self.n_arm:, null.shape[1]:] = np.eye(self.n_loc) * sigma_location
        info = t.T @ self.normal_matrix(x_lin) @ t  # any nearby point preconditions well
        chol = np.linalg.cholesky(info + 1e-12 * np.trace(info) / len(info) * np.eye(len(info)))
        self.basis = t
        self.r_inv = np.linalg.inv(chol.T)
        self.p = t @ self.r_inv

    # ------------------------------------------------------------ sizes and coordinates
    @property
    def n_data(self) -> int:
        """Number of data residuals (3 per sample); the nests' prior rows follow them."""
        return int(self.nest.shape[0])

    @property
    def n_arm_y(self) -> int:
        """Number of arm coordinates in the scaled null-space basis (the first of y)."""
        return int(self.basis.shape[1] - self.n_loc)

    def z(self, x: np.ndarray) -> np.ndarray:
        """Return the reduced coordinates of a full vector in the constraints' null space."""
        z: np.ndarray = np.linalg.lstsq(self.p, x - self.x_ref, rcond=None)[0]
        return z

    def x(self, z: np.ndarray) -> np.ndarray:
        """Return the full vector for reduced coordinates z."""
        x: np.ndarray = self.x_ref + self.p @ z
        return x

    def with_measured(self, measured: np.ndarray) -> Problem:
        """Return the same problem (structure, preconditioner) for other measured centres."""
        out = copy.copy(self)
        out.measured = np.asarray(measured, dtype=float)
        return out

    # ------------------------------------------------------------ residuals and Jacobians
    def data_jacobian(self, x_arm: np.ndarray) -> BlockJacobian:
        """Return d(data residuals)/d(free arm entries) at x_arm (weighted rows), (3N, n_arm)."""
        _, jac = self.unknowns.jacobian(x_arm, self.q)
        return jac if self.row_weight is None else jac.scaled(self.row_weight)

    def fun(self, z: np.ndarray) -> np.ndarray:
        """Return the residuals: data (predicted - measured, 3N, weighted) then the nests' prior rows."""
        x = self.x(z)
        pred = self.unknowns.positions(x[:self.n_arm], self.q).reshape(-1)
        data = pred - self.measured.reshape(-1)
        if self.row_weight is not None:
            data = data * self.row_weight
        data = data + self.nest @ x[self.n_arm:]
        return np.concatenate([data, self.prior * x[self.n_arm:]])

    def jac(self, z: np.ndarray) -> np.ndarray:
        """Return d(fun)/dz as a dense array, shape (n_data + n_loc, n_z)."""
        jac = self.data_jacobian(self.x(z)[:self.n_arm])
        p_arm, p_loc = self.p[:self.n_arm], self.p[self.n_arm:]
        out: np.ndarray = np.vstack([jac.matmul(p_arm) + self.nest @ p_loc, self.prior * p_loc])
        return out

    def jac_operator(self, z: np.ndarray) -> LinearOperator:
        """Return d(fun)/dz as an operator (products only), for large campaigns."""
        jac = self.data_jacobian(self.x(z)[:self.n_arm])
        nest, prior = self.nest, self.prior
        p_arm, p_loc = self.p[:self.n_arm], self.p[self.n_arm:]
        n_data = self.n_data

        def matvec(v: np.ndarray) -> np.ndarray:
            return np.concatenate([jac.matmul(p_arm @ v) + nest @ (p_loc @ v), prior * (p_loc @ v)])

        def rmatvec(u: np.ndarray) -> np.ndarray:
            data, rest = u[:n_data], u[n_data:]
            out: np.ndarray = p_arm.T @ jac.rmatmul(data) + p_loc.T @ (nest.T @ data + prior * rest)
            return out

        return LinearOperator(shape=(n_data + self.n_loc, self.p.shape[1]), dtype=float,
                              matvec=matvec, rmatvec=rmatvec)

    def factor(self, z: np.ndarray) -> Factor:
        """Return the reduced QR factors of the dense Jacobian at z."""
        q, r = np.linalg.qr(self.jac(z))
        return Factor(q, r)

    def normal_matrix(self, x: np.ndarray) -> np.ndarray:
        """Return J^T J of the data and prior rows w.r.t. the full vector at x, shape (n_x, n_x)."""
        jac = self.data_jacobian(x[:self.n_arm])
        na = self.n_arm
        info = np.empty((na + self.n_loc, na + self.n_loc))
        info[:na, :na] = jac.normal()
        cross = np.zeros((na, self.n_loc))
        for j in range(self.n_loc):
            cross[:, j] = jac.rmatmul(self.nest[:, j].toarray().ravel())
        info[:na, na:] = cross
        info[na:, :na] = cross.T
        info[na:, na:] = (self.nest.T @ self.nest).toarray() + self.prior ** 2 * np.eye(self.n_loc)
        return info

    def covariance(self, x: np.ndarray, sigma: float) -> np.ndarray:
        """Return the linearised covariance of the full vector at x for data noise sigma (m).

        ``T^T (J^T J / sigma^2 + blockdiag(0, I / sigma_location^2)) T``, inverted: the data rows
        with this sigma, the nest offsets' prior with its own sigma whatever the data's.
        """
        info = self.normal_matrix(x)
        na = self.n_arm
        info[na:, na:] -= self.prior ** 2 * np.eye(self.n_loc)  # the solve's weighting, removed
        info /= sigma ** 2
        info[na:, na:] += np.eye(self.n_loc) / self.sigma_location ** 2
        info = self.basis.T @ info @ self.basis
        cov_y = np.linalg.pinv(info, rcond=1e-14, hermitian=True)
        out: np.ndarray = self.basis @ cov_y @ self.basis.T
        return out

    # ------------------------------------------------------------ solving
    def dense(self, n_z: int) -> bool:
        """Whether a Jacobian of n_z reduced columns is small enough for the dense solver."""
        return bool(n_z * self.q.shape[0] * 3 < DENSE_LIMIT)

    def solve(self, z0: np.ndarray, settings: SolverSettings, jac: str = "analytic",
              on_evaluation: Callable[[], None] | None = None) -> OptimizeResult:
        """Minimise from z0 with scipy's trust-region reflective solver.

        Args:
            z0: start, reduced coordinates, shape (n_z,).
            settings: loss, its scale and the evaluation budget.
            jac: ``"analytic"`` or a scipy finite-difference scheme (``"2-point"``, ...).
            on_evaluation: called after every residual evaluation (progress).
        """
        dense = jac != "analytic" or self.dense(z0.size)

        def fun(z: np.ndarray) -> np.ndarray:
            out = self.fun(z)
            if on_evaluation is not None:
                on_evaluation()
            return out

        jac_fun: Callable[[np.ndarray], np.ndarray | LinearOperator] | str = jac
        if jac == "analytic":
            jac_fun = self.jac if dense else self.jac_operator
        return least_squares(fun, z0, jac=jac_fun, method="trf",
                             tr_solver="exact" if dense else "lsmr", loss=settings.loss,
                             f_scale=settings.f_scale, max_nfev=settings.max_nfev, ftol=1e-12,
                             xtol=1e-12, gtol=1e-12)

    def gauss_newton(self, z: np.ndarray, factor: Factor, iterations: int
                     ) -> tuple[np.ndarray, bool]:
        """Gauss-Newton steps with a fixed factored Jacobian until the step is below 1e-12 of z.

        Returns the reduced coordinates reached and whether the steps converged.
        """
        for _ in range(iterations):
            step = np.linalg.solve(factor.r, factor.q.T @ self.fun(z))
            z = z - step
            if np.linalg.norm(step) < 1e-12 * max(1.0, float(np.linalg.norm(z))):
                return z, True
        return z, False
