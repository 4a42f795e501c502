"""The ``acquire`` and ``fake-devices`` subcommands: record a SPAT from serial ports, or fake them.

pyserial, the simulator and Pinocchio are imported inside the handlers. Both commands stop cleanly
on SIGINT/SIGTERM (the run loop sees a stop event; the campaign files stay consistent).
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from aacmm_pin.cli._options import (
    FORCE_FILE,
    add_command,
    arm_option,
    claim_file,
    force_option,
    json_option,
    load_given_arm,
    nest_option,
    positive,
    read_files,
    seed_option,
    write_json,
)
from aacmm_pin.units import DEFAULT_SIMULATOR_EFFECTS as DEFAULT_EFFECTS
from aacmm_pin.units import SIMULATOR_EFFECTS


@contextmanager
def _stop_on_signals(stop: threading.Event) -> Iterator[None]:
    """Set ``stop`` on SIGINT/SIGTERM while inside (main thread only), then restore the handlers."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    signals = (signal.SIGINT, signal.SIGTERM)
    old = {s: signal.getsignal(s) for s in signals}
    for s in signals:
        signal.signal(s, lambda *_: stop.set())
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


def _triple_mm(text: str) -> list[float]:
    """Parse ``x,y,z`` in mm (argparse type)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 3 or not all(abs(v) < 1e9 for v in values):
        raise argparse.ArgumentTypeError(f"expected x,y,z in mm, got {text!r}")
    return values


def _request_bytes(text: str) -> bytes:
    r"""Parse a request given with Python escapes, e.g. ``\x02`` (argparse type)."""
    return text.encode("latin-1").decode("unicode_escape").encode("latin-1")


def _acquire(args: argparse.Namespace) -> int:
    import numpy as np

    from aacmm_pin.acquire.nest import Nest, read_nest
    from aacmm_pin.acquire.protocols import parse_gauge_spec
    from aacmm_pin.acquire.session import AcquisitionConfig, acquire
    from aacmm_pin.extras import require

    require("serial", "acquire")  # before a file is claimed or a port opened

    try:
        gauges = tuple(parse_gauge_spec(text, default_channel=k + 1)
                       for k, text in enumerate(args.gauge))
        config = AcquisitionConfig(
            campaign=args.campaign, location=args.location, arm=args.arm_port, gauges=gauges,
            zero=None if args.zero is None else np.array(args.zero) * 1e-3,
            nest=read_nest(args.nest) if args.nest else Nest(), arm_format=args.arm_format,
            n_axes=args.axes, baudrate=args.baud, seconds=args.seconds, decimate=args.decimate,
            max_skew=args.max_skew_ms * 1e-3, steady_rad=math.radians(args.steady_deg),
            steady_m=args.steady_um * 1e-6, timeout=args.timeout_s, give_up=args.give_up_s,
            gauge_range=args.gauge_range_mm * 1e-3, heidenhain_request=args.heidenhain_request,
            mitutoyo_request=args.mitutoyo_request, poll_interval=1.0 / args.poll_hz
            if args.poll_hz else 0.0, fsync_interval=args.fsync_s, status_interval=args.status_s,
            summary=args.summary, force=args.force,
            inputs=(args.nest,) if args.nest else ())
    except ValueError as exc:
        print(f"aacmm-pin acquire: error: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    with _stop_on_signals(stop):
        summary = acquire(config, stop=stop, status=None if args.quiet else sys.stderr)
    return summary.status


def _fake_devices(args: argparse.Namespace) -> int:
    from aacmm_pin.acquire.fake_devices import FakeConfig, FakeDevices
    from aacmm_pin.acquire.nest import Nest, read_nest
    from aacmm_pin.data.output_claim import input_paths

    effects = tuple(e.strip() for e in args.effects.split(",") if e.strip())
    inputs = input_paths(args.nest, *read_files(args))  # its nest file, URDF: never replaced
    with claim_file(args.json, args.force, inputs):  # refused before the devices start
        try:
            config = FakeConfig(
                location=args.location, seed=args.seed, effects=effects, postures=args.postures,
                rate=args.rate_hz, gauge_format=args.gauge_format, dwell=args.dwell_s,
                garbage=args.garbage, checksum=args.checksum_errors,
                out_of_range=args.out_of_range, timeouts=args.timeouts, silence=args.silence_s,
                nest=read_nest(args.nest) if args.nest else Nest())
            devices = FakeDevices(config, load_given_arm(args))
        except ValueError as exc:
            print(f"aacmm-pin fake-devices: error: {exc}", file=sys.stderr)
            return 2
        _play(args, config, devices, effects)
    counts = ", ".join(f"{k} {v}" for k, v in devices.injected.items())
    print(f"fake-devices: stopped; {devices.lines_sent} arm lines; injected: {counts}", flush=True)
    return 0


def _play(args: argparse.Namespace, config: Any, devices: Any, effects: tuple[str, ...]) -> None:
    """Run the fake devices until stopped; write ``--json`` at the start and at the end."""
    stop = threading.Event()
    with _stop_on_signals(stop), devices:
        print(f"fake-devices: location {config.location} of a simulated campaign (seed "
              f"{config.seed}, effects {','.join(effects)}), {len(devices.q_deg)} postures held "
              f"{config.dwell:g} s each, {config.rate:g} lines/s, for "
              f"{'ever' if args.seconds is None else f'{args.seconds:g} s'}")
        print(f"arm {devices.arm_path}")
        for spec in devices.gauges:
            print(f"gauge {spec}")
        print("zero_mm " + ",".join(f"{v * 1e3:.6f}" for v in devices.zero))
        print("run: aacmm-pin acquire CAMPAIGN " + " ".join(devices.acquire_args()), flush=True)
        if args.json:
            write_json(args.json, devices.describe(), args.force)
        devices.run(args.seconds, stop)
    if args.json:  # its own file, still claimed: replaced
        write_json(args.json, devices.describe(), force=True)


def add_parsers(subparsers: Any) -> None:
    """Add the subcommands ``acquire`` and ``fake-devices`` to ``subparsers``.

    Args:
        subparsers: what ``ArgumentParser.add_subparsers()`` returned; each parser sets
            ``handler``, a function of the parsed arguments returning the exit status.
    """
    _add_acquire_parser(subparsers)
    _add_fake_devices_parser(subparsers)


def _add_acquire_parser(subparsers: Any) -> None:
    """Add the subcommand ``acquire`` to ``subparsers``."""
    p = add_command(
        subparsers, "acquire", "record a SPAT from the arm and R-Test gauges on serial ports",
        description="Record one R-Test location's SPAT into CAMPAIGN/spat.csv (appended, one "
                    "flushed row per paired sample) with a live status line; faults are counted, "
                    "never written. Line formats: see aacmm_pin.acquire.protocols.",
        parents=[nest_option("nest file (JSON with 3 sensor directions; default: orthogonal x, "
                             "y, z)"),
                 force_option("replace the --summary FILE if it exists (never one of the run's "
                              "inputs); without it such a file is refused. The default summary, "
                              "an earlier run's of the location, is replaced without it")])
    p.add_argument("campaign", type=Path, help="campaign folder (spat.csv is appended to)")
    p.add_argument("--arm-port", required=True, help="arm port: device path or pyserial URL")
    p.add_argument("--gauge", action="append", required=True, metavar="FORMAT[:CHANNEL]=PORT",
                   help="gauge port, e.g. heidenhain:1=/dev/ttyUSB1 (one per gauge) or "
                        "mitutoyo=/dev/ttyUSB1 (channels 01-03 on one port); repeat as needed")
    p.add_argument("--location", type=int, required=True, help="R-Test location (nest), >= 1")
    p.add_argument("--zero", type=_triple_mm, default=None, metavar="X,Y,Z",
                   help="nest zero position in the MT-CS, mm, for locations.csv")
    p.add_argument("--seconds", type=positive(), default=None,
                   help="stop after this long (default: at Ctrl-C)")
    p.add_argument("--arm-format", choices=("nmea", "csv"), default="nmea",
                   help="arm line format: nmea ($A,...*HH) or csv")
    p.add_argument("--axes", type=int, default=7, help="readouts per arm line")
    p.add_argument("--baud", type=int, default=115200, help="baud rate of every port")
    p.add_argument("--decimate", type=positive(int), default=1, help="write every n-th sample")
    p.add_argument("--max-skew-ms", type=positive(), default=10.0,
                   help="largest time between an arm sample and its gauge readings, ms")
    p.add_argument("--steady-deg", type=positive(zero=True), default=0.5,
                   help="a readout that changes more than this within a pair's time window drops "
                        "the pair (the arm was moving), deg")
    p.add_argument("--steady-um", type=positive(zero=True), default=1.0,
                   help="a gauge reading that changes more than this within a pair's time window "
                        "drops the pair, um")
    p.add_argument("--timeout-s", type=positive(), default=0.5, help="silence counted as a timeout, s")
    p.add_argument("--give-up-s", type=positive(), default=5.0,
                   help="a port lost or silent this long ends the run (status 1), s")
    p.add_argument("--gauge-range-mm", type=float, default=1.0,
                   help="readings beyond +- this are out-of-range faults, mm")
    p.add_argument("--heidenhain-request", type=_request_bytes, default=b"\x02",
                   help=r"request sent to heidenhain gauges, with Python escapes (\x02 is Ctrl-B)")
    p.add_argument("--mitutoyo-request", type=_request_bytes, default=None,
                   help="request sent to mitutoyo ports (default: none, they stream)")
    p.add_argument("--poll-hz", type=positive(zero=True), default=0.0,
                   help="most requests per second to a polled gauge (0: as fast as it answers)")
    p.add_argument("--fsync-s", type=positive(zero=True), default=1.0,
                   help="seconds between fsyncs")
    p.add_argument("--status-s", type=positive(), default=0.5, help="seconds between status lines")
    p.add_argument("--summary", type=Path, default=None, metavar="FILE",
                   help="JSON summary (default: CAMPAIGN/acquire-location<M>.json); an existing "
                        "file is refused without --force")
    p.add_argument("--quiet", action="store_true", help="no status line or report")
    p.set_defaults(handler=_acquire)


def _add_fake_devices_parser(subparsers: Any) -> None:
    """Add the subcommand ``fake-devices`` to ``subparsers``."""
    p = add_command(
        subparsers, "fake-devices", "a simulated arm and R-Test gauges on pseudo-terminals",
        description="Play one R-Test location of a simulated campaign on pseudo-terminals, print "
                    "their paths and the acquire command that reads them, run for --seconds.",
        parents=[seed_option("seed of the simulated campaign"), arm_option(),
                 nest_option("nest file (default: orthogonal)"),
                 json_option("the paths, played postures/readings and injected faults"),
                 force_option(FORCE_FILE)])
    p.add_argument("--location", type=int, default=1, help="R-Test location to play (1-4)")
    p.add_argument("--effects", default=",".join(DEFAULT_EFFECTS),
                   help=f"comma-separated simulator effects from {', '.join(SIMULATOR_EFFECTS)}")
    p.add_argument("--postures", type=positive(int), default=40,
                   help="simulated postures per location")
    p.add_argument("--rate-hz", type=positive(), default=1000.0, help="arm lines per second")
    p.add_argument("--gauge-format", choices=("heidenhain", "mitutoyo"), default="heidenhain",
                   help="heidenhain (three polled ports) or mitutoyo (one streaming port)")
    p.add_argument("--dwell-s", type=positive(), default=0.05, help="seconds per posture")
    p.add_argument("--garbage", type=float, default=0.0, help="probability of garbage per line")
    p.add_argument("--checksum-errors", type=float, default=0.0,
                   help="probability of a checksum error per arm line")
    p.add_argument("--out-of-range", type=float, default=0.0,
                   help="probability of an out-of-range value per gauge line")
    p.add_argument("--timeouts", type=float, default=0.0,
                   help="silences per second and device, each --silence-s long")
    p.add_argument("--silence-s", type=float, default=0.3, help="length of an injected silence, s")
    p.add_argument("--seconds", type=float, default=60.0, help="run this long, s")
    p.set_defaults(handler=_fake_devices)


PARSERS: dict[str, Callable[[Any], None]] = {"acquire": _add_acquire_parser,
                                             "fake-devices": _add_fake_devices_parser}
"""Each command's parser builder (:func:`aacmm_pin.cli.build_parser` builds only the command given)."""
