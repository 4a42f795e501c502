r"""The least-squares problem of an identification, in reduced and preconditioned coordinates.

:class:`Problem` is the typed interface that the analyses above the solver use (uncertainty,
discovery, the linearised length bar): residuals, Jacobians, coordinates, covariance and the solve
itself. :func:`aacmm_pin.identify` builds one per round and keeps the last in
:attr:`aacmm_pin.Calibration.problem`. :meth:`Problem.solve` starts from a
:class:`~aacmm_pin.fit.solver_values.WarmStart` and returns a :class:`~aacmm_pin.fit.solver_values.Solution`.

The full vector is ``[arm unknowns, nest offsets, instrument frames]``
(:class:`~aacmm_pin.fit.data_rows.Nuisance`): every R-Test location's zero position has an
unknown error (3 per location) with the stated prior ``sigma_location``, so the location
uncertainty enters the estimate and its covariance (generalised least squares); a length-bar
socket used as a calibration input is a nest with a loose prior whose distances to the other
sockets of its placement are residual rows; points
measured in a second instrument frame carry that frame's six unknowns.

Constraints ``C (x_arm - x_start) = 0`` (gauges, held directions) are met exactly by moving only in
their null space: ``x = x_ref + P z`` with ``P = T R^-1``, T a basis of the null space (scaled by
the plausible sizes) and R the Cholesky factor of ``T^T J^T J T`` at a nearby point. The columns of
``J P`` are then nearly orthonormal, which makes the dense and the iterative (LSMR) trust region
solvers converge in a few steps at any campaign size.

The pieces: the rows (:class:`~aacmm_pin.fit.data_rows.DataRows`), the reduced coordinates and
the Jacobian's forms (:class:`~aacmm_pin.fit.reduced_jacobian.ReducedJacobian`), the
preconditioner (here) and one solve's state with its Jacobians' memory
(:class:`~aacmm_pin.fit.solve_run.SolveRun`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from aacmm_pin.fit.chunked_jacobian import ChunkedJacobian, DataJacobian
from aacmm_pin.fit.data_rows import Nuisance
from aacmm_pin.fit.reduced_jacobian import RANK_TOL, ReducedJacobian
from aacmm_pin.fit.solve_run import BUDGET_MESSAGE, STEP_TOL, SolveRun
from aacmm_pin.fit.solver_values import (
    Factor,
    Solution,
    SolverSettings,
    WarmStart,
)
from aacmm_pin.fit.unknowns import Unknowns

__all__ = ["BUDGET_MESSAGE", "DENSE_LIMIT", "RANK_TOL", "STEP_TOL", "Factor", "Nuisance", "Problem",
           "Solution", "SolverSettings", "WarmStart"]

DENSE_LIMIT = 2e7
"""Up to this many Jacobian entries (residuals x unknowns) a refit factors the dense Jacobian once
(Gauss-Newton steps, :func:`aacmm_pin.fit.identification.refit`); above, it solves with LSMR."""
FRAME_ANGLE = 1e-2
FRAME_LENGTH = 1e-2
"""Scales (rad, m) of an instrument frame's six unknowns in the preconditioner's basis."""


class Problem(ReducedJacobian):
    """The least-squares problem in reduced, preconditioned coordinates (see module doc).

    Args:
        unknowns: the layout of the arm unknowns (free entries, start values).
        q: readouts, shape (N, n_axes), rad.
        measured: measured points, shape (N, 3), m: sphere centres in the MT-CS (or the main
            frame), or points in their instrument frame (see ``nuisance.frame``).
        nuisance: nest offsets, instrument frames and length rows (:class:`Nuisance`).
        constraints: rows C over the free arm entries held as ``C (x - x_start) = 0``,
            shape (k, n_arm).
        scale: plausible size of every free arm entry, shape (n_arm,), SI.
        x_ref: full vector (arm entries, nest offsets, frames) at which z = 0, shape (n_x,).
        x_lin: full vector near the solution, where the preconditioner is computed.
        sigma: noise per coordinate assumed by the solve, m (weights the nests' prior rows).
        weight: per sample, ``sigma / (its stated noise)``, shape (N,); None: all 1 (generalised
            least squares with per-sample noise: the data rows are multiplied by it).
        jac_lin: :meth:`data_jacobian` at x_lin when the caller has it (not computed again).
        f_ref: :meth:`residual_at` x_ref when the caller has it (:meth:`data_rows_at`).

    A campaign whose data Jacobian would exceed
    :data:`~aacmm_pin.fit.chunked_jacobian.CHUNKED_BYTES` is :attr:`chunked`: its data Jacobian is
    a :class:`~aacmm_pin.fit.chunked_jacobian.ChunkedJacobian` (products chunk by chunk, never
    held whole) and the solver's steps come from the normal equations (:meth:`compressed`).
    """

    held: np.ndarray
    """Directions of the free arm entries the constraints hold, plausible-scaled, SI,
    shape (n_arm, n_held)."""
    r_inv: np.ndarray
    """R^-1: scaled basis coordinates y of reduced coordinates z (``y = R^-1 z``), shape (n_y, n_z)."""

    def __init__(self, unknowns: Unknowns, q: np.ndarray, measured: np.ndarray,
                 nuisance: Nuisance, constraints: sp.csr_matrix, scale: np.ndarray,
                 x_ref: np.ndarray, x_lin: np.ndarray, sigma: float,
                 weight: np.ndarray | None = None, jac_lin: DataJacobian | None = None,
                 f_ref: np.ndarray | None = None):
        super().__init__(unknowns, q, measured, nuisance, sigma, weight)
        self.x_ref = x_ref
        cons = constraints.toarray() * scale[None, :]
        null = np.eye(self.n_arm)
        self.held = np.zeros((self.n_arm, 0))
        if cons.shape[0]:
            _, sv, vt = np.linalg.svd(cons, full_matrices=True)
            rank = int(np.sum(sv > sv.max() * RANK_TOL))
            null = vt[rank:].T
            self.held = (vt[:rank] * scale[None, :]).T
        n_null, n_nuis = null.shape[1], self.n_loc + self.n_frame
        t = np.zeros((self.n_arm + n_nuis, n_null + n_nuis))
        t[:self.n_arm, :n_null] = scale[:, None] * null
        frame_scale = np.tile([FRAME_ANGLE, FRAME_ANGLE, FRAME_ANGLE, FRAME_LENGTH, FRAME_LENGTH,
                               FRAME_LENGTH], nuisance.n_frames)
        t[self.n_arm:, n_null:] = np.diag(np.concatenate([self.nest_sigma, frame_scale]))
        if isinstance(jac_lin, ChunkedJacobian) and np.array_equal(x_lin, x_ref):
            # at z = 0 (a fit's start): one pass gives the preconditioner's J^T (nuisance
            # columns) and the first Gauss-Newton step's J^T f (fun(0) is this residual; none
            # if the caller deferred them to an earlier pass, :meth:`data_rows_at`)
            jac_lin.products(self.nuisance_jacobian(x_lin),
                             (self.residual_at(x_lin) if f_ref is None else f_ref)[:self.n_data])
        # any nearby point preconditions well
        info = t.T @ self.normal_matrix(x_lin, jac_lin) @ t
        chol = np.linalg.cholesky(info + 1e-12 * np.trace(info) / len(info) * np.eye(len(info)))
        self.basis = t
        self.r_inv = np.linalg.inv(chol.T)
        self.p = t @ self.r_inv

    # ------------------------------------------------------------ solving
    def dense(self, n_z: int) -> bool:
        """Whether a Jacobian of n_z reduced columns is small enough for the dense solver."""
        return bool(n_z * self.q.shape[0] * 3 < DENSE_LIMIT)

    def solve(self, start: WarmStart | np.ndarray, settings: SolverSettings,
              jac: str = "analytic", on_evaluation: Callable[[float], None] | None = None
              ) -> Solution:
        """Minimise from ``start`` with scipy's trust-region reflective solver (LSMR steps).

        Args:
            start: the start, reduced coordinates, shape (n_z,), or a :class:`WarmStart` with
                what the caller has there (the caller keeps no reference to its Jacobian, so that
                its memory is freed after scipy's first step).
            settings: loss, its scale and the evaluation budget.
            jac: ``"analytic"`` or a scipy finite-difference scheme (``"2-point"``, ...).
            on_evaluation: called after every residual evaluation with the residual's RMS (m,
                in units of the solve's sigma for weighted rows), for progress.

        Returns:
            scipy's result and, with the analytic Jacobian, the data Jacobian at the solution
            (:class:`Solution`).
        """
        run = SolveRun(self, start, settings, jac, on_evaluation)
        del start  # the warm start's Jacobian: freed after scipy's first step
        return run.run()
