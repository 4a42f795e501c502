"""The ``iso10360`` subcommand: acceptance figures ``spat``, ``sphere``, ``ldia`` and ``euni``.

The formulas and their sources are in :mod:`aacmm_pin.analyses.iso10360`, imported inside the handlers.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from aacmm_pin.cli._options import (
    FORCE_FILE,
    Handler,
    add_command,
    arm_option,
    claim_file,
    effects_file_option,
    force_option,
    input_path,
    json_option,
    load_given_arm,
    no_rtest_option,
    params_option,
    read_files,
    write_json,
)


def _load(args: argparse.Namespace) -> tuple[Any, Any]:
    """Return (arm, parameters): from --params, else the nominal --arm."""
    from aacmm_pin.model.parameters import Parameters
    from aacmm_pin.outputs.calibration_folder import read_calibration

    if getattr(args, "params", None):
        folder = read_calibration(args.params)
        arm = load_given_arm(args, args.arm or folder.parameters.arm,
                             error_frames=bool(folder.parameters.dh))
        folder.check(arm)
        return arm, folder.parameters
    arm = load_given_arm(args, args.arm or "aacmm7")
    return arm, Parameters.nominal(arm)


def _points(args: argparse.Namespace) -> tuple[Any, Any]:
    """Return (points (N, 3) in m, group column or None) of the POINTS file."""
    from aacmm_pin.analyses.iso10360 import read_points

    points, groups, readouts = read_points(args.points)
    if readouts is not None:
        from aacmm_pin.data.campaign import read_readouts
        from aacmm_pin.effects.calibrated import predict

        arm, params = _load(args)
        readouts = read_readouts(args.points, arm)  # against the arm: its number of axes
        points = predict(arm, params, readouts)
    return points, groups


def _finish(args: argparse.Namespace, text: str, data: dict[str, Any]) -> int:
    print(text)
    if args.json:
        write_json(args.json, data, args.force, _inputs(args))
    return 0


def _inputs(args: argparse.Namespace) -> list[Path]:
    """Return the files and folders the figure reads (kept from ``--json``)."""
    from aacmm_pin.data.output_claim import input_paths

    return input_paths(getattr(args, "points", None), *read_files(args),
                       campaigns=[getattr(args, "campaign", None)], calibrations=[args.params])


def _claiming(handler: Handler) -> Handler:
    """Return ``handler`` run with its ``--json`` file claimed first (refused before any work)."""
    def run(args: argparse.Namespace) -> int:
        with claim_file(args.json, args.force, _inputs(args)):
            return handler(args)

    run.__doc__ = handler.__doc__
    return run


def _spat(args: argparse.Namespace) -> int:
    from aacmm_pin.analyses.iso10360 import point_articulation, spat_centres
    from aacmm_pin.data.campaign import read_campaign

    arm, params = _load(args)
    centres = spat_centres(arm, params, read_campaign(args.campaign, arm=arm), use_rtest=not args.no_rtest)
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


def _sphere(args: argparse.Namespace) -> int:
    from aacmm_pin.analyses.iso10360 import probing_errors

    points, _ = _points(args)
    r = probing_errors(points, args.diameter_mm * 1e-3)
    note = "" if len(points) == 25 else f" (the test takes 25 points; {len(points)} given)"
    text = (f"least-squares sphere of {len(points)} points{note}: centre "
            + ", ".join(f"{v * 1e3:.6f}" for v in r.fit.centre)
            + f" mm, diameter {r.fit.diameter * 1e3:.6f} mm\n"
            f"P_Size {r.p_size * 1e6:+.2f} um, P_Form {r.p_form * 1e6:.2f} um")
    return _finish(args, text, r.to_dict())


def _ldia(args: argparse.Namespace) -> int:
    from aacmm_pin.analyses.iso10360 import articulated_location

    points, groups = _points(args)
    r = articulated_location(points, groups=groups, group_size=args.group_size)
    rows = [f"  centre {k + 1}: " + ", ".join(f"{v * 1e3:.6f}" for v in c) + " mm"
            for k, c in enumerate(r.centres)]
    text = "\n".join([f"{len(r.centres)} sphere centres:", *rows,
                      f"L_Dia {r.l_dia * 1e6:.2f} um (diameter of the smallest sphere enclosing "
                      "the centres)"])
    return _finish(args, text, r.to_dict())


def _euni(args: argparse.Namespace) -> int:
    from aacmm_pin.analyses.iso10360 import length_errors
    from aacmm_pin.data.campaign import read_campaign

    arm, params = _load(args)
    r = length_errors(arm, params, read_campaign(args.campaign, arm=arm))
    rows = [f"  placement {k}: " + ", ".join(f"{a}-{b} {e * 1e6:+.2f} um"
                                              for (a, b), e in zip(r.pairs, errs))
            for k, errs in zip(r.placements, r.errors)]
    text = "\n".join(["length errors (measured - calibrated):", *rows,
                      f"E_UNI {r.e_uni * 1e6:.2f} um (largest |error| of {r.errors.size} lengths)"])
    return _finish(args, text, r.to_dict())


def add_parsers(subparsers: Any) -> None:
    """Add the subcommand ``iso10360`` (with ``spat``, ``sphere``, ``ldia``, ``euni``) to ``subparsers``.

    Args:
        subparsers: what ``ArgumentParser.add_subparsers()`` returned; each leaf parser sets
            ``handler``, a function of the parsed arguments returning the exit status.
    """
    iso = add_command(
        subparsers, "iso10360", "acceptance figures (ISO 10360-12 / ASME B89.4.22)",
        description="Point articulation (SPAT), P_Size/P_Form, L_Dia and E_UNI; formulas and "
                    "sources in aacmm_pin.analyses.iso10360.")
    sub = iso.add_subparsers(dest="figure", required=True)
    common = [params_option(), effects_file_option(),
              arm_option(None, "URDF path or embedded arm name (default: the one the parameters "
                               "name, else aacmm7)"),
              json_option("the figures"), force_option(FORCE_FILE)]

    q = add_command(sub, "spat", "point articulation figures of a SPAT log, per location",
                    parents=[*common, no_rtest_option("do not remove the R-Test displacement "
                                                      "(conventional SPAT)")])
    q.add_argument("campaign", type=input_path, help="campaign folder with spat.csv")
    q.set_defaults(handler=_claiming(_spat))

    points_help = ("CSV with x_mm,y_mm,z_mm (points) or q1_deg..qn_deg (readouts, with --params); "
                   "optional column group")
    q = add_command(sub, "sphere", "P_Size and P_Form from 25 points on a calibrated sphere",
                    parents=common)
    q.add_argument("points", type=input_path, help=points_help)
    q.add_argument("--diameter-mm", type=float, required=True,
                   help="calibrated sphere diameter, mm")
    q.set_defaults(handler=_claiming(_sphere))

    q = add_command(sub, "ldia", "L_Dia from 5 x 5 articulated points on a sphere",
                    parents=common)
    q.add_argument("points", type=input_path, help=points_help + " (else consecutive groups)")
    q.add_argument("--group-size", type=int, default=5, help="points per articulation")
    q.set_defaults(handler=_claiming(_ldia))

    q = add_command(sub, "euni", "E_UNI from the length bar", parents=common)
    q.add_argument("campaign", type=input_path, help="campaign folder with lengthbar.csv and bar.csv")
    q.set_defaults(handler=_claiming(_euni))


PARSERS: dict[str, Callable[[Any], None]] = {"iso10360": add_parsers}
"""The command's parser builder (:func:`aacmm_pin.cli.build_parser` builds only the command given)."""
