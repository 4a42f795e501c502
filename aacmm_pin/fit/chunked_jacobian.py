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

from collections.abc import Callable, Iterator

import numpy as np
import scipy.sparse as sp

from aacmm_pin._heap import release_free_heap
from aacmm_pin.fit.robust import node_sensitivity
from aacmm_pin.fit.unknowns import CHUNK, BlockJacobian, Unknowns, node_normal

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


def chunk_normal(jac: BlockJacobian) -> np.ndarray:
    """Return J^T J of a chunk's rows, shape (n_free, n_free): :meth:`BlockJacobian.normal` faster.

    The node-dense block ``W^T (D J)``, with every sample's axis columns against its dense rows
    taken for all axes in one batched product (a (n_axes, 3) by (3, n_dense) matrix per sample,
    :data:`~aacmm_pin.fit.unknowns.CHUNK` samples at a time) and summed onto the nodes by one
    sparse product (two weights per sample and axis), instead of one pass over the dense rows per
    axis: 2.5x less CPU for that block (the paper's arm, 7 maps). The same numbers to rounding.
    """
    axes = [ax for ax in jac.axes if ax.size]
    if not axes:
        return jac.normal()
    nd, m = jac.dense.shape[1], jac.shape[1]
    n, n_ax = jac.dense.shape[0] // 3, len(axes)
    dense3 = jac.dense.reshape(n, 3, nd)
    d = np.stack([ax.d for ax in axes], axis=1)                             # (N, n_ax, 3)
    weights = sp.csr_matrix(
        (np.stack([ax.weight for ax in axes], axis=1).ravel(),
         np.stack([ax.col + ax.offset for ax in axes], axis=1).ravel(),
         np.arange(0, 2 * n * n_ax + 1, 2)), shape=(n * n_ax, jac.n_nodes))  # W, (N n_ax, nodes)
    cross = np.zeros((jac.n_nodes, nd))
    for lo in range(0, n, CHUNK):
        hi = min(n, lo + CHUNK)
        per = np.matmul(d[lo:hi], dense3[lo:hi]).reshape(-1, nd)            # (n_ax (hi-lo), nd)
        cross += weights[n_ax * lo:n_ax * hi].T @ per
        del per  # before the next block's: one block's 28 MB at a time
    out = np.empty((m, m))
    out[:nd, :nd] = jac.dense.T @ jac.dense
    out[nd:, :nd] = cross
    out[:nd, nd:] = cross.T
    out[nd:, nd:] = node_normal(jac)
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
        self._deferred: tuple[sp.csr_matrix | None, np.ndarray | None] = (None, None)
        """The u and f whose J^T u, J^T f the next pass with products takes (:meth:`defer`)."""
        self._residual_rows: Callable[[int, int, np.ndarray], np.ndarray] | None = None
        """Makes f's rows from a chunk's positions in the next pass (:meth:`evaluate`)."""
        self._f_out: np.ndarray | None = None
        """Where the next pass writes f (:meth:`evaluate`'s ``out``), or None (a new array)."""

    @property
    def shape(self) -> tuple[int, int]:
        """(3N, n_free)."""
        return 3 * self.q.shape[0], int(self.unknowns.free.sum())

    def scaled(self, row_weight: np.ndarray) -> ChunkedJacobian:
        """Return diag(row_weight) @ J (row_weight shape (3N,))."""
        w = row_weight if self.row_weight is None else self.row_weight * row_weight
        return ChunkedJacobian(self.unknowns, self.x_arm, self.q, w)

    def chunks(self, products: bool = False) -> Iterator[tuple[int, int, BlockJacobian]]:
        """Yield (first row, end row, the Jacobian's rows there) chunk by chunk.

        ``products``: the same pass takes J^T J (unless kept) and the deferred J^T u and J^T f
        (:meth:`defer`, :meth:`evaluate`), kept once every chunk has been yielded (a pass ended
        early keeps none). A chunk's rows live in buffers the next chunk overwrites: use them
        before asking for the next.
        """
        n, m = self.q.shape[0], self.shape[1]
        rows, f = self._deferred if products else (None, None)
        rows_of = self._residual_rows if products else None
        if rows_of is not None:
            f = np.empty(3 * n) if self._f_out is None else self._f_out
        normal = np.zeros((m, m)) if products and self._normal is None else None
        cross = None if rows is None else np.zeros((m, rows.shape[1]))
        grad = None if f is None else np.zeros(m)
        yield from self._passed(rows_of, f, normal, rows, cross, grad, {})  # buffers: this pass'
        release_free_heap()  # the chunks' temporaries: free heap pages, not resident ones
        if normal is not None:
            self._normal = normal
        if cross is not None and rows is not None:
            self._cross = (rows, cross)
        if grad is not None and f is not None:
            self._grad = (f, grad)
        if products:
            self._deferred, self._residual_rows, self._f_out = (None, None), None, None

    def _passed(self, rows_of: Callable[[int, int, np.ndarray], np.ndarray] | None,
                f: np.ndarray | None, normal: np.ndarray | None, rows: sp.csr_matrix | None,
                cross: np.ndarray | None, grad: np.ndarray | None, work: dict[str, np.ndarray]
                ) -> Iterator[tuple[int, int, BlockJacobian]]:
        """:meth:`chunks`' pass: each chunk's rows in ``work``, f's rows and the sums taken.

        ``work``: the pass's buffers (positions, dense block, angle columns: about 80 MB), reused
        by each of its chunks (the same pages, not fresh ones: page faults made system time grow
        faster than the data) and freed when the pass ends: a Jacobian the solver holds between
        passes holds none, nor does the process while the solver works on the row space
        (:meth:`~aacmm_pin.fit.reduced_jacobian.ReducedJacobian.compressed`; 80 MB off the peak at
        1.6M samples for one allocation per pass).
        """
        n = self.q.shape[0]
        for lo in range(0, n, CHUNK_SAMPLES):
            hi = min(n, lo + CHUNK_SAMPLES)
            pos, jac = self.unknowns.jacobian_rows(self.x_arm, self.q, lo, hi, work)
            if rows_of is not None and f is not None:
                f[3 * lo:3 * hi] = rows_of(3 * lo, 3 * hi, pos)
            del pos
            if self.row_weight is not None:  # in place: the rows are this pass's own
                jac = jac.scaled(self.row_weight[3 * lo:3 * hi], in_place=True)
            if normal is not None:
                normal += chunk_normal(jac)
            if cross is not None and rows is not None:
                cross += sparse_cross(jac, rows[3 * lo:3 * hi])
            if grad is not None and f is not None:
                grad += jac.rmatmul(f[3 * lo:3 * hi])
            yield 3 * lo, 3 * hi, jac

    def evaluate(self, u: sp.spmatrix | sp.sparray,
                 residual_rows: Callable[[int, int, np.ndarray], np.ndarray],
                 out: np.ndarray | None = None) -> np.ndarray:
        """Return the data residual f, shape (3N,), from the positions of one pass, its products kept.

        The chain gives each chunk's positions with its Jacobian rows (the same numbers as
        :meth:`~aacmm_pin.fit.unknowns.Unknowns.positions`): ``residual_rows(first row, end row,
        positions (chunk, 3) m)`` turns them into the chunk's rows of f, and the same pass takes
        J^T J, J^T u and J^T f (kept: :meth:`products` asks no pass for them). A residual
        evaluation and the Jacobian's products at its point in one pass over the chunks.

        ``out``: where f is written, shape (3N,) (e.g. the data rows of the whole residual), else
        a new array. The f returned is the one kept with its J^T f, not a copy (one vector of
        3N less: 38 MB at 1.6M samples): J^T f is taken again only if its entries change.
        """
        self._deferred = (sp.csr_matrix(u), None)
        self._residual_rows, self._f_out = residual_rows, out
        for _ in self.chunks(products=True):
            pass
        assert self._grad is not None
        f: np.ndarray = self._grad[0]
        return f

    def defer(self, u: sp.spmatrix | sp.sparray | None = None, f: np.ndarray | None = None
              ) -> None:
        """Ask for J^T u (sparse u, shape (3N, k)) and J^T f (shape (3N,)) in the next pass.

        The next pass over :meth:`chunks` with products takes them (the gauge check's, at a
        fit's start: the solver's first products need no pass of their own); :meth:`products`
        then finds them kept.
        """
        self._deferred = (None if u is None else sp.csr_matrix(u),
                          None if f is None else np.array(f, dtype=float))

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
        if (self._normal is None or (rows is not None and known is None)
                or (f is not None and known_grad is None)):
            ask_rows = rows if known is None else None
            ask_f = None if f is None or known_grad is not None else np.array(f, dtype=float)
            pending_rows, pending_f = self._deferred  # a deferred ask rides on this pass too
            self._deferred = (pending_rows if ask_rows is None else ask_rows,
                              pending_f if ask_f is None else ask_f)
            for _ in self.chunks(products=True):
                pass
            if known is None and rows is not None:
                known = self._known_cross(rows)
            if known_grad is None and f is not None:
                assert self._grad is not None
                known_grad = self._grad[1].copy()
        assert self._normal is not None
        return self._normal.copy(), known, known_grad

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


def chunked_node_sensitivity(jac: ChunkedJacobian) -> sp.coo_matrix:
    """:func:`aacmm_pin.fit.robust.node_sensitivity` of ``jac``'s node block, chunk by chunk.

    Each chunk's node block (:attr:`~aacmm_pin.fit.unknowns.BlockJacobian.nodes`) made and
    reduced to its samples' sensitivities, the chunks' entries stacked: the same numbers, in the
    same order, as from the whole Jacobian's node block, without it (24 bytes per sample and node
    touched instead of the Jacobian's 1.1 kB per sample). Shape (N, n_nodes), m^2/rad^2.
    """
    rows, cols, vals = [], [], []
    for a, b, part in jac.chunks():
        per = node_sensitivity(part.nodes, (b - a) // 3)
        rows.append((per.row + a // 3).astype(np.int32))  # N < 2^31
        cols.append(per.col.astype(np.int32))
        vals.append(per.data)
    u = jac.unknowns
    n_nodes = jac.shape[1] - int(u.free[:u.n_dense].sum())
    if not vals:
        return sp.coo_matrix((jac.q.shape[0], n_nodes))
    data, row, col = np.concatenate(vals), np.concatenate(rows), np.concatenate(cols)
    del vals, rows, cols
    out = sp.coo_matrix((data, (row, col)), shape=(jac.q.shape[0], n_nodes))
    out.has_canonical_format = True  # each chunk's sorted (by sample, then node), none summed
    return out
