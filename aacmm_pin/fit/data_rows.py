r"""The rows of an identification's least-squares problem: data, nest priors and lengths.

:class:`DataRows` holds what the residual rows need at a full vector ``[arm unknowns, nest
offsets, instrument frames]`` (:class:`Nuisance`): the data rows (model - measured, per sample,
weighted by ``sigma / stated noise``), the nests' prior rows and the length rows, with their
Jacobians with respect to the nuisance unknowns and the data Jacobian with respect to the arm's.
No constraints, no preconditioner: :class:`~aacmm_pin.fit.reduced_jacobian.ReducedJacobian` adds
the reduced coordinates, :class:`~aacmm_pin.fit.solver.Problem` the preconditioner and the solve.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np
import pinocchio as pin
import scipy.sparse as sp

from aacmm_pin.fit.chunked_jacobian import ChunkedJacobian, DataJacobian, is_chunked
from aacmm_pin.fit.unknowns import Unknowns

R = TypeVar("R", bound="DataRows")


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


def _skew(v: np.ndarray) -> np.ndarray:
    """Return the cross-product matrices of vectors v (N, 3), shape (N, 3, 3)."""
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


def nest_rows(nest: np.ndarray, n_loc: int) -> sp.csr_matrix:
    """Return d(residual)/d(nest offset): -1 on the rows of each sample's nest and coordinate.

    Shape (3N, n_loc) for ``nest`` the nest of every sample, shape (N,) (-1: none). Built in CSR
    directly (one entry a row, in row order; 32-bit indices when they fit, as scipy's conversion
    from coordinates chooses): the same matrix without the coordinates' 64-bit row and column
    arrays and their conversion (250 MB at 1.6M samples).
    """
    n = len(nest)
    has = nest >= 0
    index = np.int32 if max(3 * n, n_loc) < 2 ** 31 - 1 else np.int64
    indptr = np.zeros(3 * n + 1, dtype=index)
    np.cumsum(np.repeat(has, 3), out=indptr[1:])
    cols = 3 * nest[has].astype(index)[:, None] + np.arange(3, dtype=index)
    data = np.full(cols.size, -1.0)
    return sp.csr_matrix((data, cols.ravel(), indptr), shape=(3 * n, n_loc))


class DataRows:
    """The data, prior and length rows of a problem, at full vectors (see module doc).

    Args:
        unknowns: the layout of the arm unknowns (free entries, start values).
        q: readouts, shape (N, n_axes), rad.
        measured: measured points, shape (N, 3), m: sphere centres in the MT-CS (or the main
            frame), or points in their instrument frame (see ``nuisance.frame``).
        nuisance: nest offsets, instrument frames and length rows (:class:`Nuisance`).
        sigma: noise per coordinate assumed by the solve, m (weights the nests' prior rows).
        weight: per sample, ``sigma / (its stated noise)``, shape (N,); None: all 1 (generalised
            least squares with per-sample noise: the data rows are multiplied by it).

    A campaign whose data Jacobian would exceed
    :data:`~aacmm_pin.fit.chunked_jacobian.CHUNKED_BYTES` is :attr:`chunked`: its data Jacobian is
    a :class:`~aacmm_pin.fit.chunked_jacobian.ChunkedJacobian` (products chunk by chunk, never
    held whole).
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
    chunked: bool
    """Whether the data Jacobian is taken chunk by chunk (a large campaign, see the class doc)."""

    def __init__(self, unknowns: Unknowns, q: np.ndarray, measured: np.ndarray,
                 nuisance: Nuisance, sigma: float, weight: np.ndarray | None = None):
        self.unknowns, self.q, self.measured = unknowns, q, measured
        self.nuisance = nuisance
        n = len(q)
        self.n_arm = int(unknowns.free.sum())
        self.n_loc = 3 * nuisance.n_nests
        self.n_frame = 6 * nuisance.n_frames
        self.nest = (sp.csr_matrix((3 * n, 0)) if nuisance.nest is None
                     else nest_rows(nuisance.nest, self.n_loc))
        self._nest_raw = self.nest
        self.row_weight = None if weight is None else np.repeat(np.asarray(weight, float), 3)
        if self.row_weight is not None:
            self.nest = sp.csr_matrix(sp.diags(self.row_weight) @ self.nest)
        self.sigma_class = sigma
        self.nest_sigma = np.repeat(np.asarray(nuisance.nest_sigma, dtype=float), 3)
        self.prior = sigma / self.nest_sigma
        self._length_ref = self._nest_reference()
        self.chunked = is_chunked(unknowns, n)

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
        rows = DataRows(unknowns, q, measured, nuisance, sigma, weight)
        return rows.nuisance_jacobian(x), rows.residual_at(x)

    def _nest_reference(self) -> np.ndarray:
        """Return every nest's reference position (the mean measured point of its samples), (n, 3)."""
        nz = self.nuisance
        if nz.nest is None or not nz.lengths.size:
            return np.zeros((nz.n_nests, 3))
        return np.array([self.measured[nz.nest == j].mean(axis=0) for j in range(nz.n_nests)])

    # ------------------------------------------------------------ sizes
    @property
    def n_data(self) -> int:
        """Number of data residuals (3 per sample); the nests' prior rows and the lengths follow."""
        return int(self.nest.shape[0])

    @property
    def n_lengths(self) -> int:
        """Number of length rows (the last rows of the residual)."""
        return int(self.nuisance.lengths.shape[0])

    def with_measured(self: R, measured: np.ndarray) -> R:
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

    def residual_at(self, x: np.ndarray) -> np.ndarray:
        """Return :meth:`fun` at the full vector x (no reduced coordinates needed)."""
        data = self.unknowns.positions(x[:self.n_arm], self.q).reshape(-1)
        data -= self.main_measured(x).reshape(-1)  # in place: a (3N,) vector less at a time
        if self.row_weight is not None:
            data *= self.row_weight
        x_loc = x[self.n_arm:self.n_arm + self.n_loc]
        tail = np.concatenate([self.prior * x_loc, self.length_residuals(x)])
        out = np.empty(data.size + tail.size)
        np.add(data, self.nest @ x_loc, out=out[:data.size])
        out[data.size:] = tail
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
