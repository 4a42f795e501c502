"""One acquisition run: read the ports, pair by time, write spat.csv rows, report the faults.

:func:`acquire` opens the arm's port and the gauge ports (one :class:`PortReader` thread each),
pairs every arm sample with the gauge readings nearest in time (:class:`Pairer`), turns the three
readings into the sphere displacement with the nest's sensor directions (:class:`Nest`) and appends
each row to ``spat.csv`` at once, flushed (:class:`SpatWriter`). A status line (rows, rate, last
readouts and displacement, displacement range, faults) goes to ``status`` while it runs; at the end
the fault counts are printed and written to a small JSON summary.

The run stops when ``seconds`` have passed or ``stop`` is set (Ctrl-C, SIGTERM: status 0), or when
it cannot go on (status 1): the arm's port or a gauge channel gone for ``give_up`` seconds (port
lost and not back, or silent). In every case each good row is already on disk.
"""

from __future__ import annotations

import json
import math
import queue
import shutil
import threading
import time
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from aacmm_pin.acquire.faults import FAULT_KINDS, AcquisitionError, PortCounts
from aacmm_pin.acquire.lock import LOCK_NAME, CampaignLock
from aacmm_pin.acquire.nest import Nest
from aacmm_pin.acquire.pairing import Pair, Pairer
from aacmm_pin.acquire.ports import PortConfig, PortEvent, PortReader, arm_port, gauge_port, open_port
from aacmm_pin.acquire.protocols import COUNTER_MODULUS, HEIDENHAIN_REQUEST, GaugeSpec
from aacmm_pin.acquire.writer import SpatWriter
from aacmm_pin.data.output_claim import CAMPAIGN_FILES, claim_output, input_paths
from aacmm_pin.data.output_file import write_text_file


@dataclass(frozen=True)
class AcquisitionConfig:
    """What to record and how; SI units (m, s)."""

    campaign: Path
    """Campaign folder: spat.csv is appended to, locations.csv gets ``zero``."""
    location: int
    """R-Test location (nest) being recorded, >= 1."""
    arm: str
    """Arm port: device path or pyserial URL."""
    gauges: tuple[GaugeSpec, ...]
    """Gauge ports; together they must carry channels 1, 2 and 3."""
    zero: np.ndarray | None = None
    """Nest zero position in the MT-CS, shape (3,), m; None leaves locations.csv alone."""
    nest: Nest = field(default_factory=Nest)
    """Sensor directions (default orthogonal)."""
    arm_format: str = "nmea"
    """Arm line format, ``nmea`` or ``csv``."""
    n_axes: int = 7
    """Readouts per arm line."""
    baudrate: int = 115200
    """Baud rate of every port."""
    seconds: float | None = None
    """Length of the run, s; None: until stopped."""
    decimate: int = 1
    """Write every n-th pair only."""
    max_skew: float = 0.01
    """Largest time difference between an arm sample and a gauge reading paired with it, s."""
    steady_rad: float = math.radians(0.5)
    """Largest change of a readout over a pair's time window, rad (more: dropped as moving).

    A posture change in a SPAT moves the readouts by degrees; an operator's steady motion over a
    window of a few ms by a small fraction of this. Within 0.5 deg the reading a posture gives
    changes by the arm's error gradient times 0.5 deg (tens of um/rad: a fraction of a um)."""
    steady_m: float = 1e-6
    """Largest change of a gauge reading over a pair's time window, m (more: dropped as moving)."""
    timeout: float = 0.5
    """Silence of a port counted as a timeout, s."""
    give_up: float = 5.0
    """A port gone (lost, silent) this long stops the run, s."""
    gauge_range: float = 1e-3
    """Gauge readings beyond +- this are out-of-range faults, m."""
    heidenhain_request: bytes = HEIDENHAIN_REQUEST
    """Request byte(s) of the heidenhain gauges."""
    mitutoyo_request: bytes | None = None
    """Request bytes of the mitutoyo ports, or None if they stream."""
    poll_interval: float = 0.0
    """Least time between two requests to a polled gauge, s."""
    fsync_interval: float = 1.0
    """Seconds between fsyncs of spat.csv."""
    status_interval: float = 0.5
    """Seconds between status lines."""
    summary: Path | None = None
    """JSON summary file (default ``campaign/acquire-location<M>.json``)."""
    force: bool = False
    """Replace an existing ``summary`` file (the default one, an earlier run's summary of the
    location, is replaced without it)."""
    inputs: tuple[Path, ...] = ()
    """Files the run reads besides the campaign's (the nest file): the summary may be none of them."""

    def __post_init__(self) -> None:
        channels = sorted(g.channel for g in self.gauges if g.channel is not None)
        streams = [g for g in self.gauges if g.channel is None]
        if len(set(channels)) != len(channels) or (not streams and channels != [1, 2, 3]):
            raise ValueError(f"gauges: channels 1, 2 and 3 are needed, once each; got "
                             f"{', '.join(str(g) for g in self.gauges) or 'none'}")
        if self.decimate < 1 or self.max_skew <= 0 or self.timeout <= 0 or self.give_up <= 0:
            raise ValueError("decimate >= 1, max_skew, timeout and give_up > 0 expected")
        object.__setattr__(self, "campaign", Path(self.campaign))
        if self.zero is not None:
            object.__setattr__(self, "zero", np.asarray(self.zero, dtype=float).reshape(3))
        own = {(self.campaign / name).resolve() for name in (*CAMPAIGN_FILES, LOCK_NAME)}
        if self.summary_path.resolve() in own:  # even before it exists: the run writes it
            raise ValueError(f"summary: {self.summary_path} is a file of the campaign the run "
                             "records into; choose another summary file")

    @property
    def summary_path(self) -> Path:
        """Where the JSON summary goes."""
        return self.summary or self.campaign / f"acquire-location{self.location}.json"

    def summary_claim(self) -> AbstractContextManager[Path]:
        """Claim the summary file for the run (before a port is opened).

        Refused when it is one of the run's inputs (the campaign's files, :attr:`inputs`), or
        exists and is neither to be replaced (:attr:`force`) nor the location's default summary
        of an earlier run.
        """
        path = self.summary_path
        earlier = self.summary is None and _is_summary(path)
        return claim_output(path, self.force or earlier, input_paths(
            *self.inputs, campaigns=[self.campaign]), folder=False)


def _is_summary(path: Path) -> bool:
    """Whether ``path`` holds an acquisition summary (a JSON object with its keys)."""
    try:
        if not path.is_file() or path.is_symlink() or path.stat().st_size > 2**20:
            return False
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and {"campaign", "location", "rows_written", "ports"} <= set(data)


@dataclass
class AcquisitionSummary:
    """What a run recorded and what went wrong; written as JSON (mm, um, s)."""

    config: AcquisitionConfig
    """The run's configuration."""
    rows_written: int = 0
    """Rows written to spat.csv by this run."""
    rows_before: int = 0
    """Data rows spat.csv held before the run."""
    duration_s: float = 0.0
    """Length of the run, s."""
    stop_reason: str = ""
    """Why the run ended."""
    status: int = 0
    """Exit status: 0 stopped as asked, 1 stopped because a port was gone."""
    ports: dict[str, PortCounts] = field(default_factory=dict)
    """Port name -> its counts."""
    port_urls: dict[str, str] = field(default_factory=dict)
    """Port name -> device path or URL."""
    unpaired: int = 0
    """Arm samples without a gauge reading within max_skew on some channel (not written)."""
    moving: int = 0
    """Arm samples whose readouts or readings changed within the pair's time window (not written)."""
    paired: int = 0
    """Arm samples paired (written, or skipped by ``decimate``)."""
    window_max: float = 0.0
    """Widest time window of a pair made: how well the worst pair is timed, s."""
    missed_samples: int = 0
    """Arm samples missing from the counter sequence (lost in transit or dropped as faults)."""
    d_min: np.ndarray = field(default_factory=lambda: np.full(3, np.inf))
    """Smallest displacement per axis over the rows written, m."""
    d_max: np.ndarray = field(default_factory=lambda: np.full(3, -np.inf))
    """Largest displacement per axis over the rows written, m."""
    last_q: list[float] = field(default_factory=list)
    """Last readouts written, rad."""
    last_d: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """Last displacement written, m."""
    locations_message: str = ""
    """What happened to locations.csv."""
    repaired_bytes: int = 0
    """Bytes of an incomplete last line of spat.csv removed before writing."""
    lock_message: str = ""
    """A stale lock file of a dead run taken over, or ''."""

    @property
    def rate_hz(self) -> float:
        """Rows written per second over the run."""
        return self.rows_written / self.duration_s if self.duration_s > 0 else 0.0

    @property
    def faults(self) -> dict[str, int]:
        """Fault kind -> count over every port."""
        return {k: sum(getattr(c, k) for c in self.ports.values()) for k in FAULT_KINDS}

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form (mm, um, s)."""
        cfg = self.config
        span = np.isfinite(self.d_min)
        return {
            "campaign": str(cfg.campaign), "location": cfg.location,
            "spat_csv": str(cfg.campaign / "spat.csv"),
            "rows_written": self.rows_written, "rows_before": self.rows_before,
            "duration_s": round(self.duration_s, 3), "rate_hz": round(self.rate_hz, 1),
            "stop_reason": self.stop_reason, "status": self.status,
            "faults": self.faults, "unpaired": self.unpaired, "pairing": self.pairing(),
            "missed_samples": self.missed_samples,
            "ports": {name: {"port": self.port_urls.get(name, ""), **c.to_dict()}
                      for name, c in self.ports.items()},
            "displacement_range_um": {axis: ([lo * 1e6, hi * 1e6] if ok else None) for axis, lo, hi, ok
                                      in zip("xyz", self.d_min, self.d_max, span)},
            "locations": self.locations_message, "repaired_bytes": self.repaired_bytes,
            "lock": self.lock_message,
        }

    def pairing(self) -> dict[str, Any]:
        """Return how the arm samples were paired (JSON form: counts, shares, ms, um, deg)."""
        cfg = self.config
        total = self.paired + self.unpaired + self.moving
        return {"arm_samples": total, "paired": self.paired,
                "unpaired_no_reading_within_skew": self.unpaired,
                "dropped_at_a_change": self.moving,
                "paired_share": round(self.paired / total, 4) if total else None,
                "window_max_ms": round(self.window_max * 1e3, 3),
                "max_skew_ms": cfg.max_skew * 1e3, "steady_um": cfg.steady_m * 1e6,
                "steady_deg": round(math.degrees(cfg.steady_rad), 4)}

    def pairing_line(self) -> str:
        """Return the pairing's quality in one line."""
        cfg, total = self.config, self.paired + self.unpaired + self.moving
        if not total:
            return "pairing: no arm samples"
        return (f"pairing: {self.paired} of {total} arm samples paired "
                f"({100 * self.paired / total:.1f} %); {self.moving} dropped at a change (a readout "
                f"or reading moved more than {math.degrees(cfg.steady_rad):.2g} deg or "
                f"{cfg.steady_m * 1e6:.2g} um within the pair's time), {self.unpaired} without a "
                f"reading within {cfg.max_skew * 1e3:g} ms; every pair written is steady within "
                f"these over its time window (the widest {self.window_max * 1e3:.1f} ms)")

    def status_line(self, rate: float) -> str:
        """Return the one-line live status (rows, rate, last values, range, faults)."""
        q = " ".join(f"{math.degrees(v):.3f}" for v in self.last_q) or "-"
        d = " ".join(f"{v * 1e6:+.1f}" for v in self.last_d)
        span = ("range " + " ".join(f"{a} {lo * 1e6:+.1f}..{hi * 1e6:+.1f}" for a, lo, hi in
                                    zip("xyz", self.d_min, self.d_max)) if self.rows_written
                else "range -")
        faults = {k: v for k, v in self.faults.items() if v}
        text = ", ".join(f"{k} {v}" for k, v in faults.items()) or "none"
        return (f"loc {self.config.location} | {self.rows_written} rows {rate:.0f} Hz | q {q} deg | "
                f"d {d} um | {span} um | unpaired {self.unpaired} | faults {text}")

    def report(self) -> str:
        """Return the end-of-run report: rows, reason, fault table, locations.csv, summary file."""
        cfg = self.config
        lines = [f"acquire: location {cfg.location}: {self.rows_written} rows appended to "
                 f"{cfg.campaign / 'spat.csv'} in {self.duration_s:.1f} s ({self.rate_hz:.0f} Hz); "
                 f"stopped: {self.stop_reason}"]
        kinds = ("lines", *FAULT_KINDS, "reconnects")
        width = max([len(n) + len(self.port_urls.get(n, "")) + 1 for n in self.ports] + [4])
        lines.append("  " + "port".ljust(width) + "".join(f"{k:>13}" for k in kinds))
        for name, c in self.ports.items():
            where = f"{name} {self.port_urls.get(name, '')}"
            lines.append("  " + where.ljust(width) + "".join(f"{getattr(c, k):>13}" for k in kinds))
        lines.append("  " + self.pairing_line())
        lines.append(f"  unpaired arm samples (not written): {self.unpaired}; "
                     f"missed arm samples (counter gaps): {self.missed_samples}")
        if self.repaired_bytes:
            lines.append(f"  removed an incomplete last line ({self.repaired_bytes} bytes) of "
                         "spat.csv left by an interrupted run")
        if self.lock_message:
            lines.append(f"  {self.lock_message}")
        lines.append(f"  {self.locations_message}")
        lines.append(f"  summary: {cfg.summary_path}")
        return "\n".join(lines)


def _port_configs(cfg: AcquisitionConfig) -> list[PortConfig]:
    """Return the arm's port configuration, then the gauges'."""
    common: dict[str, Any] = {"baudrate": cfg.baudrate, "timeout": cfg.timeout,
                              "give_up": cfg.give_up}
    ports = [arm_port(cfg.arm, cfg.n_axes, cfg.arm_format, **common)]
    for spec in cfg.gauges:
        request = cfg.heidenhain_request if spec.fmt == "heidenhain" else cfg.mitutoyo_request
        name = spec.fmt if spec.channel is None else f"{spec.fmt}:{spec.channel}"
        ports.append(gauge_port(name, spec.port, spec.fmt, spec.channel, cfg.gauge_range, request,
                                poll_interval=cfg.poll_interval, **common))
    if len({p.name for p in ports}) != len(ports):
        raise ValueError("gauges: two ports with the same name; give each port once")
    return ports


def _write_json(path: Path, data: dict[str, Any]) -> None:
    """Write the summary as JSON, whole or not at all (claimed by :func:`acquire` for the run)."""
    write_text_file(path, json.dumps(data, indent=2) + "\n", force=True)


def _drain(events: queue.Queue[PortEvent], timeout: float) -> list[PortEvent]:
    """Return the events waiting on ``events`` (waiting up to ``timeout`` s for the first); [] if none.

    A new list every call: an idle queue gives an empty batch, never the previous one again.
    """
    items: list[PortEvent] = []
    try:
        items.append(events.get(timeout=timeout))
        while True:
            items.append(events.get_nowait())
    except queue.Empty:
        pass
    return items


def acquire(config: AcquisitionConfig, *, stop: threading.Event | None = None,
            status: TextIO | None = None) -> AcquisitionSummary:
    """Record one location's SPAT into the campaign folder; see the module docstring.

    Args:
        config: ports, location, nest and limits.
        stop: set it to end the run (e.g. from a signal handler); None: only ``seconds`` or a
            gone port end it.
        status: stream of the live status line and the final report (e.g. ``sys.stderr``);
            None prints nothing.

    Returns:
        The summary (also written as JSON to ``config.summary_path``).

    Raises:
        AcquisitionError: if another acquire holds the campaign's lock (one writer per
            campaign, :class:`~aacmm_pin.acquire.lock.CampaignLock`), a port cannot be opened or
            the campaign files conflict (nothing is written then).
        OutputExistsError: if the summary file is an input of the run, exists (and neither
            ``force`` nor the location's default summary), or another run writes it (before a
            port is opened).
    """
    with CampaignLock(config.campaign) as lock, config.summary_claim():
        return _record(config, lock, stop or threading.Event(), status)


def _open_readers(configs: list[PortConfig], events: queue.Queue[PortEvent],
                  halt: threading.Event) -> list[PortReader]:
    """Open every port (all or none: the ones opened are closed on an error) and its reader."""
    opened: list[Any] = []
    try:
        for pc in configs:
            opened.append(open_port(pc.url, pc.baudrate))
    except AcquisitionError:
        for port in opened:
            port.close()
        raise
    return [PortReader(pc, events, halt, port) for pc, port in zip(configs, opened)]


class _Recording:
    """One recording's state: arm samples paired with gauge readings, the rows written, why it ends."""

    def __init__(self, cfg: AcquisitionConfig, writer: SpatWriter, summary: AcquisitionSummary):
        self.cfg, self.writer, self.summary = cfg, writer, summary
        self.pairer = Pairer((1, 2, 3), cfg.max_skew, steady_rad=cfg.steady_rad,
                             steady_m=cfg.steady_m)
        self.t0, self.wall0 = time.monotonic(), time.time()
        self.last_counter: int | None = None
        self.n_pairs = 0
        self.reason: str | None = None
        """Why the recording ends (None: it goes on)."""

    def handle(self, event: PortEvent) -> str | None:
        """Count and pair one port event; return why the recording must end (a port gone)."""
        summary = self.summary
        what, name = event[0], event[1]
        counts = summary.ports[name]
        if what == "data":
            counts.lines += len(event[3])
            if event[2] == "arm":
                for t, (counter, q), lo, hi in event[3]:
                    if counter is not None and self.last_counter is not None:
                        gap = (counter - self.last_counter - 1) % COUNTER_MODULUS
                        # a counter that goes back (device restarted) is no gap of ~2**32
                        summary.missed_samples += gap if gap < COUNTER_MODULUS // 2 else 0
                    self.last_counter = counter if counter is not None else self.last_counter
                    self.pairer.add_arm(t, q, span=(lo, hi))
            else:
                for t, (channel, value), lo, hi in event[3]:
                    self.pairer.add_gauge(channel, t, value, span=(lo, hi))
        elif what == "fault":
            counts.add(event[2])
        elif what == "reconnect":
            counts.reconnects += 1
        elif what == "gone":
            return f"{name} port gone: {event[3]}"
        return None

    def count_pairing(self) -> None:
        """Copy the pairer's counts to the summary."""
        p, summary = self.pairer, self.summary
        summary.unpaired, summary.moving, summary.paired = p.unpaired, p.moving, p.paired
        summary.window_max = 2 * p.u_max

    def write(self, pairs: list[Pair]) -> None:
        """Write every ``decimate``-th pair as a SPAT row (time, readouts, displacement)."""
        cfg, summary = self.cfg, self.summary
        for pair in pairs:
            self.n_pairs += 1
            if (self.n_pairs - 1) % cfg.decimate:
                continue
            d = cfg.nest.displacement(np.array(pair.readings))
            self.writer.write(self.wall0 + (pair.t - self.t0), pair.q, d)
            summary.rows_written += 1
            summary.last_q, summary.last_d = pair.q, d
            np.minimum(summary.d_min, d, out=summary.d_min)
            np.maximum(summary.d_max, d, out=summary.d_max)


def _record(cfg: AcquisitionConfig, lock: CampaignLock, stop: threading.Event,
            status: TextIO | None) -> AcquisitionSummary:
    """Run :func:`acquire` while holding the campaign's lock."""
    writer = SpatWriter(cfg.campaign, cfg.location, cfg.n_axes, cfg.zero, cfg.fsync_interval)
    summary = AcquisitionSummary(cfg, rows_before=writer.rows_before,
                                 locations_message=writer.locations_message,
                                 repaired_bytes=writer.repaired_bytes, lock_message=lock.message)
    configs = _port_configs(cfg)
    events: queue.Queue[PortEvent] = queue.Queue()
    halt = threading.Event()
    readers = _open_readers(configs, events, halt)
    for pc in configs:
        summary.ports[pc.name] = PortCounts()
        summary.port_urls[pc.name] = pc.url
    tty = bool(status is not None and getattr(status, "isatty", lambda: False)())
    rec = _Recording(cfg, writer, summary)
    for reader in readers:
        reader.start()
    try:
        _run(rec, events, stop, status, tty)
    finally:
        halt.set()
        for reader in readers:
            reader.join(timeout=1.0)
        _finish(rec, events, status, tty)
    return summary


def _run(rec: _Recording, events: queue.Queue[PortEvent], stop: threading.Event,
         status: TextIO | None, tty: bool) -> None:
    """Pair and write the ports' events until a port is gone, a stop or the time is up."""
    cfg, summary, t0 = rec.cfg, rec.summary, rec.t0
    width = shutil.get_terminal_size().columns - 1
    last_status, rows_at_status, rate = t0, 0, 0.0
    while rec.reason is None:
        for item in _drain(events, 0.01):
            gone = rec.handle(item)
            rec.reason = rec.reason or gone
        now = time.monotonic()
        rec.write(rec.pairer.pop(now))
        rec.count_pairing()
        summary.duration_s = now - t0
        if rec.reason is not None:
            summary.status = 1
        elif stop.is_set():
            rec.reason = "stopped (signal or request)"
        elif cfg.seconds is not None and now - t0 >= cfg.seconds:
            rec.reason = f"time up ({cfg.seconds:g} s)"
        if now - last_status >= cfg.status_interval:
            rate = (summary.rows_written - rows_at_status) / (now - last_status)
            last_status, rows_at_status = now, summary.rows_written
            if status is not None:
                line = summary.status_line(rate)
                status.write(f"\r{line[:width]}\x1b[K" if tty else line + "\n")
                status.flush()
            _write_json(cfg.summary_path, summary.to_dict() | {"running": True})


def _finish(rec: _Recording, events: queue.Queue[PortEvent], status: TextIO | None,
            tty: bool) -> None:
    """After the readers stopped: take their last events, write the last pairs, close, report."""
    summary = rec.summary
    try:
        while True:
            item = events.get_nowait()
            if item[0] != "gone":
                rec.handle(item)
    except queue.Empty:
        pass
    rec.write(rec.pairer.pop())
    rec.writer.close()
    rec.count_pairing()
    summary.duration_s = time.monotonic() - rec.t0
    summary.stop_reason = rec.reason or "interrupted"
    _write_json(rec.cfg.summary_path, summary.to_dict())
    if status is not None:
        status.write(("\n" if tty else "") + summary.report() + "\n")
        status.flush()
