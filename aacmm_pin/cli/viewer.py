"""The ``view`` subcommand: :func:`aacmm_pin.outputs.viewer.view` live on localhost or as one HTML file."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from aacmm_pin.cli._options import (
    FORCE_FILE,
    add_command,
    effects_file_option,
    force_option,
    input_path,
)


def _view(args: argparse.Namespace) -> int:
    """Handler of ``aacmm-pin view``."""
    from aacmm_pin.outputs.viewer import view

    result = view(args.caldir, args.campaign, html=args.html, open_browser=args.open,
                  compare=args.compare, location=args.location, scale=args.scale,
                  force=args.force)
    summary = ", ".join(f"{m['label']} RMS {m['rms_um']:.2f} um" for m in result.scene.info["models"])
    if result.html is not None:
        print(f"wrote {result.html}: {summary} (deviations magnified {result.scene.scale:g}x)")
        return 0
    from aacmm_pin.progress import idle

    idle()  # from here on the server waits for the user: no "still working" lines
    try:
        print(f"serving {result.url} : {summary}; Ctrl+C stops", flush=True)
        deadline = None if args.serve_for is None else time.monotonic() + args.serve_for
        while deadline is None or time.monotonic() < deadline:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        result.close()
    return 0


def add_parsers(subparsers: Any) -> None:
    """Add the ``view`` subcommand to ``aacmm-pin``'s subparsers (``handler`` set to its function).

    Args:
        subparsers: what ``ArgumentParser.add_subparsers()`` returned.
    """
    p = add_command(subparsers, "view", "MeshCat view of the arm, the campaign and the residuals "
                                        "(live on localhost, or --html FILE)",
                    parents=[effects_file_option(), force_option(FORCE_FILE)])
    p.add_argument("caldir", type=input_path, help="calibration folder or parameters.json (shown first)")
    p.add_argument("campaign", type=input_path, help="campaign folder")
    p.add_argument("--html", type=Path, default=None, metavar="FILE",
                   help="write one self-contained HTML file (opens offline) instead of serving")
    p.add_argument("--open", action="store_true", help="open the page in the default browser")
    p.add_argument("--compare", type=input_path, nargs="+", action="extend", default=[], metavar="CALDIR",
                   help="more calibrations to switch to (e.g. the dh model's folder)")
    p.add_argument("--location", type=int, default=None,
                   help="R-Test location whose SPAT postures the animation steps through "
                        "(default: the first)")
    p.add_argument("--scale", type=float, default=None,
                   help="magnification of the deviations from each nest (default: the first "
                        "calibration's RMS residual drawn ~20 mm long)")
    p.add_argument("--serve-for", type=float, default=None, metavar="SECONDS",
                   help="stop the live server after this long (default: at Ctrl+C)")
    p.set_defaults(handler=_view)


PARSERS: dict[str, Callable[[Any], None]] = {"view": add_parsers}
"""The command's parser builder (:func:`aacmm_pin.cli.build_parser` builds only the command given)."""
