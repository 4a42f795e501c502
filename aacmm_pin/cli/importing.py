"""The ``import-points`` subcommand: tracker or motion-capture CSV files to a points campaign.

:func:`aacmm_pin.data.point_import.import_points` on the command line: the column mapping by
options (``--joints``, ``--point``, ``--units``, ``--angles``) or a preset recognised from the
header (``--format jacobi2025``, the shipped laser-tracker data); the folder it writes is read by
``identify``, ``discover`` and ``validate`` as it is.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from aacmm_pin.cli._options import (
    ARM_HELP,
    add_command,
    arm_details,
    arm_source,
    force_option,
    input_path,
    load_given_arm,
    noise_um,
)

AUTO = "auto"
"""``--format`` value: the preset the header is, unless ``--joints`` and ``--point`` are given."""


def _format(args: argparse.Namespace, arm: Any = None) -> Any:
    """Return the PointFormat the options give, or None (a preset from each file's header).

    ``arm``: the arm ``--arm`` names, or None; without ``--joints`` its independent joints' names
    are the joint columns.
    """
    from aacmm_pin.data.point_import import (
        PRESETS,
        PointFormat,
        parse_columns,
        read_header,
    )

    by_columns = args.joints is not None or args.point is not None
    if by_columns and args.format != AUTO:
        raise ValueError("--format: give either a preset or --joints and --point, not both")
    if by_columns:
        if args.point is None or (args.joints is None and arm is None):
            raise ValueError("--joints, --point: give both (e.g. --joints q1..q6 --point x,y,z; "
                             "with --arm, --joints defaults to the arm's joint names)")
        point = _point_columns(args.point, [Path(s) for s in args.sources])
        joints = (parse_columns(args.joints) if args.joints is not None else
                  tuple(arm.axis_names[k] for k in range(arm.n_axes) if not arm.coupled[k]))
        return PointFormat(joints, point, args.units or "mm", args.angles or "deg",
                           angles_stated=args.angles is not None, tool=args.tool, pose=args.pose)
    if args.tool is not None or args.pose is not None:
        raise ValueError("--tool, --pose: they go with --point (a preset names its columns)")
    if args.units is not None or args.angles is not None:
        raise ValueError("--units, --angles: they go with --joints and --point (a preset states "
                         "its units)")
    if args.format == AUTO:
        return None
    for source in args.sources:
        header = read_header(Path(source)) or []
        if PRESETS[args.format](header) is None:
            raise ValueError(f"{source}:1: the header is not the {args.format} format "
                             f"({', '.join(header[:10])}...); give --joints and --point")
    return None


def _point_columns(text: str, sources: list[Path]) -> tuple[tuple[str, str | None], ...]:
    """Return ``--point``'s columns, read against every source's header.

    ``A-B`` is a difference unless the header has a column ``A-B``; a source whose header reads
    it otherwise than the first one's is named (line 1).
    """
    from aacmm_pin.data.point_import import parse_point, read_header

    def show(cols: tuple[tuple[str, str | None], ...]) -> str:
        return ", ".join(a if b is None else f"{a} minus {b}" for a, b in cols)

    first = parse_point(text, read_header(sources[0]) or [])
    for source in sources[1:]:
        if (here := parse_point(text, read_header(source) or [])) != first:
            raise ValueError(f"{source}:1: --point {text!r} reads as {show(here)} here but as "
                             f"{show(first)} in {sources[0]} (a column named with '-' in one "
                             "header only): import the files separately or rename the column")
    return first


def _import_points(args: argparse.Namespace) -> int:
    """Handler of ``aacmm-pin import-points``."""
    from aacmm_pin.data.output_claim import claim_output
    from aacmm_pin.data.point_import import import_points
    from aacmm_pin.units import UM

    sources = [Path(s) for s in args.sources]
    with claim_output(args.out, args.force, sources):  # the folder held before any reading
        arm = None if args.arm is None else load_given_arm(args)
        result = import_points(sources, args.out, _format(args, arm),
                               sigma=None if args.sigma_um is None else args.sigma_um * UM,
                               one_frame=args.one_frame, force=args.force,
                               instrument=args.instrument, arm=arm)
    for f in result.files:
        print(f"read {len(f.log.q)} points of {f.log.q.shape[1]} axes from {f.path}")
    print(f"format {result.format.describe()}")
    if (offset := result.mean_offset) is not None:
        print(f"mean distance between nominal and measured points: {offset * 1e3:.4f} mm "
              "(the uncalibrated error)")
    points = result.campaign.points
    assert points is not None
    groups = len(set(points.group.tolist()))
    noise = result.campaign.noise
    stated = (f"stated point noise {noise.point / UM:g} um per coordinate"
              + (f" ({noise.instrument})" if noise.instrument else "") if noise is not None
              else "no stated noise (the package's default applies)")
    poses = (f", {len(set(points.columns['pose'].tolist()))} poses of several points: column "
             "pose" if "pose" in points.columns else "")
    print(f"wrote {args.out}: points.csv ({len(points.q)} points, {groups} instrument "
          f"set-up{'s' if groups > 1 else ''}{poses}), campaign.json ({stated}, provenance)")
    print(f"next: aacmm-pin identify {args.out} --arm {args.arm or 'URDF'}")
    return 0


def add_parsers(subparsers: Any) -> None:
    """Add the ``import-points`` subcommand to ``aacmm-pin``'s subparsers.

    Args:
        subparsers: what ``ArgumentParser.add_subparsers()`` returned.
    """
    p = add_command(subparsers, "import-points",
                    "convert laser-tracker or motion-capture CSV files into a points campaign",
                    parents=[force_option()],
                    description="Convert laser-tracker or motion-capture CSV files (joint angles "
                                "and measured tool points, one row per pose) into a points "
                                "campaign folder that identify, discover and validate read: "
                                "points.csv (mm, degrees) and campaign.json (stated noise, "
                                "provenance). The columns come from --joints and --point, or "
                                "from a preset recognised by the header.")
    p.add_argument("sources", nargs="+", type=input_path, metavar="SOURCE",
                   help="CSV file(s); each is one instrument set-up (frame) unless --one-frame")
    p.add_argument("--out", type=Path, required=True, metavar="FOLDER",
                   help="campaign folder to write")
    p.add_argument("--format", choices=(AUTO, "jacobi2025"), default=AUTO,
                   help="a preset of columns and units; auto: recognised from the header "
                        "(jacobi2025: step_order,x_t..z_t,x_dif..z_dif,joint_1..joint_n, the "
                        "shared laser-tracker data)")
    p.add_argument("--joints", default=None, metavar="COLUMNS",
                   help="joint-angle columns in axis order, e.g. 'q1..q6' or 'a1,a2,a3,a4,a5,a6'")
    p.add_argument("--point", default=None, metavar="X,Y,Z",
                   help="measured point columns, e.g. 'x,y,z'; 'a-b' subtracts column b from a "
                        "(e.g. nominal minus deviation)")
    p.add_argument("--units", choices=("mm", "m"), default=None,
                   help="unit of the point columns (default mm)")
    p.add_argument("--angles", choices=("deg", "rad"), default=None,
                   help="unit of the joint columns (default deg)")
    p.add_argument("--sigma-um", type=noise_um, default=None, metavar="UM",
                   help="the instrument's standard uncertainty of a point per coordinate, um "
                        "(default: the preset's, else --instrument's; else none stated and "
                        "identify uses 20 um)")
    p.add_argument("--instrument", choices=("laser-tracker", "motion-capture"), default=None,
                   help="the kind of instrument, written to campaign.json: its stated point noise "
                        "(20 um a laser tracker, 100 um motion capture) unless --sigma-um or the "
                        "preset states one")
    p.add_argument("--tool", default=None, metavar="COLUMN",
                   help="the column naming the tool (marker) each row measures, one of the arm's "
                        "tools (aacmm-pin axes ARM lists them); written as points.csv's tool")
    p.add_argument("--pose", default=None, metavar="COLUMN",
                   help="the column naming each row's pose (rows with one label are one pose, "
                        "e.g. two markers; default: identical readouts in consecutive rows); "
                        "written as points.csv's pose, numbered 1, 2, ...")
    p.add_argument("--arm", type=arm_source, default=None, metavar="URDF",
                   help=ARM_HELP + "; given, --joints are its independent joints in order (default: "
                        "their names; a coupled joint needs no column), points.csv names its "
                        "columns <joint>_deg and the tools are checked")
    arm_details(p)
    p.add_argument("--one-frame", action="store_true",
                   help="the files share one instrument frame (one set-up) instead of one each")
    p.set_defaults(handler=_import_points)


PARSERS: dict[str, Callable[[Any], None]] = {"import-points": add_parsers}
"""The command's parser builder (:func:`aacmm_pin.cli.build_parser` builds only the command given)."""
