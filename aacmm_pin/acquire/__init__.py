"""Acquisition of SPAT campaigns over serial ports, and fake devices to try it without hardware.

``aacmm-pin acquire`` reads the arm's encoder readouts and three R-Test gauges from serial ports,
pairs them by time, turns the gauge readings into the sphere displacement and appends crash-safe
rows to a campaign's ``spat.csv``; ``aacmm-pin fake-devices`` plays a simulated SPAT on
pseudo-terminals. The rooms:

* :mod:`~aacmm_pin.acquire.protocols`: the line formats (arm ``$A,...*HH``, Heidenhain-style,
  Mitutoyo-style gauges), parsers and formatters;
* :mod:`~aacmm_pin.acquire.faults`: :class:`AcquisitionError`, :class:`LineError` and the
  counts of bad input per port;
* :mod:`~aacmm_pin.acquire.nest`: :class:`Nest`, the sensor directions (readings -> displacement);
* :mod:`~aacmm_pin.acquire.pairing`: :class:`Pairer`, pairing by time;
* :mod:`~aacmm_pin.acquire.writer`: :class:`SpatWriter`, flushed appends to spat.csv;
* :mod:`~aacmm_pin.acquire.ports`: one reader thread per serial port (pyserial);
* :mod:`~aacmm_pin.acquire.session`: :func:`acquire`, the run loop, status and summary;
* :mod:`~aacmm_pin.acquire.fake_devices`: :class:`FakeDevices`, simulator-driven ptys;
* :mod:`aacmm_pin.cli.acquisition` (outside this package): the ``acquire`` and ``fake-devices``
  subcommands.

pyserial and the simulator are imported only by the modules that use them.
"""

from __future__ import annotations

from aacmm_pin.acquire.faults import FAULT_KINDS, AcquisitionError, LineError, PortCounts
from aacmm_pin.acquire.nest import Nest, read_nest
from aacmm_pin.acquire.pairing import Pair, Pairer
from aacmm_pin.acquire.protocols import GaugeSpec, parse_gauge_spec
from aacmm_pin.acquire.writer import SpatWriter, write_zero

__all__ = [
    "FAULT_KINDS", "AcquisitionError", "GaugeSpec", "LineError", "Nest", "Pair", "Pairer",
    "PortCounts", "SpatWriter", "parse_gauge_spec", "read_nest", "write_zero",
]
