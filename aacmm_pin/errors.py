"""The exceptions of aacmm_pin: one base class, subclasses that carry their context."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


class AacmmError(Exception):
    """Base class of every error that aacmm_pin raises on purpose."""


@dataclass(frozen=True)
class Problem:
    """One problem found in an input file."""

    path: Path | str
    """File in which the problem is."""
    line: int | None
    """1-based line number, or None where the problem concerns the whole file."""
    column: str | None
    """Column name (or 1-based column number as text), or None."""
    reason: str
    """What is wrong, in plain words."""
    count: int = 1
    """How many problems this one stands for: more than 1 for a line that counts the problems of
    one kind left out ("... and 1,745 more rows like it")."""

    def __str__(self) -> str:
        """Format as ``path:line: column 'x': reason``."""
        where = str(self.path)
        if self.line is not None:
            where += f":{self.line}"
        if self.column is not None:
            where += f": column '{self.column}'"
        return f"{where}: {self.reason}"


class FileFormatError(AacmmError):
    """An input file (campaign CSV, parameters JSON, readouts) is malformed.

    All problems found are collected and reported together, each with file, line and column.
    """

    def __init__(self, problems: list[Problem]):
        self.problems = list(problems)
        n = sum(p.count for p in self.problems)
        shown = f" ({len(self.problems)} lines)" if n != len(self.problems) else ""
        head = f"{n:,} problem{'s' if n != 1 else ''} in input files{shown}:"
        super().__init__("\n".join([head, *(f"  {p}" for p in self.problems)]))


class CampaignFormatError(FileFormatError):
    """A campaign folder (spat.csv, locations.csv, lengthbar.csv, bar.csv) is malformed."""


class AcquisitionError(AacmmError):
    """The acquisition cannot start (ports, nest file, campaign files), with the reason."""


class ArmModelError(AacmmError):
    """A URDF does not follow aacmm_pin's arm conventions (axes, error frames, tool)."""

    def __init__(self, path: Path | str, reason: str):
        self.path = path
        self.reason = reason
        super().__init__(f"{path}: {reason}")


class FrameNotFound(AacmmError):
    """A frame, joint or parameter name is not in the arm."""

    def __init__(self, name: str, choices: list[str]):
        self.name = name
        self.choices = list(choices)
        super().__init__(f"'{name}' is not in the arm; choose from: {', '.join(self.choices)}")


class MissingExtraError(AacmmError, ModuleNotFoundError):
    """An optional part of aacmm_pin (an extra: viewer, figures, serial, urdf) is not installed.

    Also a ``ModuleNotFoundError`` (``name``: the module that is missing), so code that catches
    a failed import catches this too.
    """

    def __init__(self, needed_by: str, extra: str, module: str, package: str | None = None):
        self.needed_by = needed_by
        """What needs it, e.g. ``view`` or ``Arm.urdf_robot``."""
        self.extra = extra
        """The extra that installs it, e.g. ``viewer``."""
        self.package = package or module
        """The name the missing module is installed by (``pyserial`` for ``serial``)."""
        AacmmError.__init__(self, f"{needed_by} needs the {extra} extra ({self.package} is not "
                                  f'installed): pip install "aacmm_pin[{extra}]"')
        self.name = module


class ArgumentError(AacmmError, ValueError):
    """A value given to a function is unfit: wrong shape, not finite, or in the wrong unit.

    Its message is one line naming the argument (a ``ValueError`` too, as scipy's are).
    """


class MissingColumn(AacmmError, KeyError):
    """Samples (or a file) have no such per-sample column, e.g. ``temp_wrist_c``.

    A ``KeyError`` too, so that an effect's code written as for a mapping catches it. Its message
    is one line naming the column and the files that could hold it.
    """

    def __init__(self, column: str, message: str):
        super().__init__(message)
        self.column = column
        """The column's name, as in the files."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""

    def __reduce__(self) -> tuple[type, tuple[str, str]]:
        return type(self), (self.column, str(self))


class CampaignWarning(UserWarning):
    """A campaign is read, but something in it deserves the user's eye (e.g. copied rows)."""


class StaleOutputWarning(UserWarning):
    """What a killed run left beside an output (a lock file, temporary files) was taken over or removed."""
