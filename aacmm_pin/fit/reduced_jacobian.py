r"""An identification's problem in reduced coordinates: its residual and Jacobian forms.

:class:`ReducedJacobian` adds to the rows of :class:`~aacmm_pin.fit.data_rows.DataRows` the
reduced coordinates ``x = x_ref + P z`` (:attr:`p`, set by
:class:`~aacmm_pin.fit.solver.Problem`'s preconditioner) and the Jacobian in them: dense
(:meth:`ReducedJacobian.jac`, :meth:`ReducedJacobian.factor`), as an operator
(:meth:`ReducedJacobian.jac_operator`) or from the normal equations
(:meth:`ReducedJacobian.compressed`), the normal matrix and the covariance, and the Gauss-Newton
steps.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, lsmr

from aacmm_pin.fit.chunked_jacobian import ChunkedJacobian, DataJacobian
from aacmm_pin.fit.data_rows import DataRows
from aacmm_pin.fit.solver_values import Counted, Factor

RANK_TOL = 1e-10
"""Relative singular value below which a constraint row adds no rank."""


class ReducedJacobian(DataRows):
    """The rows of :class:`DataRows` in reduced coordinates z (``x = x_ref + P z``), and their Jacobian.

    The coordinates' attributes are set by :class:`~aacmm_pin.fit.solver.Problem`.
    """

    x_ref: np.ndarray
    """Full vector at z = 0, shape (n_x,)."""
    basis: np.ndarray
    """T: plausible-scaled basis of the constraints' null space (arm), of the nest offsets
    (scaled by their prior) and of the frames, shape (n_x, n_y)."""
    p: np.ndarray
    """P = T R^-1: full-vector change per reduced coordinate (``x = x_ref + P z``), shape (n_x, n_z)."""

    # ------------------------------------------------------------ coordinates
    @property
    def n_arm_y(self) -> int:
        """Number of arm coordinates in the scaled null-space basis (the first of y)."""
        return int(self.basis.shape[1] - self.n_loc - self.n_frame)

    def z(self, x: np.ndarray) -> np.ndarray:
        """Return the reduced coordinates of a full vector in the constraints' null space."""
        z: np.ndarray = np.linalg.lstsq(self.p, x - self.x_ref, rcond=None)[0]
        return z

    def x(self, z: np.ndarray) -> np.ndarray:
        """Return the full vector for reduced coordinates z."""
        x: np.ndarray = self.x_ref + self.p @ z
        return x

    # ------------------------------------------------------------ residuals and Jacobians
    def fun(self, z: np.ndarray) -> np.ndarray:
        """Return the residuals: data (model - measured, 3N, weighted), nest prior rows, lengths."""
        return self.residual_at(self.x(z))

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
        nest, weight = self.nest, self.row_weight

        def rows(a: int, b: int, positions: np.ndarray) -> np.ndarray:
            data: np.ndarray = positions.reshape(-1) - measured[a:b]  # as residual_at's rows
            if weight is not None:
                data *= weight[a:b]
            data += nest[a:b] @ x_loc  # the chunk's rows of nest @ x_loc: no (3N,) vector
            return data

        tail = np.concatenate([self.prior * x_loc, self.length_residuals(x)])
        out = np.empty(self.n_data + tail.size)
        out[self.n_data:] = tail
        jac.evaluate(self.nuisance_jacobian(x), rows, out=out[:self.n_data])  # f's data rows
        return out, jac

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

        return _compressed_operator(f, size, r, g, b_mat), [jac]

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

    # ------------------------------------------------------------ steps
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


def _compressed_operator(f: np.ndarray, size: float, r: np.ndarray, g: np.ndarray,
                         b_mat: np.ndarray) -> LinearOperator:
    """Return :meth:`ReducedJacobian.compressed`'s ``K = H [g^T; B; 0] R``, shape (n_rows, n_z).

    Args:
        f: the residual, shape (n_rows,), m.
        size: ``|f|``, m.
        r: R, shape (n_z, n_z).
        g: the residual's coefficients on the columns' orthonormal basis over ``|f|``, (n_z,).
        b_mat: ``B = (I - g g^T)^(1/2)``, shape (n_z, n_z).
    """
    def reflector() -> np.ndarray:
        """Return H's vector ``w = f / |f| - e1``, shape (n_rows,).

        Made when used: the operator holds no (n_rows,) vector of its own (38 MB at 1.6M
        samples) beside the residual the solver holds.
        """
        w = f / size if size > 0.0 else np.zeros_like(f)
        w[0] -= 1.0
        return w

    w0 = reflector()
    ww = float(w0 @ w0)
    del w0
    n_z, n_rows = g.size, f.size

    def reflect(u: np.ndarray, own: bool = False) -> np.ndarray:
        """H u: ``u - (2 w.u / w.w) w`` in one new vector of n_rows (u itself if ``own``)."""
        if ww <= 1e-300:
            return u if own else u.copy()
        w = reflector()
        c = 2.0 * float(w @ u) / ww
        np.multiply(w, -c, out=w)  # u + (-c w): the same numbers as u - c w
        w += u
        return w

    def matvec(v: np.ndarray) -> np.ndarray:
        t = r @ np.ravel(v)
        top = np.zeros(n_rows)
        top[0] = g @ t
        top[1:n_z + 1] = b_mat @ t
        return reflect(top, own=True)

    def rmatvec(u: np.ndarray) -> np.ndarray:
        h = reflect(np.ravel(u))
        out: np.ndarray = r.T @ (g * h[0] + b_mat @ h[1:n_z + 1])
        return out

    return LinearOperator(shape=(n_rows, n_z), dtype=float, matvec=matvec, rmatvec=rmatvec)
