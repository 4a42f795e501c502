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

        Each of u and f may be None (its product None); J^T J is kept (:meth:`normal`).
        """
        if u is None and f is None and self._normal is not None:
            return self._normal.copy(), None, None
        rows = None if u is None else sp.csr_matrix(u)
        m = self.shape[1]
        normal = None if self._normal is not None else np.zeros((m, m))
        cross = None if rows is None else np.zeros((m, rows.shape[1]))
        grad = None if f is None else np.zeros(m)
        for a, b, jac in self.chunks():
            if normal is not None:
                normal += jac.normal()
            if cross is not None and rows is not None:
                cross += jac.cross(rows[a:b])
            if grad is not None and f is not None:
                grad += jac.rmatmul(f[a:b])
        if normal is not None:
            self._normal = normal
        assert self._normal is not None
        return self._normal.copy(), cross, grad

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
