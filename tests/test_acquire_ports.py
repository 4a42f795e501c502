"""The port reader against scripted ports: lines delivered in fragments, late, across timeouts.

A real serial port (and a pseudo-terminal under load) hands a line to the reader in pieces, and the
rest of a line may come after the reader's timeout. A :class:`ScriptedPort` releases fragments on
the reader's requests or on a timer, so the order of events is fixed whatever the machine's load:
a line must come out whole, exactly once, never as a garbled piece.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from typing import Any

import pytest
import serial

from aacmm_pin.acquire.ports import (
    READ_TIMEOUT,
    PortConfig,
    PortEvent,
    PortReader,
    arm_port,
    gauge_port,
)
from aacmm_pin.acquire.protocols import HEIDENHAIN_REQUEST, format_arm_line, format_heidenhain

TIMEOUT = 0.05
"""The readers' silence timeout here, s (a polled gauge is asked again after it)."""


class ScriptedPort:
    """A stand-in for a pyserial port: bytes become readable when the script releases them.

    Args:
        on_request: request number (1, 2, ...) -> bytes released when the reader writes it.
        late_writes: requests whose write raises pyserial's write timeout once it is done, as
            pyserial does when the writing thread was not run for ``write_timeout``.
    """

    def __init__(self, on_request: dict[int, bytes] | None = None,
                 late_writes: tuple[int, ...] = ()):
        self.on_request = on_request or {}
        self.late_writes = late_writes
        self.requests = 0
        self._data = bytearray()
        self._cond = threading.Condition()

    def feed(self, data: bytes) -> None:
        """Make ``data`` readable."""
        with self._cond:
            self._data += data
            self._cond.notify_all()

    @property
    def in_waiting(self) -> int:
        with self._cond:
            return len(self._data)

    def read(self, size: int = 1) -> bytes:
        """Return up to ``size`` readable bytes, waiting up to the reader's read timeout for one."""
        with self._cond:
            self._cond.wait_for(lambda: bool(self._data), timeout=READ_TIMEOUT)
            out = bytes(self._data[:size])
            del self._data[:size]
            return out

    def write(self, data: bytes) -> int:
        for _ in range(data.count(HEIDENHAIN_REQUEST)):
            self.requests += 1
            self.feed(self.on_request.get(self.requests, b""))
        if self.requests in self.late_writes:
            raise serial.SerialTimeoutException("Write timeout")
        return len(data)

    def close(self) -> None:
        pass


def read_events(config: PortConfig, port: ScriptedPort, until: Callable[[list[PortEvent]], bool],
                seconds: float = 3.0) -> list[PortEvent]:
    """Run a PortReader on ``port`` until ``until(events)`` holds (or ``seconds``); return its events."""
    out: queue.Queue[PortEvent] = queue.Queue()
    stop = threading.Event()
    reader = PortReader(config, out, stop, port)
    reader.start()
    events: list[PortEvent] = []
    deadline = time.monotonic() + seconds
    try:
        while not until(events) and time.monotonic() < deadline:
            try:
                events.append(out.get(timeout=0.01))
            except queue.Empty:
                pass
    finally:
        stop.set()
        reader.join(timeout=1.0)
    assert not reader.is_alive()
    while not out.empty():
        events.append(out.get_nowait())
    return events


def values(events: list[PortEvent]) -> list[Any]:
    return [value for what, _, _, payload in events if what == "data" for _, value, *_ in payload]


def faults(events: list[PortEvent]) -> list[str]:
    return [kind for what, _, kind, _ in events if what == "fault"]


REPLY = format_heidenhain(0.0100)  # b"+   0.0100 \r\n"


@pytest.mark.parametrize("fragments", [
    [b"+", REPLY[1:]],  # seen under load: the sign read at once, the rest after the timeout
    [REPLY[:3], REPLY[3:7], REPLY[7:-1], REPLY[-1:]],  # cut inside the value and the line end
], ids=["sign-then-rest", "four-pieces"])
def test_polled_reply_in_fragments_across_timeouts_is_one_good_line(fragments: list[bytes]) -> None:
    """A gauge reply whose pieces come only after the reader timed out and asked again: one line.

    Each fragment is released by one request, so each after a timeout of the previous one. The
    later requests' own replies are never sent: exactly one reading, 0.01 mm, no garbled line.
    """
    port = ScriptedPort(dict(enumerate(fragments, start=1)))
    config = gauge_port("heidenhain:1", "scripted", "heidenhain", 1, 1e-3, timeout=TIMEOUT)
    events = read_events(config, port, lambda ev: port.requests > len(fragments) + 1)
    assert port.requests > len(fragments)  # every fragment came after a timeout and a new request
    assert "garbled" not in faults(events), events
    assert values(events) == [(1, pytest.approx(1e-5, abs=1e-15))]


def test_streamed_line_in_fragments_across_timeouts_is_one_good_line() -> None:
    """An arm line in pieces with silences longer than the timeout between them: one line, once."""
    q = [10.0, -20.5, 30.25, 0.0, 45.0, -90.0, 179.999999]
    line = format_arm_line(7, q) + format_arm_line(8, q)
    cuts = [0, 1, 20, len(line) // 2 - 1, len(line) // 2 + 3, len(line) - 1, len(line)]
    port = ScriptedPort()

    def feed() -> None:
        for a, b in zip(cuts, cuts[1:]):
            port.feed(line[a:b])
            time.sleep(2 * TIMEOUT)  # each piece after the reader counted a silence

    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    events = read_events(arm_port("scripted", 7, timeout=TIMEOUT), port,
                         lambda ev: len(values(ev)) >= 2 and not feeder.is_alive())
    feeder.join(timeout=2.0)
    assert "timeout" in faults(events)  # the silences were seen ...
    assert "garbled" not in faults(events), events  # ... and cut no line
    assert [counter for counter, _ in values(events)] == [7, 8]


def test_write_timeout_of_a_sent_request_is_no_lost_port() -> None:
    """pyserial's write timeout after a request went out (a thread not run for 20 ms) loses nothing.

    The first two requests "time out" although sent; their replies come. The port is not closed and
    reopened (which drops its input): no port_lost fault, no reconnect, both readings.
    """
    port = ScriptedPort({1: REPLY, 2: REPLY}, late_writes=(1, 2))
    config = gauge_port("heidenhain:1", "scripted", "heidenhain", 1, 1e-3, timeout=TIMEOUT)
    events = read_events(config, port, lambda ev: len(values(ev)) >= 2)
    assert "port_lost" not in faults(events), events
    assert [e for e in events if e[0] in ("reconnect", "gone")] == []
    assert values(events) == [(1, pytest.approx(1e-5, abs=1e-15))] * 2


class HaltedWhileReading(ScriptedPort):
    """A streaming port whose bytes come while the reader waits for a first one, and the halt
    with them: the reader's read returns that byte and finds the run stopped."""

    def __init__(self, pending: bytes, stop: threading.Event):
        super().__init__()
        self.pending, self.stop = pending, stop

    def read(self, size: int = 1) -> bytes:
        if not self.pending:
            return super().read(size)
        first, rest, self.pending = self.pending[:1], self.pending[1:], b""
        self.feed(rest)
        self.stop.set()
        return first


def events_to_halt(port_class: type[HaltedWhileReading], pending: bytes) -> list[PortEvent]:
    """Run an arm port's reader on ``port_class(pending, stop)`` until it halts; its events."""
    out: queue.Queue[PortEvent] = queue.Queue()
    stop = threading.Event()
    reader = PortReader(arm_port("scripted", 6), out, stop, port_class(pending, stop))
    reader.start()
    reader.join(timeout=5.0)
    assert not reader.is_alive()
    events = []
    while not out.empty():
        events.append(out.get_nowait())
    return events


def test_lines_that_arrived_before_the_halt_are_read_not_dropped() -> None:
    """Halted with complete lines waiting in the port: every one comes out (nothing lost), the
    incomplete rest does not."""
    sent = [format_arm_line(k, [10.0 * k] * 6) for k in range(3)]
    events = events_to_halt(HaltedWhileReading, b"".join(sent) + sent[0][:5])
    assert [counter for counter, _ in values(events)] == [0, 1, 2]
    assert faults(events) == []


class LostAtHalt(HaltedWhileReading):
    """A port that fails (unplugged) when the reader takes its last lines after the halt."""

    def __init__(self, pending: bytes, stop: threading.Event):
        super().__init__(pending, stop)
        self.asked = 0

    @property
    def in_waiting(self) -> int:
        self.asked += 1
        if self.stop.is_set() and self.asked > 2:  # the final read's question
            raise serial.SerialException("device reports readiness to read but returned no data")
        return 0


def test_a_port_lost_at_the_last_read_is_a_counted_fault() -> None:
    """The port fails as the halted reader takes its waiting lines: a port_lost fault, no crash."""
    events = events_to_halt(LostAtHalt, b"$")
    assert faults(events) == ["port_lost"] and values(events) == []
