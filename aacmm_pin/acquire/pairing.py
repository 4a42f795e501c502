"""Pairing by time: each arm sample gets the gauge readings of its own time, or none.

All readings carry the host's monotonic clock at their arrival (a polled gauge: within its request
and its answer). An arm sample at time ``t`` is paired once every reading up to ``t + max_skew``
can have arrived: for each gauge channel the reading nearest to ``t`` is taken if it is within
``max_skew``; otherwise the sample is *unpaired* (counted, not written). Nearest, not
interpolated: a value that jumps between two readings is never blended into one that no device
reported.

A reading's arrival is known within an interval: a reader busy elsewhere (or starved of the CPU)
finds several lines waiting at once, which arrived at any time since its previous read. Each
reading carries that uncertainty ``u`` (its true arrival is within ``t +- u``), and a pair is made
only if the arrival times differ by ``max_skew`` at most whatever they are within their intervals:
``|t_arm - t_gauge| + u_arm + u_gauge <= max_skew``.

Close in time is not yet the same posture: an arm that moves between its sample and the reading
(in a SPAT, an operator changing posture) would pair a reading of one posture with the readouts of
another. So a pair is also checked against what the devices reported around it. Its *window* is
the time span in which both the arm sample and its readings may have arrived; the arm's readouts
and each channel's readings over the window (from the last value surely before it to the first
surely after it) must agree with the paired ones within ``steady_rad`` (any axis) and
``steady_m``. Otherwise the pair is *moving*: dropped and counted. The error of a pair made is
then bounded by these two tolerances whatever the timing within the intervals (a channel that
changes between two of its readings by more than the tolerance and back is not seen: the devices'
rates bound what can be checked). A pair waits for a value after its window on every stream, at
most :data:`HOLD` seconds; then (and at the end of a run) the values seen decide.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from typing import Generic, NamedTuple, TypeVar

HOLD = 0.25
"""Longest wait for a stream's first value after a pair's window, s."""

V = TypeVar("V")


class Pair(NamedTuple):
    """An arm sample with its gauge readings."""

    t: float
    """Arrival time of the arm sample, host monotonic clock, s."""
    q: list[float]
    """Encoder readouts, n values, rad."""
    readings: tuple[float, ...]
    """Readings of the gauge channels (in the Pairer's channel order), m."""
    u: float = 0.0
    """Half-width of the pair's window: how well the sample and its readings are timed, s."""


class _Stream(Generic[V]):
    """Values of one device in arrival order, each stamped ``t`` and arrived in ``[lo, hi]`` (s)."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.lo: list[float] = []
        self.hi: list[float] = []
        self.v: list[V] = []
        self.start = 0
        """Index of the first value held (older ones are dropped)."""

    def __len__(self) -> int:
        return len(self.t)

    def add(self, t: float, value: V, lo: float, hi: float) -> None:
        self.t.append(t)
        self.v.append(value)
        self.lo.append(lo)
        self.hi.append(hi)

    def nearest(self, t: float) -> int | None:
        """Return the index of the value nearest in time to ``t``, or None if none is held."""
        k = bisect.bisect_left(self.t, t, self.start)
        best = [i for i in (k - 1, k) if self.start <= i < len(self.t)]
        return min(best, key=lambda i: abs(self.t[i] - t), default=None)

    def around(self, i: int, lo: float, hi: float) -> tuple[list[V], bool]:
        """Return the values from the last surely before ``lo`` to the first surely after ``hi``.

        The value ``i`` is inside the span. Returns the values and whether the stream holds a
        value surely after ``hi`` yet (at its start it may hold nothing surely before ``lo``:
        nothing came before).
        """
        ends_at, starts_at = self.hi, self.lo
        j = i
        while j > self.start and ends_at[j] > lo:
            j -= 1
        k = i + 1
        while k < len(starts_at) and starts_at[k] < hi:
            k += 1
        return self.v[j:k + 1], k < len(starts_at)

    def trim(self, before: float) -> int:
        """Drop the values older than the last one surely arrived before ``before`` (s).

        Returns by how much the indices of the values held went down.
        """
        ends_at = self.hi
        while self.start + 1 < len(ends_at) and ends_at[self.start + 1] < before:
            self.start += 1
        if self.start <= 4096:
            return 0
        shift = self.start  # amortised: the lists do not grow with the run
        for a in (self.t, self.lo, self.hi, self.v):
            del a[:shift]
        self.start = 0
        return shift


class Pairer:
    """Pair arm samples with gauge readings by time, as they stream in.

    Args:
        channels: gauge channels to pair, e.g. (1, 2, 3).
        max_skew: largest accepted time difference between an arm sample and a reading, s.
        latency: time a reading may take from its arrival stamp to :meth:`add_gauge`, s.
        steady_rad: largest change of any readout over a pair's window, rad (None: not checked).
        steady_m: largest change of any channel's reading over a pair's window, m (None: not
            checked).
    """

    def __init__(self, channels: Sequence[int] = (1, 2, 3), max_skew: float = 0.01,
                 latency: float = 0.005, steady_rad: float | None = None,
                 steady_m: float | None = None):
        if max_skew <= 0:
            raise ValueError(f"max_skew: must be > 0 s, got {max_skew}")
        for name, tol in (("steady_rad", steady_rad), ("steady_m", steady_m)):
            if tol is not None and not tol >= 0:
                raise ValueError(f"{name}: must be >= 0, got {tol}")
        self.channels = tuple(channels)
        self.max_skew = float(max_skew)
        self.latency = float(latency)
        self.steady_rad = steady_rad
        self.steady_m = steady_m
        self._arm: _Stream[list[float]] = _Stream()
        self._next = 0  # index in self._arm of the next sample to pair
        self._gauge: dict[int, _Stream[float]] = {c: _Stream() for c in self.channels}
        self.unpaired = 0
        """Arm samples dropped for want of a reading within ``max_skew`` on some channel."""
        self.missing = dict.fromkeys(self.channels, 0)
        """Channel -> arm samples that lacked its reading."""
        self.moving = 0
        """Arm samples dropped because the arm or a reading changed within the pair's window."""
        self.paired = 0
        """Pairs made."""
        self.u_max = 0.0
        """Largest half-width of a pair's window over the pairs made, s."""

    @property
    def checks_steadiness(self) -> bool:
        """Whether pairs are checked against the values around them."""
        return self.steady_rad is not None or self.steady_m is not None

    def add_arm(self, t: float, q: list[float], u: float = 0.0,
                span: tuple[float, float] | None = None) -> None:
        """Add an arm sample with readouts ``q`` (rad) stamped ``t`` (s, nondecreasing).

        It arrived within ``t +- u``, or within ``span`` = (earliest, latest) if given (s).
        """
        lo, hi = span if span is not None else (t - u, t + u)
        self._arm.add(t, q, lo, hi)

    def add_gauge(self, channel: int, t: float, value: float, u: float = 0.0,
                  span: tuple[float, float] | None = None) -> None:
        """Add a reading of ``channel`` (m) stamped ``t`` (s, nondecreasing per channel).

        It arrived within ``t +- u``, or within ``span`` = (earliest, latest) if given (s).
        """
        stream = self._gauge.get(channel)
        if stream is not None:
            lo, hi = span if span is not None else (t - u, t + u)
            stream.add(t, value, lo, hi)

    def _readings(self, i: int) -> list[int | None]:
        """Return per channel the index of the reading nearest arm sample ``i``.

        None where its arrival and the sample's may lie more than ``max_skew`` apart.
        """
        arm = self._arm
        t, lo, hi = arm.t[i], arm.lo[i], arm.hi[i]
        out: list[int | None] = []
        for c in self.channels:
            stream = self._gauge[c]
            k = stream.nearest(t)
            if k is not None and max(hi - stream.lo[k], stream.hi[k] - lo) > self.max_skew:
                k = None
            out.append(k)
        return out

    def _window(self, i: int, found: list[int]) -> tuple[float, float]:
        """Return the time span in which arm sample ``i`` and its readings ``found`` arrived (s)."""
        arm = self._arm
        lo, hi = arm.lo[i], arm.hi[i]
        for c, k in zip(self.channels, found):
            lo, hi = min(lo, self._gauge[c].lo[k]), max(hi, self._gauge[c].hi[k])
        return lo, hi

    def _steady(self, i: int, found: list[int], final: bool) -> bool | None:
        """Whether the values around the pair of arm sample ``i`` agree with it.

        None: no change seen yet, but a stream has no value after the window yet (unless
        ``final``: then what was seen decides).
        """
        arm = self._arm
        lo, hi = self._window(i, found)
        known = True
        if self.steady_rad is not None:
            values, ends = arm.around(i, lo, hi)
            q = arm.v[i]
            if any(abs(a - b) > self.steady_rad for v in values for a, b in zip(v, q)):
                return False
            known = ends
        if self.steady_m is not None:
            for c, k in zip(self.channels, found):
                stream = self._gauge[c]
                values_g, ends = stream.around(k, lo, hi)
                if any(abs(v - stream.v[k]) > self.steady_m for v in values_g):
                    return False
                known = known and ends
        return True if known or final else None

    def pop(self, now: float = math.inf) -> list[Pair]:
        """Return the pairs of the arm samples older than ``now - max_skew - latency``.

        Args:
            now: current time of the same clock, s; ``inf`` pairs every sample held (at the end).
        """
        out: list[Pair] = []
        ready = now - self.max_skew - self.latency
        arm, final = self._arm, math.isinf(now)
        while self._next < len(arm) and arm.t[self._next] <= ready:
            i = self._next
            t = arm.t[i]
            found = self._readings(i)
            if any(k is None for k in found):
                self.unpaired += 1
                for c, k in zip(self.channels, found):
                    self.missing[c] += k is None
                self._next += 1
                continue
            ks = [k for k in found if k is not None]
            steady = self._steady(i, ks, final or now - t > self.max_skew + self.latency + HOLD) \
                if self.checks_steadiness else True
            if steady is None:
                break  # a stream has no value after the window yet: wait for it
            self._next += 1
            if not steady:
                self.moving += 1
                continue
            lo, hi = self._window(i, ks)
            half = (hi - lo) / 2
            self.u_max = max(self.u_max, half)
            self.paired += 1
            out.append(Pair(t, arm.v[i], tuple(self._gauge[c].v[k] for c, k in zip(self.channels, ks)),
                            half))
        self._trim(ready)
        return out

    def _trim(self, ready: float) -> None:
        """Drop what no later pair can need (bounded memory while a device is silent)."""
        arm = self._arm
        # every later window starts after t_next - max_skew (a pair's intervals lie within
        # max_skew of its arm sample); later arm samples arrive after the latest one, or after
        # `ready` if none is held
        pending = self._next < len(arm)
        t_next = arm.t[self._next] if pending else min(arm.t[-1], ready) if len(arm) else ready
        cutoff = t_next - self.max_skew
        self._next -= arm.trim(cutoff)
        for stream in self._gauge.values():
            stream.trim(cutoff)
