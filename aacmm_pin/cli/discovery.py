"""The ``discover`` subcommand: find what a model is missing, printing each step as it is found.

The handler parses nothing itself: it calls :func:`aacmm_pin.analyses.discovery.discover` with the
parsed arguments and prints; the modules that import Pinocchio, scipy or matplotlib are imported
inside it.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aacmm_pin.analyses.false_alarm import FALSE_ALARM
from aacmm_pin.cli._options import (
    add_command,
    arm_option,
    campaign_inputs,
    effects_file_option,
    force_option,
    input_path,
    load_given_arm,
    max_nfev_option,
    no_rtest_option,
    noise_um,
    out_option,
    positive,
)
from aacmm_pin.cli.calibration_summary import print_sizes, print_urdf_loss
from aacmm_pin.data.output_claim import claim_output

if TYPE_CHECKING:
    from aacmm_pin.analyses.discovery_results import Discovery, Step
    from aacmm_pin.model.arm import Arm


def _discover(args: argparse.Namespace) -> int:
    with claim_output(args.out, args.force, campaign_inputs(args)):
        return _discover_into(args)  # the folder held from before the work


def _discover_into(args: argparse.Namespace) -> int:
    from aacmm_pin.analyses.discovery import FitCapReached, discover
    from aacmm_pin.data.campaign import StatedNoise, read_campaign
    from aacmm_pin.data.logs import noise_summary
    from aacmm_pin.extras import skipped
    from aacmm_pin.outputs.discovery_figures import write_discovery
    from aacmm_pin.units import UM

    arm = load_given_arm(args)
    effects = None if args.effects is None else [e.strip() for e in args.effects.split(",")
                                                 if e.strip()]
    campaign = read_campaign(args.campaign, arm=arm)
    given = {kind: value * UM for kind in ("rtest", "location", "point")
             if (value := getattr(args, f"sigma_{kind}_um")) is not None}
    try:  # the command line over campaign.json over the paper's values
        noise = dataclasses.replace(campaign.noise or StatedNoise(), **given)
    except ValueError as exc:
        raise SystemExit(f"discover: --sigma-*-um: {exc}") from exc
    try:
        result = discover(campaign, arm, args.start, effects=effects,
                          use_rtest=not args.no_rtest, max_steps=args.max_steps,
                          max_nfev=args.max_nfev, progress=True, noise=noise,
                          false_alarm=args.false_alarm,
                          on_start=functools.partial(
                              _print_discovery_start_sizes, args.start, arm,
                              noise_summary(campaign, noise if given else None)),
                          on_step=_print_discovery_step)  # results as they are found, figures after
    except FitCapReached as exc:  # no model to write
        print(exc, file=sys.stderr)
        return 1
    if not result.steps:
        print("nothing is missing")
    print(f"stopped: {result.stopped_because}")
    print(result.false_alarm_text())
    if left_out := result.left_out_text(named=effects is not None):  # their columns missing
        print(left_out)
    if result.widened:
        print(f"  with the default effects the residual stayed larger than the stated noise, "
              f"following no variable: "
              f"also tried {', '.join(result.widened)} (not offered by default), by the same tests")
    if result.refit_rule:
        _print_refits(result)
    if result.scan is not None:
        print(("unexplained: " if result.scan.unexplained else "residual: ") + result.scan.hint())
    sys.stdout.flush()
    no_figures = skipped("figures", "figures")  # without matplotlib: the results, no figures
    write_discovery(result, arm, args.out, force=args.force, campaign=campaign,
                    figures=no_figures is None)
    print(f"wrote {args.out / 'discovery.json'}, {'' if no_figures else 'figures and '}the final "
          f"model (CALDIR) in {args.out} ({result.runtime_s:.1f} s)")
    if no_figures:
        print(f"  {no_figures}")
    print_urdf_loss(args.out)
    if result.capped or result.failed:  # the steps so far are written; a fit ended the loop
        print(f"discover: {result.stopped_because}", file=sys.stderr)
        return 1
    return 0


def _print_refits(result: Discovery) -> None:
    """Print why steps were checked by refits, the refit errors and the steps refused."""
    errors = " -> ".join(f"{v * 1e3:.4f}" for v in result.refit_errors)
    print(f"refits: {result.refit_rule}" + (f"; refit error {errors} mm" if errors else ""))
    if result.refused:
        print("  refused (significant, refit error not lower): " + ", ".join(
            f"{'+'.join(r['terms']) or key} ({r['refit_error_um'] / 1e3:.4f} mm)"
            for key, r in result.refused.items()))


def _print_discovery_start(start: str, noise: str, heldout_rms: float, fit_rms: float,
                           bar_rms: float | None, size_factors: dict[str, float]) -> None:
    """Print the start model's line as soon as it is fitted, and the stated noise.

    RMS in m (the bar's is not shown); ``noise``: the stated noise the final residual is judged
    against (:func:`aacmm_pin.data.logs.noise_summary`).
    """
    print(f"start {start}: held-out RMS {heldout_rms * 1e6:.2f} um, fit RMS "
          f"{fit_rms * 1e6:.2f} um")
    print(f"  stated noise per coordinate: {noise}")
    if widened := {g: f for g, f in size_factors.items() if round(f, 2) > 1.0}:  # x1: no word
        print("  the fit rejects the arm's sizes of " + ", ".join(
            f"{g} (x{f:.3g})" for g, f in widened.items()) + ": held-out priors widened")
    sys.stdout.flush()


def _print_discovery_start_sizes(start: str, arm: Arm, noise: str, *values: Any) -> None:
    """Print the start model's line (:func:`_print_discovery_start`), then the sizes used."""
    _print_discovery_start(start, noise, *values)
    print_sizes(arm, indent="  ")


def _print_discovery_step(k: int, step: Step) -> None:
    """Print step k's lines as soon as it is found."""
    axes = f" on {', '.join(f'A{a}' for a in step.axes)}" if step.axes else ""
    print(f"step {k}: {step.effect}{axes}: held-out RMS {step.heldout_rms_before * 1e6:.2f} -> "
          f"{step.heldout_rms_after * 1e6:.2f} um, fit RMS {step.fit_rms_before * 1e6:.2f} -> "
          f"{step.fit_rms_after * 1e6:.2f} um")
    if step.refit_error_before is not None and step.refit_error_after is not None:
        print(f"  k-fold refits (mean position error): {step.refit_error_before * 1e3:.4f} -> "
              f"{step.refit_error_after * 1e3:.4f} mm")
    if step.bar_rms_before is not None:
        print(f"  length bar: {step.bar_summary()}")
    for line in (step.bar_disagreement(), step.selection_summary()):
        if line:
            print(f"  {line}")
    sys.stdout.flush()


def _rate(text: str) -> float:
    """Return a false-alarm rate in (0, 1) (an argparse type)."""
    value = positive()(text)
    if value >= 1.0:
        raise argparse.ArgumentTypeError(f"expected a rate below 1 (e.g. 0.01), got {text!r}")
    return float(value)


def add_discover_parser(subparsers: Any, arm: argparse.ArgumentParser) -> None:
    """Add ``discover`` (``arm``: the shared ``--arm`` parent)."""
    p = add_command(subparsers, "discover", "find what a model is missing: name the effect, add "
                                            "it, show the held-out gap shrink",
                    parents=[no_rtest_option("start without the R-Test displacements "
                                             "(location means)"),
                             arm, out_option(Path("discovery"), "output folder: discovery.json, "
                                                                "figures, final CALDIR"),
                             max_nfev_option(discovery=True), force_option(),
                             effects_file_option()])
    p.add_argument("campaign", type=input_path,
                   help="campaign folder (spat.csv and locations.csv, and/or points.csv; "
                        "lengthbar.csv and bar.csv)")
    p.add_argument("--start", choices=("dh", "proposed"), default="dh",
                   help="start model: dh (DH errors, tool) or proposed (also encoder maps)")
    p.add_argument("--effects", default=None,
                   help="comma-separated library effects to try, or 'all' (default: every "
                        "effect, built-in, installed plugins' and --effects-file's, but those "
                        "tried only when named: lateral_compliance)")
    p.add_argument("--max-steps", type=positive(int, zero=True), default=6,
                   help="most effects to add")
    p.add_argument("--false-alarm", type=_rate, default=FALSE_ALARM,
                   help="family-wise false-alarm rate of the whole discovery, spent once over "
                        "the steps' candidates and the residual scan: on a campaign where "
                        f"nothing is missing, the chance that anything is named or called "
                        f"unexplained (default {FALSE_ALARM:g})")
    for kind, what, default in (("rtest", "R-Test gauge reading", "2"),
                                ("location", "R-Test nest (zero) position", "3"),
                                ("point", "tool point of an instrument", "20")):
        p.add_argument(f"--sigma-{kind}-um", type=noise_um, default=None,
                       help=f"stated noise of a {what} per coordinate, um, which the final "
                            f"residual is judged against (default: campaign.json's noise_um, "
                            f"else its instrument's, else {default})")
    p.set_defaults(handler=_discover)


PARSERS: dict[str, Callable[[Any], None]] = {
    "discover": lambda subparsers: add_discover_parser(subparsers, arm_option())}
"""The command's parser builder (:func:`aacmm_pin.cli.build_parser` builds only the command given)."""
