"""The calibration subcommands: simulate, predict, identify, validate, uncertainty, plan, demo, axes.

``discover`` is :mod:`aacmm_pin.cli.discovery` (its parser added here, in the same place).

Each handler parses nothing itself: it calls the public API with the parsed arguments and prints.
The modules that import Pinocchio, scipy or matplotlib are imported inside the handlers.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aacmm_pin.cli._options import (
    FORCE_FILE,
    add_command,
    arm_details,
    arm_option,
    arm_source,
    campaign_inputs,
    claim_file,
    effects_file_option,
    force_option,
    input_path,
    json_option,
    load_given_arm,
    max_nfev_option,
    model_option,
    no_rtest_option,
    noise_um,
    noise_um_or_zero,
    out_option,
    positive,
    read_files,
    seed_option,
    write_json,
)
from aacmm_pin.cli.calibration_summary import print_calibration, print_sizes
from aacmm_pin.data.output_claim import claim_output, input_paths
from aacmm_pin.units import DEFAULT_SIMULATOR_EFFECTS as DEFAULT_EFFECTS
from aacmm_pin.units import SIMULATOR_EFFECTS

if TYPE_CHECKING:
    from aacmm_pin.model.arm import Arm


def _simulate(args: argparse.Namespace) -> int:
    from aacmm_pin.analyses.simulate import SimulationConfig

    effects = tuple(e.strip() for e in args.effects.split(",") if e.strip())
    config = SimulationConfig(seed=args.seed, effects=effects,
                              samples_per_location=args.samples_per_location,
                              samples_per_socket=args.samples_per_socket, points=args.points)
    with claim_output(args.out, args.force, input_paths(*read_files(args))):
        return _simulate_into(args, config, effects)  # the folder held from before the work


def _simulate_into(args: argparse.Namespace, config: Any, effects: tuple[str, ...]) -> int:
    from aacmm_pin.analyses.simulate import simulate_campaign
    from aacmm_pin.outputs.simulation_folder import write_simulation
    from aacmm_pin.progress import phase

    if config.points:
        print(f"simulating {config.points} instrument points (seed {config.seed}) ...", flush=True)
    else:
        print(f"simulating {len(config.location_xy)} SPATs of {config.samples_per_location} "
              f"postures and {config.bar_placements} bar placements (seed {config.seed}; a few "
              "seconds) ...", flush=True)
    arm = load_given_arm(args)
    if args.compliance is not None:
        config = dataclasses.replace(config, compliance=_compliances(args.compliance, arm))
    phase("simulating")
    sim = simulate_campaign(arm, config)
    phase(f"writing {args.out}")
    write_simulation(sim, args.out, force=args.force)
    spat = sim.campaign.spat
    what = (f"{config.points} points" if spat is None else
            f"{len(spat.location)} SPAT samples at {len(sim.campaign.locations)} locations")
    print(f"wrote {args.out}: {what}, effects {', '.join(effects)}; truth in "
          f"{Path(args.out) / 'truth.json'}")
    return 0


def _compliances(text: str, arm: Arm) -> dict[int, float]:
    """Parse ``--compliance A2=4e-6,T4=1e-5``: axis (``A<k>`` or joint name) -> rad per N m."""
    out: dict[int, float] = {}
    for item in (i.strip() for i in text.split(",") if i.strip()):
        name, _, value = item.partition("=")
        name = name.strip()
        if name in arm.axis_names:
            axis = arm.axis_names.index(name) + 1
        elif name[:1] in "Aa" and name[1:].isdigit() and 1 <= int(name[1:]) <= arm.n_axes:
            axis = int(name[1:])
        else:
            raise ValueError(f"--compliance {item}: {name!r} is no axis of {arm.name} (A1..A"
                             f"{arm.n_axes} or a joint: {', '.join(arm.axis_names)})")
        try:
            k = float(value)
        except ValueError:
            raise ValueError(f"--compliance {item}: write AXIS=K, K in rad per N m") from None
        if not (math.isfinite(k) and k >= 0):
            raise ValueError(f"--compliance {item}: K must be a finite number >= 0 rad per N m")
        out[axis] = k
    return out


def _predict(args: argparse.Namespace) -> int:
    inputs = input_paths(args.readouts, *read_files(args), calibrations=[args.params])
    with claim_output(args.out, args.force, inputs, folder=False):  # before reading anything
        return _predict_into(args, inputs)


def _predict_into(args: argparse.Namespace, inputs: list[Path]) -> int:
    from aacmm_pin.data.campaign import (
        read_id_columns,
        read_sample_columns,
        read_tool_column,
        write_points,
    )
    from aacmm_pin.data.output_file import output_file
    from aacmm_pin.effects.calibrated import predict
    from aacmm_pin.model.samples import Samples
    from aacmm_pin.outputs.calibration_folder import read_calibration
    from aacmm_pin.outputs.instrument_frames import frame_of, to_instrument_frame

    folder = read_calibration(args.params)
    params = folder.parameters
    arm = load_given_arm(args, args.arm or params.arm, error_frames=bool(params.dh))
    folder.check(arm)
    q, columns = read_sample_columns(args.readouts, arm)
    tool = args.tool if args.tool is not None or arm.n_tools == 1 else read_tool_column(
        args.readouts, arm)
    samples = Samples(arm, q, columns=columns, files=(Path(args.readouts).name,))
    points = predict(arm, params, q, samples, tool=tool)
    where = "stylus centres (x_mm, y_mm, z_mm, r-CS)"
    if args.frame is not None:  # the instrument's frame: r-CS -> MT-CS -> the group's frame
        rot, trans = frame_of(folder.report, args.frame, str(args.params))
        points = to_instrument_frame(points @ params.rotation().T + params.translation, rot, trans)
        where = f"points (x_mm, y_mm, z_mm) in the frame of instrument group {args.frame}"
    keep = read_id_columns(args.readouts, arm)
    with output_file(args.out, args.force, inputs) as tmp:
        write_points(tmp, points, keep)  # id cells made safe for spreadsheets
    kept = f" after the input's {', '.join(keep)} columns" if keep else ""
    print(f"wrote {len(points)} {where}{kept} to {args.out}")
    return 0


def _identify(args: argparse.Namespace) -> int:
    from aacmm_pin.errors import ArgumentError
    from aacmm_pin.model.encoder_map import step_problem

    if (why := step_problem(args.step_deg)) is not None:  # before any work
        raise ArgumentError(f"--step-deg: {why}")
    with claim_output(args.out, args.force, campaign_inputs(args)):
        return _identify_into(args)  # the folder held from before the work


def _identify_into(args: argparse.Namespace) -> int:
    from aacmm_pin.analyses.model_choice import AUTO, identify_model
    from aacmm_pin.data.campaign import read_campaign
    from aacmm_pin.data.logs import noise_summary
    from aacmm_pin.effects.registry import term_from_key
    from aacmm_pin.effects.term_axes import check_terms
    from aacmm_pin.outputs.export import write_calibration
    from aacmm_pin.progress import phase

    terms = tuple(term_from_key(k.strip()) for k in (args.terms or "").split(",") if k.strip())
    phase("loading the arm")
    arm = load_given_arm(args)
    check_terms(terms, arm, "--terms")
    print_sizes(arm)
    phase(f"reading {args.campaign}")
    campaign = read_campaign(args.campaign, arm=arm)
    print("stated noise per coordinate: " + (f"{args.sigma_um:g} um (--sigma-um)" if args.sigma_um
                                             is not None else noise_summary(campaign, None,
                                                                            args.use_bar)))
    cal, choice = identify_model(campaign, arm, args.model, extensions=terms,
                                 use_rtest=not args.no_rtest, loss=args.loss,
                                 step_deg=args.step_deg,
                                 sigma=None if args.sigma_um is None else args.sigma_um * 1e-6,
                                 max_nfev=args.max_nfev, progress=True, use_bar=args.use_bar,
                                 nests=args.nests, robust=args.robust)
    phase(f"writing {args.out}")
    write_calibration(cal, arm, args.out, force=args.force,
                      report=None if choice is None else {"model_choice": choice.to_dict()},
                      campaign=campaign)
    print_calibration(cal, args.out)
    if choice is not None and (advice := choice.advice(args.model == AUTO)):
        print(f"  {advice}")
    return 0 if cal.success else 1


def _validate(args: argparse.Namespace) -> int:
    inputs = input_paths(*read_files(args), calibrations=[args.caldir],
                         campaigns=[args.campaign])
    with claim_file(args.json, args.force, inputs):  # before the work, not after it
        return _validate_into(args, inputs)


def _validate_into(args: argparse.Namespace, inputs: list[Path]) -> int:
    from aacmm_pin.analyses.validation import validate, validate_points
    from aacmm_pin.data.campaign import read_campaign
    from aacmm_pin.model.arm import load_arm
    from aacmm_pin.outputs.calibration_folder import read_calibration

    cal = read_calibration(args.caldir)
    params = cal.parameters
    arm = load_arm(params.arm, error_frames=bool(params.dh))  # calibrated.urdf: tool, error frames written
    cal.check(arm)  # exactly as predict does
    campaign = read_campaign(args.campaign, arm=arm)
    data: dict[str, Any] = {}
    if campaign.lengthbar is not None or campaign.points is None:
        result = validate(arm, params, campaign, cal.accuracy)
        print(result.table())
        data = result.to_dict()
        if cal.fitted_with_bar:
            data["note"] = ("this calibration was fitted with a length bar (identify --use-bar): on "
                            "that bar's campaign these errors and the scatter check are not an "
                            "independent test")
            print(f"NOTE: {data['note']}")
    if campaign.points is not None:
        points = validate_points(arm, params, campaign)
        print(points.table())
        data["points"] = points.to_dict()
    if args.json:
        write_json(args.json, data, args.force, inputs)
    return 0


def _uncertainty(args: argparse.Namespace) -> int:
    from aacmm_pin.errors import ArgumentError
    from aacmm_pin.machine import check_workers

    try:
        check_workers(args.workers or 1)  # before any work
    except ArgumentError as exc:
        raise ArgumentError(f"--{exc}") from None
    with claim_output(args.out, args.force, campaign_inputs(args)):
        return _uncertainty_into(args)  # the folder held from before the work


def _uncertainty_into(args: argparse.Namespace) -> int:
    import numpy as np

    from aacmm_pin.analyses.uncertainty import monte_carlo
    from aacmm_pin.data.campaign import StatedNoise, read_campaign
    from aacmm_pin.fit.identification import identify
    from aacmm_pin.outputs.uncertainty_folder import write_uncertainty
    from aacmm_pin.units import UM

    arm = load_given_arm(args)
    print_sizes(arm)
    campaign = read_campaign(args.campaign, arm=arm)
    cal = identify(campaign, arm, model=args.model, use_rtest=not args.no_rtest,
                   max_nfev=args.max_nfev, progress=True)
    stated = cal.stated_noise or campaign.noise or StatedNoise()  # what the fit stated
    rtest_um = stated.rtest / UM if args.sigma_rtest_um is None else args.sigma_rtest_um
    location_um = stated.location / UM if args.sigma_location_um is None else args.sigma_location_um
    mc = monte_carlo(cal, campaign, args.trials, sigma_rtest=rtest_um * UM,
                     sigma_location=location_um * UM, workers=args.workers,
                     seed=args.seed, progress=True)
    out = Path(args.out)
    no_figures = write_uncertainty(cal, arm, campaign, mc, out, args.force)
    ratio = mc.ratio()
    ratio = ratio[np.isfinite(ratio)]
    shaken = "" if campaign.spat is None else (f", sigma R-Test {rtest_um:g} um, sigma "
                                               f"location {location_um:g} um")
    if campaign.points is not None:
        shaken += ", points by their stated noise"
    print(f"{mc.trials} Monte Carlo trials ({mc.converged} converged){shaken} -> {out}")
    if no_figures:
        print(f"  {no_figures}")
    print(f"Monte Carlo / linearised std: median {np.median(ratio):.3f}, "
          f"{np.mean(np.abs(ratio - 1) <= 0.2):.0%} of {ratio.size} identified values within 20%")
    if mc.length_std is not None:
        lin = mc.length_linear_std if mc.length_linear_std is not None else mc.length_std
        assert campaign.lengthbar is not None
        pairs = [f"{a}-{b}" for a, b in campaign.bar]
        placements = list(dict.fromkeys(int(k) for k in campaign.lengthbar.placement))
        print("length-error std (um), Monte Carlo / linearised, per bar placement:")
        for i, k in enumerate(placements):
            cells = ", ".join(f"{pair} {mc.length_std[i, j] * 1e6:.2f} / {lin[i, j] * 1e6:.2f}"
                              for j, pair in enumerate(pairs))
            print(f"  placement {k}: {cells}")
    disagree = mc.disagreements()
    if disagree:
        print(f"differ by more than {mc.agree_limit:.0%}: {', '.join(disagree[:12])}"
              f"{' ...' if len(disagree) > 12 else ''}")
    if note := mc.resolution_note():
        print(f"note: {note}")
    return 0


def _plan(args: argparse.Namespace) -> int:
    inputs = campaign_inputs(args)
    with claim_file(args.json, args.force, inputs):  # before the minutes of work, not after them
        return _plan_into(args, inputs)


def _plan_into(args: argparse.Namespace, inputs: list[Path]) -> int:
    from aacmm_pin.analyses.planning import candidate_grid, check_plannable, plan
    from aacmm_pin.data.campaign import read_campaign
    from aacmm_pin.fit.identification import identify

    arm = load_given_arm(args)
    print_sizes(arm)
    campaign = read_campaign(args.campaign, arm=arm)
    check_plannable(campaign)  # before minutes of identification
    cal = identify(campaign, arm, model=args.model, max_nfev=args.max_nfev,
                   progress=True)
    heights = [float(h) * 1e-3 for h in args.heights_mm.split(",")]
    grid = candidate_grid(campaign, args.grid, args.spacing_mm, heights, unit=1e-3)
    result = plan(cal, campaign, grid=grid, n_postures=args.postures, seed=args.seed,
                  progress=True)
    print(result.table(args.top))
    if args.json:
        write_json(args.json, result.to_dict(), args.force, inputs)
    return 0


def _demo(args: argparse.Namespace) -> int:
    from aacmm_pin.outputs.demo import run_demo

    run_demo(args.out, seed=args.seed, force=args.force)
    return 0


def _axes(args: argparse.Namespace) -> int:
    import numpy as np

    arm = load_given_arm(args)
    print(f"{arm.name}: {arm.n_axes} axes; readout columns q1_deg..q{arm.n_axes}_deg in this order "
          "(or <joint>_deg, any order)")
    print_sizes(arm)
    for n, (name, (lo, hi)) in enumerate(zip(arm.axis_names, np.degrees(arm.joint_limits)), 1):
        coupled = arm.couplings.get(name)
        note = f"  coupled: {coupled.formula()} (no readout needed)" if coupled else ""
        print(f"  {f'q{n}_deg':<7} joint {name:<12} limits {lo:8.1f} .. {hi:7.1f} deg{note}")
    print(f"tools ({arm.n_tools}; points.csv column 'tool'"
          f"{', optional' if arm.n_tools == 1 else ''}):")
    for name, joint, link in zip(arm.tool_names, arm.tool_joints, arm.tool_links):
        print(f"  {name:<12} joint {joint:<16} link {link:<16} unknowns {joint}_x, _y, _z")
    if arm.off_chain:
        print(f"held fixed (on no tool's chain): {', '.join(arm.off_chain)}")
    print(f"error frames ({len(arm.error_names)}): {', '.join(arm.error_names)}")
    if args.write_error_frames is not None:
        _write_completed(arm, args.write_error_frames, args.force)
    return 0


def _write_completed(arm: Arm, out: Path, force: bool) -> None:
    """Write the arm's URDF as the package uses it: its added tool joint and error frames."""
    from aacmm_pin.data.output_file import output_file
    from aacmm_pin.outputs.urdf_resources import rebase_resources

    tree = arm.urdf_tree()
    rebase_resources(tree.root, Path(str(arm.source)).parent, Path(out).absolute().parent)
    with output_file(out, force, [Path(str(arm.source))]) as tmp:
        Path(tmp).write_text(tree.xml(), encoding="utf-8")
    added = len(arm.completion.error_frames)
    print(f"wrote {out}: {arm.n_axes} axes, {len(arm.error_names)} error frames"
          f"{f' ({added} added)' if added else ''}, tool joints {', '.join(arm.tool_joints)}")


def add_parsers(subparsers: Any) -> None:
    """Add axes, simulate, predict, identify, validate, uncertainty, plan and demo.

    Args:
        subparsers: what ``ArgumentParser.add_subparsers()`` returned; each parser sets
            ``handler``, a function of the parsed arguments returning the exit status.
    """
    for build in PARSERS.values():
        build(subparsers)


def _add_axes_parser(subparsers: Any) -> None:
    """Add ``axes`` to ``subparsers``."""
    p = add_command(subparsers, "axes", "list an arm's axes in readout-column order (depth-first "
                    "over its tree), their limits, its tools and its error frames",
                    parents=[force_option(FORCE_FILE)])
    p.add_argument("arm", nargs="?", type=arm_source, default="aacmm7", metavar="URDF",
                   help="URDF path or embedded arm name (aacmm7, ur5, wam7)")
    arm_details(p)
    p.add_argument("--write-error-frames", type=Path, default=None, metavar="OUT.urdf",
                   help="write the URDF as the package uses it: with the tool joint and error "
                        "frames it adds in memory (a URDF without them), their values zero")
    p.set_defaults(handler=_axes)


def _add_simulate_parser(subparsers: Any) -> None:
    """Add ``simulate`` to ``subparsers``."""
    p = add_command(subparsers, "simulate",
                    "write a simulated SPAT + length-bar campaign and its truth",
                    parents=[seed_option("random seed (same seed, same files)"), arm_option(),
                             force_option()])
    p.add_argument("out", type=Path, help="campaign folder to write")
    p.add_argument("--effects", default=",".join(DEFAULT_EFFECTS),
                   help=f"comma-separated effects from {', '.join(SIMULATOR_EFFECTS)}")
    p.add_argument("--samples-per-location", type=positive(int), default=200,
                   help="SPAT samples per R-Test location")
    p.add_argument("--samples-per-socket", type=positive(int), default=40,
                   help="length-bar postures per socket")
    p.add_argument("--points", type=positive(int, zero=True), default=0,
                   help="instead of SPATs and the bar: this many tool points of a tracker or "
                        "motion capture (every tool of a tree, alternately; 20 um noise)")
    p.add_argument("--compliance", default=None, metavar="AXIS=K,...",
                   help="the hidden joint compliances of the effect compliance, rad per N m, by "
                        "axis (A2) or joint name (T4), e.g. T2=4e-6,T4=1e-5 (default A2=4e-6,"
                        "A4=6e-6)")
    p.set_defaults(handler=_simulate)


def _add_predict_parser(subparsers: Any) -> None:
    """Add ``predict`` to ``subparsers``."""
    p = add_command(subparsers, "predict", "stylus centres (r-CS, mm) for encoder readouts",
                    parents=[out_option(Path("points.csv"), "output CSV"),
                             arm_option(None, "override the URDF named in the parameters"),
                             effects_file_option(), force_option(FORCE_FILE)])
    p.add_argument("params", type=input_path, help="parameters.json or a calibration folder")
    p.add_argument("readouts", type=input_path,
                   help="CSV with columns q1_deg..qn_deg (or one <joint>_deg per axis)")
    p.add_argument("--tool", default=None,
                   help="the tool whose point to predict, for an arm with several (see axes); "
                        "default: the readouts' tool column")
    p.add_argument("--frame", type=int, default=None, metavar="GROUP",
                   help="write the points in the frame of this instrument group (the group "
                        "column of points.csv), with the frame the calibration fitted, to compare "
                        "with that instrument's data directly; default: the arm's r-CS")
    p.set_defaults(handler=_predict)



def _add_identify_parser(subparsers: Any) -> None:
    """Add ``identify`` to ``subparsers``."""
    p = add_command(subparsers, "identify", "identify DH errors (and encoder maps) from SPATs, "
                                            "absolute points (points.csv) or both",
                    parents=[model_option(("auto", "dh", "proposed"),
                                          "dh: DH errors only; proposed: DH errors and encoder "
                                          "maps; auto: proposed on SPATs, and on points alone "
                                          "the one that predicts left-out poses better (dh "
                                          "unless the maps pay; both held-out RMS printed)",
                                          "auto"),
                             no_rtest_option("conventional SPAT: each location's mean "
                                             "displacement for every sample (SPAT only)"),
                             arm_option(), out_option(Path("calibration"), "calibration folder"),
                             max_nfev_option(), force_option(), effects_file_option()])
    p.add_argument("campaign", type=input_path,
                   help="campaign folder (spat.csv and locations.csv, and/or points.csv; "
                        "lengthbar.csv and bar.csv)")
    p.add_argument("--loss", default="linear",
                   help="scipy loss of every solve: linear, soft_l1, huber, cauchy, arctan (for "
                        "outliers use --robust)")
    p.add_argument("--robust", action="store_true",
                   help="reject outlier samples (Huber then hard rejection beyond 5 robust sigma "
                        "of the whitened residual norm; listed in report.json 'outliers')")
    p.add_argument("--sigma-um", type=noise_um, default=None,
                   help="stated noise per coordinate, um, of the R-Test readings or, on points "
                        "alone, of points without a sigma_um column: the residual is judged "
                        "against it (default: campaign.json's noise_um, else its instrument's, "
                        "else 2 um R-Test, 20 um points; printed)")
    p.add_argument("--step-deg", type=positive(), default=5.0, help="map node step, deg")
    p.add_argument("--terms", default=None, metavar="KEYS",
                   help="comma-separated effect terms to estimate beside the model, as "
                        "parameters.json names them (e.g. compliance[A2],thermal; a plugin's "
                        "too: see --effects-file)")
    p.add_argument("--nests", choices=("auto", "estimate", "fixed"), default="auto",
                   help="R-Test nest offsets: estimated with their 3 um prior, fixed at the "
                        "measured positions, or auto: estimated only when the model's residual "
                        "matches the stated R-Test noise")
    p.add_argument("--use-bar", action="store_true",
                   help="fit the length-bar readouts too (a calibration input: socket positions "
                        "estimated, calibrated lengths as residuals); validate then on another "
                        "bar placement set")
    p.set_defaults(handler=_identify)


def _add_validate_parser(subparsers: Any) -> None:
    """Add ``validate`` to ``subparsers``."""
    p = add_command(subparsers, "validate", "length-bar errors (paper Fig. 9) or point errors of "
                                            "a calibration on a test campaign",
                    parents=[json_option("the errors"), effects_file_option(),
                             force_option(FORCE_FILE)],
                    description="Test a calibration on a campaign. With lengthbar.csv and bar.csv: "
                                "the error of every calibrated socket distance per bar placement "
                                "(paper Fig. 9) and the readouts' scatter about their sockets. "
                                "With points.csv: the error of every point (mean, RMS, max). "
                                "Without SPAT the lowest instrument group is predicted in the "
                                "calibration's own frame (base_to_mt of parameters.json), so the "
                                "error is absolute; every other group has a frame of its own, "
                                "which is fitted to the predicted points first (six unknowns, "
                                "the groups are named in the output): its error is that of the "
                                "shape only. predict --frame GROUP writes predicted points in a "
                                "group's frame as the calibration fitted it.")
    p.add_argument("caldir", type=input_path, help="calibration folder or parameters.json")
    p.add_argument("campaign", type=input_path,
                   help="campaign folder with lengthbar.csv and bar.csv, and/or points.csv")
    p.set_defaults(handler=_validate)


def _add_uncertainty_parser(subparsers: Any) -> None:
    """Add ``uncertainty`` to ``subparsers``."""
    p = add_command(subparsers, "uncertainty", "Monte Carlo uncertainty of every identified value",
                    parents=[model_option(),
                             no_rtest_option("conventional SPAT (location means)"), arm_option(),
                             seed_option("seed of the first trial (trial i uses seed + i)"),
                             out_option(Path("uncertainty"), "output folder"), max_nfev_option(),
                             force_option()])
    p.add_argument("campaign", type=input_path, help="campaign folder")
    p.add_argument("--trials", type=positive(int), default=100, help="Monte Carlo trials")
    p.add_argument("--workers", type=positive(int), default=None,
                   help="local processes, at most one a core (default: all cores)")
    p.add_argument("--sigma-rtest-um", type=noise_um_or_zero, default=None,
                   help="R-Test reading sigma, um (default: the stated noise the fit used: "
                        "campaign.json's, else 2)")
    p.add_argument("--sigma-location-um", type=noise_um_or_zero, default=None,
                   help="R-Test location sigma, um (default: the stated noise the fit used: "
                        "campaign.json's, else 3)")
    p.set_defaults(handler=_uncertainty)


def _add_plan_parser(subparsers: Any) -> None:
    """Add ``plan`` to ``subparsers``."""
    p = add_command(subparsers, "plan", "where to measure next: rank candidate SPATs",
                    parents=[model_option(("proposed",), "the model whose uncertainty is planned "
                                                         "for (DH errors and encoder maps)"),
                             arm_option(), seed_option("seed of the candidate postures' IK starts"),
                             json_option("the plan"), max_nfev_option(),
                             force_option(FORCE_FILE)])
    p.add_argument("campaign", type=input_path, help="campaign folder")
    p.add_argument("--grid", type=positive(int), default=3, help="candidate nests per side")
    p.add_argument("--spacing-mm", type=positive(zero=True), default=260.0,
                   help="half width of the candidate grid around the nests' centre, mm")
    p.add_argument("--heights-mm", default="0,250",
                   help="comma-separated candidate heights above the nests, mm")
    p.add_argument("--postures", type=positive(int), default=40, help="postures per candidate SPAT")
    p.add_argument("--top", type=positive(int), default=10, help="candidates to print")
    p.set_defaults(handler=_plan)


def _add_demo_parser(subparsers: Any) -> None:
    """Add ``demo`` to ``subparsers``."""
    p = add_command(subparsers, "demo", "the main job: simulate, identify the paper's 3 models, "
                                        "validate, figures",
                    parents=[out_option(Path("aacmm-pin-demo"), "output folder"),
                             seed_option("seed of the simulated campaign"), force_option()])
    p.set_defaults(handler=_demo)


PARSERS: dict[str, Callable[[Any], None]] = {
    "axes": _add_axes_parser, "simulate": _add_simulate_parser, "predict": _add_predict_parser,
    "identify": _add_identify_parser, "validate": _add_validate_parser,
    "uncertainty": _add_uncertainty_parser, "plan": _add_plan_parser, "demo": _add_demo_parser}
"""Each command's parser builder, in the order of ``aacmm-pin --help``."""
