"""The data Jacobian of a large campaign, never held whole: its products taken chunk by chunk.

A campaign's data Jacobian costs about 1.1 kB per sample (the paper's arm: 31 dense columns, 7
maps): 1.8 GB at 1.6M samples. Everything the fit takes from it is small: the normal matrix
``J^T J`` (observability, preconditioner, covariance), ``J^T u`` for the nuisance columns and for
the residual (the solver's gradient and steps), and the R factor of the gauge check. Above
:data:`CHUNKED_BYTES` of Jacobian (a layout whose Jacobian comes from the chain alone) the fit
takes these from :class:`ChunkedJacobian`, which computes the rows of :data:`CHUNK_SAMPLES`
samples at a time (:meth:`aacmm_pin.fit.unknowns.Unknowns.jacobian_rows`) and keeps none of them.
Below it the fit holds the :class:`~aacmm_pin.fit.unknowns.BlockJacobian` as before (the same
numbers bit for bit).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import scipy.sparse as sp

from aacmm_pin.fit.unknowns import BlockJacobian, Unknowns

CHUNKED_BYTES = 2 ** 28
"""Data Jacobians larger than this (bytes, 256 MiB: about 240,000 samples of the paper's arm) are
never held whole: the fit takes their products chunk by chunk (:class:`ChunkedJacobian`)."""
CHUNK_SAMPLES = 65536
"""Samples per chunk (a multiple of the chain's own block; about 70 MB of Jacobian rows)."""


def jacobian_bytes(unknowns: Unknowns, n_samples: int) -> int:
    """Return the bytes of the :class:`BlockJacobian` of n_samples samples for this layout.

    24 bytes per sample and dense column (3 rows of float64), 56 per sample and map axis (two
    node columns, two weights, three angle derivatives).
    """
    n_dense = int(unknowns.free[:unknowns.n_dense].sum())
    return int(n_samples) * (24 * n_dense + 56 * len(unknowns.map_axes))


def is_chunked(unknowns: Unknowns, n_samples: int) -> bool:
    """Whether the fit takes this layout's Jacobian of n_samples samples chunk by chunk."""
    return unknowns.chain_only() and jacobian_bytes(unknowns, n_samples) > CHUNKED_BYTES


def sparse_cross(jac: BlockJacobian, u: sp.csr_matrix) -> np.ndarray:
    """Return J^T u for a sparse u, shape (3N, k), in sparse products only, shape (n_free, k).

    :meth:`~aacmm_pin.fit.unknowns.BlockJacobian.cross` with the node block's part taken as
    ``W^T (D u)``: D (N, 3N) holds each sample's d(point)/d(angle) on its three rows and W the
    interpolation weights (:meth:`~aacmm_pin.fit.unknowns.AxisNodes.transposed_weights`), so the
    cost follows u's nonzeros (one per row for the nests) instead of a dense copy of u's rows.
    """
    n = jac.dense.shape[0] // 3
    out = np.empty((jac.shape[1], u.shape[1]))
    nd = jac.dense.shape[1]
    out[:nd] = np.asarray(u.T @ jac.dense).T
    rows, starts = np.arange(3 * n), np.arange(0, 3 * n + 1, 3)
    for ax in jac.axes:
        d = sp.csr_matrix((ax.d.ravel(), rows, starts), shape=(n, 3 * n))
        out[nd + ax.offset:nd + ax.offset + ax.size] = (ax.transposed_weights() @ (d @ u)).toarray()
    return out


class ChunkedJacobian:
    """d(data residuals)/d(free arm entries) at one point, rows weighted, shape (3N, n_free).

    The products a fit needs, each in one pass over chunks of samples; :meth:`normal` is kept
    once computed (the small (n_free, n_free) matrix).

    Args:
        unknowns: the layout (:meth:`~aacmm_pin.fit.unknowns.Unknowns.chain_only`).
        x_arm: free arm entries, shape (n_free,), SI.
        q: readouts, shape (N, n_axes), rad.
        row_weight: weight of every row, shape (3N,), or None (all 1).
    """

    def __init__(self, unknowns: Unknowns, x_arm: np.ndarray, q: np.ndarray,
                 row_weight: np.ndarray | None = None):
        self.unknowns, self.x_arm, self.q = unknowns, np.array(x_arm, dtype=float), q
        self.row_weight = row_weight
        self._normal: np.ndarray | None = None
        self._cross: tuple[sp.csr_matrix, np.ndarray] | None = None
        """The last J^T u and its u (the covariance at a solve's solution asks for the solve's)."""
        self._grad: tuple[np.ndarray, np.ndarray] | None = None
        """The last J^T f and its f (a pass primed by the fit serves the solve's first step)."""

    @property
    def shape(self) -> tuple[int, int]:
        """(3N, n_free)."""
        return 3 * self.q.shape[0], int(self.unknowns.free.sum())

    def scaled(self, row_weight: np.ndarray) -> ChunkedJacobian:
        """Return diag(row_weight) @ J (row_weight shape (3N,))."""
        w = row_weight if self.row_weight is None else self.row_weight * row_weight
        return ChunkedJacobian(self.unknowns, self.x_arm, self.q, w)

    def chunks(self) -> Iterator[tuple[int, int, BlockJacobian]]:
        """Yield (first row, end row, the Jacobian's rows there) chunk by chunk."""
        n = self.q.shape[0]
        for lo in range(0, n, CHUNK_SAMPLES):
            hi = min(n, lo + CHUNK_SAMPLES)
            _, jac = self.unknowns.jacobian_rows(self.x_arm, self.q, lo, hi)
            if self.row_weight is not None:
                jac = jac.scaled(self.row_weight[3 * lo:3 * hi])
            yield 3 * lo, 3 * hi, jac

    def products(self, u: sp.spmatrix | sp.sparray | None = None, f: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Return J^T J, J^T u (sparse u, shape (3N, k)) and J^T f (f shape (3N,)) in one pass.

        Each of u and f may be None (its product None). J^T J, the last J^T u and the last J^T f
        are kept: asked again (same entries of u, of f), they take no pass.
        """
        rows = None if u is None else sp.csr_matrix(u)
        known = self._known_cross(rows)
        known_grad = None
        if f is not None and self._grad is not None and np.array_equal(self._grad[0], f):
            known_grad = self._grad[1].copy()
        if (self._normal is not None and (rows is None or known is not None)
                and (f is None or known_grad is not None)):
            return self._normal.copy(), known, known_grad
        m = self.shape[1]
        normal = None if self._normal is not None else np.zeros((m, m))
        cross = None if rows is None or known is not None else np.zeros((m, rows.shape[1]))
        grad = None if f is None or known_grad is not None else np.zeros(m)
        for a, b, jac in self.chunks():
            if normal is not None:
                normal += jac.normal()
            if cross is not None and rows is not None:
                cross += sparse_cross(jac, rows[a:b])
            if grad is not None and f is not None:
                grad += jac.rmatmul(f[a:b])
        if normal is not None:
            self._normal = normal
        if cross is not None and rows is not None:
            self._cross = (rows, cross)
        if grad is not None and f is not None:
            self._grad = (np.array(f, dtype=float), grad)
        assert self._normal is not None
        return (self._normal.copy(), known if cross is None else cross.copy(),
                known_grad if grad is None else grad.copy())

    def _known_cross(self, rows: sp.csr_matrix | None) -> np.ndarray | None:
        """Return the kept J^T u if u is the kept one's (same entries), else None."""
        if rows is None or self._cross is None:
            return None
        kept, cross = self._cross
        if kept.shape != rows.shape or (kept != rows).nnz:
            return None
        out: np.ndarray = cross.copy()
        return out

    def normal(self) -> np.ndarray:
        """Return J^T J, shape (n_free, n_free) (computed once)."""
        if self._normal is None:
            self.products()
        assert self._normal is not None
        out: np.ndarray = self._normal.copy()
        return out

    def keep_normal(self, normal: np.ndarray) -> None:
        """Keep J^T J computed elsewhere in a pass over :meth:`chunks` (no pass of its own)."""
        if self._normal is None:
            self._normal = np.array(normal, dtype=float)

    def cross(self, u: sp.spmatrix | sp.sparray) -> np.ndarray:
        """Return J^T @ u for a sparse u of shape (3N, k), shape (n_free, k)."""
        out = self.products(u)[1]
        assert out is not None
        return out

    def rmatmul(self, u: np.ndarray) -> np.ndarray:
        """Return J^T @ u for u of shape (3N,)."""
        out = self.products(f=u)[2]
        assert out is not None
        return out

    def matmul(self, m: np.ndarray) -> np.ndarray:
        """Return J @ m for m of shape (n_free,) or (n_free, k)."""
        out = np.empty((self.shape[0], *m.shape[1:]))
        for a, b, jac in self.chunks():
            out[a:b] = jac.matmul(m)
        return out

    def columns_sum(self, cols: np.ndarray) -> np.ndarray:
        """Return the sum of the given columns (free-vector indices), shape (3N,)."""
        sel = np.zeros(self.shape[1])
        sel[cols] = 1.0
        return self.matmul(sel)


DataJacobian = BlockJacobian | ChunkedJacobian
"""A data Jacobian as the fit holds it: whole (blocks) or chunk by chunk."""
