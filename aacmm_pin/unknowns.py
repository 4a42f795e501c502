"""The unknowns of an identification: layout of the parameter vector, residuals and Jacobian.

Vector layout (paper Eq. 5-6, with the reference-sample differencing replaced by an unknown
translation): ``[alpha0, beta0, gamma0, mt_x, mt_y, mt_z, <error frames>, tool_x, tool_y, tool_z,
<extension terms' parameters>, <free nodes of map 1>, <free nodes of map 2>, ...]``; an arm with
several tools has each tool's three entries instead of ``tool_x, tool_y, tool_z`` (``tool_left_x``
..., :attr:`aacmm_pin.arm.Arm.tool_unknowns`). Any entry can be
held fixed at its start value. Extension terms come from the effect library
(:mod:`aacmm_pin.effects`); ``samples`` gives what they depend on for the identification's readouts.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field
from typing import NamedTuple, TypeAlias

import numpy as np
import scipy.sparse as sp

from aacmm_pin.arm import Arm
from aacmm_pin.effects import Term, measurement_shift, term_columns
from aacmm_pin.encoder_map import EncoderMap, node_angles
from aacmm_pin.kinematics import StylusJacobians, stylus_jacobians, stylus_positions
from aacmm_pin.parameters import Parameters
from aacmm_pin.samples import Samples

BASE_NAMES = ("alpha0", "beta0", "gamma0", "mt_x", "mt_y", "mt_z")
TOOL_NAMES = ("tool_x", "tool_y", "tool_z")
"""The tool entries of a single-tool arm (``Arm.tool_unknowns`` in general)."""


class NodeKey(NamedTuple):
    """One encoder map node among the unknowns; ``str()`` gives its name, e.g. ``map3[-175]``."""

    axis: int
    """Axis of the map, 1-based."""
    node_deg: float
    """Node angle, deg (rounded to 1e-9 deg, so that keys built from radians compare equal)."""

    @classmethod
    def at(cls, axis: int, node_deg: float) -> NodeKey:
        """Return the key of the node of ``axis`` at ``node_deg`` (deg)."""
        return cls(int(axis), round(float(node_deg), 9))

    def __str__(self) -> str:
        return f"map{self.axis}[{self.node_deg:g}]"


class NestKey(NamedTuple):
    """One coordinate of an R-Test nest's offset; ``str()`` gives its name, e.g. ``location2_dx``."""

    location: int
    """R-Test location (or the id of another nest, e.g. a length-bar socket)."""
    coordinate: str
    """``"x"``, ``"y"`` or ``"z"`` (MT-CS)."""
    label: str = ""
    """Name of a nest that is not an R-Test location, e.g. ``bar3A`` (placement 3, socket A)."""

    def __str__(self) -> str:
        return f"{self.label or f'location{self.location}'}_d{self.coordinate}"


class FrameKey(NamedTuple):
    """One of an instrument frame's six unknowns; ``str()`` gives its name, e.g. ``group2_rx``."""

    group: int
    """Instrument group (``group`` column of points.csv)."""
    component: str
    """``rx``, ``ry``, ``rz`` (rotation vector, rad) or ``tx``, ``ty``, ``tz`` (translation, m)."""

    def __str__(self) -> str:
        return f"group{self.group}_{self.component}"


UnknownKey: TypeAlias = "str | NodeKey | NestKey | FrameKey"
"""What an estimated entry is: a named parameter (``dx21``, ``tool_x``, a term's parameter), a
map node, a nest offset coordinate or an instrument frame's unknown. ``str(key)`` is its name in
files and reports."""


@dataclass(frozen=True)
class Unknowns:
    """Which parameters are estimated, and where each sits in the vector."""

    arm: Arm
    """The arm."""
    start: Parameters
    """Values at the start (and of every fixed entry)."""
    map_axes: tuple[int, ...]
    """Axes whose maps are estimated (empty for the DH-only model)."""
    free: np.ndarray
    """Mask over the full layout: True where the entry is estimated, shape (n_full,)."""
    terms: tuple[Term, ...] = ()
    """Extension terms (angle, scale or measurement kind) whose parameters are estimated."""
    samples: Samples | None = field(default=None, compare=False)
    """Temperature, motion and R-Test displacement of the identification's samples."""
    _cache: tuple[bytes, np.ndarray, tuple[np.ndarray, BlockJacobian]] | None = field(
        default=None, init=False, repr=False, compare=False)
    """The last Jacobian: (x bytes, the readouts array it was for, result)."""

    @classmethod
    def full(cls, arm: Arm, start: Parameters, map_axes: tuple[int, ...],
             terms: tuple[Term, ...] = (), samples: Samples | None = None) -> Unknowns:
        """Return the layout with every parameter and every node of ``map_axes`` free."""
        n = (6 + len(arm.error_names) + 3 * arm.n_tools + sum(len(t.names) for t in terms)
             + sum(start.map(a).n_nodes for a in map_axes))
        return cls(arm, start, tuple(map_axes), np.ones(n, dtype=bool), tuple(terms), samples)

    # ------------------------------------------------------------ names and slices
    @property
    def n_terms(self) -> int:
        """Number of extension parameters in the full layout."""
        return sum(len(t.names) for t in self.terms)

    @property
    def n_dense(self) -> int:
        """Number of non-map entries in the full layout (X0, translation, DH, tool, extensions)."""
        return 6 + len(self.arm.error_names) + 3 * self.arm.n_tools + self.n_terms

    def with_free(self, free: np.ndarray) -> Unknowns:
        """Return the same layout with another free mask."""
        return Unknowns(self.arm, self.start, self.map_axes, free, self.terms, self.samples)

    def map_slice(self, axis: int) -> slice:
        """Slice of one map's nodes in the full layout."""
        start = self.n_dense
        for a in self.map_axes:
            n = self.start.map(a).n_nodes
            if a == axis:
                return slice(start, start + n)
            start += n
        raise KeyError(axis)

    @property
    def full_keys(self) -> list[UnknownKey]:
        """Keys of every entry of the full layout."""
        keys: list[UnknownKey] = [*BASE_NAMES, *self.arm.error_names, *self.arm.tool_unknowns]
        keys += [n for t in self.terms for n in t.names]
        for a in self.map_axes:
            keys += [NodeKey.at(a, d) for d in np.degrees(node_angles(self.start.step_deg))]
        return keys

    @property
    def keys(self) -> list[UnknownKey]:
        """Keys of the free entries, in vector order."""
        return [k for k, f in zip(self.full_keys, self.free) if f]

    @property
    def full_names(self) -> list[str]:
        """Names of every entry of the full layout."""
        return [str(k) for k in self.full_keys]

    @property
    def names(self) -> list[str]:
        """Names of the free entries, in vector order."""
        return [str(k) for k in self.keys]

    def with_fixed(self, fixed: np.ndarray) -> Unknowns:
        """Return a layout in which the entries of the full-layout mask ``fixed`` are held."""
        return self.with_free(self.free & ~fixed)

    # ------------------------------------------------------------ vector <-> parameters
    def full_vector(self, params: Parameters) -> np.ndarray:
        """Return every entry of the full layout for these parameters."""
        parts = [params.rotation_abc, params.translation,
                 np.array([params.dh[n] for n in self.arm.error_names]),
                 *params.tool_vectors(self.arm).values()]
        parts += [params.extensions.get(t.key, np.zeros(len(t.names))) for t in self.terms]
        parts += [params.map(a).values for a in self.map_axes]
        return np.concatenate(parts)

    def vector(self, params: Parameters) -> np.ndarray:
        """Return the free entries for these parameters, shape (n_free,)."""
        free: np.ndarray = self.full_vector(params)[self.free]
        return free

    def parameters(self, x: np.ndarray) -> Parameters:
        """Return the parameters with the free entries set from ``x`` (others at start)."""
        full = self.full_vector(self.start)
        full[self.free] = x
        n_err, n_tool = len(self.arm.error_names), 3 * self.arm.n_tools
        maps = dict(self.start.encoder_maps)
        for a in self.map_axes:
            maps[a] = EncoderMap(full[self.map_slice(a)], self.start.step_deg)
        extensions = dict(self.start.extensions)
        at = 6 + n_err + n_tool
        for t in self.terms:
            extensions[t.key] = full[at:at + len(t.names)]
            at += len(t.names)
        tool = full[6 + n_err:6 + n_err + n_tool].reshape(-1, 3)
        tools = ({} if self.arm.n_tools == 1 and not self.start.tools
                 else dict(zip(self.arm.tool_joints, tool)))
        return self.start.replace(
            rotation_abc=full[0:3], translation=full[3:6],
            dh=dict(zip(self.arm.error_names, full[6:6 + n_err])),
            tool=tool[0], tools=tools, encoder_maps=maps, extensions=extensions)

    def _samples(self, q: np.ndarray) -> Samples | None:
        return self.samples if self.samples is not None and self.samples.matches(q) else None

    def measurement_shift(self, params: Parameters, q: np.ndarray) -> np.ndarray:
        """Return the measurement terms' change of the modelled point, shape (N, 3), m."""
        samples = self._samples(q)
        if samples is None:  # readouts other than the identification's: no measurement there
            return np.zeros((q.shape[0], 3))
        return measurement_shift(self.terms, params.extensions, samples)

    def term_columns(self, params: Parameters, q: np.ndarray, jac: StylusJacobians) -> np.ndarray:
        """Return d(model point)/d(extension parameters) at ``params``, shape (N, 3, n_terms).

        ``jac`` are the stylus Jacobians at ``params`` (:func:`stylus_jacobians`).
        """
        samples = self._samples(q) or Samples(self.arm, q)
        cols = [term_columns(t, samples, jac, params) for t in self.terms]
        return np.concatenate(cols, axis=2) if cols else np.zeros((q.shape[0], 3, 0))

    # ------------------------------------------------------------ model
    def positions(self, x: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Return predicted MT-CS stylus centres for readouts q (N, n_axes), shape (N, 3), m."""
        params = self.parameters(x)
        pos = stylus_positions(self.arm, params, q, frame="mt", samples=self._samples(q))
        return pos + self.measurement_shift(params, q) if self.terms else pos

    def jacobian(self, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, BlockJacobian]:
        """Return predicted positions (N, 3) and d(positions)/d(free entries) as blocks.

        Rows are sample-major (row 3 i + k is coordinate k of sample i). The last result is cached.
        """
        key = x.tobytes()
        cache = self._cache  # read once: other threads may replace it
        if cache is not None and cache[0] == key and cache[1] is q:
            return cache[2]
        _release_cached_jacobians()  # their memory is free for the new one
        params = self.parameters(x)
        jac = stylus_jacobians(self.arm, params, q, frame="mt", samples=self._samples(q))
        n = q.shape[0]
        free = self.free[:self.n_dense]
        dense: np.ndarray = np.empty((n, 3, int(free.sum())))  # the free columns, written once
        at = col = 0
        for part in (jac.rotation, jac.translation, jac.dh, jac.tool,
                     self.term_columns(params, q, jac)):
            sel = free[at:at + part.shape[2]]
            k = int(sel.sum())
            dense[:, :, col:col + k] = part if k == sel.size else part[:, :, sel]
            at, col = at + sel.size, col + k
        dense = dense.reshape(3 * n, -1)
        angles, position = jac.angles.copy(), jac.position
        del jac, part  # the whole stylus Jacobian, before the node columns are built
        # map nodes: d(p)/d(node) = d(p)/d(angle) * interpolation weight, free nodes only
        blocks = [params.map(a).node_columns(q[:, a - 1], angles[:, :, a - 1],
                                             self.free[self.map_slice(a)]) for a in self.map_axes]
        nodes = _hstack_csc(blocks, 3 * n)
        del blocks
        if self.terms:
            position = position + self.measurement_shift(params, q)
        out = (position, BlockJacobian(dense, nodes))
        object.__setattr__(self, "_cache", (key, q, out))  # holds q: its identity is the key
        _CACHED.append(weakref.ref(self))
        return out


_CACHED: list[weakref.ref[Unknowns]] = []
"""The layouts holding a cached Jacobian (a campaign's Jacobian can weigh hundreds of MB)."""


def _release_cached_jacobians() -> None:
    """Drop every layout's cached Jacobian (only one is kept in a process: the newest)."""
    while _CACHED:
        holder = _CACHED.pop()()
        if holder is not None:
            object.__setattr__(holder, "_cache", None)


def _hstack_csc(blocks: list[sp.csc_matrix], n_rows: int) -> sp.csc_matrix:
    """Return the CSC blocks side by side (their arrays concatenated, no conversion)."""
    if not blocks:
        return sp.csc_matrix((n_rows, 0))
    ends = np.cumsum([0] + [b.nnz for b in blocks])
    indptr = np.concatenate([[0], *(b.indptr[1:] + e for b, e in zip(blocks, ends))])
    index = np.int32 if ends[-1] < 2 ** 31 else np.int64
    out = sp.csc_matrix((np.concatenate([b.data for b in blocks]),
                         np.concatenate([b.indices for b in blocks]).astype(index),
                         indptr.astype(index)), shape=(n_rows, sum(b.shape[1] for b in blocks)))
    out.has_sorted_indices = all(b.has_sorted_indices for b in blocks)
    return out


@dataclass(frozen=True)
class BlockJacobian:
    """Jacobian w.r.t. the free entries, as two blocks (columns in this order).

    A dense block (X0, translation, DH, tool) and a sparse block (map nodes, two entries per sample
    and axis).
    """

    dense: np.ndarray
    """d(positions)/d(non-map entries), shape (3N, n_dense)."""
    nodes: sp.csc_matrix
    """d(positions)/d(map nodes), shape (3N, n_nodes)."""
    _normal: list[np.ndarray] = field(default_factory=list, init=False, repr=False, compare=False)
    """J^T J once computed (:meth:`normal`)."""

    @property
    def shape(self) -> tuple[int, int]:
        """(3N, n_free)."""
        return self.dense.shape[0], self.dense.shape[1] + self.nodes.shape[1]

    def sparse(self) -> sp.csr_matrix:
        """Return the whole Jacobian as one sparse matrix (for small campaigns and tests)."""
        return sp.csr_matrix(sp.hstack([sp.csr_matrix(self.dense), self.nodes]))

    def normal(self) -> np.ndarray:
        """Return J^T J, shape (n_free, n_free), from block products (no dense 3N x n matrix).

        Computed once per Jacobian (the identifiability analysis and the solver both ask for it).
        """
        if self._normal:
            cached: np.ndarray = self._normal[0].copy()
            return cached
        nd = self.dense.shape[1]
        out = np.empty((self.shape[1], self.shape[1]))
        out[:nd, :nd] = self.dense.T @ self.dense
        cross = np.asarray((self.nodes.T @ self.dense))
        out[nd:, :nd] = cross
        out[:nd, nd:] = cross.T
        out[nd:, nd:] = (self.nodes.T @ self.nodes).toarray()
        self._normal.append(out)
        fresh: np.ndarray = out.copy()
        return fresh

    def scaled(self, row_weight: np.ndarray) -> BlockJacobian:
        """Return diag(row_weight) @ J (row_weight shape (3N,))."""
        return BlockJacobian(self.dense * row_weight[:, None],
                             sp.csc_matrix(sp.diags(row_weight) @ self.nodes))

    def matmul(self, m: np.ndarray) -> np.ndarray:
        """Return J @ m for m of shape (n_free,) or (n_free, k)."""
        nd = self.dense.shape[1]
        out: np.ndarray = self.dense @ m[:nd] + self.nodes @ m[nd:]
        return out

    def rmatmul(self, u: np.ndarray) -> np.ndarray:
        """Return J^T @ u for u of shape (3N,)."""
        return np.concatenate([self.dense.T @ u, self.nodes.T @ u])

    def columns_sum(self, cols: np.ndarray) -> np.ndarray:
        """Return the sum of the given columns (free-vector indices), shape (3N,)."""
        nd = self.dense.shape[1]
        out: np.ndarray = self.dense[:, cols[cols < nd]].sum(axis=1)
        node_cols = cols[cols >= nd] - nd
        if node_cols.size:
            out = out + np.asarray(self.nodes[:, node_cols].sum(axis=1)).ravel()
        return out
