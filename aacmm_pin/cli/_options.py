"""Shared pieces of the ``aacmm-pin`` parsers: help formatter, repeated options, ``--json`` writer.

Every option repeated across commands is a parent parser (``argparse``'s ``parents=[...]``) made by
one function here, so its name, type and wording are written once. The functions take the default
or the help text where commands differ (the ``--out`` folder of ``identify`` is not ``demo``'s).
Nothing here imports the rest of the package at import time: building the parser stays cheap
(:func:`load_effect_files` imports the effect library when a command is given a file).
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager, nullcontext
from pathlib import Path
from typing import Any

Handler = Callable[[argparse.Namespace], int]
"""What every leaf parser sets as ``handler``: parsed arguments -> exit status."""


ARM_HELP = "URDF path or embedded arm name"


def input_path(text: str) -> Path:
    """``type=`` of an argument the command reads: a :class:`~pathlib.Path`, marked as an input.

    :func:`check_input_paths` (``main``, before the handler) checks that every such path exists:
    a wrong path is reported before the command imports Pinocchio and SciPy or starts its work.
    """
    return Path(text)


def arm_source(text: str) -> str:
    """``type=`` of an arm argument (URDF path or embedded arm's name), checked as an input."""
    return text


def sizes_source(text: str) -> str:
    """``type=`` of ``--sizes`` (a sizes file or an embedded arm's name), checked as an input."""
    return text


def check_input_paths(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Raise if an argument of ``parser`` of type :func:`input_path` names no file or folder.

    An argument of type :func:`arm_source` must be a URDF file or an embedded arm's name, one of
    type :func:`sizes_source` a sizes file or the name of an embedded arm with one.

    Raises:
        FileNotFoundError: naming the path and the argument (one line), for the first missing one.
        ArmModelError: for an arm (or sizes) that is neither a file nor an embedded arm's name.
    """
    import errno
    import os

    from aacmm_pin.model.arm_files import resolve_arm_path, resolve_sizes_path

    for action in parser._actions:
        if action.type is arm_source and getattr(args, action.dest, None) is not None:
            resolve_arm_path(getattr(args, action.dest))
        if action.type is sizes_source and getattr(args, action.dest, None) is not None:
            resolve_sizes_path(getattr(args, action.dest))
        if action.type is not input_path:
            continue
        given = getattr(args, action.dest, None)
        for path in given if isinstance(given, list) else [given]:
            if path is not None and not Path(path).exists():
                name = action.option_strings[-1] if action.option_strings else action.dest
                raise FileNotFoundError(errno.ENOENT, f"{os.strerror(errno.ENOENT)} "
                                                      f"(the {name} argument)", str(path))


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """``ArgumentDefaultsHelpFormatter`` that shows no ``(default: None)``, ``False`` or ``[]``.

    Such an option is off unless given; its help says what happens without it (``--workers``:
    "default: all cores"), which says more than ``None``.
    """

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default is None or action.default is False or action.default == []:
            return action.help
        return super()._get_help_string(action)


def add_command(subparsers: Any, name: str, help: str, *,
                parents: Sequence[argparse.ArgumentParser] = (),
                description: str | None = None) -> argparse.ArgumentParser:
    """Add subcommand ``name`` with the defaults-showing help formatter and return its parser.

    Args:
        subparsers: what ``ArgumentParser.add_subparsers()`` returned.
        name: the subcommand.
        help: one line for the list of commands (and the description, unless given).
        parents: parent parsers of shared options (made by the functions of this module).
        description: longer text for the command's own ``--help``.
    """
    parser: argparse.ArgumentParser = subparsers.add_parser(
        name, help=help, description=description or help, parents=list(parents),
        formatter_class=HelpFormatter)
    parser.set_defaults(command_parser=parser)  # the innermost command's: it reports stray arguments
    return parser


def _parent() -> argparse.ArgumentParser:
    return argparse.ArgumentParser(add_help=False)


TOOL_FRAME_HELP = ("for a URDF without a fixed joint 'tool': the link the measured point (stylus, "
                   "SMR) hangs off; a joint 'tool' is added on it in memory, the point's vector "
                   "in its frame identified (default: tool0)")
SIZES_HELP = ("the arm's plausible error sizes, a sizes file (JSON, SI) or an embedded arm's name "
              "(its sizes, e.g. ur5 for another UR5 URDF; default: <urdf>.sizes.json beside the "
              "URDF, else the default AACMM's)")


def arm_details(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add ``--tool-frame LINK`` and ``--sizes FILE`` (how to read an arm's URDF) to ``p``."""
    p.add_argument("--tool-frame", default=None, metavar="LINK", help=TOOL_FRAME_HELP)
    p.add_argument("--sizes", type=sizes_source, default=None, metavar="FILE", help=SIZES_HELP)
    return p


def arm_option(default: str | None = "aacmm7", text: str = ARM_HELP) -> argparse.ArgumentParser:
    """``--arm URDF``: the arm's URDF path or embedded name, with ``--tool-frame`` and ``--sizes``."""
    p = _parent()
    p.add_argument("--arm", type=arm_source, default=default, metavar="URDF", help=text)
    return arm_details(p)


def load_given_arm(args: argparse.Namespace, arm: str | None = None, *, error_frames: bool = True
                   ) -> Any:
    """Load the arm ``arm`` (default ``args.arm``) with ``--tool-frame`` and ``--sizes``.

    ``error_frames``: as :func:`~aacmm_pin.model.arm.load_arm`'s (False for the arm of parameters
    without DH values: a compact URDF).

    Prints, in one line, what was added to the URDF in memory (a tool joint, error frames), if
    anything (:attr:`aacmm_pin.model.arm.Arm.note`). Returns the :class:`~aacmm_pin.model.arm.Arm`.
    """
    from aacmm_pin.model.arm import load_arm

    out = load_arm(args.arm if arm is None else arm, getattr(args, "tool_frame", None),
                   getattr(args, "sizes", None), error_frames=error_frames)
    if out.note:
        print(out.note, flush=True)
    return out


def out_option(default: Path, text: str) -> argparse.ArgumentParser:
    """``--out PATH``: where the command writes."""
    p = _parent()
    p.add_argument("--out", type=Path, default=default, help=text)
    return p


FORCE_FOLDER = ("replace the output folder if it exists and holds files (all of them are "
                "removed); without it such a folder is refused")
FORCE_FILE = "replace the output file if it exists; without it an existing file is refused"


def force_option(text: str = FORCE_FOLDER) -> argparse.ArgumentParser:
    """``--force``: replace an existing output (a folder or a file, written whole or not at all).

    Without it an existing output is refused; with it too, an output that is one of the command's
    inputs (:func:`aacmm_pin.data.output_claim.check_inputs`).
    """
    p = _parent()
    p.add_argument("--force", action="store_true", help=text)
    return p


def positive(kind: type = float, zero: bool = False) -> Callable[[str], Any]:
    """Return an argparse type: a finite number > 0 (>= 0 with ``zero``) of ``kind``."""
    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not math.isfinite(value) or value < 0 or (value == 0 and not zero):
            raise argparse.ArgumentTypeError(
                f"expected a finite number {'>=' if zero else '>'} 0, got {text!r}")
        return value

    parse.__name__ = f"{'non-negative' if zero else 'positive'} {kind.__name__}"
    return parse


def noise_um(text: str) -> float:
    """Argparse type of a stated noise in um: within the bounds of :func:`aacmm_pin.units.noise_problem`."""
    from aacmm_pin.units import UM, noise_problem

    value = positive()(text)
    if (why := noise_problem(value * UM)) is not None:
        raise argparse.ArgumentTypeError(why)
    return float(value)


def noise_um_or_zero(text: str) -> float:
    """Argparse type of a simulated noise in um: 0 (none) or as :func:`noise_um`."""
    value = positive(zero=True)(text)
    return 0.0 if value == 0 else noise_um(text)


def seed_option(text: str) -> argparse.ArgumentParser:
    """``--seed N``: a random seed, 0 by default (same seed, same result)."""
    p = _parent()
    p.add_argument("--seed", type=int, default=0, help=text)
    return p


def json_option(what: str) -> argparse.ArgumentParser:
    """``--json FILE``: also write ``what`` as JSON."""
    p = _parent()
    p.add_argument("--json", type=Path, default=None, metavar="FILE",
                   help=f"also write {what} as JSON")
    return p


def model_option(choices: Sequence[str] = ("dh", "proposed"),
                 text: str = "dh: DH errors only; proposed: DH errors and encoder maps",
                 default: str = "proposed") -> argparse.ArgumentParser:
    """``--model``: the identification model."""
    p = _parent()
    p.add_argument("--model", choices=tuple(choices), default=default, help=text)
    return p


def no_rtest_option(text: str) -> argparse.ArgumentParser:
    """``--no-rtest``: leave out the R-Test displacements (conventional SPAT)."""
    p = _parent()
    p.add_argument("--no-rtest", action="store_true", help=text)
    return p


def max_nfev_option(discovery: bool = False) -> argparse.ArgumentParser:
    """``--max-nfev N``: the evaluation cap of a fit (its solves stop at their tolerance).

    With ``discovery``: of all the discovery's fits together (default from ``--max-steps``).
    """
    p = _parent()
    p.add_argument("--max-nfev", type=positive(int), default=None, metavar="N", help=(
        "most residual evaluations of all the discovery's fits together (the start, each step's "
        "refit, refits after a dropped term; default 200 x (--max-steps + 1)); a step's fit that "
        "reaches it ends the loop, the steps so far written, exit 1" if discovery else
        "most residual evaluations of a fit, all its solves together (rounds, robust passes, the "
        "refit with fixed nests; a fit stops at its tolerance, the count used is printed and in "
        "report.json); default: no cap on the whole fit, each solve stops after 200"))
    return p


def nest_option(text: str) -> argparse.ArgumentParser:
    """``--nest FILE``: the R-Test nest's sensor directions."""
    p = _parent()
    p.add_argument("--nest", type=input_path, default=None, metavar="FILE", help=text)
    return p


def params_option() -> argparse.ArgumentParser:
    """``--params PARAMS_OR_CALDIR``: a calibration instead of the nominal arm."""
    p = _parent()
    p.add_argument("--params", type=input_path, default=None, metavar="PARAMS_OR_CALDIR",
                   help="parameters.json or calibration folder (default: the nominal arm)")
    return p


def effects_file_option() -> argparse.ArgumentParser:
    """``--effects-file FILE`` (repeatable): Python files that register effects, run first.

    :func:`load_effect_files` runs them (``main`` does, before the command's handler), so that
    the command's reading of parameters and its ``--effects`` know their effects.
    """
    p = _parent()
    p.add_argument("--effects-file", type=input_path, action="append", default=[], metavar="FILE",
                   help="a Python file that registers effects (aacmm_pin.register_effect), run "
                        "before anything else; repeatable. Effects of installed packages (entry "
                        "point group aacmm_pin.effects) load without it")
    return p


def load_effect_files(args: argparse.Namespace) -> list[str]:
    """Run every ``--effects-file`` of the parsed arguments, in order; return the effects registered.

    Raises:
        AacmmError: naming the file that does not exist or fails.
    """
    files = getattr(args, "effects_file", None) or []
    if not files:
        return []
    from aacmm_pin.effects.registry import load_effect_file  # the effect library: only when asked

    return [name for path in files for name in load_effect_file(path)]


def write_json(path: Path, data: dict[str, Any], force: bool = False,
               inputs: Sequence[str | Path] = ()) -> None:
    """Write ``data`` as JSON to ``path`` (what ``--json FILE`` asks for), whole or not at all.

    Through :func:`aacmm_pin.data.output_file.write_text_file`: an existing file is replaced only
    with ``force``, never when it is one of ``inputs``.
    """
    from aacmm_pin.data.output_file import write_text_file

    write_text_file(path, json.dumps(data, indent=2) + "\n", force, inputs)


def claim_file(path: Path | None, force: bool, inputs: Sequence[str | Path] = ()
               ) -> AbstractContextManager[Any]:
    """Claim an optional output file (``--json``, ``--html``) at a command's start, before its work.

    Returns :func:`aacmm_pin.data.output_claim.claim_output` of the file (refused at once when it
    exists without ``force``, is an input, or another run writes it), or a no-op for None.
    """
    if path is None:
        return nullcontext()
    from aacmm_pin.data.output_claim import claim_output

    return claim_output(path, force, inputs, folder=False)


def read_files(args: argparse.Namespace) -> list[str | None]:
    """Return the files a command reads beside its campaign and calibration (kept from its outputs).

    ``--arm``'s URDF (None for an embedded arm's name) and the ``--effects-file`` modules.
    """
    arm = getattr(args, "arm", None)
    return [arm if arm is not None and Path(arm).is_file() else None,
            *(getattr(args, "effects_file", None) or [])]


def campaign_inputs(args: argparse.Namespace) -> list[Path]:
    """Return what a command of a campaign and ``--arm`` reads (kept from its outputs)."""
    from aacmm_pin.data.output_claim import input_paths

    return input_paths(*read_files(args), campaigns=[args.campaign])
