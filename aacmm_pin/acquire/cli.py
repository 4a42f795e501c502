"""The ``acquire``, ``fake-devices`` and ``iso10360`` subcommands of ``aacmm-pin``.

:func:`add_parsers` adds them to the subparsers of ``aacmm-pin``; every leaf parser sets
``handler(args) -> exit status``. Standalone: ``python -m aacmm_pin.acquire.cli acquire ...``.
Heavy imports (pyserial, Pinocchio, scipy) happen inside the handlers.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any


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

    try:
        gauges = tuple(parse_gauge_spec(text, default_channel=k + 1)
                       for k, text in enumerate(args.gauge))
        config = AcquisitionConfig(
            campaign=args.campaign, location=args.location, arm=args.arm_port, gauges=gauges,
            zero=None if args.zero is None else np.array(args.zero) * 1e-3,
            nest=read_nest(args.nest) if args.nest else Nest(), arm_format=args.arm_format,
            n_axes=args.axes, baudrate=args.baud, seconds=args.seconds, decimate=args.decimate,
            max_skew=args.max_skew_ms * 1e-3, timeout=args.timeout_s, give_up=args.give_up_s,
            gauge_range=args.gauge_range_mm * 1e-3, heidenhain_request=args.heidenhain_request,
            mitutoyo_request=args.mitutoyo_request, poll_interval=1.0 / args.poll_hz
            if args.poll_hz else 0.0, fsync_interval=args.fsync_s, status_interval=args.status_s,
            summary=args.summary)
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
    from aacmm_pin.arm import load_arm

    effects = tuple(e.strip() for e in args.effects.split(",") if e.strip())
    try:
        config = FakeConfig(
            location=args.location, seed=args.seed, effects=effects, postures=args.postures,
            rate=args.rate_hz, gauge_format=args.gauge_format, dwell=args.dwell_s,
            garbage=args.garbage, checksum=args.checksum_errors, out_of_range=args.out_of_range,
            timeouts=args.timeouts, silence=args.silence_s,
            nest=read_nest(args.nest) if args.nest else Nest())
        devices = FakeDevices(config, load_arm(args.arm))
    except ValueError as exc:
        print(f"aacmm-pin fake-devices: error: {exc}", file=sys.stderr)
        return 2
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
            _write_json(args.json, devices.describe())
        devices.run(args.seconds, stop)
    if args.json:
        _write_json(args.json, devices.describe())
    counts = ", ".join(f"{k} {v}" for k, v in devices.injected.items())
    print(f"fake-devices: stopped; {devices.lines_sent} arm lines; injected: {counts}", flush=True)
    return 0


def _write_json(path: Path, data: dict[str, Any]) -> None:
    """Write JSON through a temporary file and an atomic rename."""
    import os

    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def _load(args: argparse.Namespace) -> tuple[Any, Any]:
    """Return (arm, parameters): from --params, else the nominal --arm."""
    from aacmm_pin.arm import load_arm
    from aacmm_pin.parameters import Parameters, check_against_arm, read_parameters

    if getattr(args, "params", None):
        params = read_parameters(args.params)
        arm = load_arm(args.arm or params.arm)
        check_against_arm(params, arm)
        return arm, params
    arm = load_arm(args.arm or "aacmm7")
    return arm, Parameters.nominal(arm)


def _points(args: argparse.Namespace) -> tuple[Any, Any]:
    """Return (points (N, 3) in m, group column or None) of the POINTS file."""
    from aacmm_pin.iso10360 import read_points

    points, groups, readouts = read_points(args.points)
    if readouts is not None:
        from aacmm_pin.kinematics import predict

        arm, params = _load(args)
        points = predict(arm, params, readouts)
    return points, groups


def _finish(args: argparse.Namespace, text: str, data: dict[str, Any]) -> int:
    print(text)
    if args.json:
        _write_json(args.json, data)
    return 0


def _iso_spat(args: argparse.Namespace) -> int:
    from aacmm_pin.campaign import read_campaign
    from aacmm_pin.iso10360 import point_articulation, spat_centres

    arm, params = _load(args)
    centres = spat_centres(arm, params, read_campaign(args.campaign), use_rtest=not args.no_rtest)
    rows, data = [], {}
    head = (f"{'location':>8} {'n':>6} {'max dev (um)':>13} {'2 sigma (um)':>13} "
            f"{'range x (um)':>13} {'range y (um)':>13} {'range z (um)':>13}")
    for m, p in centres.items():
        r = point_articulation(p)
        rows.append(f"{m:>8} {r.n:>6} {r.max_deviation * 1e6:>13.2f} {r.two_sigma * 1e6:>13.2f} "
                    + " ".join(f"{v * 1e6:>13.2f}" for v in r.ranges))
        data[str(m)] = r.to_dict()
    rtest = "without R-Test correction" if args.no_rtest else "R-Test displacement removed"
    text = "\n".join([f"point articulation (SPAT) per location, {rtest}:", head, *rows])
    return _finish(args, text, {"locations": data, "use_rtest": not args.no_rtest})


def _iso_sphere(args: argparse.Namespace) -> int:
    from aacmm_pin.iso10360 import probing_errors

    points, _ = _points(args)
    r = probing_errors(points, args.diameter_mm * 1e-3)
    note = "" if len(points) == 25 else f" (the test takes 25 points; {len(points)} given)"
    text = (f"least-squares sphere of {len(points)} points{note}: centre "
            + ", ".join(f"{v * 1e3:.6f}" for v in r.fit.centre)
            + f" mm, diameter {r.fit.diameter * 1e3:.6f} mm\n"
            f"P_Size {r.p_size * 1e6:+.2f} um, P_Form {r.p_form * 1e6:.2f} um")
    return _finish(args, text, r.to_dict())


def _iso_ldia(args: argparse.Namespace) -> int:
    from aacmm_pin.iso10360 import articulated_location

    points, groups = _points(args)
    r = articulated_location(points, groups=groups, group_size=args.group_size)
    rows = [f"  centre {k + 1}: " + ", ".join(f"{v * 1e3:.6f}" for v in c) + " mm"
            for k, c in enumerate(r.centres)]
    text = "\n".join([f"{len(r.centres)} sphere centres:", *rows,
                      f"L_Dia {r.l_dia * 1e6:.2f} um (diameter of the smallest sphere enclosing "
                      "the centres)"])
    return _finish(args, text, r.to_dict())


def _iso_euni(args: argparse.Namespace) -> int:
    from aacmm_pin.campaign import read_campaign
    from aacmm_pin.iso10360 import length_errors

    arm, params = _load(args)
    r = length_errors(arm, params, read_campaign(args.campaign))
    rows = [f"  placement {k}: " + ", ".join(f"{a}-{b} {e * 1e6:+.2f} um"
                                              for (a, b), e in zip(r.pairs, errs))
            for k, errs in zip(r.placements, r.errors)]
    text = "\n".join(["length errors (measured - calibrated):", *rows,
                      f"E_UNI {r.e_uni * 1e6:.2f} um (largest |error| of {r.errors.size} lengths)"])
    return _finish(args, text, r.to_dict())


def add_parsers(subparsers: Any) -> None:
    """Add the subcommands ``acquire``, ``fake-devices`` and ``iso10360`` to ``subparsers``.

    Args:
        subparsers: what ``ArgumentParser.add_subparsers()`` returned; each leaf parser sets
            ``handler``, a function of the parsed arguments returning the exit status.
    """
    p = subparsers.add_parser(
        "acquire", help="record a SPAT from the arm and R-Test gauges on serial ports",
        description="Record one R-Test location's SPAT into CAMPAIGN/spat.csv (appended, one "
                    "flushed row per paired sample) with a live status line; faults are counted, "
                    "never written. Line formats: see aacmm_pin.acquire.protocols.")
    p.add_argument("campaign", type=Path, help="campaign folder (spat.csv is appended to)")
    p.add_argument("--arm-port", required=True, help="arm port: device path or pyserial URL")
    p.add_argument("--gauge", action="append", required=True, metavar="FORMAT[:CHANNEL]=PORT",
                   help="gauge port, e.g. heidenhain:1=/dev/ttyUSB1 (one per gauge) or "
                        "mitutoyo=/dev/ttyUSB1 (channels 01-03 on one port); repeat as needed")
    p.add_argument("--location", type=int, required=True, help="R-Test location (nest), >= 1")
    p.add_argument("--zero", type=_triple_mm, default=None, metavar="X,Y,Z",
                   help="nest zero position in the MT-CS, mm, for locations.csv")
    p.add_argument("--nest", type=Path, default=None,
                   help="nest file (JSON with 3 sensor directions; default orthogonal x, y, z)")
    p.add_argument("--seconds", type=float, default=None, help="stop after this long "
                                                               "(default: Ctrl-C)")
    p.add_argument("--arm-format", choices=("nmea", "csv"), default="nmea")
    p.add_argument("--axes", type=int, default=7, help="readouts per arm line (default 7)")
    p.add_argument("--baud", type=int, default=115200)
    p.add_argument("--decimate", type=int, default=1, help="write every n-th sample (default 1)")
    p.add_argument("--max-skew-ms", type=float, default=10.0,
                   help="largest time between an arm sample and its gauge readings (default 10)")
    p.add_argument("--timeout-s", type=float, default=0.5, help="silence counted as a timeout")
    p.add_argument("--give-up-s", type=float, default=5.0,
                   help="a port lost or silent this long ends the run (status 1)")
    p.add_argument("--gauge-range-mm", type=float, default=1.0,
                   help="readings beyond +- this are out-of-range faults (default 1 mm)")
    p.add_argument("--heidenhain-request", type=_request_bytes, default=b"\x02",
                   help=r"request sent to heidenhain gauges (default \x02, Ctrl-B)")
    p.add_argument("--mitutoyo-request", type=_request_bytes, default=None,
                   help="request sent to mitutoyo ports (default: none, they stream)")
    p.add_argument("--poll-hz", type=float, default=0.0,
                   help="most requests per second to a polled gauge (default: as fast as it "
                        "answers)")
    p.add_argument("--fsync-s", type=float, default=1.0, help="seconds between fsyncs")
    p.add_argument("--status-s", type=float, default=0.5, help="seconds between status lines")
    p.add_argument("--summary", type=Path, default=None,
                   help="JSON summary (default CAMPAIGN/acquire-location<M>.json)")
    p.add_argument("--quiet", action="store_true", help="no status line or report")
    p.set_defaults(handler=_acquire)

    from aacmm_pin.simulate import DEFAULT_EFFECTS

    p = subparsers.add_parser(
        "fake-devices", help="a simulated arm and R-Test gauges on pseudo-terminals",
        description="Play one R-Test location of a simulated campaign on pseudo-terminals, print "
                    "their paths and the acquire command that reads them, run for --seconds.")
    p.add_argument("--location", type=int, default=1, help="R-Test location to play (1-4)")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated campaign")
    p.add_argument("--effects", default=",".join(DEFAULT_EFFECTS), help="simulator effects")
    p.add_argument("--postures", type=int, default=40, help="simulated postures per location")
    p.add_argument("--rate-hz", type=float, default=1000.0, help="arm lines per second")
    p.add_argument("--gauge-format", choices=("heidenhain", "mitutoyo"), default="heidenhain")
    p.add_argument("--dwell-s", type=float, default=0.05, help="seconds per posture")
    p.add_argument("--garbage", type=float, default=0.0, help="probability of garbage per line")
    p.add_argument("--checksum-errors", type=float, default=0.0,
                   help="probability of a checksum error per arm line")
    p.add_argument("--out-of-range", type=float, default=0.0,
                   help="probability of an out-of-range value per gauge line")
    p.add_argument("--timeouts", type=float, default=0.0,
                   help="silences per second and device, each --silence-s long")
    p.add_argument("--silence-s", type=float, default=0.3, help="length of an injected silence")
    p.add_argument("--nest", type=Path, default=None, help="nest file (default orthogonal)")
    p.add_argument("--arm", default="aacmm7", help="URDF path or embedded arm (default aacmm7)")
    p.add_argument("--seconds", type=float, default=60.0, help="run this long (default 60)")
    p.add_argument("--json", type=Path, default=None,
                   help="also write paths, played postures/readings and injected faults as JSON")
    p.set_defaults(handler=_fake_devices)

    iso = subparsers.add_parser(
        "iso10360", help="acceptance figures (ISO 10360-12 / ASME B89.4.22)",
        description="Point articulation (SPAT), P_Size/P_Form, L_Dia and E_UNI; formulas and "
                    "sources in aacmm_pin.iso10360.")
    sub = iso.add_subparsers(dest="figure", required=True)

    def common(q: argparse.ArgumentParser, params: bool = True) -> None:
        if params:
            q.add_argument("--params", type=Path, default=None,
                           help="parameters.json or calibration folder (default: nominal arm)")
        q.add_argument("--arm", default=None, help="URDF path or embedded arm")
        q.add_argument("--json", type=Path, default=None, help="also write the figures as JSON")

    q = sub.add_parser("spat", help="point articulation figures of a SPAT log, per location")
    q.add_argument("campaign", type=Path, help="campaign folder with spat.csv")
    q.add_argument("--no-rtest", action="store_true",
                   help="do not remove the R-Test displacement (conventional SPAT)")
    common(q)
    q.set_defaults(handler=_iso_spat)

    points_help = ("CSV with x_mm,y_mm,z_mm (points) or q1_deg..qn_deg (readouts, with --params); "
                   "optional column group")
    q = sub.add_parser("sphere", help="P_Size and P_Form from 25 points on a calibrated sphere")
    q.add_argument("points", type=Path, help=points_help)
    q.add_argument("--diameter-mm", type=float, required=True, help="calibrated sphere diameter")
    common(q)
    q.set_defaults(handler=_iso_sphere)

    q = sub.add_parser("ldia", help="L_Dia from 5 x 5 articulated points on a sphere")
    q.add_argument("points", type=Path, help=points_help + " (else consecutive groups)")
    q.add_argument("--group-size", type=int, default=5, help="points per articulation (5)")
    common(q)
    q.set_defaults(handler=_iso_ldia)

    q = sub.add_parser("euni", help="E_UNI from the length bar")
    q.add_argument("campaign", type=Path, help="campaign folder with lengthbar.csv and bar.csv")
    common(q)
    q.set_defaults(handler=_iso_euni)


Handler = Callable[[argparse.Namespace], int]
