"""Pairing by time: each arm sample gets the gauge readings nearest to it in time.

All readings carry the host's monotonic clock at their arrival (a polled gauge: the middle of its
request and its answer). An arm sample at time ``t`` is paired once every reading up to
``t + max_skew`` can have arrived: for each gauge channel the reading nearest to ``t`` is taken if
it is within ``max_skew``; otherwise the sample is *unpaired* (counted, not written). Nearest, not
interpolated: a value that jumps between two readings is never blended into one that no device
reported.

A reading's arrival is known within an interval: a reader busy elsewhere (or starved of the CPU)
finds several lines waiting at once, which arrived at any time since its previous read. Each
reading carries that uncertainty ``u`` (its true arrival is within ``t +- u``), and a pair is made
only if the arrival times differ by ``max_skew`` at most whatever they are within their intervals:
``|t_arm - t_gauge| + u_arm + u_gauge <= max_skew``. Under load, samples whose timing is unknown
are counted unpaired instead of being paired with a reading of another posture.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from typing import NamedTuple


class Pair(NamedTuple):
    """An arm sample with its gauge readings."""

    t: float
    """Arrival time of the arm sample, host monotonic clock, s."""
    q: list[float]
    """Encoder readouts, n values, rad."""
    readings: tuple[float, ...]
    """Readings of the gauge channels (in the Pairer's channel order), m."""


class Pairer:
    """Pair arm samples with gauge readings by time, as they stream in.

    Args:
        channels: gauge channels to pair, e.g. (1, 2, 3).
        max_skew: largest accepted time difference between an arm sample and a reading, s.
        latency: time a reading may take from its arrival stamp to :meth:`add_gauge`, s.
    """

    def __init__(self, channels: Sequence[int] = (1, 2, 3), max_skew: float = 0.01,
                 latency: float = 0.005):
        if max_skew <= 0:
            raise ValueError(f"max_skew: must be > 0 s, got {max_skew}")
        self.channels = tuple(channels)
        self.max_skew = float(max_skew)
        self.latency = float(latency)
        self._arm: deque[tuple[float, list[float], float]] = deque()
        self._gauge: dict[int, deque[tuple[float, float, float]]] = {c: deque()
                                                                      for c in self.channels}
        self.unpaired = 0
        """Arm samples dropped for want of a reading within ``max_skew`` on some channel."""
        self.missing = dict.fromkeys(self.channels, 0)
        """Channel -> arm samples that lacked its reading."""

    def add_arm(self, t: float, q: list[float], u: float = 0.0) -> None:
        """Add an arm sample arrived at ``t`` +- ``u`` (s, t nondecreasing) with readouts ``q`` (rad)."""
        self._arm.append((t, q, u))

    def add_gauge(self, channel: int, t: float, value: float, u: float = 0.0) -> None:
        """Add a reading of ``channel`` (m) arrived at ``t`` +- ``u`` (s, t nondecreasing per channel)."""
        buf = self._gauge.get(channel)
        if buf is not None:
            buf.append((t, value, u))

    def _nearest(self, channel: int, t: float, u: float) -> float | None:
        """Return the reading of ``channel`` nearest to ``t`` if surely within max_skew of it.

        ``u`` is the arm sample's time uncertainty; readings older than the nearest are dropped.
        """
        buf = self._gauge[channel]
        while len(buf) >= 2 and buf[1][0] <= t:
            buf.popleft()  # a later reading is still at or before t: this one is never nearest
        # buf[0] is the last reading at or before t (or the first after), buf[1] the first after.
        candidates = [buf[k] for k in range(min(2, len(buf)))]
        best = min(candidates, key=lambda r: abs(r[0] - t), default=None)
        if best is None or abs(best[0] - t) + u + best[2] > self.max_skew:
            return None
        return best[1]

    def pop(self, now: float = math.inf) -> list[Pair]:
        """Return the pairs of the arm samples older than ``now - max_skew - latency``.

        Args:
            now: current time of the same clock, s; ``inf`` pairs every sample held (at the end).
        """
        out: list[Pair] = []
        ready = now - self.max_skew - self.latency
        while self._arm and self._arm[0][0] <= ready:
            t, q, u = self._arm.popleft()
            values = [self._nearest(c, t, u) for c in self.channels]
            if any(v is None for v in values):
                self.unpaired += 1
                for c, v in zip(self.channels, values):
                    self.missing[c] += v is None
                continue
            out.append(Pair(t, q, tuple(v for v in values if v is not None)))
        cutoff = (self._arm[0][0] if self._arm else ready) - self.max_skew
        for buf in self._gauge.values():  # bounded memory while the arm is silent
            while len(buf) >= 2 and buf[1][0] < cutoff:
                buf.popleft()
        return out
