"""Serial port readers: one thread per port turns its lines into readings and faults.

A reader opens its port with pyserial (a device path or any ``serial_for_url`` URL), discards what
the port buffered before the run, splits the byte stream into lines, stamps each line with the
host's monotonic clock, parses it with its protocol and puts batches of results on a queue for the
acquisition loop. The lines of one read surely arrived, in order, in one interval: since the reader
last saw its input empty (and since the request of a polled device). Each line gets a time of its
own within it (:func:`spread_stamp`: the n lines of a read spread evenly, never one time for all)
and an uncertainty that covers the whole interval. A reader that falls behind its device under load
reads a backlog of lines of unknown age (measured: 4 KB chunks with 4 KB more waiting, lines
~0.2 s old stamped as new, paired with readings of a later posture); their uncertainty grows until
the backlog is drained, and the pairing (:mod:`aacmm_pin.acquire.pairing`) leaves them unpaired.

A line is complete only at its line end, however its bytes arrive: a real port delivers a line in
fragments, and under load the rest of a line may come after a timeout. Timeouts and new requests
never drop the bytes already read; only a port lost and reopened starts a new line. (Dropping them
at each request of a polled gauge cut a reply in two under load: the reader had read its sign, the
request timed out, the rest came as a garbled line.)

Faults are put on the same queue and never stop the reader:

* a bad line (garbled, checksum, out of range) is counted and dropped;
* a silence longer than ``timeout`` is counted once; a polled gauge is asked again;
* a write timeout of a request is no fault: its reply or the next timeout tells;
* a failing port (cable pulled, device gone) is counted and reopened every 0.1 s; after
  ``give_up`` seconds without a good line (silent or closed) the reader reports ``gone`` and ends.

Every reader ends within about 0.05 s of its ``stop`` event.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from aacmm_pin.acquire.faults import AcquisitionError, LineError
from aacmm_pin.acquire.protocols import parse_arm_line, parse_heidenhain, parse_mitutoyo
from aacmm_pin.extras import require

READ_TIMEOUT = 0.02
"""Longest blocking read, s: how soon a reader notices its stop event."""
MAX_LINE = 4096
"""Longest line kept, bytes; a longer run without a line end is one garbled line."""

Parser = Callable[[bytes], Any]
"""Parses one line (without its end) into a value, or raises LineError."""

PortEvent = tuple[str, str, str, Any]
"""What a :class:`PortReader` puts on its queue: (what, port name, kind, payload); the payload is the
list of (t, parsed value, earliest, latest) for ``"data"`` (stamped ``t``, arrived between the
earliest and the latest time, s), else a str (see
:class:`PortReader`)."""


@dataclass(frozen=True)
class PortConfig:
    """How to read one port."""

    name: str
    """Name in reports, e.g. ``arm`` or ``heidenhain:1``."""
    url: str
    """Device path or pyserial URL."""
    kind: str
    """``"arm"`` or ``"gauge"``: what the parsed values are."""
    parse: Parser
    """Line parser: arm -> (counter, q rad); gauge -> (channel, value m)."""
    request: bytes | None = None
    """Bytes sent to ask for each line (polled devices), or None (streaming)."""
    baudrate: int = 115200
    """Baud rate (ignored by pseudo-terminals)."""
    timeout: float = 0.5
    """Silence counted as a timeout, s."""
    give_up: float = 5.0
    """Silence (or closed port) after which the reader reports ``gone`` and ends, s."""
    poll_interval: float = 0.0
    """Least time between two requests of a polled device, s (0: as fast as it answers)."""


def arm_port(url: str, n_axes: int, fmt: str = "nmea", **kwargs: Any) -> PortConfig:
    """Return the configuration of the arm's port (format ``nmea`` or ``csv``)."""
    return PortConfig("arm", url, "arm", lambda line: parse_arm_line(line, n_axes, fmt), **kwargs)


def gauge_port(name: str, url: str, fmt: str, channel: int | None, range_m: float,
               request: bytes | None = None, **kwargs: Any) -> PortConfig:
    """Return the configuration of a gauge port (``heidenhain`` with its channel, or ``mitutoyo``)."""
    if fmt == "heidenhain":
        if channel is None:
            raise ValueError("channel: a heidenhain port carries one gauge channel (1-3)")

        def parse(line: bytes) -> tuple[int, float]:
            return channel, parse_heidenhain(line, range_m)

        return PortConfig(name, url, "gauge", parse, request or b"\x02", **kwargs)
    if fmt == "mitutoyo":
        def parse_m(line: bytes) -> tuple[int, float]:
            ch, value = parse_mitutoyo(line, range_m)
            if ch not in (1, 2, 3):
                raise LineError("garbled", line, f"channel {ch:02d} is not 01, 02 or 03")
            return ch, value

        return PortConfig(name, url, "gauge", parse_m, request, **kwargs)
    raise ValueError(f"fmt: choose heidenhain or mitutoyo, got {fmt!r}")


def spread_stamp(since: float, now: float, k: int, n: int) -> float:
    """Return the stamp of the ``k``-th of ``n`` lines read at once (s).

    The lines surely arrived between ``since`` and ``now``, in order: line ``k`` is stamped at the
    middle of the k-th of n equal parts of that interval, so that every line of a read has a time
    of its own; its arrival is known only within the whole interval.
    """
    return since + (k + 0.5) / n * (now - since)


def open_port(url: str, baudrate: int = 115200) -> Any:
    """Open a serial port (device path or pyserial URL) for line reading; drop its old input.

    Raises:
        MissingExtraError: if pyserial (the ``serial`` extra) is not installed.
        AcquisitionError: if the port cannot be opened.
    """
    require("serial", "acquire")
    import serial

    try:
        port = serial.serial_for_url(url, baudrate=baudrate, timeout=READ_TIMEOUT,
                                     write_timeout=READ_TIMEOUT)
        port.reset_input_buffer()
    except (serial.SerialException, OSError, ValueError) as exc:
        raise AcquisitionError(f"cannot open serial port {url}: {exc}") from None
    return port


class PortReader(threading.Thread):
    """Read one port in a daemon thread until ``stop`` is set or the port is gone.

    Puts on ``out``: ``("data", name, kind, [(t, value, earliest, latest), ...])`` for good lines
    (stamped ``t``, arrived between ``earliest`` and ``latest``),
    ``("fault", name, kind_of_fault, reason)`` for faults, ``("reconnect", name, "", url)`` and, last,
    ``("gone", name, "", reason)`` if the reader gave up. ``t`` is the host monotonic time, s.

    Args:
        config: the port.
        out: queue read by the acquisition loop.
        stop: set to end the reader.
        port: an already open port (else opened at start; :func:`open_port` raises if it cannot).
    """

    def __init__(self, config: PortConfig, out: queue.Queue[PortEvent], stop: threading.Event,
                 port: Any | None = None):
        super().__init__(name=f"aacmm-pin reader {config.name}", daemon=True)
        self.config = config
        self.out = out
        self.stop = stop
        self.port = port if port is not None else open_port(config.url, config.baudrate)

    def _emit(self, *event: Any) -> None:
        self.out.put(event)

    def _reopen(self, since: float) -> bool:
        """Reopen the port every 0.1 s until it opens (True) or give_up passed since ``since``."""
        cfg = self.config
        try:
            self.port.close()
        except Exception:  # noqa: BLE001 - a dead port may fail to close; it is dropped anyway
            pass
        while not self.stop.is_set() and time.monotonic() - since < cfg.give_up:
            try:
                self.port = open_port(cfg.url, cfg.baudrate)
            except AcquisitionError:
                self.stop.wait(0.1)
                continue
            self._emit("reconnect", cfg.name, "", cfg.url)
            return True
        return False

    def _ask(self) -> None:
        """Send the request of a polled device; a write timeout is no lost port.

        pyserial (3.5) raises its write timeout after a complete write when the thread was not run
        for ``write_timeout`` (0.02 s) between the start of the write and its end: under load the
        request was sent and its reply comes. (Measured at load 6: "Write timeout" in 1 of 8
        two-second recordings of the fake devices; the port was then closed and reopened, which
        dropped its input.) Sent or not, the reply or, for a request that did not go, the next
        timeout and request tell; a port that takes no request at all ends silent after
        ``give_up``.
        """
        import serial

        assert self.config.request is not None
        try:
            self.port.write(self.config.request)
        except serial.SerialTimeoutException:
            pass

    def run(self) -> None:
        """Read lines until stopped; see the class docstring for what is put on the queue."""
        import serial

        cfg = self.config
        buf = bytearray()
        last_good = t_request = t_asked = t_empty = time.monotonic()
        awaiting = False
        silent = False
        errors = (serial.SerialException, OSError)
        while not self.stop.is_set():
            now = time.monotonic()
            try:
                if cfg.request is not None and (not awaiting or now - t_request > cfg.timeout):
                    wait = cfg.poll_interval - (now - t_request)
                    if not awaiting and wait > 0:
                        self.stop.wait(min(wait, READ_TIMEOUT))
                        continue
                    # the bytes already read stay: they may be the start of the reply, the rest
                    # still on its way (a line is complete only at its end, however late)
                    self._ask()
                    # a late answer to an earlier request may still come: it dates from then
                    t_asked = t_asked if awaiting else now
                    t_request, awaiting = now, True
                chunk = self.port.read(self.port.in_waiting or 1)
                drained = not self.port.in_waiting
            except errors as exc:
                self._emit("fault", cfg.name, "port_lost", str(exc))
                if not self._reopen(last_good):
                    if not self.stop.is_set():
                        self._emit("gone", cfg.name, "", f"port lost ({exc}) and not back within "
                                                         f"{cfg.give_up:g} s")
                    break
                buf.clear()
                awaiting, t_empty = False, time.monotonic()
                continue
            now = time.monotonic()
            good: list[tuple[float, Any, float, float]] = []
            if chunk:
                # the lines arrived after the input was last seen empty (and after the request)
                since = max(t_asked, t_empty) if awaiting else t_empty
                good, answered = self._lines(buf, chunk, now, since)
                awaiting = awaiting and not answered
            if drained:  # what the next read returns arrived after this
                t_empty = now
            if good:
                self.out.put(("data", cfg.name, cfg.kind, good))
                last_good, silent = now, False
            elif now - last_good > cfg.timeout and not silent:
                self._emit("fault", cfg.name, "timeout", f"no good line for {cfg.timeout:g} s")
                silent = True
            if now - last_good > cfg.give_up:
                self._emit("gone", cfg.name, "", f"no good line for {cfg.give_up:g} s")
                break
        else:  # stopped: the lines that had arrived are taken, not dropped
            try:
                chunk = self.port.read(self.port.in_waiting) if self.port.in_waiting else b""
            except errors as exc:
                self._emit("fault", cfg.name, "port_lost", str(exc))
                chunk = b""
            if chunk:
                now = time.monotonic()
                good, _ = self._lines(buf, chunk, now,
                                      max(t_asked, t_empty) if awaiting else t_empty)
                if good:
                    self.out.put(("data", cfg.name, cfg.kind, good))
        self._close()

    def _lines(self, buf: bytearray, chunk: bytes, now: float,
               since: float) -> tuple[list[tuple[float, Any, float, float]], bool]:
        """Add ``chunk`` to ``buf`` and take the complete lines out of it.

        Returns the good lines as ``(t, value, since, now)``, arrived between ``since`` and ``now``
        (host monotonic time, s), and whether any line (good or not) came. A garbled line and a
        rest longer than :data:`MAX_LINE` without a line end are reported as faults.
        """
        cfg = self.config
        buf += chunk
        *lines, rest = buf.split(b"\n")
        buf[:] = rest
        if len(buf) > MAX_LINE:
            self._emit("fault", cfg.name, "garbled", f"{len(buf)} bytes without a line end")
            buf.clear()
        lines = [line for line in lines if line.strip()]
        good = []
        for k, line in enumerate(lines):
            t = spread_stamp(since, now, k, len(lines))
            try:
                good.append((t, cfg.parse(bytes(line)), since, now))
            except LineError as exc:
                self._emit("fault", cfg.name, exc.kind, exc.reason)
        return good, bool(lines)

    def _close(self) -> None:
        try:
            self.port.close()
        except Exception:  # noqa: BLE001 - closing a dead port may fail; nothing to do
            pass
