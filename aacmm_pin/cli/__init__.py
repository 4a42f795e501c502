"""The ``aacmm-pin`` command: :func:`main`, and one module of subcommands per group.

* :mod:`~aacmm_pin.cli.calibration`: ``axes``, ``simulate``, ``predict``, ``identify``,
  ``validate``, ``uncertainty``, ``plan``, ``demo``;
* :mod:`~aacmm_pin.cli.discovery`: ``discover``;
* :mod:`~aacmm_pin.cli.viewer`: ``view``;
* :mod:`~aacmm_pin.cli.acquisition`: ``acquire``, ``fake-devices``;
* :mod:`~aacmm_pin.cli.iso10360`: ``iso10360 spat|sphere|ldia|euni``;
* :mod:`~aacmm_pin.cli.importing`: ``import-points``.

Each module's ``PARSERS`` maps its commands to the functions that add their parsers
(:func:`build_parser` builds only the command a command line names: :data:`COMMANDS`); every leaf
parser sets ``handler``, a thin function of the parsed arguments that calls the public API, prints
and returns the exit status. Building the parser imports neither Pinocchio, yourdfpy, scipy nor
matplotlib: the handlers import what they need, so ``aacmm-pin --help`` and ``--version`` answer
at once.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import warnings
from collections.abc import Callable, Iterator, Sequence
from typing import Any, NoReturn

from aacmm_pin._blas import started_single_threaded
from aacmm_pin.cli._collector import imports_uncollected
from aacmm_pin.cli._options import Handler, HelpFormatter, check_input_paths, load_effect_files
from aacmm_pin.errors import AacmmError, CampaignWarning, StaleOutputWarning
from aacmm_pin.interrupts import Terminated, sigint_handler, sigterm_as_interrupt

__all__ = ["Handler", "build_parser", "main", "os_error_message", "run", "version"]


def version() -> str:
    """Return the installed version of aacmm_pin (the package's ``__version__`` if not installed)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed_version

    try:
        return installed_version("aacmm_pin")
    except PackageNotFoundError:
        from aacmm_pin import __version__

        return __version__


class _VersionAction(argparse.Action):
    """``--version``: print ``aacmm-pin <version>`` and exit 0 (the version is looked up only then)."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS,
                 default: Any = argparse.SUPPRESS, help: str | None = None) -> None:
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        print(f"{parser.prog} {version()}")
        parser.exit()


COMMANDS = {"axes": "calibration", "simulate": "calibration", "predict": "calibration",
            "identify": "calibration", "discover": "discovery", "validate": "calibration",
            "uncertainty": "calibration", "plan": "calibration", "demo": "calibration",
            "view": "viewer", "acquire": "acquisition", "fake-devices": "acquisition",
    "iso10360": "iso10360", "import-points": "importing"}
"""Each command's module in :mod:`aacmm_pin.cli` (its ``PARSERS`` builds the command's parser), in
the order of ``aacmm-pin --help``."""


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """Return the argument parser of ``aacmm-pin``.

    Args:
        command: build this command's parser alone (the command a command line starts with: the
            others' parsers and modules cost ~20 ms to build and import, a sixth of a small
            ``identify`` beyond its floor); default, or a name that is no command: all of them.
    """
    parser = argparse.ArgumentParser(
        prog="aacmm-pin",
        description="Calibrate articulated arm CMMs (Ibaraki & Saito, CIRP Annals 2023) on "
                    "Pinocchio.",
        formatter_class=HelpFormatter)
    parser.add_argument("--version", action=_VersionAction,
                        help="print the program's version (aacmm-pin X.Y.Z) and exit")
    sub = parser.add_subparsers(dest="command", required=True)
    for name, module in COMMANDS.items():
        if command not in COMMANDS or name == command:
            __import__(f"aacmm_pin.cli.{module}")  # an import statement's path: the collector's hook
            sys.modules[f"aacmm_pin.cli.{module}"].PARSERS[name](sub)
    return parser


BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS",
                         "MKL_NUM_THREADS", "BLIS_NUM_THREADS")
"""Environment variables that set a BLAS library's threads: a user's setting of any of them stands."""
ONE_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")
"""What :func:`one_blas_thread_at_start` sets to 1: each BLAS library numpy and SciPy are built on
(OpenBLAS in their wheels, MKL or BLIS in other builds) reads its own; not OpenMP's, which other
libraries read too."""


def one_blas_thread_at_start() -> bool:
    """Start BLAS with one thread here and in the processes started; return whether it did.

    identify, discover and uncertainty run with one BLAS thread anyway (products of a few hundred
    columns: :func:`aacmm_pin._blas.single_threaded_blas`), and the other commands gain little
    from more (2 cores, paper-sized campaign, CPU / wall s with one thread vs two: plan 17.2 / 17.2
    vs 24.9 / 16.4, validate 0.38 / 0.40 vs 0.59 / 0.38, simulate 5.7 / 5.7 vs 5.2 / 5.1), but
    OpenBLAS starts a pool of threads when it is loaded, once in numpy and once in scipy: ~0.2 s
    of CPU per command (`aacmm-pin identify` of a paper-sized campaign: 0.92 -> 0.70 s;
    ``benchmarks/cli.py``). Only at the start of the program, before numpy is imported, and only
    when the user set none of :data:`BLAS_THREAD_VARIABLES` (a user's setting stands). Sets
    :data:`ONE_THREAD_VARIABLES`, and tells :func:`~aacmm_pin._blas.single_threaded_blas` it has
    nothing left to limit.
    """
    if "numpy" in sys.modules or any(v in os.environ for v in BLAS_THREAD_VARIABLES):
        return False
    for name in ONE_THREAD_VARIABLES:
        os.environ[name] = "1"
    started_single_threaded()
    return True


INTERRUPTED = 128 + 2
"""Exit status after Ctrl-C (SIGINT): 128 + the signal's number, as the shells report it."""
TERMINATED = 128 + 15
"""Exit status after SIGTERM, handled as Ctrl-C is: 128 + the signal's number."""

@contextlib.contextmanager
def sigint_noted() -> Iterator[list[bool]]:
    """Within: Ctrl-C raises ``KeyboardInterrupt`` and is noted in the yielded one-element list.

    SIGINT is handled as Python's default handler does, plus the note, where Python's handler
    would raise (:func:`~aacmm_pin.interrupts.sigint_handler`; an ignored SIGINT stays ignored).

    An interrupt that lands inside an import of a C extension can surface as another error
    (numpy turns it into an ``ImportError`` about a bad install); the note tells the caller it
    was Ctrl-C.
    """
    noted = [False]

    def on_sigint(signum: int, frame: Any) -> None:
        noted[0] = True
        signal.default_int_handler(signum, frame)

    with sigint_handler(on_sigint):
        yield noted


QUIET_COMMANDS = ("acquire", "fake-devices")
"""Commands without a heartbeat: they run until stopped and print their own status."""


def parse_arguments(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Parse ``aacmm-pin``'s arguments; stray ones are reported by the subcommand they were given to.

    (argparse reports them with the top-level usage: ``aacmm-pin iso10360 euni CALDIR CAMPAIGN``
    would print the list of commands instead of ``euni``'s usage.)

    Raises:
        SystemExit: 2 after the usage and the error, as ``ArgumentParser.error``.
    """
    given = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(given[0] if given else None)
    args, stray = parser.parse_known_args(given)
    if stray:
        command: argparse.ArgumentParser = getattr(args, "command_parser", parser)
        command.error(f"unrecognized arguments: {' '.join(stray)}")
    return args


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``aacmm-pin``; return the exit status (errors are printed, not raised).

    Imports run without the garbage collector, their objects returned to it at the end
    (:func:`~aacmm_pin.cli._collector.imports_uncollected`).
    """
    with imports_uncollected():
        return _main(argv)


def run() -> NoReturn:
    """The ``aacmm-pin`` program: :func:`main` on the command line, then exit with its status.

    The imports' objects stay frozen to the exit (its last collection skips them).
    """
    with imports_uncollected(keep_frozen=True):
        status = _main(None)
    sys.exit(status)


def _main(argv: Sequence[str] | None) -> int:
    try:
        args = parse_arguments(argv)
    except KeyboardInterrupt:  # Ctrl-C while the parser loads (a slow disk)
        print("aacmm-pin: interrupted", file=sys.stderr)
        return INTERRUPTED
    one_blas_thread_at_start()
    # a sign of life whenever a command is silent for 1.5 s (acquisition reports on its own)
    beat = args.command not in QUIET_COMMANDS
    name = args.command_parser.prog  # "aacmm-pin iso10360 euni": the whole command
    with sigint_noted() as interrupted, sigterm_as_interrupt():
        try:
            return _run(args, name, beat)
        except Exception:
            if interrupted[0]:  # Ctrl-C turned into another error (inside an import)
                print(f"{name}: interrupted", file=sys.stderr)
                return INTERRUPTED
            raise


def _run(args: argparse.Namespace, name: str, beat: bool) -> int:
    """Run the command's handler; errors are printed as one line with the exit status."""
    from aacmm_pin.progress import Heartbeat

    try:
        handler: Handler = args.handler
        check_input_paths(args.command_parser, args)  # a wrong path: before the heavy imports
        with Heartbeat(name, enabled=beat), warnings.catch_warnings():
            warnings.showwarning = _one_line_warning(name)
            load_effect_files(args)  # --effects-file: before anything reads parameters
            return handler(args)
    except (AacmmError, ValueError) as exc:  # bad input or a bad argument: a message, no traceback
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    except Terminated:  # SIGTERM: as Ctrl-C (workers ended, claims released), its own status
        print(f"{name}: terminated (SIGTERM)", file=sys.stderr)
        return TERMINATED
    except KeyboardInterrupt:  # Ctrl-C: one line; the claims and atomic writers left nothing partial
        print(f"{name}: interrupted", file=sys.stderr)
        return INTERRUPTED
    except BrokenPipeError:  # `aacmm-pin ... | head`: the reader left; so do we, quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # no second error when Python flushes at exit
        return 1  # as the Python documentation recommends for a broken pipe
    except OSError as exc:  # read-only or full disk, a folder where a file should be, permissions
        print(f"{name}: error: {os_error_message(exc)}", file=sys.stderr)
        return 2


def _one_line_warning(command: str) -> Callable[..., None]:
    """Return a ``warnings.showwarning`` that prints a campaign warning as one line, no source.

    So too what a killed run left and this one took over (:class:`StaleOutputWarning`).
    """
    default = warnings.showwarning

    def show(message: Warning | str, category: type[Warning], *args: Any, **kwargs: Any) -> None:
        if issubclass(category, (CampaignWarning, StaleOutputWarning)):
            print(f"{command}: warning: {message}", file=sys.stderr)
        else:
            default(message, category, *args, **kwargs)
    return show


def os_error_message(exc: OSError) -> str:
    """Return one line for an operating-system error: the path(s) and what the system said."""
    paths = [str(p) for p in (exc.filename, exc.filename2) if p is not None]
    reason = exc.strerror or str(exc)
    return f"{' -> '.join(paths)}: {reason}" if paths else reason
