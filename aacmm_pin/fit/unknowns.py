"""The unknowns of an identification: layout of the parameter vector, residuals and Jacobian.

Vector layout (paper Eq. 5-6, with the reference-sample differencing replaced by an unknown
translation): ``[alpha0, beta0, gamma0, mt_x, mt_y, mt_z, <error frames>, tool_x, tool_y, tool_z,
<extension terms' parameters>, <free nodes of map 1>, <free nodes of map 2>, ...]``; an arm with
several tools has each tool's three entries instead of ``tool_x, tool_y, tool_z`` (``tool_left_x``
..., :attr:`aacmm_pin.model.arm.Arm.tool_unknowns`). Any entry can be
held fixed at its start value. Extension terms come from the effect library
(:mod:`aacmm_pin.effects`); ``samples`` gives what they depend on for the identification's readouts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import NamedTuple, TypeAlias, cast

import numpy as np
import scipy.sparse as sp

from aacmm_pin.effects.base import Term
from aacmm_pin.effects.calibrated import needs_tilts, stylus_jacobians, stylus_positions
from aacmm_pin.effects.contract import check_once
from aacmm_pin.effects.forward import measurement_shift
from aacmm_pin.fit.jacobian_cache import LAST_JACOBIAN
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.encoder_map import EncoderMap, node_angles
from aacmm_pin.model.kinematics import StylusJacobians, identification_configuration, tool_rows
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples

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

    def with_samples(self, samples: Samples) -> Unknowns:
        """Return the same layout for other readouts: its terms read ``samples``' columns.

        E.g. a length bar's readouts with their ``temp_c`` (:meth:`Samples.of_log`), whose
        :meth:`jacobian` at ``samples.q`` a term that reads a per-sample column needs.
        """
        return Unknowns(self.arm, self.start, self.map_axes, self.free, self.terms, samples)

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
        return list(self._full_keys)

    @cached_property
    def _full_keys(self) -> tuple[UnknownKey, ...]:
        """:attr:`full_keys`, made once (a fit asks for them tens of times)."""
        keys: list[UnknownKey] = [*BASE_NAMES, *self.arm.error_names, *self.arm.tool_unknowns]
        keys += [n for t in self.terms for n in t.names]
        for a in self.map_axes:
            keys += [NodeKey.at(a, d) for d in np.degrees(node_angles(self.start.step_deg))]
        return tuple(keys)

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
            tool=tool[0], tools=tools, encoder_maps=maps, extensions=extensions,
            extension_terms={**self.start.extension_terms, **{t.key: t for t in self.terms}})

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
        check_once(self.terms, samples, params)  # columns vs forward change, once per process
        cols = [t.columns(samples, jac, params) for t in self.terms]
        return np.concatenate(cols, axis=2) if cols else np.zeros((q.shape[0], 3, 0))

    # ------------------------------------------------------------ model
    def positions(self, x: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Return predicted MT-CS stylus centres for readouts q (N, n_axes), shape (N, 3), m."""
        params = self.parameters(x)
        n = q.shape[0]
        if n > BUILD_CHUNK and self.chain_only(params):
            # a large campaign's chunk by chunk: the configurations (8 nq bytes per sample)
            # exist for one chunk only (every sample's arithmetic is that of one call)
            tools = tool_rows(self.arm, n, None, self._samples(q))
            out = np.empty((n, 3))
            for lo in range(0, n, BUILD_CHUNK):
                hi = min(n, lo + BUILD_CHUNK)
                out[lo:hi] = stylus_positions(self.arm, params, q[lo:hi], frame="mt",
                                              tool=tools[lo:hi])
            return out
        pos = stylus_positions(self.arm, params, q, frame="mt", samples=self._samples(q))
        return pos + self.measurement_shift(params, q) if self.terms else pos

    def _chain_blocks(self, params: Parameters, q: np.ndarray, lo: int = 0, hi: int | None = None,
                      work: dict[str, np.ndarray] | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return positions, free non-map columns and map axes' angle columns, without terms.

        Shapes (N, 3), (3N, k) and (n_map_axes, N, 3): the dense block is kept, the maps' angle
        columns only read (each axis' block contiguous, so the node columns keep it without a
        copy). Built :data:`BUILD_CHUNK` samples at a time into the results: the configurations
        (8 ``nq`` bytes per sample) and the chain's blocks exist for one chunk only, and every
        sample's columns are those of a single call (the chain works sample by sample).
        ``lo:hi``: the samples of q to take (default all; N = hi - lo). ``work``: buffers kept
        from an earlier call (filled in and returned, overwritten by the next call), for chunks of
        one size taken over and over (:meth:`jacobian_rows`).
        """
        ident = self.arm.identification
        fids = np.asarray(ident.tool_frames)[tool_rows(self.arm, q.shape[0], None,
                                                       self._samples(q))][lo:hi]
        q = q[lo:hi]
        n = q.shape[0]
        order = np.concatenate([ident.base_idx[[4, 3, 5]], ident.base_idx[:3], ident.error_idx,
                                ident.tool_idx])[self.free[:self.n_dense]]
        maps = ident.axis_idx[[a - 1 for a in self.map_axes]]
        pos = _buffer(work, "pos", (n, 3))
        dense = _buffer(work, "dense", (n, 3, order.size))
        angles = _buffer(work, "angles", (maps.size, n, 3))
        for lo in range(0, n, BUILD_CHUNK):
            hi = min(n, lo + BUILD_CHUNK)
            config = identification_configuration(self.arm, params, q[lo:hi], "mt")
            extra = ident.chain.jacobian_blocks(config, fids[lo:hi], order, maps,
                                                out=(pos[lo:hi], dense[lo:hi]))[2]
            angles[:, lo:hi] = extra.transpose(2, 0, 1)
        return pos, dense.reshape(3 * n, -1), angles

    def _general_blocks(self, params: Parameters, q: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :meth:`_chain_blocks` (in one piece), through :func:`stylus_jacobians` (terms)."""
        jac = stylus_jacobians(self.arm, params, q, frame="mt", samples=self._samples(q),
                               tilts=needs_tilts(self.terms))
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
        angles = jac.angles[:, :, [a - 1 for a in self.map_axes]].transpose(2, 0, 1)
        return jac.position, dense.reshape(3 * n, -1), angles

    def jacobian(self, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, BlockJacobian]:
        """Return predicted positions (N, 3) and d(positions)/d(free entries) as blocks.

        Rows are sample-major (row 3 i + k is coordinate k of sample i). The process' last result
        is kept (:data:`~aacmm_pin.fit.jacobian_cache.LAST_JACOBIAN`, released before the next
        is built).
        """
        return cast(tuple[np.ndarray, BlockJacobian], LAST_JACOBIAN.get(self, x, q, self._jacobian))

    def _jacobian(self, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, BlockJacobian]:
        """Return :meth:`jacobian`'s result, built."""
        params = self.parameters(x)
        if not self.chain_only(params):
            position, dense, angles = self._general_blocks(params, q)
        else:  # straight from the chain into one array: no per-block copies
            position, dense, angles = self._chain_blocks(params, q)
        if self.terms:
            position = position + self.measurement_shift(params, q)
        return position, self._with_nodes(params, q, dense, angles)

    def _with_nodes(self, params: Parameters, q: np.ndarray, dense: np.ndarray,
                    angles: np.ndarray) -> BlockJacobian:
        """Return the Jacobian of readouts q from its dense block and the maps' angle columns."""
        # map nodes: d(p)/d(node) = d(p)/d(angle) * interpolation weight, free nodes only
        axes, at = [], 0
        for k, a in enumerate(self.map_axes):
            keep = self.free[self.map_slice(a)]
            axes.append(AxisNodes.build(params.map(a), q[:, a - 1], angles[k], keep, at))
            at += int(keep.sum())
        return BlockJacobian(dense, tuple(axes), at)

    def chain_only(self, params: Parameters | None = None) -> bool:
        """Whether the Jacobian comes from the chain alone (no terms, no extensions' values)."""
        params = self.start if params is None else params
        return not (self.terms or params.extensions)

    def jacobian_rows(self, x: np.ndarray, q: np.ndarray, lo: int, hi: int,
                      work: dict[str, np.ndarray] | None = None
                      ) -> tuple[np.ndarray, BlockJacobian]:
        """Return :meth:`jacobian`'s positions and Jacobian for the samples ``lo:hi`` of q only.

        Shapes (hi - lo, 3) and (3 (hi - lo), n_free); the same values as those rows of
        :meth:`jacobian` (not cached). Only for a layout whose Jacobian comes from the chain alone
        (:meth:`chain_only`): the chunked products of a large campaign
        (:class:`aacmm_pin.fit.chunked_jacobian.ChunkedJacobian`). ``work``: the caller's
        buffers (a dict, empty at first): the results live in them until the next call.
        """
        params = self.parameters(x)
        if not self.chain_only(params):
            raise ValueError("jacobian_rows: only for a layout without terms or extensions")
        position, dense, angles = self._chain_blocks(params, q, lo, hi, work)
        return position, self._with_nodes(params, q[lo:hi], dense, angles)


def _buffer(work: dict[str, np.ndarray] | None, name: str, shape: tuple[int, ...]) -> np.ndarray:
    """Return an array of this shape (C order) over ``work[name]``'s storage, if large enough.

    Else a new array (its storage kept there, if ``work``): a campaign's last, shorter chunk
    uses the front of the buffers, which the next pass's full chunks find as they were.
    """
    if work is None:
        return np.empty(shape)
    size = int(np.prod(shape))
    if name not in work or work[name].size < size:
        work[name] = np.empty(size)
    return work[name][:size].reshape(shape)


CHUNK = 16384
"""Samples per block in the products over samples (keeps their temporaries in cache)."""
BUILD_CHUNK = 65536
"""Samples per block when the chain's Jacobian is built (:meth:`Unknowns._chain_blocks`): a
multiple of the chain's own block, so that every sample's arithmetic is that of one call."""


class AxisNodes(NamedTuple):
    """The map-node columns of one axis, per sample: two nodes, their weights and d(p)/d(angle).

    Column ``offset + col[i, s]`` of the node block has the entries ``weight[i, s] * d[i, k]`` on
    rows ``3 i + k``: the axis column times the interpolation weight (a held node or a zero
    weight has weight 0).
    """

    col: np.ndarray
    """Column of the lower and upper node within this axis' free nodes, shape (N, 2)."""
    weight: np.ndarray
    """Interpolation weight of each (0 where the node is held), shape (N, 2)."""
    d: np.ndarray
    """d(point)/d(true angle of the axis), rows weighted as the Jacobian's, shape (N, 3)."""
    offset: int
    """First column of this axis in the node block."""
    size: int
    """Number of this axis' columns (its free nodes)."""

    @classmethod
    def build(cls, emap: EncoderMap, readout: np.ndarray, d_angle: np.ndarray, keep: np.ndarray,
              offset: int) -> AxisNodes:
        """Return the columns of the free nodes ``keep`` (mask) of ``emap`` at these readouts."""
        keep = np.asarray(keep, dtype=bool)
        column = np.cumsum(keep) - 1
        lower, upper, frac = emap.neighbours(readout)
        node = np.column_stack([lower, upper])
        held = ~keep[node]
        weight = np.column_stack([1.0 - frac, frac])
        weight[held] = 0.0
        col = column[node]
        col[held] = 0
        return cls(col, weight, np.ascontiguousarray(d_angle, dtype=float), offset, int(keep.sum()))

    def transposed_weights(self) -> sp.csr_matrix:
        """Return W^T, shape (size, N): ``W^T @ s`` sums s (N, ...) onto the columns."""
        n = self.col.shape[0]
        return sp.csr_matrix((self.weight.ravel(), (self.col.ravel(), np.repeat(np.arange(n), 2))),
                             shape=(self.size, n))


@dataclass(frozen=True)
class BlockJacobian:
    """Jacobian w.r.t. the free entries, as two blocks (columns in this order).

    A dense block (X0, translation, DH, tool) and the map nodes, kept per axis and sample
    (:class:`AxisNodes`: two entries per sample, axis and coordinate); their products and the
    normal matrix are computed from that structure, the sparse matrix only when asked
    (:attr:`nodes`).
    """

    dense: np.ndarray
    """d(positions)/d(non-map entries), shape (3N, n_dense)."""
    axes: tuple[AxisNodes, ...]
    """The map-node columns, one entry per map axis."""
    n_nodes: int
    """Number of node columns."""
    _normal: list[np.ndarray] = field(default_factory=list, init=False, repr=False, compare=False)
    """J^T J once computed (:meth:`normal`)."""
    _csc: list[sp.csc_matrix] = field(default_factory=list, init=False, repr=False, compare=False)

    @property
    def shape(self) -> tuple[int, int]:
        """(3N, n_free)."""
        return self.dense.shape[0], self.dense.shape[1] + self.n_nodes

    @property
    def nodes(self) -> sp.csc_matrix:
        """d(positions)/d(map nodes) as a sparse matrix, shape (3N, n_nodes) (built once)."""
        if not self._csc:
            rows, cols, vals = [], [], []
            for ax in self.axes:
                n = ax.col.shape[0]
                v = ax.weight[:, :, None] * ax.d[:, None, :]                    # (N, 2, 3)
                keep = v.reshape(-1) != 0.0
                rows.append(np.broadcast_to(3 * np.arange(n)[:, None, None] + np.arange(3),
                                            (n, 2, 3)).reshape(-1)[keep])
                cols.append(np.repeat(ax.col.reshape(-1) + ax.offset, 3)[keep])
                vals.append(v.reshape(-1)[keep])
            cat = (lambda a: np.concatenate(a)) if self.axes else (lambda a: np.zeros(0))
            self._csc.append(sp.csc_matrix((cat(vals), (cat(rows).astype(np.int64),
                                                        cat(cols).astype(np.int64))),
                                           shape=(self.dense.shape[0], self.n_nodes)))
        return self._csc[0]

    def sparse(self) -> sp.csr_matrix:
        """Return the whole Jacobian as one sparse matrix (for small campaigns and tests)."""
        return sp.csr_matrix(sp.hstack([sp.csr_matrix(self.dense), self.nodes]))

    def node_rmatmul(self, u: np.ndarray | sp.spmatrix | sp.sparray) -> np.ndarray:
        """Return (node block)^T @ u for u of shape (3N, k), shape (n_nodes, k).

        A sparse u (the nests' and frames' columns) is made dense one block of rows at a time,
        never whole (a dense copy costs 24 k bytes per sample).
        """
        out = np.zeros((self.n_nodes, u.shape[1]))
        if not self.axes or not u.shape[1]:
            return out
        n, k = u.shape[0] // 3, u.shape[1]
        if sp.issparse(u):
            rows = sp.csr_matrix(u)

            def block(lo: int) -> np.ndarray:
                dense: np.ndarray = rows[3 * lo:3 * (lo + CHUNK)].toarray().reshape(-1, 3, k)
                return dense
        else:
            u3 = np.asarray(u).reshape(-1, 3, k)

            def block(lo: int) -> np.ndarray:
                return u3[lo:lo + CHUNK]
        for ax in self.axes:
            s = np.empty((n, k))
            for lo in range(0, n, CHUNK):
                s[lo:lo + CHUNK] = np.einsum("ik,ikj->ij", ax.d[lo:lo + CHUNK], block(lo))
            out[ax.offset:ax.offset + ax.size] = ax.transposed_weights() @ s
        return out

    def cross(self, u: sp.spmatrix | sp.sparray) -> np.ndarray:
        """Return J^T @ u for a sparse u of shape (3N, k) (the nests' and frames' columns), (n_free, k)."""
        out: np.ndarray = np.vstack([np.asarray(u.T @ self.dense).T, self.node_rmatmul(u)])
        return out

    def normal(self) -> np.ndarray:
        """Return J^T J, shape (n_free, n_free), from the blocks (no dense 3N x n matrix).

        The node-node part from the per-sample structure: samples touch two nodes per axis.
        Computed once per Jacobian (the identifiability analysis and the solver both ask for it).
        """
        if self._normal:
            cached: np.ndarray = self._normal[0].copy()
            return cached
        nd = self.dense.shape[1]
        out = np.zeros((self.shape[1], self.shape[1]))
        out[:nd, :nd] = self.dense.T @ self.dense
        cross = self.node_rmatmul(self.dense)
        out[nd:, :nd] = cross
        out[:nd, nd:] = cross.T
        out[nd:, nd:] = node_normal(self)
        self._normal.append(out)
        fresh: np.ndarray = out.copy()
        return fresh

    def scaled(self, row_weight: np.ndarray, in_place: bool = False) -> BlockJacobian:
        """Return diag(row_weight) @ J (row_weight shape (3N,)).

        ``in_place``: its dense block is this one's, scaled (no copy of the largest block).
        """
        w3 = row_weight.reshape(-1, 3)
        if in_place:
            np.multiply(self.dense, row_weight[:, None], out=self.dense)
        return BlockJacobian(self.dense if in_place else self.dense * row_weight[:, None],
                             tuple(ax._replace(d=ax.d * w3) for ax in self.axes), self.n_nodes)

    def matmul(self, m: np.ndarray) -> np.ndarray:
        """Return J @ m for m of shape (n_free,) or (n_free, k)."""
        nd = self.dense.shape[1]
        out: np.ndarray = self.dense @ m[:nd]
        if m.ndim == 1:
            flat3 = out.reshape(-1, 3)
            for ax in self.axes:
                v = m[nd + ax.offset:nd + ax.offset + ax.size]
                g = ax.weight[:, 0] * v[ax.col[:, 0]]
                g += ax.weight[:, 1] * v[ax.col[:, 1]]
                flat3 += ax.d * g[:, None]
            return out
        out3 = out.reshape(-1, 3, m.shape[1])
        for ax in self.axes:
            v = m[nd + ax.offset:nd + ax.offset + ax.size]
            g = ax.weight[:, :1] * v[ax.col[:, 0]] + ax.weight[:, 1:] * v[ax.col[:, 1]]  # (N, k)
            out3 += ax.d[:, :, None] * g[:, None, :]
        return out

    def rmatmul(self, u: np.ndarray) -> np.ndarray:
        """Return J^T @ u for u of shape (3N,)."""
        u3 = u.reshape(-1, 3)
        nodes = np.zeros(self.n_nodes)
        for ax in self.axes:
            s = ax.d[:, 0] * u3[:, 0]
            s += ax.d[:, 1] * u3[:, 1]
            s += ax.d[:, 2] * u3[:, 2]
            nodes[ax.offset:ax.offset + ax.size] = (
                np.bincount(ax.col[:, 0], ax.weight[:, 0] * s, minlength=ax.size)
                + np.bincount(ax.col[:, 1], ax.weight[:, 1] * s, minlength=ax.size))
        return np.concatenate([self.dense.T @ u, nodes])

    def columns_sum(self, cols: np.ndarray) -> np.ndarray:
        """Return the sum of the given columns (free-vector indices), shape (3N,)."""
        nd = self.dense.shape[1]
        out: np.ndarray = self.dense[:, cols[cols < nd]].sum(axis=1)
        node_cols = cols[cols >= nd] - nd
        if node_cols.size:
            sel = np.zeros(self.n_nodes)
            sel[node_cols] = 1.0
            out = out + self.matmul(np.concatenate([np.zeros(nd), sel]))
        return out


def node_normal(jac: BlockJacobian) -> np.ndarray:
    """Return the node-node block of J^T J, shape (n_nodes, n_nodes), from the per-sample structure.

    Samples touch two nodes per axis: entry (a's node, b's node) sums ``w_a w_b (d_a . d_b)``.
    """
    out = np.zeros((jac.n_nodes, jac.n_nodes))
    for i, a in enumerate(jac.axes):
        for b in jac.axes[i:]:
            g = np.einsum("ik,ik->i", a.d, b.d)
            flat = np.zeros(a.size * b.size)
            for s in range(2):
                for t in range(2):
                    flat += np.bincount(a.col[:, s] * b.size + b.col[:, t],
                                         a.weight[:, s] * b.weight[:, t] * g,
                                         minlength=a.size * b.size)
            block = flat.reshape(a.size, b.size)
            out[a.offset:a.offset + a.size, b.offset:b.offset + b.size] = block
            if b is not a:
                out[b.offset:b.offset + b.size, a.offset:a.offset + a.size] = block.T
    return out
