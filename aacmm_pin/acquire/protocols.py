r"""Line formats of the arm and of the displacement gauges: parse, format, checksum.

Every device sends ASCII lines ended by ``\n`` (a ``\r`` before it is ignored). Values on the line
are in degrees or mm; the parsers return SI (rad, m).

**Arm, format ``nmea`` (default)**, one line per sample, NMEA-0183-like::

    $A,<counter>,<q1_deg>,<q2_deg>,...,<qn_deg>*<HH>\r\n
    $A,17,-35.063444,78.282159,171.074130,35.139578,-135.639175,-78.001445,128.347322*73

* ``counter``: unsigned decimal sample counter, +1 per sample, wrapping at 2**32 (gaps are
  counted as missed samples);
* ``qk_deg``: readout of axis k, decimal degrees (``[+-]digits[.digits]``), at most +-720 deg;
* ``HH``: two hexadecimal digits, the XOR of every byte between ``$`` and ``*`` (exclusive), as in
  NMEA 0183. A line with the wrong checksum is a ``checksum`` fault; anything else that does not
  follow the format (wrong field count, not a number, no ``$``/``*``) is ``garbled``.

**Arm, format ``csv``**: ``<q1_deg>,...,<qn_deg>`` and nothing else (no counter, no checksum: only
garbled lines can be detected).

**Gauge, format ``heidenhain``** (Heidenhain ND 28x-style counter, one gauge per port, polled): the
host sends a request byte (default STX, Ctrl-B, ``\x02``); the counter answers one line, sign,
optional blanks, the value in mm, optional blanks::

    +   0.0123 \r\n

**Gauge, format ``mitutoyo``** (Mitutoyo-style counter output, streamed; several channels may
share a port): two-digit channel number, ``A`` (normal data), sign, value in mm::

    01A+0000.123\r\n

Channel ``01`` is gauge 1 (the first sensor direction of the nest), ``02`` gauge 2, ``03`` gauge 3.
A gauge value beyond +-``range`` is an ``out_of_range`` fault (a counter that overflows or a
sensor off its stroke), never data.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from functools import reduce
from operator import xor

from aacmm_pin.acquire.faults import LineError

ARM_FORMATS = ("nmea", "csv")
"""Arm line formats."""
GAUGE_FORMATS = ("heidenhain", "mitutoyo")
"""Gauge line formats."""
MAX_ANGLE_DEG = 720.0
"""Largest accepted readout, deg (as in the campaign files)."""
COUNTER_MODULUS = 2**32
"""The arm's sample counter wraps here."""
HEIDENHAIN_REQUEST = b"\x02"
"""Default request byte of the Heidenhain-style counters (STX, Ctrl-B)."""

_NUMBER = rb"[+-]?[0-9]+(?:\.[0-9]*)?"
_NMEA = re.compile(rb"\$([^$*]*)\*([0-9A-Fa-f]{2})")
_NUMBERS_RE = re.compile(_NUMBER + rb"(?:," + _NUMBER + rb")*")
_RAD = math.pi / 180.0
_HEIDENHAIN = re.compile(rb"\s*([+-])\s*([0-9]+(?:\.[0-9]*)?)\s*")
_MITUTOYO = re.compile(rb"([0-9]{2})A([+-][0-9]+(?:\.[0-9]*)?)\s*")


def nmea_checksum(body: bytes) -> int:
    """Return the XOR of the bytes of ``body`` (the text between ``$`` and ``*``), 0-255."""
    return reduce(xor, body, 0)


def format_arm_line(counter: int, q_deg: Sequence[float], decimals: int = 6) -> bytes:
    r"""Return the ``nmea`` line of one arm sample, ending with ``\r\n``.

    Args:
        counter: sample counter, taken modulo 2**32.
        q_deg: readouts of the n axes, deg.
        decimals: decimals written per angle.
    """
    body = f"A,{counter % COUNTER_MODULUS}," + ",".join(f"{v:.{decimals}f}" for v in q_deg)
    data = body.encode("ascii")
    return b"$" + data + b"*%02X\r\n" % nmea_checksum(data)


def _angles(text: bytes, n_axes: int, line: bytes) -> list[float]:
    """Return the readouts (rad) of n_axes comma-separated decimal degrees, or raise a LineError."""
    if not _NUMBERS_RE.fullmatch(text):
        raise LineError("garbled", line, "the angles are not comma-separated decimal numbers")
    q_deg = [float(f) for f in text.split(b",")]
    if len(q_deg) != n_axes:
        raise LineError("garbled", line, f"{len(q_deg)} angles instead of {n_axes}")
    if max(map(abs, q_deg)) > MAX_ANGLE_DEG:
        raise LineError("out_of_range", line, f"an angle is beyond +-{MAX_ANGLE_DEG:g} deg")
    return [v * _RAD for v in q_deg]


def parse_arm_line(line: bytes, n_axes: int, fmt: str = "nmea") -> tuple[int | None, list[float]]:
    """Parse one arm line (without its line end).

    Args:
        line: the bytes of the line; surrounding blanks are ignored.
        n_axes: number of readouts expected.
        fmt: ``"nmea"`` or ``"csv"`` (see the module docstring).

    Returns:
        (counter, readouts): the sample counter (None for ``csv``) and the n readouts, in rad.

    Raises:
        LineError: ``garbled``, ``checksum`` or ``out_of_range``.
    """
    text = line.strip()
    if fmt == "csv":
        return None, _angles(text, n_axes, line)
    m = _NMEA.fullmatch(text)
    if not m:
        raise LineError("garbled", line, "not a $...*HH line")
    body = m[1]
    if nmea_checksum(body) != int(m[2], 16):
        raise LineError("checksum", line, f"checksum {m[2].decode()} does not match "
                                          f"{nmea_checksum(body):02X}")
    fields = body.split(b",", 2)
    if len(fields) < 3 or fields[0] != b"A" or not fields[1].isdigit():
        raise LineError("garbled", line, "expected 'A,<counter>,' after '$'")
    return int(fields[1]) % COUNTER_MODULUS, _angles(fields[2], n_axes, line)


def format_heidenhain(value_mm: float) -> bytes:
    r"""Return a Heidenhain-style reply ``+   0.0123 \r\n`` for a value in mm (4 decimals)."""
    sign = "-" if value_mm < 0 else "+"
    return f"{sign}{abs(value_mm):9.4f} \r\n".encode("ascii")


def parse_heidenhain(line: bytes, range_m: float = math.inf) -> float:
    """Parse a Heidenhain-style reply; return the value in m.

    Raises:
        LineError: ``garbled`` or ``out_of_range`` (beyond +-``range_m``).
    """
    m = _HEIDENHAIN.fullmatch(line)
    if not m:
        raise LineError("garbled", line, "not a '+   0.0123' value line")
    value = float(m[2]) * (-1e-3 if m[1] == b"-" else 1e-3)
    if abs(value) > range_m:
        raise LineError("out_of_range", line, f"beyond +-{range_m * 1e3:g} mm")
    return value


def format_mitutoyo(channel: int, value_mm: float, decimals: int = 4) -> bytes:
    r"""Return a Mitutoyo-style line ``01A+0000.1234\r\n`` for a channel (1-99) and mm value."""
    width = 5 + decimals + 1
    return f"{channel:02d}A{value_mm:+0{width}.{decimals}f}\r\n".encode("ascii")


def parse_mitutoyo(line: bytes, range_m: float = math.inf) -> tuple[int, float]:
    """Parse a Mitutoyo-style line; return (channel, value in m).

    Raises:
        LineError: ``garbled`` or ``out_of_range`` (beyond +-``range_m``).
    """
    m = _MITUTOYO.fullmatch(line.strip())
    if not m:
        raise LineError("garbled", line, "not a '01A+0000.123' value line")
    value = float(m[2]) * 1e-3
    if abs(value) > range_m:
        raise LineError("out_of_range", line, f"beyond +-{range_m * 1e3:g} mm")
    return int(m[1]), value


@dataclass(frozen=True)
class GaugeSpec:
    """One gauge port: its line format, the channel it carries and where it is."""

    fmt: str
    """``"heidenhain"`` or ``"mitutoyo"``."""
    channel: int | None
    """Gauge (1-3) of a ``heidenhain`` port; None for ``mitutoyo`` (channel from each line)."""
    port: str
    """Device path or pyserial URL, e.g. ``/dev/ttyUSB1``."""

    def __str__(self) -> str:
        """Format as on the command line: ``heidenhain:1=/dev/ttyUSB1``."""
        channel = "" if self.channel is None else f":{self.channel}"
        return f"{self.fmt}{channel}={self.port}"


def parse_gauge_spec(text: str, default_channel: int | None = None) -> GaugeSpec:
    """Parse ``FORMAT[:CHANNEL]=PORT``, e.g. ``heidenhain:2=/dev/ttyUSB2`` or ``mitutoyo=COM3``.

    Args:
        text: the specification.
        default_channel: channel of a ``heidenhain`` port given without one.

    Raises:
        ValueError: naming the valid formats and channels.
    """
    head, sep, port = text.partition("=")
    fmt, _, channel = head.partition(":")
    why = ""
    if not sep or not port:
        why = "expected FORMAT[:CHANNEL]=PORT"
    elif fmt not in GAUGE_FORMATS:
        why = f"format {fmt!r} unknown; choose from {', '.join(GAUGE_FORMATS)}"
    elif channel and channel not in ("1", "2", "3"):
        why = f"channel {channel!r}: choose 1, 2 or 3"
    elif fmt == "mitutoyo" and channel:
        why = "a mitutoyo port takes each line's channel number (01-03): give no channel"
    elif fmt == "heidenhain" and not channel and default_channel is None:
        why = "a heidenhain port carries one gauge: give its channel, e.g. heidenhain:1=PORT"
    if why:
        raise ValueError(f"gauge {text!r}: {why}")
    if fmt == "mitutoyo":
        return GaugeSpec(fmt, None, port)
    return GaugeSpec(fmt, int(channel) if channel else default_channel, port)
