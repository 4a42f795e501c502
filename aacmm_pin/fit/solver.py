r"""The least-squares problem of an identification, in reduced and preconditioned coordinates.

:class:`Problem` is the typed interface that the analyses above the solver use (uncertainty,
discovery, the linearised length bar): residuals, Jacobians, coordinates, covariance and the solve
itself. :func:`aacmm_pin.identify` builds one per round and keeps the last in
:attr:`aacmm_pin.Calibration.problem`. :meth:`Problem.solve` starts from a
:class:`~aacmm_pin.fit.solver_values.WarmStart` and returns a :class:`~aacmm_pin.fit.solver_values.Solution`.

The full vector is ``[arm unknowns, nest offsets, instrument frames]`` (:class:`Nuisance`): every
R-Test location's zero position has an unknown error (3 per location) with the stated prior
``sigma_location``, so the location uncertainty enters the estimate and its covariance
(generalised least squares); a length-bar socket used as a calibration input is a nest with a
loose prior whose distances to the other sockets of its placement are residual rows; points
measured in a second instrument frame carry that frame's six unknowns.

Constraints ``C (x_arm - x_start) = 0`` (gauges, held directions) are met exactly by moving only in
their null space: ``x = x_ref + P z`` with ``P = T R^-1``, T a basis of the null space (scaled by
the plausible sizes) and R the Cholesky factor of ``T^T J^T J T`` at a nearby point. The columns of
``J P`` are then nearly orthonormal, which makes the dense and the iterative (LSMR) trust region
solvers converge in a few steps at any campaign size.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np
import pinocchio as pin
import scipy.sparse as sp
from scipy.optimize import OptimizeResult, least_squares
from scipy.sparse.linalg import LinearOperator, lsmr

from aacmm_pin.fit.chunked_jacobian import ChunkedJacobian, DataJacobian, is_chunked
from aacmm_pin.fit.solver_values import (
    BudgetSpent,
    Counted,
    Factor,
    Solution,
    SolverSettings,
    WarmStart,
)
from aacmm_pin.fit.unknowns import Unknowns

__all__ = ["DENSE_LIMIT", "STEP_TOL", "Factor", "Nuisance", "Problem", "Solution", "SolverSettings",
           "WarmStart"]

T = TypeVar("T")

DENSE_LIMIT = 2e7
"""Up to this many Jacobian entries (residuals x unknowns) a refit factors the dense Jacobian once
(Gauss-Newton steps, :func:`aacmm_pin.fit.identification.refit`); above, it solves with LSMR."""
STEP_TOL = 1e-4
"""A solve ends at an accepted point when no reduced coordinate's Gauss-Newton step from it exceeds
this many standard deviations: scipy's ``gtol`` (on the largest entry of the gradient
``(J P)^T f``) set to ``STEP_TOL`` x the solve's sigma. The columns of ``J P`` are nearly
orthonormal and every row's noise is the solve's sigma, so the gradient is about minus the
Gauss-Newton step and each reduced coordinate's standard deviation is about sigma. It is as strict
as scipy's ``ftol`` of 1e-12 on these problems (a cost change of 1e-12 is a step of 0.7e-4 to 7e-4
sigma for 1,600 to 160,000 samples), but it does not wait for the cost: below such a step the
cost's change is its rounding, and the trust region rejected steps at random until the step's
tolerance stopped it (5 to 13 evaluations at every size, depending on the noise, the last ones
moving nothing)."""
BUDGET_MESSAGE = "The maximum number of function evaluations is exceeded."
"""scipy's message for a solve stopped at its cap, also given when the fit's budget is spent."""
RANK_TOL = 1e-10
"""Relative singular value below which a constraint row adds no rank."""
FRAME_ANGLE = 1e-2
FRAME_LENGTH = 1e-2
"""Scales (rad, m) of an instrument frame's six unknowns in the preconditioner's basis."""


@dataclass(frozen=True)
class Nuisance:
    """What a problem estimates beside the arm: nest offsets, instrument frames, bar lengths.

    Nests: every R-Test location (or length-bar socket) has an unknown offset of its reference
    position (3 per nest) with a prior of its own standard deviation. Instrument frames: points
    measured in another instrument's frame (a second tracker station, or a tracker beside the
    R-Test's MT-CS) are mapped into the main frame by ``exp(w) R0 m + t0 + t`` with 6 unknowns
    (w, t) per frame and no prior. Lengths: the distance between two nests' positions equals a
    calibrated length (the length bar as a calibration input), one residual row each.
    """

    nest: np.ndarray | None = None
    """Nest of every sample, 0..n_nests-1, or -1 for none, shape (N,); None: no nests at all."""
    nest_sigma: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Prior standard deviation of each nest's offset per coordinate, shape (n_nests,), m."""
    frame: np.ndarray | None = None
    """Instrument frame of every sample, 0..n_frames-1, or -1 for the main frame, shape (N,)."""
    frame_start: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 4)))
    """Start transform instrument -> main frame of each frame, ``[R0 | t0]``, shape (n_frames, 3, 4)."""
    lengths: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """Rows (nest a, nest b, calibrated distance m), shape (n_lengths, 3)."""
    length_weight: float = 1.0
    """Weight of a length row: the solve's sigma over the stated length uncertainty."""

    @property
    def n_nests(self) -> int:
        """Number of nests."""
        return int(self.nest_sigma.size)

    @property
    def n_frames(self) -> int:
        """Number of instrument frames besides the main one."""
        return int(self.frame_start.shape[0])


class _Handover:
    """A warm start's residual and Jacobian for scipy's first calls.

    Each is served to the first call of its kind if that call is at the start exactly, and
    released after it.
    """

    def __init__(self, warm: WarmStart, jacobian: bool):
        self.z = np.array(warm.z, dtype=float)
        self._residual = [] if warm.residual is None else [warm.residual]
        self._jacobian = [] if warm.jacobian is None or not jacobian else [warm.jacobian]

    def _take(self, held: list[T], z: np.ndarray) -> T | None:
        given = held.pop() if held else None
        return given if given is not None and np.array_equal(self.z, z) else None

    def residual(self, z: np.ndarray) -> np.ndarray | None:
        """Return the start's residual on the first call if z is the start, else None."""
        return self._take(self._residual, z)

    def jacobian(self, z: np.ndarray) -> DataJacobian | None:
        """Return the start's data Jacobian on the first call if z is the start, else None."""
        return self._take(self._jacobian, z)


def _skew(v: np.ndarray) -> np.ndarray:
    """Return the cross-product matrices of vectors v (N, 3), shape (N, 3, 3)."""
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


class Problem:
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

    unknowns: Unknowns
    """The arm unknowns' layout."""
    q: np.ndarray
    """Readouts, shape (N, n_axes), rad."""
    measured: np.ndarray
    """Measured points, shape (N, 3), m (main frame, or the sample's instrument frame)."""
    nuisance: Nuisance
    """Nests, instrument frames and length rows."""
    n_arm: int
    """Number of free arm entries (the first ``n_arm`` entries of a full vector)."""
    n_loc: int
    """Number of nest offsets (3 per nest; the entries after the arm's)."""
    n_frame: int
    """Number of instrument frame entries (6 per frame; the last entries of a full vector)."""
    nest: sp.csr_matrix
    """d(data residuals)/d(nest offsets), shape (3N, n_loc) (weighted rows)."""
    row_weight: np.ndarray | None
    """Weight of every data row, shape (3N,), or None (all 1)."""
    prior: np.ndarray
    """Weight of each nest offset's prior row in the residual, ``sigma / nest sigma``, (n_loc,)."""
    nest_sigma: np.ndarray
    """Prior standard deviation of each nest offset entry, shape (n_loc,), m."""
    sigma_class: float
    """The noise per coordinate the solve assumes, m (a row of weight 1 has this noise)."""
    x_ref: np.ndarray
    """Full vector at z = 0, shape (n_x,)."""
    basis: np.ndarray
    """T: plausible-scaled basis of the constraints' null space (arm), of the nest offsets
    (scaled by their prior) and of the frames, shape (n_x, n_y)."""
    held: np.ndarray
    """Directions of the free arm entries the constraints hold, plausible-scaled, SI,
    shape (n_arm, n_held)."""
    r_inv: np.ndarray
    """R^-1: scaled basis coordinates y of reduced coordinates z (``y = R^-1 z``), shape (n_y, n_z)."""
    p: np.ndarray
    """P = T R^-1: full-vector change per reduced coordinate (``x = x_ref + P z``), shape (n_x, n_z)."""
    chunked: bool
    """Whether the data Jacobian is taken chunk by chunk (a large campaign, see the class doc)."""

    def __init__(self, unknowns: Unknowns, q: np.ndarray, measured: np.ndarray,
                 nuisance: Nuisance, constraints: sp.csr_matrix, scale: np.ndarray,
                 x_ref: np.ndarray, x_lin: np.ndarray, sigma: float,
                 weight: np.ndarray | None = None, jac_lin: DataJacobian | None = None,
                 f_ref: np.ndarray | None = None):
        self._data_rows(unknowns, q, measured, nuisance, sigma, weight)
        self.x_ref = x_ref
        self.chunked = is_chunked(unknowns, len(q))
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

    def _data_rows(self, unknowns: Unknowns, q: np.ndarray, measured: np.ndarray,
                   nuisance: Nuisance, sigma: float, weight: np.ndarray | None) -> None:
        """Set what the data, prior and length rows need (no constraints, no preconditioner)."""
        self.unknowns, self.q, self.measured = unknowns, q, measured
        self.nuisance = nuisance
        n = len(q)
        self.n_arm = int(unknowns.free.sum())
        self.n_loc = 3 * nuisance.n_nests
        self.n_frame = 6 * nuisance.n_frames
        if nuisance.nest is None:
            self.nest = sp.csr_matrix((3 * n, 0))
        else:
            has = np.flatnonzero(nuisance.nest >= 0)
            rows = (3 * has[:, None] + np.arange(3)).ravel()
            cols = (3 * nuisance.nest[has][:, None] + np.arange(3)).ravel()
            # d(residual)/d(nest offset): -1 on the rows of that nest and coordinate
            self.nest = sp.csr_matrix((-np.ones(rows.size), (rows, cols)), shape=(3 * n, self.n_loc))
        self._nest_raw = self.nest
        self.row_weight = None if weight is None else np.repeat(np.asarray(weight, float), 3)
        if self.row_weight is not None:
            self.nest = sp.csr_matrix(sp.diags(self.row_weight) @ self.nest)
        self.sigma_class = sigma
        self.nest_sigma = np.repeat(np.asarray(nuisance.nest_sigma, dtype=float), 3)
        self.prior = sigma / self.nest_sigma
        self._length_ref = self._nest_reference()

    @classmethod
    def data_rows_at(cls, unknowns: Unknowns, q: np.ndarray, measured: np.ndarray,
                     nuisance: Nuisance, sigma: float, weight: np.ndarray | None, x: np.ndarray
                     ) -> tuple[sp.csr_matrix, np.ndarray]:
        """Return :meth:`nuisance_jacobian` and :meth:`residual_at` at the full vector x.

        Neither depends on the constraints or the preconditioner: a fit has them before it
        decides what the data determine, and defers the products of its start's chunked
        Jacobian with them to the gauge check's pass
        (:meth:`~aacmm_pin.fit.chunked_jacobian.ChunkedJacobian.defer`); the residual is then
        the problem's ``f_ref``. Arguments as the constructor's; ``x``: the full vector, shape
        (n_arm + n_nuisance,).

        Returns:
            The nuisance Jacobian, shape (3N, n_nuisance), and the data residual, shape (3N,)
            (whitened, unitless).
        """
        rows = cls.__new__(cls)
        rows._data_rows(unknowns, q, measured, nuisance, sigma, weight)
        return rows.nuisance_jacobian(x), rows.residual_at(x)

    def _nest_reference(self) -> np.ndarray:
        """Return every nest's reference position (the mean measured point of its samples), (n, 3)."""
        nz = self.nuisance
        if nz.nest is None or not nz.lengths.size:
            return np.zeros((nz.n_nests, 3))
        return np.array([self.measured[nz.nest == j].mean(axis=0) for j in range(nz.n_nests)])

    # ------------------------------------------------------------ sizes and coordinates
    @property
    def n_data(self) -> int:
        """Number of data residuals (3 per sample); the nests' prior rows and the lengths follow."""
        return int(self.nest.shape[0])

    @property
    def n_arm_y(self) -> int:
        """Number of arm coordinates in the scaled null-space basis (the first of y)."""
        return int(self.basis.shape[1] - self.n_loc - self.n_frame)

    @property
    def n_lengths(self) -> int:
        """Number of length rows (the last rows of the residual)."""
        return int(self.nuisance.lengths.shape[0])

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

    # ------------------------------------------------------------ instrument frames and lengths
    def frames(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return every instrument frame's rotation (F, 3, 3) and translation (F, 3) to the main frame."""
        nz = self.nuisance
        xf = x[self.n_arm + self.n_loc:].reshape(-1, 6)
        rot = np.array([pin.exp3(w) @ s[:, :3] for w, s in zip(xf[:, :3], nz.frame_start)])
        return rot.reshape(-1, 3, 3), nz.frame_start[:, :, 3] + xf[:, 3:]

    def main_measured(self, x: np.ndarray) -> np.ndarray:
        """Return the measured points mapped into the main frame with the frames of x, (N, 3), m."""
        frame = self.nuisance.frame
        if frame is None or not self.n_frame:
            measured: np.ndarray = self.measured
            return measured
        rot, trans = self.frames(x)
        out: np.ndarray = self.measured.copy()
        sel = frame >= 0
        f = frame[sel]
        out[sel] = np.einsum("nij,nj->ni", rot[f], self.measured[sel]) + trans[f]
        return out

    def nuisance_jacobian(self, x: np.ndarray) -> sp.csr_matrix:
        """Return d(data residuals)/d(nest offsets, frames) at x (weighted rows), (3N, n_loc + n_frame)."""
        frame = self.nuisance.frame
        if frame is None or not self.n_frame:
            return self.nest
        w_all = x[self.n_arm + self.n_loc:].reshape(-1, 6)[:, :3]
        rot, _ = self.frames(x)
        sel = np.flatnonzero(frame >= 0)
        f = frame[sel]
        u = np.einsum("nij,nj->ni", rot[f], self.measured[sel])  # exp(w) R0 m
        # residual = model - (exp(w) R0 m + t0 + t): d/dw = [u]x exp(w) Jr(w), d/dt = -I
        left = np.array([pin.exp3(w) @ pin.Jexp3(w) for w in w_all]).reshape(-1, 3, 3)
        d_w = _skew(u) @ left[f]
        blocks = np.concatenate([d_w, -np.broadcast_to(np.eye(3), d_w.shape)], axis=2)  # (n, 3, 6)
        rows = np.repeat((3 * sel[:, None] + np.arange(3))[:, :, None], 6, axis=2)
        cols = np.broadcast_to((6 * f[:, None, None] + np.arange(6)), blocks.shape)
        jac = sp.csr_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())),
                            shape=(self.n_data, self.n_frame))
        if self.row_weight is not None:
            jac = sp.csr_matrix(sp.diags(self.row_weight) @ jac)
        return sp.csr_matrix(sp.hstack([self.nest, jac]))

    def _length_parts(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        lengths = self.nuisance.lengths
        a, b = lengths[:, 0].astype(int), lengths[:, 1].astype(int)
        loc = x[self.n_arm:self.n_arm + self.n_loc].reshape(-1, 3)
        d = (self._length_ref[b] + loc[b]) - (self._length_ref[a] + loc[a])
        dist = np.linalg.norm(d, axis=1)
        return a, b, dist, d / np.maximum(dist, 1e-300)[:, None]

    def length_residuals(self, x: np.ndarray) -> np.ndarray:
        """Return the weighted length rows ``w (|s_b - s_a| - L)``, shape (n_lengths,)."""
        if not self.n_lengths:
            return np.zeros(0)
        _, _, dist, _ = self._length_parts(x)
        out: np.ndarray = self.nuisance.length_weight * (dist - self.nuisance.lengths[:, 2])
        return out

    def length_jacobian(self, x: np.ndarray) -> sp.csr_matrix:
        """Return d(length rows)/d(nest offsets, frames), shape (n_lengths, n_loc + n_frame)."""
        n = self.n_lengths
        if not n:
            return sp.csr_matrix((0, self.n_loc + self.n_frame))
        a, b, _, unit = self._length_parts(x)
        w = self.nuisance.length_weight
        rows = np.repeat(np.arange(n), 6)
        cols = np.concatenate([3 * b[:, None] + np.arange(3), 3 * a[:, None] + np.arange(3)], axis=1)
        vals = np.concatenate([w * unit, -w * unit], axis=1)
        return sp.csr_matrix((vals.ravel(), (rows, cols.ravel())),
                             shape=(n, self.n_loc + self.n_frame))

    # ------------------------------------------------------------ residuals and Jacobians
    def data_jacobian(self, x_arm: np.ndarray) -> DataJacobian:
        """Return d(data residuals)/d(free arm entries) at x_arm (weighted rows), (3N, n_arm).

        A :class:`~aacmm_pin.fit.chunked_jacobian.ChunkedJacobian` for a :attr:`chunked` problem.
        """
        if self.chunked:
            return ChunkedJacobian(self.unknowns, x_arm, self.q, self.row_weight)
        _, jac = self.unknowns.jacobian(x_arm, self.q)
        return jac if self.row_weight is None else jac.scaled(self.row_weight)

    def fun(self, z: np.ndarray) -> np.ndarray:
        """Return the residuals: data (model - measured, 3N, weighted), nest prior rows, lengths."""
        return self.residual_at(self.x(z))

    def residual_at(self, x: np.ndarray) -> np.ndarray:
        """Return :meth:`fun` at the full vector x (no reduced coordinates needed)."""
        pred = self.unknowns.positions(x[:self.n_arm], self.q).reshape(-1)
        data = pred - self.main_measured(x).reshape(-1)
        if self.row_weight is not None:
            data = data * self.row_weight
        x_loc = x[self.n_arm:self.n_arm + self.n_loc]
        data = data + self.nest @ x_loc
        return np.concatenate([data, self.prior * x_loc, self.length_residuals(x)])

    def fun_with_products(self, z: np.ndarray) -> tuple[np.ndarray, ChunkedJacobian]:
        """Return :meth:`fun` at z and the data Jacobian there, its products taken in the same pass.

        For a :attr:`chunked` problem: the chain gives every chunk's positions with its Jacobian
        rows, so one pass over the chunks makes the residual (the same numbers as :meth:`fun`) and
        J^T J, J^T (nuisance columns) and J^T f at its point
        (:meth:`~aacmm_pin.fit.chunked_jacobian.ChunkedJacobian.evaluate`): a step the solver
        accepts needs no pass of its own for its Jacobian's products.
        """
        x = self.x(z)
        jac = self.data_jacobian(x[:self.n_arm])
        assert isinstance(jac, ChunkedJacobian)
        measured = self.main_measured(x).reshape(-1)
        x_loc = x[self.n_arm:self.n_arm + self.n_loc]
        nest = self.nest @ x_loc
        weight = self.row_weight

        def rows(a: int, b: int, positions: np.ndarray) -> np.ndarray:
            data: np.ndarray = positions.reshape(-1) - measured[a:b]  # as residual_at's rows
            if weight is not None:
                data = data * weight[a:b]
            out: np.ndarray = data + nest[a:b]
            return out

        data = jac.evaluate(self.nuisance_jacobian(x), rows)
        return np.concatenate([data, self.prior * x_loc, self.length_residuals(x)]), jac

    def fun_reported(self, z: np.ndarray, on_evaluation: Callable[[float], None] | None,
                     given: np.ndarray | None = None,
                     evaluate: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
        """Return :meth:`fun` at z (shape (n_rows,), m) and report its RMS to ``on_evaluation``.

        The RMS is in m (in units of the solve's sigma for weighted rows); ``on_evaluation`` is
        called once per evaluation when given (progress). A :class:`~aacmm_pin.fit.solver_values.Counted`
        callback takes the evaluation from its budget first (raising
        :class:`~aacmm_pin.fit.solver_values.BudgetSpent` when none is left). ``given``: the
        residual at z when the caller has it (counted and reported, not computed again);
        ``evaluate``: what computes it instead of :meth:`fun` (the same numbers).
        """
        if isinstance(on_evaluation, Counted):
            on_evaluation.budget.take()
        out = (self.fun if evaluate is None else evaluate)(z) if given is None else given
        if on_evaluation is not None:
            on_evaluation(float(np.sqrt(np.mean(out ** 2))))
        return out

    def data_residuals(self, x: np.ndarray) -> np.ndarray:
        """Return the unweighted data residuals (model - measured, nest offsets applied), (N, 3), m.

        Unlike the data rows of :meth:`fun` they are defined for samples of weight 0 too.
        """
        pred = self.unknowns.positions(x[:self.n_arm], self.q).reshape(-1)
        data = pred - self.main_measured(x).reshape(-1)
        data = data + self._nest_raw @ x[self.n_arm:self.n_arm + self.n_loc]
        out: np.ndarray = data.reshape(-1, 3)
        return out

    def _prior_rows(self, p_nuis: np.ndarray) -> np.ndarray:
        out: np.ndarray = self.prior[:, None] * p_nuis[:self.n_loc]
        return out

    def jac(self, z: np.ndarray) -> np.ndarray:
        """Return d(fun)/dz as a dense array, shape (n_data + n_loc + n_lengths, n_z)."""
        x = self.x(z)
        jac = self.data_jacobian(x[:self.n_arm])
        p_arm, p_nuis = self.p[:self.n_arm], self.p[self.n_arm:]
        out: np.ndarray = np.vstack([jac.matmul(p_arm) + self.nuisance_jacobian(x) @ p_nuis,
                                     self._prior_rows(p_nuis), self.length_jacobian(x) @ p_nuis])
        return out

    def jac_operator(self, z: np.ndarray, data: DataJacobian | None = None) -> LinearOperator:
        """Return d(fun)/dz as an operator (products only), for large campaigns.

        ``data``: :meth:`data_jacobian` at ``x(z)`` when the caller has it (not computed again).
        """
        return self._operator(z, data)[0]

    def _operator(self, z: np.ndarray, data: DataJacobian | None = None
                  ) -> tuple[LinearOperator, list[DataJacobian]]:
        """Return the operator of :meth:`jac_operator` and the list holding its data Jacobian.

        The list is emptied when the operator is no longer used, so that its memory is freed.
        """
        x = self.x(z)
        held = [self.data_jacobian(x[:self.n_arm]) if data is None else data]
        nuis, lengths, prior = self.nuisance_jacobian(x), self.length_jacobian(x), self.prior
        p_arm, p_nuis = self.p[:self.n_arm], self.p[self.n_arm:]
        n_data, n_loc = self.n_data, self.n_loc

        def matvec(v: np.ndarray) -> np.ndarray:
            v = np.ravel(v)
            v_nuis = p_nuis @ v
            return np.concatenate([held[0].matmul(p_arm @ v) + nuis @ v_nuis,
                                   prior * v_nuis[:n_loc], lengths @ v_nuis])

        def rmatvec(u: np.ndarray) -> np.ndarray:
            u = np.ravel(u)
            data, rest, tail = u[:n_data], u[n_data:n_data + n_loc], u[n_data + n_loc:]
            back = nuis.T @ data + lengths.T @ tail
            back[:n_loc] += prior * rest
            out: np.ndarray = p_arm.T @ held[0].rmatmul(data) + p_nuis.T @ back
            return out

        op = LinearOperator(shape=(n_data + n_loc + self.n_lengths, self.p.shape[1]), dtype=float,
                            matvec=matvec, rmatvec=rmatvec)
        return op, held

    def compressed(self, z: np.ndarray, f: np.ndarray, data: DataJacobian | None = None
                   ) -> tuple[LinearOperator, list[DataJacobian]]:
        r"""Return an operator K, shape (n_rows, n_z), equivalent to d(fun)/dz for least squares at z.

        ``K^T K = (J P)^T (J P)`` and ``K^T f = (J P)^T f`` for the residual f at z: a linear
        least-squares problem ``min ||f + K dz||`` (a trust-region step, the Gauss-Newton step,
        the predicted reduction, scipy's gradient) has the same solution and values as with
        ``J P``, and K holds no per-sample Jacobian. With ``A = (J P)^T (J P) = R^T R`` and
        ``c = R^{-T} (J P)^T f`` (the residual's coefficients on an orthonormal basis of the
        columns' span, ``|c| <= |f|``), ``K = H [g^T; B; 0] R`` with ``g = c / |f|``,
        ``B = (I - g g^T)^{1/2}`` and H the Householder reflection taking the first unit vector to
        ``f / |f|``. A and ``(J P)^T f`` are taken in one pass over the data Jacobian's chunks
        (:meth:`~aacmm_pin.fit.chunked_jacobian.ChunkedJacobian.products`).

        Args:
            z: reduced coordinates, shape (n_z,).
            f: :meth:`fun` at z, shape (n_rows,), m.
            data: :meth:`data_jacobian` at ``x(z)`` when the caller has it (not computed again).

        Returns:
            K, and the list holding the data Jacobian (as :meth:`_operator`'s).
        """
        x = self.x(z)
        jac = self.data_jacobian(x[:self.n_arm]) if data is None else data
        nuis = self.nuisance_jacobian(x)
        n_data, n_loc = self.n_data, self.n_loc
        f_data = f[:n_data]
        if isinstance(jac, ChunkedJacobian):  # one pass over the chunks
            normal, cross, g_arm = jac.products(nuis, f_data)
            assert cross is not None and g_arm is not None
        else:
            normal, cross, g_arm = jac.normal(), jac.cross(nuis), jac.rmatmul(f_data)
        info = self._information(x, normal, cross, nuis)
        back = nuis.T @ f_data + self.length_jacobian(x).T @ f[n_data + n_loc:]
        back[:n_loc] += self.prior * f[n_data:n_data + n_loc]
        a = self.p.T @ info @ self.p
        b = self.p.T @ np.concatenate([g_arm, back])
        lam, vec = np.linalg.eigh(a)
        root = np.sqrt(np.clip(lam, 0.0, None))
        r = root[:, None] * vec.T                                        # A = R^T R
        seen = root > root.max(initial=0.0) * RANK_TOL
        c = np.where(seen, (vec.T @ b) / np.where(seen, root, 1.0), 0.0)  # R^-T b
        size = float(np.linalg.norm(f))
        g = c / size if size > 0.0 else np.zeros_like(c)
        g2 = float(g @ g)
        if g2 > 1.0:  # rounding: c is a projection of f
            g, g2 = g / np.sqrt(g2), 1.0
        b_mat = np.eye(g.size) - np.outer(g, g) / (1.0 + np.sqrt(1.0 - g2))  # (I - g g^T)^(1/2)
        w = f / size if size > 0.0 else np.zeros_like(f)
        w[0] -= 1.0
        ww = float(w @ w)
        n_z, n_rows = g.size, f.size

        def reflect(u: np.ndarray) -> np.ndarray:
            out: np.ndarray = u - (2.0 * float(w @ u) / ww) * w if ww > 1e-300 else u.copy()
            return out

        def matvec(v: np.ndarray) -> np.ndarray:
            t = r @ np.ravel(v)
            top = np.zeros(n_rows)
            top[0] = g @ t
            top[1:n_z + 1] = b_mat @ t
            return reflect(top)

        def rmatvec(u: np.ndarray) -> np.ndarray:
            h = reflect(np.ravel(u))
            out: np.ndarray = r.T @ (g * h[0] + b_mat @ h[1:n_z + 1])
            return out

        op = LinearOperator(shape=(n_rows, n_z), dtype=float, matvec=matvec, rmatvec=rmatvec)
        return op, [jac]

    def factor(self, z: np.ndarray) -> Factor:
        """Return the reduced QR factors of the dense Jacobian at z."""
        q, r = np.linalg.qr(self.jac(z))
        return Factor(q, r)

    def normal_matrix(self, x: np.ndarray, jac: DataJacobian | None = None) -> np.ndarray:
        """Return J^T J of the data, prior and length rows w.r.t. the full vector at x, (n_x, n_x).

        ``jac``: :meth:`data_jacobian` at x when the caller has it (not computed again).
        """
        jac = self.data_jacobian(x[:self.n_arm]) if jac is None else jac
        nuis = self.nuisance_jacobian(x)
        if isinstance(jac, ChunkedJacobian):  # one pass over the chunks
            normal, cross, _ = jac.products(nuis)
            assert cross is not None
        else:
            normal, cross = jac.normal(), jac.cross(nuis)
        return self._information(x, normal, cross, nuis)

    def _information(self, x: np.ndarray, normal: np.ndarray, cross: np.ndarray,
                     nuis: sp.csr_matrix) -> np.ndarray:
        """Return :meth:`normal_matrix` from the data block's J^T J and J^T (nuisance columns)."""
        lengths = self.length_jacobian(x)
        na, nn = self.n_arm, self.n_loc + self.n_frame
        info = np.empty((na + nn, na + nn))
        info[:na, :na] = normal
        info[:na, na:] = cross
        info[na:, :na] = cross.T
        info[na:, na:] = (nuis.T @ nuis + lengths.T @ lengths).toarray()
        info[na:na + self.n_loc, na:na + self.n_loc] += np.diag(self.prior ** 2)
        return info

    def covariance(self, x: np.ndarray, sigma: float, jac: DataJacobian | None = None
                   ) -> np.ndarray:
        """Return the linearised covariance of the full vector at x for data noise sigma (m).

        ``T^T (J^T J / sigma^2 + blockdiag(0, I / sigma_nest^2, 0)) T``, inverted: the data and
        length rows with this sigma, the nest offsets' prior with its own sigma whatever the data's.
        """
        info = self.normal_matrix(x, jac)  # jac: data_jacobian at x, if the caller has it
        na, nl = self.n_arm, self.n_loc
        info[na:na + nl, na:na + nl] -= np.diag(self.prior ** 2)  # the solve's weighting, removed
        info /= sigma ** 2
        info[na:na + nl, na:na + nl] += np.diag(1.0 / self.nest_sigma ** 2)
        info = self.basis.T @ info @ self.basis
        cov_y = np.linalg.pinv(info, rcond=1e-14, hermitian=True)
        out: np.ndarray = self.basis @ cov_y @ self.basis.T
        return out

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
        warm = start if isinstance(start, WarmStart) else WarmStart(np.asarray(start))
        # The analytic Jacobian goes to LSMR as an operator at every size: in the preconditioned
        # coordinates its columns are nearly orthonormal, so LSMR takes a few products per step
        # where the exact solver takes a dense SVD (paper-sized campaign: 3x less CPU, the same
        # solution to 1e-4 of its standard deviations, tests/test_identification.py)
        dense = jac != "analytic"
        z0 = warm.z
        handover = _Handover(warm, jacobian=not dense)
        exact = warm.at is None or np.array_equal(warm.at, self.x(z0))
        del warm, start
        evaluations = [0]
        best: list[tuple[float, np.ndarray, np.ndarray]] = []  # (cost, z, f) of the lowest cost
        latest: list[tuple[np.ndarray, np.ndarray]] = []  # (z, f) of the last evaluation

        fused: list[tuple[np.ndarray, ChunkedJacobian]] = []  # (z, its Jacobian) of fun's pass

        def with_products(z: np.ndarray) -> np.ndarray:
            f, jac_z = self.fun_with_products(z)
            fused[:] = [(np.array(z, dtype=float), jac_z)]
            return f

        def fun(z: np.ndarray) -> np.ndarray:
            given = handover.residual(z)
            if given is None:
                given = self.fun_reported(z, on_evaluation,
                                          evaluate=with_products if fuse else None)
                evaluations[0] += 1
            cost = 0.5 * float(given @ given)
            latest[:] = [(np.array(z, dtype=float), given)]
            if not best or cost < best[0][0]:
                best[:] = [(cost, np.array(z, dtype=float), given)]
            return given

        jac_fun: Callable[[np.ndarray], np.ndarray | LinearOperator] | str = jac
        previous: list[list[DataJacobian]] = []
        at: list[np.ndarray] = []
        used_given = [False]  # the current operator holds the caller's (maybe inexact) Jacobian

        def operator(z: np.ndarray) -> LinearOperator:
            # scipy keeps the first Jacobian and the current one while it builds the next: only
            # the current one is used, so the others' data (hundreds of MB for a large campaign)
            # is released first
            while previous:
                previous.pop().clear()
            given = handover.jacobian(z)
            from_caller = given is not None
            if fused and np.array_equal(fused[0][0], z):  # fun's pass at z: exactly here
                given, from_caller = fused.pop()[1], False
            fused.clear()
            if normal_equations:  # scipy evaluated the residual at z just before
                f = latest[0][1] if latest and np.array_equal(latest[0][0], z) else self.fun(z)
                op, held = self.compressed(z, f, given)
            else:
                op, held = self._operator(z, given)
            used_given[0] = from_caller
            del given
            previous.append(held)
            at[:] = [np.array(z, dtype=float)]
            return op

        # a chunked problem's steps from its normal equations (a linear loss: a robust loss
        # reweights the rows, which the normal equations do not keep)
        normal_equations = self.chunked and settings.loss == "linear"
        fuse = normal_equations and jac == "analytic"  # residuals with their products
        if jac == "analytic":
            jac_fun = self.jac if dense else operator
        try:
            out = least_squares(fun, z0, jac=jac_fun, method="trf",
                                tr_solver="exact" if dense else "lsmr", loss=settings.loss,
                                f_scale=settings.f_scale, max_nfev=settings.max_nfev, ftol=1e-12,
                                xtol=1e-12, gtol=STEP_TOL * self.sigma_class)
        except BudgetSpent:  # the fit's evaluations are spent: it ends at its lowest cost
            while previous:
                previous.pop().clear()
            if best:
                cost, z_best, f_best = best[0]
            else:  # nothing evaluated here: the start's residual (for the report, not a step)
                z_best = np.array(z0, dtype=float)
                f_best = self.fun(z_best)
                cost = 0.5 * float(f_best @ f_best)
            out = OptimizeResult(x=z_best, fun=f_best, cost=cost, status=0, success=False,
                                 message=BUDGET_MESSAGE, njev=0, optimality=np.nan)
        fused.clear()
        out.nfev = evaluations[0]
        last: DataJacobian | None = None
        if previous:  # the last operator's Jacobian, if taken at the solution
            held = previous.pop()
            if held and np.array_equal(at[0], out.x) and (exact or not used_given[0]):
                last = held[0]
            held.clear()
            out.pop("jac", None)
        return Solution(out, last)

    def newton_step(self, z: np.ndarray, f: np.ndarray, data: DataJacobian | None = None
                    ) -> np.ndarray:
        """Return the Gauss-Newton step at z: the dz minimising ``||f + (J P) dz||``, shape (n_z,).

        LSMR on :meth:`jac_operator` at every size, as :meth:`solve`'s steps: near the point the
        preconditioner was computed at the columns of ``J P`` are nearly orthonormal, so a few
        products reach the step (a dense least-squares solve took 2 s of CPU on 16,000 samples,
        LSMR 0.1 s). The step is in reduced coordinates (m of weighted residual per unit).

        Args:
            z: reduced coordinates, shape (n_z,).
            f: :meth:`fun` at z, shape (n_data + n_loc + n_lengths,), m.
            data: :meth:`data_jacobian` at ``x(z)`` when the caller has it (not computed again).
        """
        op = self.compressed(z, f, data)[0] if self.chunked else self.jac_operator(z, data)
        step: np.ndarray = lsmr(op, -f, atol=1e-12, btol=1e-12)[0]
        return step

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
