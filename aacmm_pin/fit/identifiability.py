"""What SPAT data can and cannot determine, found from the Jacobian, and the rules that handle it.

Three kinds of direction are not seen by SPATs; each is detected from the Jacobian and handled by a
stated rule, and every one is listed in the report:

1. **Unvisited map nodes** (no readout of any posture falls next to them): their Jacobian columns
   are zero. Rule: held at zero.
2. **Gauge directions**: a constant added to a map is indistinguishable from other parameters
   (the axis offset ``dth``, ``gamma0`` for A1, the tool vector for A7, a DH combination for A2).
   Detected per axis by regressing the map's constant column on the other columns of the Jacobian;
   where it lies in their span (relative residual < 1e-6), the rule is: the map has zero mean over
   its free nodes (a hard constraint) and the constant is carried by the other parameters.
3. **Undetermined directions** (e.g. the A7 map when the stylus sits on the A7 axis, or an axis
   offset that map shapes can imitate): with every column scaled by a plausible size of its
   parameter (the arm's :class:`aacmm_pin.model.sizes.Sizes`), the singular value of a direction is how
   far a change of that size moves the data (m, norm over all samples). Rule: a direction whose
   singular value is below ``2 sigma`` (sigma: the R-Test noise) is *not determined*; its
   component is held at the start value by a constraint row (truncated SVD). A parameter or node
   is *identifiable* when more than half of its scaled unit vector lies in the determined subspace.

Where the Jacobian is taken: :func:`aacmm_pin.identify` decides all three at the start values,
then checks the held directions where one Gauss-Newton step of that constrained problem lands
(the residual is nearly linear in the errors: near the solution) and again at the solution. A
check that holds another number of directions (:func:`held_count`) decides them again there; one
that holds as many keeps the start's. So a direction that only the start makes degenerate is
judged as at the solution before the solve: the nominal tool sits on the A7 axis, where a
direction mixing dth60 with dx76 and one mixing a76 with dy76 move nothing, while with the
identified tool 75 um off the axis 160,000 samples determine them (3.2 and 3.3 sigma where the
step lands and at the solution).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from aacmm_pin.fit.chunked_jacobian import ChunkedJacobian, DataJacobian
from aacmm_pin.fit.unknowns import NodeKey, Unknowns
from aacmm_pin.model.encoder_map import touched_nodes

GAUGE_TOL = 1e-6
GAUGE_WEIGHT = 1e3
"""Weight of a gauge or hold row, m per unit: 1e-9 of violation costs as much as 1 um of data."""
QR_ROWS = 30_000
"""Rows per block of the blocked QR in :func:`gauge_axes` (a few MB each)."""
DETERMINED_K = 2.0
"""A direction is determined when a plausible change along it moves the data by >= K sigma."""


def plausible_sizes(unknowns: Unknowns) -> np.ndarray:
    """Return the plausible size of every entry of the full layout (rad or m), the arm's sizes."""
    arm = unknowns.arm
    sizes = arm.sizes
    out = [sizes.x0_angle] * 3 + [sizes.x0_translation] * 3
    out += [sizes.dh_angle if f.is_angle else sizes.dh_length for f in arm.error_frames]
    out += [sizes.tool] * (3 * arm.n_tools)
    out += [float(v) for t in unknowns.terms for v in t.sizes(sizes)]
    n_nodes = unknowns.free.size - len(out)
    return np.array(out + [sizes.map_node] * n_nodes)


def plausible_groups(unknowns: Unknowns) -> list[str]:
    """Return the sizes-file group of every entry of the full layout (as :func:`plausible_sizes`).

    ``x0_angle``, ``x0_translation``, ``dh_angle``, ``dh_length``, ``tool``, ``effects.<name>`` for
    the terms' parameters and ``map_node``: the entries that share one size of the arm.
    """
    out = ["x0_angle"] * 3 + ["x0_translation"] * 3
    out += ["dh_angle" if f.is_angle else "dh_length" for f in unknowns.arm.error_frames]
    out += ["tool"] * (3 * unknowns.arm.n_tools)
    out += [f"effects.{t.effect}" for t in unknowns.terms for _ in t.names]
    return out + ["map_node"] * (unknowns.free.size - len(out))


def unvisited_nodes(unknowns: Unknowns, q: np.ndarray) -> np.ndarray:
    """Return a full-layout mask of the map nodes that no readout touches."""
    mask = np.zeros(unknowns.free.size, dtype=bool)
    touched = touched_nodes(q, unknowns.start.step_deg)
    for axis in unknowns.map_axes:
        mask[unknowns.map_slice(axis)] = ~touched[axis - 1]
    return mask


def gauge_axes(unknowns: Unknowns, jac: DataJacobian) -> list[int]:
    """Return the map axes whose constant lies in the span of the non-map columns.

    Args:
        unknowns: the layout (its free mask must match ``jac``'s columns).
        jac: data Jacobian w.r.t. the free entries, shape (3N, n_free).
    """
    full_cols = np.flatnonzero(unknowns.free)
    axes, col_sets = [], []
    for axis in unknowns.map_axes:
        sl = unknowns.map_slice(axis)
        cols = np.flatnonzero((full_cols >= sl.start) & (full_cols < sl.stop))
        if cols.size:
            axes.append(axis)
            col_sets.append(cols)
    if not axes:
        return []
    # The least-squares fit of a constant column is its projection on the dense block's numerical
    # range (the singular vectors numpy's lstsq keeps, rcond=None). One QR of [dense | constants]
    # (R only) gives it without a tall factor: [dense | C] = Q [[R11, R12], [0, R22]], the dense
    # block's singular values and left vectors are R11's (u), and the residual of column j is
    # ||(I - u u^T) R12[:, j]||^2 + ||R22[:, j]||^2. R is taken by blocks of rows (the blocks'
    # R stacked and factored again): no copy of the tall matrix.
    nd = int(unknowns.free[:unknowns.n_dense].sum())
    blocks = list(_qr_blocks(jac, col_sets))
    r = _r_factor(np.vstack(blocks)) if len(blocks) > 1 else blocks[0]
    u, sv, _ = np.linalg.svd(r[:nd, :nd], full_matrices=False)
    rng = u[:, sv > (sv.max(initial=0.0) * np.finfo(float).eps * max(jac.shape[0], nd))]
    r12 = r[:nd, nd:]
    off = r12 - rng @ (rng.T @ r12)
    residual = np.sqrt(np.sum(off ** 2, axis=0) + np.sum(r[nd:, nd:] ** 2, axis=0))
    norm = np.linalg.norm(r[:, nd:], axis=0)  # = the constants' norms (Q is orthonormal)
    return [axis for axis, res, nrm in zip(axes, residual, norm)
            if nrm == 0.0 or res / nrm < GAUGE_TOL]


def _qr_blocks(jac: DataJacobian, col_sets: list[np.ndarray]) -> Iterator[np.ndarray]:
    """Yield R of ``[dense block | sums of the columns of each set]`` per block of QR_ROWS rows.

    A :class:`ChunkedJacobian` chunk by chunk (its J^T J and the products deferred by the fit
    kept from the same pass: the observability analysis and the first problem ask for them next).
    """
    if isinstance(jac, ChunkedJacobian):
        for _, _, part in jac.chunks(products=True):
            yield from _qr_blocks(part, col_sets)
        return
    dense = jac.dense
    constants = [jac.columns_sum(cols) for cols in col_sets]
    for i in range(0, dense.shape[0], QR_ROWS):
        yield _r_factor(np.column_stack([dense[i:i + QR_ROWS], *(c[i:i + QR_ROWS]
                                                                for c in constants)]))


def _r_factor(a: np.ndarray) -> np.ndarray:
    """Return R of the reduced QR factorisation of a, shape (min(m, n), n) (Q not formed)."""
    r: np.ndarray = np.asarray(np.linalg.qr(a, mode="r"))
    return r


def gauge_rows(unknowns: Unknowns, axes: list[int]) -> sp.csr_matrix:
    """Return one row per gauge axis: the mean of its free nodes x GAUGE_WEIGHT, (n_axes, n_free)."""
    full_cols = np.flatnonzero(unknowns.free)
    rows = []
    for axis in axes:
        sl = unknowns.map_slice(axis)
        sel = (full_cols >= sl.start) & (full_cols < sl.stop)
        rows.append(GAUGE_WEIGHT * sel / max(sel.sum(), 1))
    return sp.csr_matrix(np.array(rows).reshape(len(rows), full_cols.size))


@dataclass(frozen=True)
class Observability:
    """The determined and undetermined directions of an identification (free entries only)."""

    hold: np.ndarray
    """Undetermined directions as rows in the scaled free space, shape (n_hold, n_free)."""
    singular: np.ndarray
    """Singular value of each held direction, m."""
    identifiable: np.ndarray
    """Per free entry: more than half of it lies in the determined subspace, shape (n_free,)."""
    scale: np.ndarray
    """Plausible size of each free entry (the column scaling), shape (n_free,)."""

    def hold_rows(self) -> sp.csr_matrix:
        """Return constraint rows holding the undetermined components: ``rows @ (x - x0) = 0``."""
        return sp.csr_matrix(GAUGE_WEIGHT * self.hold / self.scale[None, :])


def observability(unknowns: Unknowns, jac: DataJacobian, extra: sp.csr_matrix, sigma: float
                  ) -> Observability:
    """Find the directions the data does not determine (truncated SVD of the scaled Jacobian).

    Args:
        unknowns: the layout (free mask matching the columns).
        jac: data Jacobian w.r.t. the free entries, shape (3N, n_free), m per unit.
        extra: other rows that determine directions (gauge rows), shape (k, n_free).
        sigma: noise per coordinate, m.
    """
    scale = plausible_sizes(unknowns)[unknowns.free]
    eigval, eigvec = np.linalg.eigh(_scaled_information(jac, extra, scale))
    singular = np.sqrt(np.clip(eigval, 0.0, None))
    held = singular < DETERMINED_K * sigma
    determined = eigvec[:, ~held]
    identifiable = np.sum(determined ** 2, axis=1) > 0.5
    return Observability(eigvec[:, held].T, singular[held], identifiable, scale)


def held_count(unknowns: Unknowns, jac: DataJacobian, extra: sp.csr_matrix, sigma: float) -> int:
    """Return how many directions :func:`observability` would hold (eigenvalues only, cheaper)."""
    scale = plausible_sizes(unknowns)[unknowns.free]
    eigval = np.linalg.eigvalsh(_scaled_information(jac, extra, scale))
    return int(np.sum(np.sqrt(np.clip(eigval, 0.0, None)) < DETERMINED_K * sigma))


def held_rank(constraints: sp.csr_matrix) -> int:
    """Return how many independent directions constraint rows hold (their rank; rows normalised).

    The gauge rows and the held directions may overlap (a map's constant held both ways, every
    direction held under a noise stated far too large): their count would overstate the directions
    held, down to fewer determined parameters than zero.

    Args:
        constraints: rows over the free arm entries, shape (k, n_free).
    """
    rows = constraints.toarray()
    if not rows.size:
        return 0
    norms = np.linalg.norm(rows, axis=1)
    return int(np.linalg.matrix_rank(rows[norms > 0] / norms[norms > 0, None]))


def _scaled_information(jac: DataJacobian, extra: sp.csr_matrix, scale: np.ndarray) -> np.ndarray:
    """Return (J^T J + extra^T extra) with rows and columns scaled by ``scale``, (n_free, n_free)."""
    out: np.ndarray = (jac.normal() + (extra.T @ extra).toarray()) * np.outer(scale, scale)
    return out


def describe(unknowns: Unknowns, unvisited: np.ndarray, obs: Observability) -> list[str]:
    """Return plain-language lines on what is not identifiable and how it was handled."""
    keys = unknowns.full_keys
    free_keys = [k for k, f in zip(keys, unknowns.free) if f]
    weak_keys = {k for k, ok in zip(free_keys, obs.identifiable) if not ok}
    lines = []
    for axis in unknowns.map_axes:
        sl = unknowns.map_slice(axis)
        nodes = np.degrees(unknowns.start.map(axis).nodes)
        held = unvisited[sl]
        if held.any():
            lines.append(f"A{axis} map: {held.sum()} of {held.size} nodes ({_ranges(nodes[held])} "
                         "deg) not identifiable: no posture visits them; held at zero")
        weak = np.array([k in weak_keys for k in keys[sl]], dtype=bool)
        if weak.any():
            lines.append(f"A{axis} map: {weak.sum()} of {weak.size} nodes ({_ranges(nodes[weak])} "
                         "deg) not identifiable: a plausible error there moves the stylus by less "
                         "than the noise in these postures; held near zero")
    for key in free_keys:
        if key in weak_keys and not isinstance(key, NodeKey):
            lines.append(f"{key}: not identifiable from these measurements (other parameters can imitate "
                         "it in these postures); held near its start value")
    groups: dict[str, int] = {}
    labels = [f"A{key.axis} map" if isinstance(key, NodeKey) else str(key) for key in free_keys]
    names = list(dict.fromkeys(labels))  # the groups in order of first appearance
    position = {g: i for i, g in enumerate(names)}
    index = np.array([position[g] for g in labels], dtype=np.intp)
    for row in obs.hold:
        mix = ", ".join(_main_groups(names, index, row))
        groups[mix] = groups.get(mix, 0) + 1
    for mix, count in groups.items():
        lines.append(f"{count} undetermined direction{'s' if count > 1 else ''} mixing {mix}: "
                     "held at the start values (truncated SVD)")
    return lines


def _main_groups(names: list[str], index: np.ndarray, row: np.ndarray, share: float = 0.1
                 ) -> list[str]:
    """Return the parameter groups (a DH name or 'A<n> map') holding > share of a direction.

    ``names``: the groups; ``index``: each entry's group in ``names``, shape (n_free,); ``row``: the
    direction (unit), shape (n_free,). Largest share first (ties in the order of ``names``).
    """
    weight = np.bincount(index, row ** 2, minlength=len(names))
    return [names[g] for g in sorted(np.flatnonzero(weight > share), key=lambda g: -weight[g])]


def _ranges(values: np.ndarray) -> str:
    """Format sorted node angles as compact ranges, e.g. '-180..-105, 110..175'."""
    values = np.sort(values)
    step = np.min(np.diff(values)) if values.size > 1 else 0.0
    parts, start = [], values[0]
    for prev, cur in zip(values[:-1], values[1:]):
        if cur - prev > step + 1e-9:
            parts.append((start, prev))
            start = cur
    parts.append((start, values[-1]))
    return ", ".join(f"{a:g}" if a == b else f"{a:g}..{b:g}" for a, b in parts)


def equivalent_vector(unknowns: Unknowns, jac_full: sp.csr_matrix, constraints: sp.csr_matrix,
                      other: np.ndarray) -> tuple[np.ndarray, float]:
    """Return the parameters equivalent to ``other`` under an identification's rules.

    Among all vectors that keep the held entries at their start values and satisfy the
    identification's constraint rows (gauge and held directions, relative to the start), find the
    one whose predictions on the campaign's postures are closest (linearised) to those of ``other``.
    This is what an identification can return at best if ``other`` is the truth: compare an
    estimate with it, not with ``other`` itself.

    Args:
        unknowns: the final layout (free mask, start values).
        jac_full: data Jacobian w.r.t. every entry of the full layout, shape (3N, n_full).
        constraints: rows over the free entries, shape (k, n_free), that the estimate satisfies
            as ``rows @ (x_free - x0_free) = 0`` (gauges and held directions).
        other: a full-layout vector (e.g. the truth), shape (n_full,).

    Returns:
        ``(vector, rms)``: the equivalent full-layout vector and the RMS change of the predictions
        it implies (m): near zero where the difference lies in unseen directions only.
    """
    start = unknowns.full_vector(unknowns.start)
    held = ~unknowns.free
    delta_held = np.where(held, start - other, 0.0)
    rhs = -(jac_full @ delta_held)
    free_idx = np.flatnonzero(unknowns.free)
    a = jac_full[:, free_idx].toarray()
    rows = constraints.toarray()
    weight = 1e3 * np.abs(a).max() / max(np.abs(rows).max(), 1e-300)
    lhs = np.vstack([a, weight * rows])
    b = np.concatenate([rhs, weight * (rows @ (start[free_idx] - other[free_idx]))])
    colscale = np.maximum(np.linalg.norm(lhs, axis=0), 1e-300)
    delta_free = np.linalg.lstsq(lhs / colscale, b, rcond=None)[0] / colscale
    out = other + delta_held
    out[free_idx] += delta_free
    change = a @ delta_free - rhs
    return out, float(np.sqrt(np.mean(change ** 2)))
