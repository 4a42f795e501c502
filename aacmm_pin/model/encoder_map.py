r"""Encoder error look-up tables: the angular position measurement error of one rotary axis.

Paper Section 2.2: the error :math:`\Delta\theta_{n,map}(i_n)` is tabulated at nominal readouts
:math:`\theta^*_{n,map}(i_n) = -180^\circ, -180^\circ + s, \ldots, 180^\circ - s` (step *s*, default
5 deg, periodic) and linearly interpolated; the model uses :math:`\theta^*_n + \Delta\theta_n(\theta^*_n)`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from aacmm_pin.errors import ArgumentError

if TYPE_CHECKING:  # sparse matrices are made where an identification asks for them
    import scipy.sparse as sp

TWO_PI = 2.0 * np.pi
DEFAULT_STEP_DEG = 5.0


MAX_MAP_NODES = 720
"""Most nodes of one encoder map (a step of 0.5 deg). Each node is an unknown of the fit, and its
covariance and Jacobian grow with their number: 7 maps of 720 nodes hold 5,040 unknowns (a 203 MB
covariance); a step of 0.01 deg, 36,000 nodes a map, had run 8.5 min into 5.5 GB, then MemoryError."""


def step_problem(step_deg: float) -> str | None:
    """Return why ``step_deg`` cannot be a map's node step (None if it can), in one line."""
    if not step_deg > 0 or not np.isfinite(step_deg):
        return f"must be a finite number > 0 that divides 360 deg, got {step_deg}"
    n = 360.0 / step_deg
    if abs(n - round(n)) > 1e-9:
        return f"must divide 360 deg, got {step_deg}"
    if round(n) > MAX_MAP_NODES:
        unknowns = 7 * round(n)
        return (f"{step_deg:g} deg gives {round(n):,} nodes a map, at most {MAX_MAP_NODES:,} "
                f"(a step of {360 / MAX_MAP_NODES:g} deg or more): 7 such maps would be "
                f"{unknowns:,} unknowns, their covariance alone {unknowns ** 2 * 8 / 1e9:,.1f} GB")
    return None


def node_count(step_deg: float) -> int:
    """Return the number of nodes of a periodic table with this step (360 / step, an integer).

    Raises:
        ArgumentError: if ``step_deg`` does not divide 360 deg, or gives more than
            :data:`MAX_MAP_NODES` nodes.
    """
    if (why := step_problem(step_deg)) is not None:
        raise ArgumentError(f"step_deg: {why}")
    return int(round(360.0 / step_deg))


def node_angles(step_deg: float = DEFAULT_STEP_DEG) -> np.ndarray:
    """Return the nominal readouts of the nodes, shape (360/step,), in rad, from -pi upwards."""
    angles: np.ndarray = np.radians(-180.0 + step_deg * np.arange(node_count(step_deg)))
    return angles


@dataclass(frozen=True, eq=False)
class EncoderMap:
    """Look-up table of one axis' angular position measurement error.

    Equality compares the step and the values exactly (arrays compared element-wise).
    """

    values: np.ndarray
    """Error at the nodes, shape (360/step,), in rad; node k sits at readout -180 deg + k*step."""
    step_deg: float = DEFAULT_STEP_DEG
    """Node spacing in degrees; must divide 360."""
    nodes: np.ndarray = field(init=False, repr=False)
    """Nominal readouts of the nodes, shape (360/step,), in rad (derived)."""

    def __post_init__(self) -> None:
        values = np.asarray(self.values, dtype=float).reshape(-1).copy()
        n = node_count(self.step_deg)
        if values.shape != (n,):
            raise ValueError(
                f"values: a map with step {self.step_deg} deg needs {n} nodes, got {values.size}"
            )
        if not np.all(np.isfinite(values)):
            raise ValueError("values: encoder map values must be finite")
        values.setflags(write=False)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "nodes", node_angles(self.step_deg))

    @classmethod
    def zero(cls, step_deg: float = DEFAULT_STEP_DEG) -> EncoderMap:
        """Return a map with zero error everywhere."""
        return cls(np.zeros(node_count(step_deg)), step_deg)

    @property
    def n_nodes(self) -> int:
        """Number of nodes."""
        return int(self.values.size)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, EncoderMap):
            return NotImplemented
        return self.step_deg == other.step_deg and bool(np.array_equal(self.values, other.values))

    __hash__ = None  # type: ignore[assignment]

    def neighbours(self, readout: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the two nodes bracketing each readout and the weight of the upper one.

        Args:
            readout: encoder readouts, any shape, in rad (any turn: the table is periodic).

        Returns:
            ``(lower, upper, frac)``: node indices (int arrays, same shape as ``readout``) and the
            interpolation fraction in [0, 1), so that the error is
            ``(1 - frac) * values[lower] + frac * values[upper]``.
        """
        u = np.mod(np.asarray(readout, dtype=float) + np.pi, TWO_PI) / np.radians(self.step_deg)
        lower = np.floor(u)
        frac = u - lower
        lower = lower.astype(np.int64) % self.n_nodes  # mod guards u == n after rounding
        return lower, (lower + 1) % self.n_nodes, frac

    def __call__(self, readout: np.ndarray) -> np.ndarray:
        """Return the interpolated error at the readouts, same shape, in rad."""
        lower, upper, frac = self.neighbours(readout)
        error: np.ndarray = (1.0 - frac) * self.values[lower] + frac * self.values[upper]
        return error

    def slope(self, readout: np.ndarray) -> np.ndarray:
        """Return d(error)/d(readout) (dimensionless), the slope of the segment holding each readout."""
        lower, upper, _ = self.neighbours(readout)
        slope: np.ndarray = (self.values[upper] - self.values[lower]) / np.radians(self.step_deg)
        return slope

    def weights(self, readout: np.ndarray) -> sp.csr_matrix:
        """Return the interpolation weights W, shape (N, n_nodes), so that ``W @ values`` = error.

        W is also d(error at readout i)/d(node value k): the Jacobian with respect to the nodes.

        Args:
            readout: encoder readouts, shape (N,), in rad.
        """
        import scipy.sparse as sp

        readout = np.asarray(readout, dtype=float).reshape(-1)
        lower, upper, frac = self.neighbours(readout)
        rows = np.repeat(np.arange(readout.size), 2)
        cols = np.column_stack([lower, upper]).reshape(-1)
        data = np.column_stack([1.0 - frac, frac]).reshape(-1)
        return sp.csr_matrix((data, (rows, cols)), shape=(readout.size, self.n_nodes))

    def node_columns(self, readout: np.ndarray, d_angle: np.ndarray,
                     nodes: np.ndarray | None = None) -> sp.csc_matrix:
        """Return d(points)/d(node values) by the chain rule: d(point)/d(angle) x weight.

        The one builder of map-node columns (identification, discovery, tests).

        Args:
            readout: encoder readouts of this axis, shape (N,), rad.
            d_angle: d(point)/d(true angle of this axis) at each readout, shape (N, 3).
            nodes: which nodes are columns (mask, shape (n_nodes,)); default: all.

        Returns:
            Sparse, shape (3N, n_columns), rows sample-major (row ``3 i + k`` is coordinate k of
            point i), at most two entries per point and coordinate (none where a weight is 0).
        """
        import scipy.sparse as sp

        readout = np.asarray(readout, dtype=float).reshape(-1)
        keep_nodes = np.ones(self.n_nodes, dtype=bool) if nodes is None else np.asarray(nodes, bool)
        n_cols = int(keep_nodes.sum())
        column = np.cumsum(keep_nodes) - 1
        lower, upper, frac = self.neighbours(readout)
        node = np.column_stack([lower, upper])                          # (N, 2)
        weight = np.column_stack([1.0 - frac, frac])
        keep = np.repeat((keep_nodes[node] & (weight != 0.0)).reshape(-1), 3)
        # entries in row order (sample, lower/upper, coordinate): a stable sort by column keeps
        # each column's rows ascending, so the CSC arrays are built directly (no COO pass)
        cols = np.repeat(column[node].reshape(-1), 3)[keep]
        rows = np.broadcast_to(3 * np.arange(readout.size)[:, None, None] + np.arange(3),
                               (readout.size, 2, 3)).reshape(-1)[keep]
        vals = (weight[:, :, None] * np.asarray(d_angle, dtype=float)[:, None, :]).reshape(-1)[keep]
        order = np.argsort(cols.astype(np.int16 if n_cols < 2 ** 15 else np.int64), kind="stable")
        indptr = np.concatenate([[0], np.cumsum(np.bincount(cols, minlength=n_cols))])
        out = sp.csc_matrix((vals[order], rows[order].astype(np.int32), indptr.astype(np.int32)),
                            shape=(3 * readout.size, n_cols))
        out.has_sorted_indices = True
        return out

    def correct(self, readout: np.ndarray) -> np.ndarray:
        """Return the angle the model uses, readout + error(readout), same shape, in rad."""
        readout = np.asarray(readout, dtype=float)
        angle: np.ndarray = readout + self(readout)
        return angle

    @cached_property
    def invertible(self) -> bool:
        """Whether :meth:`correct` rises on every segment (slope of the error above -1).

        A map of physical errors (arcseconds over a few degrees) always is; a map that is not
        would give two readouts for one angle.
        """
        return bool(np.all(self._slopes > 0.0))

    @cached_property
    def _slopes(self) -> np.ndarray:
        """d(corrected angle)/d(readout) on each segment, shape (n_nodes,)."""
        slopes: np.ndarray = 1.0 + np.diff(self.values, append=self.values[:1]) / np.radians(
            self.step_deg)
        return slopes

    @cached_property
    def breakpoints(self) -> np.ndarray:
        """The corrected angle at the nodes over one turn, shape (n_nodes + 1,), rad.

        Node 0 .. node n (node 0 + 2 pi): :meth:`correct` maps segment k onto
        ``breakpoints[k] .. breakpoints[k + 1]``.
        """
        out: np.ndarray = (np.append(self.nodes, self.nodes[0] + TWO_PI)
                           + np.append(self.values, self.values[0]))
        return out

    def inverse(self, angle: np.ndarray) -> np.ndarray:
        r"""Return the readouts whose corrected angle is ``angle``: the inverse of :meth:`correct`.

        :meth:`correct` is piecewise linear, :math:`r + e(r)`, node k of the table going to
        :math:`\theta^*_k + e_k` (:attr:`breakpoints`); each segment is inverted exactly (one
        division), so ``correct(inverse(a)) == a`` to rounding, at any turn.

        Args:
            angle: true joint angles, any shape, rad.

        Returns:
            Readouts, same shape, rad.

        Raises:
            ValueError: if the map is not invertible (:attr:`invertible`).
        """
        if not self.invertible:
            raise ValueError("encoder map: its corrected angle falls on some segment (an error "
                             "slope below -1); it has no inverse")
        angle = np.asarray(angle, dtype=float)
        breaks = self.breakpoints
        turns = np.floor((angle - breaks[0]) / TWO_PI)
        reduced = angle - TWO_PI * turns          # in [breaks[0], breaks[0] + 2 pi)
        k = np.clip(np.searchsorted(breaks, reduced, side="right") - 1, 0, self.n_nodes - 1)
        readout: np.ndarray = (self.nodes[k] + (reduced - breaks[k]) / self._slopes[k]
                               + TWO_PI * turns)
        return readout


def touched_nodes(q: np.ndarray, step_deg: float) -> np.ndarray:
    """Return which map nodes the readouts touch (interpolation weight > 0), shape (n_axes, nodes).

    Args:
        q: encoder readouts, shape (N, n_axes), rad.
        step_deg: map node step, deg.
    """
    emap = EncoderMap(np.zeros(node_count(step_deg)), step_deg)
    return np.array([np.asarray(abs(emap.weights(q[:, a])).sum(axis=0)).ravel() > 0
                     for a in range(q.shape[1])]).reshape(q.shape[1], emap.n_nodes)


def correct_readouts(q: np.ndarray, maps: dict[int, EncoderMap]) -> np.ndarray:
    """Wrap joint configurations: readouts in, corrected configuration out.

    Args:
        q: encoder readouts, shape (N, n_axes) or (n_axes,), in rad.
        maps: axis number (1-based) -> map; axes without a map have zero error.

    Returns:
        The corrected angles, same shape as ``q``, in rad.

    Raises:
        ArgumentError: for a ``q`` without a column for every mapped axis, or not finite.
    """
    q = _checked(q, maps, "q")
    out: np.ndarray = q.copy()
    for axis, emap in maps.items():
        out[..., axis - 1] = emap.correct(q[..., axis - 1])
    return out


def _checked(values: np.ndarray, maps: dict[int, EncoderMap], name: str) -> np.ndarray:
    """Return values as a float array whose last axis holds every mapped axis, all finite.

    Raises:
        ArgumentError: naming ``name``, in one line (a runtime check of the arm's own axis count,
            range and units is :class:`aacmm_pin.CalibratedArm`'s).
    """
    try:
        out = np.array(values, dtype=float)
    except (TypeError, ValueError):
        raise ArgumentError(f"{name}: need numbers in rad, got {type(values).__name__}") from None
    top = max(maps, default=0)
    if out.ndim not in (1, 2) or out.shape[-1] < top:
        raise ArgumentError(f"{name}: need shape (n_axes,) or (N, n_axes) with the maps' axes "
                            f"1..{top} among the columns, in rad; got shape {out.shape}")
    if not np.isfinite(out).all():
        raise ArgumentError(f"{name}: every value must be a finite number in rad (found "
                            f"{out[~np.isfinite(out)][0]})")
    return out


def readouts_of_angles(angles: np.ndarray, maps: dict[int, EncoderMap]) -> np.ndarray:
    """Return the readouts whose corrected angles are ``angles``: the inverse of :func:`correct_readouts`.

    For commanding an arm through its calibration (a target joint angle -> the readout to send).

    Args:
        angles: true joint angles, shape (N, n_axes) or (n_axes,), in rad.
        maps: axis number (1-based) -> map; axes without a map have zero error.

    Returns:
        The readouts, same shape as ``angles``, in rad (``correct_readouts`` of them gives
        ``angles`` back to rounding).

    Raises:
        ArgumentError: for ``angles`` without a column for every mapped axis, or not finite, or a
            map that is not invertible (:attr:`EncoderMap.invertible`), naming its axis.
    """
    angles = _checked(angles, maps, "angles")
    out: np.ndarray = angles.copy()
    for axis, emap in maps.items():
        if not emap.invertible:
            raise ArgumentError(f"maps: the map of A{axis} has no inverse (its corrected angle "
                                "falls on some segment: an error slope below -1)")
        out[..., axis - 1] = emap.inverse(angles[..., axis - 1])
    return out


def correct_with_slopes(q: np.ndarray, maps: dict[int, EncoderMap]) -> tuple[np.ndarray, np.ndarray]:
    """Return the corrected angles and d(angle)/d(readout) of every axis, each shape (N, n_axes).

    The same values as :func:`correct_readouts` and ``1 +`` :meth:`EncoderMap.slope`, all axes
    in one pass when the maps share one node step (the inverse kinematics calls this thousands of
    times on a few readouts).

    Args:
        q: encoder readouts, shape (N, n_axes), in rad.
        maps: axis number (1-based) -> map; axes without a map have zero error and slope 1.
    """
    q = np.array(q, dtype=float)
    slopes = np.ones_like(q)
    steps = {m.step_deg for m in maps.values()}
    if len(steps) != 1:
        for axis, emap in maps.items():
            slopes[:, axis - 1] += emap.slope(q[:, axis - 1])
        return correct_readouts(q, maps), slopes
    axes = np.array(sorted(maps)) - 1
    table = np.array([maps[a + 1].values for a in axes])  # (n_maps, n_nodes)
    lower, upper, frac = maps[axes[0] + 1].neighbours(q[:, axes])
    rows = np.arange(axes.size)
    low, up = table[rows, lower], table[rows, upper]
    out = q.copy()
    out[:, axes] = q[:, axes] + ((1.0 - frac) * low + frac * up)
    slopes[:, axes] += (up - low) / np.radians(steps.pop())
    return out, slopes

