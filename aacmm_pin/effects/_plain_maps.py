"""One sample's encoder maps in plain Python floats: the runtime object's single-sample path.

numpy spends about a microsecond on each operation whatever the size of its arrays, so on the
handful of values of one readout vector a loop over Python floats is several times faster than the
vectorised :class:`~aacmm_pin.model.encoder_map.EncoderMap` (``benchmarks/runtime.py``). The values
are the same to rounding: ``tests/test_calibrated_arm.py`` compares both on every path.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Callable

from aacmm_pin.model.encoder_map import EncoderMap

TWO_PI = 2.0 * math.pi


class PlainMaps:
    """Every axis' map (or none) and readout bounds, as lists of floats.

    Args:
        maps: axis number (1-based) -> map; axes without one have zero error.
        n_axes: number of axes.
        lower: per axis, the lowest value accepted, rad.
        upper: per axis, the highest value accepted, rad.
        refuse: called with the values and the argument's name when a value is out of bounds or
            not a number; it raises.
        slack: how far true angles (:meth:`inverse`) may pass the bounds, rad.
    """

    def __init__(self, maps: dict[int, EncoderMap], n_axes: int, lower: list[float],
                 upper: list[float], refuse: Callable[[list[float], str], None], slack: float = 0.0):
        self._refuse = refuse
        self._slack = slack
        self._axes: list[tuple[float, float, list[float] | None, float, list[float], list[float]]] = []
        for a in range(n_axes):
            emap = maps.get(a + 1)
            if emap is None:
                self._axes.append((lower[a], upper[a], None, 1.0, [], []))
                continue
            values = [*emap.values.tolist(), float(emap.values[0])]
            nodes = [*emap.nodes.tolist(), float(emap.nodes[0]) + TWO_PI]
            breaks = emap.breakpoints.tolist() if emap.invertible else []
            self._axes.append((lower[a], upper[a], values, math.radians(emap.step_deg), nodes,
                               breaks))

    def forward(self, q: list[float], name: str) -> tuple[list[float], list[float]]:
        """Return the corrected angles and d(angle)/d(readout) of one sample's readouts (rad)."""
        out, slopes = [], []
        for x, (lo, hi, values, step, _, _) in zip(q, self._axes):
            if not lo <= x <= hi:  # NaN too
                self._refuse(q, name)
            if values is None:
                out.append(x)
                slopes.append(1.0)
                continue
            u = ((x + math.pi) % TWO_PI) / step
            k = int(u)
            if k >= len(values) - 1:  # u == n after rounding: node 0 of the next turn
                k, u = 0, 0.0
            f = u - k
            out.append(x + values[k] * (1.0 - f) + values[k + 1] * f)
            slopes.append(1.0 + (values[k + 1] - values[k]) / step)
        return out, slopes

    def inverse(self, theta: list[float], name: str) -> list[float] | None:
        """Return the readouts of one sample's true angles (rad); None if a map has no inverse."""
        out = []
        slack = self._slack
        for x, (lo, hi, values, step, nodes, breaks) in zip(theta, self._axes):
            if not lo - slack <= x <= hi + slack:
                self._refuse(theta, name)
            if values is None:
                out.append(x)
                continue
            if not breaks:
                return None
            turns = math.floor((x - breaks[0]) / TWO_PI)
            reduced = x - TWO_PI * turns
            k = min(max(bisect_right(breaks, reduced) - 1, 0), len(values) - 2)
            slope = 1.0 + (values[k + 1] - values[k]) / step
            out.append(nodes[k] + (reduced - breaks[k]) / slope + TWO_PI * turns)
        return out
