"""A virtual arm and R-Test gauges on pseudo-terminals, driven by the simulator.

:class:`FakeDevices` simulates a campaign (:func:`aacmm_pin.analyses.simulate.simulate_campaign`: a virtual
arm with DH, encoder and R-Test effects, IK postures at each R-Test location) and plays one
location's SPAT on real pseudo-terminals (``os.openpty``), in the line formats of
:mod:`aacmm_pin.acquire.protocols`:

* the arm streams ``nmea`` lines at ``rate`` lines per second, holding each simulated posture for
  ``dwell`` seconds and cycling through them (it jumps between postures: a real operator moves
  continuously, which the simulator's postures do not describe);
* the gauges answer the reading of the posture of the arm's last line written (the sphere is where
  the arm is, whatever the scheduling of the threads under load): ``heidenhain`` (one pty per
  gauge, one reply line per request byte) or ``mitutoyo`` (one pty streaming the three channels at
  ``rate``).
  The reading of gauge k is the simulator's R-Test displacement projected on the nest's direction
  k, so acquire must recover the simulator's displacement.

Faults are injected per line with the given probabilities: garbage (noise or a truncated line),
checksum errors (one digit of an arm line changed, checksum kept), gauge values out of range
(9.9999 mm), and timeouts (every device falls silent for ``silence`` seconds, ``timeouts`` times
per second). A device's writes never
block: what does not fit in the pty's buffer (no reader attached, or a reader far behind under
load) is dropped, possibly in the middle of a line, as a serial port whose receive buffer overflows
drops bytes; the reader then sees one garbled line (measured at load 6: 1 cut write in 4846).
"""

from __future__ import annotations

import math
import os
import select
import threading
import time
import tty
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aacmm_pin.acquire.nest import Nest
from aacmm_pin.acquire.protocols import (
    GAUGE_FORMATS,
    HEIDENHAIN_REQUEST,
    GaugeSpec,
    format_arm_line,
    format_heidenhain,
    format_mitutoyo,
)
from aacmm_pin.analyses.simulate import DEFAULT_EFFECTS

OUT_OF_RANGE_MM = 9.9999
"""Value sent for an injected out-of-range gauge reading, mm."""
ARM_DECIMALS = 6
"""Decimals of the angles on the fake arm's lines (1e-6 deg)."""
GAUGE_DECIMALS = 4
"""Decimals of the fake gauges' values (0.1 um)."""


@dataclass(frozen=True)
class FakeConfig:
    """What the fake devices play and which faults they inject."""

    location: int = 1
    """R-Test location of the simulated campaign to play."""
    seed: int = 0
    """Seed of the simulated campaign."""
    effects: tuple[str, ...] = DEFAULT_EFFECTS
    """Simulator effects (see :data:`aacmm_pin.analyses.simulate.EFFECTS`)."""
    postures: int = 40
    """Simulated postures per location."""
    rate: float = 1000.0
    """Arm lines per second (and mitutoyo lines per second per channel)."""
    gauge_format: str = "heidenhain"
    """``heidenhain`` (three polled ptys) or ``mitutoyo`` (one streaming pty)."""
    dwell: float = 0.05
    """Seconds each posture is held."""
    garbage: float = 0.0
    """Probability per line of garbage instead of the line."""
    checksum: float = 0.0
    """Probability per arm line of a checksum error."""
    out_of_range: float = 0.0
    """Probability per gauge line of an out-of-range value."""
    timeouts: float = 0.0
    """Silences per second and device (periodic, random phase, each ``silence`` seconds long)."""
    silence: float = 0.3
    """Length of an injected silence, s."""
    nest: Nest = field(default_factory=Nest)
    """Sensor directions of the nest (default orthogonal)."""

    def __post_init__(self) -> None:
        if self.gauge_format not in GAUGE_FORMATS:
            raise ValueError(f"gauge_format: choose from {', '.join(GAUGE_FORMATS)}, "
                             f"got {self.gauge_format!r}")
        if self.rate <= 0 or self.dwell <= 0 or self.silence < 0:
            raise ValueError("rate and dwell > 0, silence >= 0 expected")
        probs = (self.garbage, self.checksum, self.out_of_range)
        if any(not 0 <= p <= 1 for p in probs) or self.garbage + self.checksum > 1 or \
                self.timeouts < 0:
            raise ValueError("fault probabilities: each in [0, 1], garbage + checksum <= 1; "
                             "timeouts >= 0 per second")


def _open_pty() -> tuple[int, int, str]:
    """Return (master fd, slave fd, slave path) of a new raw pseudo-terminal."""
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    return master, slave, os.ttyname(slave)


def _sent(values: np.ndarray, decimals: int) -> np.ndarray:
    """Return the values as the devices print them (rounded through their decimal text)."""
    sent: np.ndarray = np.vectorize(lambda v: float(f"{v:.{decimals}f}"))(values).astype(float)
    return sent


class FakeDevices:
    """The fake arm and gauges of one location; start them, read their paths, stop them.

    Args:
        config: what to play and which faults to inject.
        arm: the arm (default: the embedded default arm).

    Raises:
        ValueError: if the simulated campaign has no such location.
    """

    def __init__(self, config: FakeConfig | None = None, arm: Any = None):
        from aacmm_pin.analyses.simulate import SimulationConfig, simulate_campaign
        from aacmm_pin.model.arm import load_arm

        self.config = config = config or FakeConfig()
        sim = simulate_campaign(arm or load_arm(), SimulationConfig(
            seed=config.seed, effects=config.effects, samples_per_location=config.postures,
            samples_per_socket=1, bar_placements=1))
        self.simulation = sim
        spat = sim.campaign.spat
        assert spat is not None
        if config.location not in sim.campaign.locations:
            raise ValueError(f"location: choose from {sorted(sim.campaign.locations)}, "
                             f"got {config.location}")
        sel = spat.location == config.location
        self.q_deg = _sent(np.degrees(spat.q[sel]), ARM_DECIMALS)
        """Postures as sent, shape (K, n), deg."""
        self.readings_mm = _sent(config.nest.readings(spat.displacement[sel]) * 1e3, GAUGE_DECIMALS)
        """Gauge readings as sent, shape (K, 3), mm."""
        self.displacement_mm = config.nest.displacement(self.readings_mm)
        """Sphere displacement the sent readings encode, shape (K, 3), mm."""
        self.zero = np.array(sim.campaign.locations[config.location])
        """Zero position of the nest (the campaign's measured one), shape (3,), m."""
        self.injected = {"garbage": 0, "checksum": 0, "out_of_range": 0, "timeout": 0}
        """Faults injected so far, by kind."""
        self.lines_sent = 0
        """Arm lines written so far (dropped ones included)."""
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._fds: list[int] = []
        self.arm_path = ""
        """Path of the arm's pty (after :meth:`start`)."""
        self.gauges: list[GaugeSpec] = []
        """Gauge ports as acquire takes them (after :meth:`start`)."""
        self._t0 = 0.0
        self._shown = 0  # posture of the arm's last line written: where the sphere is

    def posture(self, t: float) -> int:
        """Return the index of the posture played at monotonic time ``t``."""
        return int(max(t - self._t0, 0.0) / self.config.dwell) % len(self.q_deg)

    def _count(self, kind: str) -> None:
        with self._lock:
            self.injected[kind] += 1

    def start(self) -> FakeDevices:
        """Open the ptys and start the device threads; return self."""
        cfg = self.config
        seeds = np.random.SeedSequence([cfg.seed, cfg.location]).spawn(4)
        rngs = iter([np.random.default_rng(s) for s in seeds])
        self._t0 = time.monotonic()
        master, slave, self.arm_path = _open_pty()
        self._fds += [master, slave]
        self._threads.append(threading.Thread(target=self._run_arm, args=(master, next(rngs)),
                                              daemon=True))
        if cfg.gauge_format == "heidenhain":
            for channel in (1, 2, 3):
                master, slave, path = _open_pty()
                self._fds += [master, slave]
                self.gauges.append(GaugeSpec("heidenhain", channel, path))
                self._threads.append(threading.Thread(
                    target=self._run_heidenhain, args=(master, channel, next(rngs)),
                    daemon=True))
        else:
            master, slave, path = _open_pty()
            self._fds += [master, slave]
            self.gauges.append(GaugeSpec("mitutoyo", None, path))
            self._threads.append(threading.Thread(target=self._run_mitutoyo,
                                                  args=(master, next(rngs)), daemon=True))
        for thread in self._threads:
            thread.start()
        return self

    def stop(self) -> None:
        """Stop the threads and close the ptys (readers then see the ports disappear)."""
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=1.0)
        for fd in self._fds:
            try:
                os.close(fd)
            except OSError:
                pass
        self._fds.clear()

    def __enter__(self) -> FakeDevices:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def acquire_args(self) -> list[str]:
        """Return the ``acquire`` options that read these devices (ports, location, zero)."""
        zero = ",".join(f"{v * 1e3:.6f}" for v in self.zero)
        args = ["--location", str(self.config.location), f"--zero={zero}", "--arm-port", self.arm_path]
        for spec in self.gauges:
            args += ["--gauge", str(spec)]
        return args

    def describe(self) -> dict[str, Any]:
        """Return the paths, the played postures and readings and the injected faults (JSON form)."""
        return {"arm": self.arm_path, "gauges": [str(g) for g in self.gauges],
                "location": self.config.location, "zero_mm": (self.zero * 1e3).tolist(),
                "acquire_args": self.acquire_args(), "q_deg": self.q_deg.tolist(),
                "readings_mm": self.readings_mm.tolist(),
                "displacement_mm": self.displacement_mm.tolist(), "injected": dict(self.injected),
                "lines_sent": self.lines_sent}

    # -- devices ------------------------------------------------------------------------------

    def _garbage(self, line: bytes, rng: np.random.Generator) -> bytes:
        """Return noise (starting with ``?``), or an arm line truncated before its ``*``."""
        self._count("garbage")
        star = line.find(b"*")
        if star > 1 and rng.random() < 0.5:
            return line[:int(rng.integers(1, star))] + b"\r\n"
        noise = rng.integers(33, 127, int(rng.integers(1, 40))).astype(np.uint8).tobytes()
        return b"?" + noise.replace(b"$", b"#") + b"\r\n"

    def _silences(self, rng: np.random.Generator) -> Callable[[float], bool]:
        """Return ``silent(t)``: whether a device is in an injected silence at monotonic time t.

        A silence of ``silence`` seconds starts every ``1 / timeouts`` seconds, at a random phase.
        """
        cfg = self.config
        period = math.inf if cfg.timeouts <= 0 else 1.0 / cfg.timeouts
        state = {"start": time.monotonic() + rng.uniform(0.0, min(period, 1e9)), "end": -math.inf}

        def silent(t: float) -> bool:
            if t >= state["start"]:
                self._count("timeout")
                state["end"] = state["start"] + cfg.silence
                state["start"] += max(period, cfg.silence)
            return t < state["end"]

        return silent

    def _ticks(self, period: float) -> Iterator[tuple[float, int]]:
        """Yield (now, n) at the line rate until stopped: n lines are due (at most 50 at once)."""
        next_t = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            if now < next_t:
                self._stop.wait(next_t - now)
                continue
            n = min(int((now - next_t) / period) + 1, 50)
            next_t = max(next_t + n * period, now - 0.1)
            yield now, n

    def _run_arm(self, fd: int, rng: np.random.Generator) -> None:
        """Stream arm lines at ``rate`` until stopped."""
        cfg = self.config
        period = 1.0 / cfg.rate
        counter, silent = 0, self._silences(rng)
        for now, n in self._ticks(period):
            chunk = []
            k = self.posture(time.monotonic())
            for _ in range(n):
                counter += 1
                if silent(now):
                    continue
                line = format_arm_line(counter, self.q_deg[k], ARM_DECIMALS)
                r = rng.random()
                if r < cfg.garbage:
                    line = self._garbage(line, rng)
                elif r < cfg.garbage + cfg.checksum:
                    self._count("checksum")
                    digits = [i for i in range(line.find(b",", 3), line.find(b"*"))
                              if line[i:i + 1].isdigit()]
                    i = int(rng.choice(digits))
                    line = line[:i] + str((int(line[i:i + 1]) + 1) % 10).encode() + line[i + 1:]
                chunk.append(line)
            self.lines_sent += n
            self._write(fd, b"".join(chunk))
            self._shown = k

    def _gauge_line(self, channel: int, rng: np.random.Generator) -> bytes:
        """Return the line of one gauge reading now, with the injected faults."""
        cfg = self.config
        value = self.readings_mm[self._shown, channel - 1]
        if rng.random() < cfg.out_of_range:
            self._count("out_of_range")
            value = OUT_OF_RANGE_MM
        if cfg.gauge_format == "heidenhain":
            line = format_heidenhain(value)
        else:
            line = format_mitutoyo(channel, value, GAUGE_DECIMALS)
        return self._garbage(line, rng) if rng.random() < cfg.garbage else line

    def _run_heidenhain(self, fd: int, channel: int, rng: np.random.Generator) -> None:
        """Answer one line per request byte until stopped."""
        silent = self._silences(rng)
        while not self._stop.is_set():
            ready, _, _ = select.select([fd], [], [], 0.05)
            if not ready:
                continue
            try:
                data = os.read(fd, 4096)
            except OSError:  # nobody has the port open: nothing to answer
                self._stop.wait(0.01)
                continue
            replies = []
            for _ in range(data.count(HEIDENHAIN_REQUEST)):
                if not silent(time.monotonic()):
                    replies.append(self._gauge_line(channel, rng))
            self._write(fd, b"".join(replies))

    def _run_mitutoyo(self, fd: int, rng: np.random.Generator) -> None:
        """Stream the three channels at ``rate`` until stopped."""
        period = 1.0 / self.config.rate
        silent = self._silences(rng)
        for now, n in self._ticks(period):
            if not silent(now):
                self._write(fd, b"".join(self._gauge_line(c, rng) for c in (1, 2, 3)))

    @staticmethod
    def _write(fd: int, data: bytes) -> None:
        """Write without blocking; drop what does not fit (nobody reading, or a reader far behind)."""
        if data:
            try:
                os.write(fd, data)
            except OSError:  # full buffer or closed: a serial line with nobody listening
                pass

    def run(self, seconds: float | None, stop: threading.Event | None = None) -> None:
        """Block until ``seconds`` have passed (None: forever) or ``stop`` is set."""
        stop = stop or threading.Event()
        end = None if seconds is None else time.monotonic() + seconds
        while not stop.is_set() and (end is None or time.monotonic() < end):
            stop.wait(0.05 if end is None else min(0.05, max(end - time.monotonic(), 0.0)))
