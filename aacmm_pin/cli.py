"""The ``aacmm-pin`` command: one small function per subcommand over the public API."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from aacmm_pin.errors import AacmmError

Handler = Callable[[argparse.Namespace], int]


def _simulate(args: argparse.Namespace) -> int:
    from aacmm_pin.arm import load_arm
    from aacmm_pin.simulate import SimulationConfig, simulate_campaign, write_simulation

    effects = tuple(e.strip() for e in args.effects.split(",") if e.strip())
    config = SimulationConfig(seed=args.seed, effects=effects,
                              samples_per_location=args.samples_per_location,
                              samples_per_socket=args.samples_per_socket)
    sim = simulate_campaign(load_arm(args.arm), config)
    write_simulation(sim, args.out)
    spat = sim.campaign.spat
    n_spat = 0 if spat is None else len(spat.location)
    print(f"wrote {args.out}: {n_spat} SPAT samples at {len(sim.campaign.locations)} locations, "
          f"effects {', '.join(effects)}; truth in {Path(args.out) / 'truth.json'}")
    return 0


def _predict(args: argparse.Namespace) -> int:
    from aacmm_pin.arm import load_arm
    from aacmm_pin.campaign import read_readouts, write_points
    from aacmm_pin.kinematics import predict
    from aacmm_pin.parameters import check_against_arm, read_parameters

    params = read_parameters(args.params)
    arm = load_arm(args.arm or params.arm)
    check_against_arm(params, arm)
    points = predict(arm, params, read_readouts(args.readouts))
    write_points(args.out, points)
    print(f"wrote {len(points)} stylus centres (x_mm, y_mm, z_mm, r-CS) to {args.out}")
    return 0


def _identify(args: argparse.Namespace) -> int:
    from aacmm_pin.arm import load_arm
    from aacmm_pin.campaign import read_campaign
    from aacmm_pin.export import write_calibration
    from aacmm_pin.identify import identify

    arm = load_arm(args.arm)
    cal = identify(read_campaign(args.campaign), arm, model=args.model,
                   use_rtest=not args.no_rtest, loss=args.loss, step_deg=args.step_deg,
                   sigma=None if args.sigma_um is None else args.sigma_um * 1e-6,
                   progress=sys.stderr.isatty())
    write_calibration(cal, arm, args.out)
    _print_calibration(cal, args.out)
    return 0 if cal.success else 1


def _print_calibration(cal: object, out: Path) -> None:
    from aacmm_pin.identify import Calibration

    assert isinstance(cal, Calibration)
    state = "converged" if cal.success else "DID NOT CONVERGE"
    by_loc = ", ".join(f"{m}: {v * 1e6:.2f}" for m, v in cal.fit_rms_by_location().items())
    rtest = "with" if cal.use_rtest else "without"
    print(f"{cal.model} model ({rtest} R-Test): {state}, "
          f"{cal.n_determined} parameters determined, fit RMS {cal.fit_rms * 1e6:.2f} um "
          f"(by location {by_loc}), "
          f"{cal.runtime_s:.1f} s -> {out}")
    for line in cal.unidentifiable:
        print(f"  not identifiable: {line}")


def _validate(args: argparse.Namespace) -> int:
    import json

    from aacmm_pin.arm import load_arm
    from aacmm_pin.campaign import read_campaign
    from aacmm_pin.parameters import read_parameters
    from aacmm_pin.validate import validate

    params = read_parameters(args.caldir)
    result = validate(load_arm(params.arm), params, read_campaign(args.campaign))
    print(result.table())
    if args.json:
        Path(args.json).write_text(json.dumps(result.to_dict(), indent=2) + "\n")
    return 0


def _demo(args: argparse.Namespace) -> int:
    from aacmm_pin.demo import run_demo

    run_demo(args.out, seed=args.seed)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``aacmm-pin``."""
    from aacmm_pin.simulate import DEFAULT_EFFECTS, EFFECTS

    parser = argparse.ArgumentParser(
        prog="aacmm-pin",
        description="Calibrate articulated arm CMMs (Ibaraki & Saito, CIRP Annals 2023) on "
                    "Pinocchio.")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("simulate", help="write a simulated SPAT + length-bar campaign and its truth")
    p.add_argument("out", type=Path, help="campaign folder to write")
    p.add_argument("--seed", type=int, default=0, help="random seed (same seed, same files)")
    p.add_argument("--effects", default=",".join(DEFAULT_EFFECTS),
                   help=f"comma-separated effects from {', '.join(EFFECTS)} "
                        f"(default: {','.join(DEFAULT_EFFECTS)})")
    p.add_argument("--arm", default="aacmm7", help="URDF path or embedded arm (default aacmm7)")
    p.add_argument("--samples-per-location", type=int, default=200)
    p.add_argument("--samples-per-socket", type=int, default=40)
    p.set_defaults(handler=_simulate)

    p = sub.add_parser("predict", help="stylus centres (r-CS, mm) for encoder readouts")
    p.add_argument("params", type=Path, help="parameters.json or a calibration folder")
    p.add_argument("readouts", type=Path, help="CSV with columns q1_deg..qn_deg")
    p.add_argument("--out", type=Path, default=Path("points.csv"), help="output CSV")
    p.add_argument("--arm", default=None, help="override the URDF named in the parameters")
    p.set_defaults(handler=_predict)

    p = sub.add_parser("identify", help="identify DH errors (and encoder maps) from SPATs")
    p.add_argument("campaign", type=Path, help="campaign folder (spat.csv, locations.csv, ...)")
    p.add_argument("--model", choices=("dh", "proposed"), default="proposed",
                   help="dh: DH errors only; proposed: DH errors and encoder maps (default)")
    p.add_argument("--no-rtest", action="store_true",
                   help="conventional SPAT: each location's mean displacement for every sample")
    p.add_argument("--arm", default="aacmm7", help="URDF path or embedded arm (default aacmm7)")
    p.add_argument("--out", type=Path, default=Path("calibration"), help="calibration folder")
    p.add_argument("--loss", default="linear",
                   help="scipy loss: linear (default), soft_l1, huber, cauchy, arctan")
    p.add_argument("--sigma-um", type=float, default=None,
                   help="R-Test noise per coordinate in um (default: from the residuals)")
    p.add_argument("--step-deg", type=float, default=5.0, help="map node step (default 5)")
    p.set_defaults(handler=_identify)

    p = sub.add_parser("validate", help="length-bar errors of a calibration (paper Fig. 9)")
    p.add_argument("caldir", type=Path, help="calibration folder or parameters.json")
    p.add_argument("campaign", type=Path, help="campaign folder with lengthbar.csv and bar.csv")
    p.add_argument("--json", type=Path, default=None, help="also write the errors as JSON")
    p.set_defaults(handler=_validate)

    p = sub.add_parser("demo", help="the main job: simulate, identify the paper's 3 models, "
                                    "validate, figures")
    p.add_argument("--out", type=Path, default=Path("aacmm-pin-demo"), help="output folder")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated campaign")
    p.set_defaults(handler=_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``aacmm-pin``; return the exit status (errors are printed, not raised)."""
    args = build_parser().parse_args(argv)
    try:
        handler: Handler = args.handler
        return handler(args)
    except AacmmError as exc:
        print(f"aacmm-pin {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
